/*
 * fb_motion.h - segment queue and the integer DDA step generator.
 *
 * The main loop prepares blocks (all divisions happen here, outside the
 * interrupt) and pushes them; the step interrupt pops them and calls
 * mo_event() at each scheduled event.  Each segment of C cycles with n steps
 * on a motor puts step k (1..n) at cycle floor((2k-1)*C / (2n)) after the
 * segment start: evenly spread, centred, and summing to exactly n steps in
 * exactly C cycles.  Segments follow each other with no gap.
 */
#ifndef FB_MOTION_H
#define FB_MOTION_H

#include <stdint.h>
#include "config.h"
#include "fb_fast.h"
#include "fb_raster.h"

enum mo_block_type {
	MO_BLK_MOVE = 0,   /* steps both motors over a duration */
	MO_BLK_HOME,       /* like MOVE, but each motor stops at its endstop */
	MO_BLK_SETPOS,     /* G92: position := n[] (as int32) */
	MO_BLK_ENABLE,     /* M17 */
	MO_BLK_DISABLE,    /* M18 */
	MO_BLK_PEN,        /* M280: servo to q[0] us at q[1] per frame, then a dwell */
	MO_BLK_RASTER,     /* G7: a MOVE of a raster scan; the pixel interrupt owns the
			    * laser (fb_raster.h); power holds the scan's id */
	MO_BLK_SCAN        /* G7: the first MOVE of a scan (its timeline starts here) */
};

/* mo_block_t.fast: 0 the C form; else the fast form.  The fast path switches
 * from a running fast block into the next only when the next has
 * MO_FAST_SWITCH_BIT, both have the same MO_FAST_RASTER_BIT and the same
 * power (board_avr_step.S): plain moves into plain moves, a scan's blocks
 * into its later blocks (power holds the scan id).  A scan's first block
 * starts through the C path, which tells the pixel interrupt its time. */
#define MO_FAST_SWITCH_BIT 0
#define MO_FAST_RASTER_BIT 2
#define MO_FAST_PLAIN 1u    /* switch bit */
#define MO_FAST_SCAN 4u     /* raster bit: entered through the C path */
#define MO_FAST_RASTER 5u   /* both */
#define MO_FAST_FORMED 0x80u /* between mo_prepare_fast and mo_seal: the fast
			      * form is filled, its kind not yet given */

/*
 * One queue entry.  The main loop fills every field (all divisions happen
 * there); while the block executes, the step interrupt updates next[] and
 * err[] (or the fast form's t and tf) in place, so starting a segment
 * copies nothing.
 * For MO_BLK_SETPOS the new position is in q[] (as int32).
 */
typedef struct {
	union {
		struct {
			uint32_t next[2];  /* cycle of the motor's next step within the segment */
			uint32_t err[2];   /* Bresenham remainder of that time, < den */
			uint32_t q[2];     /* cycles / n: whole cycles between steps */
			uint32_t r2[2];    /* 2 * (cycles % n) */
			uint32_t den[2];   /* 2 * n */
		};
		fast_t f;          /* when fast is 1 (fb_fast.h) */
	};
	uint32_t cycles;   /* segment duration in CPU cycles */
	uint32_t line;     /* line number of the command */
	uint8_t type;      /* enum mo_block_type */
	uint8_t dirs;      /* bit set = motor steps negative */
	uint8_t power;     /* laser power during the segment */
	uint8_t fast;      /* nonzero: the fast form above is filled, not next..den (MO_FAST_*) */
	uint8_t pdirs;     /* fast form: the direction pins' port bits */
} mo_block_t;

#define MO_NEVER 0xffffffffUL

/* Reset the queue and the generator (the motors keep their position, H and
 * Ln done). */
void mo_init(void);
/* At boot, before mo_init: take position, H and Ln done from the record a
 * reset that leaves the RAM powered keeps (board_keep) if it is valid and
 * power_on is 0; else start from A:0,B:0, H:0, Ln done 0.  Returns 1 when
 * the record was kept. */
uint8_t mo_boot(uint8_t power_on);

/* Queue: the main loop fills mo_slot() and then calls mo_push().  The count
 * includes the block executing now; mo_status_t.waiting does not. */
uint8_t mo_queue_count(void);
uint8_t mo_queue_free(void);
mo_block_t *mo_slot(void);
void mo_push(void);
/* Whether the filled slot is a G7 block (MO_BLK_RASTER or MO_BLK_SCAN). */
uint8_t mo_slot_raster(void);
/* The fast form (fb_fast.h) of a filled block, 1 when it takes one: a plain
 * MOVE (or a G7 block) that fast_form() accepts, with endstop supervision
 * ($7) off. */
uint8_t mo_fast_form(const mo_block_t *b, fast_t *f);
/* Give a filled block its fast form when it takes one and the board runs
 * fast blocks (BOARD_FAST_PATH); main loop, before mo_push, with interrupts
 * on: a few hundred cycles. */
