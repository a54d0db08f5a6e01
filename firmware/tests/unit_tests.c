/*
 * unit_tests.c - host unit tests of the portable firmware core.
 *
 * Built with gcc and the address/undefined sanitizers by `make -C firmware
 * test`, and run by tests/firmware/test_unit_c.py.  Prints one line per
 * failed check and exits 1 if any failed.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "board.h"
#include "config.h"
#include "fake_board.h"
#include "fb_main.h"
#include "fb_motion.h"
#include "fb_proto.h"
#include "fb_state.h"
#include "status.h"

static int failures, checks;

#define BANNER "fivebar " FB_VERSION " proto:4 rx:255 queue:16 line:128\r\n"

#define CHECK(cond, ...) do { checks++; if (!(cond)) { failures++; \
	printf("FAIL %s:%d: ", __FILE__, __LINE__); printf(__VA_ARGS__); printf("\n"); } } while (0)

/* The motion's status fields, as one report would show them. */
static mo_status_t motion(void)
{
	mo_status_t st;
	mo_status(&st);
	return st;
}

/* ---- parser ------------------------------------------------------------------ */

/* The line as proto_parse_line left it: a G6 line's items rewritten into
 * their records (fb_proto.h), which proto_g6_next reads. */
static char parsed[256];

static uint8_t parse(proto_lines_t *ln, const char *s, proto_cmd_t *c)
{
	size_t n = strlen(s);
	memcpy(parsed, s, n);
	return proto_parse_line(ln, parsed, (uint8_t)n, c);
}

/* body with its checksum field "*<crc16>/<len>", as the host sends it */
static void framed(char *out, size_t size, const char *body)
{
	uint8_t len = (uint8_t)strlen(body);
	snprintf(out, size, "%s*%u/%u", body, proto_crc16(body, len), len);
}

/* Expected values from Python's binascii.crc_hqx(data, 0xFFFF), an independent
 * CRC-16/CCITT-FALSE. */
static void test_crc(void)
{
	CHECK(proto_crc16("123456789", 9) == 0x29B1, "CRC-16/CCITT-FALSE check value");
	CHECK(proto_crc16("", 0) == 0xFFFF, "empty crc is the initial value");
	CHECK(proto_crc16("A", 1) == 47381, "one byte");
	CHECK(proto_crc16("N201 G1 A-706 B-507 P16795 S255", 31) == 49724, "a G1 line");
	/* the line that lost two bytes and kept its CRC-8 (32) under protocol 1 */
	CHECK(proto_crc16("N201 G1 A-76 B-07 P16795 S255", 29) == 45618, "that line, two bytes lost");
}

/* Decimal overflow at the edges of 32 bits (the parser checks v * 10 + d
 * against the limit without dividing): line numbers up to 2^32 - 1. */
static void test_number_bounds(void)
{
	static const struct { const char *body; uint8_t status; uint32_t n; } cases[] = {
		{ "N4294967295 G90", FB_OK, 4294967295UL },
		{ "N4294967294 G90", FB_OK, 4294967294UL },
		{ "N4294967290 G90", FB_OK, 4294967290UL },
		{ "N429496729 G90", FB_OK, 429496729UL },
		{ "N4294967296 G90", FB_ERR_BAD_NUMBER, 0 },
		{ "N4294967299 G90", FB_ERR_BAD_NUMBER, 0 },
		{ "N4294967300 G90", FB_ERR_BAD_NUMBER, 0 },
		{ "N4294967305 G90", FB_ERR_BAD_NUMBER, 0 },
		{ "N42949672950 G90", FB_ERR_BAD_NUMBER, 0 },
		{ "N99999999999 G90", FB_ERR_BAD_NUMBER, 0 },
	};
	char buf[64];
	for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
		proto_lines_t ln = { cases[k].n - 1u, 1 };
		proto_cmd_t c;
		framed(buf, sizeof buf, cases[k].body);
		uint8_t st = parse(&ln, buf, &c);
		CHECK(st == cases[k].status && (st != FB_OK || c.n == cases[k].n), cases[k].body);
	}
	proto_cmd_t c;
	proto_lines_t ln = { 0 };
	CHECK(parse(&ln, "G1 A2147483647 P1000", &c) == FB_ERR_OUT_OF_RANGE, "A 2^31 - 1: beyond the limit");
	CHECK(parse(&ln, "G1 A2147483648 P1000", &c) == FB_ERR_OUT_OF_RANGE, "A 2^31: over");
	CHECK(parse(&ln, "G1 A100000000 P1000", &c) == FB_OK && c.a == 100000000L, "A at the limit");
}

/*
 * G6 item numbers (fb_proto.c's item_num, its 16-bit short path and
 * item_num_long) against a reference reading of the same digits: random
 * values of 1 to 12 digits (leading zeros included), either sign, after an
 * optional P item, followed by the line's end, a blank, the next item, or a
 * byte that cannot end a number.  Expected: the value when it is at most
 * 100,000,000, else error:7; error:3 for the bad end, whatever the value.
 */
static void test_g6_item_numbers(void)
{
	static const char *const ends[] = { "", " ", "+1+1", "#", "." };
	uint64_t x = 12345;
	for (int round = 0; round < 20000; round++) {
		char digits[2][16], buf[96];
		uint64_t want[2];
		int neg[2];
		for (int k = 0; k < 2; k++) {
			x = x * 6364136223846793005ULL + 1442695040888963407ULL;
			int nd = 1 + (int)((x >> 33) % 12), zeros = (int)((x >> 40) % 4);
			want[k] = 0;
			for (int i = 0; i < nd; i++) {
				x = x * 6364136223846793005ULL + 1442695040888963407ULL;
				int dg = i < zeros ? 0 : (int)((x >> 35) % 10);
				digits[k][i] = (char)('0' + dg);
				want[k] = want[k] * 10u + (uint64_t)dg;
			}
			digits[k][nd] = 0;
			neg[k] = (int)((x >> 50) & 1u);
		}
		const char *end = ends[(x >> 20) % 5];
		snprintf(buf, sizeof buf, "G6 P1000 %s%c%s%c%s%s", (x >> 24) & 1u ? "P2000" : "",
			 neg[0] ? '-' : '+', digits[0], neg[1] ? '-' : '+', digits[1], end);
		/* the first number (ended by the second's sign) is judged first */
		uint8_t expect = want[0] > 100000000u ? FB_ERR_OUT_OF_RANGE
				 : (end[0] == '#' || end[0] == '.') ? FB_ERR_BAD_NUMBER
				 : want[1] > 100000000u ? FB_ERR_OUT_OF_RANGE : FB_OK;
		proto_lines_t ln = { 0 };
		proto_cmd_t c;
		uint8_t st = parse(&ln, buf, &c);
		CHECK(st == expect, "'%s': %u, expected %u", buf, st, expect);
		if (st != FB_OK)
			continue;
		uint8_t at = c.g6_at;
		int32_t p = c.p, d[2];
		CHECK(proto_g6_next(parsed, &at, c.g6_end, &p, d) &&
		      d[0] == (neg[0] ? -(int32_t)want[0] : (int32_t)want[0]) &&
		      d[1] == (neg[1] ? -(int32_t)want[1] : (int32_t)want[1]) &&
		      p == ((x >> 24) & 1u ? 2000 : 1000), "'%s': read %ld %ld P %ld", buf,
		      (long)d[0], (long)d[1], (long)p);
	}
}

/* G6 (protocol 3): a G1 head and relative items, one line number each. */
static void test_parse_g6(void)
{
	static const struct { const char *line; uint8_t status; uint8_t count; } cases[] = {
		{ "G6 A1 B2 P1000 S0 +1-2+0+0", FB_OK, 2 },
		{ "g6a1p1000 +1-2 p200 -3+4", FB_OK, 2 },
		{ "G6 P1000", FB_OK, 0 },
		{ "G6 P1000 +1-1 ; comment", FB_OK, 1 },
		{ "G6 P1000+1-1", FB_ERR_BAD_NUMBER, 0 },   /* a head number ends at a blank */
		{ "G6 A1 +1-1", FB_ERR_MISSING_WORD, 0 },
		{ "G6 P1000 +1", FB_ERR_BAD_WORD, 0 },
		{ "G6 P1000 +1 -1", FB_ERR_BAD_WORD, 0 },
		{ "G6 P1000 1-1", FB_ERR_BAD_WORD, 0 },
		{ "G6 P1000 +1-1P99+0+0", FB_ERR_OUT_OF_RANGE, 0 },
		{ "G6 P1000 +1-1P+9+0+0", FB_ERR_BAD_NUMBER, 0 },
		{ "G6 P1000 +1-1P500", FB_ERR_BAD_WORD, 0 },
		{ "G6 P1000 +1-1 A5", FB_ERR_BAD_WORD, 0 },
		{ "G6 A1 P1000 S0 P200+1-1", FB_OK, 1 },       /* a second P starts the items */
		{ "G6 A1 P1000 P200", FB_ERR_BAD_WORD, 0 },
		{ "G6 P1000 +100000001+0", FB_ERR_OUT_OF_RANGE, 0 },
		{ "G6 P1000 +1.5+0", FB_ERR_BAD_NUMBER, 0 },
		{ "G6 P1000 +-1+0", FB_ERR_BAD_NUMBER, 0 },
	};
	for (size_t i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		proto_lines_t ln = { 0 };
		proto_cmd_t c;
		uint8_t st = parse(&ln, cases[i].line, &c);
		CHECK(st == cases[i].status, "'%s': status %u, want %u", cases[i].line, st, cases[i].status);
		CHECK(c.kind == PROTO_CMD_G6, "'%s': kind %u", cases[i].line, c.kind);
		CHECK(ln.last == 1u + cases[i].count, "'%s': last %u", cases[i].line, ln.last);
	}
	proto_lines_t ln = { 40, 1 };
	proto_cmd_t c;
	char buf[96];
	framed(buf, sizeof buf, "N41 G6 P1000 +1-1+2+2");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 43, "a numbered G6 uses 3 numbers");
	CHECK(parse(&ln, buf, &c) == FB_ERR_LINE_NUMBER && ln.last == 43, "and is not repeated");
	/* the items as records (fb_proto.h): every move size, P where an item has it */
	ln.last = 0;
	ln.numbered = 0;
	const char *line = "G6 P7000 P250+3-4 -5+0 +200-40000 P300 +123456-32768+0+127 -128+32767";
	CHECK(parse(&ln, line, &c) == FB_OK && c.g6_count == 6, "'%s' parses", line);
	static const int32_t want[6][3] = { { 250, 3, -4 }, { 250, -5, 0 }, { 250, 200, -40000 },
					     { 300, 123456, -32768 }, { 300, 0, 127 },
					     { 300, -128, 32767 } };
	int32_t p = c.p, d[2];
	uint8_t at = c.g6_at;
	for (int k = 0; k < 6; k++)
		CHECK(proto_g6_next(parsed, &at, c.g6_end, &p, d) && p == want[k][0] &&
		      d[0] == want[k][1] && d[1] == want[k][2], "item %d: P%ld %ld %ld", k, (long)p,
		      (long)d[0], (long)d[1]);
	CHECK(!proto_g6_next(parsed, &at, c.g6_end, &p, d), "end of the items");
	CHECK(c.g6_end < strlen(line), "the records are shorter than the text");
}

