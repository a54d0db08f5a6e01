/*
 * fb_main.c - protocol state machine of the fivebar firmware.
 *
 * Real-time bytes (? ! ~ Ctrl-X) are acted on inside the receive interrupt;
 * every other byte goes through the receive ring into the line buffer, and
 * each '\n' gets exactly one reply ("ok" or "error:<code>"), in order, so a
 * host can count characters against the ring size given in the banner.
 */
#include <string.h>
#include "fb_main.h"
#include "fb_proto.h"
#include "fb_motion.h"
#include "board.h"
#include "board_uart.h"
#include "config.h"
#include "status.h"

#if CFG_RX_SIZE != 128 && CFG_RX_SIZE != 64 && CFG_RX_SIZE != 32
#error "CFG_RX_SIZE must be 32, 64 or 128"
#endif
#define RX_MASK (CFG_RX_SIZE - 1u)

#define CTRL_X 0x18

enum { SET_MAX_RATE, SET_A_MIN, SET_A_MAX, SET_B_MIN, SET_B_MAX, SET_SOFT_LIMITS,
       SET_LASER_TIMEOUT, SET_HOMING, SET_HOMING_RATE, SET_PULLOFF, SET_HOME_A,
       SET_HOME_B, SET_TRAVEL, SET_HOMING_DIR, SET_PEN_PARK, SET_COUNT };

enum { HOLD_HOST = 0, HOLD_LASER_TIMEOUT = 1, HOLD_ERROR = 2 };

/* receive ring: free-running indices, so all CFG_RX_SIZE bytes are usable */
static volatile uint8_t rx_buf[CFG_RX_SIZE];
static volatile uint8_t rx_head, rx_tail, rx_discard, rx_overflow;
static volatile uint32_t last_rx_ms;
static volatile uint8_t f_status, f_reset, f_home_abort;
static volatile uint8_t held, hold_reason, homing, alarm;
/* a '~' lowered a parked pen again: the timeline resumes at this board_ms()
 * (0 = no resume pending) */
static volatile uint32_t resume_at;

static char line[CFG_LINE_MAX];
static uint8_t line_len, line_over;
static fb_lines_t lines;
static fb_cmd_t cmd;
static uint8_t pending;
/* the pending G6 line: checked as a whole, segments queued so far (0: none,
 * 1: its head), where its next item starts, its current duration */
static uint8_t g6_checked, g6_queued, g6_at;
static int32_t g6_p;

/* $B (protocol section 1.1): the rate to switch to once its ok has left,
 * the rate in force, and when a switched rate began its trial (it falls back
 * to FB_BAUD unless a valid line arrives within BAUD_TRIAL_MS) */
#define BAUD_TRIAL_MS 1000u
static uint32_t baud_next, baud_now;
static uint32_t baud_since_ms;
static uint8_t baud_trial;

static int32_t settings[SET_COUNT];
static uint32_t min_interval;
static uint8_t absolute, laser_on, laser_s, motors_on;
static int32_t plan[2];
static uint16_t pen_plan;  /* pen pulse after the queued M280 blocks */
static uint32_t first_queued_ms;

/* ---- output ---------------------------------------------------------------- */

static void put_P(const char *s)
{
	char c;
	while ((c = fb_pgm_char(s++)) != 0)
		board_tx((uint8_t)c);
}

static void put_u32(uint32_t v)
{
	char d[10];
	uint8_t n = 0;
	do {
		d[n++] = (char)('0' + v % 10u);
		v /= 10u;
	} while (v);
	while (n)
		board_tx((uint8_t)d[--n]);
}

static void put_i32(int32_t v)
{
	if (v < 0) {
		board_tx('-');
		put_u32((uint32_t)0 - (uint32_t)v);
	} else {
		put_u32((uint32_t)v);
	}
}

static void put_eol(void) { put_P(FB_PSTR("\r\n")); }

