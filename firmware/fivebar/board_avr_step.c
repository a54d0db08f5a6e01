/*
 * board_avr_step.c - the step interrupt of the ATmega328P (Timer1 compare A),
 * its C half.
 *
 * Timer1 runs free at F_CPU; OCR1A holds the exact timer time of the pending
 * event (board_step.sched), so interrupt latency never accumulates.  An event
 * is handled by one of two paths, chosen by GPIOR0 bit BOARD_FL_SLOW:
 *
 *  - the fast path, hand-written assembly in board_avr_step.S, for blocks
 *    with the fast form (fb_fast.h, whose C it follows);
 *  - the C path, here (__vector_fb_step_slow, mo_event() in fb_motion.c),
 *    for everything else: block boundaries the fast path does not take (an
 *    empty queue, a laser power change, a C-form block, a G92/M17/M18/M280),
 *    homing, endstop supervision, slow motors, long waits.  It starts a
 *    fast block with mo_fast_begin() and hands it to the fast path
 *    (fast_start).
 *
 * The step pins rise by writing PIND (the fast path) or PORTD (the C path)
 * and fall together by a PORTD write at least PULSE_CYCLES later.
 */
#ifdef __AVR__

#include <avr/io.h>
#include <avr/interrupt.h>
#include "board.h"
#include "board_avr_step.h"
#include "config.h"
#include "fb_fast.h"
#include "fb_motion.h"
#include "fb_raster.h"

/* C path: the pins go low at least this many cycles after its event starts
 * (>= 2.5 us high, measured in the simavr trace). */
#define PULSE_CYCLES 56u
/* C path: events closer than this run in the same interrupt (busy-waiting
 * until their exact cycle) instead of leaving and re-entering it. */
#define NEAR_CYCLES 160
/* fast_start() arms the first event of a block no closer than START_MARGIN
 * cycles after it reads the timer (its writes of OCR1A take about 20); a
 * start from a stop that close moves to START_SHIFT cycles after the read
 * (the shift takes about 60 more). */
#define START_MARGIN 48
#define START_SHIFT 128

/* The pixel interrupt (below). */
/*
 * Its compare fires PX_LEAD cycles before the change is due: the cycles the
 * interrupt takes from its compare to the laser write (entry, the registers'
 * save, px_event() up to board_laser()), so that the write lands on the
 * change's time (the schedule, px_sched, keeps the exact time).  Measured in
 * the emulator (fbsim -t's lwrite events against the planned times, fast-path
 * scans of configs/raster-fast.toml): 51 cycles at the least, 106 the
 * median; docs/raster.md.
 */
#define PX_LEAD 96u
/*
 * A scan started on the C path (a block the fast path cannot take: the
 * default profile's G7 blocks, one motor's steps farther apart than
 * FAST_QMAX) puts its step edges this many cycles after their timer times
 * more than the fast path does (the C path's entry and mo_event() up to
 * board_steps_high(): the due time to the edge); its pixel timeline starts
 * as much later, so that changes and steps keep their planned distance.
 * Measured as PX_LEAD: the writes of a C-path scan (the default profile) came
 * a median 3.3 us before their planned times, a fast-path scan's 6.6 us
 * after, with the same interrupt in between: ~158 cycles, 144 taken (with
 * both, the default profile's changes fall a median 0.02 us from their
 * crossings).  Then 32 cycles came off the C path's entry (113 to 81 from
 * the vector's jump to mo_event()'s call, counted on the disassembly: px_start
 * and fast_start no longer inlined, 9 registers fewer saved, no frame), so its
 * edges come that much sooner: 144 - 32.  Stack: the nesting below adds one
 * pixel interrupt frame (2 + 22 registers + 4 bytes of locals + 2 for its
 * call of advance(): 30 bytes) on top of this one (benchmarks/stack.py).
 */
#define PX_C_LAG 112u