static void test_parse_table(void)
{
	static const struct { const char *line; uint8_t status; uint8_t kind; } cases[] = {
		{ "G1 A10 B-5 P1000 S3", FB_OK, PROTO_CMD_G1 },
		{ "g1a10b-5p1000", FB_OK, PROTO_CMD_G1 },
		{ "  G1\tA+10 P100 ; a comment", FB_OK, PROTO_CMD_G1 },
		{ "", FB_OK, PROTO_CMD_NONE },
		{ "   ; only a comment", FB_OK, PROTO_CMD_NONE },
		{ "G1 A10", FB_ERR_MISSING_WORD, PROTO_CMD_G1 },
		{ "G1 A1.5 P1000", FB_ERR_BAD_NUMBER, PROTO_CMD_G1 },
		{ "G1 A P1000", FB_ERR_BAD_NUMBER, PROTO_CMD_G1 },
		{ "G1 A- P1000", FB_ERR_BAD_NUMBER, PROTO_CMD_G1 },
		{ "G1 A99999999999 P1000", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 A100000001 P1000", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 A-2147483648 P1000", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 A1 P99", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 A1 P100000001", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 A1 P1000 S256", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 A1 P1000 S-1", FB_ERR_OUT_OF_RANGE, PROTO_CMD_G1 },
		{ "G1 X5 P1000", FB_ERR_BAD_WORD, PROTO_CMD_G1 },
		{ "G1 A1 A2 P1000", FB_ERR_BAD_WORD, PROTO_CMD_G1 },
		{ "G1 G90 P1000", FB_ERR_BAD_WORD, PROTO_CMD_G1 },
		{ "G1 A1 P1000 #", FB_ERR_BAD_WORD, PROTO_CMD_G1 },
		{ "G2 A1", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "G99999999", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "M999", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "hello", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "A10 P100", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "G", FB_ERR_BAD_NUMBER, PROTO_CMD_NONE },
		{ "G1\x01 P100", FB_ERR_INVALID_CHAR, PROTO_CMD_NONE },
		{ "G1 P100 \x7f", FB_ERR_INVALID_CHAR, PROTO_CMD_NONE },
		{ "G90", FB_OK, PROTO_CMD_G90 },
		{ "G91", FB_OK, PROTO_CMD_G91 },
		{ "G90 A1", FB_ERR_BAD_WORD, PROTO_CMD_G90 },
		{ "G92", FB_ERR_MISSING_WORD, PROTO_CMD_G92 },
		{ "G92 B-7", FB_OK, PROTO_CMD_G92 },
		{ "G92 P5", FB_ERR_BAD_WORD, PROTO_CMD_G92 },
		{ "M3", FB_OK, PROTO_CMD_M3 },
		{ "M3 S255", FB_OK, PROTO_CMD_M3 },
		{ "M3 S256", FB_ERR_OUT_OF_RANGE, PROTO_CMD_M3 },
		{ "M5", FB_OK, PROTO_CMD_M5 },
		{ "M5 S1", FB_ERR_BAD_WORD, PROTO_CMD_M5 },
		{ "M17", FB_OK, PROTO_CMD_M17 },
		{ "M18", FB_OK, PROTO_CMD_M18 },
		{ "$I", FB_OK, PROTO_CMD_INFO },
		{ "$i", FB_OK, PROTO_CMD_INFO },
		{ "$$", FB_OK, PROTO_CMD_LIST },
		{ "$H", FB_OK, PROTO_CMD_HOME },
		{ "$X", FB_OK, PROTO_CMD_UNLOCK },
		{ "$IX", FB_ERR_BAD_WORD, PROTO_CMD_INFO },
		{ "$Q", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "$", FB_ERR_UNKNOWN_COMMAND, PROTO_CMD_NONE },
		{ "$0", FB_ERR_MISSING_WORD, PROTO_CMD_NONE },
		{ "$0=", FB_ERR_BAD_NUMBER, PROTO_CMD_NONE },
		{ "$0=12x", FB_ERR_BAD_WORD, PROTO_CMD_NONE },
		{ "$0=1.5", FB_ERR_BAD_NUMBER, PROTO_CMD_NONE },
		{ "$0=12 3", FB_ERR_BAD_WORD, PROTO_CMD_NONE },
		{ "$999=1", FB_ERR_UNKNOWN_SETTING, PROTO_CMD_NONE },
		{ "$13=-3", FB_OK, PROTO_CMD_SET },
	};
	for (size_t i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		proto_lines_t ln = { 0 };
		proto_cmd_t c;
		uint8_t st = parse(&ln, cases[i].line, &c);
		CHECK(st == cases[i].status, "'%s': status %u, want %u", cases[i].line, st, cases[i].status);
		if (st == FB_OK || cases[i].kind != PROTO_CMD_NONE)
			CHECK(c.kind == cases[i].kind, "'%s': kind %u, want %u", cases[i].line, c.kind,
			      cases[i].kind);
		CHECK(ln.last == 1, "'%s': an unnumbered line advances the line count", cases[i].line);
	}
	proto_lines_t ln = { 0 };
	proto_cmd_t c;
	CHECK(parse(&ln, "G1 A10 B-5 P1000 S3", &c) == FB_OK && c.a == 10 && c.b == -5 && c.p == 1000 &&
	      c.s == 3 && c.has == (PROTO_W_A | PROTO_W_B | PROTO_W_P | PROTO_W_S), "G1 values");
	CHECK(parse(&ln, "$13=-3", &c) == FB_OK && c.setting == 13 && c.value == -3, "setting values");
	CHECK(parse(&ln, "G1 A-100000000 P100", &c) == FB_OK && c.a == -100000000, "lowest A");
	test_parse_g6();
	test_g6_item_numbers();
}

static void test_framing(void)
{
	proto_lines_t ln = { 0 };
	proto_cmd_t c;
	char buf[128];
	framed(buf, sizeof buf, "N1 G90");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 1 && c.has_n && c.n == 1, "N1 accepted");
	framed(buf, sizeof buf, "N3 G90");
	CHECK(parse(&ln, buf, &c) == FB_ERR_LINE_NUMBER && ln.last == 1, "gap refused");
	framed(buf, sizeof buf, "N1 G90");
	CHECK(parse(&ln, buf, &c) == FB_ERR_LINE_NUMBER && ln.last == 1, "repeat refused");
	framed(buf, sizeof buf, "N2 G90");
	buf[3] = 'X';
	CHECK(parse(&ln, buf, &c) == FB_ERR_CHECKSUM && ln.last == 1, "corruption refused");
	CHECK(parse(&ln, "N2 G90", &c) == FB_ERR_NO_CHECKSUM && ln.last == 1, "N needs a checksum");
	framed(buf, sizeof buf, "N2 G1 A5 P100");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 2 && c.a == 5, "N2 accepted");
	/* strict framing: after a numbered line, every line needs its number */
	CHECK(parse(&ln, "G1 A5 P100", &c) == FB_ERR_NO_CHECKSUM && ln.last == 2 && ln.numbered,
	      "a line that lost its N and checksum is refused, not executed");
	framed(buf, sizeof buf, "G91");
	CHECK(parse(&ln, buf, &c) == FB_ERR_NO_CHECKSUM && ln.last == 2, "checksum without N refused");
	CHECK(parse(&ln, "", &c) == FB_ERR_NO_CHECKSUM && ln.last == 2, "empty line refused");
	CHECK(parse(&ln, "G5", &c) == FB_ERR_NO_CHECKSUM && ln.last == 2,
	      "refused before its parse error");
	CHECK(parse(&ln, "M110 A1", &c) == FB_ERR_NO_CHECKSUM && ln.last == 2, "a bad M110 too");
	framed(buf, sizeof buf, "N3 G5");
	CHECK(parse(&ln, buf, &c) == FB_ERR_UNKNOWN_COMMAND && ln.last == 3,
	      "a well-framed bad command is accepted, then refused");
	framed(buf, sizeof buf, "N100 M110");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 100 && ln.numbered,
	      "M110 sets the line number; numbered, it keeps strict framing");
	CHECK(parse(&ln, "G90", &c) == FB_ERR_NO_CHECKSUM && ln.last == 100, "still strict");
	CHECK(parse(&ln, "M110", &c) == FB_OK && ln.last == 0 && !ln.numbered,
	      "M110 without N resets and ends strict framing");
	CHECK(parse(&ln, "G91", &c) == FB_OK && ln.last == 1, "unnumbered line counts");
	framed(buf, sizeof buf, "G90");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 2, "checksum without N");
	CHECK(parse(&ln, "M110", &c) == FB_OK && ln.last == 0, "M110 without N resets");
	framed(buf, sizeof buf, "G90");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 1, "checksum without N");
	/* the checksum field of G90: CRC-16 56831, 3 bytes */
	static const char *const bad_fields[] = {
		"G90*", "G90*/3", "G90*56831", "G90*56831/", "G90*56831/3x", "G90*12x/3",
		"G90*65536/3", "G90*123456/3", "G90*056831/3", "G90*56831/03", "G90*56831/4",
		"G90*56831/2", "G90*56830/3", "G90*56831 /3", "G90*56831/ 3", "G90*56831//3",
		"G90*56831/3/3", "G90*56831/3*", "G90*+56831/3", "G90*56831/+3", "G90*56831/-3",
		"G90**56831/3", "G90*56831/3 x", "G90*56831/100",
	};
	for (size_t k = 0; k < sizeof bad_fields / sizeof bad_fields[0]; k++)
		CHECK(parse(&ln, bad_fields[k], &c) == FB_ERR_CHECKSUM && ln.last == 1,
		      "bad checksum field %s", bad_fields[k]);
	CHECK(parse(&ln, "G90*56831/3 \t", &c) == FB_OK && ln.last == 2,
	      "five CRC digits, the length, then spaces and tabs");
	CHECK(parse(&ln, "*65535/0", &c) == FB_OK && ln.last == 3 && c.kind == PROTO_CMD_NONE,
	      "an empty body: length 0");
	CHECK(parse(&ln, "G1 A5 P100 ; a*b*33201/16", &c) == FB_OK && ln.last == 4 && c.a == 5,
	      "the field follows the last '*'; a '*' in a comment is part of the body");
	framed(buf, sizeof buf, "N5 G90 ; note");
	CHECK(parse(&ln, buf, &c) == FB_OK && ln.last == 5, "comment inside the checksum");
	framed(buf, sizeof buf, "Nx G90");
	CHECK(parse(&ln, buf, &c) == FB_ERR_BAD_NUMBER && ln.last == 5, "malformed N");
	/* a numbered line that lost its N and its '*' is refused in either mode,
	 * also as the first line after boot (docs/protocol.md 5.2, step 5): the
	 * host's N1 G1 A10 P1000*13217/15 without "N" and "*" */
	static const char *const lost[] = {
		"1 G1 A10 P100013217/15", "  1 G1 A10 P100013217/15  ", "123", "1",
		"; 1 G1 A10 P100013217/15", "G1 G1 A10 P100013217/15", "G90 ; 1/2 \t",
		"1 G1 A10 P1000;13217/15", "1*51074/1",
	};
	for (int mode = 0; mode < 2; mode++) {
		for (size_t k = 0; k < sizeof lost / sizeof lost[0]; k++) {
			proto_lines_t fresh = { 7, (uint8_t)mode };
			CHECK(parse(&fresh, lost[k], &c) == FB_ERR_NO_CHECKSUM && fresh.last == 7 &&
			      fresh.numbered == mode, "'%s' (numbered %d): refused with a resend", lost[k],
			      mode);
		}
	}
	static const char *const kept[] = { "G90 ; 1/", "G90 ; a/2", "G90 ; 1/a", "G90 ; /2",
					    "G90 ; 1 /2" };
	for (size_t k = 0; k < sizeof kept / sizeof kept[0]; k++) {
		proto_lines_t fresh = { 7, 0 };
		CHECK(parse(&fresh, kept[k], &c) == FB_OK && fresh.last == 8, "'%s' accepted", kept[k]);
	}
	CHECK(proto_is_resend(FB_ERR_CHECKSUM) && proto_is_resend(FB_ERR_LINE_NUMBER) &&
	      proto_is_resend(FB_ERR_NO_CHECKSUM) && !proto_is_resend(FB_ERR_BAD_WORD), "resend codes");
}

