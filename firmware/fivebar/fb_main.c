/*
 * fb_main.c - protocol state machine of the fivebar firmware: the receive
 * interrupt, line assembly, one reply per line, the host-silence and
 * hardware watchdogs, and the main loop.
 *
 * Real-time bytes (? ! ~ Ctrl-X) are acted on inside the receive interrupt;
 * every other byte goes through the receive ring into the line buffer, and
 * each '\n' gets exactly one reply ("ok" or "error:<code>"), in order, so a
 * host can count characters against the ring size given in the banner.
 * Executing a line is fb_exec.c's (homing fb_home.c's, settings
 * fb_settings.c's, $B fb_baud.c's); writing to the host fb_report.c's.
 */
#include "fb_main.h"
#include "fb_state.h"
#include "fb_baud.h"
#include "fb_exec.h"
#include "fb_report.h"
#include "fb_settings.h"
#include "fb_proto.h"
#include "fb_motion.h"
#include "board.h"
#include "config.h"
#include "status.h"

/* the ring's bytes (fb_state.h): a power of two up to 256 (8-bit free-running
 * indices); it holds CFG_RX_SIZE of them, at most one less than its size when 256 */
#define RX_BUF FB_RX_RING
#if CFG_RX_SIZE > 255 || CFG_RX_SIZE > RX_BUF || (CFG_RX_SIZE < RX_BUF && CFG_RX_SIZE * 2 <= RX_BUF)
#error "CFG_RX_SIZE must be 129..255 for a 256-byte ring"
#endif
#define RX_MASK (RX_BUF - 1u)

#define CTRL_X 0x18

/* the receive ring's head at a Ctrl-X, and a byte lost to a full ring (the ring:
 * fb_state.rx) */
static volatile uint8_t rx_discard, rx_overflow;
/* when the main loop last saw fb_state.rx.heard set (since_last_rx) */
static uint32_t last_rx_ms;
/* a '~' lowered a parked pen again: the timeline resumes at this board_ms()
 * (0 = no resume pending) */
static volatile uint32_t resume_at;

/* the application state the command modules share (fb_state.h) */
fb_state_t fb_state;

/* the bytes of the line being assembled; LINE_OVER once it ran past
 * CFG_LINE_MAX (the rest of it is dropped; one byte for both, of the 294 the
 * stack has: benchmarks/stack.py) */
#define LINE_OVER (CFG_LINE_MAX + 1u)
#if LINE_OVER > 255
#error "CFG_LINE_MAX must leave room for LINE_OVER in a byte"
#endif
static uint8_t line_len;
static proto_cmd_t cmd;
static uint8_t pending;

/* ---- state ----------------------------------------------------------------- */

void fb_raise_alarm(uint8_t code)
{
	mo_stop();
	mo_clear_queue();
	fb_state.held = 0;
	resume_at = 0;
	fb_state.alarm_code = code;
	exec_sync_plan();
	report_P(BOARD_PSTR("ALARM:"));
	report_u32(code);
	report_eol();
}

static void do_reset(void)
{
	uint8_t sreg = board_irq_save();
	fb_state.f_reset = 0;
	fb_state.rx.tail = rx_discard;
	rx_overflow = 0;
	fb_state.held = 0;
	resume_at = 0;
	board_irq_restore(sreg);
	mo_init();
	line_len = 0;
	pending = 0;
	fb_state.lines.last = 0;
	fb_state.lines.numbered = 0;
	exec_reset();
	baud_reset();
	report_banner();
}

void fb_rx_isr(uint8_t c)
{
	fb_state.rx.heard = 1;
	switch (c) {
	case '?':
		fb_state.f_status = 1;
		return;
	case '!':
		if (fb_state.homing) {
			fb_state.f_home_abort = 1;
			mo_stop();
		} else if (!fb_state.held && !fb_state.alarm_code) {
			fb_state.held = 1;
			fb_state.hold_reason = FB_HOLD_HOST;
			mo_hold();
		} else if (resume_at) {
			/* held again while the pen was going back down */
			resume_at = 0;
			fb_state.hold_reason = FB_HOLD_HOST;
			mo_hold();
		}
		return;
	case '~':
		if (fb_state.held && !resume_at) {
			/* a parked pen goes back first; the timeline waits its time */
			uint16_t ms = mo_pen_unpark();
			if (ms) {
				resume_at = board_ms() + ms;
				if (!resume_at)
					resume_at = 1;
			} else {
				fb_state.held = 0;
				mo_resume();
			}
		}
		return;
	case CTRL_X:
		mo_stop();
		if (fb_state.homing)
			fb_state.f_home_abort = 1;
		fb_state.f_reset = 1;
		rx_discard = fb_state.rx.head;
		return;
	default:
		break;
	}
	/* board_avr.c's fast path does these lines (and heard) for a byte it
	 * takes: keep them alike */
	uint8_t h = fb_state.rx.head;
	if ((uint8_t)(h - fb_state.rx.tail) >= CFG_RX_SIZE) {
		rx_overflow = 1;
		return;
	}
	fb_state.rx.buf[h & RX_MASK] = c;
	fb_state.rx.head = (uint8_t)(h + 1u);
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
void fb_feed_watchdog(void)
{
	if (mo_alive())
		board_wdt_feed();
}

/* An error refusing part of a running job stops it: laser off, motion held. */
static void error_hold(void)
{
	uint8_t sreg = board_irq_save();
	if (!fb_state.held && (mo_running() || mo_queue_count())) {
		fb_state.held = 1;
		fb_state.hold_reason = FB_HOLD_ERROR;
		mo_hold();
	}
	board_irq_restore(sreg);
}

static void finish(uint8_t st)
{
	if (st == FB_OK) {
		report_P(BOARD_PSTR("ok"));
		report_eol();
		return;
	}
	if (!proto_is_resend(st))
		error_hold();
	report_error(st);
}

static void try_execute(void)
{
	uint8_t st = exec_command(&cmd);
	if (st == EXEC_WAIT)
		return;
	pending = 0;
	finish(st);
	baud_after_reply();
}

static void handle_line(void)
{
	uint8_t len = line_len, over = len == LINE_OVER;
	line_len = 0;
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
		finish(fb_state.lines.numbered ? FB_ERR_CHECKSUM : FB_ERR_LINE_TOO_LONG);
		return;
	}
	uint8_t st = proto_parse_line(&fb_state.lines, fb_state.line, len, &cmd);
	if (st == FB_OK)
		baud_heard();  /* the host speaks at this rate */
	if (st != FB_OK) {
		finish(st);
		return;
	}
	pending = 1;
	try_execute();
}

