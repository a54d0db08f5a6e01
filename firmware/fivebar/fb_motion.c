/*
 * fb_motion.c - segment queue and event-driven integer DDA.
 *
 * mo_event() runs in the step interrupt: 32-bit adds and compares only, no
 * division, no floats.  Times inside a segment are counted in CPU cycles
 * from the segment start; the board's timer turns the returned deltas into
 * compare-match times on a free-running counter, so ISR latency never
 * accumulates into the schedule.
 *
 * The position, H and Ln done live in board_keep, the record a reset that
 * leaves the RAM powered keeps (see board.h).  Every update of it is bracketed
 * by busy = 1 ... busy = 0; a step sets busy before its pins rise and clears
 * it once off (the C path) or left (the fast path) is stored, so a valid
 * record never claims a step that was not issued, nor misses one that was.
 */
#include <string.h>
#include "fb_motion.h"
#include "fb_raster.h"
#include "board.h"
#include "status.h"

#define QMASK (CFG_QUEUE_SIZE - 1u)
#if (CFG_QUEUE_SIZE & (CFG_QUEUE_SIZE - 1)) != 0 || CFG_QUEUE_SIZE > 128
#error "CFG_QUEUE_SIZE must be a power of two up to 128"
#endif

/* the queue and its running block (fb_motion.h) */
mo_state_t mo_state;

/* generator state, owned by the step interrupt while running */
static uint32_t s_now;           /* cycle of the pending event within mo_state.cur */
static uint8_t s_due;            /* motors stepping at that event */
static uint8_t s_home_axes, s_es_enabled, s_seek_neg;
static uint8_t s_rest;           /* the block boundary() last started follows a stop */
static volatile uint8_t s_running, s_alarm, s_home_hits, s_laser;
/* s_beat: set by every mo_event() (the step interrupt is alive), consumed by
 * mo_alive() (the fast path's beat is its left[] counting down); s_held: the
 * generator's timer is paused by mo_hold() */
static volatile uint8_t s_beat;
static volatile uint8_t s_held;
static volatile uint32_t s_underruns;

/* pen servo: pulse now in 1/16 us, target and park in us, step per frame in
 * 1/16 us; p_saved: the target a park interrupted (0 = none); p_time: move +
 * settle ms of the M280 that set the target (the time to get back to it) */
static volatile uint16_t p_now16, p_target, p_park, p_step16, p_saved, p_time;

#define K board_keep
#define FB_KEEP_MAGIC 0xFB5AFE17UL
/* off is folded into base when a step of the C path takes it to +-OFF_FOLD,
 * and by the main loop (mo_fold) from +-MAIN_FOLD: a fast block adds all its
 * steps (at most FAST_NMAX) when it starts, so off stays in range as long
 * as the main loop runs once while a block of that size executes (0.27 s at
 * 60 kHz; one main loop pass takes tens of milliseconds at most, measured
 * under the busiest step interrupt) */
#define OFF_FOLD 127
#define MAIN_FOLD 8192

static uint32_t keep_sum(void)
{
	return FB_KEEP_MAGIC + (uint32_t)K.base[0] + (uint32_t)K.base[1] + K.homed;
}

/* Rewrite the whole record; interrupts off (or in the step interrupt). */
static void keep_write(int32_t a, int32_t b, uint32_t done, uint8_t homed)
{
	K.busy = 1;
	K.base[0] = a;
	K.base[1] = b;
	K.off[0] = 0;
	K.off[1] = 0;
	K.left[0] = K.left[1] = 0;
	K.fdirs = 0;
	K.done = done;
	K.ndone = ~done;
	K.homed = homed;
	K.check = keep_sum();
	K.busy = 0;
}

/* Ln done := line (the step interrupt, or interrupts off). */
BOARD_INLINE void keep_done(uint32_t line)
{
	K.busy = 1;
	K.done = line;
	K.ndone = ~line;
	K.busy = 0;
}

/* The steps of motor i the running fast block added to off and has not
 * issued yet, signed. */
static int32_t fast_ahead(uint8_t i)
{
	int32_t d = (int32_t)K.left[i];
	return (K.fdirs & (1u << i)) ? -d : d;
}

/* The position as the record holds it; interrupts off. */
static int32_t keep_pos(uint8_t i)
{
	return K.base[i] + K.off[i] - fast_ahead(i);
}