void mo_seal(mo_block_t *b);
/* Drop every queued block; only while the generator is stopped. */
void mo_clear_queue(void);

/*
 * Fill a MOVE block for deltas da/db over p_us microseconds (or over a
 * number of CPU cycles).  Returns FB_OK, or FB_ERR_TOO_FAST when a motor
 * would need an interval below min_interval cycles between steps.
 */
uint8_t mo_prepare(mo_block_t *b, int32_t da, int32_t db, uint32_t p_us,
		   uint32_t min_interval);
uint8_t mo_prepare_cycles(mo_block_t *b, int32_t da, int32_t db, uint32_t cycles,
			  uint32_t min_interval);
/*
 * mo_prepare_cycles, straight into the fast form when the block takes one:
 * the same divisions and step-rate test, then fast_form() on them (fast
 * MO_FAST_FORMED until mo_seal gives the kind), else mo_prepare_cycles.  The
 * C form written and read back cost ~800 cycles a block (python
 * benchmarks/segcost.py).  mo_prepare uses it on a board with the fast path
 * while endstops are not supervised (the same rule as mo_fast_form, for the
 * MOVE and G7 blocks it prepares); tests/fast_tests.c holds it to
 * mo_prepare_cycles + mo_fast_form.
 */
uint8_t mo_prepare_fast(mo_block_t *b, int32_t da, int32_t db, uint32_t cycles,
			uint32_t min_interval);

/*
 * Fill a PEN block (M280): when it starts, the servo pulse moves from where
 * it is to to_us in steps of at most the rate that takes it from from_us
 * (the pen position the main loop planned) to to_us in move_ms, one step per
 * 20 ms servo frame; the block then lasts move_ms + settle_ms with no step,
 * so the next segment's first step waits until the pen has had its time.
 */
void mo_prepare_pen(mo_block_t *b, uint16_t from_us, uint16_t to_us, uint16_t move_ms,
		    uint16_t settle_ms);

/*
 * The pen servo (docs/protocol.md 6.2).  The pulse is 0 (no pulses: no pen)
 * while the park pulse ($14) is 0.  Parking sets the pulse to the park value
 * at once (the servo then moves at its own speed).
 */
/* Set the park (pen up) pulse and park there; 0 = no pen servo. */
void mo_pen_setup(uint16_t park_us);
/* Park the pen (hold, silence): the target it had is kept for mo_pen_unpark. */
void mo_pen_park(void);
/* Back to the target a park interrupted; returns the ms the pen needs to get
 * there (the move + settle time of the M280 that set it), 0 when nothing was
 * parked.  Interrupts off or in an interrupt. */
uint16_t mo_pen_unpark(void);
/* The pen is away from its park position (a lowered pen). */
uint8_t mo_pen_down(void);
/* The target of the pen (where the last executed M280 or a park sent it). */
uint16_t mo_pen_target(void);
/* The servo frame's interrupt calls this every CFG_SERVO_FRAME_MS: one step
 * of the move towards the target; returns the pulse to send, us (0 = none). */
uint16_t mo_pen_frame(void);

/* Start executing the queue (no-op while running). */
void mo_start(void);
/* The step interrupt's body: handle the due event, return cycles until the
 * next one (1..MO_MAX_DELAY), or 0 once stopped (queue empty, alarm).
 * Longer gaps are split into waits of MO_WAIT cycles.  MO_MAX_DELAY stays
 * well below 32768 because the board compares 16-bit timer values as
 * signed differences.  The board may let the pixel interrupt (fb_raster.h)
 * nest in it (board_avr_step.c): what it changes of the pixel timeline and
 * the laser it changes with interrupts off. */
#define MO_MAX_DELAY 0x6000u
#define MO_WAIT 0x4000u
uint16_t mo_event(void);
/* mo_event() returns this when the block it just started has the fast form:
 * the board then starts it with mo_fast_begin() and its own fast interrupt. */
#define MO_FAST 0xffffu

/*
 * The fast path's side of the queue (boards with BOARD_FAST_PATH).  The fast
 * block mo_event() started begins at timer time base: its times become
 * timer times, its steps go into the kept position (board.h) and *e is its
 * first event (fast_pick).  Returns 1 when the block starts from a stop (the
 * first after mo_start()): only then may the board start its whole
 * timeline later.
 */
uint8_t mo_fast_begin(uint16_t base, fast_event_t *e);
/* The fast interrupt stepped the running block to its end (its boundary is
 * the pending event): the next mo_event() call handles that boundary. */
void mo_fast_end(void);
/* The timer's timeline moved by delta cycles (a resumed hold): the running
 * fast block's stored times move with it. */
