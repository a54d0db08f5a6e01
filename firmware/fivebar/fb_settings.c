/*
 * fb_settings.c - the $n settings: defaults (config.h), the range of each,
 * $n=v (only while idle) and the $$ listing.  $14 (pen park) is also kept by
 * the board (board_pen_park_store) so it survives a power cycle.
 */
#include "fb_settings.h"
#include "fb_exec.h"
#include "fb_motion.h"
#include "fb_report.h"
#include "fb_state.h"
#include "board.h"
#include "config.h"
#include "status.h"

void settings_defaults(void)
{
	fb_state.settings[SET_MAX_RATE] = DEF_MAX_RATE;
	fb_state.settings[SET_A_MIN] = DEF_LIMIT_A_MIN;
	fb_state.settings[SET_A_MAX] = DEF_LIMIT_A_MAX;
	fb_state.settings[SET_B_MIN] = DEF_LIMIT_B_MIN;
	fb_state.settings[SET_B_MAX] = DEF_LIMIT_B_MAX;
	fb_state.settings[SET_SOFT_LIMITS] = DEF_SOFT_LIMITS;
	fb_state.settings[SET_LASER_TIMEOUT] = DEF_LASER_TIMEOUT;
	fb_state.settings[SET_HOMING] = DEF_HOMING_ENABLE;
	fb_state.settings[SET_HOMING_RATE] = DEF_HOMING_RATE;
	fb_state.settings[SET_PULLOFF] = DEF_HOMING_PULLOFF;
	fb_state.settings[SET_HOME_A] = DEF_HOME_A;
	fb_state.settings[SET_HOME_B] = DEF_HOME_B;
	fb_state.settings[SET_TRAVEL] = DEF_HOMING_TRAVEL;
	fb_state.settings[SET_HOMING_DIR] = DEF_HOMING_DIR;
	uint16_t park = board_pen_park_load();
	fb_state.settings[SET_PEN_PARK] = park == 0xffffu ? DEF_PEN_PARK : park;
}

uint32_t settings_interval(int32_t rate)
{
	return (uint32_t)((FB_F_CPU + (uint32_t)rate - 1u) / (uint32_t)rate);
}

uint8_t settings_seek_neg(void)
{
	return (uint8_t)(~fb_state.settings[SET_HOMING_DIR] & 3);
}

void settings_apply(void)
{
	fb_state.min_interval = settings_interval(fb_state.settings[SET_MAX_RATE]);
	mo_set_endstops((uint8_t)fb_state.settings[SET_HOMING], settings_seek_neg());
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

uint8_t settings_set(const proto_cmd_t *c)
{
	int32_t lo, hi;
	if (!setting_range(c->setting, &lo, &hi))
		return FB_ERR_UNKNOWN_SETTING;
	if (c->value < lo || c->value > hi ||
	    (c->setting == SET_PEN_PARK && c->value && c->value < CFG_SERVO_MIN_US))
		return FB_ERR_OUT_OF_RANGE;
	if (!exec_idle())
		return FB_ERR_BUSY;
	fb_state.settings[c->setting] = c->value;
	settings_apply();
	if (c->setting == SET_PEN_PARK) {
		board_pen_park_store((uint16_t)c->value);
		mo_pen_setup((uint16_t)c->value);
		exec_sync_plan();
	}
	return FB_OK;
}

void settings_list(void)
{
	for (uint8_t i = 0; i < SET_COUNT; i++) {
		board_tx('$');
		report_u32(i);
		board_tx('=');
		report_i32(fb_state.settings[i]);
		report_eol();
	}
}
