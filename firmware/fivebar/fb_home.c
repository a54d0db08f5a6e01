/*
 * fb_home.c - the homing cycle ($H): seek the switches in chunks of at most
 * $12 steps in all, pull off by $9, then set the position to ($10, $11).
 * It runs inside the main loop's call, so it serves '?' and feeds the
 * watchdog itself while it waits for each move.
 */
#include "fb_home.h"
#include "fb_exec.h"
#include "fb_report.h"
#include "fb_settings.h"
#include "fb_state.h"
#include "fb_motion.h"
#include "board.h"
#include "status.h"

/* Wait for the generator to stop, serving status requests; 0 if aborted. */
static uint8_t home_wait(void)
{
	while (mo_running()) {
		fb_feed_watchdog();
		board_idle();
		if (fb_state.f_status) {
			fb_state.f_status = 0;
			report_status();
		}
		if (fb_state.f_home_abort)
			return 0;
	}
	return !fb_state.f_home_abort;
}

static uint8_t home_move(uint8_t type, uint8_t axes, uint8_t neg, uint32_t steps, uint32_t interval)
{
	mo_block_t *blk = mo_slot();
	int32_t d[2];
	for (uint8_t i = 0; i < 2; i++)
		d[i] = (axes & (1u << i)) ? ((neg & (1u << i)) ? -(int32_t)steps : (int32_t)steps) : 0;
	mo_prepare_cycles(blk, d[0], d[1], steps * interval, 0);
	blk->type = type;
	blk->power = 0;
	blk->line = fb_state.lines.last;
	mo_push();
	exec_start_unless(&fb_state.f_home_abort);
	return home_wait();
}

uint8_t home_cycle(void)
{
	if (!fb_state.settings[SET_HOMING])
		return FB_ERR_HOMING_DISABLED;
	if (!exec_idle() || fb_state.held)
		return FB_ERR_BUSY;
	if (!fb_state.motors_on)
		return FB_ERR_MOTORS_OFF;
	fb_state.homing = 1;
	fb_state.f_home_abort = 0;
	mo_reset_home_hits();
	/* the position is unknown until homed: count the seek from 0, which
	 * also keeps repeated failed homings from running the counter away.  H
	 * goes first, so a reset in between never keeps H:1 with position 0. */
	int32_t zero[2] = { 0, 0 };
	mo_set_homed(0);
	mo_set_pos(zero);
	exec_sync_plan();
	uint32_t interval = settings_interval(fb_state.settings[SET_HOMING_RATE]);
	uint32_t chunk_max = 0x7fffffffUL / interval;
	uint8_t seek_neg = settings_seek_neg();
	uint32_t left = (uint32_t)fb_state.settings[SET_TRAVEL];
	uint8_t result = FB_OK;
	while (left && (mo_home_hits() & 3u) != 3u) {
		uint32_t chunk = left < chunk_max ? left : chunk_max;
		if (!home_move(MO_BLK_HOME, (uint8_t)(~mo_home_hits() & 3u), seek_neg, chunk, interval)) {
			result = FB_ALARM_HOMING_ABORT;
			break;
		}
		left -= chunk;
	}
	if (result == FB_OK && (mo_home_hits() & 3u) != 3u)
		result = FB_ALARM_HOMING_FAIL;
	if (result == FB_OK && fb_state.settings[SET_PULLOFF] > 0 &&
	    !home_move(MO_BLK_MOVE, 3u, (uint8_t)(~seek_neg & 3u),
		       (uint32_t)fb_state.settings[SET_PULLOFF], interval))
		result = FB_ALARM_HOMING_ABORT;
	if (result == FB_OK && board_endstops())
		result = FB_ALARM_HOMING_FAIL;
	fb_state.homing = 0;
	if (result != FB_OK) {
		fb_raise_alarm(result);
		return result;
	}
	int32_t home[2] = { fb_state.settings[SET_HOME_A], fb_state.settings[SET_HOME_B] };
	mo_set_pos(home);
	mo_set_homed(1);
	exec_sync_plan();
	fb_state.alarm_code = 0;
	return FB_OK;
}
