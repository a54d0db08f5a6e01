/*
 * board_avr_step.S - the fast path of the ATmega328P's step interrupt
 * (Timer1 compare A), hand-written assembly.
 *
 * It runs the events of blocks in their fast form (fb_fast.h: plain moves of
 * up to 16383 steps at >= 977 steps/s per motor); fb_fast.c is the portable
 * C it follows, the form, the pick (fast_pick) and the one-event step
 * (fast_next), which tests/fast_tests.c checks against the DDA schedule.
 * The pins of the pending event are in GPIOR1, so the rising edges leave
 * ten cycles after the vector, whatever the bookkeeping: the steps left (the
 * kept record's left[]: a block's steps go into the kept position when it
 * starts), the next time (16-bit time + 16-bit fraction, no division, no
 * compare of remainders), the pick of the next event, and the switch to the
 * next block when it is fast too, of the same kind (fb_motion.h MO_FAST_*:
 * plain moves, or a scan's blocks)
 * and keeps the laser power (Ln done, its
 * steps into the kept position, direction pins, its times).  When the other
 * motor's step follows within FAST_PAIR_CYCLES (too close to leave and come
 * back) the pick marks a pair (GPIOR0 BOARD_FL_PAIR, its time in
 * board_step.t2, its pins in GPIOR2) and the same interrupt waits for it;
 * anything closer than LEAVE_CYCLES when the interrupt ends is waited for
 * too.  About 145 cycles an event of one motor, all in (fbsim -P).
 *
 * Everything else is the C path's (board_avr_step.c): when GPIOR0's
 * BOARD_FL_SLOW is set the vector jumps to __vector_fb_step_slow before it
 * saves anything.  Step pins rise by writing PIND (which toggles PORTD bits:
 * the pins are low before) and fall together by a PORTD write.
 *
 * The offsets and sizes of the C structs it reads and writes, and the C
 * constants it uses, come from board_avr_layout.h, generated from the C
 * definitions (firmware/layout/board_avr_layout.c); the sizes it was
 * written for are checked below.
 */
#include <avr/io.h>
#include "config.h"
#include "board_avr_step.h"
#include "board_avr_layout.h"

/* the fast path writes PIND and PORTD */
#define PORT_IS_D_D 1
#define CAT2(a, b) a##b
#define CAT(a, b) CAT2(a, b)
#if !CAT(PORT_IS_D_, PIN_STEP_PORT) || !CAT(PORT_IS_D_, PIN_DIR_PORT)
#error "the fast step path needs the step and direction pins on port D"
#endif

#define GP0 _SFR_IO_ADDR(GPIOR0)
#define GP1 _SFR_IO_ADDR(GPIOR1)
#define GP2 _SFR_IO_ADDR(GPIOR2)
#define PIN_D _SFR_IO_ADDR(PIND)
#define PORT_D _SFR_IO_ADDR(PORTD)
#define S_REG _SFR_IO_ADDR(SREG)
#define TIMER_L _SFR_MEM_ADDR(TCNT1L)
#define TIMER_H _SFR_MEM_ADDR(TCNT1H)
#define OCR_L _SFR_MEM_ADDR(OCR1AL)
#define OCR_H _SFR_MEM_ADDR(OCR1AH)
#define TIFR_1 _SFR_IO_ADDR(TIFR1)
#define TIMSK_1 _SFR_MEM_ADDR(TIMSK1)
#define TIMSK_0 _SFR_MEM_ADDR(TIMSK0)
#define UCSR_B _SFR_MEM_ADDR(UCSR0B)

#define STEP_A_BIT PIN_STEP_A_BIT
#define STEP_B_BIT PIN_STEP_B_BIT
#define STEPS_MASK ((1 << PIN_STEP_A_BIT) | (1 << PIN_STEP_B_BIT))
#define DIRS_MASK ((1 << PIN_DIR_A_BIT) | (1 << PIN_DIR_B_BIT))