static void banner(void)
{
	put_P(FB_PSTR("fivebar " FB_VERSION " proto:"));
	put_u32(FB_PROTOCOL);
	put_P(FB_PSTR(" rx:"));
	put_u32(CFG_RX_SIZE);
	put_P(FB_PSTR(" queue:"));
	put_u32(CFG_QUEUE_SIZE);
	put_P(FB_PSTR(" line:"));
	put_u32(CFG_LINE_MAX);
	put_eol();
}

static void reply_error(uint8_t code)
{
	put_P(FB_PSTR("error:"));
	put_u32(code);
	if (fb_is_resend(code)) {
		put_P(FB_PSTR(" resend:"));
		put_u32(lines.last + 1u);
	}
	put_eol();
}

static void status_report(void)
{
	int32_t pos[2];
	mo_get_pos(pos);
	board_tx('<');
	if (alarm) {
		put_P(FB_PSTR("Alarm:"));
		put_u32(alarm);
	} else if (homing) {
		put_P(FB_PSTR("Home"));
	} else if (held) {
		put_P(FB_PSTR("Hold:"));
		put_u32(hold_reason);
	} else if (mo_running() || mo_queue_count()) {
		put_P(FB_PSTR("Run"));
	} else {
		put_P(FB_PSTR("Idle"));
	}
	put_P(FB_PSTR("|A:"));
	put_i32(pos[0]);
	put_P(FB_PSTR(",B:"));
	put_i32(pos[1]);
	put_P(FB_PSTR("|Q:"));
	put_u32(mo_queue_waiting());
	put_P(FB_PSTR("|Ln:"));
	put_u32(mo_done_line());
	board_tx(',');
	put_u32(lines.last);
	put_P(FB_PSTR("|L:"));
	put_u32(mo_laser());
	put_P(FB_PSTR("|U:"));
	put_u32(mo_underruns());
	put_P(FB_PSTR("|H:"));
	board_tx(mo_homed() ? '1' : '0');
	put_P(FB_PSTR("|P:"));
	put_u32(mo_pen());
	board_tx('>');
	put_eol();
}

/* ---- settings -------------------------------------------------------------- */

static void settings_defaults(void)
{
	settings[SET_MAX_RATE] = DEF_MAX_RATE;
	settings[SET_A_MIN] = DEF_LIMIT_A_MIN;
	settings[SET_A_MAX] = DEF_LIMIT_A_MAX;
	settings[SET_B_MIN] = DEF_LIMIT_B_MIN;
	settings[SET_B_MAX] = DEF_LIMIT_B_MAX;
	settings[SET_SOFT_LIMITS] = DEF_SOFT_LIMITS;
	settings[SET_LASER_TIMEOUT] = DEF_LASER_TIMEOUT;
	settings[SET_HOMING] = DEF_HOMING_ENABLE;
	settings[SET_HOMING_RATE] = DEF_HOMING_RATE;
	settings[SET_PULLOFF] = DEF_HOMING_PULLOFF;
	settings[SET_HOME_A] = DEF_HOME_A;
	settings[SET_HOME_B] = DEF_HOME_B;
	settings[SET_TRAVEL] = DEF_HOMING_TRAVEL;
	settings[SET_HOMING_DIR] = DEF_HOMING_DIR;
	uint16_t park = board_pen_park_load();
	settings[SET_PEN_PARK] = park == 0xffffu ? DEF_PEN_PARK : park;
}

static uint32_t interval_for(int32_t rate)
{
	return (uint32_t)((FB_F_CPU + (uint32_t)rate - 1u) / (uint32_t)rate);
}

/* Motors whose switch lies in the negative direction ($13 clear bits). */
static uint8_t seek_neg_mask(void)
{
	return (uint8_t)(~settings[SET_HOMING_DIR] & 3);
}

static void settings_apply(void)
{
	min_interval = interval_for(settings[SET_MAX_RATE]);
	mo_set_endstops((uint8_t)settings[SET_HOMING], seek_neg_mask());
}

