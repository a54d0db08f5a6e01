/*
 * fast_tests.c - the fast form (fb_fast.c) against the DDA schedule, on
 * random blocks.
 *
 * Built with gcc and the address/undefined sanitizers by `make -C firmware
 * test` (and, against a deliberately broken fb_fast.c, by `make fast-mutant
 * MUTANT=n`, which must fail).  A job of random blocks is queued block by
 * block as the firmware would (mo_prepare_cycles, the block's C form; then
 * mo_fast_form, its fast form or a refusal), each fast block starting where
 * the previous one ended on a 16-bit timer that starts at a random count
 * (fast_begin: the fast path's switch to the next block, or the C path's
 * start of it, both start it at the previous end).  Each fast block is run
 * event by event with fast_next() until it ends, and every event is checked
 * against an oracle computed here from the block's C and n alone:
 *   - step k (1..n) of a motor is at floor((2k-1) Q / 2^17) cycles after the
 *     block start, Q = floor(2^16 C / n) (the fast form's definition,
 *     fb_fast.h), exactly, in timer ticks; that time is the DDA's
 *     floor((2k-1) C / 2n) or one tick before it, never after, and equal to
 *     it when 2^16 (C mod n) is a multiple of n;
 *   - each event is the earliest step left (both motors when equal); the
 *     other motor's next step is its pair exactly when it follows within
 *     FAST_PAIR_CYCLES, issued as one edge (under FAST_TINY_CYCLES), a
 *     close pair (under FAST_CLOSE_CYCLES) or a pair (fast_kind);
 *   - each motor steps exactly n times, and the block ends exactly C ticks
 *     after it started.
 * A refused block must be one the rules refuse (a motor over FAST_NMAX
 * steps or FAST_QMAX cycles between steps, no motor moving); the C path
 * runs it, and the next block starts C later.
 *
 * `fast_tests [seed] [blocks]`; prints the first failures and a summary,
 * exits 1 if any check failed.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fake_board.h"
#include "fb_fast.h"
#include "fb_motion.h"
#include "status.h"

/* the shortest step interval the firmware queues: $0 at its cap */
#define MIN_INTERVAL ((uint32_t)((FB_F_CPU + CFG_MAX_RATE_LIMIT - 1) / CFG_MAX_RATE_LIMIT))
#define NONE UINT64_MAX

static unsigned long checks, failures;

#define CHECK(cond, ...) do { checks++; if (!(cond)) { if (failures++ < 20) { \
	printf("FAIL %s:%d: ", __FILE__, __LINE__); printf(__VA_ARGS__); printf("\n"); } } } while (0)

/* xorshift64*: the same job for the same seed on every host */
static uint64_t rng_state;

static uint64_t rnd(void)
{
	rng_state ^= rng_state >> 12;
	rng_state ^= rng_state << 25;
	rng_state ^= rng_state >> 27;
	return rng_state * 2685821657736338717ULL;
}

/* Uniform in lo..hi. */
static uint32_t between(uint32_t lo, uint32_t hi)
{
	return lo + (uint32_t)(rnd() % ((uint64_t)hi - lo + 1u));
}

/* lo..hi (lo >= 1), about log-uniform: an octave at random, then a value
 * in it (as many short blocks as long ones). */
static uint32_t log_between(uint32_t lo, uint32_t hi)
{
	uint32_t octaves = 0;
	for (uint64_t x = lo; x * 2u <= hi; x *= 2u)
		octaves++;
	uint64_t from = (uint64_t)lo << between(0, octaves), to = 2u * from - 1u;
	return between((uint32_t)from, (uint32_t)(to < hi ? to : hi));
}

/* The oracle, from C and n alone (64-bit, no shortcut). */
static uint64_t dda_time(uint64_t c, uint64_t n, uint64_t k)
{
	return (2u * k - 1u) * c / (2u * n);
}

static uint64_t fast_time(uint64_t c, uint64_t n, uint64_t k)
{
	uint64_t q = (c << 16) / n;
	return ((2u * k - 1u) * q) >> 17;
}

static struct {
	unsigned long blocks, fast, refused, events, steps, both, early, ones, tiny, close, far;
} stat;

/* The events the oracle expects next, given the next absolute step time of
 * each motor (NONE when done). */