/* the C structs, by the generated offsets */
#define CUR (mo_state + MO_CUR)
#define QUEUE (mo_state + MO_QUEUE)
#define QUEUE_END (mo_state + MO_QUEUE + MO_QUEUE_SIZE)
#define Q_HEAD (mo_state + MO_HEAD)
#define Q_TAIL (mo_state + MO_TAIL)
#define SCHED (board_step + STEP_SCHED)
#define T2 (board_step + STEP_T2)
#define GAP (board_step + STEP_GAP)

/* Leave the interrupt only when the next event is at least this far: else
 * it would come while the interrupt is still returning. */
#define LEAVE_CYCLES 48
/* A farther pair's first motor's bookkeeping runs before the second edge
 * when that edge is at least this far when the interrupt looks (the
 * bookkeeping and the wait's set-up take about 56); closer, it waits first
 * (waiting first whenever the edge was within FAST_CLOSE_CYCLES spent ~40
 * cycles of each pair at 90-110 cycles spinning). */
#define PAIR_BK1 60
/* The waits end this many cycles after the event time, so that an edge
 * placed by waiting leaves when an interrupt's would (measured). */
#define SPIN_LAG 8

/* The sizes the code below was written for. */
.if BLK_T_SIZE != 4 || BLK_TF_SIZE != 4 || BLK_Q_SIZE != 4 || BLK_QF_SIZE != 4
.error "the fast form's t, tf, q, qf: two 16-bit words"
.endif
.if BLK_CNT_SIZE != 4 || BLK_TAIL_SIZE != 2 || BLK_LINE_SIZE != 4
.error "the fast form's cnt: two 16-bit words, tail: one; a block's line: 32 bits"
.endif
.if BLK_DIRS_SIZE != 1 || BLK_POWER_SIZE != 1 || BLK_FAST_SIZE != 1 || BLK_PDIRS_SIZE != 1
.error "a block's dirs, power, fast, pdirs: bytes"
.endif
.if MO_CUR_SIZE != 2 || MO_HEAD_SIZE != 1 || MO_TAIL_SIZE != 1
.error "mo_state: a 16-bit pointer, byte indices"
.endif
.if KEEP_DONE_SIZE != 4 || KEEP_NDONE_SIZE != 4 || KEEP_OFF_SIZE != 4 || KEEP_LEFT_SIZE != 4
.error "board_keep: 32-bit done and ndone, two 16-bit off and left"
.endif
.if KEEP_BUSY_SIZE != 1 || KEEP_FDIRS_SIZE != 1
.error "board_keep: byte busy and fdirs"
.endif
.if STEP_SCHED_SIZE != 2 || STEP_T2_SIZE != 2 || STEP_GAP_SIZE != 1
.error "board_step: 16-bit times, a byte gap"
.endif
.if FAST_PAIR_CYCLES >= 200
.error "the waits of a pair stay below 128 cycles"
.endif
.if FAST_PAIR_CYCLES >= 256
.error "the pick compares -d's low byte"
.endif

/* Z+dst[i] += Z+src[i], 16 bits, the low byte by op (add, or adc to take
 * the carry of the previous one in).  Leaves the sum in r18:r19.  Uses r18,
 * r19, r26, r27. */
.macro ADD16_Z dst, src, i, op
	ldd r18, Z+\dst+2*\i
	ldd r19, Z+\dst+2*\i+1
	ldd r26, Z+\src+2*\i
	ldd r27, Z+\src+2*\i+1
	\op r18, r26
	adc r19, r27
	std Z+\dst+2*\i, r18
	std Z+\dst+2*\i+1, r19
.endm

/*
 * One motor's step bookkeeping (i = 0 A, 1 B): its steps left (the kept
 * record's left[i], which is the kept position's count too) and, unless
 * that was the last, its next time t.tf += q.qf, left in r18:r19; after the
 * last, GPIOR0's done bit of the motor is set instead (fast_next).  The
 * count goes down by its low byte, the high byte only on a borrow or at a
 * low 0 (two cycles fewer a step than a 16-bit load, subtract and store;
 * the busy flag covers the two stores as it covered one).  Uses r18, r19,
 * r26, r27.
 */
