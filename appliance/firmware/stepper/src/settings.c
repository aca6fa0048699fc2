#include <string.h>
#include "settings.h"
#include "crc.h"
#include "pgm.h"

/* Defaults, bounds and names come from ../codes.def, the table the Python
 * driver reads too, so the two sides cannot disagree on a range. */
#define SETTING(num, name, dflt, lo, hi, text) dflt,
static const int32_t defaults[SETTING_COUNT] PROGMEM = {
#include "../codes.def"
};
#undef SETTING
#define SETTING(num, name, dflt, lo, hi, text) lo,
static const int32_t lows[SETTING_COUNT] PROGMEM = {
#include "../codes.def"
};
#undef SETTING
#define SETTING(num, name, dflt, lo, hi, text) hi,
static const int32_t highs[SETTING_COUNT] PROGMEM = {
#include "../codes.def"
};
#undef SETTING
#define SETTING(num, name, dflt, lo, hi, text) static const char name_##name[] PROGMEM = #name;
#include "../codes.def"
#undef SETTING
#define SETTING(num, name, dflt, lo, hi, text) name_##name,
static const char *const names[SETTING_COUNT] PROGMEM = {
#include "../codes.def"
};
#undef SETTING

void settings_defaults(settings_t *s)
{
  for (uint8_t i = 0; i < SETTING_COUNT; i++) s->v[i] = PGM_I32(&defaults[i]);
}

void settings_encode(const settings_t *s, uint8_t *blob)
{
  blob[0] = SETTINGS_MAGIC;
  blob[1] = SETTINGS_LAYOUT;
  blob[2] = SETTING_COUNT;
  for (uint8_t i = 0; i < SETTING_COUNT; i++) {
    uint32_t u = (uint32_t)s->v[i];
    for (uint8_t b = 0; b < 4; b++) blob[3 + 4 * i + b] = (uint8_t)(u >> (8 * b));
  }
  uint16_t crc = crc16(blob, SETTINGS_BLOB_SIZE - 2);
  blob[SETTINGS_BLOB_SIZE - 2] = (uint8_t)crc;
  blob[SETTINGS_BLOB_SIZE - 1] = (uint8_t)(crc >> 8);
}

uint8_t settings_decode(const uint8_t *blob, settings_t *s)
{
  if (blob[0] != SETTINGS_MAGIC || blob[1] != SETTINGS_LAYOUT || blob[2] != SETTING_COUNT) return SETTINGS_BAD_HEADER;
  uint16_t crc = crc16(blob, SETTINGS_BLOB_SIZE - 2);
  if ((uint8_t)crc != blob[SETTINGS_BLOB_SIZE - 2] || (uint8_t)(crc >> 8) != blob[SETTINGS_BLOB_SIZE - 1])
    return SETTINGS_BAD_CRC;
  settings_t t;
  for (uint8_t i = 0; i < SETTING_COUNT; i++) {
    uint32_t u = 0;
    for (uint8_t b = 0; b < 4; b++) u |= (uint32_t)blob[3 + 4 * i + b] << (8 * b);
    t.v[i] = (int32_t)u;
    if (settings_check_value(i, t.v[i])) return SETTINGS_BAD_VALUE;
  }
  if (settings_check_all(&t)) return SETTINGS_BAD_VALUE;
  *s = t;
  return SETTINGS_OK;
}

int8_t settings_find(const char *name)
{
  for (uint8_t i = 0; i < SETTING_COUNT; i++)
    if (strcmp_P(name, PGM_PTR(&names[i])) == 0) return (int8_t)i;
  return -1;
}

const char *settings_name(uint8_t id) { return PGM_PTR(&names[id]); }

uint8_t settings_check_value(uint8_t id, int32_t value)
{
  if (id >= SETTING_COUNT) return ERR_unknown_setting;
  if (value < PGM_I32(&lows[id]) || value > PGM_I32(&highs[id])) return ERR_setting_out_of_range;
  return 0;
}

/* Relations between settings: a soft-limit window must have room, and the
 * homing rates may not exceed the MOVE rate the ramp table is built for. */
uint8_t settings_check_all(const settings_t *s)
{
  if (s->v[SET_soft_min] >= s->v[SET_soft_max]) return ERR_settings_inconsistent;
  if (s->v[SET_home_fast] > s->v[SET_max_rate] || s->v[SET_home_slow] > s->v[SET_max_rate])
    return ERR_settings_inconsistent;
  return 0;
}
