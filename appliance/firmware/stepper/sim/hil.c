/* hil.c -- the hardware-in-the-loop bench: the real firmware ELF on simavr.
 *
 *   hil FIRMWARE.elf [--speed X] [--stage STEPS] [--seed N] [--top-switch STEPS]
 *
 * What it simulates
 *   - the ATmega328P at 16 MHz running the unmodified firmware;
 *   - its UART, bridged to a pseudo-terminal whose path is printed at start
 *     ("port /dev/pts/N"): pyserial opens it like a USB-serial adapter;
 *   - the lifting stage: every STEP rising edge moves it one step in the
 *     direction DIR shows, between mechanical end stops (steps driven into an
 *     end stop are lost, and counted as stalls);
 *   - the two limit switches, closed (pin low) at and beyond their trigger
 *     points: bottom at position <= 0, top at position >= --top-switch;
 *   - the wire's pace and the chip's 2-byte receive buffer: bytes are fed
 *     one frame apart, and a byte that would have overrun the real buffer
 *     is counted (rx_overruns), since simavr's own 64-byte FIFO hides it;
 *   - faults on the wire, by rate, each direction: dropped, corrupted (one
 *     byte XOR a random non-zero value) and duplicated bytes; and resets of
 *     the MCU (the reset pin), which keep EEPROM like the real chip.
 *
 * Positions are in steps in the firmware's own frame (0 = where the home
 * switch closes), so "commanded position == counted steps" is a direct
 * comparison.  Every STEP/DIR edge can be logged with its simulated cycle
 * (16 per microsecond) for the timing benches.
 *
 * Control: one command per line on stdin, one reply line on stdout.
 *   pos                      -> pos <steps> <cycle>
 *   stage <steps>            place the stage (before homing)
 *   fault <rx|tx> <drop|corrupt|dup> <ppm>   rx = host to MCU
 *   seed <n>                 seed of the fault generator
 *   reset                    pulse the MCU's reset line
 *   record <path> | record off   log edges: 16-byte records
 *                            (u64 cycle, u8 pin 0=STEP 1=DIR, u8 level, 6 pad)
 *   stats                    counters, key=value
 *   speed <x>                simulated seconds per real second, 0 = flat out
 *   eeprom <addr> [<value>]  read or write one EEPROM byte
 *   quit
 *
 * Time.  simavr advances its cycle counter instantly while the firmware
 * sleeps; the default sleep callback then usleeps to stay near real time.
 * This bench replaces it with its own pacing: simulated time is held at
 * `speed` times wall time by waiting in select() on the pty and stdin, so a
 * byte from the host ends the wait at once.  speed 0 never waits: the
 * simulation runs as fast as the host CPU allows (10x or more while the
 * firmware sleeps), which is what the soak test and the benches use.
 *
 * Exit: stdin closing or "quit" ends the process with _exit(), because
 * simavr's own teardown can hang. */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/select.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "sim_avr.h"
#include "sim_elf.h"
#include "sim_irq.h"
#include "sim_io.h"
#include "avr_ioport.h"
#include "avr_uart.h"
#include "avr_eeprom.h"

#define F_CPU 16000000ULL
#define STEP_PORT 'B'
#define STEP_PIN 1
#define DIR_PORT 'D'
#define DIR_PIN 5
#define LIMIT_PORT 'C'
#define LIM_BOTTOM_PIN 0
#define LIM_TOP_PIN 1
#define POLL_CYCLES 4000 /* check the pty and stdin every 250 us of simulated time */

static avr_t *avr;
static int pty_master = -1, pty_slave = -1;
static double speed = 1.0;
static double pace_wall0;
static uint64_t pace_cycle0;

/* the stage */
static int64_t stage_pos = 64000;   /* 40 mm at 1600 steps/mm */
static int64_t top_switch = 156800; /* 98 mm */
static int64_t mech_min = -3200, mech_max = 160000;
static int dir_level, step_level;
static uint64_t steps_up, steps_down, stalls;
static uint64_t last_step_cycle, last_dir_cycle, last_rise_cycle;
static uint64_t min_pulse = UINT64_MAX, min_dir_setup = UINT64_MAX;
static int dir_changed_since_step;
static avr_irq_t *irq_lim_bottom, *irq_lim_top, *irq_uart_in;
static int lim_bottom_level = -1, lim_top_level = -1;
static FILE *rec;
static FILE *ctl_out; /* our stdout; simavr's chatter goes to stderr */

