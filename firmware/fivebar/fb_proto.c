/*
 * fb_proto.c - line framing and command parsing (pure, portable C).
 *
 * A line is: [N<n>] <command> [words] [;comment] [*<crc16>/<len>]
 * G6 (protocol 3) carries several segments: a G1 head, then relative items
 * "[P<us>]<+|-><a><+|-><b>", each one more segment and one more line number;
 * G7 (protocol 4) binary segments and pixels (fb_g7.c).
 * The checksum field covers every byte before the last '*' (the body): its
 * CRC-16 and its length in bytes.  Numbers are decimal integers; there are no
 * floats anywhere in the firmware.
 */
#include <string.h>
#include "fb_proto.h"
#include "config.h"
#include "status.h"

/*
 * CRC-16/CCITT-FALSE (width 16, poly 0x1021, init 0xFFFF, refin/refout false,
 * xorout 0, check 0x29B1: CRC-16/IBM-3740 in Greg Cook's "Catalogue of
 * parametrised CRC algorithms"): MSB first, each byte goes into the top of the
 * register and its bits shift out through the polynomial.  That is avr-libc's
 * _crc_xmodem_update step (which starts from 0 instead of 0xFFFF).  On the AVR
 * its branch-free inline assembly runs about 25 cycles a byte against about 90
 * for the bit loop below; the difference decided whether the main loop keeps
 * the queue fed at a 40 kHz uneven step rate (python benchmarks/firmware.py).
 * The host build (unit tests, fuzzing) runs the bit loop, the emulator tests
 * the assembly against the host's protocol.crc16.
 */
#if defined(__AVR__)
#include <util/crc16.h>
#endif

uint16_t proto_crc16(const char *s, uint8_t len)
{
	uint16_t crc = 0xFFFFu;
	for (uint8_t i = 0; i < len; i++) {
#if defined(__AVR__)
		crc = _crc_xmodem_update(crc, (uint8_t)s[i]);
#else
		crc ^= (uint16_t)((uint16_t)(uint8_t)s[i] << 8);
		for (uint8_t b = 0; b < 8; b++)
			crc = (crc & 0x8000u) ? (uint16_t)((uint16_t)(crc << 1) ^ 0x1021u)
					      : (uint16_t)(crc << 1);
#endif
	}
	return crc;
}

static uint8_t is_ws(char c) { return c == ' ' || c == '\t'; }
static uint8_t is_digit(char c) { return c >= '0' && c <= '9'; }
static char upper(char c) { return (c >= 'a' && c <= 'z') ? (char)(c - 'a' + 'A') : c; }
static uint8_t is_letter(char c) { c = upper(c); return c >= 'A' && c <= 'Z'; }

static uint8_t skip_ws(const char *s, uint8_t i, uint8_t end)
{
	while (i < end && is_ws(s[i]))
		i++;
	return i;
}

/*
 * Whether the checksum field after the last '*' (at index end) is right:
 * "<crc16>/<len>", then only spaces or tabs; the CRC-16 that of the body
 * line[0..end), the length end (the body's, at most 99).  The length catches
 * every byte lost from or added to the body, which the CRC-16 alone would let
 * through with the odds of a random 16-bit match (docs/protocol.md 14).
 * Both numbers are decimal without a leading zero (0 itself is "0"), so each
 * value has one spelling and a digit inserted or dropped in the field always
 * changes a value or breaks the form.  One loop parses both numbers: the
 * smaller of the two forms measured with avr-gcc -Os (a helper called once
 * per number took 44 bytes more of flash).
 */
static uint8_t field_ok(const char *line, uint8_t end, uint8_t len)
{
	uint16_t num[2] = { 0, 0 };
	uint8_t i = (uint8_t)(end + 1);
	for (uint8_t k = 0; k < 2; k++) {
		uint8_t start = i;
		uint16_t v = 0;
		while (i < len && is_digit(line[i])) {
			uint8_t d = (uint8_t)(line[i] - '0');
			if (v > 6553u || (v == 6553u && d > 5u))
				return 0;  /* above 65535 */
			v = (uint16_t)(v * 10u + d);
			i++;
		}
		if (i == start || (line[start] == '0' && i > start + 1))
			return 0;  /* no digit, or a leading zero */
		num[k] = v;
		if (k == 0) {
			if (i >= len || line[i] != '/')
				return 0;
			i++;
		}
	}
	if (num[1] > 255u || num[1] != end || skip_ws(line, i, len) < len)
		return 0;
	return proto_crc16(line, end) == num[0];
}