/*
 * A resume restarts the held timeline this many cycles after its read of
 * TCNT1: more than the cycles until its compare writes (counted on the
 * disassembly: ~76 to the step compare, after the shift of the fast block's
 * times; ~116 to the pixel compare, which fires PX_LEAD early, so it needs
 * 116 + PX_LEAD).
 * With 64, a step due within ~14 cycles of the hold (or already due, its
 * flag set) had its compare written after the timer passed it and waited a
 * whole timer period: the steps 4.1 ms late, a raster scan's burn that much
 * ahead of the arms for the rest of its row (tests/firmware/
 * test_hold_timeline_sim.py holds at random instants and checks every
 * resume).  The timeline restarting 16 us after the resume (12 more than
 * before) is nothing a hold notices.
 */
#define RESUME_CYCLES 256u

#define STEP_A_BIT PIN_STEP_A_BIT
#define STEP_B_BIT PIN_STEP_B_BIT

/* The pending event (board_avr_step.h); the assembly half reads and writes
 * it too, by name, hence not static. */
board_step_t board_step;
static uint16_t paused_rem, paused_at;  /* paused_at: TCNT1 when held */
static uint8_t paused;
/* the pixel timer (compare B): its pending event's exact time, and while
 * paused (a hold) the cycles it had left; px_paused: it was on */
static uint16_t px_sched, px_paused_rem;
static uint8_t px_paused;
/* px_lagged: the pixel timeline runs PX_C_LAG behind the plan, as the C
 * path's step edges do (the block running is in the C form) */
static uint8_t px_lagged;
static void board_px_shift(uint16_t delta);
static void board_px_lag(uint8_t lagged);

/* simavr 1.6 arms a compare at OCR1A < ~5 only if it handles the timer
 * overflow within that many cycles, and otherwise misses it by a whole
 * period (65536 cycles).  A match up to 7 cycles late costs nothing on
 * hardware, and the schedule keeps the exact time in board_step.sched. */
static inline uint16_t ocr_value(uint16_t t)
{
	return t >= 8u ? t : 8u;
}

static uint8_t step_pins(uint8_t motors)
{
	return (uint8_t)(((motors & 1u) ? (1u << STEP_A_BIT) : 0u) |
			 ((motors & 2u) ? (1u << STEP_B_BIT) : 0u));
}

/* Start the fast block mo_event() just started at timer time base; returns
 * how much later it really starts (0, or the shift of a start from a stop
 * whose first step the C path had run past). */
/* Not inlined (nor px_start, fb_raster.c): their locals and registers would
 * be the C path's, saved by its prologue on every event and kept on the stack
 * through mo_event() and the pixel interrupt nested in it, the stack's deepest
 * point (13 bytes: 38 to 25 a frame; benchmarks/stack.py). */
static __attribute__((noinline)) uint16_t fast_start(uint16_t base)
{
	fast_event_t e;
	uint8_t rest = mo_fast_begin(base, &e);
	uint16_t shift = 0;
	uint16_t t = e.t, t2 = e.t2;
	uint8_t pins = step_pins(e.bits), flags = 0;
	GPIOR2 = step_pins(e.bits2);
	/* how the assembly's fp_pair_set issues the pair */
	switch (fast_kind(&e)) {
	case FAST_TINY:
		pins = step_pins((uint8_t)(e.bits | e.bits2));
		t = t2;
		break;
	case FAST_CLOSE: {
		uint16_t gap = (uint16_t)(t2 - t);
		board_step.gap = (uint8_t)(gap > BOARD_CLOSE_OVH ? gap - BOARD_CLOSE_OVH : 0u);
		flags = (uint8_t)(1u << BOARD_FL_CLOSE);
		break;
	}
	case FAST_PAIR:
		flags = (uint8_t)(1u << BOARD_FL_PAIR);
		break;
	default:
		break;
	}
	GPIOR1 = pins;
	if (!mo_state.cur->f.cnt[0])
		flags |= (uint8_t)(1u << BOARD_FL_ADONE);
	if (!mo_state.cur->f.cnt[1])
		flags |= (uint8_t)(1u << BOARD_FL_BDONE);
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
			shift = delta;
		}
	}
	board_step.t2 = t2;
	board_step.sched = t;
	OCR1A = ocr_value(arm);
	return shift;
}

