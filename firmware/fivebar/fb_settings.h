/*
 * fb_settings.h - the $n settings (protocol section 8): table, defaults,
 * ranges, $n=v and $$.
 */
#ifndef FB_SETTINGS_H
#define FB_SETTINGS_H

#include <stdint.h>
#include "fb_proto.h"

enum { SET_MAX_RATE, SET_A_MIN, SET_A_MAX, SET_B_MIN, SET_B_MAX, SET_SOFT_LIMITS,
       SET_LASER_TIMEOUT, SET_HOMING, SET_HOMING_RATE, SET_PULLOFF, SET_HOME_A,
       SET_HOME_B, SET_TRAVEL, SET_HOMING_DIR, SET_PEN_PARK, SET_COUNT };

/* fb_state.settings := the defaults from config.h; $14 from its stored
 * copy if any. */
void settings_defaults(void);
/* Derive fb_state.min_interval and the endstop set-up from the settings. */
void settings_apply(void);
/* CPU cycles per step at `rate` steps/s (rounded up). */
uint32_t settings_interval(int32_t rate);
/* Motors whose switch lies in the negative direction ($13 clear bits). */
uint8_t settings_seek_neg(void);
/* $n=v */
uint8_t settings_set(const proto_cmd_t *c);
/* $$: one $n=v line per setting. */
void settings_list(void);

#endif
