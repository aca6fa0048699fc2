/* settings.h -- the controller's settings and their EEPROM image.
 *
 * The EEPROM image is:  magic (0xA5), layout version, value count,
 * count x int32 little-endian, CRC-16 of everything before it.
 * A blank chip (all 0xFF), a half-written block (power lost during SET), a
 * firmware with a different layout: all fail the magic/version/count/CRC
 * check, and the controller then boots on the defaults, writes them back and
 * raises the settings_defaulted flag so the host knows its tuning is gone.
 * Every value is also range-checked on load, so a CRC collision cannot feed
 * the planner an impossible number. */
#ifndef SETTINGS_H
#define SETTINGS_H
#include <stdint.h>
#include "codes.h"

#define SETTINGS_MAGIC 0xA5
#define SETTINGS_LAYOUT 1
#define SETTINGS_BLOB_SIZE (3 + 4 * SETTING_COUNT + 2)

typedef struct {
  int32_t v[SETTING_COUNT];
} settings_t;

enum settings_load { SETTINGS_OK = 0, SETTINGS_BAD_HEADER, SETTINGS_BAD_CRC, SETTINGS_BAD_VALUE };

void settings_defaults(settings_t *s);
void settings_encode(const settings_t *s, uint8_t *blob);
uint8_t settings_decode(const uint8_t *blob, settings_t *s); /* enum settings_load */
int8_t settings_find(const char *name);                      /* id or -1 */
const char *settings_name(uint8_t id);                       /* flash pointer on AVR */
uint8_t settings_check_value(uint8_t id, int32_t value);     /* 0 or ERR_* */
uint8_t settings_check_all(const settings_t *s);             /* 0 or ERR_* */
#endif
