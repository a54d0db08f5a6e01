/*
 * fb_g7.c - parsing a G7 raster line's binary data (docs/protocol.md 6.4).
 *
 *   N<n> G7:<data>*<crc>/<len>
 *   data   = head, P mask, items, powers, every byte escaped (PROTO_PX_ESC)
 *   head   = H: bits 0-4 segments - 1, bit 5 U follows, bit 6 T follows
 *            [U varint] [T varint]
 *   P mask = ceil(segments / 8) bytes: bit i set = segment i carries its P
 *   item   = [P varint] da zigzag-varint db zigzag-varint
 *   powers = the rest, one byte a pixel
 *
 * Varints are LEB128 (7 bits a byte, low first, bit 7 = more), at most 5
 * bytes and 32 bits; zigzag maps 0, -1, 1, -2 ... to 0, 1, 2, 3 ....  Binary
 * where text would cost the most: a G7 line is mostly its pixels, and a
 * segment's P, A and B as text ("P11197-91-118") took 13 bytes against 6.
 * The line's framing is as for every line: the checksum field covers the
 * whole body, escapes included.
 *
 * Pure and portable, like fb_proto.c: no I/O, no hardware.
 */
#include "fb_proto.h"
#include "config.h"
#include "status.h"

uint8_t proto_px_escaped(uint8_t c)
{
	switch (c) {
	case '\n': case '\r': case 0x18: case '!': case '*': case '?': case '~':
	case PROTO_PX_ESC:
		return 1;
	default:
		return 0;
	}
}

uint8_t proto_rd_byte(proto_rd_t *r, uint8_t *b)
{
	if (r->at >= r->end)
		return 0;
	uint8_t c = (uint8_t)r->s[r->at++];
	if (c == PROTO_PX_ESC) {
		if (r->at >= r->end)
			return 0;
		c = (uint8_t)((uint8_t)r->s[r->at++] ^ PROTO_PX_XOR);
		if (!proto_px_escaped(c))
			return 0;
	} else if (proto_px_escaped(c)) {
		return 0;
	}
	*b = c;
	return 1;
}

/* An unsigned LEB128 varint of at most 5 bytes and 32 bits. */
static uint8_t rd_varint(proto_rd_t *r, uint32_t *v)
{
	uint32_t x = 0;
	for (uint8_t k = 0; k < 5; k++) {
		uint8_t b;
		if (!proto_rd_byte(r, &b))
			return 0;
		if (k == 4 && b > 0x0fu)
			return 0;  /* past 32 bits */
		x |= (uint32_t)(b & 0x7fu) << (7u * k);
		if (!(b & 0x80u)) {
			*v = x;
			return 1;
		}
	}
	return 0;
}

static int32_t unzigzag(uint32_t z)
{
	return (int32_t)(z >> 1) ^ -(int32_t)(z & 1u);
}

/* One item: [P] da db; FB_OK, or the error of a malformed or out-of-range one. */
static uint8_t rd_item(proto_rd_t *r, uint8_t has_p, int32_t *p, int32_t d[2])
{
	uint32_t v;
	if (has_p) {
		if (!rd_varint(r, &v))
			return FB_ERR_BAD_NUMBER;
		if (v < CFG_P_MIN_US || v > CFG_P_MAX_US)
			return FB_ERR_OUT_OF_RANGE;
		*p = (int32_t)v;
	}
	for (uint8_t k = 0; k < 2; k++) {
		if (!rd_varint(r, &v))
			return FB_ERR_BAD_NUMBER;
		int32_t x = unzigzag(v);
		if (x > CFG_POS_LIMIT || x < -CFG_POS_LIMIT)
			return FB_ERR_OUT_OF_RANGE;
		d[k] = x;
	}
	return FB_OK;
}

uint8_t proto_g7_next(const char *line, uint8_t *at, uint8_t end, uint8_t has_p, int32_t *p,
		      int32_t d[2])
{
	proto_rd_t r = { line, *at, end };
	if (rd_item(&r, has_p, p, d) != FB_OK)
		return 0;
	*at = r.at;
	return 1;
}

uint8_t proto_g7_parse(const char *s, uint8_t at, uint8_t end, proto_cmd_t *cmd)
{
	proto_rd_t r = { s, at, end };
	uint8_t h, b;
	uint32_t v;
	if (!proto_rd_byte(&r, &h) || (h & 0x80u))
		return FB_ERR_BAD_WORD;
	uint8_t count = (uint8_t)((h & 0x1fu) + 1u);
	if (h & 0x20u) {
		if (!rd_varint(&r, &v))
			return FB_ERR_BAD_NUMBER;
		if (v > PROTO_PX_U_MAX)
			return FB_ERR_OUT_OF_RANGE;
		cmd->r = (int32_t)v;
		cmd->has |= PROTO_W_U;
	}
	if (h & 0x40u) {
		if (!rd_varint(&r, &v))
			return FB_ERR_BAD_NUMBER;
		if (v > PROTO_PX_T_MAX)
			return FB_ERR_OUT_OF_RANGE;
		cmd->d = (int32_t)v;
		cmd->has |= PROTO_W_T;
	}
	for (uint8_t k = 0; k < (uint8_t)((count + 7u) / 8u); k++) {
		if (!proto_rd_byte(&r, &b))
			return FB_ERR_BAD_WORD;
		cmd->g7_pmask |= (uint32_t)b << (8u * k);
	}
	if (count < 32u && (cmd->g7_pmask >> count))
		return FB_ERR_BAD_WORD;  /* a P bit of a segment the line does not have */
	cmd->g6_at = r.at;
	int32_t p = 0, d[2];
	for (uint8_t k = 0; k < count; k++) {
		uint8_t st = rd_item(&r, (uint8_t)((cmd->g7_pmask >> k) & 1u), &p, d);
		if (st != FB_OK)
			return st;
	}
	cmd->g6_end = end;
	cmd->g6_count = (uint8_t)(count - 1u);
	cmd->px_at = r.at;
	cmd->px_end = end;
	while (r.at < end) {
		if (!proto_rd_byte(&r, &b))
			return FB_ERR_BAD_WORD;
		cmd->px_n++;
	}
	return FB_OK;
}
