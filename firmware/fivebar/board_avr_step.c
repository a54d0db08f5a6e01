/*
 * board_avr_step.c - the step interrupt of the ATmega328P (Timer1 compare A).
 *
 * Timer1 runs free at F_CPU; OCR1A holds the exact timer time of the pending
 * event (board_sched), so interrupt latency never accumulates.  An event is
 * handled by one of two paths, chosen by GPIOR0 bit FL_SLOW:
 *
 *  - the fast path, hand-written below, for blocks with the fast form
 *    (fb_fast.h fast_t: plain moves of up to 16383 steps at >= 977
 *    steps/s per motor).  The pins of the pending event are in GPIOR1, so
 *    the rising edges leave ten cycles after the vector, whatever the
 *    bookkeeping: the steps left (the kept record's left[]: a block's steps
 *    go into the kept position when it starts), the next time
 *    (16-bit time + 16-bit fraction, no division, no compare of remainders),
 *    the pick of the next event, and the switch to the next block when it is
 *    fast too and keeps the laser power (Ln done, its steps into the kept
 *    position, direction pins, its times).
 *    When the other motor's step follows within FAST_PAIR_CYCLES (too close
 *    to leave and come back) the pick marks a pair (GPIOR0 FL_PAIR, its time
 *    in board_t2, its pins in GPIOR2) and the same interrupt waits for it;
 *    anything closer than LEAVE_CYCLES when the interrupt ends is waited for
 *    too.  About 145 cycles an event of one motor, all in (fbsim -P).
 *  - the C path (__vector_fb_step_slow, mo_event() in fb_motion.c) for everything
 *    else: block boundaries the fast path does not take (an empty queue, a
 *    laser power change, a C-form block, a G92/M17/M18/M280), homing,
 *    endstop supervision, slow motors, long waits.  It starts a fast block
 *    with mo_fast_begin().
 *
 * Step pins rise by writing PIND (which toggles PORTD bits: the pins are low
 * before) and fall together by a PORTD write at least PULSE_MIN cycles later.
 * fb_fast.c is the portable C the assembly follows: the form, the pick
 * (fast_pick) and the one-event step (fast_next).
 */
#ifdef __AVR__

#include <stddef.h>
#include <avr/io.h>
#include <avr/interrupt.h>
#include "board.h"
#include "config.h"
#include "fb_motion.h"

/* C path: the pins go low at least this many cycles after its event starts
 * (>= 2.5 us high, measured in the simavr trace). */
#define PULSE_CYCLES 56u
/* C path: events closer than this run in the same interrupt (busy-waiting
 * until their exact cycle) instead of leaving and re-entering it. */
#define NEAR_CYCLES 160

/* GPIOR0 flags (sbic/sbi/cbi reach it) */
#define FL_SLOW 0   /* the pending event is the C path's */
#define FL_ENDED 1  /* ... and it is the end of a fast block */
#define FL_PAIR 2   /* the pending fast event has a second edge at board_t2 */
#define FL_CLOSE 3  /* ... a close pair (fb_fast.h): a counted wait of board_gap */
#define FL_ADONE 4  /* the running fast block's motor A has no step left */
#define FL_BDONE 5  /* ... and motor B (the fast path's pick reads these) */

uint16_t board_sched;  /* exact timer value of the pending step event */
uint16_t board_t2;     /* a pair's second edge */
uint8_t board_gap;     /* a close pair's wait count (the gap less CLOSE_OVH) */
static uint16_t paused_rem;
static uint8_t paused;

/* Offsets the assembly uses, checked against the C layout. */
#define O_T 0
#define O_TF 4
#define O_Q 8
#define O_QF 12
#define O_CNT 16
#define O_TAIL 20
#define O_LINE 44
#define O_DIRS 49
#define O_POWER 50
#define O_FAST 51
#define O_PDIRS 52
#define BLOCK_SIZE 53
#define K_DONE 8
#define K_OFF 17
#define K_BUSY 21
#define K_LEFT 22
#define K_FDIRS 26
#define K_NDONE 27
_Static_assert(offsetof(mo_block_t, f.t) == O_T && offsetof(mo_block_t, f.tf) == O_TF &&
	       offsetof(mo_block_t, f.q) == O_Q && offsetof(mo_block_t, f.qf) == O_QF &&
	       offsetof(mo_block_t, f.cnt) == O_CNT && offsetof(mo_block_t, f.tail) == O_TAIL &&
	       offsetof(mo_block_t, line) == O_LINE && offsetof(mo_block_t, dirs) == O_DIRS &&
	       offsetof(mo_block_t, power) == O_POWER && offsetof(mo_block_t, fast) == O_FAST &&
	       offsetof(mo_block_t, pdirs) == O_PDIRS && sizeof(mo_block_t) == BLOCK_SIZE,
	       "fast path block offsets");
