/*
 * fb_fast.h - the fast form of a block, in portable C: the form itself, the
 * pick of the next event and the one-event step.
 *
 * The step interrupt's fast path (board_avr_step.S, hand-written assembly)
 * executes blocks in this form; this module is its executable specification.
 * The AVR build uses fast_form() when the main loop queues a block
 * (mo_seal) and fast_pick() when the C path starts a fast block
 * (mo_fast_begin); the assembly does fast_next()'s work in the interrupt,
 * making the same decisions.  tests/fast_tests.c runs fast_next() over
 * random blocks against the DDA schedule; the emulator's pin trace checks
 * the assembly (tests/firmware, benchmarks/firmware.py).
 *
 * Both motors run on 16-bit timer times with a 16-bit fraction.  Step k of a
 * motor is at t1 + (k-1) * (q + qf/65536) with t1 = (q + qf/65536) / 2, where
 * q + qf/65536 is C/n cut to 16 fraction bits: in 1/65536 cycle, step k is
 * at floor((2k-1) * Q / 2) with Q = floor(65536 C / n), the timer time its
 * whole part.  That is the DDA time floor((2k-1)C/2n) or one cycle before
 * it (the cut loses less than k/65536 cycle, < 1/4 for n <= FAST_NMAX); the
 * same when 65536 (C mod n) is a multiple of n.  The block ends exactly C
 * cycles after its start (tail after its last step, which the cut may have
 * moved), so the next block starts on the DDA's time.
 *
 * Motor masks: bit 0 = A, bit 1 = B.  No floats, no division outside
 * fast_form() (main loop).
 */
#ifndef FB_FAST_H
#define FB_FAST_H

#include <stdint.h>

/*
 * A block's fast form.  t[] are cycles from the block start until the block
 * starts (fast_begin), timer times after.  The steps left of each motor are
 * not here: the running count lives in the kept record (board_keep.left[],
 * board.h), which the fast interrupt counts down.
 */
typedef struct {
	uint16_t t[2];     /* next step of motor i */
	uint16_t tf[2];    /* its fraction, 1/65536 cycle */
	uint16_t q[2];     /* whole cycles between steps */
	uint16_t qf[2];    /* fraction of a cycle between steps, 1/65536 */
	uint16_t cnt[2];   /* steps of motor i in the block */
	uint16_t tail;     /* cycles from the block's last step to its end */
} fast_t;

/* A block takes the fast form when each moving motor has n <= FAST_NMAX
 * steps at intervals q <= FAST_QMAX cycles (so every time difference the
 * interrupt compares stays below 32768) and some motor moves. */
#define FAST_NMAX 16383u
#define FAST_QMAX 16383u

/*
 * The pick's pairs.  When the other motor's next step follows the first
 * within FAST_PAIR_CYCLES the same interrupt issues it (a pair): closer than
 * FAST_TINY_CYCLES, as one edge of both at the later time (the first motor
 * up to 7 cycles late); closer than FAST_CLOSE_CYCLES, after a counted wait
 * (a close pair); else after a timer poll.  120: a step farther behind the
 * previous one gets an interrupt of its own (the waits for pairs at 120-180
 * took more of the CPU than the extra interrupts; measured with
 * benchmarks/firmware.py --at 55).
 */
#define FAST_PAIR_CYCLES 120
#define FAST_CLOSE_CYCLES 80
#define FAST_TINY_CYCLES 8

/* An event of a fast block: what the interrupt at t does. */
typedef struct {
	uint16_t t;      /* timer time of its (first) edge, or of the block's end */
	uint16_t t2;     /* a pair's second edge */
	uint8_t bits;    /* motors stepping at t; 0: the block ends at t */
	uint8_t bits2;   /* motors stepping at t2; 0: not a pair */
} fast_event_t;

/* How the board issues an event (fast_kind). */
enum { FAST_ONE, FAST_TINY, FAST_CLOSE, FAST_PAIR };

/*
 * The fast form of a MOVE block whose motor i has n[i] steps at q[i] whole
 * cycles apart with remainder m[i] < n[i] (its C cycles are q n + m): 1 and
 * *f filled when the block qualifies (see FAST_NMAX), else 0 with *f not
 * written at all (mo_seal forms a block in place, over its C form).  Main
 * loop: a few hundred cycles on the AVR.
 */
uint8_t fast_form(fast_t *f, const uint32_t n[2], const uint32_t q[2], const uint32_t m[2]);
/* fast_form's work for a block it takes (some n > 0, each n <= FAST_NMAX and
 * its q <= FAST_QMAX, m < n; q and m 0 where n is): in 16 bits, so a caller
 * that checked those rules itself (mo_prepare_fast) keeps 12 bytes of
 * arguments on the stack instead of 24. */
void fast_form16(fast_t *f, const uint16_t n[2], const uint16_t q[2], const uint16_t m[2]);

/* The block starts at timer time base: its times become timer times. */
void fast_begin(fast_t *f, uint16_t base);

/*
 * The pick: the next event of a started block whose motor i has left[i]
 * steps left (not both 0): the earlier of the live motors' next steps (both
 * when equal), and the other one as its pair when it follows within
 * FAST_PAIR_CYCLES.
 */
void fast_pick(const fast_t *f, const uint16_t left[2], fast_event_t *e);

/* FAST_ONE (one edge at e->t), or how a pair is issued (see FAST_PAIR_CYCLES). */
uint8_t fast_kind(const fast_event_t *e);

/*
 * The one-event step, what the fast interrupt does once the edges of *e have
 * left: count the steps of its motors in left[], advance their next times,
 * and pick the following event into *e.  Returns 1, or 0 once both motors
 * are done: *e is then the block's end (bits 0) at its last event + tail.
 */
uint8_t fast_next(fast_t *f, uint16_t left[2], fast_event_t *e);

#endif
