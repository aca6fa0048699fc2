/* stepper.c -- step generation from Timer1.
 *
 * Timer1 runs in CTC mode at 2 MHz: a compare match with OCR1A is a step.  In
 * CTC mode the counter restarts at every match, so the interval loaded into
 * OCR1A during one interrupt is exactly the time to the next step, however
 * late the interrupt itself ran; lateness shows up only as jitter of the
 * software edge, never as drift.
 *
 * The interrupt is deliberately dumb (see planner.h for why the maths lives
 * elsewhere).  Per step it:
 *   1. checks the one limit switch ahead of the motion (stop before, not
 *      after, stepping into it);
 *   2. raises STEP and counts the step;
 *   3. when the current block of the plan is used up, loads the next block's
 *      count and interval (a table read);
 *   4. holds STEP high until pulse_us has passed since the rising edge,
 *      measured on the same timer, then lowers it.
 * Holding the pulse inside the interrupt costs pulse_us of CPU per step (2 us
 * of a 50 us step at 20 kHz) and saves a second interrupt and its jitter.
 *
 * DIR only changes between moves, in stepper_start(), which waits
 * dir_setup_us before starting the timer: the driver's setup time is met by
 * construction. */
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
static int8_t st_dir;
static uint8_t st_limit_mask, st_limit_xor;   /* (PIN ^ xor) & mask != 0: switch ahead pressed */
static uint8_t pulse_ticks = 4, dir_setup = 1, invert_bits;

void stepper_init(void)
{
  STEP_DDR |= _BV(STEP_BIT);
  DIR_DDR |= _BV(DIR_BIT);
  EN_DDR |= _BV(EN_BIT);
  LIMIT_DDR &= (uint8_t)~(_BV(LIMIT_BOTTOM_BIT) | _BV(LIMIT_TOP_BIT));
  LIMIT_PORT |= _BV(LIMIT_BOTTOM_BIT) | _BV(LIMIT_TOP_BIT);     /* pull-ups */
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
  if (invert & 4) EN_PORT |= _BV(EN_BIT); else EN_PORT &= (uint8_t)~_BV(EN_BIT);
}

uint8_t limits_pressed(void)
{
  uint8_t pins = LIMIT_PIN;
  if (!(invert_bits & 2)) pins = (uint8_t)~pins;
  return (uint8_t)(((pins >> LIMIT_BOTTOM_BIT) & 1) | (((pins >> LIMIT_TOP_BIT) & 1) << 1));
}

static void load_next_block(void)
{
  uint16_t iv;
  while (st_block <= 2 * st_plan.nseg) {
    st_left = plan_block(st_ramp, &st_plan, st_block, &iv);
    if (st_left) { OCR1A = iv; return; }
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
  if (up ^ (invert_bits & 1)) DIR_PORT |= _BV(DIR_BIT); else DIR_PORT &= (uint8_t)~_BV(DIR_BIT);
  st_limit_mask = up ? _BV(LIMIT_TOP_BIT) : _BV(LIMIT_BOTTOM_BIT);
  st_limit_xor = (invert_bits & 2) ? 0 : (_BV(LIMIT_TOP_BIT) | _BV(LIMIT_BOTTOM_BIT));
  stop_reason = STOP_DONE;
  st_block = 0;
  load_next_block();
  if (!st_left) return;
  for (uint8_t i = 0; i < dir_setup; i++) _delay_us(1);
  stepper_running = 1;
  TCNT1 = 0;
  TIFR1 = _BV(OCF1A);
  TCCR1B = _BV(WGM12) | _BV(CS11);           /* CTC on OCR1A, clk/8 = 2 MHz */
}

ISR(TIMER1_COMPA_vect)
{
  if ((LIMIT_PIN ^ st_limit_xor) & st_limit_mask) {
    TCCR1B = 0;
    stepper_running = 0;
    stop_reason = STOP_LIMIT;
    return;
  }
  STEP_PORT |= _BV(STEP_BIT);
  uint16_t rise = TCNT1;
  position += st_dir;
  if (--st_left == 0) {
    st_block++;
    load_next_block();
    if (!st_left) { TCCR1B = 0; stepper_running = 0; }
  }
  while ((uint16_t)(TCNT1 - rise) <= pulse_ticks) {
    if (!stepper_running) break;          /* timer stopped: TCNT1 frozen */
  }
  if (!stepper_running) { uint8_t pt = pulse_ticks; while (pt--) _delay_us(0.5); }
  STEP_PORT &= (uint8_t)~_BV(STEP_BIT);
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