/*
 * Line noise on valid numbered lines (docs/protocol.md 5.1 and 14).  Every
 * drop of one byte or of two, every insertion of one byte or of two and every
 * replacement of one byte or of two adjacent bytes is refused with a resend,
 * the line counter unchanged; the one edit accepted is spaces or tabs added
 * at the end, which the format allows after the length.  For drops and
 * insertions the guarantee comes from the length in the checksum field, not
 * from the CRC: one in the body changes its length, one in the field changes
 * a number or breaks it.  Replacements in the body are the CRC's: a burst of
 * at most 16 bits.
 */
static const char *const noise_lines[] = {
	/* three drops the CRC-16 alone let through (tests/line_noise.py) */
	"N65726 G1 A-6020 B-15004 P74824 S132",
	"N27559 G1 A8140 B-8138 P98890 S165",
	"N19311 G1 A-11807 B2341 P15132 S193",
	"N9 G90",                                        /* a one-digit length */
	"N1 G1 P100",                                    /* length 10: "1" and "0" */
	"N1 G1 A10 P1000",          /* lost N and '*': 1 G1 A10 P100013217/15 */
	"N4294967295 G1 A-100000000 B-100000000 P100000000 S255", /* the longest G1 */
	/* G6 lines (protocol 3): several segments, one line number each */
	"N1207G6A-1234B567P1333S0 +1-2+0+1+1-1P1400+2+0-1+1",
	"N9G6P100 +0+0",
	"N33G6A5B-5P2000S255 +10-10P100000000+0+1P150-3+3+1+1+1+1+1+1+1+1+1+1",
};

/* A byte noise may put into a line: any but the newline, which ends it, and
 * the bytes the receiver drops from a line ('\r' and the real-time bytes). */
static uint8_t noise_byte(int b)
{
	return b != '\n' && b != '\r' && b != '?' && b != '!' && b != '~' && b != 0x18;
}

/* Parse s as the line expected after line n-1, in numbered mode or (noise_mode
 * 0) as the first numbered line after a boot: 1 when it is refused with a
 * resend and the counter stays, 2 when it is accepted as line n without error,
 * 0 otherwise. */
static uint8_t noise_mode;
static uint32_t noise_last;  /* the counter after the undamaged line (a G6 uses several) */
static int noisy_outcome(uint32_t n, const char *s, size_t len)
{
	proto_lines_t ln = { n - 1u, noise_mode };
	proto_cmd_t c;
	char line[256];
	memcpy(line, s, len);  /* the parse rewrites a G6 line's items */
	uint8_t st = proto_parse_line(&ln, line, (uint8_t)len, &c);
	if (proto_is_resend(st))
		return ln.last == n - 1u ? 1 : 0;
	return st == FB_OK && ln.last == noise_last ? 2 : 0;
}

static void test_line_noise(void)
{
	for (noise_mode = 0; noise_mode < 2; noise_mode++) {
	/* Bytes that two insertions or two adjacent replacements are drawn from:
	 * any other byte in the checksum field breaks its form; in the body any
	 * byte inserted changes the length, and any two replaced are within the
	 * CRC's burst guarantee.  These are the ones that could make a field look
	 * right. */
	static const char pair_bytes[] = "0123456789*/ \t-A+P";
	const size_t npair = sizeof pair_bytes - 1;
	for (size_t k = 0; k < sizeof noise_lines / sizeof noise_lines[0]; k++) {
		char valid[128], noisy[130];
		framed(valid, sizeof valid, noise_lines[k]);
		const size_t len = strlen(valid);
		const uint32_t n = (uint32_t)strtoul(noise_lines[k] + 1, NULL, 10);
		int bad = 0;
		proto_lines_t first = { n - 1u, noise_mode };
		proto_cmd_t fc;
		memcpy(noisy, valid, len);  /* the parse rewrites a G6 line's items */
		CHECK(proto_parse_line(&first, noisy, (uint8_t)len, &fc) == FB_OK, "%s parses", valid);
		noise_last = first.last;
		CHECK(noisy_outcome(n, valid, len) == 2, "%s accepted", valid);
		/* drops: one byte, and every pair of bytes */
		for (size_t i = 0; i < len; i++) {
			memcpy(noisy, valid, i);
			memcpy(noisy + i, valid + i + 1, len - i - 1);
			bad += noisy_outcome(n, noisy, len - 1) != 1;
			for (size_t j = i + 1; j < len; j++) {
				memcpy(noisy, valid, i);
				memcpy(noisy + i, valid + i + 1, j - i - 1);
				memcpy(noisy + j - 1, valid + j + 1, len - j - 1);
				bad += noisy_outcome(n, noisy, len - 2) != 1;
			}
		}
		CHECK(bad == 0, "%s: %d drops of 1 or 2 bytes not refused", valid, bad);
		/* one byte inserted, one byte replaced: every byte, every place */
		bad = 0;
		for (size_t i = 0; i <= len; i++) {
			for (int b = 0; b < 256; b++) {
				if (!noise_byte(b))
					continue;
				memcpy(noisy, valid, i);
				noisy[i] = (char)b;
				memcpy(noisy + i + 1, valid + i, len - i);
				int blank_end = i == len && (b == ' ' || b == '\t');
				bad += noisy_outcome(n, noisy, len + 1) != (blank_end ? 2 : 1);
				if (i < len && b != (uint8_t)valid[i]) {
					memcpy(noisy, valid, len);
					noisy[i] = (char)b;
					bad += noisy_outcome(n, noisy, len) != 1;
				}
			}
		}
		CHECK(bad == 0, "%s: %d single insertions or replacements not refused", valid, bad);
		/* two bytes inserted, at any two places (the second after the first) */
		bad = 0;
		for (size_t i = 0; i <= len; i++) {
			for (size_t j = i + 1; j <= len + 1; j++) {
				for (size_t x = 0; x < npair; x++) {
					for (size_t y = 0; y < npair; y++) {
						char once[129];
						memcpy(once, valid, i);
						once[i] = pair_bytes[x];
						memcpy(once + i + 1, valid + i, len - i);
						memcpy(noisy, once, j);
						noisy[j] = pair_bytes[y];
						memcpy(noisy + j + 1, once + j, len + 1 - j);
						int blank_end = i == len && j == len + 1 &&
							(pair_bytes[x] == ' ' || pair_bytes[x] == '\t') &&
							(pair_bytes[y] == ' ' || pair_bytes[y] == '\t');
						bad += noisy_outcome(n, noisy, len + 2) != (blank_end ? 2 : 1);
					}
				}
			}
		}
		CHECK(bad == 0, "%s: %d insertions of 2 bytes not refused", valid, bad);
		/* two adjacent bytes replaced */
		bad = 0;
		for (size_t i = 0; i + 1 < len; i++) {
			for (size_t x = 0; x < npair; x++) {
				for (size_t y = 0; y < npair; y++) {
					if (pair_bytes[x] == valid[i] || pair_bytes[y] == valid[i + 1])
						continue;
					memcpy(noisy, valid, len);
					noisy[i] = pair_bytes[x];
					noisy[i + 1] = pair_bytes[y];
					bad += noisy_outcome(n, noisy, len) != 1;
				}
			}
		}
		CHECK(bad == 0, "%s: %d replacements of 2 adjacent bytes not refused", valid, bad);
	}
	}
}

/* ---- step generator -------------------------------------------------------------- */

typedef struct { int32_t a, b; uint32_t p; uint8_t power; } seg_t;

static void queue_segments(const seg_t *segs, size_t n, uint32_t min_interval)
{
	for (size_t i = 0; i < n; i++) {
		mo_block_t *blk = mo_slot();
		CHECK(mo_prepare(blk, segs[i].a, segs[i].b, segs[i].p, min_interval) == FB_OK, "prepare %zu", i);
		blk->power = segs[i].power;
		blk->line = (uint32_t)i + 1u;
		mo_push();
	}
}

/* Every step lands on start + floor((2k-1)C/2n), segments back to back. */
static void check_schedule(const seg_t *segs, size_t n, uint64_t start)
{
	size_t idx[2] = { 0, 0 };
	size_t cursor[2] = { 0, 0 };
	uint64_t seg_start = start;
	for (size_t s = 0; s < n; s++) {
		uint64_t C = (uint64_t)segs[s].p * 16u;
		int32_t d[2] = { segs[s].a, segs[s].b };
		for (int ax = 0; ax < 2; ax++) {
			uint64_t steps = (uint64_t)(d[ax] < 0 ? -(int64_t)d[ax] : d[ax]);
			for (uint64_t k = 1; k <= steps; k++) {
				uint64_t want = seg_start + ((2 * k - 1) * C) / (2 * steps);
				while (cursor[ax] < fake_nsteps && !(fake_steps[cursor[ax]].mask & (1u << ax)))
					cursor[ax]++;
				if (cursor[ax] >= fake_nsteps) {
					CHECK(0, "segment %zu axis %d: step %llu missing", s, ax,
					      (unsigned long long)k);
					return;
				}
				const fake_step_t *st = &fake_steps[cursor[ax]];
				if (st->cycle != want || ((st->dirs >> ax) & 1u) != (d[ax] < 0) ||
				    st->laser != segs[s].power) {
					CHECK(0, "segment %zu axis %d step %llu: at %llu want %llu, dir %u, laser %u",
					      s, ax, (unsigned long long)k, (unsigned long long)st->cycle,
					      (unsigned long long)want, (st->dirs >> ax) & 1u, st->laser);
					return;
				}
				cursor[ax]++;
				idx[ax]++;
			}
		}
		seg_start += C;
	}
	size_t total = 0;
	for (size_t i = 0; i < fake_nsteps; i++)
		total += (fake_steps[i].mask & 1u) + ((fake_steps[i].mask >> 1) & 1u);
	CHECK(total == idx[0] + idx[1], "no extra steps: %zu recorded, %zu expected", total, idx[0] + idx[1]);
	CHECK(fake_now == seg_start, "the last boundary is at the end of the last segment: %llu vs %llu",
	      (unsigned long long)fake_now, (unsigned long long)seg_start);
}

