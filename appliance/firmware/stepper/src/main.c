/* main.c -- the controller: boot, the command dispatcher, homing, alarms.
 *
 * Everything slow lives here, in the main loop, never in an interrupt:
 * parsing lines, planning moves, the homing sequence, EEPROM.  The loop
 * sleeps (idle mode) whenever there is nothing to do and is woken by the
 * UART, the step timer or Timer2's 100 Hz tick, which exists so that the
 * watchdog is fed even when nothing else happens.  If the loop ever hangs,
 * the watchdog resets the chip and the next boot reports reset=watchdog.
 *
 * Duplicate detection: the host resends a command whose reply it did not
 * get.  The controller remembers the (seq, crc) of the last command it
 * executed and the exact reply it sent; a line with the same pair is
 * answered with that reply again and not executed again.  That is what makes
 * "resend until acknowledged" safe for MOVE.  After a reset the memory is
 * empty, but so is the homed flag, so a resent MOVE is refused (not_homed)
 * rather than executed from an unknown position. */
#include <string.h>
#include <avr/io.h>
#include <avr/interrupt.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <avr/eeprom.h>
#include <util/delay.h>
#include "codes.h"
#include "protocol.h"
#include "settings.h"
#include "planner.h"
#include "stepper.h"
#include "serial.h"
#include "pgm.h"

#define FW_VERSION "0.1.0"

/* ---- reset reason: MCUSR must be read and cleared before anything else,
 * and the watchdog disabled, or a watchdog reset loops forever ---- */
static uint8_t reset_flags __attribute__((section(".noinit")));
void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void)
{
  reset_flags = MCUSR;
  MCUSR = 0;
  wdt_disable();
}

static uint8_t reset_reason(void)
{
  if (reset_flags & _BV(WDRF)) return RESET_watchdog;
  if (reset_flags & _BV(BORF)) return RESET_brown_out;
  if (reset_flags & _BV(EXTRF)) return RESET_external;
  if (reset_flags & _BV(PORF)) return RESET_power_on;
  return RESET_unknown;
}

/* ---- controller state ---- */
static settings_t cfg;
static ramp_t ramp;
static uint8_t state = STATE_idle, alarm = ALARM_none, homed, settings_defaulted, fresh = 1;
static int32_t target;
static linebuf_t line;
static char reply[REPLY_MAX];
static char last_reply[REPLY_MAX];
static uint8_t last_reply_len;
static uint16_t last_seq, last_crc;

static uint8_t EEMEM ee_settings[SETTINGS_BLOB_SIZE];

static void apply_settings(void)
{
  ramp_build(&ramp, (uint32_t)cfg.v[SET_max_rate], (uint32_t)cfg.v[SET_accel]);
  stepper_configure((uint8_t)cfg.v[SET_pulse_us], (uint8_t)cfg.v[SET_dir_setup_us], (uint8_t)cfg.v[SET_invert]);
}

static void save_settings(void)
{
  uint8_t blob[SETTINGS_BLOB_SIZE];
  settings_encode(&cfg, blob);
  eeprom_update_block(blob, ee_settings, sizeof blob);
}

static void load_settings(void)
{
  uint8_t blob[SETTINGS_BLOB_SIZE];
  eeprom_read_block(blob, ee_settings, sizeof blob);
  if (settings_decode(blob, &cfg) != SETTINGS_OK) {
    settings_defaults(&cfg);
    save_settings();
    settings_defaulted = 1;
  }
  apply_settings();
}

/* ---- motion ---- */
static void start_move(int32_t to, uint32_t rate)
{
  int32_t from = stepper_position();
  plan_t p;
  int32_t d = to - from;
  plan_move(&ramp, (uint32_t)(d < 0 ? -d : d), rate, &p);
  stepper_start(&ramp, &p, d < 0 ? -1 : 1);
}

static void raise_alarm(uint8_t st, uint8_t why)
{
  stepper_halt_now();
  state = st;
  alarm = why;
  homed = 0;
}

/* Homing, as a sequence of plain moves, one phase per finished move:
 *   CLEAR    only if the switch is already pressed: back off it first
 *   SEEK     fast towards the switch, at most home_travel, stop on it
 *   BACKOFF  off the switch by home_backoff (fast: nothing is measured here)
 *   LOCATE   slowly back onto it (at most 2 x home_backoff); the step where
 *            the switch closes is position 0, the origin of all positions.
 *            Only this approach is slow, because only its end is measured.
 *   PULLOFF  up to home_pulloff, clear of the switch: homed. */
