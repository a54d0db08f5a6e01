/*
 * fb_exec.c - executing parsed commands: G1 and G6 moves (checked against
 * the position limits, the soft limits and the step rate), G90/G91/G92,
 * M3/M5, M280 pen blocks, M17/M18, and the $ commands, onto the block queue
 * of fb_motion; an alarm locks out all but the $ commands.  It also keeps
 * the plan (where the queue will leave the machine) and starts the queue.
 */
#include <string.h>
#include "fb_exec.h"
#include "fb_baud.h"
#include "fb_home.h"
#include "fb_report.h"
#include "fb_settings.h"
#include "fb_state.h"
#include "fb_motion.h"
#include "fb_raster.h"
#include "board.h"
#include "config.h"
#include "status.h"

static uint8_t absolute, laser_on, laser_s;
static int32_t plan[2];
static uint16_t pen_plan;  /* pen pulse after the queued M280 blocks */
static uint32_t first_queued_ms;
/* the pending G6 line: checked as a whole, segments queued so far (0: none,
 * 1: its head), where its next item starts, its current duration */
static uint8_t g6_checked, g6_queued, g6_at;
static int32_t g6_p;
/* G7 (protocol 6.4): the modal P and T of G7 lines; the scan being queued: its
 * id (in its blocks' power), whether the last block queued was one of its,
 * the scan time (cycles from its start) at the end of its last block queued
 * and of its last pixel change; the pending line: its record is in the ring,
 * it starts a scan */
static int32_t g7_p, g7_t;
static uint8_t g7_in_scan, g7_pushed;
#ifndef FB_SERVO
static uint8_t g7_scan, g7_new;
static uint32_t g7_time, g7_last;
#endif

uint8_t exec_idle(void)
{
	return !mo_running() && mo_queue_count() == 0 && !fb_state.homing;
}

void exec_sync_plan(void)
{
	mo_get_pos(plan);
	pen_plan = mo_pen_target();
}

void exec_reset(void)
{
	g6_checked = 0;
	g6_queued = 0;
	g7_pushed = 0;
	g7_in_scan = 0;
	g7_p = g7_t = 0;
	absolute = 1;
	laser_on = 0;
	laser_s = 0;
	fb_state.motors_on = 1;
	board_enable_motors(1);
	exec_sync_plan();
}


/*
 * A Ctrl-X is acted on in the receive interrupt, and its mo_stop() frees the
 * slot of the block it drops.  The line waiting for a slot was received before
 * the Ctrl-X, so it must be discarded by do_reset() without a reply, never
 * queued into that slot.  The main loop notices f_reset only at the top of
 * fb_poll(), so every step that would act on a freed slot checks f_reset with
 * interrupts off, in the same critical section as what it acts on.
 */
static uint8_t slot_free(void)
{
	uint8_t sreg = board_irq_save();
	uint8_t ok = !fb_state.f_reset && mo_queue_free();
	board_irq_restore(sreg);
	return ok;
}

/* Queue the block prepared in mo_slot(); 0 (nothing queued) once a Ctrl-X came. */
static uint8_t commit_block(void)
{
	mo_seal(mo_slot());
	uint8_t sreg = board_irq_save();
	uint8_t ok = !fb_state.f_reset;
	if (ok) {
		if (!mo_running() && mo_queue_count() == 0)
			first_queued_ms = board_ms();
		g7_in_scan = mo_slot_raster();
		mo_push();
	}
	board_irq_restore(sreg);
	return ok;
}

/* mo_start() unless *cancel (fb_state.f_reset or .f_home_abort) was set by
 * an interrupt: tested with interrupts off, so none sets it in between. */
void exec_start_unless(volatile uint8_t *cancel)
{
	uint8_t sreg = board_irq_save();
	if (!*cancel)
		mo_start();
	board_irq_restore(sreg);
}

static uint8_t queue_sync_block(uint8_t type, int32_t a, int32_t b)
{
	if (!slot_free())
		return EXEC_WAIT;
	mo_block_t *blk = mo_slot();
	memset(blk, 0, sizeof(*blk));
	blk->type = type;
	blk->q[0] = (uint32_t)a;
	blk->q[1] = (uint32_t)b;
	blk->line = fb_state.lines.last;
	return commit_block() ? FB_OK : EXEC_WAIT;
}

/* The position checks of a G1 target t reached from `from` (protocol section
 * 6, in order): range, soft limits, motors on. */