/* A number must end at the end, at whitespace or at the next word's letter. */
static uint8_t number_ends(const char *s, uint8_t i, uint8_t end)
{
	return i >= end || is_ws(s[i]) || is_letter(s[i]);
}

/* Unsigned decimal into uint32; FB_ERR_BAD_NUMBER when malformed,
 * FB_ERR_OUT_OF_RANGE when above max. */
static uint8_t parse_uint(const char *s, uint8_t *pi, uint8_t end, uint32_t max, uint32_t *out)
{
	uint8_t i = *pi, over = 0, digits = 0;
	uint32_t v = 0;
	while (i < end && is_digit(s[i])) {
		uint8_t d = (uint8_t)(s[i] - '0');
		/* over when v * 10 + d > max; no division (a 32-bit one per digit
		 * was most of a line's parse time): v * 10 + d fits 32 bits up to
		 * v = 429496729 with d <= 5 */
		if (v > 429496729u || (v == 429496729u && d > 5u) || v * 10u + d > max)
			over = 1;
		else
			v = v * 10u + d;
		i++;
		digits++;
	}
	if (!digits || !number_ends(s, i, end))
		return FB_ERR_BAD_NUMBER;
	*pi = i;
	if (over)
		return FB_ERR_OUT_OF_RANGE;
	*out = v;
	return FB_OK;
}

/* Signed decimal into int32. */
static uint8_t parse_int(const char *s, uint8_t *pi, uint8_t end, int32_t *out)
{
	uint8_t i = *pi, neg = 0;
	if (i < end && (s[i] == '-' || s[i] == '+')) {
		neg = s[i] == '-';
		i++;
	}
	uint32_t v = 0;
	uint8_t st = parse_uint(s, &i, end, neg ? 2147483648UL : 2147483647UL, &v);
	if (st != FB_OK)
		return st;
	*pi = i;
	*out = neg ? (int32_t)(0u - v) : (int32_t)v;
	return FB_OK;
}

/* The words (PROTO_W_*) a command may carry.  Tests, not a switch: avr-gcc
 * turned the switch into a 16-byte lookup table in the static RAM (.data,
 * CSWTCH), 16 of the bytes the stack has above it (python
 * benchmarks/stack.py). */
static uint8_t allowed_words(uint8_t kind)
{
	if (kind == PROTO_CMD_G1 || kind == PROTO_CMD_G6)
		return PROTO_W_A | PROTO_W_B | PROTO_W_P | PROTO_W_S;
	if (kind == PROTO_CMD_G92)
		return PROTO_W_A | PROTO_W_B;
	if (kind == PROTO_CMD_M3)
		return PROTO_W_S;
	if (kind == PROTO_CMD_M280)
		return PROTO_W_S | PROTO_W_R | PROTO_W_D;
	return 0;
}