_Static_assert(offsetof(board_keep_t, done) == K_DONE &&
	       offsetof(board_keep_t, off) == K_OFF && offsetof(board_keep_t, busy) == K_BUSY &&
	       offsetof(board_keep_t, left) == K_LEFT && offsetof(board_keep_t, fdirs) == K_FDIRS &&
	       offsetof(board_keep_t, ndone) == K_NDONE,
	       "fast path keep offsets");
_Static_assert(FAST_PAIR_CYCLES < 200, "the waits of a pair stay below 128 cycles");
_Static_assert(FAST_PAIR_CYCLES < 256, "the fast path compares -d's low byte");
/* the fast path writes PIND and PORTD */
#define FB_PORT_IS_D_D 1
#if !BOARD_CAT(FB_PORT_IS_D_, PIN_STEP_PORT) || !BOARD_CAT(FB_PORT_IS_D_, PIN_DIR_PORT)
#error "the fast step path needs the step and direction pins on port D"
#endif

#define STEP_A_BIT PIN_STEP_A_BIT
#define STEP_B_BIT PIN_STEP_B_BIT
#define STEPS_MASK ((1 << PIN_STEP_A_BIT) | (1 << PIN_STEP_B_BIT))
#define DIRS_MASK ((1 << PIN_DIR_A_BIT) | (1 << PIN_DIR_B_BIT))
/* Leave the interrupt only when the next event is at least this far: else
 * it would come while the interrupt is still returning. */
#define LEAVE_CYCLES 48
/* A farther pair's first motor's bookkeeping runs before the second edge
 * when that edge is at least this far when the interrupt looks (the
 * bookkeeping and the wait's set-up take about 56); closer, it waits first
 * (waiting first whenever the edge was within FAST_CLOSE_CYCLES spent ~40 cycles of
 * each pair at 90-110 cycles spinning). */
#define PAIR_BK1 60
/* The waits end this many cycles after the event time, so that an edge
 * placed by waiting leaves when an interrupt's would (measured). */
#define SPIN_LAG 8
/* A close pair's (fb_fast.h) second edge leaves 14 + 3 * floor(board_gap / 3)
 * cycles after the first (the instructions between the two in the entry
 * path): board_gap = gap - CLOSE_OVH puts it within a cycle of the gap. */
#define CLOSE_OVH 13
/* fast_start() arms the first event of a block no closer than START_MARGIN
 * cycles after it reads the timer (its writes of OCR1A take about 20); a
 * start from a stop that close moves to START_SHIFT cycles after the read
 * (the shift takes about 60 more). */
#define START_MARGIN 48
#define START_SHIFT 128

#define S_(x) #x
#define S(x) S_(x)

/* Z+dst[i] += Z+src[i], 16 bits, the low byte by op ("add", or "adc" to take
 * the carry of the previous one in).  Leaves the sum in r18:r19.  Uses r18,
 * r19, r26, r27. */
#define ADD16_Z(dst, src, i, op) \
	"ldd r18, Z+" S(dst) "+2*" #i "\n\t" \
	"ldd r19, Z+" S(dst) "+2*" #i "+1\n\t" \
	"ldd r26, Z+" S(src) "+2*" #i "\n\t" \
	"ldd r27, Z+" S(src) "+2*" #i "+1\n\t" \
	op " r18, r26\n\tadc r19, r27\n\t" \
	"std Z+" S(dst) "+2*" #i ", r18\n\t" \
	"std Z+" S(dst) "+2*" #i "+1, r19\n\t"

/*
 * One motor's step bookkeeping (i = 0 A, 1 B): its steps left (the kept
 * record's left[i], which is the kept position's count too) and, unless
 * that was the last, its next time t.tf += q.qf, left in r18:r19; after the
 * last, GPIOR0's done bit of the motor is set instead.  The count goes down
 * by its low byte, the high byte only on a borrow or at a low 0 (two cycles
 * fewer a step than a 16-bit load, subtract and store; the busy flag covers
 * the two stores as it covered one).  Uses r18, r19, r26, r27.
 */
#define STEP_MOTOR(i, L) \
	"lds r26, %[keep]+" S(K_LEFT) "+2*" #i "\n\t" \
	"subi r26, 1\n\t" \
	"sts %[keep]+" S(K_LEFT) "+2*" #i ", r26\n\t" \
	"brcs " L "_b\n\t"           /* the low byte was 0: borrow */ \
	"breq " L "_z\n"              /* it is 0 now: the last step if the high byte is 0 */ \
	L "_t:\n\t" \
	ADD16_Z(O_TF, O_QF, i, "add") \
	ADD16_Z(O_T, O_Q, i, "adc") \
	"rjmp " L "_d\n" \
	L "_b:\n\t" \
	"lds r27, %[keep]+" S(K_LEFT) "+2*" #i "+1\n\t" \
	"dec r27\n\t" \
	"sts %[keep]+" S(K_LEFT) "+2*" #i "+1, r27\n\t" \
	"rjmp " L "_t\n" \
	L "_z:\n\t" \
	"lds r27, %[keep]+" S(K_LEFT) "+2*" #i "+1\n\t" \
	"tst r27\n\t" \
	"brne " L "_t\n\t" \
	"sbi %[gp0], " S(FL_ADONE) "+" #i "\n" \
	L "_d:\n\t"