/*
 * mo_event() with the pixel interrupt let in (a scan runs: OCIE1B set).  The
 * C path takes 400-480 cycles an event (measured with fbsim -D: the due time
 * to the OCR1A write), and a power change due in it waited for all of it: on
 * the default profile every G7 block runs on the C path (one motor's steps
 * are more than FAST_QMAX apart), and 2 % of its changes came 20-55 us late.
 * So the other sources are masked (the serial interrupts' enables in UCSR0B,
 * Timer0's in TIMSK0, this interrupt's own OCIE1A: they wait as long as they
 * waited before) and interrupts are enabled: only the pixel interrupt can
 * come in.  mo_event() makes its changes of the pixel timeline and the laser
 * with interrupts off (fb_motion.c).  Nothing else either side touches is
 * shared: the pixel interrupt writes mo_state.px, OCR1B, TIMSK1's OCIE1B and
 * the laser.  Stack: one pixel interrupt frame more at most (30 bytes), on
 * top of this one (it cannot nest in itself).  Without a scan, mo_event()
 * as before.
 */
static uint16_t event_px_nested(void)
{
	uint8_t m0 = TIMSK0, ub = UCSR0B;
	TIMSK0 = 0;
	UCSR0B = (uint8_t)(ub & (uint8_t)~((1u << RXCIE0) | (1u << UDRIE0)));
	TIMSK1 &= (uint8_t)~(1u << OCIE1A);
	sei();
	uint16_t d = mo_event();
	cli();
	TIMSK1 |= (uint8_t)(1u << OCIE1A);
	UCSR0B = ub;
	TIMSK0 = m0;
	return d;
}

/* The C path: a complete interrupt of its own, entered by a jump from the
 * vector (board_avr_step.S) before anything was saved; named __vector_* so
 * that avr-gcc (its LTO link too) takes the handler attributes without a
 * misspelled-ISR warning. */
void __vector_fb_step_slow(void) __attribute__((signal, used, externally_visible));
void __vector_fb_step_slow(void)
{
	if (GPIOR0 & (1u << BOARD_FL_ENDED))
		mo_fast_end();
	GPIOR0 = (uint8_t)(1u << BOARD_FL_SLOW);
	uint16_t t = board_step.sched;
	for (;;) {
		uint16_t t0 = TCNT1;
		uint16_t d = (TIMSK1 & (1u << OCIE1B)) ? event_px_nested() : mo_event();
		while ((uint16_t)(TCNT1 - t0) < PULSE_CYCLES)
			;
		BOARD_STEP_PORT &= (uint8_t)~BOARD_STEP_PINS;
		if (!d) {
			TIMSK1 &= (uint8_t)~(1u << OCIE1A);
			break;
		}
		/* a scan's first block starts at t: the pixel timeline first, so that
		 * fast_start() arms the steps after its cycles (a compare armed in
		 * the past waits a whole timer period) */
		if (mo_state.px.pending) {
			px_lagged = d != MO_FAST;
			px_start(px_lagged ? (uint16_t)(t + PX_C_LAG) : t);
		} else if ((d == MO_FAST) == px_lagged) {
			board_px_lag(d != MO_FAST);  /* a scan's block of the other form */
		}
		if (d == MO_FAST) {
			uint16_t shift = fast_start(t);
			if (shift)
				board_px_shift(shift);  /* the block starts later: its pixels too */
			break;
		}
		t = (uint16_t)(t + d);
		if ((int16_t)(t - TCNT1) > NEAR_CYCLES) {
			board_step.sched = t;
			OCR1A = ocr_value(t);
			break;
		}
		while ((int16_t)(TCNT1 - t) < 0)
			;
	}
}