/* Range of setting n, or 0 when there is no such setting. */
static uint8_t setting_range(uint8_t n, int32_t *lo, int32_t *hi)
{
	switch (n) {
	case SET_MAX_RATE: case SET_HOMING_RATE:
		*lo = 1; *hi = CFG_MAX_RATE_LIMIT; return 1;
	case SET_A_MIN: case SET_A_MAX: case SET_B_MIN: case SET_B_MAX:
	case SET_HOME_A: case SET_HOME_B:
		*lo = -CFG_POS_LIMIT; *hi = CFG_POS_LIMIT; return 1;
	case SET_SOFT_LIMITS: case SET_HOMING:
		*lo = 0; *hi = 1; return 1;
	case SET_LASER_TIMEOUT:
		*lo = 100; *hi = 60000; return 1;
	case SET_PULLOFF:
		*lo = 0; *hi = 1000000L; return 1;
	case SET_TRAVEL:
		*lo = 1; *hi = 10000000L; return 1;
	case SET_HOMING_DIR:
		*lo = 0; *hi = 3; return 1;
	case SET_PEN_PARK:
		*lo = 0; *hi = CFG_SERVO_MAX_US; return 1;
	default:
		return 0;
	}
}

/* ---- state ----------------------------------------------------------------- */

static uint8_t is_idle(void)
{
	return !mo_running() && mo_queue_count() == 0 && !homing;
}

static void sync_plan(void)
{
	mo_get_pos(plan);
	pen_plan = mo_pen_target();
}

static void raise_alarm(uint8_t code)
{
	mo_stop();
	mo_clear_queue();
	held = 0;
	resume_at = 0;
	alarm = code;
	sync_plan();
	put_P(FB_PSTR("ALARM:"));
	put_u32(code);
	put_eol();
}

static void do_reset(void)
{
	uint8_t sreg = board_irq_save();
	f_reset = 0;
	rx_tail = rx_discard;
	rx_overflow = 0;
	held = 0;
	resume_at = 0;
	board_irq_restore(sreg);
	mo_init();
	line_len = 0;
	line_over = 0;
	pending = 0;
	g6_checked = 0;
	g6_queued = 0;
	lines.last = 0;
	lines.numbered = 0;
	absolute = 1;
	laser_on = 0;
	laser_s = 0;
	motors_on = 1;
	board_enable_motors(1);
	sync_plan();
	baud_next = 0;
	baud_trial = 0;
	if (baud_now != FB_BAUD) {  /* a reset or Ctrl-X speaks at the base rate */
		board_uart_baud(FB_BAUD);
		baud_now = FB_BAUD;
	}
	banner();
}

void fb_rx_isr(uint8_t c)
{
	last_rx_ms = board_ms();
	switch (c) {
	case '?':
		f_status = 1;
		return;
	case '!':
		if (homing) {
			f_home_abort = 1;
			mo_stop();
		} else if (!held && !alarm) {
			held = 1;
			hold_reason = HOLD_HOST;
			mo_hold();
		} else if (resume_at) {
			/* held again while the pen was going back down */
			resume_at = 0;
			hold_reason = HOLD_HOST;
			mo_hold();
		}
		return;
	case '~':
		if (held && !resume_at) {
			/* a parked pen goes back first; the timeline waits its time */
			uint16_t ms = mo_pen_unpark();
			if (ms) {
				resume_at = board_ms() + ms;
				if (!resume_at)
					resume_at = 1;
			} else {
				held = 0;
				mo_resume();
			}
		}
		return;
	case CTRL_X:
		mo_stop();
		if (homing)
			f_home_abort = 1;
		f_reset = 1;
		rx_discard = rx_head;
		return;
	default:
		break;
	}
	uint8_t h = rx_head;
	if ((uint8_t)(h - rx_tail) >= CFG_RX_SIZE) {
		rx_overflow = 1;
		return;
	}
	rx_buf[h & RX_MASK] = c;
	rx_head = (uint8_t)(h + 1u);
}

/* ---- commands -------------------------------------------------------------- */

#define ST_WAIT 0xffu   /* queue full: try again later */

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
	uint8_t ok = !f_reset && mo_queue_free();
	board_irq_restore(sreg);
	return ok;
}