.macro STEP_MOTOR i, L
	lds r26, board_keep+KEEP_LEFT+2*\i
	subi r26, 1
	sts board_keep+KEEP_LEFT+2*\i, r26
	brcs \L\()_b                    /* the low byte was 0: borrow */
	breq \L\()_z                    /* it is 0 now: the last step if the high byte is 0 */
\L\()_t:
	ADD16_Z BLK_TF, BLK_QF, \i, add
	ADD16_Z BLK_T, BLK_Q, \i, adc
	rjmp \L\()_d
\L\()_b:
	lds r27, board_keep+KEEP_LEFT+2*\i+1
	dec r27
	sts board_keep+KEEP_LEFT+2*\i+1, r27
	rjmp \L\()_t
\L\()_z:
	lds r27, board_keep+KEEP_LEFT+2*\i+1
	tst r27
	brne \L\()_t
	sbi GP0, BOARD_FL_ADONE+\i
\L\()_d:
.endm

/*
 * Start of the next block's motor i in the kept record (busy set), Z = that
 * block, r26 = its directions: all its steps go into off[i] (negative when
 * direction bit i is set) and into left[i], the ones not issued yet; the
 * motor's done bit in GPIOR0 is set when it has none.  Uses r24, r25, r27.
 */
.macro AHEAD_MOTOR i, L
	ldd r24, Z+BLK_CNT+2*\i
	ldd r25, Z+BLK_CNT+2*\i+1
	sts board_keep+KEEP_LEFT+2*\i, r24
	sts board_keep+KEEP_LEFT+2*\i+1, r25
	cbi GP0, BOARD_FL_ADONE+\i
	mov r27, r24
	or r27, r25
	brne \L\()_l
	sbi GP0, BOARD_FL_ADONE+\i
\L\()_l:
	sbrs r26, \i
	rjmp \L
	com r25
	neg r24
	sbci r25, 0xff
\L:
	lds r27, board_keep+KEEP_OFF+2*\i
	add r24, r27
	lds r27, board_keep+KEEP_OFF+2*\i+1
	adc r25, r27
	sts board_keep+KEEP_OFF+2*\i, r24
	sts board_keep+KEEP_OFF+2*\i+1, r25
.endm

/*
 * The pick when the other motor is done (entered at Done): the block ends
 * when motor i is done too, else motor i's next step is the event (entered
 * at Arm with its time already in r18:r19).
 */
.macro ALONE i, Done, Arm
\Done:
	sbic GP0, BOARD_FL_ADONE+\i
	rjmp fp_block_end
	ldd r18, Z+BLK_T+2*\i
	ldd r19, Z+BLK_T+2*\i+1
\Arm:
	ldi r24, 1 << (STEP_A_BIT+(\i)*(STEP_B_BIT-STEP_A_BIT))
	rjmp fp_arm
.endm

/*
 * Wait until the timer reaches r18:r19 + SPIN_LAG (at once when past).  The
 * remaining wait is below 128 cycles, so the loop compares low bytes only
 * (5 cycles a turn).  Uses r26, r27.
 */
.macro SPIN L
	lds r26, TIMER_L
	lds r27, TIMER_H
	sub r26, r18
	sbc r27, r19
	subi r26, SPIN_LAG
	sbci r27, 0
	brpl \L\()_go
	mov r27, r18
	subi r27, -SPIN_LAG
\L\()_w:
	lds r26, TIMER_L
	sub r26, r27
	brmi \L\()_w
\L\()_go:
.endm