static void run_job(const seg_t *segs, size_t n, uint32_t min_interval)
{
	fake_reset();
	mo_init();
	int32_t zero[2] = { 0, 0 };
	mo_set_pos(zero);
	queue_segments(segs, n, min_interval);
	mo_start();
	uint64_t start = fake_now + fake_timer_delay;
	fake_run(UINT64_MAX / 2);
	CHECK(!mo_running(), "generator stopped after the job");
	CHECK(fake_laser == 0, "laser off at the end of the job");
	check_schedule(segs, n, start);
	int32_t pos[2], want[2] = { 0, 0 };
	for (size_t i = 0; i < n; i++) {
		want[0] += segs[i].a;
		want[1] += segs[i].b;
	}
	mo_get_pos(pos);
	CHECK(pos[0] == want[0] && pos[1] == want[1], "position %d,%d want %d,%d", pos[0], pos[1],
	      want[0], want[1]);
	CHECK(motion().done == n, "last done line %u", motion().done);
	CHECK(motion().underruns == 1, "one stop at the end of the job");
}

static void test_dda_exact(void)
{
	static const seg_t job[] = {
		{ 1, 0, 100, 0 },
		{ 0, 0, 1000, 10 },
		{ 3, 7, 1000, 255 },
		{ -3, -7, 1000, 128 },
		{ 1000, 999, 50000, 0 },
		{ -500, 250, 20000, 1 },
		{ 2, 3, 100000000, 0 },
		{ 40, -39, 1000, 0 },
		{ 400, 1, 10000, 0 },
		{ 1, 400, 10001, 0 },
		{ 397, 398, 9999, 7 },
	};
	run_job(job, sizeof(job) / sizeof(job[0]), 16);

	/* pseudo-random jobs, 16 segments each */
	uint32_t x = 12345;
	for (int round = 0; round < 40; round++) {
		seg_t segs[CFG_QUEUE_SIZE];
		for (size_t i = 0; i < CFG_QUEUE_SIZE; i++) {
			x = x * 1103515245u + 12345u;
			uint32_t p = 100u + (x >> 8) % 200000u;
			uint32_t max = p * 16u / 400u;
			x = x * 1103515245u + 12345u;
			int32_t a = (int32_t)((x >> 4) % (2 * max + 1)) - (int32_t)max;
			x = x * 1103515245u + 12345u;
			int32_t b = (int32_t)((x >> 4) % (2 * max + 1)) - (int32_t)max;
			segs[i] = (seg_t){ a, b, p, (uint8_t)(x >> 24) };
		}
		run_job(segs, CFG_QUEUE_SIZE, 400);
	}
}

/* Every delay handed to the board fits its signed 16-bit comparisons. */
static void test_delays_bounded(void)
{
	static const seg_t job[] = { { 3, 1, 3000000, 0 }, { 0, 0, 70000, 0 }, { 1, 0, 2049, 0 } };
	fake_reset();
	mo_init();
	queue_segments(job, 3, 400);
	mo_start();
	uint16_t max_delay = 0;
	while (fake_timer_on) {
		fake_now += fake_timer_delay;
		uint16_t d = mo_event();
		if (!d)
			break;
		if (d > max_delay)
			max_delay = d;
		fake_timer_delay = d;
	}
	CHECK(max_delay <= MO_MAX_DELAY && MO_MAX_DELAY < 32768u - 1024u, "delay %u", max_delay);
	CHECK(motion().done == 3, "job finished");
}

static void test_too_fast(void)
{
	mo_block_t b;
	CHECK(mo_prepare(&b, 4, 0, 100, 400) == FB_OK, "4 steps in 1600 cycles at 400/step");
	CHECK(mo_prepare(&b, 5, 0, 100, 400) == FB_ERR_TOO_FAST, "5 steps in 1600 cycles");
	CHECK(mo_prepare(&b, 0, -5, 100, 400) == FB_ERR_TOO_FAST, "B too fast");
	CHECK(mo_prepare(&b, 100000000, 0, 100000000, 16) == FB_OK, "long segment");
}

static void test_hold_resume(void)
{
	static const seg_t job[] = { { 100, 50, 10000, 200 }, { -100, -50, 10000, 0 } };
	fake_reset();
	mo_init();
	queue_segments(job, 2, 400);
	mo_start();
	uint64_t start = fake_now + fake_timer_delay;
	fake_run(60000);
	size_t before = fake_nsteps;
	CHECK(before > 0 && fake_laser == 200, "moving with the laser on");
	mo_hold();
	CHECK(fake_laser == 0 && fake_timer_paused, "hold: laser off, timeline frozen");
	uint64_t held_at = fake_now;
	fake_run(1000000);
	CHECK(fake_nsteps == before, "no step while held");
	fake_now = held_at;
	mo_resume();
	CHECK(fake_laser == 200 && !fake_timer_paused, "resume: laser back");
	fake_run(UINT64_MAX / 2);
	check_schedule(job, 2, start);
}

static void test_homing_block(void)
{
	fake_reset();
	mo_init();
	int32_t zero[2] = { 0, 0 };
	mo_set_pos(zero);
	mo_reset_home_hits();
	mo_block_t *b = mo_slot();
	CHECK(mo_prepare_cycles(b, -1000, -1000, 1000u * 800u, 400) == FB_OK, "home block");
	b->type = MO_BLK_HOME;
	b->power = 0;
	mo_push();
	mo_start();
	fake_endstops = 1;
	fake_run(800u * 10u);
	int32_t pos[2];
	mo_get_pos(pos);
	CHECK(pos[0] == -1 && mo_home_hits() == 1, "A stops on its switch: pos %d hits %u", pos[0],
	      mo_home_hits());
	fake_endstops = 3;
	fake_run(UINT64_MAX / 2);
	mo_get_pos(pos);
	CHECK(mo_home_hits() == 3 && pos[0] == -1 && pos[1] > -20, "B stops too: %d, %d", pos[0], pos[1]);
	CHECK(fake_now < 800u * 30u, "the block ends once both switches are found");
	CHECK(mo_alarm() == 0, "no alarm while homing");
}

static void test_endstop_alarm(void)
{
	static const seg_t job[] = { { 100, 0, 10000, 255 }, { 50, 0, 10000, 0 } };
	fake_reset();
	mo_init();
	mo_set_endstops(1, 1);
	queue_segments(job, 2, 400);
	mo_start();
	fake_run(50000);
	fake_endstops = 3;
	fake_run(UINT64_MAX / 2);
	CHECK(mo_alarm() == 0 && fake_nsteps == 150,
	      "A moving away from its switch and B standing still raise no alarm");
	fake_reset();
	mo_init();
	static const seg_t back[] = { { 10, 0, 10000, 255 }, { -100, 0, 10000, 255 } };
	queue_segments(back, 2, 400);
	mo_start();
	fake_endstops = 1;
	fake_run(UINT64_MAX / 2);
	CHECK(mo_alarm() == FB_ALARM_ENDSTOP, "alarm %u", mo_alarm());
	CHECK(!mo_running() && fake_laser == 0, "stopped, laser off");
	CHECK(fake_nsteps == 11, "stopped on the first step towards the switch: %zu", fake_nsteps);
	mo_clear_alarm();
	mo_set_endstops(0, 3);
}

/* ---- the whole protocol on the fake board -------------------------------------------------- */

static void send(const char *s)
{
	for (; *s; s++)
		fb_rx_isr((uint8_t)*s);
}

static const char *poll_out(int polls)
{
	for (int i = 0; i < polls; i++) {
		fb_poll();
		fake_run(UINT64_MAX / 2);
	}
	return fake_take_tx();
}

static void expect(const char *input, const char *want)
{
	send(input);
	const char *got = poll_out(50);
	CHECK(strcmp(got, want) == 0, "'%s': got '%s' want '%s'", input, got, want);
}

/* Let time pass: the queue starts CFG_START_DELAY_MS after its first block. */
static void tick(uint32_t ms)
{
	fake_ms += ms;
	const char *out = poll_out(5);
	CHECK(out[0] == 0, "no output while time passes: '%s'", out);
}

