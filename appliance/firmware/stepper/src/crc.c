#include "crc.h"

/* Bitwise rather than a 512-byte table: flash and RAM matter more than the
 * ~100 cycles per byte, and lines are short. */
uint16_t crc16_update(uint16_t crc, uint8_t byte)
{
  crc ^= (uint16_t)byte << 8;
  for (uint8_t i = 0; i < 8; i++) crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
  return crc;
}

uint16_t crc16(const void *data, size_t len)
{
  const uint8_t *p = data;
  uint16_t crc = CRC16_INIT;
  while (len--) crc = crc16_update(crc, *p++);
  return crc;
}
