/*
 * fivebar.ino - Arduino IDE entry point of the fivebar firmware.
 *
 * Everything lives in the C files of this folder (fb_*.c, board_avr.c); the
 * IDE compiles them along with this sketch.  `make -C firmware` builds the
 * same files with plain avr-libc.  Protocol: docs/protocol.md.
 */
#include "fb_main.h"

void setup()
{
	fb_setup();
}

void loop()
{
	fb_poll();
}
