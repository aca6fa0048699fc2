/* crc.h -- CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection).
 *
 * One CRC for both jobs: protecting each protocol line (4 hex digits after
 * '*') and the settings block in EEPROM.  Chosen over CRC-8 because a scan
 * sends thousands of lines over a line that may drop bytes: a CRC-8 lets one
 * damaged line in 256 through, CRC-16 one in 65536, and it catches every
 * burst of up to 16 bits.  Python's binascii.crc_hqx(data, 0xFFFF) computes
 * the same value, so the host side needs no code of its own. */
#ifndef CRC_H
#define CRC_H
#include <stdint.h>
#include <stddef.h>

#define CRC16_INIT 0xFFFFu
uint16_t crc16_update(uint16_t crc, uint8_t byte);
uint16_t crc16(const void *data, size_t len);
#endif