/* Queue the block prepared in mo_slot(); 0 (nothing queued) once a Ctrl-X came. */
static uint8_t commit_block(void)
{
	uint8_t sreg = board_irq_save();
	uint8_t ok = !f_reset;
	if (ok) {
		if (!mo_running() && mo_queue_count() == 0)
			first_queued_ms = board_ms();
		mo_push();
	}
	board_irq_restore(sreg);
	return ok;
}

/* mo_start() unless *cancel (f_reset, f_home_abort) was set by an interrupt. */
static void start_unless(volatile uint8_t *cancel)
{
	uint8_t sreg = board_irq_save();
	if (!*cancel)
		mo_start();
	board_irq_restore(sreg);
}

static uint8_t queue_sync_block(uint8_t type, int32_t a, int32_t b)
{
	if (!slot_free())
		return ST_WAIT;
	fb_block_t *blk = mo_slot();
	memset(blk, 0, sizeof(*blk));
	blk->type = type;
	blk->q[0] = (uint32_t)a;
	blk->q[1] = (uint32_t)b;
	blk->line = lines.last;
	return commit_block() ? FB_OK : ST_WAIT;
}

static uint8_t exec_g1(const fb_cmd_t *c)
{
	if (!slot_free())
		return ST_WAIT;
	int32_t t[2] = { plan[0], plan[1] };
	if (c->has & W_A)
		t[0] = absolute ? c->a : plan[0] + c->a;
	if (c->has & W_B)
		t[1] = absolute ? c->b : plan[1] + c->b;
	for (uint8_t i = 0; i < 2; i++)
		if (t[i] > CFG_POS_LIMIT || t[i] < -CFG_POS_LIMIT)
			return FB_ERR_OUT_OF_RANGE;
	if (settings[SET_SOFT_LIMITS] &&
	    (t[0] < settings[SET_A_MIN] || t[0] > settings[SET_A_MAX] ||
	     t[1] < settings[SET_B_MIN] || t[1] > settings[SET_B_MAX]))
		return FB_ERR_SOFT_LIMIT;
	if (!motors_on && (t[0] != plan[0] || t[1] != plan[1]))
		return FB_ERR_MOTORS_OFF;
	fb_block_t *blk = mo_slot();
	uint8_t st = mo_prepare(blk, t[0] - plan[0], t[1] - plan[1], (uint32_t)c->p, min_interval);
	if (st != FB_OK)
		return st;
	uint8_t s = (c->has & W_S) ? (uint8_t)c->s : laser_s;
	blk->power = laser_on ? s : 0;
	blk->line = lines.last - c->g6_count;  /* a G6 head: its first number */
	if (!commit_block())
		return ST_WAIT;
	laser_s = s;
	plan[0] = t[0];
	plan[1] = t[1];
	return FB_OK;
}

/* Whether target t may be reached from `from` in a segment of p_us (the G1
 * checks of protocol section 6, in order, with mo_prepare's step rate test:
 * floor(C / n) >= min_interval <=> n <= floor(C / min_interval)). */
static uint8_t check_target(const int32_t from[2], const int32_t t[2], int32_t p_us)
{
	for (uint8_t i = 0; i < 2; i++)
		if (t[i] > CFG_POS_LIMIT || t[i] < -CFG_POS_LIMIT)
			return FB_ERR_OUT_OF_RANGE;
	if (settings[SET_SOFT_LIMITS] &&
	    (t[0] < settings[SET_A_MIN] || t[0] > settings[SET_A_MAX] ||
	     t[1] < settings[SET_B_MIN] || t[1] > settings[SET_B_MAX]))
		return FB_ERR_SOFT_LIMIT;
	if (!motors_on && (t[0] != from[0] || t[1] != from[1]))
		return FB_ERR_MOTORS_OFF;
	uint32_t lim = (uint32_t)p_us * (FB_F_CPU / 1000000UL) / min_interval;
	for (uint8_t i = 0; i < 2; i++) {
		int32_t d = t[i] - from[i];
		if ((uint32_t)(d < 0 ? -d : d) > lim)
			return FB_ERR_TOO_FAST;
	}
	return FB_OK;
}

