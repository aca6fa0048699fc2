/* fuzz_parser.c -- libFuzzer target: arbitrary bytes through the line
 * assembler, the parser and the reply formatter, exactly as the firmware's
 * main loop feeds them (real-time bytes excepted, which never reach here).
 * Invariants checked beyond "no crash, no sanitizer report": a line the
 * parser accepts really carries its CRC, and a sealed reply never exceeds
 * its buffer.  Also decodes the input as an EEPROM image. */
#include <stdint.h>
#include <stddef.h>
#include <string.h>
#include <stdlib.h>
#include "crc.h"
#include "protocol.h"
#include "settings.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
  linebuf_t lb;
  linebuf_init(&lb);
  for (size_t i = 0; i < size; i++) {
    uint8_t r = linebuf_feed(&lb, data[i]);
    if (r == LB_LINE) {
      char copy[LINE_MAX + 1];
      memcpy(copy, lb.buf, lb.len + 1);
      command_t c;
      uint8_t err = proto_parse(lb.buf, lb.len, &c);
      if (!err) {
        uint8_t body = (uint8_t)(lb.len - 5);
        if (crc16(copy, body) != c.crc || c.seq == 0 || c.verb >= V_COUNT) abort();
        for (uint8_t k = 0; k < c.argc; k++)
          if (c.arg[k] < lb.buf || c.arg[k] >= lb.buf + lb.len) abort();
      }
      char reply[REPLY_MAX];
      uint8_t n = proto_put_i32(reply, 0, REPLY_MAX, c.seq);
      n = proto_put_i32(reply, n, REPLY_MAX, (int32_t)err);
      if (c.argc)
        for (const char *p = c.arg[0]; *p && n < REPLY_MAX - 10; p++) reply[n++] = *p;
      uint8_t sealed = proto_seal(reply, n, REPLY_MAX);
      if (sealed > REPLY_MAX) abort();
      linebuf_init(&lb);
    }
  }
  if (size >= SETTINGS_BLOB_SIZE) {
    settings_t s;
    if (settings_decode(data, &s) == SETTINGS_OK && settings_check_all(&s)) abort();
  }
  return 0;
}
