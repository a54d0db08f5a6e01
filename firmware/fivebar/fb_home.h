/*
 * fb_home.h - $H, the homing cycle (protocol section 8).
 */
#ifndef FB_HOME_H
#define FB_HOME_H

#include <stdint.h>

/* Seek both switches, pull off, set the home position; blocks until done
 * (serving status requests).  FB_OK, an error, or the alarm it raised. */
uint8_t home_cycle(void);

#endif
