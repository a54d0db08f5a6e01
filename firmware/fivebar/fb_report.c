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

void put_P(const char *s)
{
	char c;
	while ((c = fb_pgm_char(s++)) != 0)
		board_tx((uint8_t)c);
}

void put_u32(uint32_t v)
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

void put_i32(int32_t v)
{
	if (v < 0) {
		board_tx('-');
		put_u32((uint32_t)0 - (uint32_t)v);
	} else {
		put_u32((uint32_t)v);
	}
}

void put_eol(void) { put_P(FB_PSTR("\r\n")); }

void banner(void)
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

void reply_error(uint8_t code)
{
	put_P(FB_PSTR("error:"));
	put_u32(code);
	if (fb_is_resend(code)) {
		put_P(FB_PSTR(" resend:"));
		put_u32(fb_state.lines.last + 1u);
	}
	put_eol();
}

void status_report(void)
{
	mo_status_t st;
	mo_status(&st);
	board_tx('<');
	if (fb_state.alarm_code) {
		put_P(FB_PSTR("Alarm:"));
		put_u32(fb_state.alarm_code);
	} else if (fb_state.homing) {
		put_P(FB_PSTR("Home"));
	} else if (fb_state.held) {
		put_P(FB_PSTR("Hold:"));
		put_u32(fb_state.hold_reason);
	} else if (st.busy) {
		put_P(FB_PSTR("Run"));
	} else {
		put_P(FB_PSTR("Idle"));
	}
	put_P(FB_PSTR("|A:"));
	put_i32(st.pos[0]);
	put_P(FB_PSTR(",B:"));
	put_i32(st.pos[1]);
	put_P(FB_PSTR("|Q:"));
	put_u32(st.waiting);
	put_P(FB_PSTR("|Ln:"));
	put_u32(st.done);
	board_tx(',');
	put_u32(fb_state.lines.last);
	put_P(FB_PSTR("|L:"));
	put_u32(st.laser);
	put_P(FB_PSTR("|U:"));
	put_u32(st.underruns);
	put_P(FB_PSTR("|H:"));
	board_tx(st.homed ? '1' : '0');
	put_P(FB_PSTR("|P:"));
	put_u32(st.pen);
	board_tx('>');
	put_eol();
}
