/* test_host.c -- unit tests of the firmware's pure sources, built for the host
 * with cmocka (and ASan/UBSan).  Run: make host-test.  The planner, the line
 * protocol, the CRC and the settings image are the same .c files the AVR
 * build compiles; only the interrupt-level code is left to the simavr tests. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <cmocka.h>

#include "crc.h"
#include "planner.h"
#include "protocol.h"
#include "settings.h"
#include "uart_math.h"

/* ---- CRC ---- */
static void crc_matches_the_catalogue_check_value(void **state)
{
  (void)state;
  assert_int_equal(crc16("123456789", 9), 0x29B1); /* CRC-16/CCITT-FALSE check value */
  assert_int_equal(crc16("", 0), 0xFFFF);
}

static void crc_catches_every_single_bit_flip(void **state)
{
  (void)state;
  char line[] = "17 MOVE 123456";
  uint16_t good = crc16(line, strlen(line));
  for (size_t i = 0; i < strlen(line); i++)
    for (int b = 0; b < 8; b++) {
      line[i] ^= (char)(1 << b);
      assert_int_not_equal(crc16(line, strlen(line)), good);
      line[i] ^= (char)(1 << b);
    }
}

/* ---- UART divider ---- */
static void ubrr_for_115200_at_16mhz_is_16_within_2_5_percent(void **state)
{
  (void)state;
  assert_int_equal(ubrr_u2x(16000000UL, 115200), 16); /* datasheet table, U2X=1 */
  assert_int_equal(ubrr_u2x(16000000UL, 9600), 207);
  assert_int_equal(ubrr_u2x(16000000UL, 250000), 7);
  uint32_t actual = baud_of_ubrr_u2x(16000000UL, 16);
  double err = ((double)actual - 115200.0) / 115200.0;
  assert_true(err < 0.025 && err > -0.025);
}

/* ---- planner ---- */
static uint32_t ramp_total(const ramp_t *r)
{
  uint32_t s = 0;
  for (int i = 0; i < RAMP_SEGMENTS; i++) s += r->steps[i];
  return s;
}

static uint32_t plan_steps(const ramp_t *r, const plan_t *p, uint64_t *ticks)
{
  uint32_t n = 0;
  *ticks = 0;
  for (uint8_t k = 0; k <= 2 * p->nseg; k++) {
    uint16_t iv;
    uint32_t c = plan_block(r, p, k, &iv);
    n += c;
    *ticks += (uint64_t)c * iv;
  }
  return n;
}

static void ramp_reaches_the_distance_v2_over_2a(void **state)
{
  (void)state;
  ramp_t r;
  ramp_build(&r, 16000, 80000);
  assert_int_equal(ramp_total(&r), 1600); /* 16000^2 / (2 * 80000) */
  assert_int_equal(r.top_interval, 125);
}

static void ramp_intervals_never_get_slower_while_accelerating(void **state)
{
  (void)state;
  ramp_t r;
  ramp_build(&r, 30000, 300000);
  uint16_t prev = 65535;
  for (int i = 0; i < RAMP_SEGMENTS; i++) {
    if (!r.steps[i]) continue;
    assert_true(r.interval[i] <= prev);
    assert_true(r.interval[i] >= r.top_interval);
    prev = r.interval[i];
  }
}

static void ramp_slices_last_as_long_as_planned(void **state)
{
  /* each slice should take T/K = v/(a K) seconds: steps x interval ~ slice ticks */
  (void)state;
  ramp_t r;
  ramp_build(&r, 16000, 80000);
  double slice_ticks = 2e6 * 16000.0 / (80000.0 * RAMP_SEGMENTS);
  for (int i = 4; i < RAMP_SEGMENTS; i++) {
    double t = (double)r.steps[i] * r.interval[i];
    assert_true(t > 0.9 * slice_ticks && t < 1.1 * slice_ticks);
  }
}

static void every_plan_makes_exactly_the_distance(void **state)
{
  (void)state;
  ramp_t r;
  ramp_build(&r, 16000, 80000);
  uint32_t dists[] = { 1, 2, 3, 7, 100, 1599, 1600, 3199, 3200, 3201, 50000, 160000 };
  for (size_t i = 0; i < sizeof dists / sizeof dists[0]; i++) {
    plan_t p;
    uint64_t ticks;
    plan_move(&r, dists[i], 16000, &p);
    assert_int_equal(plan_steps(&r, &p, &ticks), dists[i]);
    assert_true(p.cruise_interval >= r.top_interval);
  }
}