static uint8_t parse_dollar(const char *s, uint8_t i, uint8_t end, proto_cmd_t *cmd)
{
	if (i >= end)
		return FB_ERR_UNKNOWN_COMMAND;
	char c = upper(s[i]);
	if (is_digit(c)) {
		uint32_t n = 0;
		uint8_t j = i;
		while (j < end && is_digit(s[j]))
			j++;
		if (j >= end || s[j] != '=') {
			/* "$5" alone: the value is missing; "$5x" is malformed */
			return (skip_ws(s, j, end) >= end) ? FB_ERR_MISSING_WORD : FB_ERR_BAD_NUMBER;
		}
		uint8_t k = i;
		/* the '=' is not a number end, so parse the digits by hand */
		while (k < j) {
			n = n * 10u + (uint32_t)(s[k] - '0');
			if (n > 255u)
				return FB_ERR_UNKNOWN_SETTING;
			k++;
		}
		j++;
		int32_t v = 0;
		uint8_t st = parse_int(s, &j, end, &v);
		if (st != FB_OK)
			return st;
		if (skip_ws(s, j, end) < end)
			return FB_ERR_BAD_WORD;
		cmd->kind = PROTO_CMD_SET;
		cmd->setting = (uint8_t)n;
		cmd->value = v;
		return FB_OK;
	}
	if (c == 'B' && i + 1u < end && s[i + 1u] == '=') {
		/* $B=<baud> (protocol section 1.1): the value is checked on execution */
		uint8_t j = (uint8_t)(i + 2u);
		int32_t v = 0;
		uint8_t st = parse_int(s, &j, end, &v);
		if (st != FB_OK)
			return st;
		if (skip_ws(s, j, end) < end)
			return FB_ERR_BAD_WORD;
		cmd->kind = PROTO_CMD_BAUD;
		cmd->value = v;
		return FB_OK;
	}
	switch (c) {
	case 'I': cmd->kind = PROTO_CMD_INFO; break;
	case '$': cmd->kind = PROTO_CMD_LIST; break;
	case 'H': cmd->kind = PROTO_CMD_HOME; break;
	case 'X': cmd->kind = PROTO_CMD_UNLOCK; break;
	default: return FB_ERR_UNKNOWN_COMMAND;
	}
	if (skip_ws(s, (uint8_t)(i + 1), end) < end)
		return FB_ERR_BAD_WORD;
	return FB_OK;
}

static uint8_t command_kind(char letter, uint32_t code)
{
	if (letter == 'G') {
		switch (code) {
		case 1: return PROTO_CMD_G1;
		case 6: return PROTO_CMD_G6;
		case 7: return PROTO_CMD_G7;
		case 90: return PROTO_CMD_G90;
		case 91: return PROTO_CMD_G91;
		case 92: return PROTO_CMD_G92;
		default: return PROTO_CMD_NONE;
		}
	}
	switch (code) {
	case 3: return PROTO_CMD_M3;
	case 5: return PROTO_CMD_M5;
	case 17: return PROTO_CMD_M17;
	case 18: return PROTO_CMD_M18;
	case 110: return PROTO_CMD_M110;
	case 280: return PROTO_CMD_M280;
	default: return PROTO_CMD_NONE;
	}
}

/*
 * A G6 item number at *pp: an optional sign and decimal digits, ending at the
 * end, whitespace, a letter or the next item's sign; |value| <=
 * CFG_POS_LIMIT.  A G6 line's items are read three times (parse, checks,
 * queueing), most of them one or two digits, so this is the parser's inner
 * loop: it walks a pointer (the AVR's post-increment loads, where an index
 * into the line cost an address sum at every byte), values below 1000 grow
 * in 16 bits (the 8x8 multiplier) and the rest in 32 bits, stopping above the
 * limit (python benchmarks/segcost.py: about a third of the cycles of the
 * general loop).
 */
/* Whether c may end an item's number: whitespace, a letter or a sign. */
static inline __attribute__((always_inline)) uint8_t item_num_end(char c)
{
	return c == ' ' || c == '\t' || (uint8_t)((uint8_t)(c | 0x20) - 'a') < 26u || c == '+' ||
	       c == '-';
}

/* item_num for a number of five digits or more, from its sign at s: the
 * general 32-bit loop, stopping above the limit (so it never overflows). */
static __attribute__((noinline)) const char *item_num_long(const char *s, const char *end,
							  int32_t *out, uint8_t *st)
{
	uint8_t neg = 0, d;
	if (*s == '-' || *s == '+') {  /* s < end: digits follow */
		neg = *s == '-';
		s++;
	}
	uint32_t v = 0;
	while (s < end && (d = (uint8_t)(*s - '0')) <= 9u) {
		if (v <= (uint32_t)CFG_POS_LIMIT)
			v = v * 10u + d;
		s++;
	}
	if (s < end && !item_num_end(*s)) {
		*st = FB_ERR_BAD_NUMBER;
		return 0;
	}
	if (v > (uint32_t)CFG_POS_LIMIT) {
		*st = FB_ERR_OUT_OF_RANGE;
		return 0;
	}
	*out = neg ? -(int32_t)v : (int32_t)v;
	return s;
}

