/*
 * raster_tests.c - host tests of G7 raster scans (fb_raster.c, the G7 parts of
 * fb_proto.c and fb_exec.c, protocol section 6.4) on the fake board.
 *
 * The fake board runs the step and pixel events at their exact cycles, so
 * every pixel change is checked against the time the protocol gives it,
 * computed here from the line alone: the scan starts at its first block's
 * start; change i of a line lands at (start of the line's first segment) +
 * U + i*T, the segments back to back at P*16 cycles each.  Built with ASan
 * and UBSan by `make -C firmware test`.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "board.h"
#include "config.h"
#include "fake_board.h"
#include "fb_main.h"
#include "fb_motion.h"
#include "fb_proto.h"
#include "fb_raster.h"
#include "status.h"

static int failures, checks;

#define CHECK(cond, ...) do { checks++; if (!(cond)) { failures++; \
	printf("FAIL %s:%d: ", __FILE__, __LINE__); printf(__VA_ARGS__); printf("\n"); } } while (0)

/* ---- recording the laser ------------------------------------------------------ */
#define MAX_CHANGES 4096
static struct { uint64_t at; uint8_t p; } changes[MAX_CHANGES];
static size_t nchanges;

static void on_laser(uint8_t p)
{
	if (nchanges < MAX_CHANGES) {
		changes[nchanges].at = fake_now;
		changes[nchanges].p = p;
		nchanges++;
	}
}

/* ---- lines ---------------------------------------------------------------------- */
typedef struct {
	char b[300];
	size_t n;
} line_t;

static void add(line_t *l, const char *s)
{
	size_t k = strlen(s);
	memcpy(l->b + l->n, s, k);
	l->n += k;
}

/* One data byte escaped as the protocol says (PROTO_PX_ESC, XOR PROTO_PX_XOR). */
static void put(line_t *l, uint8_t c)
{
	if (proto_px_escaped(c)) {
		l->b[l->n++] = (char)PROTO_PX_ESC;
		l->b[l->n++] = (char)(c ^ PROTO_PX_XOR);
	} else {
		l->b[l->n++] = (char)c;
	}
}

/* An unsigned LEB128 varint (7 bits a byte, low first). */
static void put_varint(line_t *l, uint32_t v)
{
	do {
		uint8_t b = (uint8_t)(v & 0x7fu);
		v >>= 7;
		put(l, (uint8_t)(b | (v ? 0x80u : 0u)));
	} while (v);
}

static void put_zigzag(line_t *l, int32_t v)
{
	put_varint(l, ((uint32_t)v << 1) ^ (uint32_t)(v >> 31));
}

static void add_pixels(line_t *l, const uint8_t *px, size_t n)
{
	for (size_t i = 0; i < n; i++)
		put(l, px[i]);
}

/* "G7:" and the binary head of `count` segments (U, T when uflag/tflag) and the P mask. */
static void add_head(line_t *l, uint8_t count, int uflag, uint32_t u, int tflag, uint32_t t,
		     uint32_t pmask)
{
	add(l, "G7:");
	put(l, (uint8_t)((count - 1u) | (uflag ? 0x20u : 0u) | (tflag ? 0x40u : 0u)));
	if (uflag)
		put_varint(l, u);
	if (tflag)
		put_varint(l, t);
	for (uint8_t k = 0; k < (count + 7u) / 8u; k++)
		put(l, (uint8_t)(pmask >> (8u * k)));
}

static void add_item(line_t *l, int withp, uint32_t p, int32_t da, int32_t db)
{
	if (withp)
		put_varint(l, p);
	put_zigzag(l, da);
	put_zigzag(l, db);
}

/* The checksum field and the newline. */
static void finish_line(line_t *l)
{
	char f[24];
	snprintf(f, sizeof f, "*%u/%u\n", proto_crc16(l->b, (uint8_t)l->n), (unsigned)l->n);
	add(l, f);
}

static void send_n(const char *s, size_t n)
{
	for (size_t i = 0; i < n; i++)
		fb_rx_isr((uint8_t)s[i]);
}

static void send(const char *s) { send_n(s, strlen(s)); }

/* Main loop passes with the timers running `slice` cycles between them; the
 * millisecond clock follows (the queue's start delay, the laser watchdog). */
static uint64_t clock_cycles;

static void run_slices(int passes, uint64_t slice)
{
	for (int i = 0; i < passes; i++) {
		fb_poll();
		fake_run(slice);
		clock_cycles += slice;
		fake_ms = (uint32_t)(clock_cycles / 16000u);
	}
}

