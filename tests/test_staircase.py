"""The staircase's rules (compile.staircase module doc) on analytic cases, and the tent's
closed forms against a sampled profile and a bisection (independent of the closed forms)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fivebar_host.compile.staircase import (
    enforce_staircase,
    staircase_ratios,
    tent_duration,
    tent_mean,
)


def _sampled_mean(c_in: float, c_out: float, q: float, acc: float, top: float) -> float:
    t = (np.arange(40_000) + 0.5) / 40_000 * q
    return float(np.minimum(np.minimum(c_in + acc * t, c_out + acc * (q - t)), top).mean())


@pytest.mark.parametrize("seed", range(6))
def test_tent_mean_is_the_sampled_profiles_mean(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 200
    c_in = rng.uniform(0, 1, n) * np.where(rng.random(n) < 0.2, 0.0, 1.0)
    c_out = np.where(rng.random(n) < 0.2, np.inf, rng.uniform(0, 1, n))
    top = np.where(rng.random(n) < 0.3, np.inf, rng.uniform(0.2, 1.5, n))
    q, acc = rng.uniform(0.001, 0.05, n), rng.uniform(5, 200, n)
    got = tent_mean((c_in, c_out), q, acc, top)
    for i in range(n):
        want = _sampled_mean(c_in[i], min(c_out[i], 1e9), q[i], acc[i], top[i])
        assert got[i] == pytest.approx(want, rel=1e-4, abs=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_tent_duration_is_the_least_time_that_covers_the_move(seed: int) -> None:
    """The closed form against a bisection on the sampled mean: x ≤ q·mean(q) at the
    returned q, and not a hair before it."""
    rng = np.random.default_rng(100 + seed)
    n = 60
    x = rng.uniform(1e-4, 0.05, n)
    c_in = np.where(rng.random(n) < 0.25, 0.0, rng.uniform(0, 1, n))
    c_out = np.where(rng.random(n) < 0.25, np.inf, rng.uniform(0, 1, n))
    top = np.where(rng.random(n) < 0.3, np.inf, rng.uniform(0.3, 1.5, n))
    acc = rng.uniform(5, 200, n)
    q = tent_duration(x, (c_in, c_out), acc, top)
    for i in range(n):
        lo, hi = 0.0, 10.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if mid * _sampled_mean(c_in[i], min(c_out[i], 1e9), mid, acc[i], top[i]) >= x[i]:
                hi = mid
            else:
                lo = mid
        assert q[i] == pytest.approx(hi, rel=2e-4)


def test_a_joint_that_stood_still_starts_at_the_junctions_jump() -> None:
    """Joint A stands while B moves, then A moves alone: its speed jumps at the junction, as
    the continuous profile's does — bounded by J (a/J = 6 ms), not by a start from rest
    (√(2a/α) = 10 ms, the per-joint rule before)."""
    d = np.array([[0.0, 0.01], [0.003, 0.0], [0.03, 0.0]])
    out = enforce_staircase(d, np.array([1000, 100, 100]), None, 60.0, 0.5)
    assert out[1] == math.ceil(0.003 / 0.5e-6)
    jr, ar = staircase_ratios(d, out, None, 60.0, 0.5)
    assert jr.max() <= 1 + 1e-9 and ar.max() <= 1 + 1e-9


def test_a_cruise_at_its_top_speed_slows_for_a_slow_neighbour() -> None:
    """A long segment whose floor is its top speed (a feed) between two slow ones: a path
    speed that never exceeds the top must fall to what the slow neighbour reaches, so the
    segment's mean is a trapezoid's, below the top: x/P = top − (top − c)²/(2·acc·P) at each
    end (the same cap on both sides here)."""
    x_long, top = 0.02, 0.5  # rad, rad/s
    d = np.array([[0.0005, 0.0], [x_long, 0.0], [0.0005, 0.0]])
    floor = np.array([4000, round(x_long / top * 1e6), 4000])
    out = enforce_staircase(d, floor, None, 60.0, 0.5)
    assert out[1] > floor[1]
    # the neighbours' reach (x/p̂ + α·p̂/2, p̂ their durations up to √(2x/α)) caps its ends
    ph = min(out[0] * 1e-6, math.sqrt(2 * 0.0005 / 60.0))
    c = 0.0005 / ph + 30.0 * ph
    p = out[1] * 1e-6
    assert x_long / p <= top - 2 * (top - c) ** 2 / (2 * 60.0 * p) + 1e-9
    assert x_long / (p - 2e-6) > top - 2 * (top - c) ** 2 / (2 * 60.0 * (p - 2e-6))
    jr, ar = staircase_ratios(d, out, None, 60.0, 0.5, floor_us=floor)
    assert jr.max() <= 1 + 1e-9 and ar.max() <= 1 + 1e-9
