/* board.h -- pins of the ATmega328P (Arduino Uno / Nano footprint).
 *   STEP   PB1 (D9)  = OC1A: the STEP edges are made by Timer1's output-compare
 *                     hardware, not by software (see stepper.c)
 *   DIR    PD5 (D5)     ENABLE  PB0 (D8, active low)
 *   LIMIT  bottom/home PC0 (A0), top PC1 (A1): inputs with pull-ups,
 *          normally-open switches to ground, so pressed reads 0
 *          (setting invert bit 1 flips this for active-high switches).
 * Nothing sits on PD2/PD3 (INT0/INT1): simavr 1.6 polls a level-triggered
 * external-interrupt pin on every cycle while it is low, even with the
 * interrupt masked, which slows the simulation a hundredfold. */
#ifndef BOARD_H
#define BOARD_H
#define STEP_PORT PORTB
#define STEP_DDR DDRB
#define STEP_BIT 1
#define DIR_PORT PORTD
#define DIR_DDR DDRD
#define DIR_BIT 5
#define EN_PORT PORTB
#define EN_DDR DDRB
#define EN_BIT 0
#define LIMIT_PIN PINC
#define LIMIT_PORT PORTC
#define LIMIT_DDR DDRC
#define LIMIT_BOTTOM_BIT 0
#define LIMIT_TOP_BIT 1
#define BAUD 115200UL
#endif