/*
 * The pixel interrupt (raster scans, fb_raster.c): Timer1 compare B at the
 * exact time of a pixel change or a chained wait.  An event its own delay
 * or a step interrupt made late is handled at once, and one due within
 * PX_NEAR cycles too (a compare armed at or before TCNT1 would wait a whole
 * timer period).  OC1B's pin (D10, endstop B) stays disconnected: only the
 * interrupt is used.
 */
#define PX_NEAR 24
static void px_arm_at(uint16_t t)
{
	px_sched = t;
	OCR1B = ocr_value((uint16_t)(t - PX_LEAD));
}

ISR(TIMER1_COMPB_vect)
{
	for (;;) {
		uint16_t d = px_event();
		if (!d) {
			TIMSK1 &= (uint8_t)~(1u << OCIE1B);
			return;
		}
		uint16_t t = (uint16_t)(px_sched + d);
		uint16_t fire = (uint16_t)(t - PX_LEAD);
		if ((int16_t)(fire - TCNT1) >= PX_NEAR) {
			px_arm_at(t);
			return;
		}
		/* too close to leave: handled here.  OCR1B is not written for it: a
		 * compare the timer passes while we wait would set the flag and run
		 * the event a second time after the return */
		px_sched = t;
		while ((int16_t)(TCNT1 - fire) < 0)
			;
	}
}

void board_px_arm(uint16_t t)
{
	uint8_t s = board_irq_save();
	if (paused) {
		/* held: the event waits for the resume, its distance from the
		 * timeline's frozen "now" kept (board.h) */
		uint16_t rem = (uint16_t)(t - paused_at);
		px_sched = t;
		px_paused_rem = (int16_t)rem < 0 ? 0u : rem;
		px_paused = 1;
		board_irq_restore(s);
		return;
	}
	/* the schedule keeps t (the events after it follow from it); the compare
	 * comes at once when t is past or too close */
	uint16_t fire = (uint16_t)(t - PX_LEAD);
	uint16_t at = (int16_t)(fire - TCNT1) < PX_NEAR ? (uint16_t)(TCNT1 + PX_NEAR) : fire;
	px_sched = t;
	OCR1B = ocr_value(at);
	TIFR1 = (uint8_t)(1u << OCF1B);
	TIMSK1 |= (uint8_t)(1u << OCIE1B);
	px_paused = 0;
	board_irq_restore(s);
}

void board_px_stop(void)
{
	uint8_t s = board_irq_save();
	TIMSK1 &= (uint8_t)~(1u << OCIE1B);
	px_paused = 0;
	board_irq_restore(s);
}

/* The pixel timeline moves delta cycles later (its scan's first block was
 * started later, fast_start). */
static void board_px_shift(uint16_t delta)
{
	if (TIMSK1 & (1u << OCIE1B))
		px_arm_at((uint16_t)(px_sched + delta));
}

/*
 * A scan's blocks change form (its ramp's slow pieces are in the C form, its
 * cruise in the fast form, and a motor slowing below FAST_QMAX mid-scan
 * makes C-form pieces there): its timeline moves PX_C_LAG later or earlier
 * with the step edges, so that changes and steps keep their planned
 * distance.  (Lagged at the scan's start and never moved back, the changes
 * of a scan whose ramp began on the C path came ~7 us late through its whole
 * image, and its first pixel, due at the ramp's fast block's start, up to
 * 21.6 us: measured on configs/raster-fast.toml, docs/raster.md.)  A change
 * moved into the past is run at once.  Without a running timeline only the
 * state changes.
 */