/*
 * Start of the next block's motor i in the kept record (busy set), Z = that
 * block, r26 = its directions: all its steps go into off[i] (negative when
 * direction bit i is set) and into left[i], the ones not issued yet; the
 * motor's done bit in GPIOR0 is set when it has none.  Uses r24, r25, r27.
 */
#define AHEAD_MOTOR(i, L) \
	"ldd r24, Z+" S(O_CNT) "+2*" #i "\n\t" \
	"ldd r25, Z+" S(O_CNT) "+2*" #i "+1\n\t" \
	"sts %[keep]+" S(K_LEFT) "+2*" #i ", r24\n\t" \
	"sts %[keep]+" S(K_LEFT) "+2*" #i "+1, r25\n\t" \
	"cbi %[gp0], " S(FL_ADONE) "+" #i "\n\t" \
	"mov r27, r24\n\t" \
	"or r27, r25\n\t" \
	"brne " L "_l\n\t" \
	"sbi %[gp0], " S(FL_ADONE) "+" #i "\n" \
	L "_l:\n\t" \
	"sbrs r26, " #i "\n\t" \
	"rjmp " L "\n\t" \
	"com r25\n\tneg r24\n\tsbci r25, 0xff\n" \
	L ":\n\t" \
	"lds r27, %[keep]+" S(K_OFF) "+2*" #i "\n\t" \
	"add r24, r27\n\t" \
	"lds r27, %[keep]+" S(K_OFF) "+2*" #i "+1\n\t" \
	"adc r25, r27\n\t" \
	"sts %[keep]+" S(K_OFF) "+2*" #i ", r24\n\t" \
	"sts %[keep]+" S(K_OFF) "+2*" #i "+1, r25\n\t"

/*
 * The pick when the other motor is done (entered at Done): the block ends
 * when motor i is done too, else motor i's next step is the event (entered
 * at Arm with its time already in r18:r19).
 */
#define ALONE(i, Done, Arm) \
	Done ":\n\t" \
	"sbic %[gp0], " S(FL_ADONE) "+" #i "\n\t" \
	"rjmp fp_block_end\n\t" \
	"ldd r18, Z+" S(O_T) "+2*" #i "\n\t" \
	"ldd r19, Z+" S(O_T) "+2*" #i "+1\n" \
	Arm ":\n\t" \
	"ldi r24, 1 << (" S(STEP_A_BIT) "+(" #i ")*(" S(STEP_B_BIT) "-" S(STEP_A_BIT) "))\n\t" \
	"rjmp fp_arm\n"

/*
 * Wait until the timer reaches r18:r19 + SPIN_LAG (at once when past).  The
 * remaining wait is below 128 cycles, so the loop compares low bytes only
 * (5 cycles a turn).  Uses r26, r27.
 */
#define SPIN(L) \
	"lds r26, %[tl]\n\t" \
	"lds r27, %[th]\n\t" \
	"sub r26, r18\n\tsbc r27, r19\n\t" \
	"subi r26, " S(SPIN_LAG) "\n\tsbci r27, 0\n\t" \
	"brpl " L "_go\n\t" \
	"mov r27, r18\n\t" \
	"subi r27, -" S(SPIN_LAG) "\n" \
	L "_w:\n\t" \
	"lds r26, %[tl]\n\t" \
	"sub r26, r27\n\t" \
	"brmi " L "_w\n" \
	L "_go:\n\t"

/* The fast path; jumps to __vector_fb_step_slow (before saving anything) when the
 * pending event is the C path's. */