static const char *take(void) { return fake_take_tx(); }

static void boot(void)
{
	int32_t zero[2] = { 0, 0 };
	clock_cycles = 0;
	fake_reset();
	mo_set_pos(zero);
	fb_setup();
	/* a Ctrl-X drops what earlier tests left in the receive ring (a real boot
	 * starts with it empty; here the ring's statics live on) */
	send("\x18");
	run_slices(2, 0);
	take();
	fake_laser_hook = on_laser;
	nchanges = 0;
}

/* ---- parsing ----------------------------------------------------------------------- */
static uint8_t parse_l(const line_t *l, proto_cmd_t *c)
{
	proto_lines_t ln = { 0, 0 };
	char b[sizeof l->b];
	memcpy(b, l->b, l->n);  /* proto_parse_line may rewrite a line (a G6's items) */
	return proto_parse_line(&ln, b, (uint8_t)l->n, c);
}

static void test_parse(void)
{
	proto_cmd_t c;
	line_t l = { .n = 0 };
	/* one segment with its P, no pixels */
	add_head(&l, 1, 0, 0, 0, 0, 1);
	add_item(&l, 1, 1000, 10, -5);
	CHECK(parse_l(&l, &c) == FB_OK && c.kind == PROTO_CMD_G7 && c.g6_count == 0 && c.px_n == 0,
	      "one segment");
	/* three segments, P on the first, U and T, pixels: three line numbers */
	l.n = 0;
	add_head(&l, 3, 1, 5, 1, 400, 1);
	add_item(&l, 1, 1000, 1, 1);
	add_item(&l, 0, 0, 2, -2);
	add_item(&l, 0, 0, -3, 0);
	uint8_t px[100];
	for (int i = 0; i < 100; i++)
		px[i] = (uint8_t)(i * 37 + 5);
	uint8_t must[] = { '\n', '\r', 0x18, '!', '*', '?', '~', PROTO_PX_ESC };
	for (size_t i = 0; i < sizeof must; i++)
		px[i] = must[i];
	add_pixels(&l, px, 100);
	size_t body = l.n;
	proto_lines_t ln = { 0, 0 };
	CHECK(proto_parse_line(&ln, l.b, (uint8_t)l.n, &c) == FB_OK && c.g6_count == 2 &&
	      c.px_n == 100 && c.r == 5 && c.d == 400 && ln.last == 3, "three segments, 100 pixels");
	line_t f = l;
	finish_line(&f);
	CHECK(body > 99, "a body of three-digit length: %zu", body);
	ln.last = 0;
	CHECK(proto_parse_line(&ln, f.b, (uint8_t)(f.n - 1), &c) == FB_OK, "framed, 3-digit length");
	for (size_t i = 0; i + 1 < f.n; i++)
		CHECK(f.b[i] != '\n' && f.b[i] != '!' && f.b[i] != '?' && f.b[i] != '~' &&
		      f.b[i] != 0x18 && (f.b[i] != '*' || i >= body), "no reserved byte in the body");
	/* every single-byte drop of the framed line is refused with a resend */
	for (size_t k = 0; k + 1 < f.n; k++) {
		char d[300];
		memcpy(d, f.b, k);
		memcpy(d + k, f.b + k + 1, f.n - 1 - k - 1);
		ln.last = 0;
		ln.numbered = 1;
		uint8_t st = proto_parse_line(&ln, d, (uint8_t)(f.n - 2), &c);
		CHECK(proto_is_resend(st), "drop at %zu: status %u", k, st);
	}
	/* malformed: no data, no head, a cut item, out of ranges, a stray P bit, a bad escape */
	struct { const char *what; uint8_t want; } bad[10];
	line_t b[10];
	int nb = 0;
#define BAD(w, code) do { bad[nb].what = (w); bad[nb].want = (code); b[nb].n = 0; } while (0)
	BAD("no ':'", FB_ERR_MISSING_WORD); add(&b[nb], "G7"); nb++;
	BAD("no head", FB_ERR_BAD_WORD); add(&b[nb], "G7:"); nb++;
	BAD("a cut item", FB_ERR_BAD_NUMBER); add_head(&b[nb], 1, 0, 0, 0, 0, 1); put_varint(&b[nb], 1000); nb++;
	BAD("P 99", FB_ERR_OUT_OF_RANGE); add_head(&b[nb], 1, 0, 0, 0, 0, 1); add_item(&b[nb], 1, 99, 1, 1); nb++;
	BAD("T too big", FB_ERR_OUT_OF_RANGE); add_head(&b[nb], 1, 0, 0, 1, PROTO_PX_T_MAX + 1, 0); add_item(&b[nb], 0, 0, 1, 1); nb++;
	BAD("move too big", FB_ERR_OUT_OF_RANGE); add_head(&b[nb], 1, 0, 0, 0, 0, 0); add_item(&b[nb], 0, 0, CFG_POS_LIMIT + 1, 1); nb++;
	BAD("P bit past the segments", FB_ERR_BAD_WORD); add_head(&b[nb], 1, 0, 0, 0, 0, 3); add_item(&b[nb], 1, 1000, 1, 1); nb++;
	BAD("a raw real-time byte in data", FB_ERR_BAD_WORD); add_head(&b[nb], 1, 0, 0, 0, 0, 0); add_item(&b[nb], 0, 0, 1, 1); add(&b[nb], "a~"); nb++;
	BAD("escape of a plain byte", FB_ERR_BAD_WORD); add_head(&b[nb], 1, 0, 0, 0, 0, 0); add_item(&b[nb], 0, 0, 1, 1); add(&b[nb], "\x7dz"); nb++;
	BAD("six-byte varint", FB_ERR_BAD_NUMBER); add_head(&b[nb], 1, 0, 0, 0, 0, 0); add(&b[nb], "\x80\x80\x80\x80\x80\x01\x02"); nb++;
#undef BAD
	for (int k = 0; k < nb; k++) {
		uint8_t st = parse_l(&b[k], &c);
		CHECK(st == bad[k].want, "%s: status %u, want %u", bad[k].what, st, bad[k].want);
	}
}