/*
 * A G6 item number at s: an optional sign and decimal digits, ending at the
 * end, whitespace, a letter or the next item's sign; |value| <=
 * CFG_POS_LIMIT.  Returns where it ends, or 0 with *st the error.  A G6
 * line's items are read three times (parse, checks, queueing), most of them
 * one or two digits, so this is the parser's inner loop: it walks a pointer
 * it returns (the AVR's post-increment loads; an index into the line cost an
 * address sum at every byte, a pointer passed by address a stack slot), and
 * numbers up to four digits stay in 16 bits (the 8x8 multiplier); longer
 * ones go to item_num_long, whose 32-bit multiply (a call) would otherwise
 * make every short number save a dozen registers (python
 * benchmarks/segcost.py).
 */
static const char *item_num(const char *s, const char *end, int32_t *out, uint8_t *st)
{
	const char *num = s;
	uint8_t neg = 0, d;
	if (s < end && (*s == '-' || *s == '+')) {
		neg = *s == '-';
		s++;
	}
	const char *start = s;
	uint16_t v = 0;
	uint8_t digits = 0;
	while (s < end && (d = (uint8_t)(*s - '0')) <= 9u) {
		if (++digits > 4u)
			return item_num_long(num, end, out, st);
		v = (uint16_t)(v * 10u + d);
		s++;
	}
	if (s == start || (s < end && !item_num_end(*s))) {
		*st = FB_ERR_BAD_NUMBER;
		return 0;
	}
	*out = neg ? -(int32_t)v : (int32_t)v;
	return s;
}

/* One G6 item from s: [P<us>] then <+|-><a><+|-><b> (docs/protocol.md 6.3).
 * Returns where it ends, or 0 with *st the error.  The two moves, nearly
 * always a few digits, are read here without a call (item_num's rules, its
 * long numbers to item_num_long): each call cost its register saves, about
 * as much as the digits (python benchmarks/segcost.py). */
static const char *g6_item(const char *s, const char *end, int32_t *p, int32_t d[2], uint8_t *st)
{
	while (s < end && (*s == ' ' || *s == '\t'))
		s++;
	if (s < end && (*s == 'P' || *s == 'p')) {
		s++;
		int32_t v = 0;
		*st = FB_ERR_BAD_NUMBER;
		if (s < end && (*s == '+' || *s == '-'))
			return 0;
		s = item_num(s, end, &v, st);
		if (!s)
			return 0;
		*st = FB_ERR_OUT_OF_RANGE;
		if (v < CFG_P_MIN_US || v > CFG_P_MAX_US)
			return 0;
		*p = v;
		while (s < end && (*s == ' ' || *s == '\t'))
			s++;
	}
	for (uint8_t k = 0; k < 2; k++) {
		if (s >= end || (*s != '+' && *s != '-')) {
			*st = FB_ERR_BAD_WORD;
			return 0;
		}
		const char *num = s;
		uint8_t neg = *s == '-', digits = 0, c;
		uint16_t v = 0;
		s++;
		while (s < end && (c = (uint8_t)(*s - '0')) <= 9u) {
			if (++digits > 4u)
				break;
			v = (uint16_t)(v * 10u + c);
			s++;
		}
		if (digits > 4u) {
			s = item_num_long(num, end, &d[k], st);
			if (!s)
				return 0;
			continue;
		}
		if (!digits || (s < end && !item_num_end(*s))) {
			*st = FB_ERR_BAD_NUMBER;
			return 0;
		}
		d[k] = neg ? -(int32_t)v : (int32_t)v;
	}
	return s;
}