static void test_app(void)
{
	char buf[256];
	int32_t zero[2] = { 0, 0 };
	fake_reset();
	mo_set_pos(zero);
	fb_setup();
	expect("", BANNER);
	expect("$I\n", BANNER "ok\r\n");
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,1|L:0|U:0|H:0|P:0>\r\n");
	expect("G1 A10 B-4 P1000\n", "ok\r\n");
	tick(100);
	expect("?", "<Idle|A:10,B:-4|Q:0|Ln:2,2|L:0|U:1|H:0|P:0>\r\n");
	expect("G91\nG1 A5 P1000\nG90\n", "ok\r\nok\r\nok\r\n");
	tick(100);
	expect("?", "<Idle|A:15,B:-4|Q:0|Ln:4,5|L:0|U:2|H:0|P:0>\r\n");
	expect("G1 A200000 P100000\n", "error:11\r\n");
	expect("G1 A10 P100\n", "error:12\r\n");
	memset(buf, 'A', CFG_LINE_MAX + 20);
	strcpy(buf + CFG_LINE_MAX + 20, "\n");
	expect(buf, "error:2\r\n");
	expect("G1 A1 P1000\x01\n", "error:1\r\n");
	expect("FOO\n", "error:4\r\n");
	framed(buf, sizeof buf, "N11 G90");
	strcat(buf, "\n");
	expect(buf, "error:9 resend:10\r\n");
	expect("N10 G90*0\n", "error:8 resend:10\r\n");
	expect("N10 G90\n", "error:10 resend:10\r\n");
	expect("M110\n", "ok\r\n");
	framed(buf, sizeof buf, "N1 G1 A0 B0 P1000");
	strcat(buf, "\n");
	expect(buf, "ok\r\n");
	tick(100);
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:1,1|L:0|U:3|H:0|P:0>\r\n");
	/* numbered mode: a line too long for the buffer (two lines merged by a
	 * lost newline) is refused with a resend, as a checksum error */
	framed(buf, sizeof buf, "N2 G1 A-100000000 B-100000000 P100000000 S255");
	framed(buf + strlen(buf), sizeof buf - strlen(buf), "N3 G1 A-100000000 B-100000000 P100000000 S255");
	framed(buf + strlen(buf), sizeof buf - strlen(buf), "N4 G1 A5 B5 P1000 S9");
	strcat(buf, "\n");
	CHECK(strlen(buf) > CFG_LINE_MAX + 1, "merged lines too long");
	expect(buf, "error:8 resend:2\r\n");
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:1,1|L:0|U:3|H:0|P:0>\r\n");
	/* strict framing until an unnumbered M110 (or a reset) */
	expect("G1 A5 P1000\n$I\n", "error:10 resend:2\r\nerror:10 resend:2\r\n");
	expect("M110\nG90\n", "ok\r\nok\r\n");
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:1,1|L:0|U:3|H:0|P:0>\r\n");

	/* hold before the job starts, then resume */
	expect("!", "");
	expect("M3 S77\nG1 A100 P100000\n", "ok\r\nok\r\n");
	tick(100);
	expect("?", "<Hold:0|A:0,B:0|Q:1|Ln:1,3|L:0|U:3|H:0|P:0>\r\n");
	CHECK(fake_nsteps == 0 || fake_laser == 0, "nothing runs while held");
	fake_nsteps = 0;
	fb_rx_isr('~');
	fb_poll();
	fake_run(16u * 50000u);
	CHECK(fake_laser == 77, "laser on during the segment");
	fb_rx_isr('!');
	CHECK(fake_laser == 0, "hold turns the laser off at once");
	expect("?", "<Hold:0|A:50,B:0|Q:0|Ln:1,3|L:0|U:3|H:0|P:0>\r\n");
	expect("~", "");
	expect("?", "<Idle|A:100,B:0|Q:0|Ln:3,3|L:0|U:4|H:0|P:0>\r\n");

	/* an error while a job runs holds it */
	expect("G1 A0 P100000\n", "ok\r\n");
	fake_ms += 100;
	fb_poll();
	fake_run(16u * 10000u);
	expect("G8\n", "error:4\r\n");
	CHECK(fake_laser == 0, "laser off after an error");
	expect("?", "<Hold:2|A:90,B:0|Q:0|Ln:3,5|L:0|U:4|H:0|P:0>\r\n");

	/* reset: banner, queue dropped, position kept */
	send("\x18");
	CHECK(fake_laser == 0 && !fake_timer_on, "reset stops at once");
	expect("", BANNER);
	expect("?", "<Idle|A:90,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n");

	/* the laser watchdog */
	expect("M3 S255\nG1 A0 P10000000\n", "ok\r\nok\r\n");
	fake_ms += 100;
	fb_poll();
	fake_run(16000u);
	CHECK(fake_laser == 255, "laser on");
	fake_ms += DEF_LASER_TIMEOUT + 1;
	fb_poll();
	CHECK(fake_laser == 0, "laser off after host silence");
	expect("?", "<Hold:1|A:90,B:0|Q:0|Ln:0,2|L:0|U:0|H:0|P:0>\r\n");
	send("\x18");
	expect("", BANNER);

	/* settings */
	expect("$0=70000\n", "error:7\r\n");
	expect("$77=1\n", "error:17\r\n");
	expect("$5=0\nG1 A200000 P10000000\n", "ok\r\nok\r\n");
	send("\x18");
	expect("", BANNER);
	expect("$5=1\n$H\n", "ok\r\nerror:16\r\n");
	expect("M18\nG1 A0 P1000\n", "ok\r\nerror:15\r\n");
	send("\x18");
	poll_out(5);

	/* homing counts its seek from 0, whatever the position was */
	int32_t far[2] = { -99000000, 99000000 };
	mo_set_pos(far);
	fake_endstops = 0;
	expect("$7=1\n$12=1000\n$8=40000\n$H\n", "ok\r\nok\r\nok\r\nALARM:31\r\nerror:31\r\n");
	int32_t pos[2];
	mo_get_pos(pos);
	CHECK(pos[0] == -1000 && pos[1] == -1000, "failed seek from 0: %d %d", pos[0], pos[1]);
	expect("$X\n$7=0\n", "ok\r\nok\r\n");
	send("\x18");
	poll_out(5);

	/* receive overflow: more than rx bytes without a newline being read */
	for (int i = 0; i < CFG_RX_SIZE + 10; i++)
		fb_rx_isr('G');
	CHECK(poll_out(5)[0] == 0, "no reply before the newline");
	send("\n");
	CHECK(strncmp(poll_out(50), "error:18", 8) == 0, "overflow reported");
	expect("$I\n", BANNER "ok\r\n");
}

static int count_of(const char *hay, const char *needle)
{
	int n = 0;
	for (const char *p = strstr(hay, needle); p; p = strstr(p + 1, needle))
		n++;
	return n;
}

static void ctrl_x_isr(void) { fb_rx_isr(0x18); }

/* A fresh device at position 0: the Ctrl-X empties the fake's receive ring, then a boot. */
static void boot_at_zero(void)
{
	int32_t zero[2] = { 0, 0 };
	fb_rx_isr(0x18);
	fb_poll();
	fake_reset();
	mo_set_pos(zero);
	fb_setup();
}

/*
 * Ctrl-X while a line waits for a queue slot (contract test
 * test_reset_discards_a_line_waiting_for_a_slot), delivered at every point of a
 * main-loop pass where interrupts are enabled again.  Its mo_stop() frees a
 * slot: the waiting line must not take it and get an "ok" before the banner,
 * and the queue must not start again (the laser would flash).
 */
/* G6 runs as the G1 lines it stands for: one block per segment, numbered
 * from its N; checked whole before any block is queued; more segments than
 * free slots wait for the queue like a G1. */
static void test_g6_app(void)
{
	char buf[128];
	int32_t zero[2] = { 0, 0 };
	fake_reset();
	mo_set_pos(zero);
	fb_setup();
	fake_tx_len = 0;
	expect("\x18", BANNER);
	expect("M110\n", "ok\r\n");
	expect("M3 S5\n", "ok\r\n");
	framed(buf, sizeof buf, "N2 G6 A10 B-4 P1000 S9 +1+1+2-2P2000+0+3");
	strcat(buf, "\n");
	expect(buf, "ok\r\n");
	tick(100);
	expect("?", "<Idle|A:13,B:-2|Q:0|Ln:5,5|L:0|U:1|H:0|P:0>\r\n");
	CHECK(fake_nsteps > 0 && fake_steps[fake_nsteps - 1].laser == 9, "S applies to every segment");
	/* one bad segment: nothing queued, the line counts whole, the error held back */
	framed(buf, sizeof buf, "N6 G6 P1000 +1+1+200000+0+1+1");
	strcat(buf, "\n");
	expect(buf, "error:11\r\n");
	expect("?", "<Idle|A:13,B:-2|Q:0|Ln:5,9|L:0|U:1|H:0|P:0>\r\n");
	framed(buf, sizeof buf, "N10 G6 P1000 +1+1+30+0");
	strcat(buf, "\n");
	expect(buf, "error:12\r\n");
	/* 30 segments for a 16-block queue: the second line's reply waits */
	expect("!", "");
	framed(buf, sizeof buf, "N13 G6 P1000 +1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0");
	strcat(buf, "\n");
	expect(buf, "ok\r\n");
	framed(buf, sizeof buf, "N28 G6 P1000 +1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0+1+0");
	strcat(buf, "\n");
	expect(buf, "");
	expect("?", "<Hold:0|A:13,B:-2|Q:16|Ln:5,42|L:0|U:1|H:0|P:0>\r\n");
	/* (the fake runs the 16 blocks without a main-loop pass in between: the
	 * queue runs dry once before the last 14 are queued, U:3) */
	expect("~", "ok\r\n");
	tick(100);
	expect("?", "<Idle|A:41,B:-2|Q:0|Ln:42,42|L:0|U:3|H:0|P:0>\r\n");
}

/* ---- G6 checks from the parse's summary -------------------------------------------------- */

static uint32_t rng_state = 12345u;
static uint32_t rnd(uint32_t n)
{
	/* xorshift32: the trials are the same on every run */
	rng_state ^= rng_state << 13;
	rng_state ^= rng_state >> 17;
	rng_state ^= rng_state << 5;
	return rng_state % n;
}

static int32_t rnd_in(int32_t lo, int32_t hi) { return lo + (int32_t)rnd((uint32_t)(hi - lo + 1)); }

/* The reply the protocol promises for a G6 line (docs/protocol.md 6, 6.3),
 * worked out item by item in order as the G1 lines it stands for: the first
 * target outside +-CFG_POS_LIMIT (7), outside the soft limits (11), moving a
 * motor while they are off (15), or asking more than floor(P * 16 / I) steps
 * of a motor, I the least step interval (12), names the error. */
typedef struct {
	int32_t lim[4];   /* A min, A max, B min, B max */
	uint8_t soft, motors_on;
	uint32_t interval;
} g6_model_t;

static int g6_model(const g6_model_t *m, const int32_t from0[2], int n, const int32_t t_all[][2],
		    const int32_t p_all[])
{
	int32_t from[2] = { from0[0], from0[1] };
	for (int k = 0; k < n; k++) {
		const int32_t *t = t_all[k];
		for (int i = 0; i < 2; i++)
			if (t[i] > CFG_POS_LIMIT || t[i] < -CFG_POS_LIMIT)
				return FB_ERR_OUT_OF_RANGE;
		for (int i = 0; i < 2; i++)
			if (m->soft && (t[i] < m->lim[2 * i] || t[i] > m->lim[2 * i + 1]))
				return FB_ERR_SOFT_LIMIT;
		if (!m->motors_on && (t[0] != from[0] || t[1] != from[1]))
			return FB_ERR_MOTORS_OFF;
		uint64_t lim = (uint64_t)p_all[k] * 16u / m->interval;
		for (int i = 0; i < 2; i++)
			if ((uint64_t)llabs((long long)t[i] - from[i]) > lim)
				return FB_ERR_TOO_FAST;
		from[0] = t[0];
		from[1] = t[1];
	}
	return FB_OK;
}

/* One item's move: mostly a few steps, now and then many (past the step
 * rate), past 65535 (which the summary does not bound) or near the
 * position limit. */
static int32_t g6_rand_move(uint8_t fine)
{
	uint32_t r = rnd(100);
	if (fine)
		return r < 97 ? rnd_in(-1, 1) : rnd_in(-3, 3);
	if (r < 93)
		return rnd_in(-4, 4);
	if (r < 97)
		return rnd_in(-300, 300);
	if (r < 99)
		return rnd_in(-70000, 70000);
	return rnd(2) ? CFG_POS_LIMIT - (int32_t)rnd(1000) : -CFG_POS_LIMIT + (int32_t)rnd(1000);
}

/* Random G6 lines (items with and without P, settings, soft limits, motors
 * off, far targets) through the whole firmware: each reply is the one the
 * item-by-item model names.  The firmware clears most lines from the
 * parse's summary without reading the items again (fb_exec.c g6_fits):
 * this holds it to the per-item rules, the first failing item's error
 * included. */