ISR(TIMER1_COMPA_vect, ISR_NAKED)
{
	__asm__ __volatile__(
		"sbic %[gp0], " S(FL_SLOW) "\n\t"
		"jmp __vector_fb_step_slow\n\t"
		"push r24\n\t"
		"in r24, %[gp1]\n\t"
		"sts %[keep]+" S(K_BUSY) ", r24\n\t"
		"out %[pind], r24\n\t"                 /* the edges */
		"sbic %[gp0], " S(FL_CLOSE) "\n\t"
		"rjmp fp_close_entry\n\t"
		"push r25\n\t"
		"in r25, __SREG__\n\t"
		"push r25\n\t"
		"push r18\n\tpush r19\n\tpush r26\n\tpush r27\n\tpush r30\n\tpush r31\n\t"
		"lds r30, %[cur]\n\t"
		"lds r31, %[cur]+1\n"
	"fp_edge_done:\n\t"
		"sbic %[gp0], " S(FL_PAIR) "\n\t"
		"rjmp fp_pair\n"
	/* ---- bookkeeping of the motors in r24 ---- */
	"fp_steps:\n\t"
		"sbrs r24, " S(STEP_A_BIT) "\n\t"
		"rjmp fp_steps_b\n\t"
		STEP_MOTOR(0, "sa")
		"sbrs r24, " S(STEP_B_BIT) "\n\t"
		"rjmp fp_pick_a\n"
	"fp_steps_b:\n\t"
		STEP_MOTOR(1, "sb")
	/* ---- pick the next event (fast_pick() in fb_fast.c); the motor
	 * stepped last has its next time in r18:r19 unless it is done ---- */
		"clr r25\n\t"
		"sts %[keep]+" S(K_BUSY) ", r25\n\t"
		"sbic %[gp0], " S(FL_BDONE) "\n\t"
		"rjmp fp_b_done\n\t"
		"sbic %[gp0], " S(FL_ADONE) "\n\t"
		"rjmp fp_arm_b\n\t"
		"movw r26, r18\n\t"                    /* tB */
		"ldd r18, Z+" S(O_T) "\n\t"
		"ldd r19, Z+" S(O_T) "+1\n\t"
		"rjmp fp_both\n"
	"fp_pick_a:\n\t"
		"clr r25\n\t"
		"sts %[keep]+" S(K_BUSY) ", r25\n\t"
		"sbic %[gp0], " S(FL_ADONE) "\n\t"
		"rjmp fp_a_done\n\t"
		"sbic %[gp0], " S(FL_BDONE) "\n\t"
		"rjmp fp_arm_a\n\t"
		"ldd r26, Z+" S(O_T) "+2\n\t"
		"ldd r27, Z+" S(O_T) "+3\n"
	"fp_both:\n\t"                                 /* r18:r19 = tA, r26:r27 = tB */
		"sub r26, r18\n\t"
		"sbc r27, r19\n\t"                     /* d = tB - tA */
		"brmi fp_b_first\n\t"
		"ldi r24, " S(1 << STEP_A_BIT) "\n\t"
		"brne 1f\n\t"
		"tst r26\n\t"
		"brne 1f\n\t"
		"ldi r24, " S(STEPS_MASK) "\n\t"            /* same time */
		"rjmp fp_arm\n"
	"1:\n\t"                                       /* A first, B d later */
		"cpi r26, " S(FAST_PAIR_CYCLES) "\n\t"
		"ldi r25, 0\n\t"
		"cpc r27, r25\n\t"
		"brsh fp_arm\n\t"
		"add r26, r18\n\t"
		"adc r27, r19\n\t"
		"ldi r25, " S(1 << STEP_B_BIT) "\n\t"
		"rjmp fp_pair_set\n"
	"fp_b_far:\n\t"
		"ldi r24, " S(1 << STEP_B_BIT) "\n\t"
		"rjmp fp_arm\n"
	"fp_b_first:\n\t"                              /* B first, A -d later */
		"movw r24, r18\n\t"                    /* tA */
		"add r18, r26\n\t"
		"adc r19, r27\n\t"                     /* r18:r19 = tB */
		"com r27\n\tneg r26\n\tsbci r27, 0xff\n\t" /* -d */
		"tst r27\n\t"
		"brne fp_b_far\n\t"
		"cpi r26, " S(FAST_PAIR_CYCLES) "\n\t"
		"brsh fp_b_far\n\t"
		"movw r26, r24\n\t"
		"ldi r24, " S(1 << STEP_B_BIT) "\n\t"
		"ldi r25, " S(1 << STEP_A_BIT) "\n"
	"fp_pair_set:\n\t"                             /* second edge: r26:r27, pins r25 */
		"sts %[t2], r26\n\t"
		"sts %[t2]+1, r27\n\t"
		"out %[gp2], r25\n\t"
		"sub r26, r18\n\t"                     /* the gap (< 150) */
		"cpi r26, " S(FAST_CLOSE_CYCLES) "\n\t"
		"brsh 3f\n\t"
		"cpi r26, " S(FAST_TINY_CYCLES) "\n\t"
		"brsh 1f\n\t"
		"or r24, r25\n\t"                     /* tiny: both at the later time */
		"lds r18, %[t2]\n\t"
		"lds r19, %[t2]+1\n\t"
		"rjmp fp_arm\n"
	"1:\n\t"
		"subi r26, " S(CLOSE_OVH) "\n\t"
		"brcc 2f\n\t"
		"clr r26\n"
	"2:\n\t"
		"sts %[gap], r26\n\t"
		"sbi %[gp0], " S(FL_CLOSE) "\n\t"
		"rjmp fp_arm\n"
	"3:\n\t"
		"sbi %[gp0], " S(FL_PAIR) "\n"
	/* ---- arm the next event: r18:r19 time, r24 pins ---- */
	"fp_arm:\n\t"
		"sts %[sched], r18\n\t"
		"sts %[sched]+1, r19\n\t"
		"out %[gp1], r24\n\t"
		"in r25, %[portd]\n\t"                 /* the fall: >= 40 cycles after the last edge */
		"andi r25, " S((~STEPS_MASK) & 0xff) "\n\t"
		"out %[portd], r25\n\t"
		"lds r26, %[tl]\n\t"
		"lds r27, %[th]\n\t"
		"sub r26, r18\n\t"
		"sbc r27, r19\n\t"                     /* now - t */
		"subi r26, lo8(-" S(LEAVE_CYCLES) ")\n\t"
		"sbci r27, hi8(-" S(LEAVE_CYCLES) ")\n\t"
		"brpl fp_cluster\n"
	"fp_ocr:\n\t"                                /* OCR1A := r18:r19, then leave */
		"tst r19\n\t"                          /* simavr: see ocr_value() */
		"brne 1f\n\t"
		"cpi r18, 8\n\t"
		"brsh 1f\n\t"
		"ldi r18, 8\n"
	"1:\n\t"
		"sts %[ocrh], r19\n\t"
		"sts %[ocrl], r18\n"
	"fp_exit:\n\t"
		"pop r31\n\tpop r30\n\tpop r27\n\tpop r26\n\tpop r19\n\tpop r18\n\t"
		"pop r25\n\t"
		"out __SREG__, r25\n\t"
		"pop r25\n\t"
		"pop r24\n\t"
		"reti\n"
		ALONE(1, "fp_a_done", "fp_arm_b")
		ALONE(0, "fp_b_done", "fp_arm_a")
	/* the pick from nothing in registers (a new block) */
	"fp_select:\n\t"
		"sbic %[gp0], " S(FL_ADONE) "\n\t"
		"rjmp fp_a_done\n\t"
		"ldd r18, Z+" S(O_T) "\n\t"
		"ldd r19, Z+" S(O_T) "+1\n\t"
		"sbic %[gp0], " S(FL_BDONE) "\n\t"
		"rjmp fp_arm_a\n\t"
		"ldd r26, Z+" S(O_T) "+2\n\t"
		"ldd r27, Z+" S(O_T) "+3\n\t"
		"rjmp fp_both\n"
	/* ---- the next event is too close to leave: wait for it here ---- */
	"fp_cluster:\n\t"
		"lds r26, %[tl]\n\t"
		"lds r27, %[th]\n\t"
		"sub r26, r18\n\t"
		"sbc r27, r19\n\t"
		"brmi 2f\n\t"                         /* overdue (catching up): */
		"ldi r25, 2\n"                         /* with the fall's path the pins stay low >= 2.3 us (the DRV8825 needs 1.9) */
	"1:\n\t"
		"dec r25\n\t"
		"brne 1b\n"
	"2:\n\t"
		SPIN("cl")
		"in r24, %[gp1]\n\t"
		"sts %[keep]+" S(K_BUSY) ", r24\n\t"
		"out %[pind], r24\n\t"
		"sbic %[gp0], " S(FL_CLOSE) "\n\t"
		"rjmp fp_close_cluster\n\t"
		"rjmp fp_edge_done\n"
	/* ---- a close pair: the second edge after a counted wait ---- */
	"fp_close_entry:\n\t"
		"push r25\n\t"
		"in r25, __SREG__\n\t"
		"push r25\n\t"
		"lds r25, %[gap]\n"
	"1:\n\t"
		"subi r25, 3\n\t"
		"brcc 1b\n\t"
		"in r25, %[gp2]\n\t"
		"out %[pind], r25\n\t"                /* the second edge */
		"or r24, r25\n\t"
		"cbi %[gp0], " S(FL_CLOSE) "\n\t"
		"push r18\n\tpush r19\n\tpush r26\n\tpush r27\n\tpush r30\n\tpush r31\n\t"
		"lds r30, %[cur]\n\t"
		"lds r31, %[cur]+1\n\t"
		"rjmp fp_close_done\n"
	"fp_close_cluster:\n\t"                       /* 5 cycles fewer before the wait */
		"lds r25, %[gap]\n\t"
		"subi r25, -5\n"
	"1:\n\t"
		"subi r25, 3\n\t"
		"brcc 1b\n\t"
		"in r25, %[gp2]\n\t"
		"out %[pind], r25\n\t"
		"or r24, r25\n\t"
		"cbi %[gp0], " S(FL_CLOSE) "\n"
	"fp_close_done:\n\t"
		"lds r18, %[t2]\n\t"                  /* now = the second edge */
		"lds r19, %[t2]+1\n\t"
		"sts %[sched], r18\n\t"
		"sts %[sched]+1, r19\n\t"
		"rjmp fp_steps\n"
	/* ---- a pair: the second edge at board_t2 ---- */
	"fp_pair:\n\t"
		"cbi %[gp0], " S(FL_PAIR) "\n\t"
		"lds r18, %[t2]\n\t"
		"lds r19, %[t2]+1\n\t"
		"lds r26, %[tl]\n\t"
		"lds r27, %[th]\n\t"
		"sub r26, r18\n\t"
		"sbc r27, r19\n\t"                     /* now - t2 */
		"subi r26, lo8(-" S(PAIR_BK1) ")\n\t"
		"sbci r27, hi8(-" S(PAIR_BK1) ")\n\t"
		"brmi 3f\n\t"
		"rjmp fp_pair_close\n"
	"3:\n\t"
		"sbrs r24, " S(STEP_A_BIT) "\n\t"      /* the first motor's bookkeeping first */
		"rjmp 1f\n\t"
		STEP_MOTOR(0, "pa")
		"rjmp 2f\n"
	"1:\n\t"
		STEP_MOTOR(1, "pb")
	"2:\n\t"
		"lds r18, %[t2]\n\t"
		"lds r19, %[t2]+1\n\t"
		SPIN("pf")
		"in r24, %[gp2]\n\t"
		"out %[pind], r24\n\t"
		"sts %[sched], r18\n\t"              /* now = the second edge */
		"sts %[sched]+1, r19\n\t"
		"rjmp fp_steps\n"
	"fp_pair_close:\n\t"
		SPIN("pc")
		"in r25, %[gp2]\n\t"
		"out %[pind], r25\n\t"
		"or r24, r25\n\t"
		"sts %[sched], r18\n\t"
		"sts %[sched]+1, r19\n\t"
		"rjmp fp_steps\n"
	/* ---- both motors done: the block ends tail cycles after this event ---- */
	"fp_block_end:\n\t"
		"lds r18, %[sched]\n\t"
		"lds r19, %[sched]+1\n\t"
		"ldd r26, Z+" S(O_TAIL) "\n\t"
		"ldd r27, Z+" S(O_TAIL) "+1\n\t"
		"add r18, r26\n\t"
		"adc r19, r27\n\t"                     /* r18:r19 = the block's end */
		"ldd r25, Z+" S(O_POWER) "\n\t"
		"movw r26, r30\n\t"                    /* X = this block */
		"adiw r30, " S(BLOCK_SIZE) "\n\t"       /* Z = the next one */
		"ldi r24, hi8(%[queue]+" S(BLOCK_SIZE * CFG_QUEUE_SIZE) ")\n\t"
		"cpi r30, lo8(%[queue]+" S(BLOCK_SIZE * CFG_QUEUE_SIZE) ")\n\t"
		"cpc r31, r24\n\t"
		"brne 1f\n\t"
		"ldi r30, lo8(%[queue])\n\t"
		"ldi r31, hi8(%[queue])\n"
	"1:\n\t"
		"ldd r24, Z+" S(O_FAST) "\n\t"
		"sbrs r24, 0\n\t"
		"rjmp fp_to_c\n\t"
		"ldd r24, Z+" S(O_POWER) "\n\t"
		"cpse r24, r25\n\t"
		"rjmp fp_to_c\n\t"
		"lds r24, %[qtail]\n\t"
		"inc r24\n\t"
		"lds r25, %[qhead]\n\t"
		"cp r24, r25\n\t"
		"brne 1f\n\t"
		"rjmp fp_to_c\n"
	"1:\n\t"
		/* the next block is queued, fast, same power: switch to it */
		"sts %[qtail], r24\n\t"
		"sts %[cur], r30\n\t"
		"sts %[cur]+1, r31\n\t"
		"ldi r24, 1\n\t"
		"sts %[keep]+" S(K_BUSY) ", r24\n\t"
		/* Ln done := the ended block's line, ndone := its complement */
		"adiw r26, " S(O_LINE) "\n\t"
		"ld r25, X+\n\tsts %[keep]+" S(K_DONE) ", r25\n\tcom r25\n\tsts %[keep]+" S(K_NDONE) ", r25\n\t"
		"ld r25, X+\n\tsts %[keep]+" S(K_DONE) "+1, r25\n\tcom r25\n\tsts %[keep]+" S(K_NDONE) "+1, r25\n\t"
		"ld r25, X+\n\tsts %[keep]+" S(K_DONE) "+2, r25\n\tcom r25\n\tsts %[keep]+" S(K_NDONE) "+2, r25\n\t"
		"ld r25, X+\n\tsts %[keep]+" S(K_DONE) "+3, r25\n\tcom r25\n\tsts %[keep]+" S(K_NDONE) "+3, r25\n\t"
		/* the next block's steps, ahead, into off and left */
		"ldd r26, Z+" S(O_DIRS) "\n\t"
		"sts %[keep]+" S(K_FDIRS) ", r26\n\t"
		AHEAD_MOTOR(0, "ah0")
		AHEAD_MOTOR(1, "ah1")
		"clr r25\n\t"
		"sts %[keep]+" S(K_BUSY) ", r25\n\t"
		/* direction pins: toggle the ones that change */
		"ldd r24, Z+" S(O_PDIRS) "\n\t"
		"in r25, %[portd]\n\t"
		"eor r24, r25\n\t"
		"andi r24, " S(DIRS_MASK) "\n\t"
		"out %[pind], r24\n\t"
		/* its times from its start (the end of this one) to timer times */
		"ldd r24, Z+" S(O_T) "\n\tldd r25, Z+" S(O_T) "+1\n\t"
		"add r24, r18\n\tadc r25, r19\n\t"
		"std Z+" S(O_T) ", r24\n\tstd Z+" S(O_T) "+1, r25\n\t"
		"ldd r24, Z+" S(O_T) "+2\n\tldd r25, Z+" S(O_T) "+3\n\t"
		"add r24, r18\n\tadc r25, r19\n\t"
		"std Z+" S(O_T) "+2, r24\n\tstd Z+" S(O_T) "+3, r25\n\t"
		"rjmp fp_select\n"
	/* ---- the C path takes the block's end, at its exact time ---- */
	"fp_to_c:\n\t"
		"sbi %[gp0], " S(FL_SLOW) "\n\t"
		"sbi %[gp0], " S(FL_ENDED) "\n\t"
		"clr r24\n\t"
		"out %[gp1], r24\n\t"
		"sts %[sched], r18\n\t"
		"sts %[sched]+1, r19\n\t"
		"in r25, %[portd]\n\t"
		"andi r25, " S((~STEPS_MASK) & 0xff) "\n\t"
		"out %[portd], r25\n\t"
		"lds r26, %[tl]\n\t"                  /* at least 24 cycles from now */
		"lds r27, %[th]\n\t"
		"adiw r26, 24\n\t"
		"movw r24, r26\n\t"
		"sub r26, r18\n\t"
		"sbc r27, r19\n\t"
		"brmi 1f\n\t"
		"movw r18, r24\n"
	"1:\n\t"
		"rjmp fp_ocr\n"
		:
		: [gp0] "I" (_SFR_IO_ADDR(GPIOR0)), [gp1] "I" (_SFR_IO_ADDR(GPIOR1)),
		  [gp2] "I" (_SFR_IO_ADDR(GPIOR2)), [pind] "I" (_SFR_IO_ADDR(PIND)),
		  [portd] "I" (_SFR_IO_ADDR(PORTD)),
		  [tl] "n" (_SFR_MEM_ADDR(TCNT1L)), [th] "n" (_SFR_MEM_ADDR(TCNT1H)),
		  [ocrl] "n" (_SFR_MEM_ADDR(OCR1AL)), [ocrh] "n" (_SFR_MEM_ADDR(OCR1AH)),
		  [keep] "i" (&board_keep), [cur] "i" (&mo_state.cur),
		  [qtail] "i" (&mo_state.tail), [qhead] "i" (&mo_state.head),
		  [queue] "i" (mo_state.queue),
		  [sched] "i" (&board_sched), [t2] "i" (&board_t2), [gap] "i" (&board_gap));
}