/* ---- a scan on the fake board ----------------------------------------------------- */

/* One G7 line: items (da, db) of p_us each, the run's U, T and pixels. */
typedef struct {
	int32_t d[4][2];
	uint8_t items;
	uint32_t p_us;
	uint32_t u, t;
	const uint8_t *px;
	uint8_t n;
} g7_t;

static void g7_line(line_t *l, uint32_t number, const g7_t *g)
{
	(void)number;  /* unnumbered: the field alone */
	l->n = 0;
	add_head(l, g->items, 1, g->u, 1, g->t, 1);
	for (uint8_t i = 0; i < g->items; i++)
		add_item(l, i == 0, g->p_us, g->d[i][0], g->d[i][1]);
	add_pixels(l, g->px, g->n);
	finish_line(l);
}

/* Whether the recorded changes after index from are exactly the expected ones
 * (times and powers), the first change of the run at run_start. */
static size_t check_run(size_t from, uint64_t run_start, const g7_t *g)
{
	size_t k = from;
	for (uint8_t i = 0; i < g->n; i++) {
		uint64_t want = run_start + g->u + (uint64_t)i * g->t;
		/* an unchanged power is written again: the interrupt does not compare */
		CHECK(k < nchanges, "change %u of the run recorded", i);
		if (k >= nchanges)
			return k;
		CHECK(changes[k].at == want && changes[k].p == g->px[i],
		      "change %u at %llu power %u, want %llu power %u", i,
		      (unsigned long long)changes[k].at, changes[k].p, (unsigned long long)want, g->px[i]);
		k++;
	}
	return k;
}

static uint8_t pix[8][120];

static void fill(int seed)
{
	for (int j = 0; j < 8; j++)
		for (int i = 0; i < 120; i++)
			pix[j][i] = (uint8_t)((i * 31 + j * 17 + seed) % 256);
}

/* Three lines of one scan, a G1 after it (its end), while held: then resume
 * and check every change against the line arithmetic. */
