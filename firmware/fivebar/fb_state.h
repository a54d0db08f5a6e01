/*
 * fb_state.h - the protocol state machine's shared state and entry points.
 *
 * The flags below are defined in fb_main.c, whose receive interrupt sets
 * most of them; the command modules (fb_exec.c, fb_home.c, fb_settings.c,
 * fb_report.c) read and clear them.  Everything else stays static in the
 * module that owns it.
 */
#ifndef FB_STATE_H
#define FB_STATE_H

#include <stdint.h>
#include "config.h"
#include "fb_proto.h"

/* why a job is held (the n of the status report's Hold:n) */
enum { HOLD_HOST = 0, HOLD_LASER_TIMEOUT = 1, HOLD_ERROR = 2 };

/* requests from the receive interrupt: status report, Ctrl-X, homing abort */
extern volatile uint8_t f_status, f_reset, f_home_abort;
/* held (and why), homing in progress, alarm code (0: none) */
extern volatile uint8_t held, hold_reason, homing, alarm_code;
/* the line being handled, and the line numbering (fb_proto) */
extern char line[CFG_LINE_MAX];
extern fb_lines_t lines;

/* Stop motion, drop the queue, lock with alarm `code`, report ALARM:<code>. */
void raise_alarm(uint8_t code);
/* Feed the hardware watchdog if the step generator is alive (fb_main.c). */
void feed_watchdog(void);

#endif
