/* board.h -- pins of the ATmega328P (Arduino Uno / Nano footprint).
 *   STEP   PD4 (D4)     DIR   PD5 (D5)     ENABLE  PB0 (D8, active low)
 *   LIMIT  bottom/home PB1 (D9), top PB2 (D10): inputs with pull-ups,
 *          normally-open switches to ground, so pressed reads 0
 *          (setting invert bit 1 flips this for active-high switches).
 * STEP is deliberately not on PD2/PD3 (INT0/INT1): simavr 1.6 polls a
 * level-triggered external-interrupt pin on every cycle while it is low,
 * even with the interrupt masked, which slows the simulation 100-fold. */
#ifndef BOARD_H
#define BOARD_H
#define STEP_PORT PORTD
#define STEP_DDR DDRD
#define STEP_BIT 4
#define DIR_PORT PORTD
#define DIR_DDR DDRD
#define DIR_BIT 5
#define EN_PORT PORTB
#define EN_DDR DDRB
#define EN_BIT 0
#define LIMIT_PIN PINB
#define LIMIT_PORT PORTB
#define LIMIT_DDR DDRB
#define LIMIT_BOTTOM_BIT 1
#define LIMIT_TOP_BIT 2
#define BAUD 115200UL
#endif
