/*
 * fake_board.c - see fake_board.h.
 */
#include <string.h>
#include "fake_board.h"
#include "board.h"
#include "board_uart.h"
#include "fb_motion.h"
#include "fb_raster.h"

uint64_t fake_now;
uint32_t fake_ms;
uint32_t fake_baud = 115200;
uint8_t fake_endstops, fake_laser, fake_dirs, fake_enabled;
int fake_timer_on, fake_timer_paused;
uint16_t fake_timer_delay;
fake_step_t fake_steps[FAKE_MAX_STEPS];
size_t fake_nsteps;
char fake_tx[65536];
size_t fake_tx_len;
uint64_t fake_budget = UINT64_MAX;
void (*fake_irq_hook)(void);
int fake_irq_countdown;
void (*fake_step_hook)(void);
uint8_t fake_power_on;
uint32_t fake_wdt_feeds;
volatile board_keep_t board_keep;
uint16_t fake_ee_park = 0xffffu;
uint16_t fake_pen_pulse;
uint32_t fake_pen_frames;
static uint64_t next_frame;
int fake_px_on;
uint64_t fake_px_at;
uint64_t fake_laser_at;
void (*fake_laser_hook)(uint8_t power);
#define FRAME_CYCLES (16000ULL * CFG_SERVO_FRAME_MS)
static uint8_t irq_on = 1;
static char tx_copy[65536];

void fake_reset(void)
{
	fake_now = 0;
	fake_ms = 0;
	fake_endstops = 0;
	fake_laser = 0;
	fake_dirs = 0;
	fake_enabled = 0;
	fake_timer_on = 0;
	fake_timer_paused = 0;
	fake_timer_delay = 0;
	fake_nsteps = 0;
	fake_tx_len = 0;
	fake_budget = UINT64_MAX;
	fake_irq_hook = 0;
	fake_irq_countdown = 0;
	fake_step_hook = 0;
	irq_on = 1;
	fake_power_on = 1;
	fake_wdt_feeds = 0;
	fake_ee_park = 0xffffu;
	fake_pen_pulse = 0;
	fake_pen_frames = 0;
	next_frame = FRAME_CYCLES;
	fake_px_on = 0;
	fake_px_at = 0;
	fake_laser_at = 0;
	fake_laser_hook = 0;
}

uint16_t board_pen_park_load(void) { return fake_ee_park; }
void board_pen_park_store(uint16_t us) { fake_ee_park = us; }

void board_init(void) {}

void board_wdt_feed(void) { fake_wdt_feeds++; }

uint8_t board_power_on(void)
{
	uint8_t was = fake_power_on;
	fake_power_on = 0;
	return was;
}

void board_tx(uint8_t c)
{
	if (fake_tx_len < sizeof(fake_tx) - 1)
		fake_tx[fake_tx_len++] = (char)c;
}

const char *fake_take_tx(void)
{
	memcpy(tx_copy, fake_tx, fake_tx_len);
	tx_copy[fake_tx_len] = 0;
	fake_tx_len = 0;
	return tx_copy;
}

uint32_t board_ms(void) { return fake_ms; }
void board_uart_baud(uint32_t baud) { fake_baud = baud; }

void board_timer_start(uint16_t delay_cycles)
{
	fake_timer_on = 1;
	fake_timer_paused = 0;
	fake_timer_delay = delay_cycles;
}

void board_timer_stop(void)
{
	fake_timer_on = 0;
	fake_timer_paused = 0;
}

static uint64_t paused_at;
/* the exact time of the pending pixel event (fake_px_at: when it runs, at once
 * when that time is past) */
static uint64_t px_sched;

void board_timer_pause(void)
{
	if (fake_timer_on && !fake_timer_paused) {
		fake_timer_paused = 1;
		paused_at = fake_now;
	}
}

/* The whole timeline moves by the time held: the step event is relative to
 * fake_now already, the pixel timer's is absolute. */
void board_timer_resume(void)
{
	if (fake_timer_paused && fake_px_on) {
		fake_px_at += fake_now - paused_at;
		px_sched += fake_now - paused_at;
	}
	fake_timer_paused = 0;
}