/*
 * Move received bytes into the line buffer; handle at most one line.  The
 * bytes up to the head seen at the start are copied in one loop with the
 * indices in registers, the tail stored once (the receive interrupt only
 * needs it to see the ring's room, which a late store can only understate):
 * a byte took ~70 cycles when each went through the volatile indices
 * (python benchmarks/segcost.py).  After a Ctrl-X the lines received before
 * it are do_reset()'s to discard (it sets the tail to rx_discard and empties
 * the line buffer): no line is handled once f_reset is seen.
 */
static void assemble(void)
{
	uint8_t t = fb_state.rx.tail, h = fb_state.rx.head;
	if (fb_state.f_reset || t == h)
		return;
	uint8_t len = line_len, nl = 0;
	while (t != h) {
		uint8_t c = fb_state.rx.buf[t & RX_MASK];
		t = (uint8_t)(t + 1u);
		if (c == '\n') {
			nl = 1;
			break;
		}
		if (c == '\r')
			continue;
		if (len < CFG_LINE_MAX)
			fb_state.line[len++] = (char)c;
		else
			len = LINE_OVER;
	}
	line_len = len;
	fb_state.rx.tail = t;  /* only the main loop writes it (do_reset: after a Ctrl-X) */
	if (nl && !fb_state.f_reset)
		handle_line();
}

/* Milliseconds since the last byte came, as the main loop saw it: the
 * receive interrupt only sets fb_state.rx.heard (its fast path has no time for
 * board_ms()), and every pass of the main loop stamps it (late by at most a
 * pass, a few ms, against a timeout of hundreds). */
static void stamp_rx(void)
{
	if (fb_state.rx.heard) {
		fb_state.rx.heard = 0;
		last_rx_ms = board_ms();
	}
}

static uint32_t since_last_rx(void)
{
	return board_ms() - last_rx_ms;
}

/*
 * Host silence (protocol section 9): with the laser on or the pen down and
 * no byte for $6 ms, a job is held (laser off, pen parked); an idle machine
 * only parks its pen.
 */
static void laser_watchdog(void)
{
	stamp_rx();
	if (!fb_state.held && (mo_laser() || mo_pen_down()) &&
	    since_last_rx() > (uint32_t)fb_state.settings[SET_LASER_TIMEOUT]) {
		uint8_t sreg = board_irq_save();
		if (mo_running() || mo_queue_count()) {
			fb_state.held = 1;
			fb_state.hold_reason = FB_HOLD_LASER_TIMEOUT;
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
	if (!fb_state.held || !resume_at)
		return;
	uint8_t sreg = board_irq_save();
	if (resume_at && (int32_t)(board_ms() - resume_at) >= 0) {
		resume_at = 0;
		fb_state.held = 0;
		mo_resume();
	}
	board_irq_restore(sreg);
}

void fb_setup(void)
{
	board_init();
	settings_defaults();
	settings_apply();
	fb_state.alarm_code = 0;
	/* position, H and Ln done survive a reset that leaves the RAM powered;
	 * after a power-on they start at 0 (the position is unknown) */
	mo_boot(board_power_on());
	/* the pen parks up at every boot (a watchdog reset included) */
	mo_pen_setup((uint16_t)fb_state.settings[SET_PEN_PARK]);
	do_reset();
}

void fb_poll(void)
{
	if (fb_state.f_reset) {
		mo_clear_done();
		do_reset();
	}
	uint8_t a = mo_alarm();
	if (a) {
		mo_clear_alarm();
		fb_raise_alarm(a);
	}
	if (fb_state.f_status) {
		fb_state.f_status = 0;
		report_status();
	}
	laser_watchdog();
	baud_fallback();
	resume_when_settled();
	exec_maybe_start();
	if (pending)
		try_execute();
	else
		assemble();
	mo_fold();
	fb_feed_watchdog();
}
