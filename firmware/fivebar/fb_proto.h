/*
 * fb_proto.h - line framing (line number, checksum) and command parsing.
 *
 * Pure functions over a line buffer: no I/O, no hardware, so the host unit
 * tests and the fuzz target run them directly.  See docs/protocol.md.
 */
#ifndef FB_PROTO_H
#define FB_PROTO_H

#include <stdint.h>
#include "status.h"

enum proto_cmd_kind {
	PROTO_CMD_NONE = 0,   /* empty line or comment only */
	PROTO_CMD_G1,         /* segment: A B P [S] */
	PROTO_CMD_G90,        /* absolute A/B */
	PROTO_CMD_G91,        /* relative A/B */
	PROTO_CMD_G92,        /* set position: A and/or B */
	PROTO_CMD_M3,         /* laser enable [S] */
	PROTO_CMD_M5,         /* laser disable */
	PROTO_CMD_M17,        /* motors on */
	PROTO_CMD_M18,        /* motors off */
	PROTO_CMD_M110,       /* set line number */
	PROTO_CMD_INFO,       /* $I banner */
	PROTO_CMD_LIST,       /* $$ list settings */
	PROTO_CMD_HOME,       /* $H */
	PROTO_CMD_UNLOCK,     /* $X */
	PROTO_CMD_SET,        /* $<n>=<v> */
	PROTO_CMD_M280,       /* pen servo: S<us> [R<ms>] [D<ms>] (queued) */
	PROTO_CMD_G6,         /* several segments: a G1 head, then relative +a+b [P] items */
	PROTO_CMD_BAUD,       /* $B=<baud>: the link's rate after this line's ok */
	PROTO_CMD_G7          /* raster: binary segments and pixels after ':' (protocol 4, fb_g7.c) */
};
/* How many command kinds there are (keep PROTO_CMD_G7 last, or move this): the
 * fuzz target's oracle refuses any other kind. */
#define PROTO_CMD_KINDS (PROTO_CMD_G7 + 1)

/* Word presence bits in proto_cmd_t.has */
#define PROTO_W_A 0x01u
#define PROTO_W_B 0x02u
#define PROTO_W_P 0x04u
#define PROTO_W_S 0x08u
#define PROTO_W_R 0x10u
#define PROTO_W_D 0x20u
#define PROTO_W_U 0x40u
#define PROTO_W_T 0x80u

/* G7 data (docs/protocol.md 6.4, fb_g7.c): bytes, except those a line cannot
 * carry (newline, CR, the real-time bytes ! ? ~ Ctrl-X, the checksum's '*') and
 * the escape itself, each sent as PROTO_PX_ESC then the byte XOR PROTO_PX_XOR. */
#define PROTO_PX_ESC 0x7du
#define PROTO_PX_XOR 0x40u
/* Longest G7 pixel period T and first-change offset U, cycles (1 s, 100 s). */
#define PROTO_PX_T_MAX 16000000L
#define PROTO_PX_U_MAX 1600000000L

typedef struct {
	uint8_t kind;       /* enum proto_cmd_kind */
	uint8_t has;        /* W_* bits */
	uint8_t has_n;      /* the line started with N<n> */
	uint8_t setting;    /* PROTO_CMD_SET: setting number */
	uint32_t n;         /* line number when has_n */
	int32_t a, b, p, s; /* word values */
	uint8_t g6_count;   /* PROTO_CMD_G6: segments after the head (the line uses
			     * 1 + g6_count line numbers) */
	uint8_t g6_at;      /* PROTO_CMD_G6: index of its first item in the line */
	uint8_t g6_end;     /* PROTO_CMD_G6: end of its items (the '*', ';' or line end) */
	union {
		struct {
			int32_t r, d;    /* M280: move and settle time, ms; G7: U and T, cycles */
			int32_t value;   /* PROTO_CMD_SET: value */
			/* PROTO_CMD_G7 (fb_g7.c): its items from line[g6_at] (g6_count =
			 * items - 1: the line uses 1 + g6_count numbers), bit i of
			 * g7_pmask set when item i carries its P, its powers
			 * line[px_at..px_end) (escaped), px_n of them; U in r and T in d
			 * (PROTO_W_U, PROTO_W_T in has) */
			uint32_t g7_pmask;
			uint8_t px_at, px_end, px_n;
		};
		/* PROTO_CMD_G6: what its items add up to, read by the parse so that
		 * the checks need not read them again (fb_exec.c g6_check): the
		 * lowest and highest running sum of the items' moves per motor (the
		 * targets after the head's, relative to it; 0 included), and
		 * g6_cps, the least over the items of floor(P * F_CPU/1e6 / n), n
		 * the larger of an item's two step counts (65535 at most, and for
		 * an item that moves no motor; 0 when the summary does not bound
		 * the line, an item moving a motor more than 32767 steps or a sum
		 * leaving the int16_t range: such a line is checked item by item).
		 * An item's step rate passes mo_prepare's test floor(C / n) >=
		 * min_interval exactly when n <= floor(C / min_interval), so g6_cps
		 * >= min_interval passes every item. */
		struct {
			int16_t g6_lo[2], g6_hi[2];
			uint16_t g6_cps;
		};
	};
} proto_cmd_t;