/* A fast block stops part-way: what it has not issued leaves the position
 * (through base).  Interrupts off (or in the step interrupt). */
static void fast_fold(void)
{
	K.busy = 1;
	for (uint8_t i = 0; i < 2; i++) {
		int32_t d = fast_ahead(i);
		K.base[i] -= d;
		K.check -= (uint32_t)d;
		K.left[i] = 0;
	}
	K.fdirs = 0;
	K.busy = 0;
}

uint8_t mo_boot(uint8_t power_on)
{
	uint8_t sreg = board_irq_save();
	uint8_t kept = !power_on && K.busy == 0 && K.homed <= 1 && K.check == keep_sum() &&
		       K.ndone == ~K.done && K.fdirs <= 3u;
	for (uint8_t i = 0; kept && i < 2; i++)
		if (K.left[i] > FAST_NMAX || keep_pos(i) > CFG_POS_LIMIT ||
		    keep_pos(i) < -CFG_POS_LIMIT)
			kept = 0;
	if (kept)
		keep_write(keep_pos(0), keep_pos(1), K.done, K.homed);
	else
		keep_write(0, 0, 0, 0);
	board_irq_restore(sreg);
	return kept;
}

/* Pulse to the park value at once; keep the target to go back to if asked
 * (a hold), else forget it (a stop: reset, alarm).  Interrupts off. */
static void pen_park_now(uint8_t keep)
{
	if (keep && p_target != p_park && !p_saved) {
		p_saved = p_target;
	} else if (!keep) {
		p_saved = 0;
	}
	p_target = p_park;
	p_now16 = (uint16_t)(p_park << 4);
}

void mo_pen_setup(uint16_t park_us)
{
	uint8_t sreg = board_irq_save();
	p_park = park_us;
	pen_park_now(0);
	board_irq_restore(sreg);
}

void mo_pen_park(void)
{
	uint8_t sreg = board_irq_save();
	pen_park_now(1);
	board_irq_restore(sreg);
}

uint16_t mo_pen_unpark(void)
{
	uint16_t t = p_saved;
	if (!t)
		return 0;
	p_saved = 0;
	p_target = t;
	p_now16 = (uint16_t)(t << 4);
	return p_time ? p_time : 1u;
}

uint8_t mo_pen_down(void) { return p_target != p_park; }
uint16_t mo_pen_target(void) { return p_target; }

uint16_t mo_pen_frame(void)
{
	uint16_t now = p_now16, to = (uint16_t)(p_target << 4), st = p_step16;
	if (now < to)
		now = (uint16_t)(to - now > st ? now + st : to);
	else if (now > to)
		now = (uint16_t)(now - to > st ? now - st : to);
	p_now16 = now;
	return (uint16_t)(now >> 4);
}

void mo_init(void)
{
	board_timer_stop();
	mo_state.head = mo_state.tail = 0;
	mo_state.cur = 0;
	s_now = 0;
	s_due = 0;
	s_running = 0;
	s_held = 0;
	s_laser = 0;
	s_underruns = 0;
	px_init();
	board_laser(0);
	pen_park_now(0);
}

static uint8_t is_raster(uint8_t type)
{
	return type == MO_BLK_RASTER || type == MO_BLK_SCAN;
}

uint8_t mo_queue_count(void) { return (uint8_t)((mo_state.head - mo_state.tail) & 0xffu); }

uint8_t mo_queue_free(void) { return (uint8_t)(CFG_QUEUE_SIZE - mo_queue_count()); }

mo_block_t *mo_slot(void)
{
	/* its form is what fills it says: mo_prepare_cycles the C form (fast 0),
	 * mo_prepare_fast the fast one (MO_FAST_FORMED), a memset 0 */
	return &mo_state.queue[mo_state.head & QMASK];
}
void mo_push(void) { mo_state.head = (uint8_t)(mo_state.head + 1u); }

uint8_t mo_slot_raster(void) { return is_raster(mo_state.queue[mo_state.head & QMASK].type); }

void mo_clear_queue(void)
{
	mo_state.tail = mo_state.head;
	px_init();  /* the dropped G7 blocks' runs */
}

/*
 * q = C / n and m = C % n (n > 0).  Segments up to 4.1 ms (C < 2^16, most of
 * a dense job) divide in 16 bits: avr-libc's __udivmodhi4 gives both in ~200
 * cycles against ~600 for the 32-bit one; one step needs none.
 */
