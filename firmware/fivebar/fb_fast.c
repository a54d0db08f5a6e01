/*
 * fb_fast.c - the fast form of a block and its events, in portable C (see
 * fb_fast.h): the specification board_avr_step.S's assembly follows.
 *
 * Built with -DFB_FAST_MUTANT=n it is deliberately wrong in one place, so
 * that tests/fast_tests.c can be seen to fail (`make fast-mutant MUTANT=n`,
 * tests/firmware/test_unit_c.py):
 *   1  the pick pairs steps FAST_PAIR_CYCLES apart (its bound off by one)
 *   2  a motor's next time drops the carry of the fraction's add
 */
#include "fb_fast.h"

#ifndef FB_FAST_MUTANT
#define FB_FAST_MUTANT 0
#endif

/* floor(m * 65536 / n) for m < n < 32768, its remainder in *r: 16 steps of
 * long division, a fraction of __udivmodsi4's cycles (the main loop runs
 * this per block). */
static uint16_t frac16(uint16_t m, uint16_t n, uint16_t *r)
{
	uint16_t q = 0;
	*r = 0;
	if (!m)
		return 0;  /* C a multiple of n (one step always): no loop */
	for (uint8_t i = 0; i < 16; i++) {
		m = (uint16_t)(m << 1);
		q = (uint16_t)(q << 1);
		if (m >= n) {
			m = (uint16_t)(m - n);
			q |= 1u;
		}
	}
	*r = m;
	return q;
}

uint8_t fast_form(fast_t *f, const uint32_t n[2], const uint32_t q[2], const uint32_t m[2])
{
	uint16_t n16[2], q16[2], m16[2];
	for (uint8_t i = 0; i < 2; i++) {
		if (n[i] > FAST_NMAX || (n[i] && q[i] > FAST_QMAX))
			return 0;
		n16[i] = (uint16_t)n[i];
		q16[i] = n[i] ? (uint16_t)q[i] : 0u;
		m16[i] = n[i] ? (uint16_t)m[i] : 0u;
	}
	if (!n[0] && !n[1])
		return 0;  /* a pure dwell: the C path's waits */
	fast_form16(f, n16, q16, m16);
	return 1;
}

void fast_form16(fast_t *f, const uint16_t n[2], const uint16_t q[2], const uint16_t m[2])
{
	uint16_t tail = 0xffffu;
	for (uint8_t i = 0; i < 2; i++) {
		f->cnt[i] = (uint16_t)n[i];
		if (!n[i]) {
			f->t[i] = f->tf[i] = f->q[i] = f->qf[i] = 0;
			continue;
		}
		uint16_t r;
		uint16_t qf = frac16(m[i], n[i], &r);
		f->q[i] = q[i];
		f->qf[i] = qf;
		/* step 1 at C/2n = (q + qf/65536) / 2 */
		f->t[i] = (uint16_t)(q[i] >> 1);
		f->tf[i] = (uint16_t)(((q[i] & 1u) << 15) | (qf >> 1));
		/* the block ends C cycles after its start: ti = C less this
		 * motor's last step.  The DDA puts it at floor((2n-1)C/2n), so
		 * C - that = ceil(C/2n) (C = qn + m, m < n).  The cut puts it
		 * a cycle earlier when the fraction of (2n-1)C/2n, j/2n with
		 * j = -C mod 2n, is below what the cut lost, (2n-1)r/(2^17 n)
		 * (r / 2^16 n of C/n, 2n-1 halves of it): 2^16 j < (2n-1) r. */
		uint16_t ti = (uint16_t)((q[i] & 1u) ? (q[i] + 1u) >> 1 : (q[i] >> 1) + (m[i] ? 1u : 0u));
		uint16_t n2 = (uint16_t)(n[i] << 1), c2 = (uint16_t)((q[i] & 1u) ? m[i] + n[i] : m[i]);
		uint16_t j = c2 ? (uint16_t)(n2 - c2) : 0u;
		if (((uint32_t)j << 16) < (uint32_t)(n2 - 1u) * r)
			ti++;
		if (ti < tail)
			tail = ti;
	}
	f->tail = tail;
}

void fast_begin(fast_t *f, uint16_t base)
{
	f->t[0] = (uint16_t)(f->t[0] + base);
	f->t[1] = (uint16_t)(f->t[1] + base);
}

void fast_pick(const fast_t *f, const uint16_t left[2], fast_event_t *e)
{
	e->bits2 = 0;
	if (!left[1]) {
		e->t = f->t[0];
		e->bits = 1;
		return;
	}
	if (!left[0]) {
		e->t = f->t[1];
		e->bits = 2;
		return;
	}
	/* the times of a block are within 32768 of each other: the sign of
	 * the 16-bit difference says which comes first */
	int16_t d = (int16_t)(f->t[1] - f->t[0]);
	uint8_t first = d < 0 ? 1u : 0u;
	uint16_t gap = (uint16_t)(d < 0 ? -d : d);
	e->t = f->t[first];
	e->bits = (uint8_t)(1u << first);
	if (d == 0) {
		e->bits = 3;
	} else if (gap < FAST_PAIR_CYCLES + (FB_FAST_MUTANT == 1)) {
		e->t2 = f->t[first ^ 1u];
		e->bits2 = (uint8_t)(2u >> first);
	}
}

uint8_t fast_kind(const fast_event_t *e)
{
	if (!e->bits2)
		return FAST_ONE;
	uint16_t gap = (uint16_t)(e->t2 - e->t);
	if (gap < FAST_TINY_CYCLES)
		return FAST_TINY;
	return gap < FAST_CLOSE_CYCLES ? FAST_CLOSE : FAST_PAIR;
}

/* Motor i's next time: t.tf += q.qf, the fraction's carry into t. */
static void advance(fast_t *f, uint8_t i)
{
	uint32_t tf = (uint32_t)f->tf[i] + f->qf[i];
	f->tf[i] = (uint16_t)tf;
	f->t[i] = (uint16_t)(f->t[i] + f->q[i] + (FB_FAST_MUTANT == 2 ? 0u : tf >> 16));
}

uint8_t fast_next(fast_t *f, uint16_t left[2], fast_event_t *e)
{
	uint8_t bits = (uint8_t)(e->bits | e->bits2);
	/* the event's time, which the block's end counts from: a pair's is its
	 * second edge (the interrupt's board_step.sched) */
	uint16_t now = e->bits2 ? e->t2 : e->t;
	for (uint8_t i = 0; i < 2; i++) {
		/* after a motor's last step its time stays: it is done */
		if ((bits & (1u << i)) && --left[i])
			advance(f, i);
	}
	if (!left[0] && !left[1]) {
		e->t = (uint16_t)(now + f->tail);
		e->bits = e->bits2 = 0;
		return 0;
	}
	fast_pick(f, left, e);
	return 1;
}
