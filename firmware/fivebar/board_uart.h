/*
 * board_uart.h - the link's baud rate, part of the board seam (board_avr.c,
 * tests/fake_board.c), kept apart from board.h.
 */
#ifndef FB_BOARD_UART_H
#define FB_BOARD_UART_H

#include <stdint.h>

/*
 * Switch UART0 to `baud` (8N1, U2X: UBRR = F_CPU / (8 baud) - 1, exact at
 * 16 MHz for 250000, 500000 and 1000000; 115200 is UBRR 16, -0.8 %).  Waits
 * until every byte already queued for sending has left at the old rate, so a
 * reply written before the switch arrives whole.  Main loop only.
 */
void board_uart_baud(uint32_t baud);

#endif