/* Line-number state shared by consecutive lines. */
typedef struct {
	uint32_t last;      /* number of the last accepted line */
	uint8_t numbered;   /* strict framing: a numbered line was accepted since
			     * the last reset or unnumbered M110, so every line
			     * must be numbered (else FB_ERR_NO_CHECKSUM) */
} proto_lines_t;

/* CRC-16/CCITT-FALSE: polynomial 0x1021, init 0xFFFF, no reflection, no
 * final xor; "123456789" gives 0x29B1.  The line checksum of protocol 2. */
uint16_t proto_crc16(const char *s, uint8_t len);

/*
 * Frame and parse one received line (without its newline; at most 255 bytes).
 * A '*' starts the checksum field "<crc16>/<len>" (docs/protocol.md 5.1): the
 * CRC-16 and the length of every byte before the last '*'; a malformed or
 * wrong field is FB_ERR_CHECKSUM.
 * Returns FB_OK or an FB_ERR_* code; on FB_ERR_CHECKSUM, FB_ERR_LINE_NUMBER and
 * FB_ERR_NO_CHECKSUM the line was not accepted and the host must resend from
 * lines->last + 1.  Every other outcome accepts the line and advances
 * lines->last (to N, or by one when the line has no N).
 *
 * Strict framing: once a numbered line is accepted (lines->numbered), a line
 * without N is refused with FB_ERR_NO_CHECKSUM, so a numbered line that lost
 * both its "N<n> " and its "*<crc>/<len>" to line noise is never executed.
 * Only an unnumbered M110 (which sets last to 0 and ends strict framing) is
 * accepted then; a numbered M110 keeps it.  In either mode a line without N
 * that starts with a digit, or that has no '*' and ends with
 * "<digit>/<digits>" (and blanks), is refused the same way: a numbered line
 * that lost both (the first one, before strict framing begins, included).
 */
uint8_t proto_parse_line(proto_lines_t *lines, char *line, uint8_t len, proto_cmd_t *cmd);

/*
 * A G6 line's items as proto_parse_line leaves them: rewritten in place, as
 * it reads them, into records of a few bytes from line[g6_at] to line[g6_end]
 * (proto_cmd_t), so that the queueing reads each segment in a few cycles
 * instead of parsing its text again (python benchmarks/segcost.py).  A record
 * is a tag byte, then the two moves little-endian in 1, 2 or 4 bytes (the
 * tag's bits 0-1 and 2-3: PROTO_G6_I8, _I16, _I32), then the item's P (4
 * bytes) when bit PROTO_G6_HAS_P is set.  A record is shorter than the text
 * it replaces (a move of 1, 2 or 4 bytes is at least 2, 4 or 6 characters, a
 * P at least 4), so it never overtakes the text still to be read.
 */
#define PROTO_G6_I8 0u
#define PROTO_G6_I16 1u
#define PROTO_G6_I32 2u
#define PROTO_G6_HAS_P 0x10u

/*
 * The next segment of a G6 line proto_parse_line accepted: the record at
 * line[*at] (before end): its P, when it has one, into *p (the duration of
 * this item and the later ones), its relative move into d.  Advances *at
 * past it.  Returns 0 at the end of the items, else 1.
 */
uint8_t proto_g6_next(const char *line, uint8_t *at, uint8_t end, int32_t *p, int32_t d[2]);

/* Whether byte c must be escaped in G7 data (and may follow the escape, XORed). */
uint8_t proto_px_escaped(uint8_t c);

/* A reader of escaped G7 data line[at..end). */
typedef struct {
	const char *s;
	uint8_t at, end;
} proto_rd_t;
/* The next data byte, unescaped: 1, or 0 at the end or a malformed escape (a
 * byte that must be escaped sent as it is, or an escape of another byte). */
uint8_t proto_rd_byte(proto_rd_t *r, uint8_t *b);
/* Parse a G7's data line[at..end) into cmd (fb_g7.c): FB_OK or an error. */
uint8_t proto_g7_parse(const char *s, uint8_t at, uint8_t end, proto_cmd_t *cmd);
/* The next item of a G7 line already checked by proto_g7_parse, from line[*at]:
 * its P (into *p, when has_p) and move (d).  Advances *at; 0 when malformed. */
uint8_t proto_g7_next(const char *line, uint8_t *at, uint8_t end, uint8_t has_p, int32_t *p,
		      int32_t d[2]);

/* True when a reply code asks the host to resend. */
static inline uint8_t proto_is_resend(uint8_t code)
{
	return code == FB_ERR_CHECKSUM || code == FB_ERR_LINE_NUMBER ||
	       code == FB_ERR_NO_CHECKSUM;
}

#endif