static uint8_t check_position(const int32_t from[2], const int32_t t[2])
{
	for (uint8_t i = 0; i < 2; i++)
		if (t[i] > CFG_POS_LIMIT || t[i] < -CFG_POS_LIMIT)
			return FB_ERR_OUT_OF_RANGE;
	if (fb_state.settings[SET_SOFT_LIMITS] &&
	    (t[0] < fb_state.settings[SET_A_MIN] || t[0] > fb_state.settings[SET_A_MAX] ||
	     t[1] < fb_state.settings[SET_B_MIN] || t[1] > fb_state.settings[SET_B_MAX]))
		return FB_ERR_SOFT_LIMIT;
	if (!fb_state.motors_on && (t[0] != from[0] || t[1] != from[1]))
		return FB_ERR_MOTORS_OFF;
	return FB_OK;
}

static uint8_t exec_g1(const proto_cmd_t *c)
{
	if (!slot_free())
		return EXEC_WAIT;
	int32_t t[2] = { plan[0], plan[1] };
	if (c->has & PROTO_W_A)
		t[0] = absolute ? c->a : plan[0] + c->a;
	if (c->has & PROTO_W_B)
		t[1] = absolute ? c->b : plan[1] + c->b;
	uint8_t st = check_position(plan, t);
	if (st != FB_OK)
		return st;
	mo_block_t *blk = mo_slot();
	st = mo_prepare(blk, t[0] - plan[0], t[1] - plan[1], (uint32_t)c->p, fb_state.min_interval);
	if (st != FB_OK)
		return st;
	uint8_t s = (c->has & PROTO_W_S) ? (uint8_t)c->s : laser_s;
	blk->power = laser_on ? s : 0;
	blk->line = fb_state.lines.last - c->g6_count;  /* a G6 head: its first number */
	if (!commit_block())
		return EXEC_WAIT;
	laser_s = s;
	plan[0] = t[0];
	plan[1] = t[1];
	return FB_OK;
}

/* The step-rate limit of segments of one duration: the most steps a motor may
 * make in p_us, floor(C / min_interval) (lim), for the duration p_us it was
 * worked out for (0: none yet).  A line's segments mostly share their
 * duration, so g6_check and g7_check keep one on their stack and divide only
 * when the duration changes: the 32-bit division (~600 cycles on the AVR) per
 * segment was a tenth of a segment's cost (python benchmarks/segcost.py). */
typedef struct {
	int32_t p_us;
	uint32_t lim;
} rate_lim_t;

/* Whether target t may be reached from `from` in a segment of p_us (the G1
 * checks of protocol section 6, in order, with mo_prepare's step rate test:
 * floor(C / n) >= min_interval <=> n <= floor(C / min_interval)). */
static uint8_t check_target(const int32_t from[2], const int32_t t[2], int32_t p_us,
			    rate_lim_t *rl)
{
	uint8_t st = check_position(from, t);
	if (st != FB_OK)
		return st;
	if (rl->p_us != p_us) {
		rl->p_us = p_us;
		rl->lim = (uint32_t)p_us * (FB_F_CPU / 1000000UL) / fb_state.min_interval;
	}
	for (uint8_t i = 0; i < 2; i++) {
		int32_t d = t[i] - from[i];
		if ((uint32_t)(d < 0 ? -d : d) > rl->lim)
			return FB_ERR_TOO_FAST;
	}
	return FB_OK;
}

/* Whether the items of a G6 line whose head reaches t pass every check of
 * check_target, from the parse's summary (proto_cmd_t g6_lo, g6_hi, g6_cps):
 * each item's target is t plus a running sum, inside a box exactly when the
 * lowest and highest sums are; a motor moves when a sum is not 0; and the
 * step rates pass when g6_cps >= min_interval (fb_proto.h).  1 proves the
 * line good; 0 says only that some item fails (or the summary does not
 * bound the line), which the item-by-item pass then names. */
static uint8_t g6_fits(const proto_cmd_t *c, const int32_t t[2])
{
	if (!c->g6_cps || c->g6_cps < fb_state.min_interval)
		return 0;
	uint8_t soft = fb_state.settings[SET_SOFT_LIMITS] != 0;
	for (uint8_t i = 0; i < 2; i++) {
		if ((c->g6_lo[i] || c->g6_hi[i]) && !fb_state.motors_on)
			return 0;
		int32_t lo = t[i] + c->g6_lo[i], hi = t[i] + c->g6_hi[i];
		if (lo < -CFG_POS_LIMIT || hi > CFG_POS_LIMIT)
			return 0;
		if (soft && (lo < fb_state.settings[i ? SET_B_MIN : SET_A_MIN] ||
			     hi > fb_state.settings[i ? SET_B_MAX : SET_A_MAX]))
			return 0;
	}
	return 1;
}

