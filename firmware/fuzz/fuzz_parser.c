/*
 * fuzz_parser.c - libFuzzer target for the line parser and the protocol
 * state machine.
 *
 * 1. Every '\n'-separated piece of the input goes through proto_parse_line with
 *    a persistent line counter; the result must be a defined status, a
 *    resend status must leave the counter unchanged, once a numbered line
 *    was accepted no unnumbered line but M110 may be (strict framing), and a
 *    line with a '*' that is not refused with a resend ends in exactly the
 *    field the host would write for its body, "*<crc16>/<len>" (then only
 *    spaces or tabs): one spelling per body, nothing else passes; a line
 *    without N that starts with a digit, or has no '*' and ends with
 *    "<digit>/<digits>" (a numbered line that lost its N and its '*'), is
 *    never accepted, in numbered mode or before it (the first line).
 * 2. The same bytes are fed to the whole firmware (fb_rx_isr / fb_poll) on
 *    the fake board, with simulated time advancing, so real-time bytes,
 *    execution and replies are exercised as well.
 *
 * Build with `make -C firmware fuzz` (clang); firmware/fuzz/replay_main.c
 * replays a corpus through the same function with gcc.  Built with
 * -DFUZZ_PARSER_ONLY (`make -C firmware fuzz-parser`) it runs part 1 alone:
 * about 50 times the executions per second, for long runs of the framing
 * rules (benchmarks/fuzz_firmware.py); part 2 simulates time on every byte.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fake_board.h"
#include "fb_main.h"
#include "fb_motion.h"
#include "fb_proto.h"
#include "status.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Whether a line that has a '*' ends in the host's checksum field for the
 * bytes before its last '*', and only spaces or tabs after it. */
static int has_host_field(const char *line, size_t len)
{
	size_t star = len;
	for (size_t k = 0; k < len; k++)
		if (line[k] == '*')
			star = k;
	if (star == len)
		return 1;
	char want[16];
	int n = snprintf(want, sizeof want, "*%u/%u",
			 (unsigned)proto_crc16(line, (uint8_t)star), (unsigned)star);
	if (n < 0 || len - star < (size_t)n || memcmp(line + star, want, (size_t)n) != 0)
		return 0;
	for (size_t k = star + (size_t)n; k < len; k++)
		if (line[k] != ' ' && line[k] != '\t')
			return 0;
	return 1;
}

/* Whether a line looks like a numbered line that lost its "N" and its '*'
 * (docs/protocol.md 5.2 step 5), written independently of fb_proto.c: its
 * first non-blank byte is a digit, or it has no '*' and its last non-blank
 * bytes are a digit, '/', digits. */
static int lost_shape(const char *line, size_t len)
{
	size_t i = 0;
	while (i < len && (line[i] == ' ' || line[i] == '\t'))
		i++;
	if (i < len && line[i] >= '0' && line[i] <= '9')
		return 1;
	if (memchr(line, '*', len))
		return 0;
	size_t e = len;
	while (e > 0 && (line[e - 1] == ' ' || line[e - 1] == '\t'))
		e--;
	size_t d = e;
	while (d > 0 && line[d - 1] >= '0' && line[d - 1] <= '9')
		d--;
	return d < e && d >= 2 && line[d - 1] == '/' && line[d - 2] >= '0' && line[d - 2] <= '9';
}

static void parse_pieces(const uint8_t *data, size_t size)
{
	proto_lines_t lines = { 0 };
	size_t start = 0;
	for (size_t i = 0; i <= size; i++) {
		if (i < size && data[i] != '\n')
			continue;
		size_t len = i - start;
		if (len > 255)
			len = 255;
		char *copy = malloc(len ? len : 1);
		memcpy(copy, data + start, len);
		proto_cmd_t cmd;
		proto_lines_t before = lines;
		uint8_t st = proto_parse_line(&lines, copy, (uint8_t)len, &cmd);
		int field_ok = has_host_field(copy, len);
		int lost = lost_shape(copy, len);
		free(copy);
		if (st > FB_ERR_RX_OVERFLOW)
			abort();
		if (proto_is_resend(st) && (lines.last != before.last || lines.numbered != before.numbered))
			abort();
		/* strict framing: after a numbered line, an unnumbered line other
		 * than M110 is never accepted (the counter does not move) */
		if (before.numbered && !cmd.has_n && cmd.kind != PROTO_CMD_M110 && lines.last != before.last)
			abort();
		/* ... nor, in either mode, one that lost its N and its '*' */
		if (lost && !cmd.has_n && (!proto_is_resend(st) || lines.last != before.last))
			abort();
		if (st == FB_OK && cmd.kind >= PROTO_CMD_KINDS)
			abort();
		if (!proto_is_resend(st) && !field_ok)
			abort();
		start = i + 1;
	}
}

#ifndef FUZZ_PARSER_ONLY
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
#endif

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	parse_pieces(data, size);
#ifndef FUZZ_PARSER_ONLY
	run_firmware(data, size);
#endif
	return 0;
}
