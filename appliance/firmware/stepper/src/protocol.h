/* protocol.h -- the line protocol of PROTOCOL.md, without any hardware:
 * assembling bytes into lines, checking and splitting a line, formatting a
 * reply.  Pure C so the host unit tests and the fuzzer run exactly this code. */
#ifndef PROTOCOL_H
#define PROTOCOL_H
#include <stdint.h>
#include "codes.h"

/* PROTO_VERSION, LINE_MAX, the real-time bytes RT_* and enum verb come from codes.def (codes.h) */
#define REPLY_MAX 96 /* characters of a reply including "*XXXX\n" */

typedef struct {
  char buf[LINE_MAX + 1];
  uint8_t len;
  uint8_t overflow;
} linebuf_t;

enum { LB_NONE = 0, LB_LINE, LB_OVERFLOW };

typedef struct {
  uint16_t seq; /* 0 when the line could not be trusted */
  uint16_t crc; /* the line's checksum, part of the duplicate check */
  uint8_t verb;
  uint8_t argc;
  char *arg[2];
} command_t;

void linebuf_init(linebuf_t *lb);
uint8_t linebuf_feed(linebuf_t *lb, uint8_t c);               /* LB_*; LB_LINE: lb->buf holds it */
uint8_t proto_parse(char *line, uint8_t len, command_t *cmd); /* 0 or ERR_* */
uint8_t proto_parse_i32(const char *s, int32_t *out);         /* 1 when s is a whole int32 */
/* Append "*XXXX\n" (the CRC of buf[0..len)) and return the new length,
 * or 0 when it does not fit in cap bytes. */
uint8_t proto_seal(char *buf, uint8_t len, uint8_t cap);
/* Append a decimal / hex number / flash string; return the new length. */
uint8_t proto_put_i32(char *buf, uint8_t len, uint8_t cap, int32_t v);
uint8_t proto_put_hex2(char *buf, uint8_t len, uint8_t cap, uint8_t v);
uint8_t proto_put_P(char *buf, uint8_t len, uint8_t cap, const char *flash_str);
/* The verbs' names (in flash) and argument counts, indexed by enum verb. */
extern const char *const proto_verb_names[V_COUNT];
extern const uint8_t proto_verb_args[V_COUNT];
/* The state words (indexed by enum state_code) and reset reasons (enum reset_code), in flash. */
extern const char *const proto_state_names[];
extern const char *const proto_reset_names[];
#endif