enum { H_NONE, H_CLEAR, H_SEEK, H_BACKOFF, H_LOCATE, H_PULLOFF };
static uint8_t home_phase;

static void home_seek(void)
{
  home_phase = H_SEEK;
  start_move(stepper_position() - cfg.v[SET_home_travel], (uint32_t)cfg.v[SET_home_fast]);
}

static void home_begin(void)
{
  state = STATE_homing;
  alarm = ALARM_none;
  homed = 0;
  if (limits_pressed() & 1) {
    home_phase = H_CLEAR;
    start_move(stepper_position() + cfg.v[SET_home_backoff], (uint32_t)cfg.v[SET_home_fast]);
  } else {
    home_seek();
  }
}

static void home_step(void)
{
  uint8_t hit = stepper_stop_reason() == STOP_LIMIT;
  uint8_t bottom = limits_pressed() & 1;
  switch (home_phase) {
  case H_CLEAR:
    if (bottom || hit) {
      raise_alarm(STATE_alarm, ALARM_home_switch_stuck);
      return;
    }
    home_seek();
    return;
  case H_SEEK:
    if (!hit) {
      raise_alarm(STATE_alarm, ALARM_home_switch_not_found);
      return;
    }
    home_phase = H_BACKOFF;
    start_move(stepper_position() + cfg.v[SET_home_backoff], (uint32_t)cfg.v[SET_home_fast]);
    return;
  case H_BACKOFF:
    if (bottom || hit) {
      raise_alarm(STATE_alarm, ALARM_home_switch_stuck);
      return;
    }
    home_phase = H_LOCATE;
    start_move(stepper_position() - 2 * cfg.v[SET_home_backoff], (uint32_t)cfg.v[SET_home_slow]);
    return;
  case H_LOCATE:
    if (!hit) {
      raise_alarm(STATE_alarm, ALARM_home_switch_not_found);
      return;
    }
    stepper_set_position(0);
    home_phase = H_PULLOFF;
    start_move(cfg.v[SET_home_pulloff], (uint32_t)cfg.v[SET_home_fast]);
    return;
  case H_PULLOFF:
    if (hit) {
      raise_alarm(STATE_alarm, ALARM_hard_limit_top);
      return;
    }
    home_phase = H_NONE;
    homed = 1;
    state = STATE_idle;
    return;
  }
}

static void motion_poll(void)
{
  if (stepper_running) return;
  if (state == STATE_homing) {
    home_step();
    return;
  }
  if (state == STATE_moving) {
    if (stepper_stop_reason() == STOP_LIMIT) {
      raise_alarm(STATE_alarm, target > stepper_position() ? ALARM_hard_limit_top : ALARM_hard_limit_bottom);
    } else {
      state = STATE_idle;
    }
  }
}

/* ---- replies ---- */
static uint8_t flags(void)
{
  uint8_t lim = limits_pressed();
  return (uint8_t)((homed ? FLAG_homed : 0) | ((lim & 1) ? FLAG_limit_bottom : 0) | ((lim & 2) ? FLAG_limit_top : 0) |
                   (settings_defaulted ? FLAG_settings_defaulted : 0) | (fresh ? FLAG_fresh_boot : 0));
}

/* "<state> <position> <flags hex> <alarm>", shared by STATUS and '?' */
static uint8_t put_status(char *b, uint8_t n)
{
  n = proto_put_P(b, n, REPLY_MAX, PGM_PTR(&proto_state_names[state]));
  b[n++] = ' ';
  n = proto_put_i32(b, n, REPLY_MAX, stepper_position());
  b[n++] = ' ';
  n = proto_put_hex2(b, n, REPLY_MAX, flags());
  b[n++] = ' ';
  return proto_put_i32(b, n, REPLY_MAX, alarm);
}

static void send_realtime_status(void)
{
  char b[40];
  uint8_t n = 0;
  b[n++] = '<';
  n = put_status(b, n);
  b[n++] = '>';
  n = proto_seal(b, n, sizeof b);
  serial_write(b, n);
}

static uint8_t begin_reply(uint16_t seq, uint8_t err)
{
  uint8_t n = proto_put_i32(reply, 0, REPLY_MAX, seq);
  if (err) {
    n = proto_put_P(reply, n, REPLY_MAX, PSTR(" error:"));
    n = proto_put_i32(reply, n, REPLY_MAX, err);
  } else {
    n = proto_put_P(reply, n, REPLY_MAX, PSTR(" ok"));
  }
  return n;
}

