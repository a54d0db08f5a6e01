/*
 * board_avr_step.h - what the two halves of the ATmega328P's step interrupt
 * share: board_avr_step.c (the C path, the start of a fast block, the
 * timer's start, stop, pause and resume) and board_avr_step.S (the fast
 * path, hand-written assembly).
 *
 * Plain macros, which the assembler reads too, and the interrupt's state,
 * board_step, whose field offsets the assembly takes from the layout header
 * generated from this definition (firmware/layout/board_avr_layout.c).
 */
#ifndef FB_BOARD_AVR_STEP_H
#define FB_BOARD_AVR_STEP_H

/* GPIOR0 flags (sbic/sbi/cbi reach it) */
#define BOARD_FL_SLOW 0   /* the pending event is the C path's */
#define BOARD_FL_ENDED 1  /* ... and it is the end of a fast block */
#define BOARD_FL_PAIR 2   /* the pending fast event has a second edge at board_step.t2 */
#define BOARD_FL_CLOSE 3  /* ... a close pair (fb_fast.h): a counted wait of board_step.gap */
#define BOARD_FL_ADONE 4  /* the running fast block's motor A has no step left */
#define BOARD_FL_BDONE 5  /* ... and motor B (the fast path's pick reads these) */

/* A close pair's second edge leaves 14 + 3 * floor(gap / 3) cycles after
 * the first (the instructions between the two in the fast path's entry):
 * gap = the pair's gap - BOARD_CLOSE_OVH puts it within a cycle of it. */
#define BOARD_CLOSE_OVH 13

#ifndef __ASSEMBLER__
#include <stdint.h>

/* The pending event of the step interrupt; the fast path keeps the events
 * of a fast block here, the C path its own next event (sched). */
typedef struct {
	uint16_t sched;  /* exact timer value of the pending step event */
	uint16_t t2;     /* a pair's second edge */
	uint8_t gap;     /* a close pair's wait count (its gap less BOARD_CLOSE_OVH) */
} board_step_t;
#endif

#endif
