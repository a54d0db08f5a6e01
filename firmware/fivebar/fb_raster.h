/*
 * fb_raster.h - raster scans (G7, docs/protocol.md 6.4): the pixel ring and
 * the pixel interrupt's timeline.
 *
 * A G7 line is one or more segments (blocks of fb_motion, type
 * MO_BLK_RASTER) and a run of pixel powers: power i is put on the laser at
 * U + i*T cycles after the start of the line's first segment.  Consecutive
 * G7 blocks form a scan, one timeline: the first G7 block after any other
 * block (or after an idle machine) starts it (MO_BLK_SCAN), and the C path
 * of the step interrupt tells the pixel interrupt its exact timer time
 * (px_start).  From there each run is placed by cycles from the change
 * before it (the main loop knows every queued G7 block's duration), so the
 * pixel interrupt needs no block boundary: the fast path switches G7 blocks
 * as it switches plain ones.
 *
 * The main loop stores each run as a record in a byte ring, decoded from the
 * line: scan id, pixel count n, gap (cycles from the previous change of the
 * scan, or from the scan's start, to the run's first change), period T, then
 * the n powers.  The pixel interrupt (Timer1 compare B on the AVR) reads the
 * records in order, sets the laser at each change, and frees the ring as it
 * goes; between changes farther apart than PX_MAX_DELAY it waits in chunks.
 *
 * No floats, no division in the interrupt.  Prefix px_, PX_.
 */
#ifndef FB_RASTER_H
#define FB_RASTER_H

#include <stdint.h>
#include "config.h"

#if (CFG_PX_RING & (CFG_PX_RING - 1)) != 0 || CFG_PX_RING > 128
#error "CFG_PX_RING must be a power of two up to 128"
#endif

/* Record header bytes: scan id, n, gap (4), T (4), little-endian. */
#define PX_HEAD 10u
/* The pixel interrupt's longest single wait; longer gaps are chained waits of
 * PX_WAIT (16-bit timer times compared as signed differences, as the step
 * interrupt's: fb_motion.h MO_MAX_DELAY). */
#define PX_MAX_DELAY 0x6000u
#define PX_WAIT 0x4000u
/* rem when no change is pending (the next record has not arrived) */
#define PX_NONE 0xffffffffUL

/*
 * The pixel interrupt's state and the ring.  Writers:
 *   ring[], wr  the main loop (px_push), which writes a whole record before
 *               it moves wr past it
 *   rd          the pixel interrupt (as it reads records and powers);
 *               px_start (step interrupt), px_clear (interrupts off)
 *   the rest    the pixel interrupt, px_start/px_end/px_break (step
 *               interrupt), px_poke (main loop, interrupts off)
 * Readers: the main loop reads wr and rd for the free room (one byte each,
 * read whole), the rest only with interrupts off.
 */
typedef struct {
	uint8_t ring[CFG_PX_RING];
	volatile uint8_t wr, rd;    /* free-running byte indices (mod 256) */
	volatile uint8_t run;       /* a scan's timeline is running */
	volatile uint8_t scan;      /* its id */
	volatile uint8_t pending;   /* a scan block has just started (px_begin): its id */
	volatile uint8_t broken;    /* a scan whose timeline broke (underrun): its records are dropped */
	volatile uint8_t power;     /* the scan's power now (the last change) */
	uint8_t left;               /* changes left in the current record after the pending one */
	uint32_t period;            /* its T, cycles */
	uint32_t rem;               /* cycles from the scheduled event to the next change; PX_NONE */
	uint32_t since;             /* cycles from the last change (or the scan start) to it */
	volatile uint16_t late;     /* changes that came more than PX_LATE cycles late */
} px_state_t;
/* The one instance is mo_state.px (fb_motion.h): the motion state's struct. */

/* A change is counted late when the interrupt ran this many cycles after it. */
#define PX_LATE 320u

/* ---- main loop ------------------------------------------------------------ */
/* Reset: no scan, empty ring (boot, Ctrl-X, alarm); the laser is the caller's. */
void px_init(void);
/* Free bytes in the ring. */
uint8_t px_room(void);
/*
 * Store a record of n powers (0 <= n, PX_HEAD + n <= CFG_PX_RING, room
 * checked by the caller) decoded from the escaped data[0..len) (protocol
 * 6.4), all 0 when dark; then let a waiting pixel interrupt take it.
 */
void px_push(uint8_t scan, uint8_t n, uint32_t gap, uint32_t period, const char *data,
	     uint8_t len, uint8_t dark);
/* Drop the records of a broken scan at the head of the ring (the main loop
 * waits for room: nothing else will consume them). */
void px_drop_broken(void);

/* ---- step interrupt (fb_motion.c's boundary, the board's C path) ---------- */
/* A MO_BLK_SCAN block starts: px_start follows with its timer time. */
void px_begin(uint8_t scan);
/* The board's C path, after mo_event(): the started scan block begins at
 * timer time t (its exact time, perhaps a little in the past). */
void px_start(uint16_t t);
/* A non-G7 block starts, the queue ran empty, or a stop: the scan ends (the
 * caller sets the laser). */
void px_end(void);
/* A G7 block of scan `scan` starts from a stop (an underrun): its timeline is
 * lost; the laser stays off until the next scan. */
void px_break(uint8_t scan);

/* ---- the pixel interrupt ---------------------------------------------------- */
/* The due event: a change (the laser takes the next power) or a chained wait.
 * Returns the cycles to the next event (1..PX_MAX_DELAY), 0: none (stop). */
uint16_t px_event(void);

#endif