/* Driver presets: (pulse_us, dir_setup_us) from the datasheets' minimum
 * STEP high time and DIR setup time, rounded up to whole microseconds. */
static const char drv_a4988[] PROGMEM = "a4988", drv_drv8825[] PROGMEM = "drv8825", drv_tmc2209[] PROGMEM = "tmc2209";
static const struct {
  const char *name;
  uint8_t pulse, setup;
} drivers[] PROGMEM = {
  { drv_a4988, 1, 1 },   /* 1 us high, 200 ns setup */
  { drv_drv8825, 2, 1 }, /* 1.9 us high, 650 ns setup */
  { drv_tmc2209, 1, 1 }, /* 100 ns high, 20 ns setup */
};

static uint8_t cmd_set(uint8_t id, int32_t value)
{
  uint8_t err = settings_check_value(id, value);
  if (err) return err;
  settings_t t = cfg;
  t.v[id] = value;
  if ((err = settings_check_all(&t))) return err;
  cfg = t;
  save_settings();
  apply_settings();
  return 0;
}

static uint8_t busy(void) { return state == STATE_moving || state == STATE_homing; }

/* Execute one checked command; the reply text goes to reply[], its length is returned. */
static uint8_t execute(command_t *c, uint8_t *reboot)
{
  int32_t v = 0;
  int8_t id;
  uint8_t n;
  switch (c->verb) {
  case V_ID:
    n = begin_reply(c->seq, 0);
    n = proto_put_P(reply, n, REPLY_MAX, PSTR(" inkslice-stepper proto="));
    n = proto_put_i32(reply, n, REPLY_MAX, PROTO_VERSION);
    n = proto_put_P(reply, n, REPLY_MAX, PSTR(" fw=" FW_VERSION " reset="));
    n = proto_put_P(reply, n, REPLY_MAX, PGM_PTR(&proto_reset_names[reset_reason()]));
    n = proto_put_P(reply, n, REPLY_MAX, settings_defaulted ? PSTR(" settings=defaults") : PSTR(" settings=ok"));
    return n;
  case V_STATUS:
    n = begin_reply(c->seq, 0);
    reply[n++] = ' ';
    return put_status(reply, n);
  case V_HOME:
    if (busy()) return begin_reply(c->seq, ERR_busy);
    home_begin();
    return begin_reply(c->seq, 0);
  case V_MOVE:
    if (!proto_parse_i32(c->arg[0], &v)) return begin_reply(c->seq, ERR_bad_argument);
    if (busy()) return begin_reply(c->seq, ERR_busy);
    if (!homed) return begin_reply(c->seq, ERR_not_homed);
    if (v < cfg.v[SET_soft_min] || v > cfg.v[SET_soft_max]) return begin_reply(c->seq, ERR_soft_limit);
    target = v;
    if (v != stepper_position()) {
      state = STATE_moving;
      start_move(v, (uint32_t)cfg.v[SET_max_rate]);
    }
    return begin_reply(c->seq, 0);
  case V_STOP:
    raise_alarm(STATE_estop, ALARM_emergency_stop);
    return begin_reply(c->seq, 0);
  case V_GET:
    if ((id = settings_find(c->arg[0])) < 0) return begin_reply(c->seq, ERR_unknown_setting);
    n = begin_reply(c->seq, 0);
    reply[n++] = ' ';
    return proto_put_i32(reply, n, REPLY_MAX, cfg.v[id]);
  case V_SET:
    if ((id = settings_find(c->arg[0])) < 0) return begin_reply(c->seq, ERR_unknown_setting);
    if (!proto_parse_i32(c->arg[1], &v)) return begin_reply(c->seq, ERR_bad_argument);
    if (busy()) return begin_reply(c->seq, ERR_busy);
    return begin_reply(c->seq, cmd_set((uint8_t)id, v));
  case V_DRIVER:
    if (busy()) return begin_reply(c->seq, ERR_busy);
    for (uint8_t i = 0; i < sizeof drivers / sizeof drivers[0]; i++) {
      if (strcmp_P(c->arg[0], PGM_PTR(&drivers[i].name)) == 0) {
        uint8_t err = cmd_set(SET_pulse_us, pgm_read_byte(&drivers[i].pulse));
        if (!err) err = cmd_set(SET_dir_setup_us, pgm_read_byte(&drivers[i].setup));
        return begin_reply(c->seq, err);
      }
    }
    return begin_reply(c->seq, ERR_bad_argument);
  case V_DEFAULTS:
    if (busy()) return begin_reply(c->seq, ERR_busy);
    settings_defaults(&cfg);
    save_settings();
    apply_settings();
    return begin_reply(c->seq, 0);
  case V_REBOOT:
    *reboot = 1;
    return begin_reply(c->seq, 0);
  }
  return begin_reply(c->seq, ERR_unknown_command);
}