/* Every segment of a G6 line against the checks of a G1, before any is
 * queued: a line is queued whole or not at all (docs/protocol.md 6.3). */
static uint8_t g6_check(const fb_cmd_t *c)
{
	int32_t from[2] = { plan[0], plan[1] }, t[2] = { plan[0], plan[1] }, d[2];
	if (c->has & W_A)
		t[0] = absolute ? c->a : plan[0] + c->a;
	if (c->has & W_B)
		t[1] = absolute ? c->b : plan[1] + c->b;
	int32_t p = c->p;
	uint8_t at = c->g6_at;
	uint8_t st = check_target(from, t, p);
	while (st == FB_OK && fb_g6_next(line, &at, c->g6_end, &p, d)) {
		from[0] = t[0];
		from[1] = t[1];
		t[0] += d[0];
		t[1] += d[1];
		st = check_target(from, t, p);
	}
	return st;
}

/* G6: the head as a G1, then one block per item, each as its slot frees
 * (ST_WAIT in between keeps the line pending); blocks get the numbers
 * first..first+count. */
static uint8_t exec_g6(const fb_cmd_t *c)
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
	uint32_t first = lines.last - c->g6_count;
	while (g6_queued <= c->g6_count) {
		if (!slot_free())
			return ST_WAIT;
		uint8_t at = g6_at;
		int32_t p = g6_p, d[2];
		if (!fb_g6_next(line, &at, c->g6_end, &p, d))
			return FB_ERR_BAD_WORD;  /* not reached: the line was checked */
		fb_block_t *blk = mo_slot();
		uint8_t st = mo_prepare(blk, d[0], d[1], (uint32_t)p, min_interval);
		if (st != FB_OK)
			return st;  /* not reached: g6_check ran the same test */
		blk->power = laser_on ? laser_s : 0;
		blk->line = first + g6_queued;
		if (!commit_block())
			return ST_WAIT;
		g6_at = at;
		g6_p = p;
		plan[0] += d[0];
		plan[1] += d[1];
		g6_queued++;
	}
	return FB_OK;
}

/* M280: a queued pen block (protocol section 6.2). */
static uint8_t exec_pen(const fb_cmd_t *c)
{
	if (!settings[SET_PEN_PARK])
		return FB_ERR_NO_PEN;
	if (!slot_free())
		return ST_WAIT;
	uint16_t to = (uint16_t)c->s;
	fb_block_t *blk = mo_slot();
	mo_prepare_pen(blk, pen_plan, to, (uint16_t)c->r, (uint16_t)c->d);
	blk->line = lines.last;
	if (!commit_block())
		return ST_WAIT;
	pen_plan = to;
	return FB_OK;
}

/*
 * The hardware watchdog (board.h): fed from the main loop (fb_poll and the
 * homing wait, its only long inner loop), and only while the step generator
 * is alive too: stopped or held legitimately, or its interrupt ran since the
 * last look (mo_alive).  So a main loop that hangs (interrupts on or off), a
 * step interrupt that spins, and a step interrupt that stopped coming while
 * the generator runs all stop the feeding, and the watchdog resets the MCU:
 * laser off at once (board_avr.c), position, H and Ln done kept (section 7).
 */
static void feed_watchdog(void)
{
	if (mo_alive())
		board_wdt_feed();
}

/* Wait for the generator to stop, serving status requests; 0 if aborted. */
static uint8_t home_wait(void)
{
	while (mo_running()) {
		feed_watchdog();
		board_idle();
		if (f_status) {
			f_status = 0;
			status_report();
		}
		if (f_home_abort)
			return 0;
	}
	return !f_home_abort;
}