/*
 * The pixel interrupt's window (raster scans): when its compare has fired
 * (TIFR1 OCF1B) and it is enabled (TIMSK1 OCIE1B), it runs here, nested,
 * instead of after the whole stay (a pair's wait and a block switch, a
 * cluster: up to ~480 cycles with interrupts off, and its power changes came
 * up to 31 us late on configs/raster-fast.toml, docs/raster.md).  The
 * windows are where the path stays and no edge is due at once: after a
 * motor's bookkeeping (every event passes one), before a cluster's and a
 * pair's wait, after a pair's second edge, at both ends of a block switch
 * (leaving needs none: the interrupt comes after reti).  The other sources
 * are masked as the C path's event_px_nested() masks them (Timer0's TIMSK0,
 * the serial interrupts' enables in UCSR0B, this interrupt's own OCIE1A:
 * they wait as they waited before), so only the pixel interrupt comes in; it
 * touches mo_state.px, OCR1B, TIMSK1's OCIE1B and the laser, nothing of the
 * fast path's, and saves every register it uses.  A step edge due meanwhile
 * waits for it, as one waits when the pixel interrupt runs from the main
 * loop.  The chip takes an interrupt after the instruction that follows sei;
 * simavr 1.6 only after two more (with one nop the window never let it in:
 * measured), hence three.  Not pending: 2 cycles (sbic skips the rcall); with
 * the pixel interrupt off, the flag its compare sets at every timer wrap is
 * cleared.  Fewer windows cost more than they save: without the ones after
 * the bookkeeping, or after a pair's second edge, a few changes of the photo
 * came 20-23 us late (measured), for 0.1-0.3 cycles of step interval jitter.
 * Stack: the call's 2 bytes and one pixel interrupt frame above this
 * vector's 10 bytes.  Uses r25, r26, r27.
 */
.macro PX_WINDOW L
	sbic TIFR_1, OCF1B
	rcall fp_px_window
.endm

	.section .text.board_step_fast, "ax", @progbits
	.global TIMER1_COMPA_vect
	.type TIMER1_COMPA_vect, @function
TIMER1_COMPA_vect:
	sbic GP0, BOARD_FL_SLOW
	jmp __vector_fb_step_slow
	push r24
	in r24, GP1
	sts board_keep+KEEP_BUSY, r24
	out PIN_D, r24                  /* the edges */
	sbic GP0, BOARD_FL_CLOSE
	rjmp fp_close_entry
	push r25
	in r25, S_REG
	push r25
	push r18
	push r19
	push r26
	push r27
	push r30
	push r31
	lds r30, CUR
	lds r31, CUR+1
fp_edge_done:
	sbic GP0, BOARD_FL_PAIR
	rjmp fp_pair
/* ---- bookkeeping of the motors in r24 ---- */
fp_steps:
	sbrs r24, STEP_A_BIT
	rjmp fp_steps_b
	STEP_MOTOR 0, sa
	sbrs r24, STEP_B_BIT
	rjmp fp_pick_a
fp_steps_b:
	STEP_MOTOR 1, sb
/* ---- pick the next event (fast_pick); the motor stepped last has its
 * next time in r18:r19 unless it is done ---- */
	clr r25
	sts board_keep+KEEP_BUSY, r25
	PX_WINDOW pxb
	sbic GP0, BOARD_FL_BDONE
	rjmp fp_b_done
	sbic GP0, BOARD_FL_ADONE
	rjmp fp_arm_b
	movw r26, r18                   /* tB */
	ldd r18, Z+BLK_T
	ldd r19, Z+BLK_T+1
	rjmp fp_both
fp_pick_a:
	clr r25
	sts board_keep+KEEP_BUSY, r25
	PX_WINDOW pxa
	sbic GP0, BOARD_FL_ADONE
	rjmp fp_a_done
	sbic GP0, BOARD_FL_BDONE
	rjmp fp_arm_a
	ldd r26, Z+BLK_T+2
	ldd r27, Z+BLK_T+3
fp_both:                                /* r18:r19 = tA, r26:r27 = tB */
	sub r26, r18
	sbc r27, r19                    /* d = tB - tA */
	brmi fp_b_first
	ldi r24, 1 << STEP_A_BIT
	brne 1f
	tst r26
	brne 1f
	ldi r24, STEPS_MASK             /* same time */
	rjmp fp_arm
