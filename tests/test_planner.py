"""Planner: closed-form forward/backward passes against a plain loop, analytic rest-to-rest
times, and the limits it promises (joint speed, pen feed, acceleration between junctions)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fivebar_host.planner import check_plan, plan


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