static uint8_t home_move(uint8_t type, uint8_t axes, uint8_t neg, uint32_t steps, uint32_t interval)
{
	fb_block_t *blk = mo_slot();
	int32_t d[2];
	for (uint8_t i = 0; i < 2; i++)
		d[i] = (axes & (1u << i)) ? ((neg & (1u << i)) ? -(int32_t)steps : (int32_t)steps) : 0;
	mo_prepare_cycles(blk, d[0], d[1], steps * interval, 0);
	blk->type = type;
	blk->power = 0;
	blk->line = lines.last;
	mo_push();
	start_unless(&f_home_abort);
	return home_wait();
}

static uint8_t exec_home(void)
{
	if (!settings[SET_HOMING])
		return FB_ERR_HOMING_DISABLED;
	if (!is_idle() || held)
		return FB_ERR_BUSY;
	if (!motors_on)
		return FB_ERR_MOTORS_OFF;
	homing = 1;
	f_home_abort = 0;
	mo_reset_home_hits();
	/* the position is unknown until homed: count the seek from 0, which
	 * also keeps repeated failed homings from running the counter away.  H
	 * goes first, so a reset in between never keeps H:1 with position 0. */
	int32_t zero[2] = { 0, 0 };
	mo_set_homed(0);
	mo_set_pos(zero);
	sync_plan();
	uint32_t interval = interval_for(settings[SET_HOMING_RATE]);
	uint32_t chunk_max = 0x7fffffffUL / interval;
	uint8_t seek_neg = seek_neg_mask();
	uint32_t left = (uint32_t)settings[SET_TRAVEL];
	uint8_t result = FB_OK;
	while (left && (mo_home_hits() & 3u) != 3u) {
		uint32_t chunk = left < chunk_max ? left : chunk_max;
		if (!home_move(BLK_HOME, (uint8_t)(~mo_home_hits() & 3u), seek_neg, chunk, interval)) {
			result = FB_ALARM_HOMING_ABORT;
			break;
		}
		left -= chunk;
	}
	if (result == FB_OK && (mo_home_hits() & 3u) != 3u)
		result = FB_ALARM_HOMING_FAIL;
	if (result == FB_OK && settings[SET_PULLOFF] > 0 &&
	    !home_move(BLK_MOVE, 3u, (uint8_t)(~seek_neg & 3u),
		       (uint32_t)settings[SET_PULLOFF], interval))
		result = FB_ALARM_HOMING_ABORT;
	if (result == FB_OK && board_endstops())
		result = FB_ALARM_HOMING_FAIL;
	homing = 0;
	if (result != FB_OK) {
		raise_alarm(result);
		return result;
	}
	int32_t home[2] = { settings[SET_HOME_A], settings[SET_HOME_B] };
	mo_set_pos(home);
	mo_set_homed(1);
	sync_plan();
	alarm = 0;
	return FB_OK;
}

static uint8_t exec_set(const fb_cmd_t *c)
{
	int32_t lo, hi;
	if (!setting_range(c->setting, &lo, &hi))
		return FB_ERR_UNKNOWN_SETTING;
	if (c->value < lo || c->value > hi ||
	    (c->setting == SET_PEN_PARK && c->value && c->value < CFG_SERVO_MIN_US))
		return FB_ERR_OUT_OF_RANGE;
	if (!is_idle())
		return FB_ERR_BUSY;
	settings[c->setting] = c->value;
	settings_apply();
	if (c->setting == SET_PEN_PARK) {
		board_pen_park_store((uint16_t)c->value);
		mo_pen_setup((uint16_t)c->value);
		sync_plan();
	}
	return FB_OK;
}

/* $B=<baud>: one of the rates the Uno's 16 MHz makes (115200 within 0.8 %,
 * the others exactly); the switch waits for the ok (switch_baud). */
static uint8_t exec_baud(const fb_cmd_t *c)
{
	switch (c->value) {
	case 115200L: case 250000L: case 500000L: case 1000000L:
		baud_next = (uint32_t)c->value;
		return FB_OK;
	default:
		return FB_ERR_OUT_OF_RANGE;
	}
}