/* Every segment of a G6 line against the checks of a G1, before any is
 * queued: a line is queued whole or not at all (docs/protocol.md 6.3).  The
 * parse's summary clears a good line at once (g6_fits); a line it does not
 * clear is read item by item for the first one that fails, so the error is
 * the one the items name in order.  Not inlined (nor g7_check): its arrays
 * would stay in exec_g6's frame while that prepares and queues blocks, the
 * stack's deepest point (python benchmarks/segcost.py prints the headroom). */
static __attribute__((noinline)) uint8_t g6_check(const proto_cmd_t *c)
{
	int32_t from[2] = { plan[0], plan[1] }, t[2] = { plan[0], plan[1] }, d[2];
	if (c->has & PROTO_W_A)
		t[0] = absolute ? c->a : plan[0] + c->a;
	if (c->has & PROTO_W_B)
		t[1] = absolute ? c->b : plan[1] + c->b;
	int32_t p = c->p;
	uint8_t at = c->g6_at;
	rate_lim_t rl = { 0, 0 };
	uint8_t st = check_target(from, t, p, &rl);
	if (st != FB_OK || !c->g6_count || g6_fits(c, t))
		return st;
	while (st == FB_OK && proto_g6_next(fb_state.line, &at, c->g6_end, &p, d)) {
		from[0] = t[0];
		from[1] = t[1];
		t[0] += d[0];
		t[1] += d[1];
		st = check_target(from, t, p, &rl);
	}
	return st;
}

/* G6: the head as a G1, then one block per item, each as its slot frees
 * (EXEC_WAIT in between keeps the line pending); blocks get the numbers
 * first..first+count. */
static uint8_t exec_g6(const proto_cmd_t *c)
{
	if (!g6_checked) {
		uint8_t st = g6_check(c);
		if (st != FB_OK)
			return st;
		g6_checked = 1;
	}
	if (!g6_queued) {
		uint8_t st = exec_g1(c);
		if (st != FB_OK)
			return st;
		g6_queued = 1;
		g6_at = c->g6_at;
		g6_p = c->p;
	}
	uint32_t first = fb_state.lines.last - c->g6_count;
	while (g6_queued <= c->g6_count) {
		if (!slot_free())
			return EXEC_WAIT;
		uint8_t at = g6_at;
		int32_t p = g6_p, d[2];
		if (!proto_g6_next(fb_state.line, &at, c->g6_end, &p, d))
			return FB_ERR_BAD_WORD;  /* not reached: the line was checked */
		mo_block_t *blk = mo_slot();
		uint8_t st = mo_prepare(blk, d[0], d[1], (uint32_t)p, fb_state.min_interval);
		if (st != FB_OK)
			return st;  /* not reached: g6_check ran the same test */
		blk->power = laser_on ? laser_s : 0;
		blk->line = first + g6_queued;
		if (!commit_block())
			return EXEC_WAIT;
		g6_at = at;
		g6_p = p;
		plan[0] += d[0];
		plan[1] += d[1];
		g6_queued++;
		/* a stopped queue starts as soon as it may (it ran empty while
		 * this line was read): the main loop's look comes only once the
		 * line waits for a slot, with the queue full, which kept the
		 * motors still while 16 blocks were prepared (seen in the
		 * emulator's pin trace with a marker pin around the parse) */
		exec_maybe_start();
	}
	return FB_OK;
}

#ifndef FB_SERVO  /* the servo build has no pixel timer: G7 is refused below */
/* Every segment of a G7 line against the G1 checks (the first one's P the
 * modal one), and its pixel run: at most what the ring holds, a period T of
 * at least PX_T_MIN_CYCLES, every change inside the line's segments. */
