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

enum fb_cmd_kind {
	CMD_NONE = 0,   /* empty line or comment only */
	CMD_G1,         /* segment: A B P [S] */
	CMD_G90,        /* absolute A/B */
	CMD_G91,        /* relative A/B */
	CMD_G92,        /* set position: A and/or B */
	CMD_M3,         /* laser enable [S] */
	CMD_M5,         /* laser disable */
	CMD_M17,        /* motors on */
	CMD_M18,        /* motors off */
	CMD_M110,       /* set line number */
	CMD_INFO,       /* $I banner */
	CMD_LIST,       /* $$ list settings */
	CMD_HOME,       /* $H */
	CMD_UNLOCK,     /* $X */
	CMD_SET,        /* $<n>=<v> */
	CMD_M280,       /* pen servo: S<us> [R<ms>] [D<ms>] (queued) */
	CMD_G6,         /* several segments: a G1 head, then relative +a+b [P] items */
	CMD_BAUD        /* $B=<baud>: the link's rate after this line's ok */
};
/* How many command kinds there are (keep CMD_BAUD last, or move this): the
 * fuzz target's oracle refuses any other kind. */
#define CMD_KINDS (CMD_BAUD + 1)

/* Word presence bits in fb_cmd_t.has */
#define W_A 0x01u
#define W_B 0x02u
#define W_P 0x04u
#define W_S 0x08u
#define W_R 0x10u
#define W_D 0x20u

typedef struct {
	uint8_t kind;       /* enum fb_cmd_kind */
	uint8_t has;        /* W_* bits */
	uint8_t has_n;      /* the line started with N<n> */
	uint8_t setting;    /* CMD_SET: setting number */
	uint32_t n;         /* line number when has_n */
	int32_t a, b, p, s; /* word values */
	int32_t r, d;       /* M280: move and settle time, ms */
	int32_t value;      /* CMD_SET: value */
	uint8_t g6_count;   /* CMD_G6: segments after the head (the line uses
			     * 1 + g6_count line numbers) */
	uint8_t g6_at;      /* CMD_G6: index of its first item in the line */
	uint8_t g6_end;     /* CMD_G6: end of its items (the '*', ';' or line end) */
} fb_cmd_t;

/* Line-number state shared by consecutive lines. */
typedef struct {
	uint32_t last;      /* number of the last accepted line */
	uint8_t numbered;   /* strict framing: a numbered line was accepted since
			     * the last reset or unnumbered M110, so every line
			     * must be numbered (else FB_ERR_NO_CHECKSUM) */
} fb_lines_t;

/* CRC-16/CCITT-FALSE: polynomial 0x1021, init 0xFFFF, no reflection, no
 * final xor; "123456789" gives 0x29B1.  The line checksum of protocol 2. */
uint16_t fb_crc16(const char *s, uint8_t len);

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
uint8_t fb_parse_line(fb_lines_t *lines, const char *line, uint8_t len, fb_cmd_t *cmd);

/*
 * The next segment of a G6 line already checked by fb_parse_line: from
 * line[*at] up to end, an optional P<us> (the new duration, into *p) and the
 * relative move "<+|-><a><+|-><b>" (into d).  Advances *at past them.
 * Returns 0 at the end of the items (or on a malformed item, which
 * fb_parse_line has refused before), else 1.
 */
uint8_t fb_g6_next(const char *line, uint8_t *at, uint8_t end, int32_t *p, int32_t d[2]);

/* True when a reply code asks the host to resend. */
static inline uint8_t fb_is_resend(uint8_t code)
{
	return code == FB_ERR_CHECKSUM || code == FB_ERR_LINE_NUMBER ||
	       code == FB_ERR_NO_CHECKSUM;
}

#endif