static void test_g6_checks_random(void)
{
	static const int32_t rates[] = { 1000, 8000, 30000, 60000 };
	int failed_before = failures, ok_lines = 0, errs[16] = { 0 };
	for (int trial = 0; trial < 4000 && failures == failed_before; trial++) {
		g6_model_t m;
		m.lim[0] = rnd_in(-600, -1);
		m.lim[1] = rnd_in(1, 600);
		m.lim[2] = rnd_in(-600, -1);
		m.lim[3] = rnd_in(1, 600);
		m.soft = (uint8_t)rnd(2);
		m.motors_on = rnd(10) != 0;
		int32_t rate = rates[rnd(4)];
		int32_t pos[2] = { rnd_in(-500, 500), rnd_in(-500, 500) };
		/* a fifth of the lines of single steps (their rates alone can be too
		 * fast), a tenth near the position limit (reached by small items) */
		uint8_t fine = rnd(5) == 0, up = rnd(6) == 0;  /* up: every move >= 0 */
		if (rnd(2)) {
			/* soft limits a few steps around the position: lines reach them exactly */
			m.lim[0] = pos[0] - (int32_t)rnd(7);
			m.lim[1] = pos[0] + 1 + (int32_t)rnd(7);
			m.lim[2] = pos[1] - (int32_t)rnd(7);
			m.lim[3] = pos[1] + 1 + (int32_t)rnd(7);
		}
		if (rnd(10) == 0) {
			uint8_t i = (uint8_t)rnd(2);
			pos[i] = rnd(2) ? CFG_POS_LIMIT - (int32_t)rnd(20) : -CFG_POS_LIMIT + (int32_t)rnd(20);
			m.soft = 0;
		}
		boot_at_zero();
		char line[CFG_LINE_MAX + 64], tmp[40];
		if (m.lim[0] >= m.lim[1] || m.lim[2] >= m.lim[3])
			continue;
		snprintf(line, sizeof line, "$0=%ld\n$1=%ld\n$2=%ld\n$3=%ld\n$4=%ld\n$5=%u\n"
			 "G92 A%ld B%ld\n%s", (long)rate, (long)m.lim[0], (long)m.lim[1],
			 (long)m.lim[2], (long)m.lim[3], (unsigned)m.soft, (long)pos[0], (long)pos[1],
			 m.motors_on ? "" : "M18\n");
		send(line);
		const char *got = poll_out(20);
		CHECK(strstr(got, "error") == NULL, "set-up: %s", got);
		fake_ms += 1000;
		poll_out(5);
		int32_t at0[2], at[2];
		mo_get_pos(at0);
		m.interval = fb_state.min_interval;
		/* the head (absolute, G90) and up to 14 items: the line's blocks fit the queue */
		int32_t t[16][2], p[16];
		p[0] = rnd_in(100, 3000);
		t[0][0] = pos[0] + (fine ? g6_rand_move(1) : rnd_in(-8, 8));
		t[0][1] = pos[1] + (fine ? g6_rand_move(1) : rnd_in(-8, 8));
		snprintf(line, sizeof line, "G6 A%ld B%ld P%ld ", (long)t[0][0], (long)t[0][1], (long)p[0]);
		int n = 1, items = 1 + (int)rnd(14);
		for (; n <= items; n++) {
			p[n] = p[n - 1];
			tmp[0] = 0;
			if (rnd(4) == 0) {
				p[n] = rnd(10) ? rnd_in(100, 3000) : rnd_in(3000, 200000);
				snprintf(tmp, sizeof tmp, "P%ld", (long)p[n]);
			}
			int32_t d[2] = { g6_rand_move(fine), g6_rand_move(fine) };
			for (int i = 0; up && i < 2; i++)
				d[i] = d[i] < 0 ? -d[i] : d[i];
			size_t len = strlen(line);
			snprintf(line + len, sizeof line - len, "%s%+ld%+ld", tmp, (long)d[0], (long)d[1]);
			if (strlen(line) > CFG_LINE_MAX - 1) {
				line[len] = 0;
				break;
			}
			t[n][0] = t[n - 1][0] + d[0];
			t[n][1] = t[n - 1][1] + d[1];
		}
		int want = g6_model(&m, pos, n, (const int32_t(*)[2])t, p);
		errs[want & 15]++;
		ok_lines += want == FB_OK;
		char want_s[24];
		if (want == FB_OK)
			snprintf(want_s, sizeof want_s, "ok\r\n");
		else
			snprintf(want_s, sizeof want_s, "error:%d\r\n", want);
		strcat(line, "\n");
		expect(line, want_s);
		/* all or nothing: a refused line moved nothing, a good one every item */
		fake_ms += 1000;
		poll_out(5);
		mo_get_pos(at);
		const int32_t *end = want == FB_OK ? t[n - 1] : pos;
		CHECK(at[0] - at0[0] == end[0] - pos[0] && at[1] - at0[1] == end[1] - pos[1] &&
		      !mo_queue_count(), "'%s': moved %ld,%ld, want %ld,%ld", line, (long)(at[0] - at0[0]),
		      (long)(at[1] - at0[1]), (long)(end[0] - pos[0]), (long)(end[1] - pos[1]));
	}
	/* the trials reach every outcome, most of them often */
	CHECK(ok_lines > 400 && errs[FB_ERR_OUT_OF_RANGE] > 10 && errs[FB_ERR_SOFT_LIMIT] > 200 &&
	      errs[FB_ERR_MOTORS_OFF] > 50 && errs[FB_ERR_TOO_FAST] > 200,
	      "outcomes: ok %d, 7: %d, 11: %d, 15: %d, 12: %d", ok_lines, errs[FB_ERR_OUT_OF_RANGE],
	      errs[FB_ERR_SOFT_LIMIT], errs[FB_ERR_MOTORS_OFF], errs[FB_ERR_TOO_FAST]);
}

/* One G6 line after a fresh boot and `setup`: its reply, and how far it moved
 * motor A and B once the queue ran. */
static void g6_case(const char *setup, const char *line, const char *want, int32_t da, int32_t db)
{
	int32_t at0[2], at[2];
	boot_at_zero();
	send(setup);
	const char *got = poll_out(20);
	CHECK(strstr(got, "error") == NULL, "set-up '%s': %s", setup, got);
	fake_ms += 1000;
	poll_out(5);
	mo_get_pos(at0);
	expect(line, want);
	fake_ms += 1000;
	poll_out(5);
	mo_get_pos(at);
	CHECK(at[0] - at0[0] == da && at[1] - at0[1] == db && !mo_queue_count(),
	      "'%s': moved %ld,%ld, want %ld,%ld; %u blocks queued", line, (long)(at[0] - at0[0]),
	      (long)(at[1] - at0[1]), (long)da, (long)db, (unsigned)mo_queue_count());
}

/* Each bound of the G6 summary at its edge: a line that just passes and one
 * that just fails, the failing item after items that move (so a line cleared
 * wrongly would move before its error). */
static void test_g6_checks_edges(void)
{
	/* step rate: $0=1000 is 16000 cycles a step; P2000 allows 2 steps, P1000 1, P999 0 */
	g6_case("$0=1000\n", "G6 A0 B0 P2000 +2+0P1000+1+1\n", "ok\r\n", 3, 1);
	g6_case("$0=1000\n", "G6 A1 B0 P2000 +2+0P999+1+0\n", "error:12\r\n", 0, 0);
	/* P16000 allows 16 steps exactly (256000 / 16000), P15999 15 */
	g6_case("$0=1000\n", "G6 A1 B0 P2000 +2+0P16000+16+0\n", "ok\r\n", 19, 0);
	g6_case("$0=1000\n", "G6 A1 B0 P2000 +2+0P15999+16+0\n", "error:12\r\n", 0, 0);
	g6_case("$0=1000\n", "G6 A0 B0 P2000 +2+0+1+3\n", "error:12\r\n", 0, 0);
	g6_case("$0=1000\n", "G6 A0 B0 P2000 +1+0P1000+0+0+0-1P2000+0-2\n", "ok\r\n", 1, -3);
	/* soft limits, reached exactly and passed by one step, low and high, both motors */
	g6_case("$1=-5\n$2=5\n$3=-5\n$4=5\n$5=1\n", "G6 A0 B0 P1000 +3-3+2-2-5+5\n", "ok\r\n", 0, 0);
	g6_case("$1=-5\n$2=5\n$3=-5\n$4=5\n$5=1\n", "G6 A0 B0 P1000 +3-3+2-2+1+0\n",
		"error:11\r\n", 0, 0);
	g6_case("$1=-5\n$2=5\n$3=-5\n$4=5\n$5=1\n", "G6 A0 B0 P1000 -3+3-2+2-1+0\n",
		"error:11\r\n", 0, 0);
	g6_case("$1=-5\n$2=5\n$3=-5\n$4=5\n$5=1\n", "G6 A0 B0 P1000 +3+3+2+2-9+1\n",
		"error:11\r\n", 0, 0);
	/* the position limit, reached by small items from near it */
	g6_case("$5=0\nG92 A99999997 B-99999997\n", "G6 A99999997 B-99999997 P1000 +1-1+2-2\n", "ok\r\n",
		3, -3);
	g6_case("$5=0\nG92 A99999997 B-99999997\n", "G6 A99999997 B-99999997 P1000 +1+0+3+0\n",
		"error:7\r\n", 0, 0);
	g6_case("$5=0\nG92 A99999997 B-99999997\n", "G6 A99999997 B-99999997 P1000 +1+0+0-4\n",
		"error:7\r\n", 0, 0);
	/* motors off: items that move only forward, or only motor B */
	g6_case("M18\n", "G6 A0 B0 P1000 +0+0+0+0\n", "ok\r\n", 0, 0);
	g6_case("M18\n", "G6 A0 B0 P1000 +0+0+1+0\n", "error:15\r\n", 0, 0);
	g6_case("M18\n", "G6 A0 B0 P1000 +0+0+0+1\n", "error:15\r\n", 0, 0);
	/* an item past 65535 steps (the summary does not bound it): checked item by item */
	g6_case("$0=60000\n$5=0\n", "G6 A5 B0 P2000000 +70000+0+1+0\n", "ok\r\n", 70006, 0);
	g6_case("$0=60000\n$5=0\n", "G6 A5 B0 P2000000 P1000000+70000+0\n", "error:12\r\n", 0,
		0);
}

/* $B (protocol 1.1): ok at the old rate, then the switch; a rate kept once a
 * valid line arrives, back to 115200 after 1 s without one, on Ctrl-X, and
 * never to a rate the Uno cannot make. */
static void test_baud(void)
{
	int32_t zero[2] = { 0, 0 };
	fake_reset();
	mo_set_pos(zero);
	fb_setup();
	fake_tx_len = 0;
	expect("\x18", BANNER);
	CHECK(fake_baud == 115200, "boots at 115200: %u", (unsigned)fake_baud);
	expect("$B=9600\n", "error:7\r\n");
	expect("$B=230400\n", "error:7\r\n");
	expect("$B\n", "error:4\r\n");
	expect("$B=5x\n", "error:5\r\n");
	CHECK(fake_baud == 115200, "refused rates keep 115200: %u", (unsigned)fake_baud);
	expect("$B=500000\n", "ok\r\n");
	CHECK(fake_baud == 500000, "switched after the ok: %u", (unsigned)fake_baud);
	fake_ms += 900;
	expect("$I\n", BANNER "ok\r\n");
	fake_ms += 5000;
	poll_out(3);
	CHECK(fake_baud == 500000, "a valid line keeps the rate: %u", (unsigned)fake_baud);
	expect("$B=1000000\n", "ok\r\n");
	expect("G1 A1 P1000\x01\n", "error:1\r\n");  /* not a valid line */
	fake_ms += 1001;
	poll_out(3);
	CHECK(fake_baud == 115200, "no valid line in 1 s: back to 115200: %u", (unsigned)fake_baud);
	expect("$B=250000\n", "ok\r\n");
	expect("$I\n", BANNER "ok\r\n");
	expect("\x18", BANNER);
	CHECK(fake_baud == 115200, "Ctrl-X: back to 115200: %u", (unsigned)fake_baud);
}