static void a_long_move_cruises_at_max_rate_and_takes_the_trapezoid_time(void **state)
{
  (void)state;
  ramp_t r;
  ramp_build(&r, 16000, 80000);
  plan_t p;
  uint64_t ticks;
  plan_move(&r, 32000, 16000, &p);
  assert_int_equal(p.nseg, RAMP_SEGMENTS);
  assert_int_equal(p.cruise_interval, 125);
  plan_steps(&r, &p, &ticks);
  /* ideal: 2 x 0.2 s ramps + (32000 - 3200) / 16000 s cruise = 2.2 s */
  double secs = ticks / 2e6;
  assert_true(secs > 2.2 * 0.98 && secs < 2.2 * 1.02);
}

static void a_slower_rate_uses_only_the_slower_slices(void **state)
{
  (void)state;
  ramp_t r;
  ramp_build(&r, 16000, 80000);
  plan_t p;
  plan_move(&r, 100000, 800, &p);
  assert_int_equal(p.cruise_interval, 2500);
  for (uint8_t k = 0; k < p.nseg; k++) assert_true(r.interval[k] > 2500);
}

/* ---- line protocol ---- */
static uint8_t parse(const char *body, command_t *c, char *store)
{
  char tmp[80];
  snprintf(tmp, sizeof tmp, "%s*%04X", body, crc16(body, strlen(body)));
  strcpy(store, tmp);
  return proto_parse(store, (uint8_t)strlen(store), c);
}

static void a_well_formed_move_parses(void **state)
{
  (void)state;
  command_t c;
  char buf[80];
  assert_int_equal(parse("42 MOVE -1600", &c, buf), 0);
  assert_int_equal(c.seq, 42);
  assert_int_equal(c.verb, V_MOVE);
  assert_int_equal(c.argc, 1);
  assert_string_equal(c.arg[0], "-1600");
}

static void a_wrong_checksum_is_refused_and_the_seq_not_trusted(void **state)
{
  (void)state;
  command_t c;
  char line[] = "42 MOVE 1600*0000";
  assert_int_equal(proto_parse(line, (uint8_t)strlen(line), &c), ERR_bad_checksum);
  assert_int_equal(c.seq, 0);
  char nostar[] = "42 MOVE 1600";
  assert_int_equal(proto_parse(nostar, (uint8_t)strlen(nostar), &c), ERR_bad_checksum);
  char badhex[] = "42 MOVE 1600*12G4";
  assert_int_equal(proto_parse(badhex, (uint8_t)strlen(badhex), &c), ERR_bad_checksum);
}

static void syntax_errors_have_their_own_codes(void **state)
{
  (void)state;
  command_t c;
  char buf[80];
  assert_int_equal(parse("MOVE 5", &c, buf), ERR_bad_syntax);
  assert_int_equal(parse("0 ID", &c, buf), ERR_bad_syntax);
  assert_int_equal(parse("65536 ID", &c, buf), ERR_bad_syntax);
  assert_int_equal(parse("7", &c, buf), ERR_bad_syntax);
  assert_int_equal(parse("7 JUMP", &c, buf), ERR_unknown_command);
  assert_int_equal(c.seq, 7);
  assert_int_equal(parse("7 MOVE", &c, buf), ERR_bad_argument);
  assert_int_equal(parse("7 ID now", &c, buf), ERR_bad_argument);
  assert_int_equal(parse("7 SET a b c", &c, buf), ERR_bad_argument);
}

static void numbers_are_whole_int32_or_nothing(void **state)
{
  (void)state;
  int32_t v;
  assert_true(proto_parse_i32("2147483647", &v) && v == INT32_MAX);
  assert_true(proto_parse_i32("-2147483648", &v) && v == INT32_MIN);
  assert_false(proto_parse_i32("2147483648", &v));
  assert_false(proto_parse_i32("12a", &v));
  assert_false(proto_parse_i32("", &v));
  assert_false(proto_parse_i32("-", &v));
  assert_false(proto_parse_i32("99999999999", &v));
}

static void a_runaway_line_is_reported_once_when_it_ends(void **state)
{
  (void)state;
  linebuf_t lb;
  linebuf_init(&lb);
  for (int i = 0; i < 200; i++) assert_int_equal(linebuf_feed(&lb, 'x'), LB_NONE);
  assert_int_equal(linebuf_feed(&lb, '\n'), LB_OVERFLOW);
  linebuf_init(&lb);
  const char *ok = "1 ID*ABCD\r";
  for (const char *p = ok; *p; p++) assert_int_equal(linebuf_feed(&lb, (uint8_t)*p), LB_NONE);
  assert_int_equal(linebuf_feed(&lb, '\n'), LB_LINE);
  assert_string_equal(lb.buf, "1 ID*ABCD");
}