1:                                      /* A first, B d later */
	cpi r26, FAST_PAIR_CYCLES
	ldi r25, 0
	cpc r27, r25
	brsh fp_arm
	add r26, r18
	adc r27, r19
	ldi r25, 1 << STEP_B_BIT
	rjmp fp_pair_set
fp_b_far:
	ldi r24, 1 << STEP_B_BIT
	rjmp fp_arm
fp_b_first:                             /* B first, A -d later */
	movw r24, r18                   /* tA */
	add r18, r26
	adc r19, r27                    /* r18:r19 = tB */
	com r27
	neg r26
	sbci r27, 0xff                  /* -d */
	tst r27
	brne fp_b_far
	cpi r26, FAST_PAIR_CYCLES
	brsh fp_b_far
	movw r26, r24
	ldi r24, 1 << STEP_B_BIT
	ldi r25, 1 << STEP_A_BIT
fp_pair_set:                            /* second edge: r26:r27, pins r25 (fast_kind) */
	sts T2, r26
	sts T2+1, r27
	out GP2, r25
	sub r26, r18                    /* the gap (< FAST_PAIR_CYCLES) */
	cpi r26, FAST_CLOSE_CYCLES
	brsh 3f
	cpi r26, FAST_TINY_CYCLES
	brsh 1f
	or r24, r25                     /* tiny: both at the later time */
	lds r18, T2
	lds r19, T2+1
	rjmp fp_arm
1:
	subi r26, BOARD_CLOSE_OVH
	brcc 2f
	clr r26
2:
	sts GAP, r26
	sbi GP0, BOARD_FL_CLOSE
	rjmp fp_arm
3:
	sbi GP0, BOARD_FL_PAIR
/* ---- arm the next event: r18:r19 time, r24 pins ---- */
fp_arm:
	sts SCHED, r18
	sts SCHED+1, r19
	out GP1, r24
	in r25, PORT_D                  /* the fall: >= 40 cycles after the last edge */
	andi r25, (~STEPS_MASK) & 0xff
	out PORT_D, r25
	lds r26, TIMER_L
	lds r27, TIMER_H
	sub r26, r18
	sbc r27, r19                    /* now - t */
	subi r26, lo8(-LEAVE_CYCLES)
	sbci r27, hi8(-LEAVE_CYCLES)
	brpl fp_cluster
fp_ocr:                                 /* OCR1A := r18:r19, then leave */
	tst r19                         /* simavr: see ocr_value() in board_avr_step.c */
	brne 1f
	cpi r18, 8
	brsh 1f
	ldi r18, 8
1:
	sts OCR_H, r19
	sts OCR_L, r18
fp_exit:
	pop r31
	pop r30
	pop r27
	pop r26
	pop r19
	pop r18
	pop r25
	out S_REG, r25
	pop r25
	pop r24
	reti
	ALONE 1, fp_a_done, fp_arm_b
	ALONE 0, fp_b_done, fp_arm_a
/* the pick from nothing in registers (a new block) */
fp_select:
	sbic GP0, BOARD_FL_ADONE
	rjmp fp_a_done
	ldd r18, Z+BLK_T
	ldd r19, Z+BLK_T+1
	sbic GP0, BOARD_FL_BDONE
	rjmp fp_arm_a
	ldd r26, Z+BLK_T+2
	ldd r27, Z+BLK_T+3
	rjmp fp_both
/* ---- the next event is too close to leave: wait for it here ---- */
fp_cluster:
	PX_WINDOW pxk
	lds r26, TIMER_L
	lds r27, TIMER_H
	sub r26, r18
	sbc r27, r19
	brmi 2f                         /* overdue (catching up): */
	ldi r25, 2                      /* with the fall's path the pins stay low >= 2.3 us (the DRV8825 needs 1.9) */