/* After $B's ok: the new rate, on trial until a valid line arrives. */
static void switch_baud(void)
{
	board_uart_baud(baud_next);
	baud_now = baud_next;
	baud_next = 0;
	baud_trial = baud_now != FB_BAUD;
	baud_since_ms = board_ms();
}

/* No valid line within BAUD_TRIAL_MS of a switch: the host cannot speak at
 * that rate, back to the base rate (the host falls back too). */
static void baud_fallback(void)
{
	if (baud_trial && board_ms() - baud_since_ms > BAUD_TRIAL_MS) {
		baud_trial = 0;
		board_uart_baud(FB_BAUD);
		baud_now = FB_BAUD;
	}
}

static void list_settings(void)
{
	for (uint8_t i = 0; i < SET_COUNT; i++) {
		board_tx('$');
		put_u32(i);
		board_tx('=');
		put_i32(settings[i]);
		put_eol();
	}
}

static uint8_t execute(const fb_cmd_t *c)
{
	if (alarm) {
		switch (c->kind) {
		case CMD_NONE: case CMD_M110: case CMD_INFO: case CMD_LIST:
		case CMD_SET: case CMD_HOME: case CMD_UNLOCK:
			break;
		default:
			return FB_ERR_ALARM_LOCK;
		}
	}
	switch (c->kind) {
	case CMD_G1:
		return exec_g1(c);
	case CMD_G6:
		return exec_g6(c);
	case CMD_G90:
		absolute = 1;
		return FB_OK;
	case CMD_G91:
		absolute = 0;
		return FB_OK;
	case CMD_G92: {
		int32_t a = (c->has & W_A) ? c->a : plan[0];
		int32_t b = (c->has & W_B) ? c->b : plan[1];
		uint8_t st = queue_sync_block(BLK_SETPOS, a, b);
		if (st == FB_OK) {
			plan[0] = a;
			plan[1] = b;
		}
		return st;
	}
	case CMD_M3:
		laser_on = 1;
		if (c->has & W_S)
			laser_s = (uint8_t)c->s;
		return FB_OK;
	case CMD_M5:
		laser_on = 0;
		return FB_OK;
	case CMD_M280:
		return exec_pen(c);
	case CMD_M17:
	case CMD_M18: {
		uint8_t st = queue_sync_block(c->kind == CMD_M17 ? BLK_ENABLE : BLK_DISABLE, 0, 0);
		if (st == FB_OK)
			motors_on = c->kind == CMD_M17;
		return st;
	}
	case CMD_INFO:
		banner();
		return FB_OK;
	case CMD_LIST:
		list_settings();
		return FB_OK;
	case CMD_HOME:
		return exec_home();
	case CMD_UNLOCK:
		alarm = 0;
		sync_plan();
		return FB_OK;
	case CMD_SET:
		return exec_set(c);
	case CMD_BAUD:
		return exec_baud(c);
	default:
		return FB_OK;
	}
}

/* An error refusing part of a running job stops it: laser off, motion held. */
static void error_hold(void)
{
	uint8_t sreg = board_irq_save();
	if (!held && (mo_running() || mo_queue_count())) {
		held = 1;
		hold_reason = HOLD_ERROR;
		mo_hold();
	}
	board_irq_restore(sreg);
}

static void finish(uint8_t st)
{
	if (st == FB_OK) {
		put_P(FB_PSTR("ok"));
		put_eol();
		return;
	}
	if (!fb_is_resend(st))
		error_hold();
	reply_error(st);
}

static void try_execute(void)
{
	uint8_t st = execute(&cmd);
	if (st == ST_WAIT)
		return;
	pending = 0;
	g6_checked = 0;
	g6_queued = 0;
	finish(st);
	if (baud_next)
		switch_baud();
}