/* One simulated second per call: homing at a few steps/s stays fast. */
void board_idle(void)
{
	fake_ms += 1000;
	fake_run(16000000);
	if (!fake_budget)
		mo_stop();
}

/* The pixel timer: the same 16-bit timer as the steps, fake_now's low bits. */
/* While held the timeline stands at paused_at (board.h): an arm is placed
 * from there, and the resume moves it by the time held. */
static uint64_t px_now64(void) { return fake_timer_paused ? paused_at : fake_now; }

void board_px_arm(uint16_t t)
{
	uint64_t now = px_now64();
	int16_t ahead = (int16_t)(uint16_t)(t - (uint16_t)now);
	px_sched = (uint64_t)((int64_t)now + ahead);
	fake_px_at = ahead < 0 ? now : px_sched;  /* a time already past: at once */
	fake_px_on = 1;
}

void board_px_stop(void) { fake_px_on = 0; }
uint16_t board_px_sched(void) { return (uint16_t)px_sched; }
uint16_t board_px_now(void) { return (uint16_t)px_now64(); }

/* The pixel events due before the next step event (which comes first at an
 * equal time, as Timer1's compare A beats compare B), then 1 when that step
 * event is in the limit. */
static int px_until(uint64_t step_at, uint64_t limit)
{
	while (fake_px_on && !fake_timer_paused && fake_px_at < step_at && fake_px_at <= limit) {
		fake_now = fake_px_at;
		uint16_t d = px_event();
		if (!d) {
			fake_px_on = 0;
		} else {
			px_sched += d;
			fake_px_at = px_sched > fake_now ? px_sched : fake_now;
		}
	}
	return step_at <= limit;
}

size_t fake_run(uint64_t max_cycles)
{
	size_t events = 0;
	uint64_t limit = fake_now + max_cycles;
	while (fake_timer_on && !fake_timer_paused && fake_budget) {
		uint64_t step_at = fake_now + fake_timer_delay;
		if (!px_until(step_at, limit)) {
			/* the next step event is past the limit: time runs to it */
			fake_timer_delay = (uint16_t)(step_at - limit);
			fake_now = limit;
			break;
		}
		fake_budget--;
		fake_now = step_at;
		while (fake_now >= next_frame) {
			fake_pen_pulse = mo_pen_frame();
			fake_pen_frames++;
			next_frame += FRAME_CYCLES;
		}
		uint16_t d = mo_event();
		if (mo_state.px.pending)
			px_start((uint16_t)fake_now);
		events++;
		if (!d) {
			fake_timer_on = 0;
			break;
		}
		fake_timer_delay = d;
	}
	return events;
}

void board_steps_high(uint8_t mask)
{
	if (fake_nsteps < FAKE_MAX_STEPS) {
		fake_steps[fake_nsteps].cycle = fake_now;
		fake_steps[fake_nsteps].mask = mask;
		fake_steps[fake_nsteps].dirs = fake_dirs;
		fake_steps[fake_nsteps].laser = fake_laser;
		fake_steps[fake_nsteps].pen = fake_pen_pulse;
		fake_nsteps++;
	}
	if (fake_step_hook)
		fake_step_hook();
}

void board_set_dirs(uint8_t neg_mask) { fake_dirs = neg_mask; }
/* the fake has no direction port: its "bits" are the mask (the fake runs no
 * fast block, BOARD_FAST_PATH 0, so no block keeps them) */
uint8_t board_dir_bits(uint8_t neg_mask) { return neg_mask; }
void board_enable_motors(uint8_t on) { fake_enabled = on; }
void board_laser(uint8_t power)
{
	fake_laser = power;
	fake_laser_at = fake_now;
	if (fake_laser_hook)
		fake_laser_hook(power);
}
uint8_t board_endstops(void) { return fake_endstops; }
uint8_t board_irq_save(void)
{
	uint8_t was = irq_on;
	irq_on = 0;
	return was;
}

void board_irq_restore(uint8_t state)
{
	irq_on = state;
	if (!state || !fake_irq_hook)
		return;
	if (fake_irq_countdown > 0) {
		fake_irq_countdown--;
		return;
	}
	void (*hook)(void) = fake_irq_hook;
	fake_irq_hook = 0;
	irq_on = 0;
	hook();
	irq_on = 1;
}
