/* pgm.h -- constant tables in flash on the AVR, in ordinary memory on the host,
 * so the same sources build for both (the host build runs the unit tests and
 * the fuzzer). */
#ifndef PGM_H
#define PGM_H
#ifdef __AVR__
#include <avr/pgmspace.h>
#define PGM_I32(p) ((int32_t)pgm_read_dword(p))
#define PGM_PTR(p) ((const char *)pgm_read_word(p))
#else
#include <string.h>
#define PROGMEM
#define PSTR(s) (s)
#define PGM_I32(p) (*(p))
#define PGM_PTR(p) (*(p))
#define pgm_read_byte(p) (*(const uint8_t *)(p))
#define strcmp_P strcmp
#define strcpy_P strcpy
#define strlen_P strlen
#endif
#endif
