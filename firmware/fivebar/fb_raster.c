/*
 * fb_raster.c - raster scans: the pixel ring and the pixel interrupt's
 * timeline (fb_raster.h, docs/protocol.md 6.4).
 *
 * The timeline is counted from the last change: `since` is the cycles from
 * it to the scheduled event, `rem` the cycles from the scheduled event to
 * the next change (PX_NONE while the record holding it has not arrived; the
 * interrupt then ticks every PX_WAIT cycles and keeps counting `since`).  A
 * record's gap is counted from the change before it, so no absolute time is
 * ever needed: the scan's start is the first "change" (px_start), with the
 * laser at 0.
 */
#include "fb_raster.h"
#include "fb_motion.h"
#include "fb_proto.h"
#include "board.h"

#define RMASK (CFG_PX_RING - 1u)

#define X mo_state.px

/* A record that comes later than its first change: up to PX_LATE_MAX cycles
 * late its changes keep their times (the first at once); later still, the
 * record starts PX_ARM_MARGIN cycles after "now" (16-bit timer times stay
 * well within their signed range). */
#define PX_ARM_MARGIN 48u
#define PX_LATE_MAX 0x3000u

void px_init(void)
{
	uint8_t sreg = board_irq_save();
	board_px_stop();
	X.wr = X.rd = 0;
	X.run = 0;
	X.pending = 0;
	X.broken = 0;
	X.power = 0;
	X.left = 0;
	X.rem = PX_NONE;
	X.since = 0;
	X.late = 0;
	board_irq_restore(sreg);
}

uint8_t px_room(void)
{
	return (uint8_t)(CFG_PX_RING - (uint8_t)(X.wr - X.rd));
}

static uint8_t at(uint8_t i) { return X.ring[i & RMASK]; }

static uint32_t at32(uint8_t i)
{
	return (uint32_t)at(i) | (uint32_t)at((uint8_t)(i + 1u)) << 8 |
	       (uint32_t)at((uint8_t)(i + 2u)) << 16 | (uint32_t)at((uint8_t)(i + 3u)) << 24;
}

static void put(uint8_t *w, uint8_t v)
{
	X.ring[*w & RMASK] = v;
	*w = (uint8_t)(*w + 1u);
}

static void put32(uint8_t *w, uint32_t v)
{
	for (uint8_t k = 0; k < 4; k++) {
		put(w, (uint8_t)v);
		v >>= 8;
	}
}

/* Whether scan id s is older than id (ids count up mod 256; a window of 127). */
static uint8_t older(uint8_t s, uint8_t id)
{
	uint8_t d = (uint8_t)(id - s);
	return d >= 1u && d < 128u;
}

/* Skip the record at rd (its header and powers). */
static void skip_record(void)
{
	X.rd = (uint8_t)(X.rd + PX_HEAD + at((uint8_t)(X.rd + 1u)));
}

/* The rest of the current record (the pending change and those after it):
 * the scan ended before them. */
static void drop_rest(void)
{
	if (X.rem != PX_NONE)
		X.rd = (uint8_t)(X.rd + 1u + X.left);
	X.left = 0;
	X.rem = PX_NONE;
}

/* Take the record at rd when it is this scan's: its first change comes gap
 * cycles after the last one.  1 when taken (rem counts from the last change:
 * the caller subtracts `since`). */
static uint8_t take_record(uint32_t *gap)
{
	if (X.rd == X.wr || at(X.rd) != X.scan)
		return 0;
	uint8_t n = at((uint8_t)(X.rd + 1u));
	*gap = at32((uint8_t)(X.rd + 2u));
	X.period = at32((uint8_t)(X.rd + 6u));
	X.left = (uint8_t)(n - 1u);
	X.rd = (uint8_t)(X.rd + PX_HEAD);
	return 1;
}