static void test_reset_while_a_line_waits(void)
{
	int fired = 1, k;
	for (k = 0; fired && k < 100; k++) {
		boot_at_zero();
		send("M3 S255\n");
		for (int i = 0; i < 3; i++)
			fb_poll();
		for (int i = 0; i < CFG_QUEUE_SIZE; i++) {
			send("G1 P1000000 S255\n");
			for (int j = 0; j < 3; j++)
				fb_poll();
		}
		fake_run(1000); /* the first dwell is under way, laser on */
		send("G1 P1000 S255\n");
		for (int j = 0; j < 3; j++)
			fb_poll();
		const char *out = fake_take_tx();
		CHECK(count_of(out, "ok\r\n") == 1 + CFG_QUEUE_SIZE && fake_laser == 255 &&
		      mo_queue_free() == 0, "k=%d: queue full, laser on, a line waiting: '%s'", k, out);
		fake_irq_hook = ctrl_x_isr;
		fake_irq_countdown = k;
		fb_poll();
		fired = fake_irq_hook == 0;
		fake_irq_hook = 0;
		if (!fired)
			fb_rx_isr(0x18); /* after the pass: the plain case */
		out = fake_take_tx();
		CHECK(out[0] == 0, "k=%d: a reply before the banner: '%s'", k, out);
		CHECK(!fake_timer_on && fake_laser == 0 && !mo_running(),
		      "k=%d: the queue started again after the Ctrl-X (laser %u)", k, fake_laser);
		for (int j = 0; j < 3; j++)
			fb_poll();
		out = fake_take_tx();
		CHECK(strcmp(out, BANNER) == 0, "k=%d: only the banner after the reset: '%s'", k, out);
		CHECK(mo_queue_count() == 0 && !mo_running() && fake_laser == 0, "k=%d: queue cleared", k);
		expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n");
	}
	CHECK(k >= 2, "the Ctrl-X was delivered inside the pass (%d points)", k - 1);
}

static int has(const char *hay, const char *needle) { return strstr(hay, needle) != 0; }

/* H: in status reports: the position was set (G92 executed, $H completed) since power-on. */
static void test_homed_flag(void)
{
	boot_at_zero();
	fake_take_tx();
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n");
	expect("G92 A5 B-5\n", "ok\r\n");
	expect("?", "<Run|A:0,B:0|Q:1|Ln:0,1|L:0|U:0|H:0|P:0>\r\n"); /* queued, not executed */
	send("\x18");
	expect("", BANNER);
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n"); /* discarded: never set */
	expect("G92 A5 B-5\n", "ok\r\n");
	tick(100);
	expect("?", "<Idle|A:5,B:-5|Q:0|Ln:1,1|L:0|U:1|H:1|P:0>\r\n");
	send("\x18");
	expect("", BANNER);
	expect("?", "<Idle|A:5,B:-5|Q:0|Ln:0,0|L:0|U:0|H:1|P:0>\r\n"); /* Ctrl-X keeps it */
	/* a homing restarts the count at 0: unknown until it completes */
	fake_endstops = 0;
	expect("$7=1\n$12=10\n$8=40000\n$H\n", "ok\r\nok\r\nok\r\nALARM:31\r\nerror:31\r\n");
	send("?");
	const char *out = poll_out(5);
	CHECK(has(out, "<Alarm:31|A:-10,B:-10|") && has(out, "|H:0|P:0>"), "failed $H: '%s'", out);
	expect("$X\n$7=0\nG92 A1\n", "ok\r\nok\r\nok\r\n");
	tick(100);
	send("?");
	out = poll_out(5);
	CHECK(has(out, "<Idle|A:1,B:-10|") && has(out, "|H:1|P:0>"), "G92 after $X: '%s'", out);
	/* power-on; the Ctrl-X only empties the fake's receive ring */
	fb_rx_isr(0x18);
	fb_poll();
	fake_reset();
	fb_setup();
	fake_take_tx();
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n");
}

/* ---- the record kept across a reset (docs/protocol.md section 7) ------------------------- */

/*
 * Boot again as after a reset: power_on 1 = a power-on, 0 = a reset that left
 * the RAM powered (board_keep as the firmware, or the test, left it).  The
 * Ctrl-X byte stops motion where it is and empties the fake's receive ring
 * (the start-up code clears it on the AVR); fb_setup() handles it without the
 * Ctrl-X's own effects.  Returns the banner check.
 */
static void reboot(uint8_t power_on)
{
	fb_rx_isr(0x18);
	fake_reset();
	fake_power_on = power_on;
	fb_setup();
	const char *out = fake_take_tx();
	CHECK(strcmp(out, BANNER) == 0, "a boot sends the banner: '%s'", out);
}

static void run_lines(const char *lines)
{
	send(lines);
	for (int i = 0; i < 20; i++)
		fb_poll();
	fake_take_tx();
}

/* A motor's steps recorded by the fake, signed by direction. */
static int32_t steps_of(int axis)
{
	int32_t n = 0;
	for (size_t i = 0; i < fake_nsteps; i++)
		if (fake_steps[i].mask & (1u << axis))
			n += ((fake_steps[i].dirs >> axis) & 1u) ? -1 : 1;
	return n;
}

static board_keep_t snapshot;
static int snapped;

static void snapshot_isr(void)
{
	snapshot = board_keep;
	snapped = 1;
}

/* The record at the 50th step edge of a run. */
static void snapshot_step(void)
{
	if (++snapped == 50)
		snapshot = board_keep;
}

static void test_kept_record(void)
{
	char want[96];
	reboot(1);
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n");
	expect("$9=5\nG92 A100 B-50\nG1 A150 B-40 P10000\nG91\n", "ok\r\nok\r\nok\r\nok\r\n");
	tick(100);
	expect("?", "<Idle|A:150,B:-40|Q:0|Ln:3,4|L:0|U:1|H:1|P:0>\r\n");

	/* a reset that keeps the RAM: position, H and Ln done stay; the rest boots */
	reboot(0);
	expect("?", "<Idle|A:150,B:-40|Q:0|Ln:3,0|L:0|U:0|H:1|P:0>\r\n");
	send("$$\n");
	const char *out = poll_out(5);
	CHECK(strstr(out, "$9=100\r\n") != 0, "settings at their boot values: '%s'", out);
	expect("G1 A-300 B-40 P100000\n", "ok\r\n"); /* G90 again: absolute, folds off below 0 */
	tick(100);
	expect("?", "<Idle|A:-300,B:-40|Q:0|Ln:2,2|L:0|U:1|H:1|P:0>\r\n");

	/* a reset mid-segment: the motors stop part-way, exactly counted */
	fake_nsteps = 0;
	run_lines("M3 S255\nG1 A700 B60 P100000\nG1 A1700 B-40 P100000\n");
	fake_ms += 100;
	fb_poll();
	fake_run(1600000u + 700000u); /* line 4 done, line 5 under way */
	CHECK(fake_laser == 255 && mo_running(), "the second segment burns");
	int32_t a = -300 + steps_of(0), b = -40 + steps_of(1);
	CHECK(700 < a && a < 1700 && b < 60 && b > -40, "part-way: %d, %d", a, b);
	reboot(0);
	CHECK(fake_laser == 0 && !fake_timer_on, "a boot stops motion, laser off");
	snprintf(want, sizeof want, "<Idle|A:%d,B:%d|Q:0|Ln:4,0|L:0|U:0|H:1|P:0>\r\n", a, b);
	expect("?", want);
	CHECK(steps_of(0) == 0 && steps_of(1) == 0, "no step after the reset");

	/* Ctrl-X after it: Ln done to 0, position and H kept */
	send("\x18");
	expect("", BANNER);
	snprintf(want, sizeof want, "<Idle|A:%d,B:%d|Q:0|Ln:0,0|L:0|U:0|H:1|P:0>\r\n", a, b);
	expect("?", want);

	/* the record is used only when it is whole: not at the instant a step's
	 * pins rose (the drivers saw the step, the count may not have it yet) */
	static const char power_on[] = "<Idle|A:0,B:0|Q:0|Ln:0,0|L:0|U:0|H:0|P:0>\r\n";
	run_lines("G1 A-100 P100000\n");
	fake_ms += 100;
	fb_poll();
	snapped = 0;
	fake_step_hook = snapshot_step;
	fake_run(800000);
	fake_step_hook = 0;
	CHECK(snapped >= 50, "the steps were seen: %d", snapped);
	board_keep = snapshot;
	reboot(0);
	expect("?", power_on);
	run_lines("G92 A7 B8\n");
	tick(100);
	reboot(0);
	expect("?", "<Idle|A:7,B:8|Q:0|Ln:1,0|L:0|U:0|H:1|P:0>\r\n");
	board_keep.check ^= 0x100u;
	reboot(0);
	expect("?", power_on);
	run_lines("G92 A7 B8\n");
	tick(100);
	board_keep.done ^= 4u; /* Ln done has its complement beside it */
	reboot(0);
	expect("?", power_on);
	run_lines("G92 A7 B8\n");
	tick(100);
	board_keep.left[1] = 3; /* a fast block's steps not issued: not in the position */
	board_keep.fdirs = 2;
	reboot(0);
	expect("?", "<Idle|A:7,B:11|Q:0|Ln:1,0|L:0|U:0|H:1|P:0>\r\n");
	board_keep.left[0] = FAST_NMAX + 1u;
	reboot(0);
	expect("?", power_on);
	run_lines("G92 A7 B8\n");
	tick(100);
	board_keep.busy = 1; /* a reset while a step or an update was being recorded */
	reboot(0);
	expect("?", power_on);
	run_lines("G92 A7 B8\n");
	tick(100);
	reboot(1); /* the hardware says power-on */
	expect("?", power_on);
	/* random RAM */
	uint32_t x = 99;
	for (int round = 0; round < 200; round++) {
		board_keep_t junk;
		uint8_t *bytes = (uint8_t *)&junk;
		for (size_t i = 0; i < sizeof junk; i++) {
			x = x * 1103515245u + 12345u;
			bytes[i] = (uint8_t)(x >> 16);
		}
		if (round % 2)
			junk.busy = 0;
		board_keep = junk;
		reboot(0);
		int32_t pos[2];
		mo_get_pos(pos);
		CHECK(pos[0] == 0 && pos[1] == 0 && !motion().homed && motion().done == 0,
		      "round %d: random RAM taken for a record", round);
	}
}

/*
 * A reset at every point of a (failing) homing where interrupts are enabled
 * again: the record the next boot finds has H:0, whatever position it holds.
 * $H clears H before it zeroes the position, so no boot finds H:1 with the
 * seek's count.
 */
static void test_reset_during_homing(void)
{
	int k, fired = 1, positions = 0;
	int32_t last = 1000;
	for (k = 0; fired && k < 200; k++) {
		reboot(1);
		expect("$7=1\n$12=10\n$8=40000\nG92 A5 B5\n", "ok\r\nok\r\nok\r\nok\r\n");
		tick(100);
		CHECK(motion().homed, "k=%d: G92 set H", k);
		send("$H\n");
		snapped = 0;
		fake_irq_hook = snapshot_isr;
		fake_irq_countdown = k;
		const char *out = poll_out(5);
		fired = snapped;
		fake_irq_hook = 0;
		CHECK(strcmp(out, "ALARM:31\r\nerror:31\r\n") == 0, "k=%d: homing fails: '%s'", k, out);
		if (!fired)
			break;
		board_keep = snapshot;
		reboot(0);
		int32_t pos[2];
		mo_get_pos(pos);
		/* Ln done: the G92's line, or the $H's once a homing move ended */
		CHECK(!motion().homed && (motion().done == 4 || motion().done == 5),
		      "k=%d: H %u, Ln done %u", k, motion().homed, motion().done);
		CHECK(pos[0] == pos[1] && (pos[0] == 5 || (pos[0] <= 0 && pos[0] >= -10)),
		      "k=%d: position %d,%d", k, pos[0], pos[1]);
		if (pos[0] != last)
			positions++;
		last = pos[0];
	}
	CHECK(k > 3 && positions >= 3, "resets at %d points saw %d positions", k, positions);
}

