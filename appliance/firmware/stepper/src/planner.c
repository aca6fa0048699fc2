#include "planner.h"

uint16_t interval_for_rate(uint32_t rate)
{
  if (rate == 0) return MAX_INTERVAL;
  uint32_t iv = (TICK_HZ + rate / 2) / rate;
  if (iv < MIN_INTERVAL) iv = MIN_INTERVAL;
  if (iv > MAX_INTERVAL) iv = MAX_INTERVAL;
  return (uint16_t)iv;
}

/* Slice i ends at t = (i+1) T / K with T = v / a; the distance covered by then
 * is s = a t^2 / 2 = v^2 (i+1)^2 / (2 a K^2), rounded to whole steps.  The
 * steps between consecutive ends are spread evenly over the slice (or over
 * several slices when earlier ones held no whole step).  64-bit integers: the
 * products reach ~1e13.  This runs once per SET, never per step. */
void ramp_build(ramp_t *r, uint32_t max_rate, uint32_t accel)
{
  const uint64_t v = max_rate, a = accel ? accel : 1, K = RAMP_SEGMENTS;
  uint64_t prev_s = 0;
  uint8_t prev_end = 0; /* slices consumed so far */
  r->top_interval = interval_for_rate(max_rate);
  for (uint8_t i = 0; i < RAMP_SEGMENTS; i++) {
    uint64_t n = (uint64_t)(i + 1) * (i + 1) * v * v;
    uint64_t s = (n + a * K * K) / (2 * a * K * K);
    uint64_t steps = s - prev_s;
    if (steps == 0) {
      r->steps[i] = 0;
      r->interval[i] = MAX_INTERVAL;
      continue;
    }
    if (steps > 65535u) steps = 65535u;
    uint64_t slices = (uint64_t)(i + 1 - prev_end);
    uint64_t iv = (slices * TICK_HZ * v + (a * K * steps) / 2) / (a * K * steps);
    if (iv < r->top_interval) iv = r->top_interval;
    if (iv > MAX_INTERVAL) iv = MAX_INTERVAL;
    r->steps[i] = (uint16_t)steps;
    r->interval[i] = (uint16_t)iv;
    prev_s = s;
    prev_end = (uint8_t)(i + 1);
  }
}

/* Climb slices while they are slower than the wanted rate and while the
 * climb, mirrored for the descent, still fits in the distance.  The middle
 * runs at the wanted rate, or (a triangle) at the next slice's speed. */
void plan_move(const ramp_t *r, uint32_t distance, uint32_t rate, plan_t *p)
{
  uint16_t want = interval_for_rate(rate);
  if (want < r->top_interval) want = r->top_interval;
  uint32_t climbed = 0;
  uint8_t m = 0;
  while (m < RAMP_SEGMENTS && r->interval[m] > want && 2 * (climbed + r->steps[m]) <= distance) {
    climbed += r->steps[m];
    m++;
  }
  /* skip empty slices at the top of the climb: they carry no steps */
  p->total = distance;
  p->nseg = m;
  p->cruise_steps = distance - 2 * climbed;
  if (m < RAMP_SEGMENTS && r->interval[m] > want) {
    uint8_t j = m;
    while (j < RAMP_SEGMENTS - 1 && r->steps[j] == 0) j++;
    p->cruise_interval = r->interval[j] > want ? r->interval[j] : want;
  } else {
    p->cruise_interval = want;
  }
}

uint32_t plan_block(const ramp_t *r, const plan_t *p, uint8_t k, uint16_t *interval)
{
  if (k < p->nseg) {
    *interval = r->interval[k];
    return r->steps[k];
  }
  if (k == p->nseg) {
    *interval = p->cruise_interval;
    return p->cruise_steps;
  }
  if (k <= 2 * p->nseg) {
    uint8_t i = (uint8_t)(2 * p->nseg - k);
    *interval = r->interval[i];
    return r->steps[i];
  }
  *interval = 0;
  return 0;
}
