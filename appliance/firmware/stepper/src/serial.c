/* serial.c -- interrupt-driven UART with ring buffers, in grbl's manner.
 *
 * The real chip buffers 2 received bytes; at 115200 baud a byte arrives every
 * 87 us, so anything that keeps the receive interrupt waiting longer than
 * ~170 us loses data.  The receive interrupt therefore does the least it can:
 * it takes the byte, and either acts on it at once (the two real-time bytes,
 * which must work even when the line buffer is full or the main loop is
 * busy) or appends it to a 64-byte ring.  The protocol is strict
 * request/response with lines of at most 48 characters, so a well-behaved
 * host can never overrun the ring.
 *
 * The emergency stop is executed right here, inside the interrupt, by
 * stopping the step timer: the motor halts before the next step is due,
 * whatever the main loop is doing.  The main loop only records the state. */
#include <avr/io.h>
#include <avr/interrupt.h>
#include <util/delay.h>
#include "serial.h"
#include "board.h"
#include "uart_math.h"
#include "protocol.h"
#include "stepper.h"

#define RX_SIZE 64
#define TX_SIZE 128
static volatile uint8_t rx_buf[RX_SIZE], rx_head, rx_tail;
static volatile uint8_t tx_buf[TX_SIZE], tx_head, tx_tail;
volatile uint8_t rt_requests;

void serial_init(void)
{
  /* U2X0 before UBRR0: simavr derives its byte time when UBRR0L is written */
  UCSR0A = _BV(U2X0);
  uint16_t ubrr = ubrr_u2x(F_CPU, BAUD);
  UBRR0H = (uint8_t)(ubrr >> 8);
  UBRR0L = (uint8_t)ubrr;
  UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
  UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

ISR(USART_RX_vect)
{
  uint8_t c = UDR0;
#ifdef TEST_SLOW_RX_US
  /* test builds only (make slow-rx): a receive interrupt too slow for the
   * line, to prove the simavr bench notices the overruns it would cause */
  _delay_us(TEST_SLOW_RX_US);
#endif
  if (c == RT_ESTOP) {
    stepper_halt_now();
    rt_requests |= RT_REQ_ESTOP;
    return;
  }
  if (c == RT_STATUS) {
    rt_requests |= RT_REQ_STATUS;
    return;
  }
  uint8_t h = rx_head, next = (uint8_t)((h + 1) & (RX_SIZE - 1));
  if (next != rx_tail) {
    rx_buf[h] = c;
    rx_head = next;
  }
  /* else: dropped; the line's checksum will fail and the host resends */
}

ISR(USART_UDRE_vect)
{
  uint8_t t = tx_tail;
  UDR0 = tx_buf[t];
  t = (uint8_t)((t + 1) & (TX_SIZE - 1));
  tx_tail = t;
  if (t == tx_head) UCSR0B &= (uint8_t)~_BV(UDRIE0);
}

uint8_t serial_available(void) { return rx_head != rx_tail; }

int16_t serial_read(void)
{
  uint8_t t = rx_tail;
  if (t == rx_head) return -1;
  uint8_t c = rx_buf[t];
  rx_tail = (uint8_t)((t + 1) & (RX_SIZE - 1));
  return c;
}

void serial_write(const char *buf, uint8_t len)
{
  while (len--) {
    uint8_t h = tx_head, next = (uint8_t)((h + 1) & (TX_SIZE - 1));
    while (next == tx_tail) continue; /* full: the UDRE interrupt drains it */
    tx_buf[h] = (uint8_t)*buf++;
    tx_head = next;
    UCSR0B |= _BV(UDRIE0);
  }
}

void serial_flush(void)
{
  while (tx_head != tx_tail) {}
  while (!(UCSR0A & _BV(TXC0)) && (UCSR0B & _BV(TXEN0))) {
    if (UCSR0A & _BV(UDRE0)) break;
  }
}