/* n bytes little-endian from r (n = 1, 2, 4), sign-extended / as they are. */
static int32_t get_le(const uint8_t *r, uint8_t n)
{
	if (n == 1u)
		return (int8_t)r[0];
	if (n == 2u)
		return (int16_t)(uint16_t)(r[0] | (uint16_t)r[1] << 8);
	return (int32_t)((uint32_t)r[0] | (uint32_t)r[1] << 8 | (uint32_t)r[2] << 16 |
			 (uint32_t)r[3] << 24);
}

uint8_t proto_g6_next(const char *line, uint8_t *at, uint8_t end, int32_t *p, int32_t d[2])
{
	if (*at >= end)
		return 0;
	const uint8_t *r = (const uint8_t *)line + *at;
	uint8_t tag = *r++;
	if (!tag) {
		/* two 1-byte moves, no P: nearly every item (a few steps each) */
		d[0] = (int8_t)r[0];
		d[1] = (int8_t)r[1];
		*at = (uint8_t)(*at + 3u);
		return 1;
	}
	for (uint8_t k = 0; k < 2; k++) {
		uint8_t n = (uint8_t)(1u << ((tag >> (2u * k)) & 3u));
		d[k] = get_le(r, n);
		r += n;
	}
	if (tag & PROTO_G6_HAS_P) {
		*p = get_le(r, 4);
		r += 4;
	}
	*at = (uint8_t)((const char *)r - line);
	return 1;
}

/* n bytes of v little-endian at w; where they end. */
static char *put_le(char *w, uint32_t v, uint8_t n)
{
	for (uint8_t k = 0; k < n; k++, v >>= 8)
		*w++ = (char)(uint8_t)v;
	return w;
}

/* An item's record (fb_proto.h) at w, with its P when has_p; where it ends. */
static char *put_item(char *w, const int32_t d[2], uint8_t has_p, int32_t p)
{
	if (!has_p && d[0] >= -128 && d[0] <= 127 && d[1] >= -128 && d[1] <= 127) {
		/* nearly every item: its record in three stores */
		w[0] = 0;
		w[1] = (char)(int8_t)d[0];
		w[2] = (char)(int8_t)d[1];
		return w + 3;
	}
	char *tag = w++;
	uint8_t t = has_p ? PROTO_G6_HAS_P : 0u;
	for (uint8_t k = 0; k < 2; k++) {
		int32_t v = d[k];
		uint8_t code = (v >= -128 && v <= 127) ? PROTO_G6_I8
			       : (v >= -32768 && v <= 32767) ? PROTO_G6_I16 : PROTO_G6_I32;
		t = (uint8_t)(t | code << (2u * k));
		w = put_le(w, (uint32_t)v, (uint8_t)(1u << code));
	}
	if (has_p)
		w = put_le(w, (uint32_t)p, 4);
	*tag = (char)t;
	return w;
}

/* floor(p_us * F_CPU/1e6 / n), at most 65535: the step interval of n steps in
 * p_us, in cycles (the G6 summary's g6_cps; n >= 1).  In 16 bits when the
 * duration's cycles fit (p_us < 4096), as mo_prepare divides. */
static uint16_t item_cps(int32_t p_us, uint16_t n)
{
	uint32_t c = (uint32_t)p_us * (FB_F_CPU / 1000000UL);
	if (n == 1u)
		return c > 0xffffu ? 0xffffu : (uint16_t)c;
	if (c <= 0xffffu)
		return (uint16_t)((uint16_t)c / n);
	c /= n;
	return c > 0xffffu ? 0xffffu : (uint16_t)c;
}

/* A G6 item's larger step count (0xffff for an item that moves no motor), or
 * 0 when a motor moves more than 32767 steps: the summary's bound, which keeps
 * every move an int16_t. */
static uint16_t item_steps(const int32_t d[2])
{
	uint16_t n = 0;
	for (uint8_t k = 0; k < 2; k++) {
		int32_t v = d[k] < 0 ? -d[k] : d[k];
		if (v > 0x7fffL)
			return 0;
		if ((uint16_t)v > n)
			n = (uint16_t)v;
	}
	return n ? n : 0xffffu;
}