void mo_fast_shift(uint16_t delta);
/*
 * The queue and its running block: the state fb_motion.c shares with the
 * board's fast path (board_avr_step.S), which reads and writes these fields
 * in the step interrupt.  Writers:
 *   queue[]  the entry at head: the main loop (mo_slot() and the caller,
 *            before mo_push()); the running block: the step interrupt, in
 *            place (the C form's next[] and err[], or the fast form's
 *            times), and mo_fast_shift() as a hold resumes (interrupts off)
 *   cur      the running block, 0 between blocks: the step interrupt (C path
 *            boundary(), the fast path's switch to the next block);
 *            mo_init(), mo_start() and mo_stop() with interrupts off
 *   head     the next entry to fill: the main loop (mo_push(), mo_init())
 *   tail     the running or next entry to run: the step interrupt (both
 *            paths, as blocks end); mo_init(), mo_stop(), mo_clear_queue()
 *            with the generator stopped or interrupts off
 * Readers: the step interrupt (all of it), the main loop (head - tail, the
 * count; cur in mo_status()).  Indices run free (mod 256); head - tail is
 * the count, the running block included.
 *   px       the pixel interrupt's state and ring (G7 scans): its writers and
 *            readers are listed at px_state_t (fb_raster.h).  Last in the
 *            struct, so the fields the fast path reads keep their offsets.
 */
typedef struct {
	mo_block_t queue[CFG_QUEUE_SIZE];
	mo_block_t *volatile cur;
	volatile uint8_t head, tail;
	px_state_t px;
} mo_state_t;

extern mo_state_t mo_state;
/* Fold the kept position's step counts into its base (main loop): the fast
 * interrupt counts its steps in the 16-bit off[] without folding. */
void mo_fold(void);
/* Stop at once: no further steps, laser off, pen parked (and no way back:
 * a reset or an alarm forgets where it was), the current block is dropped. */
void mo_stop(void);
/* Freeze / continue the timeline of the running segment; laser follows.
 * mo_hold also parks the pen (mo_pen_park); the caller lowers it again with
 * mo_pen_unpark and waits its time before mo_resume. */
void mo_hold(void);
void mo_resume(void);

uint8_t mo_running(void);
/*
 * The watchdog's view of the step generator (fb_main.c feeds the watchdog
 * only when this says 1): 1 when the generator is legitimately quiet
 * (stopped, or held with its timer paused), or when the step interrupt has
 * run mo_event() since the previous call; 0 while it should be running and
 * has not run since.  Each call consumes the interrupt's beat.  While running,
 * the interrupt runs at least every MO_MAX_DELAY cycles (1.5 ms), so a main
 * loop that calls this more often misses some beats but feeds every ~1.5 ms;
 * a step interrupt that stopped while the generator runs stops the feeding.
 */
uint8_t mo_alive(void);
/*
 * What a status report shows of the motion.  The fields a block switch
 * changes (Ln done, queue, laser, underruns) are copied together with
 * interrupts off so they belong to one instant: read one by one, a switch
 * between two reads showed a block's Ln done with the next block's laser
 * power.  The position is copied just before them.
 */
typedef struct {
	int32_t pos[2];     /* steps */
	uint32_t done;      /* Ln done */
	uint32_t underruns;
	uint16_t pen;       /* servo pulse output now, us (0 = none) */
	uint8_t waiting;    /* blocks queued behind the one executing */
	uint8_t busy;       /* running, or blocks queued */
	uint8_t laser;      /* power now */
	uint8_t homed;      /* see mo_set_homed */
} mo_status_t;
void mo_status(mo_status_t *st);
void mo_get_pos(int32_t pos[2]);
/* Only while stopped. */
void mo_set_pos(const int32_t pos[2]);
/* Ln done := 0 (Ctrl-X). */
void mo_clear_done(void);
uint8_t mo_laser(void);
/* Set the laser output now (the pixel interrupt's changes; the status
 * report's L follows). */
void mo_set_laser(uint8_t p);
/* mo_status_t.homed: the position was set since power-on: a G92 block
 * executed (set here, in the step interrupt) or a homing completed (fb_main).
 * mo_init() keeps it, as a Ctrl-X keeps the position, and so does a reset that
 * keeps the record. */
void mo_set_homed(uint8_t on);
/* Endstop supervision outside homing (the $7 setting): a motor stepping
 * towards its switch (negative where seek_neg has its bit) while the switch
 * is pressed raises FB_ALARM_ENDSTOP; stepping away is allowed. */
void mo_set_endstops(uint8_t on, uint8_t seek_neg);
/* Alarm raised by the generator (0 = none); reading does not clear. */
uint8_t mo_alarm(void);
void mo_clear_alarm(void);
/* Motors whose endstop stopped them during the last HOME block. */
uint8_t mo_home_hits(void);
void mo_reset_home_hits(void);

#endif
