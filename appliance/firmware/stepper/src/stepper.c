/* stepper.c -- step generation by Timer1's output-compare hardware.
 *
 * Why the hardware makes the edges.  A STEP edge written by software in an
 * interrupt lands whenever the interrupt gets to run: after the UART's
 * interrupts, after any cli() section, after the instruction in flight.
 * That is microseconds of jitter, and a driver turns jitter into vibration.
 * So STEP sits on OC1A and Timer1 toggles it itself at the exact compare
 * match (COM1A = toggle).  The interrupts only schedule the next compare;
 * when one runs late, the edge it schedules is still exact, because times
 * are absolute on the free-running 2 MHz counter:
 *
 *   rise interrupt  (STEP just went high at time R):
 *       schedule the fall at R + pulse (or as soon as possible, if late).
 *   fall interrupt  (STEP just went low):
 *       count the step; stop if the limit switch ahead is pressed;
 *       take the next interval from the plan (a table read; planner.h says
 *       why all the maths lives outside); schedule the rise at R + interval.
 *
 * A late interrupt only matters if it is later than the next compare it has
 * to set up: for the fall that costs a longer pulse (never a shorter one), for
 * the rise it would cost a step period, so an interval must exceed the pulse
 * plus the worst interrupt latency: MIN_INTERVAL (20 us) covers that.
 *
 * DIR only changes between moves, in stepper_start(), which waits
 * dir_setup_us before starting the timer: the driver's setup time is met by
 * construction.  The limit switch ahead of the motion is checked before each
 * step is scheduled, so a pressed switch is never stepped into. */
#include <avr/interrupt.h>
#include <util/delay.h>
#include <util/atomic.h>
#include "stepper.h"

volatile uint8_t stepper_running;
static volatile int32_t position;
static volatile uint8_t stop_reason;

/* what the interrupt walks; written by stepper_start() only while stopped */
static const ramp_t *st_ramp;
static plan_t st_plan;
static uint8_t st_block;
static uint32_t st_left;
static uint16_t st_interval; /* ticks from this rise to the next */
static uint16_t st_rise;     /* timer time of the last rising edge */
static uint8_t st_high;      /* the next compare is the fall */
static int8_t st_dir;
static uint8_t st_limit_mask, st_limit_xor; /* (PIN ^ xor) & mask != 0: switch ahead pressed */
static uint8_t pulse_ticks = 4, dir_setup = 1, invert_bits;

#define LATE_MARGIN 6 /* ticks: time to write OCR1A before the counter passes it */

void stepper_init(void)
{
  STEP_PORT &= (uint8_t)~_BV(STEP_BIT);
  STEP_DDR |= _BV(STEP_BIT);
  DIR_DDR |= _BV(DIR_BIT);
  EN_DDR |= _BV(EN_BIT);
  const uint8_t limits = _BV(LIMIT_BOTTOM_BIT) | _BV(LIMIT_TOP_BIT);
  LIMIT_DDR &= (uint8_t)~limits;
  LIMIT_PORT |= limits; /* pull-ups */
  TCCR1A = 0;
  TCCR1B = 0;
  TIMSK1 = _BV(OCIE1A);
}

void stepper_configure(uint8_t pulse_us, uint8_t dir_setup_us, uint8_t invert)
{
  pulse_ticks = (uint8_t)(pulse_us * 2);
  dir_setup = dir_setup_us;
  invert_bits = invert;
  /* the driver stays enabled: the lead screw and the holding torque keep
   * the base where the last step left it */
  if (invert & 4) EN_PORT |= _BV(EN_BIT);
  else EN_PORT &= (uint8_t)~_BV(EN_BIT);
}

uint8_t limits_pressed(void)
{
  uint8_t pins = LIMIT_PIN;
  if (!(invert_bits & 2)) pins = (uint8_t)~pins;
  return (uint8_t)(((pins >> LIMIT_BOTTOM_BIT) & 1) | (((pins >> LIMIT_TOP_BIT) & 1) << 1));
}

/* Make st_left/st_interval describe the next non-empty block; 0 left = done. */
static void load_next_block(void)
{
  while (st_block <= 2 * st_plan.nseg) {
    st_left = plan_block(st_ramp, &st_plan, st_block, &st_interval);
    if (st_left) return;
    st_block++;
  }
  st_left = 0;
}

void stepper_start(const ramp_t *r, const plan_t *p, int8_t dir)
{
  stepper_halt_now();
  st_ramp = r;
  st_plan = *p;
  st_dir = dir;
  uint8_t up = dir > 0;
  if (up ^ (invert_bits & 1)) DIR_PORT |= _BV(DIR_BIT);
  else DIR_PORT &= (uint8_t)~_BV(DIR_BIT);
  st_limit_mask = up ? _BV(LIMIT_TOP_BIT) : _BV(LIMIT_BOTTOM_BIT);
  st_limit_xor = (invert_bits & 2) ? 0 : (_BV(LIMIT_TOP_BIT) | _BV(LIMIT_BOTTOM_BIT));
  stop_reason = STOP_DONE;
  st_block = 0;
  load_next_block();
  if (!st_left) return;
  if ((LIMIT_PIN ^ st_limit_xor) & st_limit_mask) {
    stop_reason = STOP_LIMIT;
    return;
  }
  for (uint8_t i = 0; i < dir_setup; i++) _delay_us(1);
  /* reset the OC1A latch to low (FOC1A with "clear on match"), then toggle mode */
  TCCR1A = _BV(COM1A1);
  TCCR1C = _BV(FOC1A);
  TCCR1A = _BV(COM1A0);
  st_high = 0;
  st_rise = st_interval; /* the first rise, one interval after start */
  TCNT1 = 0;
  OCR1A = st_rise;
  TIFR1 = _BV(OCF1A);
  stepper_running = 1;
  TCCR1B = _BV(CS11); /* normal mode, clk/8 = 2 MHz */
}

ISR(TIMER1_COMPA_vect)
{
  if (!st_high) { /* STEP rose at st_rise */
    st_high = 1;
    /* one tick (0.5 us) beyond the setting: pulse_us is the driver's
     * minimum, and an edge may land a few cycles off its compare (the
     * simulator rounds to instruction boundaries; the pin synchroniser on
     * the chip) without ever making the pulse too short */
    uint16_t fall = st_rise + pulse_ticks + 1;
    uint16_t soonest = TCNT1 + LATE_MARGIN;
    OCR1A = ((int16_t)(fall - soonest) > 0) ? fall : soonest;
    return;
  }
  st_high = 0; /* STEP fell: the step is done */
  position += st_dir;
  if (--st_left == 0) {
    st_block++;
    load_next_block();
    if (!st_left) {
      TCCR1B = 0;
      TCCR1A = 0;
      stepper_running = 0;
      return;
    }
  }
  if ((LIMIT_PIN ^ st_limit_xor) & st_limit_mask) {
    TCCR1B = 0;
    TCCR1A = 0;
    stepper_running = 0;
    stop_reason = STOP_LIMIT;
    return;
  }
  /* never schedule into the past: the counter would have to wrap (32 ms)
   * before the compare came round; a late step is better than a stall */
  uint16_t rise = st_rise + st_interval;
  uint16_t soonest = TCNT1 + LATE_MARGIN;
  st_rise = ((int16_t)(rise - soonest) > 0) ? rise : soonest;
  OCR1A = st_rise;
}

uint8_t stepper_stop_reason(void) { return stop_reason; }

int32_t stepper_position(void)
{
  int32_t p;
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { p = position; }
  return p;
}

void stepper_set_position(int32_t pos)
{
  ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { position = pos; }
}