/* simavr 1.6 arms a compare at OCR1A < ~5 only if it handles the timer
 * overflow within that many cycles, and otherwise misses it by a whole
 * period (65536 cycles).  A match up to 7 cycles late costs nothing on
 * hardware, and the schedule keeps the exact time in board_sched. */
static inline uint16_t ocr_value(uint16_t t)
{
	return t >= 8u ? t : 8u;
}

static uint8_t step_pins(uint8_t motors)
{
	return (uint8_t)(((motors & 1u) ? (1u << STEP_A_BIT) : 0u) |
			 ((motors & 2u) ? (1u << STEP_B_BIT) : 0u));
}

/* Start the fast block mo_event() just started at timer time base. */
static void fast_start(uint16_t base)
{
	fast_event_t e;
	uint8_t rest = mo_fast_begin(base, &e);
	uint16_t t = e.t, t2 = e.t2;
	uint8_t pins = step_pins(e.bits), flags = 0;
	GPIOR2 = step_pins(e.bits2);
	/* as the assembly's fp_pair_set */
	switch (fast_kind(&e)) {
	case FAST_TINY:
		pins = step_pins((uint8_t)(e.bits | e.bits2));
		t = t2;
		break;
	case FAST_CLOSE: {
		uint16_t gap = (uint16_t)(t2 - t);
		board_gap = (uint8_t)(gap > CLOSE_OVH ? gap - CLOSE_OVH : 0u);
		flags = (uint8_t)(1u << FL_CLOSE);
		break;
	}
	case FAST_PAIR:
		flags = (uint8_t)(1u << FL_PAIR);
		break;
	default:
		break;
	}
	GPIOR1 = pins;
	if (!mo_state.cur->f.cnt[0])
		flags |= (uint8_t)(1u << FL_ADONE);
	if (!mo_state.cur->f.cnt[1])
		flags |= (uint8_t)(1u << FL_BDONE);
	GPIOR0 = flags;
	/* A start from a stop whose first step the C path has (nearly) run
	 * past (boundary() and the first block's setup take longer than half a
	 * step interval at high rates) starts the whole block later: no step of
	 * it is late and the motors are at rest until then.  Mid-job the
	 * schedule stays exact: the interrupt comes as soon as it can and the
	 * fast path catches up (an overdue step waits >= 2 us low).  TCNT1 is
	 * read last, just before OCR1A is written: a compare armed in the past
	 * would wait a whole timer period. */
	uint16_t now = TCNT1, arm = t;
	if ((int16_t)(t - now) < START_MARGIN) {
		arm = (uint16_t)(now + START_MARGIN);
		if (rest) {
			uint16_t delta = (uint16_t)(now + START_SHIFT - t);
			mo_fast_shift(delta);
			t = (uint16_t)(t + delta);
			t2 = (uint16_t)(t2 + delta);
			arm = t;
		}
	}
	board_t2 = t2;
	board_sched = t;
	OCR1A = ocr_value(arm);
}