/*
 * The items of a G6 line from s[i]: each must parse; counted in cmd, and
 * summed up for the checks (proto_cmd_t's g6_lo, g6_hi, g6_cps).  The checks
 * read the line once here instead of again item by item: a third of a
 * segment's parse and all of its checks, and the queue ran empty while a
 * line of 23 items was read and checked (python benchmarks/segcost.py).  A
 * duration run's step interval is divided once, when its P changes.  The sums
 * are 16-bit (a line whose sums leave the int16_t range, or with a move over
 * 32767 steps, is not summed up: g6_cps 0).  Not inlined: its locals would
 * stay in the main loop's frame under every line, G7 scans (the stack's
 * deepest point, benchmarks/stack.py) included.
 */
static __attribute__((noinline)) uint8_t g6_items(char *s, uint8_t i, uint8_t end,
						  proto_cmd_t *cmd)
{
	int32_t p = cmd->p, d[2];
	int16_t sum[2] = { 0, 0 }, lo[2] = { 0, 0 }, hi[2] = { 0, 0 };
	int32_t run_p = p;
	uint16_t run_n = 0, cps = 0xffffu;  /* the run's most steps; the least interval */
	uint8_t wide = 0;                   /* not summed up (above) */
	cmd->g6_at = i;
	const char *at = s + i, *e = s + end;
	char *w = s + i;  /* the records (fb_proto.h), behind what is read */
	for (;;) {
		while (at < e && is_ws(*at))
			at++;
		if (at >= e)
			break;
		uint8_t st = FB_OK;
		int32_t p_was = p;
		at = g6_item(at, e, &p, d, &st);
		if (!at)
			return st;
		w = put_item(w, d, p != p_was, p);
		cmd->g6_end = (uint8_t)(w - s);
		cmd->g6_count++;
		if (wide)
			continue;
		uint16_t n = item_steps(d);
		if (!n) {
			wide = 1;
			continue;
		}
		if (p != run_p) {
			if (run_n) {
				uint16_t c = item_cps(run_p, run_n);
				cps = c < cps ? c : cps;
			}
			run_p = p;
			run_n = 0;
		}
		if (n != 0xffffu && n > run_n)
			run_n = n;
		for (uint8_t k = 0; k < 2; k++) {
			if (__builtin_add_overflow(sum[k], (int16_t)d[k], &sum[k]))
				wide = 1;
			if (sum[k] < lo[k])
				lo[k] = sum[k];
			if (sum[k] > hi[k])
				hi[k] = sum[k];
		}
	}
	for (uint8_t k = 0; k < 2; k++) {
		cmd->g6_lo[k] = lo[k];
		cmd->g6_hi[k] = hi[k];
	}
	if (run_n) {
		uint16_t c = item_cps(run_p, run_n);
		cps = c < cps ? c : cps;
	}
	cmd->g6_cps = wide ? 0 : cps;
	return FB_OK;
}

/* Whether the command at s[i] (after blanks) is G7: the index past its code,
 * else 0.  A G7's code may end at its data's ':' (not only where other numbers
 * end). */
static uint8_t g7_code_end(const char *s, uint8_t i, uint8_t end)
{
	i = skip_ws(s, i, end);
	if (i >= end || upper(s[i]) != 'G')
		return 0;
	uint32_t code = 0;
	uint8_t j = (uint8_t)(i + 1u);
	while (j < end && is_digit(s[j]) && code < 1000u)
		code = code * 10u + (uint32_t)(s[j++] - '0');
	return (code == 7u && j > i + 1u && (j >= end || !is_digit(s[j]))) ? j : 0;
}

