/*
 * fb_baud.c - the link's baud rate switch ($B, protocol section 1.1): the
 * rate to switch to once its ok has left, the rate in force, and when a
 * switched rate began its trial (it falls back to FB_BAUD unless a valid
 * line arrives within BAUD_TRIAL_MS).
 */
#include "fb_baud.h"
#include "board.h"
#include "board_uart.h"
#include "config.h"
#include "status.h"

#define BAUD_TRIAL_MS 1000u
static uint32_t baud_next, baud_now;
static uint32_t baud_since_ms;
static uint8_t baud_trial;

/* $B=<baud>: one of the rates the Uno's 16 MHz makes (115200 within 0.8 %,
 * the others exactly); the switch waits for the ok (switch_baud). */
uint8_t baud_request(const proto_cmd_t *c)
{
	switch (c->value) {
	case 115200L: case 250000L: case 500000L: case 1000000L:
		baud_next = (uint32_t)c->value;
		return FB_OK;
	default:
		return FB_ERR_OUT_OF_RANGE;
	}
}

/* After $B's ok: the new rate, on trial until a valid line arrives. */
static void switch_baud(void)
{
	board_uart_baud(baud_next);
	baud_now = baud_next;
	baud_next = 0;
	baud_trial = baud_now != FB_BAUD;
	baud_since_ms = board_ms();
}

void baud_after_reply(void)
{
	if (baud_next)
		switch_baud();
}

void baud_heard(void)
{
	baud_trial = 0;
}

/* No valid line within BAUD_TRIAL_MS of a switch: the host cannot speak at
 * that rate, back to the base rate (the host falls back too). */
void baud_fallback(void)
{
	if (baud_trial && board_ms() - baud_since_ms > BAUD_TRIAL_MS) {
		baud_trial = 0;
		board_uart_baud(FB_BAUD);
		baud_now = FB_BAUD;
	}
}

void baud_reset(void)
{
	baud_next = 0;
	baud_trial = 0;
	if (baud_now != FB_BAUD) {  /* a reset or Ctrl-X speaks at the base rate */
		board_uart_baud(FB_BAUD);
		baud_now = FB_BAUD;
	}
}