1:
	dec r25
	brne 1b
2:
	SPIN cl
	in r24, GP1
	sts board_keep+KEEP_BUSY, r24
	out PIN_D, r24
	sbic GP0, BOARD_FL_CLOSE
	rjmp fp_close_cluster
	rjmp fp_edge_done
/* ---- a close pair: the second edge after a counted wait ---- */
fp_close_entry:
	push r25
	in r25, S_REG
	push r25
	lds r25, GAP
1:
	subi r25, 3
	brcc 1b
	in r25, GP2
	out PIN_D, r25                  /* the second edge */
	or r24, r25
	cbi GP0, BOARD_FL_CLOSE
	push r18
	push r19
	push r26
	push r27
	push r30
	push r31
	lds r30, CUR
	lds r31, CUR+1
	rjmp fp_close_done
fp_close_cluster:                       /* 5 cycles fewer before the wait */
	lds r25, GAP
	subi r25, -5
1:
	subi r25, 3
	brcc 1b
	in r25, GP2
	out PIN_D, r25
	or r24, r25
	cbi GP0, BOARD_FL_CLOSE
fp_close_done:
	PX_WINDOW pxd
	lds r18, T2                     /* now = the second edge */
	lds r19, T2+1
	sts SCHED, r18
	sts SCHED+1, r19
	rjmp fp_steps
/* ---- a pair: the second edge at board_step.t2 ---- */
fp_pair:
	cbi GP0, BOARD_FL_PAIR
	lds r18, T2
	lds r19, T2+1
	lds r26, TIMER_L
	lds r27, TIMER_H
	sub r26, r18
	sbc r27, r19                    /* now - t2 */
	subi r26, lo8(-PAIR_BK1)
	sbci r27, hi8(-PAIR_BK1)
	brmi 3f
	rjmp fp_pair_close
3:
	sbrs r24, STEP_A_BIT            /* the first motor's bookkeeping first */
	rjmp 1f
	STEP_MOTOR 0, pa
	rjmp 2f
1:
	STEP_MOTOR 1, pb
2:
	PX_WINDOW pxp
	lds r18, T2
	lds r19, T2+1
	SPIN pf
	in r24, GP2
	out PIN_D, r24
	PX_WINDOW pxf
	sts SCHED, r18                  /* now = the second edge */
	sts SCHED+1, r19
	rjmp fp_steps
fp_pair_close:
	SPIN pc
	in r25, GP2
	out PIN_D, r25
	or r24, r25
	PX_WINDOW pxc
	sts SCHED, r18
	sts SCHED+1, r19
	rjmp fp_steps
/* ---- both motors done: the block ends tail cycles after this event ---- */
fp_block_end:
	PX_WINDOW pxe
	lds r18, SCHED
	lds r19, SCHED+1
	ldd r26, Z+BLK_TAIL
	ldd r27, Z+BLK_TAIL+1
	add r18, r26
	adc r19, r27                    /* r18:r19 = the block's end */
	ldd r25, Z+BLK_POWER
	ldd r24, Z+BLK_FAST
	out GP2, r24                    /* this block's MO_FAST_* (GPIOR2: no pair pends at a block's end) */
	movw r26, r30                   /* X = this block */
	adiw r30, BLK_SIZE              /* Z = the next one */
	ldi r24, hi8(QUEUE_END)
	cpi r30, lo8(QUEUE_END)
	cpc r31, r24
	brne 1f
	ldi r30, lo8(QUEUE)
	ldi r31, hi8(QUEUE)
1:
	ldd r24, Z+BLK_POWER
	cpse r24, r25
	rjmp fp_to_c
	in r25, GP2
	ldd r24, Z+BLK_FAST
	sbrs r24, MO_FAST_SWITCH_BIT    /* a fast block the fast path may enter (not a scan's first) */
	rjmp fp_to_c
	eor r25, r24
	sbrc r25, MO_FAST_RASTER_BIT    /* of the same kind: plain, or raster (fb_motion.h) */
	rjmp fp_to_c
	lds r24, Q_TAIL
	inc r24
	lds r25, Q_HEAD
	cp r24, r25
	brne 1f
	rjmp fp_to_c