/* The C path: a complete interrupt of its own, entered by a jump from the
 * vector before anything was saved. */
/* named __vector_* so that avr-gcc (its LTO link too) takes the handler
 * attributes without a misspelled-ISR warning */
void __vector_fb_step_slow(void) __attribute__((signal, used, externally_visible));
void __vector_fb_step_slow(void)
{
	if (GPIOR0 & (1u << FL_ENDED))
		mo_fast_end();
	GPIOR0 = (uint8_t)(1u << FL_SLOW);
	uint16_t t = board_sched;
	for (;;) {
		uint16_t t0 = TCNT1;
		uint16_t d = mo_event();
		while ((uint16_t)(TCNT1 - t0) < PULSE_CYCLES)
			;
		BOARD_STEP_PORT &= (uint8_t)~BOARD_STEP_PINS;
		if (!d) {
			TIMSK1 &= (uint8_t)~(1u << OCIE1A);
			break;
		}
		if (d == MO_FAST) {
			fast_start(t);
			break;
		}
		t = (uint16_t)(t + d);
		if ((int16_t)(t - TCNT1) > NEAR_CYCLES) {
			board_sched = t;
			OCR1A = ocr_value(t);
			break;
		}
		while ((int16_t)(TCNT1 - t) < 0)
			;
	}
}

