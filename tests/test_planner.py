"""Planner: the staircase the firmware runs (constant rate per segment) checked by a plain
loop; the least durations against a plain sequential reference of the same bounds; closed
forms for a lone segment; never a longer segment with a raised limit; the geometric cut."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fivebar_host.planner import (
    cut_fractions,
    piece_sizes,
    staircase_durations,
    staircase_ratios,
)

Q = 2 * math.pi / 12800  # one step, rad


def _staircase_reference(dth: np.ndarray, us: np.ndarray, stop: np.ndarray, alpha: float,
                         jump: float) -> tuple[float, float]:
    """Worst jump and average-acceleration ratios by a plain loop over the boundaries."""
    t = us * 1e-6
    w = dth / t[:, None]
    worst_j = worst_a = 0.0
    k = len(t)
    for i in range(k):
        first = i == 0 or stop[i - 1]
        last = i == k - 1 or stop[i]
        for side in (first, last):
            if side:  # from or to standstill
                m = float(np.abs(w[i]).max())
                worst_j = max(worst_j, m / jump)
                worst_a = max(worst_a, m / (alpha * t[i] / 2))
        if i > 0:
            m = float(np.abs(w[i] - w[i - 1]).max())
            worst_j = max(worst_j, m / jump)
            worst_a = max(worst_a, m / (alpha * (t[i] + t[i - 1]) / 2))
    return worst_j, worst_a


def _bound(a: float, b: float, p: float, jump: float, alpha: float) -> float:
    """Shortest q after a boundary for one joint that keeps its direction (module doc (3),
    (4)), in seconds, written out plainly."""
    if a == 0.0:
        return 0.0
    q_jump = a / (jump + b / p)
    p_hat = min(p, math.sqrt(2 * b / alpha))
    c = b / p_hat + alpha * p_hat / 2 if p_hat > 0 else 0.0
    q_acc = (-c + math.sqrt(c * c + 2 * alpha * a)) / alpha  # root of α/2·q² + c·q − a
    return max(q_jump, q_acc)


def _least_reference(d: np.ndarray, length: np.ndarray, feed: float, wmax: float,
                     alpha: float, stop: np.ndarray, jump: float, pmin: int) -> np.ndarray:
    """The least integer durations (µs) by a plain Gauss–Seidel loop: start at the caps and
    raise any duration that breaks a bound until none does."""
    k = len(d)
    dist = np.abs(d).max(axis=1)
    p = [max(pmin, math.ceil(dist[i] / wmax * 1e6 - 1e-9),
             math.ceil(length[i] / feed * 1e6 - 1e-9)) for i in range(k)]
    for i in range(k):
        if i == 0 or stop[i - 1] or i == k - 1 or stop[i]:
            p[i] = max(p[i], math.ceil(max(dist[i] / jump, math.sqrt(2 * dist[i] / alpha))
                                       * 1e6 - 1e-9))
    bounds = []  # (segment to raise, other segment, a, b) for every direction-keeping joint
    for i in range(1, k):  # across stops too
        for j in range(2):
            a, b = abs(d[i, j]), abs(d[i - 1, j])
            if d[i, j] * d[i - 1, j] < 0:  # reversal: (5)
                for s, x in ((i, a), (i - 1, b)):
                    p[s] = max(p[s], math.ceil(max((a + b) / jump, math.sqrt(2 * x / alpha))
                                               * 1e6 - 1e-9))
            else:
                bounds += [(i, i - 1, a, b), (i - 1, i, b, a)]
    changed = True
    while changed:
        changed = False
        for s, o, a, b in bounds:
            need = math.ceil(_bound(a, b, p[o] * 1e-6, jump, alpha) * 1e6 - 1e-9)
            if need > p[s]:
                p[s], changed = need, True
    return np.array(p)


def _chain(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random whole-step segments (some collinear runs, reversals, tiny ones) and stops."""
    rng = np.random.default_rng(seed)
    d = rng.integers(-40, 41, (n, 2)).astype(float)
    d[rng.random(n) < 0.3] = d[0]  # collinear repeats
    d[np.abs(d).max(axis=1) == 0] = [3.0, 1.0]
    length = np.abs(d).max(axis=1) * Q * rng.uniform(40, 120, n)  # ~ mm per rad
    return d * Q, length, rng.random(n) < 0.1


