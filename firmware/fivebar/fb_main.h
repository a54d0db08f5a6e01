/*
 * fb_main.h - the firmware application: serial protocol, commands, settings,
 * homing and laser safety on top of fb_proto and fb_motion.
 */
#ifndef FB_MAIN_H
#define FB_MAIN_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Once at boot: hardware, state, banner. */
void fb_setup(void);
/* Repeatedly from the main loop: never blocks for long. */
void fb_poll(void);
/* From the serial receive interrupt, one byte at a time: the whole handler
 * (real-time bytes, a full ring); the board's interrupt may store a byte
 * that is neither itself, as this function's last lines do (fb_rx_t). */
void fb_rx_isr(uint8_t c);

/*
 * The receive ring, from the receive interrupt to the line assembly
 * (fb_main.c): free-running 8-bit indices over all 256 bytes, CFG_RX_SIZE of
 * them used.  Written: head, buf[head] and heard by the receive interrupt
 * (fb_rx_isr, or the board's fast path for a byte that is not a real-time
 * one while the ring has room: board_avr.c USART_RX_vect, whose C model is
 * fb_rx_isr); tail by the main loop.  heard: a byte came since the main loop
 * last looked (the host-silence watchdog's clock, read and cleared there).
 */
typedef struct {
	volatile uint8_t buf[256];
	volatile uint8_t head, tail, heard;
} fb_rx_t;
extern fb_rx_t fb_rx;

#ifdef __cplusplus
}
#endif

#endif
