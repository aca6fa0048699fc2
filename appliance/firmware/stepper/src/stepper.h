#ifndef STEPPER_H
#define STEPPER_H
#include <stdint.h>
#include <avr/io.h>
#include "board.h"
#include "planner.h"

enum stop_reason { STOP_DONE = 0, STOP_LIMIT, STOP_HALT };

extern volatile uint8_t stepper_running;

/* The emergency stop.  Inline and register-only so the UART interrupt can
 * call it without saving the world first: stopping Timer1's clock means no
 * further compare match, so no further step. */
static inline void stepper_halt_now(void)
{
  TCCR1B = 0;                           /* no clock: no further compare match */
  TCCR1A = 0;                           /* hand the pin back to PORTB ... */
  STEP_PORT &= (uint8_t)~_BV(STEP_BIT); /* ... which holds it low */
  stepper_running = 0;
}

void stepper_init(void);
void stepper_configure(uint8_t pulse_us, uint8_t dir_setup_us, uint8_t invert);
/* Start a planned move of p->total steps, +1 (up) or -1 (down).  The limit
 * switch in the direction of travel stops it (stop reason STOP_LIMIT). */
void stepper_start(const ramp_t *r, const plan_t *p, int8_t dir);
uint8_t stepper_stop_reason(void);
int32_t stepper_position(void);
void stepper_set_position(int32_t pos);
uint8_t limits_pressed(void); /* bit 0 bottom, bit 1 top */
#endif
