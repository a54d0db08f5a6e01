/*
 * fb_state.h - the application's shared state: one struct, fb_state, defined
 * in fb_main.c, and the entry points of fb_main.c the command modules call.
 *
 * Every field the protocol state machine (fb_main.c) and the command modules
 * (fb_exec.c, fb_home.c, fb_settings.c, fb_report.c) share is here, with who
 * writes it and who reads it; everything else stays static in the module
 * that owns it.  "rx" is fb_rx_isr(), the serial receive interrupt (via the
 * board); everything else runs in the main loop.  The fields rx writes or
 * reads are volatile, and the main loop clears or tests them with
 * interrupts off where a byte arriving in between would matter.
 *
 * The motion queue has its own struct (mo_state, fb_motion.h), and the
 * record kept across a reset its own (board_keep, board.h).
 */
#ifndef FB_STATE_H
#define FB_STATE_H

#include <stdint.h>
#include "config.h"
#include "fb_proto.h"
#include "fb_settings.h"

/* The receive ring: free-running 8-bit indices over all FB_RX_RING bytes,
 * CFG_RX_SIZE of them used (fb_state_t.rx; board_avr.c's fast path takes the
 * head as the index, so 256). */
#define FB_RX_RING 256u
typedef struct {
	volatile uint8_t buf[FB_RX_RING];
	volatile uint8_t head, tail, heard;
} fb_rx_t;

/* why a job is held (the n of the status report's Hold:n) */
enum { FB_HOLD_HOST = 0, FB_HOLD_LASER_TIMEOUT = 1, FB_HOLD_ERROR = 2 };

typedef struct {
	/* The receive ring, from the receive interrupt to the line assembly.
	 * Written: head, buf[head] and heard by rx (fb_rx_isr, or the board's
	 * fast path for a byte that is not a real-time one while the ring has
	 * room: board_avr.c USART_RX_vect, whose C model is fb_rx_isr); tail by
	 * fb_main.c (line assembly, do_reset).  heard: a byte came since the main
	 * loop last looked (the host-silence clock; read and cleared by
	 * fb_main.c).  First in the struct: the fast path's addresses are
	 * fb_state's own. */
	fb_rx_t rx;
	/* '?': a status report is due.  Set: rx.  Cleared (and the report
	 * written): fb_poll(), the homing wait (fb_home.c). */
	volatile uint8_t f_status;
	/* Ctrl-X: reset once the main loop sees it.  Set: rx.  Cleared: fb_main.c
	 * do_reset().  Read: fb_exec.c before it queues a block. */
	volatile uint8_t f_reset;
	/* '!' or Ctrl-X during homing.  Set: rx.  Cleared: fb_home.c at the
	 * start of $H, which stops on it. */
	volatile uint8_t f_home_abort;
	/* A job is held (feed hold), and why (HOLD_*).  Set: rx ('!'), fb_main.c
	 * (an error refusing part of a job, host silence).  Cleared: rx ('~'),
	 * fb_main.c (the resume after a pen went down, an alarm, a reset).
	 * Read: fb_exec.c (no start while held), fb_home.c, fb_report.c. */
	volatile uint8_t held, hold_reason;
	/* $H in progress.  Written: fb_home.c.  Read: rx ('!', Ctrl-X abort it),
	 * fb_exec.c (not idle), fb_report.c. */
	volatile uint8_t homing;
	/* The alarm in force (FB_ALARM_*, 0: none): commands but $ are locked
	 * out.  Set: fb_main.c fb_raise_alarm() (fb_home.c's failures, the step
	 * generator's endstop alarm).  Cleared: fb_main.c at boot, fb_exec.c
	 * ($X), fb_home.c (a homing that completed).  Read: rx ('!' is ignored),
	 * fb_exec.c, fb_report.c. */
	volatile uint8_t alarm_code;
	/* M17 / M18 in force (motion needs them on).  Written: fb_exec.c.
	 * Read: fb_exec.c, fb_home.c. */
	uint8_t motors_on;
	/* The line being executed, as received.  Written: fb_main.c (line
	 * assembly, never while a line is pending).  Read: fb_exec.c (a G6
	 * line's items are read from it as their slots free). */
	char line[CFG_LINE_MAX];
	/* The line numbering (fb_proto.c).  Written: fb_main.c (parsing a line,
	 * a reset).  Read: fb_exec.c and fb_home.c (the line number of a
	 * block), fb_report.c (resend:, Ln:). */
	proto_lines_t lines;
	/* The $n settings in force.  Written: fb_settings.c (defaults at boot,
	 * $n=v).  Read: fb_exec.c (limits), fb_home.c, fb_main.c ($6). */
	int32_t settings[SET_COUNT];
	/* Step interval in CPU cycles at the maximum rate $0.  Written:
	 * fb_settings.c (from $0).  Read: fb_exec.c (the rate check of G1/G6). */
	uint32_t min_interval;
} fb_state_t;

extern fb_state_t fb_state;

/* Stop motion, drop the queue, lock with alarm `code`, report ALARM:<code>. */
void fb_raise_alarm(uint8_t code);
/* Feed the hardware watchdog if the step generator is alive (fb_main.c). */
void fb_feed_watchdog(void);

#endif