static uint32_t div_cn(uint32_t c, uint32_t n, uint32_t *m)
{
	if (n == 1u) {
		*m = 0;
		return c;
	}
	if (c <= 0xffffu && n <= 0xffffu) {
		uint16_t c16 = (uint16_t)c, n16 = (uint16_t)n;
		*m = (uint16_t)(c16 % n16);
		return (uint16_t)(c16 / n16);
	}
	uint32_t q = c / n;
	*m = c - q * n;
	return q;
}

static uint8_t prep_axis(mo_block_t *b, uint8_t i, int32_t d, uint32_t min_interval)
{
	uint32_t n;
	if (d < 0) {
		b->dirs |= (uint8_t)(1u << i);
		n = (uint32_t)0 - (uint32_t)d;
	} else {
		n = (uint32_t)d;
	}
	if (n == 0) {
		b->next[i] = MO_NEVER;
		b->err[i] = b->q[i] = b->r2[i] = 0;
		b->den[i] = 1;
		return FB_OK;
	}
	uint32_t m, q = div_cn(b->cycles, n, &m);
	if (q < min_interval)
		return FB_ERR_TOO_FAST;
	b->q[i] = q;
	b->r2[i] = m << 1;
	b->den[i] = n << 1;
	/* step 1 at floor(C / 2n) with remainder C % 2n: see the header */
	b->next[i] = q >> 1;
	b->err[i] = (q & 1u) ? n + m : m;
	return FB_OK;
}

uint8_t mo_prepare_cycles(mo_block_t *b, int32_t da, int32_t db, uint32_t cycles,
			  uint32_t min_interval)
{
	b->type = MO_BLK_MOVE;
	b->fast = 0;  /* the C form until mo_seal() says otherwise */
	b->dirs = 0;
	b->cycles = cycles;
	uint8_t st = prep_axis(b, 0, da, min_interval);
	if (st == FB_OK)
		st = prep_axis(b, 1, db, min_interval);
	return st;
}

uint8_t mo_fast_form(const mo_block_t *b, fast_t *f)
{
	if ((b->type != MO_BLK_MOVE && !is_raster(b->type)) || s_es_enabled)
		return 0;
	uint32_t n[2], q[2], m[2];
	for (uint8_t i = 0; i < 2; i++) {
		n[i] = b->next[i] == MO_NEVER ? 0 : b->den[i] >> 1;
		q[i] = b->q[i];
		m[i] = b->r2[i] >> 1;
	}
	return fast_form(f, n, q, m);
}

void mo_seal(mo_block_t *b)
{
	if (b->fast == MO_FAST_FORMED && BOARD_FAST_PATH && (b->type == MO_BLK_MOVE ||
							     is_raster(b->type))) {
		/* mo_prepare_fast formed it: only its kind and pins are left */
		b->pdirs = board_dir_bits(b->dirs);
		b->fast = b->type == MO_BLK_SCAN ? MO_FAST_SCAN
			  : b->type == MO_BLK_RASTER ? MO_FAST_RASTER : MO_FAST_PLAIN;
		return;
	}
	b->fast = 0;
	/* straight into the block: mo_fast_form reads the C form (the union's
	 * other half) into locals before fast_form writes, and fast_form refuses
	 * before it writes anything, so a refused block keeps its C form (a copy
	 * through the stack cost ~150 cycles a block) */
	if (!BOARD_FAST_PATH || !mo_fast_form(b, &b->f))
		return;
	b->pdirs = board_dir_bits(b->dirs);
	b->fast = b->type == MO_BLK_SCAN ? MO_FAST_SCAN
		  : b->type == MO_BLK_RASTER ? MO_FAST_RASTER : MO_FAST_PLAIN;
}

void mo_prepare_pen(mo_block_t *b, uint16_t from_us, uint16_t to_us, uint16_t move_ms,
		    uint16_t settle_ms)
{
	uint32_t d16 = (uint32_t)(from_us > to_us ? from_us - to_us : to_us - from_us) << 4;
	/* the board sends each frame's width one frame after asking mo_pen_frame()
	 * for it, so the move takes one frame less: its last width is on the wire
	 * within move_ms of the block start (and a move under two frames jumps) */
	uint32_t frames = move_ms / CFG_SERVO_FRAME_MS;
	frames = frames ? frames - 1u : 0u;
	uint32_t step = frames ? (d16 + frames - 1u) / frames : 0xffffu;
	mo_prepare_cycles(b, 0, 0, ((uint32_t)move_ms + settle_ms) * (FB_F_CPU / 1000UL), 0);
	b->type = MO_BLK_PEN;
	b->power = 0;
	b->q[0] = to_us;
	b->q[1] = step ? (step > 0xffffu ? 0xffffu : step) : 1u;
	b->r2[0] = (uint32_t)move_ms + settle_ms;
}