static uint8_t check_ranges(proto_cmd_t *cmd)
{
	if ((cmd->has & PROTO_W_A) && (cmd->a > CFG_POS_LIMIT || cmd->a < -CFG_POS_LIMIT))
		return FB_ERR_OUT_OF_RANGE;
	if ((cmd->has & PROTO_W_B) && (cmd->b > CFG_POS_LIMIT || cmd->b < -CFG_POS_LIMIT))
		return FB_ERR_OUT_OF_RANGE;
	if (cmd->kind == PROTO_CMD_M280) {
		/* S is a servo pulse here, not a laser power */
		if ((cmd->has & PROTO_W_S) && (cmd->s < CFG_SERVO_MIN_US || cmd->s > CFG_SERVO_MAX_US))
			return FB_ERR_OUT_OF_RANGE;
		if ((cmd->has & PROTO_W_R) && (cmd->r < 0 || cmd->r > CFG_PEN_MS_MAX))
			return FB_ERR_OUT_OF_RANGE;
		if ((cmd->has & PROTO_W_D) && (cmd->d < 0 || cmd->d > CFG_PEN_MS_MAX))
			return FB_ERR_OUT_OF_RANGE;
		if (!(cmd->has & PROTO_W_S))
			return FB_ERR_MISSING_WORD;
	} else if ((cmd->has & PROTO_W_S) && (cmd->s < 0 || cmd->s > 255)) {
		return FB_ERR_OUT_OF_RANGE;
	}
	if ((cmd->has & PROTO_W_P) && (cmd->p < CFG_P_MIN_US || cmd->p > CFG_P_MAX_US))
		return FB_ERR_OUT_OF_RANGE;
	if ((cmd->kind == PROTO_CMD_G1 || cmd->kind == PROTO_CMD_G6) && !(cmd->has & PROTO_W_P))
		return FB_ERR_MISSING_WORD;
	if (cmd->kind == PROTO_CMD_G92 && !(cmd->has & (PROTO_W_A | PROTO_W_B)))
		return FB_ERR_MISSING_WORD;
	return FB_OK;
}

/* Parse the command part of a line: s[i..end) with the checksum removed.  A
 * G7 is its code, blanks, ':' and binary data to the end (fb_g7.c): only its
 * code is text. */
static uint8_t parse_body(char *s, uint8_t i, uint8_t end, proto_cmd_t *cmd)
{
	uint8_t g7 = g7_code_end(s, i, end);
	if (g7) {
		cmd->kind = PROTO_CMD_G7;
		uint8_t k = skip_ws(s, g7, end);
		if (k >= end || s[k] != ':')
			return FB_ERR_MISSING_WORD;  /* no data: a G7 has at least one segment */
		return proto_g7_parse(s, (uint8_t)(k + 1u), end, cmd);
	}
	/* one walk: every byte printable (or a tab), and the comment's ';' (the
	 * body ends there); the two index loops it replaces cost ~10 cycles a
	 * byte more (python benchmarks/segcost.py) */
	uint8_t comment = 0;
	for (const char *k = s + i, *e = s + end; k < e; k++) {
		uint8_t c = (uint8_t)*k;
		if ((uint8_t)(c - 0x20u) > 0x5eu && c != '\t')
			return FB_ERR_INVALID_CHAR;
		if (c == ';' && !comment) {
			comment = 1;
			end = (uint8_t)(k - s);
		}
	}
	i = skip_ws(s, i, end);
	if (i >= end) {
		cmd->kind = PROTO_CMD_NONE;
		return FB_OK;
	}
	char c = upper(s[i]);
	if (c == '$')
		return parse_dollar(s, (uint8_t)(i + 1), end, cmd);
	if (c != 'G' && c != 'M')
		return FB_ERR_UNKNOWN_COMMAND;
	i++;
	uint32_t code = 0;
	uint8_t st = parse_uint(s, &i, end, 65535u, &code);
	if (st != FB_OK)
		return st == FB_ERR_OUT_OF_RANGE ? FB_ERR_UNKNOWN_COMMAND : st;
	cmd->kind = command_kind(c, code);
	if (cmd->kind == PROTO_CMD_NONE)
		return FB_ERR_UNKNOWN_COMMAND;

	uint8_t allowed = allowed_words(cmd->kind);
	for (;;) {
		i = skip_ws(s, i, end);
		if (i >= end)
			break;
		char w = upper(s[i]);
		/* a G6's items start at a sign, or at a second P */
		if (cmd->kind == PROTO_CMD_G6 && (w == '+' || w == '-' || (w == 'P' && (cmd->has & PROTO_W_P)))) {
			st = g6_items(s, i, end, cmd);
			if (st != FB_OK)
				return st;
			break;
		}
		uint8_t bit;
		int32_t *dst;
		switch (w) {
		case 'A': bit = PROTO_W_A; dst = &cmd->a; break;
		case 'B': bit = PROTO_W_B; dst = &cmd->b; break;
		case 'P': bit = PROTO_W_P; dst = &cmd->p; break;
		case 'S': bit = PROTO_W_S; dst = &cmd->s; break;
		case 'R': bit = PROTO_W_R; dst = &cmd->r; break;
		case 'D': bit = PROTO_W_D; dst = &cmd->d; break;
		default: return FB_ERR_BAD_WORD;
		}
		if (!(allowed & bit) || (cmd->has & bit))
			return FB_ERR_BAD_WORD;
		i++;
		st = parse_int(s, &i, end, dst);
		if (st != FB_OK)
			return st;
		cmd->has |= bit;
	}
	return check_ranges(cmd);
}