static void board_px_lag(uint8_t lagged)
{
	px_lagged = lagged;
	if (!(TIMSK1 & (1u << OCIE1B)))
		return;
	uint16_t t = (uint16_t)(px_sched + (lagged ? PX_C_LAG : (uint16_t)-PX_C_LAG));
	uint16_t fire = (uint16_t)(t - PX_LEAD);
	px_sched = t;
	if ((int16_t)(fire - TCNT1) < PX_NEAR) {
		OCR1B = ocr_value((uint16_t)(TCNT1 + PX_NEAR));  /* a flag already set runs it */
		return;
	}
	OCR1B = ocr_value(fire);
	TIFR1 = (uint8_t)(1u << OCF1B);  /* set for the old time */
}

uint16_t board_px_sched(void) { return px_sched; }
uint16_t board_px_now(void) { return paused ? paused_at : TCNT1; }

void board_timer_start(uint16_t delay_cycles)
{
	uint8_t s = board_irq_save();
	paused = 0;
	GPIOR0 = (uint8_t)(1u << BOARD_FL_SLOW);  /* a start is a block boundary */
	GPIOR1 = 0;
	board_step.sched = (uint16_t)(TCNT1 + delay_cycles);
	OCR1A = ocr_value(board_step.sched);
	TIFR1 = (uint8_t)(1u << OCF1A);
	TIMSK1 |= (uint8_t)(1u << OCIE1A);
	board_irq_restore(s);
}

void board_timer_stop(void)
{
	uint8_t s = board_irq_save();
	TIMSK1 &= (uint8_t)~((1u << OCIE1A) | (1u << OCIE1B));
	px_paused = 0;
	paused = 0;
	GPIOR0 = (uint8_t)(1u << BOARD_FL_SLOW);
	GPIOR1 = 0;
	BOARD_STEP_PORT &= (uint8_t)~BOARD_STEP_PINS;
	board_irq_restore(s);
}

void board_timer_pause(void)
{
	uint8_t s = board_irq_save();
	if (!paused && (TIMSK1 & (1u << OCIE1A))) {
		TIMSK1 &= (uint8_t)~(1u << OCIE1A);
		paused_at = TCNT1;
		uint16_t rem = (uint16_t)(board_step.sched - paused_at);
		if ((TIFR1 & (1u << OCF1A)) || (int16_t)rem < 0)
			rem = 0;  /* due now (or matched already) */
		paused_rem = rem;
		paused = 1;
		if (TIMSK1 & (1u << OCIE1B)) {
			TIMSK1 &= (uint8_t)~(1u << OCIE1B);
			/* its compare fires PX_LEAD early: a set flag does not mean
			 * the change is due, px_sched says when it is */
			rem = (uint16_t)(px_sched - paused_at);
			if ((int16_t)rem < 0)
				rem = 0;
			px_paused_rem = rem;
			px_paused = 1;
		}
	}
	board_irq_restore(s);
}

void board_timer_resume(void)
{
	uint8_t s = board_irq_save();
	if (paused) {
		paused = 0;
		uint16_t t = (uint16_t)(TCNT1 + paused_rem + RESUME_CYCLES);
		/* the whole timeline moves: the fast block's stored times too */
		uint16_t delta = (uint16_t)(t - board_step.sched);
		mo_fast_shift(delta);
		board_step.t2 = (uint16_t)(board_step.t2 + delta);
		board_step.sched = t;
		OCR1A = ocr_value(t);
		TIFR1 = (uint8_t)(1u << OCF1A);
		TIMSK1 |= (uint8_t)(1u << OCIE1A);
		if (px_paused) {
			/* the pixel timeline moves with the steps' (same delta) */
			px_paused = 0;
			px_arm_at((uint16_t)(t + (uint16_t)(px_paused_rem - paused_rem)));
			TIFR1 = (uint8_t)(1u << OCF1B);
			TIMSK1 |= (uint8_t)(1u << OCIE1B);
		}
	}
	board_irq_restore(s);
}

#endif