/* fast_axes' answer for a block the fast form does not take (a
 * dwell, or steps too many or too far apart): the caller prepares the C form */
#define PREP_C_FORM 0xffu

/* Each motor's n, q = C / n and m = C % n in 16 bits (v[i], v[2 + i], v[4 + i]:
 * fast_form16's three arrays), with prep_axis's step-rate test in its order;
 * FB_OK when the fast form takes the block.  Not inlined: its divisions'
 * registers and spills stay out of mo_prepare_fast's frame, which
 * fast_form16 and mo_prepare_cycles run on. */
static __attribute__((noinline)) uint8_t fast_axes(int32_t da, int32_t db, uint32_t cycles,
						   uint32_t min_interval, uint16_t v[6])
{
	uint8_t fast = 1;
	for (uint8_t i = 0; i < 2; i++) {
		int32_t d = i ? db : da;
		uint32_t n = d < 0 ? (uint32_t)0 - (uint32_t)d : (uint32_t)d;
		v[i] = v[2 + i] = v[4 + i] = 0;
		if (!n)
			continue;
		uint32_t m, q = div_cn(cycles, n, &m);
		if (q < min_interval)
			return FB_ERR_TOO_FAST;  /* prep_axis's test, in its order */
		if (n > FAST_NMAX || q > FAST_QMAX)
			fast = 0;  /* fast_form's rules */
		v[i] = (uint16_t)n;
		v[2 + i] = (uint16_t)q;
		v[4 + i] = (uint16_t)m;
	}
	if (!fast || (!v[0] && !v[1]))  /* a dwell: the C path's waits */
		return PREP_C_FORM;
	return FB_OK;
}

/* The fast form straight from the move, or the C form.  The stack's deepest
 * points run through here (the main loop's, with the serial, step and pixel
 * interrupts nested on top of it; benchmarks/stack.py), hence one frame that
 * holds the arrays and calls three functions in turn, none inside another:
 * fast_axes() divides and returns before fast_form16() multiplies, and
 * mo_prepare_cycles() divides again for a C-form block (the default
 * profile's G7 blocks).  That one used to run inside the frame of the fast
 * attempt (its 32 bytes of arrays and spills, 18 saved registers): 30 bytes
 * above the static RAM at the deepest. */
uint8_t mo_prepare_fast(mo_block_t *b, int32_t da, int32_t db, uint32_t cycles,
			uint32_t min_interval)
{
	uint16_t v[6];
	uint8_t st = fast_axes(da, db, cycles, min_interval, v);
	if (st == PREP_C_FORM)
		return mo_prepare_cycles(b, da, db, cycles, min_interval);
	if (st != FB_OK)
		return st;
	fast_form16(&b->f, v, v + 2, v + 4);
	b->type = MO_BLK_MOVE;
	b->dirs = (uint8_t)((da < 0 ? 1u : 0u) | (db < 0 ? 2u : 0u));
	b->cycles = cycles;
	b->fast = MO_FAST_FORMED;
	return FB_OK;
}

uint8_t mo_prepare(mo_block_t *b, int32_t da, int32_t db, uint32_t p_us, uint32_t min_interval)
{
	uint32_t cycles = p_us * (FB_F_CPU / 1000000UL);
	if (BOARD_FAST_PATH && !s_es_enabled)
		return mo_prepare_fast(b, da, db, cycles, min_interval);
	return mo_prepare_cycles(b, da, db, cycles, min_interval);
}

BOARD_INLINE void set_laser(uint8_t p)
{
	s_laser = p;
	board_laser(p);
}

void mo_set_laser(uint8_t p) { set_laser(p); }

void mo_start(void)
{
	uint8_t sreg = board_irq_save();
	if (!s_running && mo_state.head != mo_state.tail) {
		mo_state.cur = 0;
		s_now = 0;
		s_due = 0;
		s_running = 1;
		s_held = 0;
		board_timer_start(64);
	}
	board_irq_restore(sreg);
}