static void expected_event(uint64_t na, uint64_t nb, uint64_t *t, uint8_t *bits, uint64_t *t2,
			   uint8_t *bits2)
{
	*bits2 = 0;
	*t2 = 0;
	if (nb == NONE) {
		*t = na;
		*bits = 1;
	} else if (na == NONE) {
		*t = nb;
		*bits = 2;
	} else if (na == nb) {
		*t = na;
		*bits = 3;
	} else {
		uint8_t first = nb < na ? 1u : 0u;
		uint64_t lo = first ? nb : na, hi = first ? na : nb;
		*t = lo;
		*bits = (uint8_t)(1u << first);
		if (hi - lo < FAST_PAIR_CYCLES) {
			*t2 = hi;
			*bits2 = (uint8_t)(2u >> first);
		}
	}
}

/* Whether the fast form's rules refuse motor counts n over c cycles. */
static int refused_by_rules(uint32_t c, const uint32_t n[2])
{
	if (!n[0] && !n[1])
		return 1;
	for (int i = 0; i < 2; i++)
		if (n[i] && (n[i] > FAST_NMAX || c / n[i] > FAST_QMAX))
			return 1;
	return 0;
}

/*
 * Run one fast block f of c cycles with n[i] steps of motor i, started at
 * absolute time start, event by event against the oracle.  Returns the
 * absolute time the model says it ends.
 */
static uint64_t run_fast_block(fast_t *f, uint32_t c, const uint32_t n[2], uint64_t start)
{
	uint64_t cyc = c;
	fast_begin(f, (uint16_t)start);
	uint16_t left[2] = { f->cnt[0], f->cnt[1] };
	fast_event_t e;
	fast_pick(f, left, &e);
	uint32_t k[2] = { 0, 0 };
	uint64_t now = start;
	for (;;) {
		uint64_t next[2];
		for (int i = 0; i < 2; i++)
			next[i] = k[i] < n[i] ? start + fast_time(cyc, n[i], k[i] + 1u) : NONE;
		uint64_t t, t2;
		uint8_t bits, bits2;
		expected_event(next[0], next[1], &t, &bits, &t2, &bits2);
		CHECK(e.t == (uint16_t)t && e.bits == bits && e.bits2 == bits2 &&
		      (!bits2 || e.t2 == (uint16_t)t2),
		      "block c=%" PRIu32 " n=%" PRIu32 ",%" PRIu32 " steps %" PRIu32 ",%" PRIu32
		      ": event t=%u bits=%u t2=%u bits2=%u, want t=%u bits=%u t2=%u bits2=%u",
		      c, n[0], n[1], k[0], k[1], e.t, e.bits, e.t2, e.bits2, (unsigned)(uint16_t)t,
		      bits, (unsigned)(uint16_t)t2, bits2);
		/* a wrong event would desynchronise every later check */
		if (e.t != (uint16_t)t || e.bits != bits || e.bits2 != bits2)
			return start + cyc;
		CHECK(t >= now && t - now < 32768u, "events in order, < 32768 apart: %" PRIu64, t - now);
		uint64_t gap = bits2 ? t2 - t : 0;
		uint8_t kind = !bits2 ? FAST_ONE : gap < FAST_TINY_CYCLES ? FAST_TINY :
			       gap < FAST_CLOSE_CYCLES ? FAST_CLOSE : FAST_PAIR;
		CHECK(fast_kind(&e) == kind, "kind %u want %u (gap %" PRIu64 ")", fast_kind(&e), kind,
		      gap);
		stat.events++;
		stat.both += bits == 3;
		stat.ones += kind == FAST_ONE;
		stat.tiny += kind == FAST_TINY;
		stat.close += kind == FAST_CLOSE;
		stat.far += kind == FAST_PAIR;
		uint8_t stepped = (uint8_t)(bits | bits2);
		for (int i = 0; i < 2; i++) {
			if (!(stepped & (1u << i)))
				continue;
			k[i]++;
			stat.steps++;
			uint64_t want = start + dda_time(cyc, n[i], k[i]), got = next[i];
			CHECK(got == want || got + 1u == want,
			      "step %" PRIu32 " of %" PRIu32 " (c=%" PRIu32 ") at %" PRIu64
			      ", the DDA's %" PRIu64, k[i], n[i], c, got - start, want - start);
			uint64_t m = cyc % n[i];
			if ((m << 16) % n[i] == 0)
				CHECK(got == want, "nothing cut (m=%" PRIu64 "): on the DDA time", m);
			stat.early += got != want;
		}
		now = bits2 ? t2 : t;
		if (!fast_next(f, left, &e))
			break;
	}
	CHECK(k[0] == n[0] && k[1] == n[1] && !left[0] && !left[1],
	      "steps %" PRIu32 ",%" PRIu32 " of %" PRIu32 ",%" PRIu32 ", left %u,%u", k[0], k[1], n[0],
	      n[1], left[0], left[1]);
	CHECK(e.bits == 0 && e.bits2 == 0, "the end is no step");
	return now + (uint16_t)(e.t - (uint16_t)now);
}

