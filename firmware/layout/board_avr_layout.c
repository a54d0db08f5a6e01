/*
 * board_avr_layout.c - the source of the layout header the fast path's
 * assembly includes (build/avr/board_avr_layout.h, made by the Makefile):
 * every struct field's offset and size and every C constant
 * board_avr_step.S uses, taken from the C definitions themselves, as
 * Linux's asm-offsets.c does.
 *
 * Compiled to assembly only (never linked): each LAYOUT() leaves a line
 * ".ascii "@@NAME value"" in it, which the Makefile turns into
 * "#define NAME value".  The sketch keeps a copy of the result,
 * fivebar/board_avr_layout.h, for the Arduino IDE, which cannot run this;
 * the build stops when the copy differs from what this file gives.
 */
#include <stddef.h>
#include "board.h"
#include "board_avr_step.h"
#include "fb_fast.h"
#include "fb_motion.h"

#define LAYOUT(name, value) \
	__asm__ __volatile__("\n.ascii \"@@" #name " %0\"" :: "n"((long)(value)))
/* A field's offset as NAME and its size as NAME_SIZE (the assembly checks
 * the sizes it was written for). */
#define FIELD(name, type, field) \
	do { \
		LAYOUT(name, offsetof(type, field)); \
		LAYOUT(name##_SIZE, sizeof(((type *)0)->field)); \
	} while (0)

void board_avr_layout(void);

void board_avr_layout(void)
{
	/* a queue entry, mo_block_t (fb_motion.h): its fast form (fb_fast.h)
	 * and the fields the fast path's switch to it reads */
	FIELD(BLK_T, mo_block_t, f.t);
	FIELD(BLK_TF, mo_block_t, f.tf);
	FIELD(BLK_Q, mo_block_t, f.q);
	FIELD(BLK_QF, mo_block_t, f.qf);
	FIELD(BLK_CNT, mo_block_t, f.cnt);
	FIELD(BLK_TAIL, mo_block_t, f.tail);
	FIELD(BLK_LINE, mo_block_t, line);
	FIELD(BLK_DIRS, mo_block_t, dirs);
	FIELD(BLK_POWER, mo_block_t, power);
	FIELD(BLK_FAST, mo_block_t, fast);
	FIELD(BLK_PDIRS, mo_block_t, pdirs);
	LAYOUT(BLK_SIZE, sizeof(mo_block_t));
	/* the queue, mo_state (fb_motion.h) */
	FIELD(MO_QUEUE, mo_state_t, queue);
	FIELD(MO_CUR, mo_state_t, cur);
	FIELD(MO_HEAD, mo_state_t, head);
	FIELD(MO_TAIL, mo_state_t, tail);
	/* the kept record, board_keep (board.h) */
	FIELD(KEEP_DONE, board_keep_t, done);
	FIELD(KEEP_OFF, board_keep_t, off);
	FIELD(KEEP_BUSY, board_keep_t, busy);
	FIELD(KEEP_LEFT, board_keep_t, left);
	FIELD(KEEP_FDIRS, board_keep_t, fdirs);
	FIELD(KEEP_NDONE, board_keep_t, ndone);
	/* the interrupt's state, board_step (board_avr_step.h) */
	FIELD(STEP_SCHED, board_step_t, sched);
	FIELD(STEP_T2, board_step_t, t2);
	FIELD(STEP_GAP, board_step_t, gap);
	/* the fast path's switch between blocks (fb_motion.h) */
	LAYOUT(MO_FAST_SWITCH_BIT, MO_FAST_SWITCH_BIT);
	LAYOUT(MO_FAST_RASTER_BIT, MO_FAST_RASTER_BIT);
	/* the pick's pairs (fb_fast.h) */
	LAYOUT(FAST_PAIR_CYCLES, FAST_PAIR_CYCLES);
	LAYOUT(FAST_CLOSE_CYCLES, FAST_CLOSE_CYCLES);
	LAYOUT(FAST_TINY_CYCLES, FAST_TINY_CYCLES);
}
