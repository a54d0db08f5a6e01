"""An independent check of the staircase's limits (compile.staircase module doc): a plain
loop over the segments, each end's cap found junction by junction, the tent's mean sampled —
no code shared with `compile.staircase` (used by tests/test_planner.py and
tests/test_job_timing.py)."""

from __future__ import annotations

import math

import numpy as np


def tent_mean_sampled(c_in: float, c_out: float, q: float, acc: float, top: float) -> float:
    """The highest mean speed over q from c_in to c_out at rate acc under top, by sampling
    the profile min(c_in + acc·t, c_out + acc·(q − t), top) (an independent check of the
    closed form)."""
    t = (np.arange(20_000) + 0.5) / 20_000 * q
    return float(np.minimum(np.minimum(c_in + acc * t, c_out + acc * (q - t)), top).mean())


def staircase_reference(dth: np.ndarray, us: np.ndarray, stop: np.ndarray, alpha: float,
                         jump: float, length: np.ndarray | None = None,
                         floor: np.ndarray | None = None) -> tuple[float, float]:
    """Worst (J1) and (A1) ratios (compile.staircase module doc) by a plain loop over the
    segments: each end's cap the smaller of J/δ (0 at a stop) and what the neighbour's mean
    speed reaches there, the tent's mean sampled."""
    t = us * 1e-6
    d = np.abs(dth).max(axis=1)
    x = d if length is None else np.where(length > 0, length, d)
    g = [dth[i] / x[i] if d[i] > 0 else np.zeros(2) for i in range(len(t))]
    acc = [alpha * x[i] / d[i] if d[i] > 0 else alpha for i in range(len(t))]
    w, s = dth / t[:, None], x / t
    top = x / (floor * 1e-6) if floor is not None else np.full(len(t), math.inf)
    worst_j = worst_a = 0.0
    k = len(t)
    for i in range(k):
        if i > 0:
            worst_j = max(worst_j, float(np.abs(w[i] - w[i - 1]).max()) / jump)
        if d[i] == 0:
            continue
        first = i == 0 or stop[i - 1] or d[i - 1] == 0
        last = i == k - 1 or stop[i] or d[i + 1] == 0
        caps = [0.0 if first else math.inf, 0.0 if last else math.inf]
        if first or last:  # from or to standstill
            worst_j = max(worst_j, float(np.abs(w[i]).max()) / jump)
        for side, j in ((0, i - 1), (1, i + 1)):
            if 0 <= j < k and d[j] > 0:
                delta = float(np.abs(g[i] - g[j]).max())
                reach = s[j] + acc[j] * t[j] / 2
                caps[side] = min(caps[side], reach, jump / delta if delta > 0 else math.inf)
        worst_a = max(worst_a, s[i] / tent_mean_sampled(caps[0], caps[1], t[i], acc[i], top[i]))
    return worst_j, worst_a
