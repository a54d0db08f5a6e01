/*
 * fb_report.c - the firmware's output: decimal numbers, the banner, error
 * replies and the status report, written straight to board_tx (no buffer).
 */
#include "fb_report.h"
#include "fb_state.h"
#include "fb_proto.h"
#include "fb_motion.h"
#include "board.h"
#include "config.h"

void report_P(const char *s)
{
	char c;
	while ((c = board_pgm_char(s++)) != 0)
		board_tx((uint8_t)c);
}

void report_u32(uint32_t v)
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

void report_i32(int32_t v)
{
	if (v < 0) {
		board_tx('-');
		report_u32((uint32_t)0 - (uint32_t)v);
	} else {
		report_u32((uint32_t)v);
	}
}

void report_eol(void) { report_P(BOARD_PSTR("\r\n")); }

void report_banner(void)
{
	report_P(BOARD_PSTR("fivebar " FB_VERSION " proto:"));
	report_u32(FB_PROTOCOL);
	report_P(BOARD_PSTR(" rx:"));
	report_u32(CFG_RX_SIZE);
	report_P(BOARD_PSTR(" queue:"));
	report_u32(CFG_QUEUE_SIZE);
	report_P(BOARD_PSTR(" line:"));
	report_u32(CFG_LINE_MAX);
#ifdef FB_SERVO
	report_P(BOARD_PSTR(" joints:servo"));  /* the servo build: steps are pulse ticks */
#endif
	report_eol();
}

void report_error(uint8_t code)
{
	report_P(BOARD_PSTR("error:"));
	report_u32(code);
	if (proto_is_resend(code)) {
		report_P(BOARD_PSTR(" resend:"));
		report_u32(fb_state.lines.last + 1u);
	}
	report_eol();
}

void report_status(void)
{
	mo_status_t st;
	mo_status(&st);
	board_tx('<');
	if (fb_state.alarm_code) {
		report_P(BOARD_PSTR("Alarm:"));
		report_u32(fb_state.alarm_code);
	} else if (fb_state.homing) {
		report_P(BOARD_PSTR("Home"));
	} else if (fb_state.held) {
		report_P(BOARD_PSTR("Hold:"));
		report_u32(fb_state.hold_reason);
	} else if (st.busy) {
		report_P(BOARD_PSTR("Run"));
	} else {
		report_P(BOARD_PSTR("Idle"));
	}
	report_P(BOARD_PSTR("|A:"));
	report_i32(st.pos[0]);
	report_P(BOARD_PSTR(",B:"));
	report_i32(st.pos[1]);
	report_P(BOARD_PSTR("|Q:"));
	report_u32(st.waiting);
	report_P(BOARD_PSTR("|Ln:"));
	report_u32(st.done);
	board_tx(',');
	report_u32(fb_state.lines.last);
	report_P(BOARD_PSTR("|L:"));
	report_u32(st.laser);
	report_P(BOARD_PSTR("|U:"));
	report_u32(st.underruns);
	report_P(BOARD_PSTR("|H:"));
	board_tx(st.homed ? '1' : '0');
	report_P(BOARD_PSTR("|P:"));
	report_u32(st.pen);
	board_tx('>');
	report_eol();
}