void mo_stop(void)
{
	uint8_t sreg = board_irq_save();
	board_timer_stop();
	s_running = 0;
	s_held = 0;
	if (mo_state.cur) {
		/* the interrupted block is dropped (a fast one's steps so far
		 * stay in the position) */
		if (mo_state.cur->fast)
			fast_fold();
		mo_state.tail = (uint8_t)(mo_state.tail + 1u);
		mo_state.cur = 0;
	}
	s_due = 0;
	px_end();
	set_laser(0);
	pen_park_now(0);
	board_irq_restore(sreg);
}

void mo_hold(void)
{
	uint8_t sreg = board_irq_save();
	if (s_running) {
		board_timer_pause();
		s_held = 1;
	}
	set_laser(0);
	pen_park_now(1);
	board_irq_restore(sreg);
}

void mo_resume(void)
{
	uint8_t sreg = board_irq_save();
	if (s_running) {
		if (mo_state.cur)
			set_laser(is_raster(mo_state.cur->type) ? (mo_state.px.run ? mo_state.px.power : 0u)
								: mo_state.cur->power);
		s_held = 0;
		board_timer_resume();
	}
	board_irq_restore(sreg);
}

/*
 * Segment boundary: retire the finished block, apply queued G92/M17/M18,
 * point at the next segment.  Returns it, or 0 when the queue is empty.
 */
BOARD_INLINE mo_block_t *boundary(void)
{
	uint8_t t = mo_state.tail;
	if (mo_state.cur) {
		keep_done(mo_state.cur->line);
		t = (uint8_t)(t + 1u);
		mo_state.cur = 0;
	}
	for (;; t = (uint8_t)(t + 1u)) {
		if (t == mo_state.head) {
			mo_state.tail = t;
			s_running = 0;
			s_underruns++;
			uint8_t sreg = board_irq_save();  /* the pixel interrupt may nest here */
			px_end();
			set_laser(0);
			board_irq_restore(sreg);
			return 0;
		}
		mo_block_t *b = &mo_state.queue[t & QMASK];
		switch (b->type) {
		case MO_BLK_SETPOS:
			keep_write((int32_t)b->q[0], (int32_t)b->q[1], b->line, 1);
			continue;
		case MO_BLK_ENABLE:
		case MO_BLK_DISABLE:
			board_enable_motors(b->type == MO_BLK_ENABLE);
			keep_done(b->line);
			continue;
		case MO_BLK_PEN:
			/* stores only: the servo frame interrupt moves the pulse */
			p_target = (uint16_t)b->q[0];
			p_step16 = (uint16_t)b->q[1];
			p_time = (uint16_t)b->r2[0];
			p_saved = 0;
			if (b->cycles == 0) {
				keep_done(b->line);
				continue;
			}
			break;  /* a dwell of move + settle time */
		default:
			break;
		}
		mo_state.tail = t;
		board_set_dirs(b->dirs);
		s_home_axes = (uint8_t)((b->next[0] != MO_NEVER ? 1u : 0u) |
					(b->next[1] != MO_NEVER ? 2u : 0u));
		s_now = 0;
		mo_state.cur = b;
		/* a scan's next block (the common case) touches neither the pixel
		 * timeline nor the laser; the rest does with interrupts off: the
		 * pixel interrupt may nest in mo_event() (board.h) */
		if (b->type != MO_BLK_RASTER || s_rest || !mo_state.px.run) {
			uint8_t sreg = board_irq_save();
			if (b->type == MO_BLK_SCAN) {
				px_begin(b->power);  /* the board's px_start() gives its time */
				set_laser(0);
			} else if (b->type != MO_BLK_RASTER) {
				px_end();
				set_laser(b->power);
			} else {
				/* a scan's later block after a stop: its timeline is lost */
				px_break(b->power);
				set_laser(0);
			}
			board_irq_restore(sreg);
		}
		return b;
	}
}