static void test_scan_timing(void)
{
	boot();
	fill(3);
	send("$0=60000\n$5=0\nM3 S0\nG90\n");
	run_slices(10, 0);
	CHECK(strcmp(take(), "ok\r\nok\r\nok\r\nok\r\n") == 0, "setup");
	send("!");  /* held: everything queues, nothing runs */
	run_slices(1, 0);
	nchanges = 0;
	g7_t g[4] = {
		/* the scan's first line: a ramp piece without pixels */
		{ .d = { { 20, -10 } }, .items = 1, .p_us = 2000, .u = 0, .t = 0, .px = 0, .n = 0 },
		{ .d = { { 100, -50 }, { 90, -60 } }, .items = 2, .p_us = 8000, .u = 300, .t = 2500,
		  .px = pix[0], .n = 70 },
		{ .d = { { 100, -50 } }, .items = 1, .p_us = 7000, .u = 17, .t = 1111, .px = pix[1], .n = 70 },
		{ .d = { { 3, 4 }, { 5, 6 } }, .items = 2, .p_us = 1000, .u = 5, .t = 400, .px = pix[2], .n = 2 },
	};
	pix[2][1] = 0;  /* the run ends the scan at power 0 */
	uint32_t number = 1;
	line_t l;
	for (int k = 0; k < 4; k++) {
		g7_line(&l, number, &g[k]);
		send_n(l.b, l.n);
		number += g[k].items;
		run_slices(3, 0);
	}
	send("G1 A0 B0 P20000\n");
	run_slices(40, 0);
	CHECK(nchanges == 0, "held: the laser is off (%zu changes)", nchanges);
	/* let the rest of the lines in as the ring frees: resume and run in slices */
	nchanges = 0;
	fb_rx_isr('~');
	uint64_t t0 = fake_now;
	run_slices(4000, 2000);
	const char *out = take();
	CHECK(strcmp(out, "ok\r\nok\r\nok\r\nok\r\nok\r\n") == 0, "five lines accepted: '%s'", out);
	CHECK(!mo_running() && mo_queue_count() == 0, "the job ran to its end");
	/* the scan starts with its first block: find it from the first step */
	CHECK(fake_nsteps > 0, "steps");
	uint64_t start = fake_steps[0].cycle - (2000u * 16u) / (2u * 20u);
	CHECK(start >= t0, "scan start %llu after resume %llu", (unsigned long long)start,
	      (unsigned long long)t0);
	/* changes: the first is the scan start's power 0 (the SCAN block), then the runs */
	size_t k = 0;
	CHECK(nchanges > 0 && changes[0].at == start && changes[0].p == 0,
	      "laser 0 at the scan's start (%llu, %u)", nchanges ? (unsigned long long)changes[0].at : 0ull,
	      nchanges ? changes[0].p : 0);
	k = 1;
	uint64_t line_start = start + 2000u * 16u;
	for (int j = 1; j < 4; j++) {
		k = check_run(k, line_start, &g[j]);
		line_start += (uint64_t)g[j].p_us * 16u * g[j].items;
	}
	/* the G1 after the scan ends it: its power (0) at its start, nothing after */
	/* and the queue's end another 0 */
	CHECK(k + 2 == nchanges && changes[k].at == line_start && changes[k].p == 0,
	      "the scan ends at the G1's start: %zu of %zu changes", k, nchanges);
	CHECK(fake_laser == 0 && !fake_px_on, "laser off, pixel timer off");
}

/* A change outside the line's segments, a period too short, pixels without T. */
static void send_g7(uint8_t count, int uf, uint32_t u, int tf, uint32_t t, uint32_t p,
		    const uint8_t *px, size_t n)
{
	line_t l = { .n = 0 };
	add_head(&l, count, uf, u, tf, t, p ? 1u : 0u);
	for (uint8_t i = 0; i < count; i++)
		add_item(&l, i == 0 && p, p, 1, 1);
	add_pixels(&l, px, n);
	finish_line(&l);
	send_n(l.b, l.n);
}