void board_timer_start(uint16_t delay_cycles)
{
	uint8_t s = board_irq_save();
	paused = 0;
	GPIOR0 = (uint8_t)(1u << FL_SLOW);  /* a start is a block boundary */
	GPIOR1 = 0;
	board_sched = (uint16_t)(TCNT1 + delay_cycles);
	OCR1A = ocr_value(board_sched);
	TIFR1 = (uint8_t)(1u << OCF1A);
	TIMSK1 |= (uint8_t)(1u << OCIE1A);
	board_irq_restore(s);
}

void board_timer_stop(void)
{
	uint8_t s = board_irq_save();
	TIMSK1 &= (uint8_t)~(1u << OCIE1A);
	paused = 0;
	GPIOR0 = (uint8_t)(1u << FL_SLOW);
	GPIOR1 = 0;
	BOARD_STEP_PORT &= (uint8_t)~BOARD_STEP_PINS;
	board_irq_restore(s);
}

void board_timer_pause(void)
{
	uint8_t s = board_irq_save();
	if (!paused && (TIMSK1 & (1u << OCIE1A))) {
		TIMSK1 &= (uint8_t)~(1u << OCIE1A);
		uint16_t rem = (uint16_t)(board_sched - TCNT1);
		if ((TIFR1 & (1u << OCF1A)) || (int16_t)rem < 0)
			rem = 0;  /* due now (or matched already) */
		paused_rem = rem;
		paused = 1;
	}
	board_irq_restore(s);
}

void board_timer_resume(void)
{
	uint8_t s = board_irq_save();
	if (paused) {
		paused = 0;
		uint16_t t = (uint16_t)(TCNT1 + paused_rem + 64u);
		/* the whole timeline moves: the fast block's stored times too */
		uint16_t delta = (uint16_t)(t - board_sched);
		mo_fast_shift(delta);
		board_t2 = (uint16_t)(board_t2 + delta);
		board_sched = t;
		OCR1A = ocr_value(t);
		TIFR1 = (uint8_t)(1u << OCF1A);
		TIMSK1 |= (uint8_t)(1u << OCIE1A);
	}
	board_irq_restore(s);
}

#endif
