"""The predictor's history: the last HISTORY solved states along the input path, in a ring.

The Newton start of a step is extrapolated through these states (`History.predict`): on
equally spaced ones by the binomial weights of a degree-(run − 1) polynomial, else through up
to four of them with Lagrange weights whose sum of magnitudes is bounded (MAX_WEIGHT, so that
the rounding of the states is not amplified). The fast path of a sweep reads the ring's arrays
directly in its inner loop (no method call per step) and writes its slot and run back.
"""

from __future__ import annotations

import math

import numpy as np

from kinematics.arrays import FloatArray

#: Most states the predictor extrapolates through (order HISTORY − 1 on equal steps).
HISTORY = 7
#: Largest sum of |Lagrange weights| accepted for the predictor (bounds noise amplification).
MAX_WEIGHT = 16.0


def _ring_weights(points: int, newest: int) -> FloatArray:
    """(2, HISTORY) weights over the ring buffer of states whose newest entry is in slot
    `newest`: row 0 extrapolates one equal step beyond `points` equally spaced states,
    q_new = Σ_j (−1)^(j+1) C(p, j) q_(k+1−j); row 1 gives the predicted motion q_new − q_k."""
    w = np.zeros((2, HISTORY))
    for j in range(1, points + 1):
        w[0, (newest - j + 1) % HISTORY] = (-1) ** (j + 1) * math.comb(points, j)
    w[1] = w[0]
    w[1, newest] -= 1.0
    return w


#: UNIFORM[run, slot]: `_ring_weights(run, slot)` for every run ≥ 2 and newest slot.
UNIFORM = {(k, p): _ring_weights(k, p) for k in range(2, HISTORY + 1) for p in range(HISTORY)}


class History:
    """The last HISTORY states (`ring`, newest in `slot`), their path parameters `s` (oldest
    first) and `run`, the number of trailing equally spaced ones."""

    __slots__ = ("ring", "run", "s", "slot")

    def __init__(self, n: int) -> None:
        self.ring = np.zeros((HISTORY, n))
        self.slot = HISTORY - 1
        self.s: list[float] = []
        self.run = 0

    def copy(self) -> History:
        """An independent copy (for a tracker's snapshot)."""
        out = History(self.ring.shape[1])
        out.set_to(self)
        return out

    def set_to(self, other: History) -> None:
        """Take `other`'s contents (the ring is copied in place)."""
        self.ring[:] = other.ring
        self.slot, self.run, self.s = other.slot, other.run, list(other.s)

    def restart(self) -> None:
        """Forget every state (the next `push` starts a new history)."""
        self.s = []
        self.run = 0

    def push(self, q: FloatArray, s: float) -> None:
        """Append the state q at path parameter s."""
        hs = self.s
        if s in hs:  # an input value revisited (back from a limit): restart the history
            del hs[:-1]
            self.run = 1
        if len(hs) >= 2:
            h_new, h_old = s - hs[-1], hs[-1] - hs[-2]
            self.run = self.run + 1 if abs(h_new - h_old) <= 1e-9 * abs(h_new) else 2
        else:
            self.run = len(hs) + 1
        self.slot = slot = (self.slot + 1) % HISTORY
        self.ring[slot] = q
        hs.append(s)
        if len(hs) > HISTORY:
            del hs[0]
        if self.run > len(hs):
            self.run = len(hs)

    def last_step(self) -> FloatArray:
        """q_k − q_(k−1): the newest state's motion from the one before."""
        return np.asarray(self.ring[self.slot] - self.ring[(self.slot - 1) % HISTORY],
                          dtype=np.float64)

    def predict(self, s_new: float) -> FloatArray | None:
        """The state extrapolated to path parameter s_new: through the trailing equally
        spaced states when s_new continues them, else through up to four states with bounded
        Lagrange weights; None when there are fewer than two or no weights are bounded."""
        hs = self.s
        k = len(hs)
        if k < 2:
            return None
        h = s_new - hs[-1]
        if self.run >= 2 and abs(h - (hs[-1] - hs[-2])) <= 1e-9 * abs(h):
            return np.asarray(UNIFORM[self.run, self.slot][0] @ self.ring, dtype=np.float64)
        for order in range(min(k, 4), 1, -1):
            pts = hs[-order:]
            w = [1.0] * order
            for a in range(order):
                for b in range(order):
                    if a != b:
                        w[a] *= (s_new - pts[b]) / (pts[a] - pts[b])
            if sum(map(abs, w)) <= MAX_WEIGHT:
                wf = np.zeros(HISTORY)
                for j, wj in enumerate(reversed(w)):  # newest first
                    wf[(self.slot - j) % HISTORY] = wj
                return np.asarray(wf @ self.ring, dtype=np.float64)
        return None