1:
	/* the next block is queued, fast, same power: switch to it */
	sts Q_TAIL, r24
	sts CUR, r30
	sts CUR+1, r31
	ldi r24, 1
	sts board_keep+KEEP_BUSY, r24
	/* Ln done := the ended block's line, ndone := its complement */
	adiw r26, BLK_LINE
	ld r25, X+
	sts board_keep+KEEP_DONE, r25
	com r25
	sts board_keep+KEEP_NDONE, r25
	ld r25, X+
	sts board_keep+KEEP_DONE+1, r25
	com r25
	sts board_keep+KEEP_NDONE+1, r25
	ld r25, X+
	sts board_keep+KEEP_DONE+2, r25
	com r25
	sts board_keep+KEEP_NDONE+2, r25
	ld r25, X+
	sts board_keep+KEEP_DONE+3, r25
	com r25
	sts board_keep+KEEP_NDONE+3, r25
	/* the next block's steps, ahead, into off and left */
	ldd r26, Z+BLK_DIRS
	sts board_keep+KEEP_FDIRS, r26
	AHEAD_MOTOR 0, ah0
	AHEAD_MOTOR 1, ah1
	clr r25
	sts board_keep+KEEP_BUSY, r25
	/* direction pins: toggle the ones that change */
	ldd r24, Z+BLK_PDIRS
	in r25, PORT_D
	eor r24, r25
	andi r24, DIRS_MASK
	out PIN_D, r24
	/* its times from its start (the end of this one) to timer times
	 * (fast_begin) */
	ldd r24, Z+BLK_T
	ldd r25, Z+BLK_T+1
	add r24, r18
	adc r25, r19
	std Z+BLK_T, r24
	std Z+BLK_T+1, r25
	ldd r24, Z+BLK_T+2
	ldd r25, Z+BLK_T+3
	add r24, r18
	adc r25, r19
	std Z+BLK_T+2, r24
	std Z+BLK_T+3, r25
	PX_WINDOW pxs
	rjmp fp_select
/* ---- the C path takes the block's end, at its exact time ---- */
fp_to_c:
	sbi GP0, BOARD_FL_SLOW
	sbi GP0, BOARD_FL_ENDED
	clr r24
	out GP1, r24
	sts SCHED, r18
	sts SCHED+1, r19
	in r25, PORT_D
	andi r25, (~STEPS_MASK) & 0xff
	out PORT_D, r25
	lds r26, TIMER_L                /* at least 24 cycles from now */
	lds r27, TIMER_H
	adiw r26, 24
	movw r24, r26
	sub r26, r18
	sbc r27, r19
	brmi 1f
	movw r18, r24
1:
	rjmp fp_ocr
/* the window's body (PX_WINDOW): entered when OCF1B is set */
fp_px_window:
	lds r25, TIMSK_1
	sbrc r25, OCIE1B
	rjmp 1f
	ldi r25, 1 << OCF1B             /* off: the timer's wraps set the flag, clear it */
	out TIFR_1, r25
	ret
1:
	andi r25, (~(1 << OCIE1A)) & 0xff
	sts TIMSK_1, r25
	lds r26, TIMSK_0
	lds r27, UCSR_B
	clr r25
	sts TIMSK_0, r25
	mov r25, r27
	andi r25, (~((1 << RXCIE0) | (1 << UDRIE0))) & 0xff
	sts UCSR_B, r25
	sei
	nop
	nop
	nop
	cli
	sts UCSR_B, r27
	sts TIMSK_0, r26
	lds r25, TIMSK_1
	ori r25, 1 << OCIE1A
	sts TIMSK_1, r25
	ret
	.size TIMER1_COMPA_vect, . - TIMER1_COMPA_vect
