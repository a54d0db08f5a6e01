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
 * that is neither itself, as this function's last lines do (fb_state.rx). */
void fb_rx_isr(uint8_t c);


#ifdef __cplusplus
}
#endif

#endif