static void handle_line(void)
{
	uint8_t over = line_over, len = line_len;
	line_len = 0;
	line_over = 0;
	if (rx_overflow) {
		rx_overflow = 0;
		finish(FB_ERR_RX_OVERFLOW);
		return;
	}
	if (over) {
		/* In numbered mode the host never sends such a line: it is line noise,
		 * most often two lines merged by a lost newline, and its checksum
		 * field was cut off, so it is refused with a resend like any line
		 * whose field does not check (docs/protocol.md 5.2, step 2). */
		finish(lines.numbered ? FB_ERR_CHECKSUM : FB_ERR_LINE_TOO_LONG);
		return;
	}
	uint8_t st = fb_parse_line(&lines, line, len, &cmd);
	if (st == FB_OK)
		baud_trial = 0;  /* the host speaks at this rate */
	if (st != FB_OK) {
		finish(st);
		return;
	}
	pending = 1;
	try_execute();
}

/* Move received bytes into the line buffer; handle at most one line. */
static void assemble(void)
{
	/* after a Ctrl-X, the lines received before it are do_reset()'s to discard */
	while (!f_reset && rx_tail != rx_head) {
		uint8_t t = rx_tail;
		uint8_t c = rx_buf[t & RX_MASK];
		rx_tail = (uint8_t)(t + 1u);
		if (c == '\n') {
			handle_line();
			return;
		}
		if (c == '\r')
			continue;
		if (line_len < CFG_LINE_MAX)
			line[line_len++] = (char)c;
		else
			line_over = 1;
	}
}

static uint32_t since_last_rx(void)
{
	uint8_t sreg = board_irq_save();
	uint32_t t = last_rx_ms;
	board_irq_restore(sreg);
	return board_ms() - t;
}

/*
 * Host silence (protocol section 9): with the laser on or the pen down and
 * no byte for $6 ms, a job is held (laser off, pen parked); an idle machine
 * only parks its pen.
 */
static void laser_watchdog(void)
{
	if (!held && (mo_laser() || mo_pen_down()) &&
	    since_last_rx() > (uint32_t)settings[SET_LASER_TIMEOUT]) {
		uint8_t sreg = board_irq_save();
		if (mo_running() || mo_queue_count()) {
			held = 1;
			hold_reason = HOLD_LASER_TIMEOUT;
			mo_hold();
		} else {
			mo_pen_park();
		}
		board_irq_restore(sreg);
	}
}

/* After a '~' that lowered a parked pen: resume once it has had its time. */
static void resume_when_settled(void)
{
	/* resume_at is set only while held: the byte keeps this cheap on every
	 * pass of a running job (the main loop's cycles are scarce at high step
	 * rates); a torn read is re-checked below, interrupts off */
	if (!held || !resume_at)
		return;
	uint8_t sreg = board_irq_save();
	if (resume_at && (int32_t)(board_ms() - resume_at) >= 0) {
		resume_at = 0;
		held = 0;
		mo_resume();
	}
	board_irq_restore(sreg);
}

static void maybe_start(void)
{
	if (held || alarm || homing || mo_running())
		return;
	uint8_t n = mo_queue_count();
	if (!n)
		return;
	if (n >= CFG_START_BLOCKS || !mo_queue_free() ||
	    board_ms() - first_queued_ms >= CFG_START_DELAY_MS)
		start_unless(&f_reset);
}

void fb_setup(void)
{
	board_init();
	settings_defaults();
	settings_apply();
	alarm = 0;
	/* position, H and Ln done survive a reset that leaves the RAM powered;
	 * after a power-on they start at 0 (the position is unknown) */
	mo_boot(board_power_on());
	/* the pen parks up at every boot (a watchdog reset included) */
	mo_pen_setup((uint16_t)settings[SET_PEN_PARK]);
	do_reset();
}

void fb_poll(void)
{
	if (f_reset) {
		mo_clear_done();
		do_reset();
	}
	uint8_t a = mo_alarm();
	if (a) {
		mo_clear_alarm();
		raise_alarm(a);
	}
	if (f_status) {
		f_status = 0;
		status_report();
	}
	laser_watchdog();
	baud_fallback();
	resume_when_settled();
	maybe_start();
	if (pending)
		try_execute();
	else
		assemble();
	feed_watchdog();
}