/* the wire */
static uint32_t rate[2][3]; /* [rx/tx][drop/corrupt/dup] in ppm */
static uint64_t count[2][3], bytes[2];
static uint64_t rng = 0x9E3779B97F4A7C15ULL;
static uint8_t inq[4096];
static size_t inq_head, inq_len;
static int uart_xoff;
static avr_uart_t *uart0; /* simavr's UART, to see its receive FIFO */
static uint64_t next_feed_cycle, rx_overruns;
static uint64_t estop_feed_cycle, resets;

static double wall_now(void)
{
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static uint64_t rand64(void)
{
  rng ^= rng << 13;
  rng ^= rng >> 7;
  rng ^= rng << 17;
  return rng;
}

/* ---- limit switches: pressed pulls the pin low ---- */
static void update_limits(void)
{
  int b = stage_pos <= 0 ? 0 : 1, t = stage_pos >= top_switch ? 0 : 1;
  if (b != lim_bottom_level) {
    lim_bottom_level = b;
    avr_raise_irq(irq_lim_bottom, b);
  }
  if (t != lim_top_level) {
    lim_top_level = t;
    avr_raise_irq(irq_lim_top, t);
  }
}

static void record(uint8_t pin, uint8_t level)
{
  if (!rec) return;
  uint8_t r[16] = { 0 };
  uint64_t c = avr->cycle;
  memcpy(r, &c, 8);
  r[8] = pin;
  r[9] = level;
  fwrite(r, 1, 16, rec);
}

static void on_step(struct avr_irq_t *irq, uint32_t value, void *param)
{
  (void)irq;
  (void)param;
  int v = value ? 1 : 0;
  if (v == step_level) return;
  step_level = v;
  record(0, (uint8_t)v);
  if (v) {
    last_rise_cycle = avr->cycle;
    if (dir_changed_since_step) {
      uint64_t setup = avr->cycle - last_dir_cycle;
      if (setup < min_dir_setup) min_dir_setup = setup;
      dir_changed_since_step = 0;
    }
    int64_t next = stage_pos + (dir_level ? 1 : -1);
    if (next < mech_min || next > mech_max) stalls++;
    else stage_pos = next;
    if (dir_level) steps_up++;
    else steps_down++;
    last_step_cycle = avr->cycle;
    update_limits();
  } else {
    uint64_t w = avr->cycle - last_rise_cycle;
    if (w < min_pulse) min_pulse = w;
  }
}

static void on_dir(struct avr_irq_t *irq, uint32_t value, void *param)
{
  (void)irq;
  (void)param;
  int v = value ? 1 : 0;
  if (v == dir_level) return;
  dir_level = v;
  last_dir_cycle = avr->cycle;
  dir_changed_since_step = 1;
  record(1, (uint8_t)v);
}

/* ---- the wire, with faults.  Index 0 = rx (host to MCU), 1 = tx. ---- */
enum { F_DROP, F_CORRUPT, F_DUP };

/* how many copies of the byte reach the other end (0, 1 or 2); may alter *c */
static int wire(int dirn, uint8_t *c)
{
  bytes[dirn]++;
  uint32_t r = (uint32_t)(rand64() % 1000000);
  uint32_t d = rate[dirn][F_DROP], k = d + rate[dirn][F_CORRUPT], u = k + rate[dirn][F_DUP];
  if (r < d) {
    count[dirn][F_DROP]++;
    return 0;
  }
  if (r < k) {
    count[dirn][F_CORRUPT]++;
    *c ^= (uint8_t)(1 + rand64() % 255);
    return 1;
  }
  if (r < u) {
    count[dirn][F_DUP]++;
    return 2;
  }
  return 1;
}

static void on_uart_out(struct avr_irq_t *irq, uint32_t value, void *param)
{
  (void)irq;
  (void)param;
  uint8_t c = (uint8_t)value;
  int n = wire(1, &c);
  for (int i = 0; i < n; i++) {
    ssize_t sent = write(pty_master, &c, 1); /* nobody listening: lost, like a byte on a wire */
    (void)sent;
  }
}

static void on_xon(struct avr_irq_t *irq, uint32_t value, void *param)
{
  (void)irq;
  (void)value;
  (void)param;
  uart_xoff = 0;
}
static void on_xoff(struct avr_irq_t *irq, uint32_t value, void *param)
{
  (void)irq;
  (void)value;
  (void)param;
  uart_xoff = 1;
}

/* The wire delivers one byte per frame time, and the real chip holds at most
 * two received bytes (UDR0 and one more) while a third shifts in.  simavr's
 * UART would buffer 64, hiding a firmware that reads too slowly.  So bytes
 * are fed one frame apart, and a byte that completes while three are still
 * unread in simavr's FIFO is counted as an overrun: on the chip it would be
 * lost (DOR).  rx_overruns must stay 0. */
static uint64_t frame_cycles(void)
{
  return uart0 && uart0->cycles_per_byte ? uart0->cycles_per_byte : F_CPU * 10 / 115200;
}

static unsigned unread_bytes(void)
{
  return (unsigned)(uart0->input.write - uart0->input.read) & (uart_fifo_fifo_size - 1);
}

static int dup_pending = -1; /* a duplicated byte, due one frame later */

static void feed_uart(void)
{
  if (avr->cycle < next_feed_cycle || uart_xoff) return;
  if (!inq_len && dup_pending < 0) return;
  if (uart0 && unread_bytes() >= 3) rx_overruns++;
  next_feed_cycle = avr->cycle + frame_cycles();
  uint8_t c;
  if (dup_pending >= 0) { /* the copy takes its own frame on the wire */
    c = (uint8_t)dup_pending;
    dup_pending = -1;
  } else {
    c = inq[inq_head];
    inq_head = (inq_head + 1) % sizeof inq;
    inq_len--;
    int n = wire(0, &c);
    if (n == 0) return;
    if (n == 2) dup_pending = c;
  }
  if (c == 0x18) estop_feed_cycle = avr->cycle;
  avr_raise_irq(irq_uart_in, c);
}

static void read_pty(void)
{
  uint8_t buf[256];
  size_t room = sizeof inq - inq_len;
  if (room > sizeof buf) room = sizeof buf;
  if (!room) return;
  ssize_t n = read(pty_master, buf, room);
  for (ssize_t i = 0; i < n; i++) inq[(inq_head + inq_len++) % sizeof inq] = buf[i];
}

/* ---- control ---- */
static void reply(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
static void reply(const char *fmt, ...)
{
  va_list ap;
  va_start(ap, fmt);
  vfprintf(ctl_out, fmt, ap);
  va_end(ap);
  fputc('\n', ctl_out);
  fflush(ctl_out);
}

static void mcu_reset(void)
{
  avr_reset(avr);
  /* simavr leaves MCUSR's reset-cause flags to the caller: this was the reset pin */
  avr_regbit_setto(avr, avr->reset_flags.extrf, 1);
  /* the reset cleared the port's input latches, but simavr only passes an
   * IRQ on when its value changes: wiggle both switch lines so the pins
   * read the switches again (the firmware is not running yet) */
  avr_raise_irq(irq_lim_bottom, !lim_bottom_level);
  avr_raise_irq(irq_lim_top, !lim_top_level);
  lim_bottom_level = lim_top_level = -1;
  update_limits();
  resets++;
}

static void eeprom_rw(int addr, int value)
{
  avr_eeprom_desc_t d = { .ee = NULL, .offset = (uint16_t)addr, .size = 1 };
  if (addr < 0 || addr >= 1024) {
    reply("err eeprom address %d outside 0..1023", addr);
    return;
  }
  if (value >= 0) {
    uint8_t b = (uint8_t)value;
    d.ee = &b;
    avr_ioctl(avr, AVR_IOCTL_EEPROM_SET, &d);
    reply("ok");
  } else {
    avr_ioctl(avr, AVR_IOCTL_EEPROM_GET, &d);
    reply("eeprom %d %d", addr, d.ee ? d.ee[0] : -1);
  }
}

static void control(char *line)
{
  char a[256] = "", b[64] = "";
  long long n = 0;
  int args = sscanf(line, "%255s %63s %lld", a, b, &n);
  if (args <= 0) return;
  if (!strcmp(a, "pos")) {
    reply("pos %lld %llu", (long long)stage_pos, (unsigned long long)avr->cycle);
  } else if (!strcmp(a, "stage") && args >= 2) {
    stage_pos = atoll(b);
    update_limits();
    reply("ok");
  } else if (!strcmp(a, "fault") && args >= 2) {
    int d = !strcmp(a, "fault") && !strcmp(b, "rx") ? 0 : !strcmp(b, "tx") ? 1 : -1;
    char kind[32] = "";
    unsigned long ppm = 0;
    if (d < 0 || sscanf(line, "%*s %*s %31s %lu", kind, &ppm) != 2) {
      reply("err fault: want fault <rx|tx> <drop|corrupt|dup> <ppm>");
      return;
    }
    int k = !strcmp(kind, "drop") ? F_DROP : !strcmp(kind, "corrupt") ? F_CORRUPT : !strcmp(kind, "dup") ? F_DUP : -1;
    if (k < 0 || ppm > 1000000) {
      reply("err fault: unknown kind '%s' or ppm > 1000000", kind);
      return;
    }
    rate[d][k] = (uint32_t)ppm;
    reply("ok");
  } else if (!strcmp(a, "seed") && args >= 2) {
    rng = (uint64_t)atoll(b) * 0x9E3779B97F4A7C15ULL + 1;
    reply("ok");
  } else if (!strcmp(a, "reset")) {
    mcu_reset();
    reply("ok %llu", (unsigned long long)avr->cycle);
  } else if (!strcmp(a, "record") && args >= 2) {
    if (rec) {
      fclose(rec);
      rec = NULL;
    }
    if (strcmp(b, "off")) {
      char path[256];
      if (sscanf(line, "%*s %255s", path) != 1 || !(rec = fopen(path, "wb"))) {
        reply("err record: cannot open %s: %s", b, strerror(errno));
        return;
      }
    }
    reply("ok");
  } else if (!strcmp(a, "stats")) {
    reply("stats cycle=%llu pos=%lld steps_up=%llu steps_down=%llu stalls=%llu "
          "min_pulse_cycles=%lld min_dir_setup_cycles=%lld last_step_cycle=%llu estop_feed_cycle=%llu "
          "rx_bytes=%llu rx_dropped=%llu rx_corrupted=%llu rx_duplicated=%llu "
          "tx_bytes=%llu tx_dropped=%llu tx_corrupted=%llu tx_duplicated=%llu resets=%llu "
          "limit_bottom=%d limit_top=%d rx_overruns=%llu",
          (unsigned long long)avr->cycle, (long long)stage_pos, (unsigned long long)steps_up,
          (unsigned long long)steps_down, (unsigned long long)stalls,
          min_pulse == UINT64_MAX ? -1LL : (long long)min_pulse,
          min_dir_setup == UINT64_MAX ? -1LL : (long long)min_dir_setup, (unsigned long long)last_step_cycle,
          (unsigned long long)estop_feed_cycle, (unsigned long long)bytes[0], (unsigned long long)count[0][F_DROP],
          (unsigned long long)count[0][F_CORRUPT], (unsigned long long)count[0][F_DUP], (unsigned long long)bytes[1],
          (unsigned long long)count[1][F_DROP], (unsigned long long)count[1][F_CORRUPT],
          (unsigned long long)count[1][F_DUP], (unsigned long long)resets, !lim_bottom_level, !lim_top_level,
          (unsigned long long)rx_overruns);
  } else if (!strcmp(a, "speed") && args >= 2) {
    speed = atof(b);
    pace_wall0 = wall_now();
    pace_cycle0 = avr->cycle;
    reply("ok");
  } else if (!strcmp(a, "eeprom") && args >= 2) {
    eeprom_rw(atoi(b), args >= 3 ? (int)n : -1);
  } else if (!strcmp(a, "quit")) {
    fflush(rec);
    _exit(0);
  } else {
    reply("err unknown control command '%s'", a);
  }
}

static char ctl_buf[1024];
static size_t ctl_len;

static void read_control(void)
{
  ssize_t n = read(0, ctl_buf + ctl_len, sizeof ctl_buf - 1 - ctl_len);
  if (n <= 0) {
    if (rec) fflush(rec);
    _exit(0);
  } /* the parent is gone */
  ctl_len += (size_t)n;
  char *nl;
  while ((nl = memchr(ctl_buf, '\n', ctl_len))) {
    *nl = 0;
    control(ctl_buf);
    size_t used = (size_t)(nl - ctl_buf) + 1;
    memmove(ctl_buf, nl + 1, ctl_len - used);
    ctl_len -= used;
  }
  if (ctl_len == sizeof ctl_buf - 1) ctl_len = 0;
}

/* Wait for input up to `timeout` seconds; handle whatever arrived. */
static void poll_io(double timeout)
{
  fd_set rd;
  FD_ZERO(&rd);
  FD_SET(0, &rd);
  FD_SET(pty_master, &rd);
  struct timeval tv = { (time_t)timeout, (suseconds_t)((timeout - (time_t)timeout) * 1e6) };
  int n = select(pty_master + 1, &rd, NULL, NULL, &tv);
  if (n > 0) {
    if (FD_ISSET(pty_master, &rd)) read_pty();
    if (FD_ISSET(0, &rd)) read_control();
  }
  feed_uart();
}

static void pace(void)
{
  if (speed <= 0) {
    poll_io(0);
    return;
  }
  double ahead = pace_wall0 + (double)(avr->cycle - pace_cycle0) / (double)F_CPU / speed - wall_now();
  if (ahead > 0.010) ahead = 0.010;
  poll_io(ahead > 0.0002 ? ahead : 0);
  if (ahead < -0.5) {
    pace_wall0 = wall_now();
    pace_cycle0 = avr->cycle;
  } /* fell behind: do not sprint */
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long)
{
  (void)a;
  (void)how_long;
}

static int open_pty(void)
{
  pty_master = posix_openpt(O_RDWR | O_NOCTTY);
  if (pty_master < 0 || grantpt(pty_master) || unlockpt(pty_master)) return -1;
  const char *name = ptsname(pty_master);
  /* keep a slave descriptor open ourselves: without one, the master reads
   * EIO whenever the host closes its side */
  pty_slave = open(name, O_RDWR | O_NOCTTY);
  if (pty_slave < 0) return -1;
  struct termios t;
  tcgetattr(pty_slave, &t);
  cfmakeraw(&t);
  tcsetattr(pty_slave, TCSANOW, &t);
  fcntl(pty_master, F_SETFL, O_NONBLOCK);
  reply("port %s", name);
  return 0;
}

int main(int argc, char **argv)
{
  if (argc < 2) {
    fprintf(stderr, "usage: hil FIRMWARE.elf [--speed X] [--stage STEPS] [--seed N]\n");
    return 2;
  }
  for (int i = 2; i + 1 < argc; i += 2) {
    if (!strcmp(argv[i], "--speed")) speed = atof(argv[i + 1]);
    else if (!strcmp(argv[i], "--stage")) stage_pos = atoll(argv[i + 1]);
    else if (!strcmp(argv[i], "--seed")) rng = (uint64_t)atoll(argv[i + 1]) * 0x9E3779B97F4A7C15ULL + 1;
    else if (!strcmp(argv[i], "--top-switch")) top_switch = atoll(argv[i + 1]);
    else {
      fprintf(stderr, "hil: unknown option %s\n", argv[i]);
      return 2;
    }
  }
  ctl_out = fdopen(dup(1), "w");
  dup2(2, 1);
  elf_firmware_t fw;
  memset(&fw, 0, sizeof fw);
  if (elf_read_firmware(argv[1], &fw)) {
    fprintf(stderr, "hil: cannot read firmware %s\n", argv[1]);
    return 2;
  }
  avr = avr_make_mcu_by_name("atmega328p");
  if (!avr) {
    fprintf(stderr, "hil: simavr has no atmega328p\n");
    return 2;
  }
  avr_init(avr);
  avr->log = 0;
  avr->frequency = (uint32_t)F_CPU;
  avr_load_firmware(avr, &fw);
  avr->frequency = (uint32_t)F_CPU;
  avr->sleep = no_sleep;
  avr_regbit_setto(avr, avr->reset_flags.porf, 1);

  irq_lim_bottom = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(LIMIT_PORT), LIM_BOTTOM_PIN);
  irq_lim_top = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(LIMIT_PORT), LIM_TOP_PIN);
  irq_uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(STEP_PORT), STEP_PIN), on_step, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(DIR_PORT), DIR_PIN), on_dir, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), on_uart_out, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), on_xon, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), on_xoff, NULL);
  /* simavr's UART would otherwise wait for the XON of a pty part */
  uint32_t flags = 0;
  avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
  flags &= ~AVR_UART_FLAG_STDIO;
  avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  for (avr_io_t *io = avr->io_port; io; io = io->next)
    if (io->kind && !strcmp(io->kind, "uart") && ((avr_uart_t *)io)->name == '0') uart0 = (avr_uart_t *)io;
  if (!uart0) fprintf(stderr, "hil: simavr's UART0 not found: overruns will not be detected\n");
  update_limits();

  if (open_pty()) {
    fprintf(stderr, "hil: cannot open a pty: %s\n", strerror(errno));
    return 2;
  }
  pace_wall0 = wall_now();
  pace_cycle0 = avr->cycle;
  uint64_t next_poll = 0;
  for (;;) {
    int st = avr_run(avr);
    if (st == cpu_Done || st == cpu_Crashed) {
      reply("crashed state=%d pc=0x%x cycle=%llu", st, avr->pc, (unsigned long long)avr->cycle);
      fflush(rec);
      _exit(3);
    }
    if (avr->cycle >= next_poll) {
      pace();
      /* while bytes wait for the wire, come back once per frame */
      next_poll =
          avr->cycle + ((inq_len || dup_pending >= 0) && frame_cycles() < POLL_CYCLES ? frame_cycles() : POLL_CYCLES);
    }
  }
}