/*
 * Whether a line without N is a numbered line that lost its "N" and its '*'
 * to line noise (docs/protocol.md 5.2, step 5): it starts with a digit (the
 * line number's, once the N is gone), or it has no '*' and ends with
 * "<digit>/<digits>" and blanks (its checksum field, once the '*' is gone).
 * No valid line does either: a command starts with G, M or $, and '/' occurs
 * only in comments.  Without this the first numbered line, before numbered
 * mode begins, could lose both and be accepted unnumbered (as error:4, or
 * executed when a ';' replaced the N), which 5.1 promises never happens.
 */
static uint8_t lost_number(const char *s, uint8_t i, uint8_t end, uint8_t len, uint8_t has_star)
{
	if (i < end && is_digit(s[i]))
		return 1;
	if (has_star)
		return 0;
	uint8_t j = len;
	while (j > 0 && is_ws(s[j - 1]))
		j--;
	uint8_t last = j;
	while (j > 0 && is_digit(s[j - 1]))
		j--;
	return j < last && j >= 2 && s[j - 1] == '/' && is_digit(s[j - 2]);
}

uint8_t proto_parse_line(proto_lines_t *lines, char *line, uint8_t len, proto_cmd_t *cmd)
{
	memset(cmd, 0, sizeof(*cmd));
	uint8_t end = len;
	uint8_t has_star = 0;
	for (uint8_t k = 0; k < len; k++) {
		if (line[k] == '*') {
			end = k;
			has_star = 1;
		}
	}
	if (has_star && !field_ok(line, end, len))
		return FB_ERR_CHECKSUM;

	uint8_t i = skip_ws(line, 0, end);
	if (i < end && upper(line[i]) == 'N') {
		if (!has_star)
			return FB_ERR_NO_CHECKSUM;
		i++;
		uint32_t n = 0;
		uint8_t st = parse_uint(line, &i, end, 0xffffffffUL, &n);
		if (st != FB_OK)
			return FB_ERR_BAD_NUMBER;
		cmd->has_n = 1;
		cmd->n = n;
	} else if (lost_number(line, i, end, len, has_star)) {
		return FB_ERR_NO_CHECKSUM;
	}

	uint8_t st = parse_body(line, i, end, cmd);
	/* a G6 uses one line number per segment; a line refused by its parse
	 * error (held back, so accepted) uses one */
	if (st != FB_OK)
		cmd->g6_count = 0;
	if (st == FB_OK && cmd->kind == PROTO_CMD_M110) {
		lines->last = cmd->has_n ? cmd->n : 0;
		lines->numbered = cmd->has_n;
		return FB_OK;
	}
	if (cmd->has_n) {
		if (cmd->n != lines->last + 1u)
			return FB_ERR_LINE_NUMBER;
		lines->last = cmd->n + cmd->g6_count;
		lines->numbered = 1;
	} else {
		/* strict framing: a numbered host's line that lost its N and its
		 * checksum must not run as an unnumbered one */
		if (lines->numbered)
			return FB_ERR_NO_CHECKSUM;
		lines->last += 1u + cmd->g6_count;
	}
	return st;
}