/* Endstops while stepping: homing stops, or the alarm; 0 when stopped. */
BOARD_INLINE uint8_t check_endstops(mo_block_t *b, uint8_t due)
{
	uint8_t es = board_endstops();
	if (b->type == MO_BLK_HOME) {
		uint8_t hit = (uint8_t)(es & due & s_home_axes);
		if (hit) {
			s_home_hits |= hit;
			if (hit & 1u)
				b->next[0] = MO_NEVER;
			if (hit & 2u)
				b->next[1] = MO_NEVER;
			if ((s_home_hits & s_home_axes) == s_home_axes)
				b->cycles = s_now + 1u;
		}
	} else if (es & due & (uint8_t)~(b->dirs ^ s_seek_neg)) {
		/* pressed, and this motor just stepped towards its switch */
		s_alarm = FB_ALARM_ENDSTOP;
		s_running = 0;
		mo_state.tail = (uint8_t)(mo_state.tail + 1u);
		mo_state.cur = 0;
		uint8_t sreg = board_irq_save();
		set_laser(0);
		board_irq_restore(sreg);
		return 0;
	}
	return 1;
}

/*
 * Count the step of motor i in the kept record (busy is set): off moves by
 * one; at +-OFF_FOLD it goes into base, and into the check with it.
 */
BOARD_INLINE void count_step(const mo_block_t *b, uint8_t i)
{
	int16_t o = K.off[i];
	o = (int16_t)((b->dirs & (1u << i)) ? o - 1 : o + 1);
	if (o >= OFF_FOLD || o <= -OFF_FOLD) {
		K.base[i] += o;
		K.check += (uint32_t)(int32_t)o;
		o = 0;
	}
	K.off[i] = o;
}

/*
 * Schedule the next step of motor i.  No step counter is needed: after the
 * last step (k = n) the next time, floor((2n+1)C/2n), is >= C, past the
 * segment end.
 */
BOARD_INLINE void step_axis(mo_block_t *b, uint8_t i)
{
	uint32_t e = b->err[i] + b->r2[i];
	uint32_t t = b->next[i] + b->q[i];
	if (e >= b->den[i]) {
		e -= b->den[i];
		t++;
	}
	b->err[i] = e;
	b->next[i] = t;
}

uint16_t mo_event(void)
{
	mo_block_t *b = mo_state.cur;
	uint8_t due = s_due;
	s_beat = 1;
	if (due) {
		/* a reset from here until busy = 0 finds the record invalid: a
		 * boot cannot know whether the drivers saw the step */
		K.busy = 1;
		board_steps_high(due);
		if (due & 1u)
			count_step(b, 0);
		if (due & 2u)
			count_step(b, 1);
		K.busy = 0;
		if (due & 1u)
			step_axis(b, 0);
		if (due & 2u)
			step_axis(b, 1);
		if ((s_es_enabled || b->type == MO_BLK_HOME) && !check_endstops(b, due))
			return 0;
	} else if (!b || s_now == b->cycles) {
		s_rest = !b;
		b = boundary();
		if (!b)
			return 0;
		if (b->fast)
			return MO_FAST;
	}
	uint32_t t = b->cycles;
	uint8_t m = 0;
	if (b->next[0] < t) {
		t = b->next[0];
		m = 1;
	}
	if (b->next[1] < t) {
		t = b->next[1];
		m = 2;
	} else if (m && b->next[1] == t) {
		m = 3;
	}
	t -= s_now;
	if (t > MO_MAX_DELAY) {
		/* a plain wait; what is left stays above MO_MAX_DELAY - MO_WAIT */
		t = MO_WAIT;
		m = 0;
	}
	s_now += t;
	s_due = m;
	return t ? (uint16_t)t : 1u;
}

uint8_t mo_fast_begin(uint16_t base, fast_event_t *e)
{
	fast_t *f = &mo_state.cur->f;
	fast_begin(f, base);
	uint8_t dirs = mo_state.cur->dirs;
	K.busy = 1;
	for (uint8_t i = 0; i < 2; i++) {
		int16_t n = (int16_t)f->cnt[i];
		K.left[i] = f->cnt[i];
		K.off[i] = (int16_t)(K.off[i] + ((dirs & (1u << i)) ? -n : n));
	}
	K.fdirs = dirs;
	K.busy = 0;
	fast_pick(f, f->cnt, e);
	return s_rest;
}

void mo_fast_end(void)
{
	fast_fold();
	s_now = mo_state.cur->cycles;
	s_due = 0;
}

void mo_fast_shift(uint16_t delta)
{
	mo_block_t *b = mo_state.cur;
	if (b && b->fast) {
		b->f.t[0] = (uint16_t)(b->f.t[0] + delta);
		b->f.t[1] = (uint16_t)(b->f.t[1] + delta);
	}
}

