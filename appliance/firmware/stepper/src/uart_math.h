/* uart_math.h -- UBRR for a baud rate.  simavr ignores the baud rate on a pty,
 * so a wrong divider would never show in simulation: the host unit tests
 * check this arithmetic against the datasheet's table instead. */
#ifndef UART_MATH_H
#define UART_MATH_H
#include <stdint.h>
/* with U2X (8 samples per bit): UBRR = round(f / (8 baud)) - 1 */
static inline uint16_t ubrr_u2x(uint32_t f_cpu, uint32_t baud)
{
  return (uint16_t)((f_cpu + 4 * baud) / (8 * baud) - 1);
}
/* actual baud rate for a divider, to bound the error */
static inline uint32_t baud_of_ubrr_u2x(uint32_t f_cpu, uint16_t ubrr) { return f_cpu / (8UL * (ubrr + 1UL)); }
#endif