static void a_sealed_reply_carries_its_crc(void **state)
{
  (void)state;
  char b[32] = "5 ok";
  uint8_t n = proto_seal(b, 4, sizeof b);
  assert_int_equal(n, 10);
  char want[16];
  snprintf(want, sizeof want, "5 ok*%04X\n", crc16("5 ok", 4));
  assert_memory_equal(b, want, 10);
  assert_int_equal(proto_seal(b, 28, sizeof b), 0); /* no room: refused, not overrun */
}

/* ---- settings image ---- */
static void defaults_survive_a_round_trip(void **state)
{
  (void)state;
  settings_t s, t;
  uint8_t blob[SETTINGS_BLOB_SIZE];
  settings_defaults(&s);
  assert_int_equal(s.v[SET_steps_per_rev], 3200);
  settings_encode(&s, blob);
  assert_int_equal(settings_decode(blob, &t), SETTINGS_OK);
  assert_memory_equal(&s, &t, sizeof s);
}

static void a_blank_or_damaged_eeprom_is_rejected(void **state)
{
  (void)state;
  settings_t s;
  uint8_t blob[SETTINGS_BLOB_SIZE];
  memset(blob, 0xFF, sizeof blob);
  assert_int_equal(settings_decode(blob, &s), SETTINGS_BAD_HEADER);
  settings_defaults(&s);
  settings_encode(&s, blob);
  blob[10] ^= 0x04;
  assert_int_equal(settings_decode(blob, &s), SETTINGS_BAD_CRC);
  blob[10] ^= 0x04;
  blob[1] = SETTINGS_LAYOUT + 1;
  assert_int_equal(settings_decode(blob, &s), SETTINGS_BAD_HEADER);
}

static void an_out_of_range_value_with_a_good_crc_is_still_rejected(void **state)
{
  (void)state;
  settings_t s;
  uint8_t blob[SETTINGS_BLOB_SIZE];
  settings_defaults(&s);
  s.v[SET_accel] = 0;
  settings_encode(&s, blob);
  assert_int_equal(settings_decode(blob, &s), SETTINGS_BAD_VALUE);
}

static void settings_are_found_by_name_and_range_checked(void **state)
{
  (void)state;
  assert_int_equal(settings_find("accel"), SET_accel);
  assert_int_equal(settings_find("acceleration"), -1);
  assert_int_equal(settings_check_value(SET_pulse_us, 0), ERR_setting_out_of_range);
  assert_int_equal(settings_check_value(SET_pulse_us, 2), 0);
  settings_t s;
  settings_defaults(&s);
  s.v[SET_soft_min] = s.v[SET_soft_max];
  assert_int_equal(settings_check_all(&s), ERR_settings_inconsistent);
}

int main(void)
{
  const struct CMUnitTest tests[] = {
    cmocka_unit_test(crc_matches_the_catalogue_check_value),
    cmocka_unit_test(crc_catches_every_single_bit_flip),
    cmocka_unit_test(ubrr_for_115200_at_16mhz_is_16_within_2_5_percent),
    cmocka_unit_test(ramp_reaches_the_distance_v2_over_2a),
    cmocka_unit_test(ramp_intervals_never_get_slower_while_accelerating),
    cmocka_unit_test(ramp_slices_last_as_long_as_planned),
    cmocka_unit_test(every_plan_makes_exactly_the_distance),
    cmocka_unit_test(a_long_move_cruises_at_max_rate_and_takes_the_trapezoid_time),
    cmocka_unit_test(a_slower_rate_uses_only_the_slower_slices),
    cmocka_unit_test(a_well_formed_move_parses),
    cmocka_unit_test(a_wrong_checksum_is_refused_and_the_seq_not_trusted),
    cmocka_unit_test(syntax_errors_have_their_own_codes),
    cmocka_unit_test(numbers_are_whole_int32_or_nothing),
    cmocka_unit_test(a_runaway_line_is_reported_once_when_it_ends),
    cmocka_unit_test(a_sealed_reply_carries_its_crc),
    cmocka_unit_test(defaults_survive_a_round_trip),
    cmocka_unit_test(a_blank_or_damaged_eeprom_is_rejected),
    cmocka_unit_test(an_out_of_range_value_with_a_good_crc_is_still_rejected),
    cmocka_unit_test(settings_are_found_by_name_and_range_checked),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