static void handle_line(char *text, uint8_t len)
{
  command_t c;
  uint8_t reboot = 0;
  if (len == 0) return; /* the host's leading '\n' */
  uint8_t err = proto_parse(text, len, &c);
  if (c.crc && c.seq && c.seq == last_seq && c.crc == last_crc) {
    serial_write(last_reply, last_reply_len); /* a resend: answer, do not execute */
    return;
  }
  uint8_t n = err ? begin_reply(c.seq, err) : execute(&c, &reboot);
  n = proto_seal(reply, n, REPLY_MAX);
  serial_write(reply, n);
  if (c.seq) { /* the line was intact: remember it */
    fresh = 0;
    last_seq = c.seq;
    last_crc = c.crc;
    memcpy(last_reply, reply, n);
    last_reply_len = n;
  }
  if (reboot) {
    serial_flush();
    _delay_ms(2);
    wdt_enable(WDTO_15MS);
    for (;;) {}
  }
}

/* The banner opens with a bare newline, as grbl's does: a reset can cut the
 * firmware off in the middle of a line, and without it the banner would run on
 * from that fragment into one line whose CRC fails, and the host would never
 * see the reset.  The host skips blank lines. */
static void banner(void)
{
  char b[64];
  serial_write("\n", 1);
  uint8_t n = proto_put_P(b, 0, sizeof b, PSTR("# inkslice-stepper proto="));
  n = proto_put_i32(b, n, sizeof b, PROTO_VERSION);
  n = proto_put_P(b, n, sizeof b, PSTR(" reset="));
  n = proto_put_P(b, n, sizeof b, PGM_PTR(&proto_reset_names[reset_reason()]));
  n = proto_seal(b, n, sizeof b);
  serial_write(b, n);
}

EMPTY_INTERRUPT(TIMER0_COMPA_vect);

int main(void)
{
  wdt_enable(WDTO_500MS);
  stepper_init();
  linebuf_init(&line);
  serial_init();
  /* Interrupts on before the slow part of the boot (the 64-bit ramp maths,
   * ~30 ms, and rewriting a damaged EEPROM image, ~200 ms): the receive
   * interrupt then keeps the 2-byte hardware buffer empty, and a command the
   * host sends meanwhile waits in the ring instead of being lost. */
  sei();
  load_settings();
  /* Timer0: a 100 Hz tick whose only job is to wake the loop to feed the
   * watchdog.  (Timer2 would do on the chip, but simavr 1.6 models its
   * asynchronous clock with a cycle timer every few cycles, which slows the
   * whole simulation a hundredfold.) */
  TCCR0A = _BV(WGM01);
  OCR0A = 155;
  TCCR0B = _BV(CS02) | _BV(CS00); /* clk/1024: 16 MHz / 1024 / 156 = 100.2 Hz */
  TIMSK0 = _BV(OCIE0A);
  set_sleep_mode(SLEEP_MODE_IDLE);
  banner();

  for (;;) {
    wdt_reset();
    uint8_t rt;
    cli();
    rt = rt_requests;
    rt_requests = 0;
    sei();
    if (rt & RT_REQ_ESTOP) raise_alarm(STATE_estop, ALARM_emergency_stop);
    motion_poll();
    if (rt & RT_REQ_STATUS) send_realtime_status();
    int16_t c;
    while ((c = serial_read()) >= 0) {
      uint8_t r = linebuf_feed(&line, (uint8_t)c);
      if (r == LB_LINE) {
        handle_line(line.buf, line.len);
        linebuf_init(&line);
        break;
      }
      if (r == LB_OVERFLOW) {
        uint8_t n = proto_seal(reply, begin_reply(0, ERR_line_too_long), REPLY_MAX);
        serial_write(reply, n);
        break;
      }
    }
    cli();
    if (!rt_requests && !serial_available() && (stepper_running || state == STATE_idle || state >= STATE_alarm)) {
      sleep_enable();
      sei();
      sleep_cpu();
      sleep_disable();
    }
    sei();
  }
}