static void test_refused(void)
{
	boot();
	send("$0=60000\nG90\nM3 S0\n");
	run_slices(6, 0);
	take();
	static const uint8_t px[4] = { 1, 2, 3, 4 };
	static const struct { uint8_t count; uint32_t u, t; size_t n; const char *want; } cases[] = {
		{ 1, 0, 400, 2, "ok\r\n" },
		{ 1, 15600, 400, 2, "error:7\r\n" },   /* 15600 + 400 = C */
		{ 1, 15599, 400, 2, "ok\r\n" },
		{ 1, 0, 399, 2, "error:7\r\n" },
		{ 2, 0, 1000, 4, "ok\r\n" },
		{ 1, 15999, 0, 1, "ok\r\n" },          /* one pixel: no T needed */
		{ 1, 16000, 0, 1, "error:7\r\n" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		send_g7(cases[i].count, 1, cases[i].u, cases[i].n > 1, cases[i].t, 1000, px, cases[i].n);
		run_slices(20, 100000);
		const char *out = take();
		CHECK(strcmp(out, cases[i].want) == 0, "case %zu: got '%s' want '%s'", i, out, cases[i].want);
		send("\x18");
		run_slices(4, 0);
		take();
		send("$0=60000\nG90\nM3 S0\n");
		run_slices(6, 0);
		take();
	}
	/* no P yet after a reset: the first G7 needs one */
	send_g7(1, 0, 0, 0, 0, 0, px, 0);
	run_slices(6, 0);
	CHECK(strcmp(take(), "error:6\r\n") == 0, "G7 without a P");
}

/* M5: the scan runs dark (every change 0); hold and resume mid-scan shift
 * the timeline by the time held; an underrun mid-scan leaves the laser off for
 * the rest of that scan. */
static void test_dark_hold_underrun(void)
{
	boot();
	fill(9);
	send("$0=60000\nG90\nM5\n");
	run_slices(6, 0);
	take();
	line_t l;
	g7_t g = { .d = { { 200, 100 } }, .items = 1, .p_us = 20000, .u = 1000, .t = 2000, .px = pix[0], .n = 70 };
	g7_line(&l, 1, &g);
	send_n(l.b, l.n);
	run_slices(2000, 1000);
	int lit = 0;
	for (size_t i = 0; i < nchanges; i++)
		lit |= changes[i].p != 0;
	CHECK(nchanges > 0 && !lit, "M5: %zu changes, all 0", nchanges);
	take();

	/* hold mid-scan */
	boot();
	send("$0=60000\nG90\nM3 S0\n");
	run_slices(8, 0);
	take();
	g7_line(&l, 1, &g);
	send_n(l.b, l.n);
	for (int i = 0; i < 1000 && !mo_running(); i++)
		run_slices(1, 2000);
	/* run to the 40th change, hold for 123456 cycles, resume */
	CHECK(mo_running(), "the scan runs");
	while (nchanges < 41 && fake_timer_on)
		fake_run(50);
	CHECK(nchanges == 41, "41 changes: %zu", nchanges);
	if (nchanges != 41)
		return;
	fb_rx_isr('!');
	CHECK(fake_laser == 0, "hold: laser off");
	size_t at_hold = nchanges;
	uint8_t power_before = changes[at_hold - 2].p;
	fake_now += 123456;
	fb_rx_isr('~');
	CHECK(fake_laser == power_before, "resume: the pixel's power again (%u, want %u)", fake_laser, power_before);
	run_slices(400, 1000);
	/* the changes after the hold: 123456 later than the timeline before it */
	size_t k = at_hold + 1;  /* the hold's 0 and the resume's power are recorded too */
	int ok = 1;
	uint64_t first = 0;
	for (size_t i = 0; i < nchanges; i++)
		if (changes[i].p == pix[0][0]) {
			first = changes[i].at;
			break;
		}
	for (uint8_t i = 40; i < g.n && k < nchanges; i++, k++) {
		uint64_t want = first + (uint64_t)i * g.t + 123456u;
		if (changes[k].at != want || changes[k].p != pix[0][i])
			ok = 0;
	}
	/* the queue's end: laser 0 (one more change) */
	CHECK(ok && k + 1 == nchanges, "after the hold the changes are %u cycles later (%zu of %zu)", 123456u, k, nchanges);
	take();

	/* underrun: the scan's second line comes after its first ran out */
	boot();
	send("$0=60000\nG90\nM3 S0\n");
	run_slices(8, 0);
	take();
	g7_t a = { .d = { { 50, 20 } }, .items = 1, .p_us = 5000, .u = 100, .t = 700, .px = pix[1], .n = 70 };
	g7_line(&l, 1, &a);
	send_n(l.b, l.n);
	run_slices(300, 2000);  /* the queue starts after 20 ms and runs empty */
	CHECK(!mo_running(), "ran out");
	nchanges = 0;
	/* the next G7 starts a new scan (the machine is idle): it burns */
	g7_line(&l, 2, &a);
	send_n(l.b, l.n);
	run_slices(300, 2000);
	CHECK(nchanges == 2u + a.n, "a new scan after an idle machine: %zu changes", nchanges);
	take();
}

/* A scan's later block that starts from a stop (the queue ran empty between
 * two blocks of one scan): its timeline is lost, so its run is dropped and
 * the laser stays off; the next scan burns again. */
static void test_broken_scan(void)
{
	boot();
	fill(5);
	mo_init();
	nchanges = 0;
	uint8_t dat[8] = { 10, 20, 30, 40, 50, 60, 70, 80 };
	mo_block_t *b = mo_slot();
	mo_prepare(b, 40, 40, 4000, 200);
	b->type = MO_BLK_SCAN;
	b->power = 7;
	b->line = 1;
	px_push(7, 4, 1000, 2000, (const char *)dat, 4, 0);
	mo_push();
	mo_start();
	fake_run(UINT64_MAX / 2);
	CHECK(nchanges == 6 && changes[4].p == 40 && changes[5].p == 0, "the scan burns: %zu changes", nchanges);
	nchanges = 0;
	b = mo_slot();
	mo_prepare(b, 40, 40, 4000, 200);
	b->type = MO_BLK_RASTER;
	b->power = 7;
	b->line = 2;
	px_push(7, 4, 1000, 2000, (const char *)dat + 4, 4, 0);
	mo_push();
	mo_start();
	fake_run(UINT64_MAX / 2);
	int lit = 0;
	for (size_t i = 0; i < nchanges; i++)
		lit |= changes[i].p != 0;
	CHECK(!lit && px_room() == CFG_PX_RING, "a broken scan stays dark, its run dropped (%zu changes)",
	      nchanges);
	nchanges = 0;
	b = mo_slot();
	mo_prepare(b, 40, 40, 4000, 200);
	b->type = MO_BLK_SCAN;
	b->power = 8;
	b->line = 3;
	px_push(8, 4, 1000, 2000, (const char *)dat, 4, 0);
	mo_push();
	mo_start();
	fake_run(UINT64_MAX / 2);
	CHECK(nchanges == 6 && changes[1].p == 10, "the next scan burns: %zu changes", nchanges);
}


/* A hold while the timeline waits for the scan's next record (the last change
 * of the running line is past), and that record arriving during the hold:
 * it is placed on the timeline as it stood when held, nothing changes the
 * laser while held, and after the resume its changes come the time held
 * later than the line arithmetic.  (The boards read "now" and armed the pixel
 * timer as if the timeline ran on through the hold: the AVR's pixel interrupt
 * came back on while held, and the record counted as late.) */
static void test_record_during_hold(void)
{
	boot();
	fill(4);
	send("$0=60000\nG90\nM3 S0\n");
	run_slices(8, 0);
	take();
	line_t l;
	/* line 1: its changes end 301,000 cycles before its segment; line 2's
	 * first change 100 cycles into its own */
	g7_t a = { .d = { { 200, 100 } }, .items = 1, .p_us = 20000, .u = 1000, .t = 2000,
		   .px = pix[0], .n = 10 };
	g7_t b = { .d = { { 200, 100 } }, .items = 1, .p_us = 20000, .u = 100, .t = 2000,
		   .px = pix[1], .n = 10 };
	g7_line(&l, 1, &a);
	send_n(l.b, l.n);
	for (int i = 0; i < 1000 && !mo_running(); i++)
		run_slices(1, 2000);
	CHECK(mo_running(), "the scan runs");
	while (nchanges < 1u + a.n && fake_timer_on)
		fake_run(50);
	CHECK(nchanges == 1u + a.n, "line 1's changes: %zu", nchanges);
	if (nchanges != 1u + a.n)
		return;
	uint64_t start = changes[1].at - a.u;  /* line 1's segment starts */
	/* hold 1,000 cycles before line 1's segment ends */
	fake_run(start + 319000u - fake_now);
	fb_rx_isr('!');
	run_slices(1, 0);
	uint64_t held_at = fake_now;
	size_t at_hold = nchanges;
	fake_now += 100000;
	g7_line(&l, 2, &b);
	send_n(l.b, l.n);
	run_slices(3, 0);
	fake_now += 23456;
	CHECK(nchanges == at_hold && fake_laser == 0, "held: no change (%zu, laser %u)",
	      nchanges - at_hold, fake_laser);
	uint64_t held = fake_now - held_at;
	fb_rx_isr('~');
	run_slices(400, 1000);
	/* past the hold's 0 and the resume's power: line 2's run, by its time */
	uint64_t want0 = start + 320000u + b.u + held;
	size_t k = at_hold;
	while (k < nchanges && changes[k].at < want0)
		k++;
	size_t end = check_run(k, start + 320000u + held, &b);
	CHECK(end + 1 == nchanges, "line 2's run, then the queue's end (%zu of %zu)", end, nchanges);
	CHECK(mo_state.px.late == 0, "no record counted late (%u)", (unsigned)mo_state.px.late);
	take();
}

int main(void)
{
	test_parse();
	test_scan_timing();
	test_refused();
	test_dark_hold_underrun();
	test_broken_scan();
	test_record_during_hold();
	printf("raster: %d checks, %d failed\n", checks, failures);
	return failures ? 1 : 0;
}
