#include <string.h>
#include "protocol.h"
#include "crc.h"
#include "pgm.h"

void linebuf_init(linebuf_t *lb)
{
  lb->len = 0;
  lb->overflow = 0;
}

/* '\n' ends a line, '\r' is ignored (terminals send it).  Bytes past
 * LINE_MAX are thrown away and the line is reported as overflowed when its
 * '\n' finally arrives, so a runaway line costs one error reply, not a
 * buffer overrun.  Real-time bytes never reach here (serial.c takes them). */
uint8_t linebuf_feed(linebuf_t *lb, uint8_t c)
{
  if (c == '\r') return LB_NONE;
  if (c == '\n') {
    uint8_t over = lb->overflow;
    lb->buf[lb->len] = 0;
    lb->overflow = 0;
    if (over) {
      lb->len = 0;
      return LB_OVERFLOW;
    }
    return LB_LINE; /* caller reads buf/len, then calls linebuf_init */
  }
  if (lb->len >= LINE_MAX) {
    lb->overflow = 1;
    return LB_NONE;
  }
  lb->buf[lb->len++] = (char)c;
  return LB_NONE;
}

static int8_t hexval(char c)
{
  if (c >= '0' && c <= '9') return (int8_t)(c - '0');
  if (c >= 'A' && c <= 'F') return (int8_t)(c - 'A' + 10);
  if (c >= 'a' && c <= 'f') return (int8_t)(c - 'a' + 10);
  return -1;
}

uint8_t proto_parse_i32(const char *s, int32_t *out)
{
  uint8_t neg = 0;
  int64_t v = 0;
  if (*s == '-' || *s == '+') neg = (*s++ == '-');
  if (!*s) return 0;
  for (uint8_t n = 0; *s; s++, n++) {
    if (*s < '0' || *s > '9' || n >= 10) return 0;
    v = v * 10 + (*s - '0');
  }
  if (neg) v = -v;
  if (v < INT32_MIN || v > INT32_MAX) return 0;
  *out = (int32_t)v;
  return 1;
}

/* Verbs and how many arguments each takes, from codes.def: data, not code. */
#define VERB(name, args, text) static const char verb_##name[] PROGMEM = #name;
#include "../codes.def"
#undef VERB
#define VERB(name, args, text) verb_##name,
const char *const proto_verb_names[V_COUNT] PROGMEM = {
#include "../codes.def"
};
#undef VERB
#define VERB(name, args, text) args,
const uint8_t proto_verb_args[V_COUNT] PROGMEM = {
#include "../codes.def"
};
#undef VERB

/* The state and reset-reason words of status reports and ID, from codes.def. */
#define CODE(kind, num, name, text) CODE_##kind(num, name)
#define CODE_ERR(num, name)
#define CODE_FLAG(num, name)
#define CODE_ALARM(num, name)
#define CODE_STATE(num, name) static const char state_##name[] PROGMEM = #name;
#define CODE_RESET(num, name) static const char reset_##name[] PROGMEM = #name;
#include "../codes.def"
#undef CODE_STATE
#undef CODE_RESET
#define CODE_STATE(num, name) [num] = state_##name,
#define CODE_RESET(num, name)
const char *const proto_state_names[] PROGMEM = {
#include "../codes.def"
};
#undef CODE_STATE
#undef CODE_RESET
#define CODE_STATE(num, name)
#define CODE_RESET(num, name) [num] = reset_##name,
const char *const proto_reset_names[] PROGMEM = {
#include "../codes.def"
};
#undef CODE
#undef CODE_ERR
#undef CODE_FLAG
#undef CODE_ALARM
#undef CODE_STATE
#undef CODE_RESET

/* "<seq> <VERB> [arg [arg]]*XXXX": the checksum is checked first and
 * nothing else is trusted before it passes; only then is the seq believed. */
uint8_t proto_parse(char *line, uint8_t len, command_t *cmd)
{
  cmd->seq = 0;
  cmd->crc = 0;
  cmd->verb = V_COUNT;
  cmd->argc = 0;
  cmd->arg[0] = cmd->arg[1] = 0;
  if (len < 6 || line[len - 5] != '*') return ERR_bad_checksum;
  uint16_t want = 0;
  for (uint8_t i = len - 4; i < len; i++) {
    int8_t h = hexval(line[i]);
    if (h < 0) return ERR_bad_checksum;
    want = (uint16_t)((want << 4) | (uint8_t)h);
  }
  len -= 5;
  if (crc16(line, len) != want) return ERR_bad_checksum;
  line[len] = 0;
  cmd->crc = want;

  char *tok[4];
  uint8_t n = 0;
  for (char *p = line; *p;) {
    while (*p == ' ') *p++ = 0;
    if (!*p) break;
    if (n == 4) return ERR_bad_argument;
    tok[n++] = p;
    while (*p && *p != ' ') p++;
  }
  int32_t seq;
  if (n < 2 || !proto_parse_i32(tok[0], &seq) || seq < 1 || seq > 65535) return ERR_bad_syntax;
  cmd->seq = (uint16_t)seq;
  for (uint8_t v = 0; v < V_COUNT; v++) {
    if (strcmp_P(tok[1], PGM_PTR(&proto_verb_names[v])) == 0) {
      cmd->verb = v;
      break;
    }
  }
  if (cmd->verb == V_COUNT) return ERR_unknown_command;
  if (n - 2 != pgm_read_byte(&proto_verb_args[cmd->verb])) return ERR_bad_argument;
  cmd->argc = (uint8_t)(n - 2);
  for (uint8_t i = 0; i < cmd->argc; i++) cmd->arg[i] = tok[2 + i];
  return 0;
}

static const char hexdig[] PROGMEM = "0123456789ABCDEF";

uint8_t proto_seal(char *buf, uint8_t len, uint8_t cap)
{
  if ((uint16_t)len + 6 > cap) return 0;
  uint16_t crc = crc16(buf, len);
  buf[len++] = '*';
  for (int8_t sh = 12; sh >= 0; sh -= 4) buf[len++] = (char)pgm_read_byte(&hexdig[(crc >> sh) & 15]);
  buf[len++] = '\n';
  return len;
}

uint8_t proto_put_i32(char *buf, uint8_t len, uint8_t cap, int32_t v)
{
  char tmp[12];
  uint8_t n = 0;
  uint32_t u = v < 0 ? (uint32_t)0 - (uint32_t)v : (uint32_t)v;
  do {
    tmp[n++] = (char)('0' + u % 10);
    u /= 10;
  } while (u);
  if (v < 0) tmp[n++] = '-';
  while (n && len < cap) buf[len++] = tmp[--n];
  return len;
}

uint8_t proto_put_hex2(char *buf, uint8_t len, uint8_t cap, uint8_t v)
{
  if (len < cap) buf[len++] = (char)pgm_read_byte(&hexdig[v >> 4]);
  if (len < cap) buf[len++] = (char)pgm_read_byte(&hexdig[v & 15]);
  return len;
}

uint8_t proto_put_P(char *buf, uint8_t len, uint8_t cap, const char *s)
{
  char c;
  while ((c = (char)pgm_read_byte(s++)) != 0 && len < cap) buf[len++] = c;
  return len;
}
