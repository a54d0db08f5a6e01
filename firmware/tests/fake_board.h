/*
 * fake_board.h - host implementation of board.h for the unit tests: records
 * what the core does to the "hardware" and lets a test drive the step timer.
 */
#ifndef FAKE_BOARD_H
#define FAKE_BOARD_H

#include <stddef.h>
#include <stdint.h>

#define FAKE_MAX_STEPS 200000

typedef struct {
	uint64_t cycle;  /* fake_now when the pins went high */
	uint8_t mask;    /* motors stepped */
	uint8_t dirs;    /* direction mask in force */
	uint8_t laser;   /* laser power in force */
	uint16_t pen;    /* servo pulse (us) of the last frame before the step */
} fake_step_t;

extern uint64_t fake_now;            /* simulated cycle counter */
extern uint32_t fake_baud;            /* the rate board_uart_baud() set last */
extern uint32_t fake_ms;             /* value of board_ms() */
extern uint8_t fake_endstops;        /* pressed switches */
extern uint8_t fake_laser;           /* last laser power */
extern uint8_t fake_dirs;
extern uint8_t fake_enabled;
extern int fake_timer_on;            /* board_timer_start called, not stopped */
extern int fake_timer_paused;
extern uint16_t fake_timer_delay;    /* delay of the pending timer event */
extern fake_step_t fake_steps[FAKE_MAX_STEPS];
extern size_t fake_nsteps;
extern char fake_tx[65536];
extern size_t fake_tx_len;
/* Step-timer events left for this run (the fuzz target bounds its inputs);
 * once spent, the timer stops and a busy-wait of the core gets mo_stop(). */
extern uint64_t fake_budget;

/* An interrupt that fires when the core re-enables interrupts
 * (board_irq_restore back to "on"): after fake_irq_countdown more such points
 * (0 = the next one), fake_irq_hook runs once, with interrupts off, as an ISR
 * would.  Lets a test deliver a byte at every point of a main-loop pass. */
extern void (*fake_irq_hook)(void);
extern int fake_irq_countdown;
/* Runs inside board_steps_high(), just after the step pins rose: what a reset
 * at that instant would find. */
extern void (*fake_step_hook)(void);

/* What board_power_on() answers next (then 0): fake_reset() sets it, so
 * fake_reset(); fb_setup(); is a power-on; clear it for a reset that keeps
 * the RAM (board_keep, which a test may also corrupt). */
extern uint8_t fake_power_on;
/* board_wdt_feed() calls since fake_reset(): the watchdog feeds. */
extern uint32_t fake_wdt_feeds;

/* The EEPROM word of the pen park pulse (0xffff: none); fake_reset() blanks it. */
extern uint16_t fake_ee_park;
/* Servo pulse of the last frame (mo_pen_frame() runs every 20 ms of fake_now
 * in fake_run), and the number of frames run. */
extern uint16_t fake_pen_pulse;
extern uint32_t fake_pen_frames;

/* The pixel timer (board_px_arm): on, and the cycle of its next event;
 * fake_run() runs its events in time order with the step events'. */
extern int fake_px_on;
extern uint64_t fake_px_at;
/* fake_now at the last board_laser(), and a hook called with every power set. */
extern uint64_t fake_laser_at;
extern void (*fake_laser_hook)(uint8_t power);

void fake_reset(void);
/* Run the step timer until it stops or max_cycles pass; returns events run. */
size_t fake_run(uint64_t max_cycles);
/* Take and clear the transmitted text. */
const char *fake_take_tx(void);

#endif