/* Random motor counts and duration of the next block, mostly ones the fast
 * path takes, within the firmware's ranges. */
static void random_block(int32_t d[2], uint32_t *c)
{
	uint32_t r = between(0, 99), n[2];
	if (r < 4) {
		/* a dwell */
		n[0] = n[1] = 0;
		*c = 16u * log_between(100, 1000000);
	} else if (r < 8) {
		/* too many steps for the fast form */
		n[0] = between(FAST_NMAX + 1u, 40000);
		n[1] = between(0, n[0]);
		*c = n[0] * between(MIN_INTERVAL, 2000);
	} else if (r < 12) {
		/* too slow for it: few steps over a long time */
		n[0] = between(1, 50);
		n[1] = between(0, 50);
		*c = between(n[0] * (FAST_QMAX + 1u), n[0] * 40000u);
	} else {
		uint32_t q = log_between(MIN_INTERVAL, FAST_QMAX);
		n[0] = log_between(1, FAST_NMAX);
		*c = q * n[0] + between(0, n[0] - 1u);
		if (between(0, 1))
			*c -= *c % 16u;  /* a G1's P in microseconds */
		if (*c / n[0] < MIN_INTERVAL)
			*c += 16u * n[0];
		switch (between(0, 5)) {
		case 0:
			n[1] = 0;
			break;
		case 1:
			n[1] = n[0];
			break;
		case 2:  /* near 1:1, where the steps seldom coincide */
			n[1] = n[0] - n[0] / between(8, 100);
			break;
		default:
			n[1] = between(0, n[0]);
			break;
		}
		if (between(0, 1)) {
			uint32_t x = n[0];
			n[0] = n[1];
			n[1] = x;
		}
	}
	for (int i = 0; i < 2; i++)
		d[i] = between(0, 1) ? -(int32_t)n[i] : (int32_t)n[i];
}

/*
 * mo_prepare_fast (what the firmware's mo_prepare runs on the AVR) against
 * the two steps this test holds to the DDA, mo_prepare_cycles then
 * mo_fast_form (b, its form f, fast whether it took it): the same fast form
 * byte for byte when it takes one, else the same C form; and the same
 * step-rate refusal when the limit is raised past a motor's interval.
 */
static void check_prepare_fast(const mo_block_t *b, const int32_t d[2], uint32_t c, uint8_t fast,
			       const fast_t *f, unsigned long j)
{
	mo_block_t g;
	memset(&g, 0xa5, sizeof g);
	CHECK(mo_prepare_fast(&g, d[0], d[1], c, MIN_INTERVAL) == FB_OK, "block %lu: prepare_fast", j);
	CHECK(g.type == MO_BLK_MOVE && g.dirs == b->dirs && g.cycles == b->cycles,
	      "block %lu: prepare_fast type %u dirs %u cycles %" PRIu32, j, g.type, g.dirs, g.cycles);
	if (fast)
		CHECK(g.fast == MO_FAST_FORMED && memcmp(&g.f, f, sizeof *f) == 0,
		      "block %lu: prepare_fast's form differs (fast %u)", j, g.fast);
	else
		CHECK(g.fast == 0 && memcmp(g.q, b->q, sizeof b->q) == 0 &&
		      memcmp(g.next, b->next, sizeof b->next) == 0 &&
		      memcmp(g.err, b->err, sizeof b->err) == 0 &&
		      memcmp(g.r2, b->r2, sizeof b->r2) == 0 && memcmp(g.den, b->den, sizeof b->den) == 0,
		      "block %lu: prepare_fast's C form differs", j);
	/* one cycle above the tighter motor's interval: both refuse, or neither */
	uint32_t qmin = 0xffffffffu;
	for (int i = 0; i < 2; i++)
		if (d[i] && c / (uint32_t)(d[i] < 0 ? -d[i] : d[i]) < qmin)
			qmin = c / (uint32_t)(d[i] < 0 ? -d[i] : d[i]);
	if (qmin != 0xffffffffu) {
		mo_block_t h;
		uint8_t want = mo_prepare_cycles(&h, d[0], d[1], c, qmin + 1u);
		CHECK(want == FB_ERR_TOO_FAST && mo_prepare_fast(&g, d[0], d[1], c, qmin + 1u) == want,
		      "block %lu: the step-rate test at %" PRIu32, j, qmin + 1u);
	}
}

