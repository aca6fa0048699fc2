/* planner.h -- trapezoidal step timing, computed outside the step interrupt.
 *
 * Why a ramp table:  the step interrupt must do nothing but toggle a pin and
 * load the next interval (grbl's rule: a dumb fast interrupt).  Computing an
 * AVR446 interval per step needs a 32-bit division, ~600 cycles on this chip,
 * more than the whole budget of a 30 kHz step (533 cycles).  But the
 * acceleration ramp depends only on (max_rate, accel), which change only on a
 * SET.  So when the settings change we cut the ramp from rest to max_rate
 * into RAMP_SEGMENTS equal slices of time and store, per slice, how many steps
 * fall in it and the constant interval that spreads them over the slice (the
 * slice's average speed, which for a linear ramp is its mid-slice speed).
 * A move then takes the first m slices up, cruises, and takes the same m
 * slices down in reverse: integer maths, done once per move, in main().
 *
 * A short move simply uses fewer slices (a triangle); a slower move (homing)
 * uses the slices below its rate.  The cost is a staircase velocity profile:
 * the speed deviates from the ideal straight ramp by at most half a slice's
 * speed change, max_rate / (2 * RAMP_SEGMENTS), ~1 % here.  benches/firmware.py
 * measures it from the recorded STEP edges.
 *
 * Timer1 counts at TICK_HZ (16 MHz / 8), so intervals are 0.5 us units and
 * fit 16 bits down to 31 steps/s.  MIN_INTERVAL keeps a step period longer
 * than the STEP pulse plus the worst interrupt latency (stepper.c). */
#ifndef PLANNER_H
#define PLANNER_H
#include <stdint.h>

#define RAMP_SEGMENTS 48
#define TICK_HZ 2000000UL
#define MIN_INTERVAL 40u /* 20 us: 50 kHz, the fastest the ISR is allowed */
#define MAX_INTERVAL 65535u

typedef struct {
  uint16_t interval[RAMP_SEGMENTS]; /* timer ticks between steps in slice i */
  uint16_t steps[RAMP_SEGMENTS];    /* steps in slice i (0 = slice merged into the next) */
  uint16_t top_interval;            /* interval at max_rate */
} ramp_t;

/* One move, as the interrupt walks it: blocks 0..nseg-1 accelerate,
 * block nseg cruises, blocks nseg+1..2*nseg decelerate (slices reversed). */
typedef struct {
  uint32_t total;
  uint8_t nseg;
  uint32_t cruise_steps;
  uint16_t cruise_interval;
} plan_t;

uint16_t interval_for_rate(uint32_t rate);
void ramp_build(ramp_t *r, uint32_t max_rate, uint32_t accel);
void plan_move(const ramp_t *r, uint32_t distance, uint32_t rate, plan_t *p);
/* Block k of a plan (k = 0 .. 2*nseg): its step count and interval. */
uint32_t plan_block(const ramp_t *r, const plan_t *p, uint8_t k, uint16_t *interval);
#endif