limits = st.tuples(st.floats(5.0, 150.0), st.floats(1.0, 30.0), st.floats(10.0, 3000.0))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 60), st.integers(0, 2**31), limits)
def test_least_durations_meet_every_limit_and_match_a_plain_loop(
        n: int, seed: int, lim: tuple[float, float, float]) -> None:
    d, length, stop = _chain(n, seed)
    feed, wmax, alpha = lim
    us = staircase_durations(d, length, np.full(n, feed), wmax, alpha, stop, 0.5, 100)
    assert us.dtype == np.int64
    assert np.array_equal(us, _least_reference(d, length, feed, wmax, alpha, stop, 0.5, 100))
    wj, wa = _staircase_reference(d, us.astype(float), stop, alpha, 0.5)
    assert wj <= 1.0 + 1e-9 and wa <= 1.0 + 1e-9
    jr, ar = staircase_ratios(d, us, stop, alpha, 0.5)
    assert jr.max() == pytest.approx(wj) and ar.max() == pytest.approx(wa)
    t = us * 1e-6
    assert (np.abs(d).max(axis=1) / t).max() <= wmax * (1 + 1e-9)
    assert (length / t).max() <= feed * (1 + 1e-9) and us.min() >= 100


def test_lone_segment_closed_form() -> None:
    """One segment from rest to rest: the largest of the caps (1) and rest bounds (2)."""
    d = np.array([[0.02, -0.01]])
    for feed, wmax, alpha in ((1e9, 100.0, 1e4), (1e9, 100.0, 10.0), (1.0, 100.0, 1e4),
                              (1e9, 0.1, 1e4)):
        us = staircase_durations(d, np.array([1.0]), np.array([feed]), wmax, alpha)
        want = max(0.02 / 0.5, math.sqrt(2 * 0.02 / alpha), 1.0 / feed, 0.02 / wmax)
        assert us[0] == math.ceil(want * 1e6 - 1e-9)


def test_collinear_ramp_speeds_up_by_the_jump_per_piece() -> None:
    """Equal collinear pieces with a high acceleration: from rest each piece may be J faster
    than the one before, so piece i runs at i·J until the joint-speed cap."""
    n, step = 40, 30 * Q
    d = np.tile([[step, step / 3]], (n, 1))
    us = staircase_durations(d, np.full(n, 1e-9), np.full(n, 1e9), 5.0, 1e6)
    w = step / (us * 1e-6)
    assert w[0] == pytest.approx(0.5, rel=1e-3) and w[1] == pytest.approx(1.0, rel=1e-3)
    assert w.max() == pytest.approx(5.0, rel=1e-3) and w[-1] == pytest.approx(0.5, rel=1e-3)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 60), st.integers(0, 2**31), limits,
       st.lists(st.one_of(st.just(1.0), st.floats(1.0, 4.0)), min_size=4, max_size=4))
def test_no_segment_longer_with_a_raised_limit(n: int, seed: int,
                                              lim: tuple[float, float, float],
                                              raise_by: list[float]) -> None:
    """The least element of bounds that all fall when a limit rises: every segment, not just
    the total, is no longer — exactly, to the µs."""
    d, length, stop = _chain(n, seed)
    feed, wmax, alpha = lim
    fr, wr, ar, jr = raise_by
    p0 = staircase_durations(d, length, np.full(n, feed), wmax, alpha, stop, 0.5, 100)
    p1 = staircase_durations(d, length, np.full(n, feed * fr), wmax * wr, alpha * ar, stop,
                             0.5 * jr, 100)
    assert (p1 <= p0).all()


def test_cut_depends_on_geometry_only_and_grows_inward() -> None:
    sizes = piece_sizes(6.0, 6.0, 60)
    assert sizes[:4].tolist() == [6.0, 12.0, 18.0, 24.0]
    counts, f = cut_fractions(np.array([0.0, 5.0, 20.0, 100.0, 5000.0]), sizes)
    assert counts.tolist()[:4] == [1, 1, 3, 7] and counts.sum() == f.size
    ends = np.split(f, np.cumsum(counts)[:-1])
    for n, e in zip([0.0, 5.0, 20.0, 100.0, 5000.0], ends, strict=True):
        assert e[-1] == 1.0 and np.all(np.diff(e) > 0)
        sz = np.diff(np.concatenate(([0.0], e * n)))
        m = (len(sz) - 1) // 2
        if m:  # from both ends: the sizes in order, and a middle no smaller than the first
            assert np.allclose(sz[:m], sizes[:m]) and np.allclose(sz[::-1][:m], sizes[:m])
            assert sz[m] >= sizes[0]
    big = ends[-1]
    assert (len(big) - 1) // 2 == int(np.searchsorted(np.cumsum(sizes), 2497, "right"))
