#ifndef SERIAL_H
#define SERIAL_H
#include <stdint.h>
void serial_init(void);
int16_t serial_read(void); /* -1 when nothing is waiting */
uint8_t serial_available(void);
void serial_write(const char *buf, uint8_t len);
void serial_flush(void);             /* wait until everything is on the wire */
extern volatile uint8_t rt_requests; /* RT_REQ_* set by the receive interrupt */
#define RT_REQ_STATUS 1
#define RT_REQ_ESTOP 2
#endif
