/*
 * fb_exec.h - executing a parsed line: motion, pen, laser and motor
 * commands onto the block queue, the alarm lock, and starting the queue.
 */
#ifndef FB_EXEC_H
#define FB_EXEC_H

#include <stdint.h>
#include "fb_proto.h"

#define EXEC_WAIT 0xffu   /* queue full: try again later */

/* Nothing running, nothing queued, not homing. */
uint8_t exec_idle(void);
/* The planned position and pen after the queue := where the machine is. */
void exec_sync_plan(void);
/* Reset / Ctrl-X: absolute mode, laser off, motors on, plan synced. */
void exec_reset(void);
/* Execute c: FB_OK, an error code, or EXEC_WAIT (call again with the same c
 * once the queue has room; a G6 line keeps its progress in between). */
uint8_t exec_command(const proto_cmd_t *c);
/* mo_start() unless *cancel (fb_state.f_reset or .f_home_abort) was set by
 * an interrupt. */
void exec_start_unless(volatile uint8_t *cancel);
/* Start the queued blocks once enough are queued or the first has waited. */
void exec_maybe_start(void);

#endif
