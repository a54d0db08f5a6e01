"""Planner: closed-form forward/backward passes against a plain loop, analytic rest-to-rest
times, and the limits it promises (joint speed, pen feed, acceleration between junctions);
the staircase the firmware runs (constant rate per segment) checked by a plain loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from staircase_reference import staircase_reference

from fivebar_host.compile.planner import check_plan, plan
from fivebar_host.compile.ramps import SHARP_SHARE, ramp_fractions, sharp_junctions
from fivebar_host.compile.staircase import enforce_staircase, raise_staircase, staircase_ratios


def test_triangle_and_trapezoid_rest_to_rest() -> None:
    a, vmax = 60.0, 6.0
    # Short move: never reaches vmax → t = 2·sqrt(D/α).
    p = plan(np.array([[0.1, 0.05]]), np.array([1.0]), np.array([1e9]), vmax, a)
    assert p.duration_s[0] == pytest.approx(2 * math.sqrt(0.1 / a), rel=1e-12)
    # Long move: t = D/v + v/α.
    p = plan(np.array([[-2.0, 1.0]]), np.array([1.0]), np.array([1e9]), vmax, a)
    assert p.duration_s[0] == pytest.approx(2.0 / vmax + vmax / a, rel=1e-12)
    assert p.duration_us[0] == math.ceil(p.duration_s[0] * 1e6 - 1e-6)


def test_collinear_chain_equals_one_segment() -> None:
    a, vmax = 60.0, 6.0
    n = 400
    d = np.tile([[2.0 / n, -1.0 / n]], (n, 1))
    p = plan(d, np.full(n, 1.0 / n), np.full(n, 1e9), vmax, a)
    assert p.duration_s.sum() == pytest.approx(2.0 / vmax + vmax / a, rel=1e-9)


def test_feed_limits_pen_speed() -> None:
    n = 50
    d = np.tile([[0.01, 0.0]], (n, 1))
    length = np.full(n, 0.5)  # 0.5 mm per 0.01 rad
    p = plan(d, length, np.full(n, 10.0), 100.0, 1e6)
    js, ps = check_plan(p, d, length, np.full(n, 10.0), 100.0)
    assert ps <= 1.0 + 1e-9 and js <= 1.0
    # cruise segments run at the feed exactly (to the µs rounding up)
    assert p.duration_s[n // 2] == pytest.approx(0.05, rel=1e-9)


def test_stop_after_forces_zero_speed() -> None:
    d = np.tile([[0.05, 0.05]], (6, 1))
    stop = np.zeros(6, bool)
    stop[2] = True
    p = plan(d, np.ones(6), np.full(6, 1e9), 6.0, 60.0, stop_after=stop)
    assert p.v_exit[2] == 0.0 and p.v_entry[3] == 0.0
    assert p.v_entry[0] == 0.0 and p.v_exit[-1] == 0.0


def _reference(dist: np.ndarray, cap: np.ndarray, alpha: float) -> np.ndarray:
    """Junction speeds by the textbook sequential forward and backward passes."""
    n = dist.shape[0]
    v2 = cap.astype(float) ** 2
    for i in range(n):
        v2[i + 1] = min(v2[i + 1], v2[i] + 2 * alpha * dist[i])
    for i in range(n - 1, -1, -1):
        v2[i] = min(v2[i], v2[i + 1] + 2 * alpha * dist[i])
    return np.sqrt(v2)


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=1, max_value=60), st.integers(min_value=0, max_value=2**31))
def test_closed_form_passes_match_loop(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    d = rng.normal(0, 0.03, (n, 2))
    length = np.abs(rng.normal(1.0, 0.5, n)) + 0.01
    feed = rng.uniform(5, 80, n)
    a, vmax, jump = 60.0, 6.0, 0.5
    p = plan(d, length, feed, vmax, a, junction_jump_rad_s=jump)
    dist = np.abs(d).max(axis=1)
    u = d / dist[:, None]
    vm = np.minimum(vmax, feed * dist / length)
    cap = np.zeros(n + 1)
    for k in range(1, n):
        jj = np.abs(u[k] - u[k - 1]).max()
        cap[k] = min(vm[k - 1], vm[k], jump / jj if jj > 0 else math.inf)
    ref = _reference(dist, cap, a)
    got = np.concatenate((p.v_entry, p.v_exit[-1:]))
    assert np.allclose(got, ref, rtol=1e-9, atol=1e-9)
    # acceleration between junctions: v1² − v0² ≤ 2αD in both directions
    assert np.all(np.abs(p.v_exit**2 - p.v_entry**2) <= 2 * a * dist * (1 + 1e-9) + 1e-12)
    js, ps = check_plan(p, d, length, feed, vmax)
    assert js <= 1.0 + 1e-9 and ps <= 1.0 + 1e-9


# ----------------------------------------------------------------------------- the staircase
@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=1, max_value=80), st.integers(min_value=0, max_value=2**31))
def test_enforce_staircase_meets_both_limits_and_only_slows(n: int, seed: int) -> None:
    """Against the plain loop, with and without the pen's path lengths: every ratio ≤ 1,
    and the vectorised ratios the loop's; the given durations are the segments' tops."""
    rng = np.random.default_rng(seed)
    d = rng.normal(0, 0.02, (n, 2))
    d[rng.random(n) < 0.2] *= 0.05  # some tiny segments
    stop = rng.random(n) < 0.15
    us = rng.integers(100, 20_000, n)
    length = np.abs(d).max(axis=1) * rng.uniform(10, 60, n) if seed % 2 else None
    out = enforce_staircase(d, us, stop, 60.0, 0.5, length_mm=length)
    assert (out >= us).all() and out.dtype == np.int64
    wj, wa = staircase_reference(d, out, stop, 60.0, 0.5, length, us)
    assert wj <= 1.0 + 1e-9 and wa <= 1.0 + 1e-6
    jr, ar = staircase_ratios(d, out, stop, 60.0, 0.5, length_mm=length, floor_us=us)
    assert jr.max() == pytest.approx(wj) and ar.max() == pytest.approx(wa, rel=1e-4)


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=1, max_value=80), st.integers(min_value=0, max_value=2**31))
def test_raise_staircase_is_the_whole_staircase_again(n: int, seed: int) -> None:
    """A staircase raised at a few segments and repaired near them is the staircase of the
    raised durations, to the µs (the link floor's later passes, `compile.timing`)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(0, 0.02, (n, 2))
    d[rng.random(n) < 0.2] *= 0.05
    d[rng.random(n) < 0.1] = 0.0  # segments without motion
    stop = rng.random(n) < 0.15
    length = np.abs(d).max(axis=1) * rng.uniform(10, 60, n) if seed % 2 else None
    floor = rng.integers(100, 20_000, n)
    out = enforce_staircase(d, floor, stop, 60.0, 0.5, length_mm=length)
    raised = np.flatnonzero((rng.random(n) < 0.1) & (np.abs(d).max(axis=1) > 0))
    out[raised] += rng.integers(1, 50_000, raised.size)
    floor[raised] = out[raised]
    whole = enforce_staircase(d, out, stop, 60.0, 0.5, length_mm=length, floor_us=floor)
    raise_staircase(d, out, raised, stop, 60.0, 0.5, length_mm=length, floor_us=floor)
    assert np.array_equal(out, whole)


def test_sharp_junctions_by_the_jump_at_peak_speed() -> None:
    """A junction is sharp where |u_k − u_j|∞ · v_peak,k > J (u = dθ/D): a joint's reversal
    at 0.4 rad/s jumps 0.8; the same direction jumps 0; from rest the whole speed."""
    jump = 0.5
    d = np.array([[0.2, 0.0], [-0.2, 0.0], [-0.2, 0.0], [0.0, 0.2]])
    p = plan(d, np.full(4, 1.0), np.full(4, 1e9), 0.4, 1e6, junction_jump_rad_s=10.0)
    np.testing.assert_allclose(p.v_peak, 0.4)
    s_in, s_out = sharp_junctions(d, p, jump)
    # entries: from rest (0.4 ≤ J: not sharp), a reversal (2 · 0.4), straight on (0), a
    # right angle (|(0,1) − (−1,0)|∞ = 1 → 0.4: not sharp)
    assert s_in.tolist() == [False, True, False, False]
    assert s_out.tolist() == [True, False, False, False]
    p = plan(d, np.full(4, 1.0), np.full(4, 1e9), 0.6, 1e6, junction_jump_rad_s=10.0)
    s_in, s_out = sharp_junctions(d, p, jump, stop_after=np.array([False, True, False, True]))
    assert s_in.tolist() == [True, True, True, True]  # 0.6 from rest; 1.2; rest; 0.6
    assert s_out.tolist() == [True, True, True, True]  # 1.2; to rest; 0.6; to rest


def test_ramp_fractions_cut_the_piece_at_a_sharp_junction() -> None:
    """A one-piece ramp up from a sharp junction is kept as its own piece: cut to
    `SHARP_SHARE` of the least piece where that piece lasts `sharp_s` at the junction's
    speed, else grown to the least piece; without the flag it joins the cruise (one piece)."""
    a, piece, least = 45.0, 0.01, 0.002
    d = np.array([[0.1, 0.0], [-0.3, 0.0]])
    p = plan(d, np.array([1.0, 3.0]), np.full(2, 1e9), 0.4, a, junction_jump_rad_s=0.5)
    assert p.v_entry[1] == pytest.approx(0.25)  # the reversal's cap: J / 2
    dist = np.abs(d).max(axis=1)
    counts, f = ramp_fractions(p, dist, a, piece, least)
    assert counts.tolist() == [1, 1]  # every ramp fits one piece: joined
    sharp = (np.array([False, True]), np.array([True, False]))
    short = SHARP_SHARE * least  # 1.2 mrad: 4.8 ms at the junction's 0.25 rad/s
    lasts = short / 0.25
    for sharp_s, first in ((0.95 * lasts, short), (1.05 * lasts, least)):
        counts, f = ramp_fractions(p, dist, a, piece, least, sharp, sharp_s)
        assert counts.tolist() == [2, 2]
        ends = f[counts[0]:] * dist[1]
        # the ramp up (0.25 → 0.4 at 45 rad/s²: 1.1 mrad) cut to the sharp piece, or grown
        assert ends[0] == pytest.approx(first)
        assert (1.0 - f[0]) * dist[0] == pytest.approx(first)


def test_ramp_fractions_cut_ramps_into_short_pieces() -> None:
    a, vmax = 45.0, 6.0
    d = np.array([[2.0, -1.0]])  # one long move from rest to rest, with a cruise
    p = plan(d, np.array([10.0]), np.array([1e9]), vmax, a)
    piece = 0.005
    counts, f = ramp_fractions(p, np.array([2.0]), a, piece)
    assert counts.sum() == f.size and f[-1] == 1.0 and np.all(np.diff(f) > 0)
    # time of each piece under the trapezoid: ramps cut into ≤ piece, one cruise piece
    x = np.concatenate(([0.0], f * 2.0))
    v0, vp, dist = 0.0, p.v_peak[0], 2.0
    da = vp * vp / (2 * a)

    def time_at(s: float) -> float:
        if s <= da:
            return math.sqrt(2 * s / a)
        if s <= dist - da:
            return vp / a + (s - da) / vp
        return 2 * vp / a + (dist - 2 * da) / vp - math.sqrt(2 * (dist - s) / a)

    dt = np.diff([time_at(s) for s in x])
    assert (dt <= piece + 1e-9).sum() == dt.size - 1  # all but the cruise piece
    assert dt.max() == pytest.approx((dist - 2 * da) / vp, rel=1e-6)
    assert v0 == 0.0
    # a piece never shorter than asked
    assert vp == pytest.approx(vmax) and counts[0] == 2 * math.ceil(vmax / a / piece) + 1
    counts, f = ramp_fractions(p, np.array([2.0]), a, piece, min_piece_rad=0.01)
    assert np.diff(np.concatenate(([0.0], f * 2.0))).min() >= 0.01 - 1e-12