#define PX_T_MIN_CYCLES 400u
static __attribute__((noinline)) uint8_t g7_check(const proto_cmd_t *c)
{
	int32_t from[2] = { plan[0], plan[1] }, t[2] = { plan[0], plan[1] }, d[2];
	int32_t p = g7_p;
	uint8_t at = c->g6_at, st = FB_OK;
	uint32_t total = 0;
	rate_lim_t rl = { 0, 0 };
	for (uint8_t k = 0; st == FB_OK && k <= c->g6_count; k++) {
		if (!proto_g7_next(fb_state.line, &at, c->g6_end, (uint8_t)((c->g7_pmask >> k) & 1u),
				   &p, d))
			return FB_ERR_BAD_WORD;  /* not reached: the line was parsed */
		if (!p)
			return FB_ERR_MISSING_WORD;  /* no P yet */
		from[0] = t[0];
		from[1] = t[1];
		t[0] += d[0];
		t[1] += d[1];
		st = check_target(from, t, p, &rl);
		uint32_t cyc = (uint32_t)p * (FB_F_CPU / 1000000UL);
		total = total + cyc < total ? 0xffffffffUL : total + cyc;
	}
	if (st != FB_OK || !c->px_n)
		return st;
	uint32_t per = (c->has & PROTO_W_T) ? (uint32_t)c->d : (uint32_t)g7_t;
	if (c->px_n > CFG_PX_RING - PX_HEAD)
		return FB_ERR_OUT_OF_RANGE;
	if (c->px_n > 1 && !per)
		return FB_ERR_MISSING_WORD;
	if (c->px_n > 1 && per < PX_T_MIN_CYCLES)
		return FB_ERR_OUT_OF_RANGE;
	uint32_t last = (uint32_t)c->r + (uint32_t)(c->px_n - 1u) * per;  /* <= 1.6e9 + 117 * 1.6e7 */
	return last < total ? FB_OK : FB_ERR_OUT_OF_RANGE;
}

/* The pending G7 line's run into the ring (when it has pixels) and whether it
 * starts a scan: the first G7 block after any other block, or on an idle
 * machine.  EXEC_WAIT while the ring or the queue has no room. */
static uint8_t g7_push(const proto_cmd_t *c)
{
	uint8_t need = c->px_n ? (uint8_t)(PX_HEAD + c->px_n) : 0u;
	if (!slot_free())
		return EXEC_WAIT;
	if (px_room() < need) {
		if (exec_idle())
			px_init();  /* nothing left to burn: a broken scan's leftovers */
		px_drop_broken();
		if (px_room() < need)
			return EXEC_WAIT;
	}
	g7_new = !g7_in_scan || exec_idle();
	if (g7_new) {
		g7_scan = (uint8_t)(g7_scan + 1u) ? (uint8_t)(g7_scan + 1u) : 1u;
		g7_time = g7_last = 0;
	}
	if (c->px_n) {
		uint32_t per = (c->has & PROTO_W_T) ? (uint32_t)c->d : (uint32_t)g7_t;
		uint32_t first = g7_time + (uint32_t)c->r;
		px_push(g7_scan, c->px_n, first - g7_last, per, fb_state.line + c->px_at,
			(uint8_t)(c->px_end - c->px_at), !laser_on);
		g7_last = first + (uint32_t)(c->px_n - 1u) * per;
	}
	g7_pushed = 1;
	return FB_OK;
}

/* G7: its run, then one block per segment as slots free (EXEC_WAIT in
 * between keeps the line pending, as a G6's); blocks get the numbers
 * first..first+count; the first of a new scan is its MO_BLK_SCAN. */
static uint8_t exec_g7(const proto_cmd_t *c)
{
	if (!g6_checked) {
		uint8_t st = g7_check(c);
		if (st != FB_OK)
			return st;
		g6_checked = 1;
		g6_at = c->g6_at;
		g6_p = g7_p;
	}
	if (!g7_pushed) {
		uint8_t st = g7_push(c);
		if (st != FB_OK)
			return st;
	}
	uint32_t first = fb_state.lines.last - c->g6_count;
	while (g6_queued <= c->g6_count) {
		if (!slot_free())
			return EXEC_WAIT;
		uint8_t at = g6_at;
		int32_t p = g6_p, d[2];
		if (!proto_g7_next(fb_state.line, &at, c->g6_end,
				   (uint8_t)((c->g7_pmask >> g6_queued) & 1u), &p, d))
			return FB_ERR_BAD_WORD;  /* not reached: the line was checked */
		mo_block_t *blk = mo_slot();
		uint8_t st = mo_prepare(blk, d[0], d[1], (uint32_t)p, fb_state.min_interval);
		if (st != FB_OK)
			return st;  /* not reached: g7_check ran the same test */
		blk->type = (g7_new && !g6_queued) ? MO_BLK_SCAN : MO_BLK_RASTER;
		blk->power = g7_scan;
		blk->line = first + g6_queued;
		if (!commit_block())
			return EXEC_WAIT;
		g7_time += blk->cycles;
		g6_at = at;
		g6_p = p;
		plan[0] += d[0];
		plan[1] += d[1];
		g6_queued++;
		exec_maybe_start();  /* as exec_g6's */
	}
	g7_p = g6_p;
	if (c->has & PROTO_W_T)
		g7_t = c->d;
	return FB_OK;
}
#endif