static void run_job(uint64_t seed, unsigned long blocks)
{
	rng_state = seed ? seed : 1u;
	uint64_t now = between(0, 65535);
	for (unsigned long j = 0; j < blocks; j++) {
		int32_t d[2];
		uint32_t c, n[2];
		random_block(d, &c);
		mo_block_t b;
		memset(&b, 0, sizeof b);
		CHECK(mo_prepare_cycles(&b, d[0], d[1], c, MIN_INTERVAL) == FB_OK, "block %lu", j);
		for (int i = 0; i < 2; i++)
			n[i] = (uint32_t)(d[i] < 0 ? -d[i] : d[i]);
		fast_t f;
		uint8_t fast = mo_fast_form(&b, &f);
		check_prepare_fast(&b, d, c, fast, &f, j);
		stat.blocks++;
		CHECK(fast == !refused_by_rules(c, n), "block %lu (c=%" PRIu32 " n=%" PRIu32 ",%" PRIu32
		      "): fast form %u", j, c, n[0], n[1], fast);
		if (!fast) {
			stat.refused++;
			now += c;
			continue;
		}
		stat.fast++;
		CHECK(f.cnt[0] == n[0] && f.cnt[1] == n[1], "counts %u,%u", f.cnt[0], f.cnt[1]);
		uint64_t end = run_fast_block(&f, c, n, now);
		CHECK(end == now + c, "block %lu (c=%" PRIu32 " n=%" PRIu32 ",%" PRIu32 ") ends %" PRId64
		      " ticks off its C", j, c, n[0], n[1], (int64_t)(end - now - c));
		now += c;
	}
}

/* The blocks that never take the fast form, whatever their counts. */
static void test_refusals(void)
{
	fake_reset();
	mo_init();
	mo_block_t b;
	fast_t f;
	CHECK(mo_prepare_cycles(&b, 100, -50, 100u * 1000u, MIN_INTERVAL) == FB_OK, "a plain move");
	CHECK(mo_fast_form(&b, &f), "takes the fast form");
	mo_set_endstops(1, 3);
	CHECK(!mo_fast_form(&b, &f), "not with endstop supervision ($7=1)");
	mo_set_endstops(0, 3);
	b.type = MO_BLK_HOME;
	CHECK(!mo_fast_form(&b, &f), "not a homing block");
	mo_prepare_pen(&b, 1000, 2000, 200, 100);
	CHECK(!mo_fast_form(&b, &f), "not a pen block");
}

int main(int argc, char **argv)
{
	uint64_t seed = argc > 1 ? strtoull(argv[1], 0, 0) : 20240531u;
	unsigned long blocks = argc > 2 ? strtoul(argv[2], 0, 0) : 3000u;
	test_refusals();
	fake_reset();
	mo_init();
	run_job(seed, blocks);
	printf("fast form: %lu blocks (%lu fast, %lu refused), %lu events: %lu one edge "
	       "(%lu of both motors), %lu tiny, %lu close, %lu far pairs; %lu of %lu steps one tick "
	       "before the DDA\n", stat.blocks, stat.fast, stat.refused, stat.events, stat.ones,
	       stat.both, stat.tiny, stat.close, stat.far, stat.early, stat.steps);
	printf("%lu checks, %lu failed\n", checks, failures);
	return failures ? 1 : 0;
}
