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

/* Pixels escaped as the protocol says (PROTO_PX_ESC, XOR PROTO_PX_XOR). */
static void add_pixels(line_t *l, const uint8_t *px, size_t n)
{
	l->b[l->n++] = ':';
	for (size_t i = 0; i < n; i++) {
		if (proto_px_escaped(px[i])) {
			l->b[l->n++] = (char)PROTO_PX_ESC;
			l->b[l->n++] = (char)(px[i] ^ PROTO_PX_XOR);
		} else {
			l->b[l->n++] = (char)px[i];
		}
	}
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
static uint8_t parse_bytes(proto_lines_t *ln, const char *s, size_t n, proto_cmd_t *c)
{
	return proto_parse_line(ln, s, (uint8_t)n, c);
}

static void test_parse(void)
{
	proto_lines_t ln = { 0, 0 };
	proto_cmd_t c;
	static const struct { const char *body; uint8_t st; uint8_t items; } cases[] = {
		{ "G7 P1000 +10-5", FB_OK, 1 },
		{ "G7P1000+10-5", FB_OK, 1 },
		{ "G7+10-5", FB_OK, 1 },
		{ "G7 U5 T400 P1000 +1+1 P2000 +2-2 -3+0", FB_OK, 3 },
		{ "g7 u5 t400 +1+1", FB_OK, 1 },
		{ "G7", FB_ERR_MISSING_WORD, 0 },
		{ "G7 U5", FB_ERR_MISSING_WORD, 0 },
		{ "G7 T-1 +1+1", FB_ERR_OUT_OF_RANGE, 0 },
		{ "G7 T16000001 +1+1", FB_ERR_OUT_OF_RANGE, 0 },
		{ "G7 U1600000001 +1+1", FB_ERR_OUT_OF_RANGE, 0 },
		{ "G7 A5 +1+1", FB_ERR_BAD_WORD, 0 },
		{ "G7 +1+1 U5", FB_ERR_BAD_WORD, 0 },
		{ "G7 P99 +1+1", FB_ERR_OUT_OF_RANGE, 0 },
		{ "G7 +1", FB_ERR_BAD_WORD, 0 },
		{ "G70 +1+1", FB_ERR_UNKNOWN_COMMAND, 0 },
		{ "G7 +1+1 ;x", FB_OK, 1 },         /* no data: a comment as anywhere */
		{ "G7 +1+1 ;x:ab", FB_ERR_BAD_WORD, 0 },  /* with data: none */
	};
	for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
		ln.last = 0;
		ln.numbered = 0;
		uint8_t st = parse_bytes(&ln, cases[k].body, strlen(cases[k].body), &c);
		CHECK(st == cases[k].st, "'%s': status %u, want %u", cases[k].body, st, cases[k].st);
		if (st == FB_OK) {
			CHECK(c.kind == PROTO_CMD_G7 && c.g6_count + 1u == cases[k].items && c.px_n == 0,
			      "'%s': kind %u items %u px %u", cases[k].body, c.kind, c.g6_count + 1u, c.px_n);
			CHECK(ln.last == cases[k].items, "'%s': uses %u line numbers", cases[k].body, ln.last);
		}
	}
	/* pixel data: every byte value, escaped where it must be */
	uint8_t px[100];
	line_t l = { .n = 0 };
	add(&l, "N1G7U0T400P1000+1+1");
	for (int i = 0; i < 100; i++)
		px[i] = (uint8_t)(i * 37 + 5);
	uint8_t must[] = { '\n', '\r', 0x18, '!', '*', '?', '~', PROTO_PX_ESC };
	for (size_t i = 0; i < sizeof must; i++)
		px[i] = must[i];
	add_pixels(&l, px, 100);
	size_t body = l.n;
	CHECK(body > 99, "a body of three-digit length: %zu", body);
	finish_line(&l);
	ln.last = 0;
	uint8_t st = parse_bytes(&ln, l.b, l.n - 1, &c);
	CHECK(st == FB_OK && c.px_n == 100, "100 pixels with escapes: status %u, %u pixels", st, c.px_n);
	for (size_t i = 0; i < body; i++)
		if (i > c.px_at)
			CHECK(l.b[i] != '\n' && l.b[i] != '*', "no newline or '*' in the data");
	/* a raw byte that must be escaped, a bad escape, an escape at the end */
	static const char *bad[] = { "G7+1+1:a*b", "G7+1+1:a\x7dz", "G7+1+1:ab\x7d", "G7+1+1:\x7d\x7d" };
	for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
		ln.last = 0;
		ln.numbered = 0;
		st = parse_bytes(&ln, bad[k], strlen(bad[k]), &c);
		/* "a*b": the last '*' starts a checksum field: that is error 8 */
		CHECK(st == FB_ERR_BAD_WORD || (k == 0 && st == FB_ERR_CHECKSUM), "bad data %zu: %u", k, st);
	}
	/* the field's length has three digits past 99, still without a leading zero */
	line_t z = { .n = 0 };
	add(&z, "N1G7U0T400P1000+1+1");
	add_pixels(&z, px + 8, 90);
	char f[32];
	snprintf(f, sizeof f, "*%u/0%u", proto_crc16(z.b, (uint8_t)z.n), (unsigned)z.n);
	add(&z, f);
	ln.last = 0;
	CHECK(parse_bytes(&ln, z.b, z.n, &c) == FB_ERR_CHECKSUM, "a leading zero in the length");
	/* every single-byte drop of a G7 line with pixels is refused with a resend */
	for (size_t k = 0; k + 1 < l.n; k++) {
		char d[300];
		memcpy(d, l.b, k);
		memcpy(d + k, l.b + k + 1, l.n - 1 - k - 1);
		ln.last = 0;
		ln.numbered = 1;
		st = parse_bytes(&ln, d, l.n - 2, &c);
		CHECK(proto_is_resend(st), "drop at %zu: status %u", k, st);
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
	char w[96];
	l->n = 0;
	(void)number;  /* unnumbered: the field alone */
	snprintf(w, sizeof w, "G7 U%u T%u", g->u, g->t);
	add(l, w);
	for (uint8_t i = 0; i < g->items; i++) {
		snprintf(w, sizeof w, "%sP%u%+d%+d", i ? "" : " ", g->p_us, g->d[i][0], g->d[i][1]);
		add(l, w);
	}
	if (g->n)
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
static void test_refused(void)
{
	boot();
	send("$0=60000\nG90\nM3 S0\n");
	run_slices(6, 0);
	take();
	static const char *lines[][2] = {
		{ "G7 U0 T400 P1000 +1+1:\x01\x02", "ok\r\n" },
		{ "G7 U15600 T400 P1000 +1+1:\x01\x02", "error:7\r\n" },   /* 15600 + 400 = C */
		{ "G7 U15599 T400 P1000 +1+1:\x01\x02", "ok\r\n" },
		{ "G7 U0 T399 P1000 +1+1:\x01\x02", "error:7\r\n" },
		{ "G7 U0 T1000 P1000 +1+1 +1+1:\x01\x02\x03\x04", "ok\r\n" },
		{ "G7 U15999 P1000 +1+1:\x05", "ok\r\n" },                 /* one pixel: no T needed */
		{ "G7 U16000 P1000 +1+1:\x05", "error:7\r\n" },
	};
	for (size_t i = 0; i < sizeof lines / sizeof lines[0]; i++) {
		send(lines[i][0]);
		send("\n");
		run_slices(20, 100000);
		const char *out = take();
		CHECK(strcmp(out, lines[i][1]) == 0, "'%s': got '%s' want '%s'", lines[i][0], out, lines[i][1]);
		send("\x18");
		run_slices(4, 0);
		take();
		send("$0=60000\nG90\nM3 S0\n");
		run_slices(6, 0);
		take();
	}
	/* no P yet after a reset: the first G7 needs one */
	send("G7 +1+1\n");
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

int main(void)
{
	test_parse();
	test_scan_timing();
	test_refused();
	test_dark_hold_underrun();
	test_broken_scan();
	printf("raster: %d checks, %d failed\n", checks, failures);
	return failures ? 1 : 0;
}