/* M280: a queued pen block (protocol section 6.2). */
static uint8_t exec_pen(const proto_cmd_t *c)
{
	if (!fb_state.settings[SET_PEN_PARK])
		return FB_ERR_NO_PEN;
	if (!slot_free())
		return EXEC_WAIT;
	uint16_t to = (uint16_t)c->s;
	mo_block_t *blk = mo_slot();
	mo_prepare_pen(blk, pen_plan, to, (uint16_t)c->r, (uint16_t)c->d);
	blk->line = fb_state.lines.last;
	if (!commit_block())
		return EXEC_WAIT;
	pen_plan = to;
	return FB_OK;
}

static uint8_t execute(const proto_cmd_t *c)
{
	if (fb_state.alarm_code) {
		switch (c->kind) {
		case PROTO_CMD_NONE: case PROTO_CMD_M110: case PROTO_CMD_INFO: case PROTO_CMD_LIST:
		case PROTO_CMD_SET: case PROTO_CMD_HOME: case PROTO_CMD_UNLOCK:
			break;
		default:
			return FB_ERR_ALARM_LOCK;
		}
	}
	switch (c->kind) {
	case PROTO_CMD_G1:
		return exec_g1(c);
	case PROTO_CMD_G6:
		return exec_g6(c);
	case PROTO_CMD_G7:
#ifdef FB_SERVO
		return FB_ERR_UNKNOWN_COMMAND;  /* no raster on servo joints (docs/protocol.md 6.5) */
#else
		return exec_g7(c);
#endif
	case PROTO_CMD_G90:
		absolute = 1;
		return FB_OK;
	case PROTO_CMD_G91:
		absolute = 0;
		return FB_OK;
	case PROTO_CMD_G92: {
		int32_t a = (c->has & PROTO_W_A) ? c->a : plan[0];
		int32_t b = (c->has & PROTO_W_B) ? c->b : plan[1];
		uint8_t st = queue_sync_block(MO_BLK_SETPOS, a, b);
		if (st == FB_OK) {
			plan[0] = a;
			plan[1] = b;
		}
		return st;
	}
	case PROTO_CMD_M3:
		laser_on = 1;
		if (c->has & PROTO_W_S)
			laser_s = (uint8_t)c->s;
		return FB_OK;
	case PROTO_CMD_M5:
		laser_on = 0;
		return FB_OK;
	case PROTO_CMD_M280:
		return exec_pen(c);
	case PROTO_CMD_M17:
	case PROTO_CMD_M18: {
		uint8_t st = queue_sync_block(c->kind == PROTO_CMD_M17 ? MO_BLK_ENABLE : MO_BLK_DISABLE, 0, 0);
		if (st == FB_OK)
			fb_state.motors_on = c->kind == PROTO_CMD_M17;
		return st;
	}
	case PROTO_CMD_INFO:
		report_banner();
		return FB_OK;
	case PROTO_CMD_LIST:
		settings_list();
		return FB_OK;
	case PROTO_CMD_HOME:
		return home_cycle();
	case PROTO_CMD_UNLOCK:
		fb_state.alarm_code = 0;
		exec_sync_plan();
		return FB_OK;
	case PROTO_CMD_SET:
		return settings_set(c);
	case PROTO_CMD_BAUD:
		return baud_request(c);
	default:
		return FB_OK;
	}
}

uint8_t exec_command(const proto_cmd_t *c)
{
	uint8_t st = execute(c);
	if (st != EXEC_WAIT) {
		g6_checked = 0;
		g6_queued = 0;
		g7_pushed = 0;
	}
	return st;
}

void exec_maybe_start(void)
{
	if (fb_state.held || fb_state.alarm_code || fb_state.homing || mo_running())
		return;
	uint8_t n = mo_queue_count();
	if (!n)
		return;
	if (n >= CFG_START_BLOCKS || !mo_queue_free() ||
	    board_ms() - first_queued_ms >= CFG_START_DELAY_MS)
		exec_start_unless(&fb_state.f_reset);
}