void px_push(uint8_t scan, uint8_t n, uint32_t gap, uint32_t period, const char *data,
	     uint8_t len, uint8_t dark)
{
	uint8_t w = X.wr;
	put(&w, scan);
	put(&w, n);
	put32(&w, gap);
	put32(&w, period);
	for (uint8_t i = 0; i < len; i++) {
		uint8_t c = (uint8_t)data[i];
		if (c == PROTO_PX_ESC)
			c = (uint8_t)((uint8_t)data[++i] ^ PROTO_PX_XOR);
		put(&w, dark ? 0u : c);
	}
	uint8_t sreg = board_irq_save();
	X.wr = w;
	if (X.run && X.rem == PX_NONE) {
		/* the interrupt is ticking without a record: place this one's first
		 * change on the running timeline */
		uint32_t g;
		if (take_record(&g)) {
			uint16_t now = board_px_now();
			uint16_t ahead = (uint16_t)(board_px_sched() - now);
			if ((int16_t)ahead < 0)
				ahead = 0;  /* the tick is due now */
			uint32_t elapsed = X.since - ahead;  /* last change to now */
			if (g >= X.since) {
				X.rem = g - X.since;  /* after the scheduled tick */
			} else if (g + PX_LATE_MAX >= elapsed) {
				/* before the tick: at its own time (at once when that has
				 * passed: late, the changes after it still on time) */
				if (g < elapsed)
					X.late++;
				X.since = g;
				X.rem = 0;
				board_px_arm((uint16_t)(now - (uint16_t)(elapsed - g)));
			} else {
				X.late++;
				X.since = elapsed + PX_ARM_MARGIN;
				X.rem = 0;
				board_px_arm((uint16_t)(now + PX_ARM_MARGIN));
			}
		}
	}
	board_irq_restore(sreg);
}

void px_drop_broken(void)
{
	uint8_t sreg = board_irq_save();
	while (X.broken && !X.run && X.rd != X.wr && at(X.rd) == X.broken)
		skip_record();
	board_irq_restore(sreg);
}

void px_begin(uint8_t scan)
{
	X.pending = scan;
}

/* The event after the one at the scheduled time: d cycles on. */
static uint16_t advance(void)
{
	uint32_t r = X.rem;
	uint16_t d = r > PX_MAX_DELAY ? (uint16_t)PX_WAIT : (uint16_t)r;
	if (r != PX_NONE)
		X.rem = r - d;
	if (X.since < 0xf0000000UL)
		X.since += d;
	return d;
}

/* Not inlined into the step interrupt's C path (its only caller): its record
 * and constants would be the C path's frame through mo_event() (board_avr_step.c
 * fast_start says how much). */
__attribute__((noinline)) void px_start(uint16_t t)
{
	uint8_t id = X.pending;
	X.pending = 0;
	if (X.run)
		drop_rest();
	/* records of older scans were left by a scan that broke */
	while (X.rd != X.wr && older(at(X.rd), id))
		skip_record();
	X.scan = id;
	X.run = 1;
	X.broken = 0;
	X.power = 0;
	X.since = 0;
	X.rem = PX_NONE;
	uint32_t g;
	if (take_record(&g))
		X.rem = g;
	board_px_arm((uint16_t)(t + advance()));
}

void px_end(void)
{
	if (!X.run)
		return;
	drop_rest();
	X.run = 0;
	board_px_stop();
}

void px_break(uint8_t scan)
{
	px_end();
	X.broken = scan;
	while (X.rd != X.wr && at(X.rd) == scan)
		skip_record();
}

uint16_t px_event(void)
{
	if (!X.run)
		return 0;
	if (X.rem == 0) {
		/* a change: the next power of the record */
		uint8_t p = at(X.rd);
		X.rd = (uint8_t)(X.rd + 1u);
		if (p != X.power)  /* the same power: its PWM runs on unbroken */
			mo_set_laser(p);
		X.power = p;
		X.since = 0;
		uint32_t g;
		if (X.left) {
			X.left--;
			X.rem = X.period;
		} else if (take_record(&g)) {
			X.rem = g;
		} else {
			X.rem = PX_NONE;
		}
	}
	return advance();
}