void mo_fold(void)
{
	for (uint8_t i = 0; i < 2; i++) {
		/* a look first with interrupts on (the main loop comes here all the
		 * time, and each interrupts-off look delayed the step interrupts
		 * landing in it by up to 14 cycles): a torn read is only a look,
		 * the fold re-reads with them off */
		int16_t seen = K.off[i];
		if (seen < MAIN_FOLD && seen > -MAIN_FOLD)
			continue;
		uint8_t sreg = board_irq_save();
		int16_t o = K.off[i];
		if (o >= MAIN_FOLD || o <= -MAIN_FOLD) {
			K.busy = 1;
			K.base[i] += o;
			K.check += (uint32_t)(int32_t)o;
			K.off[i] = 0;
			K.busy = 0;
		}
		board_irq_restore(sreg);
	}
}

uint8_t mo_running(void) { return s_running; }

uint8_t mo_alive(void)
{
	/* the fast path (board_avr_step.S) sets no beat: each of its steps
	 * counts a kept left[] down, which changes its low byte, so a change of
	 * a low byte since the last look is its beat (read outside the
	 * interrupts-off section: one byte is read whole) */
	static uint8_t seen[2];
	uint8_t l0 = (uint8_t)K.left[0], l1 = (uint8_t)K.left[1];
	uint8_t sreg = board_irq_save();
	uint8_t ok = s_beat || !s_running || s_held;
	s_beat = 0;
	board_irq_restore(sreg);
	ok = (uint8_t)(ok || l0 != seen[0] || l1 != seen[1]);
	seen[0] = l0;
	seen[1] = l1;
	return ok;
}

void mo_get_pos(int32_t pos[2])
{
	/* a copy with interrupts off, the sums after (they took 230 cycles) */
	int32_t base[2];
	int16_t off[2];
	uint16_t left[2];
	uint8_t sreg = board_irq_save();
	for (uint8_t i = 0; i < 2; i++) {
		base[i] = K.base[i];
		off[i] = K.off[i];
		left[i] = K.left[i];
	}
	uint8_t fdirs = K.fdirs;
	board_irq_restore(sreg);
	for (uint8_t i = 0; i < 2; i++)
		pos[i] = base[i] + off[i] + ((fdirs & (1u << i)) ? (int32_t)left[i] : -(int32_t)left[i]);
}

void mo_status(mo_status_t *st)
{
	/* The position moves with every step: its own copy.  The rest changes
	 * together at a block switch: one raw copy with interrupts off (every
	 * cycle off delays a step edge), worked out after. */
	mo_get_pos(st->pos);
	uint8_t sreg = board_irq_save();
	uint32_t done = K.done, underruns = s_underruns;
	uint16_t pen16 = p_now16;
	uint8_t head = mo_state.head, tail = mo_state.tail, laser = s_laser, running = s_running;
	uint8_t cur = mo_state.cur != 0;
	board_irq_restore(sreg);
	uint8_t count = (uint8_t)(head - tail);
	st->done = done;
	st->underruns = underruns;
	st->pen = (uint16_t)(pen16 >> 4);
	st->waiting = (uint8_t)(count - cur);
	st->busy = (uint8_t)(running || count);
	st->laser = laser;
	st->homed = K.homed;
}

void mo_set_pos(const int32_t pos[2])
{
	uint8_t sreg = board_irq_save();
	keep_write(pos[0], pos[1], K.done, K.homed);
	board_irq_restore(sreg);
}

void mo_clear_done(void)
{
	uint8_t sreg = board_irq_save();
	keep_done(0);
	board_irq_restore(sreg);
}

uint8_t mo_laser(void) { return s_laser; }

void mo_set_homed(uint8_t on)
{
	uint8_t sreg = board_irq_save();
	K.busy = 1;
	K.check += (uint32_t)on - K.homed;
	K.homed = on;
	K.busy = 0;
	board_irq_restore(sreg);
}

void mo_set_endstops(uint8_t on, uint8_t seek_neg)
{
	uint8_t sreg = board_irq_save();
	s_es_enabled = on;
	s_seek_neg = seek_neg & 3u;
	board_irq_restore(sreg);
}

uint8_t mo_alarm(void) { return s_alarm; }
void mo_clear_alarm(void) { s_alarm = 0; }

uint8_t mo_home_hits(void) { return s_home_hits; }
void mo_reset_home_hits(void) { s_home_hits = 0; }
