/*
 * board_servo.h - the servo build's part of the board seam (make SERVO=1,
 * -DFB_SERVO): the arms are hobby servos, not steppers.  board.h includes it
 * in place of the step/direction/endstop inlines of the stepper build.
 *
 * A servo joint's "steps" are pulse ticks of 0.5 us (Timer1 at F_CPU/8): its
 * position is the width of the pulse it is sent, 3000 = 1500 us.  The core
 * runs the same DDA on them (G1/G6 deltas, Ln done, the kept record, exact
 * resume); the step interrupt of this build (board_servo.c, Timer2's
 * overflow) only advances that DDA, and Timer1 sends each arm, every 20 ms
 * frame, a hardware-timed pulse as wide as the joint's position at the
 * frame's start: each segment's pulse widths interpolated frame by frame.
 */
#ifndef FB_BOARD_SERVO_H
#define FB_BOARD_SERVO_H

#include <stdint.h>
#include "config.h"

/* The step and direction pins are unused here, kept as low outputs. */
#define BOARD_STEP_PORT  BOARD_CAT(PORT, PIN_STEP_PORT)
#define BOARD_DIR_PORT   BOARD_CAT(PORT, PIN_DIR_PORT)
#define BOARD_STEP_PINS  ((uint8_t)((1u << PIN_STEP_A_BIT) | (1u << PIN_STEP_B_BIT)))
#define BOARD_DIR_PINS   ((uint8_t)((1u << PIN_DIR_A_BIT) | (1u << PIN_DIR_B_BIT)))

/* Timer1 and the arm servos' pins; called by board_init(). */
void board_servo_init(void);
/* M17 / M18: the arm servos get pulses / none (a servo without pulses goes
 * limp, where it is: the position is kept). */
void board_enable_motors(uint8_t on);

/* A step only moves the position the core counts in board_keep; the servo
 * frame reads it (mo_get_pos). */
BOARD_INLINE void board_steps_high(uint8_t mask)
{
	(void)mask;
}

BOARD_INLINE uint8_t board_dir_bits(uint8_t neg_mask)
{
	(void)neg_mask;
	return 0;
}

BOARD_INLINE void board_set_dirs(uint8_t neg_mask)
{
	(void)neg_mask;
}

/* No endstops: D9/D10 (the limit headers) carry the arm servos' pulses, and
 * a servo knows its angle from its pulse. */
BOARD_INLINE uint8_t board_endstops(void)
{
	return 0;
}

/* every block runs on mo_event() (no fast path) */
#define BOARD_FAST_PATH 0

#endif
