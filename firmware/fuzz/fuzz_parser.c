/*
 * fuzz_parser.c - libFuzzer target for the line parser and the protocol
 * state machine.
 *
 * 1. Every '\n'-separated piece of the input goes through fb_parse_line with
 *    a persistent line counter; the result must be a defined status, a
 *    resend status must leave the counter unchanged, and once a numbered line
 *    was accepted no unnumbered line but M110 may be (strict framing).
 * 2. The same bytes are fed to the whole firmware (fb_rx_isr / fb_poll) on
 *    the fake board, with simulated time advancing, so real-time bytes,
 *    execution and replies are exercised as well.
 *
 * Build with `make -C firmware fuzz` (clang); firmware/fuzz/replay_main.c
 * replays a corpus through the same function with gcc.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fake_board.h"
#include "fb_main.h"
#include "fb_motion.h"
#include "fb_proto.h"
#include "status.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void parse_pieces(const uint8_t *data, size_t size)
{
	fb_lines_t lines = { 0 };
	size_t start = 0;
	for (size_t i = 0; i <= size; i++) {
		if (i < size && data[i] != '\n')
			continue;
		size_t len = i - start;
		if (len > 255)
			len = 255;
		char *copy = malloc(len ? len : 1);
		memcpy(copy, data + start, len);
		fb_cmd_t cmd;
		fb_lines_t before = lines;
		uint8_t st = fb_parse_line(&lines, copy, (uint8_t)len, &cmd);
		free(copy);
		if (st > FB_ERR_RX_OVERFLOW)
			abort();
		if (fb_is_resend(st) && (lines.last != before.last || lines.numbered != before.numbered))
			abort();
		/* strict framing: after a numbered line, an unnumbered line other
		 * than M110 is never accepted (the counter does not move) */
		if (before.numbered && !cmd.has_n && cmd.kind != CMD_M110 && lines.last != before.last)
			abort();
		if (st == FB_OK && cmd.kind > CMD_SET)
			abort();
		start = i + 1;
	}
}

static void run_firmware(const uint8_t *data, size_t size)
{
	/* each input starts from a powered-up board: the position is kept
	 * across resets by design, so clear it here to keep inputs independent */
	static const int32_t origin[2] = { 0, 0 };
	fake_reset();
	fake_budget = 200000;
	mo_set_pos(origin);
	fb_setup();
	for (size_t i = 0; i < size; i++) {
		fb_rx_isr(data[i]);
		fb_poll();
		fake_ms++;
		fake_run(16000);
		if (fake_tx_len > 60000)
			fake_take_tx();
	}
	for (int i = 0; i < 200; i++) {
		fb_poll();
		fake_ms++;
		fake_run(16000);
	}
	/* the firmware must still answer */
	fb_rx_isr(0x18);
	fb_poll();
	fake_take_tx();
	const char *probe = "$I\n";
	for (const char *p = probe; *p; p++)
		fb_rx_isr((uint8_t)*p);
	for (int i = 0; i < 5; i++)
		fb_poll();
	const char *out = fake_take_tx();
	if (!strstr(out, "ok\r\n"))
		abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	parse_pieces(data, size);
	run_firmware(data, size);
	return 0;
}