/* Strict framing in the firmware: refused lines are not executed; a Ctrl-X ends it. */
static void test_strict_framing(void)
{
	char buf[64];
	boot_at_zero();
	fake_take_tx();
	expect("$I\n", BANNER "ok\r\n"); /* a host that never numbers lines */
	framed(buf, sizeof buf, "N2 G90");
	strcat(buf, "\n");
	expect(buf, "ok\r\n");
	expect("G1 A50 P100000\n", "error:10 resend:3\r\n");
	tick(100);
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,2|L:0|U:0|H:0|P:0>\r\n");
	CHECK(fake_nsteps == 0, "the refused line did not move");
	send("\x18");
	expect("", BANNER);
	expect("$I\n", BANNER "ok\r\n"); /* a reset ends strict framing */
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,1|L:0|U:0|H:0|P:0>\r\n");
}

/*
 * The watchdog feeding rule (fb_main.c fb_feed_watchdog, mo_alive): the main
 * loop feeds only while the step generator is stopped, held, or its
 * interrupt ran since the last look.  Here the fake's step timer runs only
 * when the test says so, so "the main loop runs, the step interrupt does not"
 * is a hung or dead step interrupt.
 */
static void test_watchdog_feeding(void)
{
	boot_at_zero();
	fake_take_tx();
	uint32_t f = fake_wdt_feeds;
	fb_poll();
	fb_poll();
	CHECK(fake_wdt_feeds == f + 2, "idle: every main loop pass feeds");
	send("M3 S255\nG1 A100 P100000\n");
	for (int i = 0; i < 10; i++)
		fb_poll();
	fake_ms += 100;
	f = fake_wdt_feeds;
	fb_poll(); /* starts the queue: the timer is armed, no event yet */
	CHECK(mo_running() && fake_timer_on && fake_wdt_feeds == f,
	      "the segment runs; no feed before its first interrupt");
	fake_run(fake_timer_delay); /* the first event: the segment starts, laser on */
	fb_poll();
	CHECK(fake_laser == 255 && fake_wdt_feeds == f + 1, "its first interrupt: fed");
	f = fake_wdt_feeds;
	for (int i = 0; i < 20; i++)
		fb_poll();
	CHECK(fake_wdt_feeds == f && fake_laser == 255,
	      "a dead step interrupt stops the feeding (laser on: the watchdog turns it off)");
	/* one step event per pass: every pass feeds; passes between events do not */
	for (int i = 0; i < 5; i++) {
		f = fake_wdt_feeds;
		fake_run(fake_timer_delay);
		fb_poll();
		CHECK(fake_wdt_feeds == f + 1, "an interrupt since the last pass: fed");
		fb_poll();
		CHECK(fake_wdt_feeds == f + 1, "no interrupt since the last pass: not fed");
	}
	/* held: the step timer is paused on purpose, the main loop alone feeds */
	fb_rx_isr('!');
	f = fake_wdt_feeds;
	fb_poll();
	fb_poll();
	CHECK(fake_timer_paused && fake_wdt_feeds == f + 2, "held: fed without steps");
	fb_rx_isr('~');
	fb_poll();
	f = fake_wdt_feeds;
	fb_poll();
	CHECK(fake_wdt_feeds == f, "resumed: the interrupt must run again before a feed");
	fake_run(UINT64_MAX / 2);
	fb_poll();
	f = fake_wdt_feeds;
	fb_poll();
	CHECK(!mo_running() && fake_wdt_feeds == f + 1, "the queue ran empty: idle, fed again");
	fake_take_tx();
}


/* Run the step timer for ms of simulated time (servo frames included). */
static void run_ms(uint32_t ms)
{
	fake_ms += ms;
	fb_poll();
	fake_run(16000ull * ms);
	fb_poll();
}

/*
 * The pen servo: M280 parsing, $14 (kept in the EEPROM), the queued pen
 * block whose move and settle time no step may enter, and the park at a
 * hold (lowered again before '~' resumes), a reset, an alarm, a boot and
 * host silence.
 */
static void test_pen(void)
{
	proto_lines_t ln = { 0, 0 };
	proto_cmd_t c;
	CHECK(parse(&ln, "M280 S1500 R200 D150", &c) == FB_OK && c.kind == PROTO_CMD_M280 &&
	      c.s == 1500 && c.r == 200 && c.d == 150, "M280 parses");
	CHECK(parse(&ln, "M280 S499", &c) == FB_ERR_OUT_OF_RANGE, "S below the servo range");
	CHECK(parse(&ln, "M280 S2501", &c) == FB_ERR_OUT_OF_RANGE, "S above the servo range");
	CHECK(parse(&ln, "M280 S1500 R-1", &c) == FB_ERR_OUT_OF_RANGE, "negative R");
	CHECK(parse(&ln, "M280 S1500 D10001", &c) == FB_ERR_OUT_OF_RANGE, "D too long");
	CHECK(parse(&ln, "M280 R10", &c) == FB_ERR_MISSING_WORD, "S required");
	CHECK(parse(&ln, "M280 S1500 P10", &c) == FB_ERR_BAD_WORD, "no P on M280");
	CHECK(parse(&ln, "G1 A1 P100 R5", &c) == FB_ERR_BAD_WORD, "no R on G1");
	CHECK(parse(&ln, "M3 S300", &c) == FB_ERR_OUT_OF_RANGE, "M3 S stays 0..255");

	int32_t zero[2] = { 0, 0 };
	reboot(1);
	mo_set_pos(zero);
	expect("M280 S1000\n", "error:19\r\n");
	expect("$14=499\n", "error:7\r\n");
	expect("$14=1800\n", "ok\r\n");
	CHECK(fake_ee_park == 1800, "$14 stored in the EEPROM: %u", fake_ee_park);
	expect("?", "<Idle|A:0,B:0|Q:0|Ln:0,3|L:0|U:0|H:0|P:1800>\r\n");
	run_ms(40);
	CHECK(fake_pen_pulse == 0, "no frames while idle in the fake");

	/* pen down over 200 ms, settle 100 ms, then a segment: its first step
	 * comes after both, with the pulse at the down value */
	fake_nsteps = 0;
	expect("M280 S1000 R200 D100\nG1 A10 P10000\n", "ok\r\nok\r\n");
	run_ms(100);
	CHECK(motion().pen < 1800 && motion().pen > 1000, "the pulse moves: %u", motion().pen);
	CHECK(fake_nsteps == 0, "no step while the pen moves");
	run_ms(1000);
	CHECK(fake_nsteps == 10, "the segment ran: %zu steps", fake_nsteps);
	CHECK(fake_steps[0].cycle >= 16000ull * 300 && fake_steps[0].pen == 1000,
	      "first step at %llu cycles with pulse %u", (unsigned long long)fake_steps[0].cycle,
	      fake_steps[0].pen);
	expect("?", "<Idle|A:10,B:0|Q:0|Ln:5,5|L:0|U:1|H:0|P:1000>\r\n");

	/* a hold parks the pen; '~' lowers it and waits its time (300 ms) first */
	expect("G1 A20 P100000\n", "ok\r\n");
	run_ms(50);
	size_t before = fake_nsteps;
	expect("!", "");
	CHECK(motion().pen == 1800, "hold parks the pen: %u", motion().pen);
	expect("~", "");
	CHECK(motion().pen == 1000, "'~' lowers it again");
	run_ms(200);
	CHECK(fake_nsteps == before, "no step before the pen's time is over");
	expect("?", "<Hold:0|A:15,B:0|Q:0|Ln:5,6|L:0|U:1|H:0|P:1000>\r\n");
	run_ms(200);
	run_ms(200);
	CHECK(fake_nsteps > before, "resumed after it");
	run_ms(1000);
	expect("?", "<Idle|A:20,B:0|Q:0|Ln:6,6|L:0|U:2|H:0|P:1000>\r\n");

	/* host silence with the pen down parks it, idle or not */
	fake_ms += DEF_LASER_TIMEOUT + 1;
	fb_poll();
	CHECK(motion().pen == 1800, "silence parks an idle pen: %u", motion().pen);
	expect("M280 S1000\nG1 A30 P10000000\n", "ok\r\nok\r\n");
	run_ms(100);
	fake_ms += DEF_LASER_TIMEOUT + 1;
	fb_poll();
	expect("?", "<Hold:1|A:20,B:0|Q:0|Ln:7,8|L:0|U:2|H:0|P:1800>\r\n");

	/* Ctrl-X parks and forgets: '~' has nothing to lower */
	send("\x18");
	expect("", BANNER);
	CHECK(motion().pen == 1800 && !mo_pen_down(), "reset parks");
	expect("M280 S900 D50\n", "ok\r\n");
	run_ms(100);
	CHECK(motion().pen == 900, "down at once without R");
	/* an alarm parks */
	expect("$7=1\n", "ok\r\n");
	fake_endstops = 1;
	expect("G1 A-5 P100000\n", "ok\r\n");
	run_ms(200);
	const char *out = poll_out(5);
	CHECK(strstr(out, "ALARM:30") != 0 || mo_alarm() == 0, "alarm raised: '%s'", out);
	CHECK(motion().pen == 1800, "alarm parks: %u", motion().pen);
	fake_endstops = 0;
	expect("$X\n$7=0\n", "ok\r\nok\r\n");

	/* a boot, power-on included, parks at the EEPROM's value */
	expect("M280 S700\n", "ok\r\n");
	run_ms(100);
	CHECK(mo_pen_target() == 700, "down");
	fb_rx_isr(0x18);
	fake_power_on = 0;
	fb_setup();
	fake_take_tx();
	CHECK(motion().pen == 1800, "a reset that keeps the RAM parks: %u", motion().pen);
	uint16_t ee = fake_ee_park;
	fake_reset();
	fake_ee_park = ee;
	fb_setup();
	fake_take_tx();
	CHECK(motion().pen == 1800, "a power-on parks at the stored value: %u", motion().pen);
	fake_reset();
	fb_setup();
	fake_take_tx();
	CHECK(motion().pen == DEF_PEN_PARK, "blank EEPROM: the default %u", motion().pen);
}

int main(void)
{
	test_crc();
	test_number_bounds();
	test_parse_table();
	test_framing();
	test_line_noise();
	test_dda_exact();
	test_delays_bounded();
	test_too_fast();
	test_hold_resume();
	test_homing_block();
	test_endstop_alarm();
	test_app();
	test_reset_while_a_line_waits();
	test_homed_flag();
	test_strict_framing();
	test_g6_app();
	test_g6_checks_random();
	test_g6_checks_edges();
	test_baud();
	test_kept_record();
	test_reset_during_homing();
	test_watchdog_feeding();
	test_pen();
	printf("%d checks, %d failed\n", checks, failures);
	return failures ? 1 : 0;
}
