"""Throughput of the closed-form five-bar kinematics, side by side with bare formulas.

Prints points/s (median of several runs) for 10^6 random reachable points:
- inverse with checks (validity mask, reason codes) vs the same atan2 formulas bare;
- forward with the assembly chosen per point vs the same intersection formulas bare.

Run: python benchmarks/kinematics.py [--n 1000000] [--repeat 7]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

# Run as a script, this file's folder comes first on sys.path and its name would shadow the
# `kinematics` package: drop that folder before importing the package.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]
from kinematics.fivebar import FiveBar  # noqa: E402


def bare_inverse(fb: FiveBar, p: np.ndarray, s1: float, s2: float) -> np.ndarray:
    """The inverse formulas of kinematics.fivebar without any checks (reference speed)."""
    out = np.empty_like(p)
    for i, (mx, a, b, s) in enumerate(((0.0, fb.a1, fb.b1, s1), (fb.w, fb.a2, fb.b2, s2))):
        dx = p[:, 0] - mx
        dy = p[:, 1]
        csq = dx * dx + dy * dy
        c = np.sqrt(csq)
        rk = s * np.sqrt((a + b + c) * (a + b - c) * (a - b + c) * (b - a + c))
        cc = csq + (a * a - b * b)
        out[:, i] = np.arctan2(dy * cc + dx * rk, dx * cc - dy * rk)
    return out


def bare_forward(fb: FiveBar, th: np.ndarray, sign: np.ndarray) -> np.ndarray:
    """The forward formulas of kinematics.fivebar without any checks (reference speed)."""
    x1 = fb.a1 * np.cos(th[:, 0])
    y1 = fb.a1 * np.sin(th[:, 0])
    dx = fb.w + fb.a2 * np.cos(th[:, 1]) - x1
    dy = fb.a2 * np.sin(th[:, 1]) - y1
    lsq = dx * dx + dy * dy
    lng = np.sqrt(lsq)
    b1, b2 = fb.b1, fb.b2
    rk = sign * np.sqrt((b1 + b2 + lng) * (b1 + b2 - lng) * (b1 - b2 + lng) * (b2 - b1 + lng))
    along = lsq + (b1 * b1 - b2 * b2)
    inv = 0.5 / lsq
    return np.stack((x1 + (along * dx - rk * dy) * inv, y1 + (along * dy + rk * dx) * inv), 1)


def median_time(fn: Callable[[], object], repeat: int) -> float:
    """Median wall time of `repeat` calls after one warm-up call."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()

    fb = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    rng = np.random.default_rng(1)
    # Random reachable points: sample motor angles, keep the forward solutions.
    th = rng.uniform(0.0, np.pi, size=(3 * args.n, 2))
    fwd = fb.forward_batch(th, "+")
    pts = fwd.points[fwd.valid][: args.n]
    assert pts.shape[0] == args.n, "not enough reachable samples"
    mode = "+-"
    angles = fb.inverse_batch(pts, mode).require()
    sign = np.where(rng.random(args.n) < 0.5, 1.0, -1.0)

    t_inv = median_time(lambda: fb.inverse_batch(pts, mode), args.repeat)
    t_inv_bare = median_time(lambda: bare_inverse(fb, pts, 1.0, -1.0), args.repeat)
    t_fwd = median_time(lambda: fb.forward_batch(angles, sign), args.repeat)
    t_fwd_bare = median_time(lambda: bare_forward(fb, angles, sign), args.repeat)

    n = args.n
    print(f"five-bar kinematics, {n} reachable points, median of {args.repeat} runs")
    print(f"{'method':44s} {'Mpoints/s':>10s} {'ms':>8s}")
    rows = [
        ("inverse, with checks (mask + reasons)", t_inv),
        ("inverse, bare formulas", t_inv_bare),
        ("forward, assembly per point, with checks", t_fwd),
        ("forward, bare formulas", t_fwd_bare),
    ]
    for name, t in rows:
        print(f"{name:44s} {n / t / 1e6:10.1f} {t * 1e3:8.1f}")
    print(f"inverse checks overhead: {t_inv / t_inv_bare:.2f}x (target ≤ 1.5x, ≥ 15 M/s)")
    print(f"forward checks overhead: {t_fwd / t_fwd_bare:.2f}x (target ≥ 10 M/s)")
    err = np.abs(bare_inverse(fb, pts, 1.0, -1.0) - angles).max()
    print(f"max |checked − bare| inverse angle difference: {err:.1e} rad")


if __name__ == "__main__":
    main()
