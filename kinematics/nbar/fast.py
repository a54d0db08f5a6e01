"""The fast path of a sweep: the same steps as `Tracker.attempt`, in blocks and a tight loop.

In the common case of a sweep (square system, Newton converging from the predictor, the step
accepted by the branch-flip guard) the per-step machinery of `Tracker.advance` is not needed.
`FastPath.run` takes such steps with the history ring's arrays in local variables:

- blocks: up to BLOCK equal steps are predicted and corrected together (one batched Newton
  step, a second one when the first did not certify the first SECOND_PASS states), each state
  passing the tests of a single step (`kinematics.nbar.guard.step_accepted`). A block is
  predicted from the last HISTORY equal steps (degree-(HISTORY − 1) extrapolation), or with
  fewer, from the Taylor series of the branch (`FastPath.taylor`: Φ is quadratic, so its
  coefficients follow from one Jacobian, order by order), as far as that series is trusted;
- single steps: extrapolate the equal steps of this sweep at the end of the history (binomial
  weights, `kinematics.nbar.history.UNIFORM`), one Newton step accepted by the quadratic
  remainder bound or by the residual, or more from there;
- fold look-ahead: near a fold the branch moves as √(t* − t), so ‖Δq‖² per step grows like
  1/(t* − t); when it grew FOLD_AHEAD-fold in the last step the fold is likely within the next
  one, and the sweep asks `Tracker.advance` to look for it before trying that step.

It stops at the first step that needs anything else (subdivision, a limit, least squares),
leaving the tracker at the last accepted state; `sweep(..., fast=False)` runs every step through
`Tracker.advance` instead (the reference path), with the same results within the tolerance.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray
from kinematics.nbar.guard import NO_PREVIOUS, step_accepted
from kinematics.nbar.history import HISTORY, UNIFORM
from kinematics.nbar.system import CONTRACTION, newton_raw, solve

if TYPE_CHECKING:
    from kinematics.nbar.tracker import Tracker

#: Equal sweep steps predicted and corrected together once HISTORY of them are known, and
#: the fewest worth a block.
BLOCK = 12
MIN_BLOCK = 4
#: A block takes its second batched Newton step only when the first leaves one of its first
#: SECOND_PASS states uncertified (otherwise the states before the first uncertified one are kept).
SECOND_PASS = 8
#: When ‖Δq‖² grew FOLD_AHEAD-fold in the last step, a fold is likely within the next one.
FOLD_AHEAD = 1.75
#: Order of the Taylor series of the branch that predicts a block (`FastPath.taylor`).
TAYLOR = 8
#: A block reaches as far as the Taylor series' last term stays below TAYLOR_TOL of its first.
TAYLOR_TOL = 1e-4


def _block_weights(newest: int) -> FloatArray:
    """(2·BLOCK, HISTORY) ring weights: rows j < BLOCK extrapolate the degree-(HISTORY − 1)
    polynomial through the last HISTORY equally spaced states j + 1 steps ahead; row
    BLOCK + j gives the predicted motion of that step (from the state before it)."""
    nodes = [-float(i) for i in range(HISTORY)]  # node i (t = −i) sits in slot newest − i
    pred = np.zeros((BLOCK, HISTORY))
    for j in range(1, BLOCK + 1):
        for i, ti in enumerate(nodes):
            w = 1.0
            for k, tk in enumerate(nodes):
                if k != i:
                    w *= (j - tk) / (ti - tk)
            pred[j - 1, (newest - i) % HISTORY] = w
    before = np.vstack((np.eye(HISTORY)[newest], pred[:-1]))
    return np.vstack((pred, pred - before))


_BLOCKS = [_block_weights(p) for p in range(HISTORY)]
#: _POWERS[j, k] = j^k: the Taylor series at the grid steps j = 0 … BLOCK ahead.
_POWERS = np.arange(BLOCK + 1, dtype=np.float64)[:, None] ** np.arange(TAYLOR + 1)
#: _RING_SLOTS[slot][a]: ring slots of the last min(a, HISTORY) of a new states after `slot`.
_RING_SLOTS = [[np.arange(slot + 1 + a - min(a, HISTORY), slot + 1 + a) % HISTORY
                for a in range(BLOCK + 1)] for slot in range(HISTORY)]


def rows(first: int, count: int, direction: int) -> slice:
    """Table rows first, first + direction, … (count of them) as a slice."""
    stop = first + direction * count
    return slice(first, stop if stop >= 0 else None, direction)


def _accepted_prefix(good: NDArray[np.bool_]) -> tuple[int, int, int]:
    """(states accepted, next block size, single steps before the next block) after a block
    whose per-state tests gave `good`: the states before the first failure are kept; a block
    costs about as much as four single steps whatever its size, so after one that accepts
    fewer than MIN_BLOCK states, BLOCK single steps come first."""
    a = int(good.argmin())
    if good[a]:
        return good.size, BLOCK, 0
    if a >= MIN_BLOCK:
        return a, a, 0
    return a, BLOCK, BLOCK


def _keep(ring: FloatArray, slot: int, hs: list[float], qs: FloatArray, s: float,
          h: float) -> int:
    """Append a block's accepted states qs (taken in equal steps h from path parameter s)
    to the history ring and parameters `hs`; return the new newest slot."""
    a = qs.shape[0]
    keep = min(a, HISTORY)
    ring[_RING_SLOTS[slot][a]] = qs[a - keep:]
    hs.extend([s + h * (j + 1) for j in range(a - keep, a)])
    del hs[:-HISTORY]
    return int((slot + a) % HISTORY)


class FastPath:
    """A sweep's fast path for one tracker: its work rows, and the block size and cool-down
    carried from one `run` to the next."""

    def __init__(self, tr: Tracker) -> None:
        sysm = tr.sys
        self.tr = tr
        self.hs, self.hs_t, self.hs_half = sysm.hs, sysm.hs_t, sysm.hs_half
        self.xs = np.ones((BLOCK, sysm.size))  # work rows for blocks (last column stays 1)
        self.tx = np.zeros((TAYLOR + 1, sysm.size))  # `taylor`'s work rows
        self.tx[0, -1] = 1.0
        self.thx = np.empty((sysm.m, TAYLOR - 1, sysm.size))
        self.bsize = BLOCK  # block size of `run`
        self.cool = 0  # single steps to take before the next block (after a poor block)
        self.stuck = 0  # iterations of the refused step that stopped `run` (0: none)
        self.fold_ahead = False  # `run` stopped because a fold is likely in the next step

    def fresh(self) -> None:
        """The tracker's history was replaced (`Tracker.replay`): blocks may start at once."""
        self.bsize, self.cool = BLOCK, 0

    def taylor(self, q: FloatArray, u: FloatArray, d: FloatArray) -> FloatArray:
        """(TAYLOR + 1, n) Taylor coefficients in t of the branch through the solved state q at
        input u as the inputs move along u + t·d.

        Φ is quadratic, Φ_r = ½ xᵀ∇²Φ_r x, so with x(t) = Σ_k x_k tᵏ the coefficient of tᵏ in
        Φ_r(x(t)) = 0 is x_0ᵀ∇²Φ_r x_k + ½ Σ_{0<i<k} x_iᵀ∇²Φ_r x_(k−i) = 0: with G = ∇²Φ x_0,
        J q_k = −G_e e_k − ½ Σ_{0<i<k} x_iᵀ∇²Φ_r x_(k−i), where e_k are the known Taylor
        coefficients of the input-driven entries (`InputBasis.taylor`). One Jacobian for every
        order; the series converges up to the nearest singular point of the branch (a fold),
        so far from one it predicts a whole block of steps to near rounding.
        """
        n, m = self.tr.n, self.tr.m
        x = self.tx
        x[0, :n] = q
        x[:, n:-1] = self.tr.mech.basis.taylor(u, d, TAYLOR)
        hx = self.thx  # hx[:, i − 1] = ½∇²Φ x_i as (m, N) rows, for i = 1 … TAYLOR − 1
        g0 = (self.hs @ x[0]).reshape(m, -1)
        neg_jac = -g0[:, :n]
        ge = g0[:, n:-1] @ x[1:, n:-1].T  # column k − 1: G_e e_k
        for k in range(1, TAYLOR + 1):
            rhs = ge[:, k - 1]
            if k > 1:
                rhs = rhs + hx[:, : k - 1].reshape(m, -1) @ x[k - 1: 0: -1].ravel()
            x[k, :n] = solve(neg_jac, rhs)
            if k < TAYLOR:
                hx[:, k - 1] = (self.hs_half @ x[k]).reshape(m, -1)
        return x[:, :n]

    def _taylor_block(self, q: FloatArray, u: FloatArray, d: FloatArray, left: int
                      ) -> tuple[FloatArray, FloatArray] | None:
        """(predictions, predicted motions) of the next steps from the Taylor series of the
        branch at q, as far as its last term stays below TAYLOR_TOL of its first (the
        truncation error is of that order while it converges); None if under MIN_BLOCK."""
        coef = self.taylor(q, u, d)
        first2, last2 = float(coef[1] @ coef[1]), float(coef[-1] @ coef[-1])
        if not (first2 > 0.0 and last2 < math.inf):  # no motion, or singular
            reach = 0
        elif last2 > 0.0:  # ‖c_K‖ jᴷ ≤ TAYLOR_TOL·‖c_1‖ j
            reach = int((TAYLOR_TOL * TAYLOR_TOL * first2 / last2) ** (0.5 / (TAYLOR - 1)))
        else:
            reach = BLOCK
        b = min(BLOCK, left, reach)
        if not b >= MIN_BLOCK:
            return None
        pw = _POWERS[: b + 1] @ coef
        preds = pw[1:]
        return preds, preds - pw[:-1]

    def _correct_block(self, preds: FloatArray, driven: FloatArray
                       ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], int]:
        """One batched Newton step for every predicted state (one product evaluates every Φ
        and J, one call solves all the systems), a second one when the first does not certify
        the first SECOND_PASS states. Returns (states, corrections², converged, iterations)."""
        tr = self.tr
        n, m, bound, accept = tr.n, tr.m, tr.bound, tr.accept
        b = preds.shape[0]
        xb = self.xs[:b]
        xb[:, :n] = preds
        xb[:, n:-1] = driven
        gb = (xb @ self.hs_t).reshape(b, m, -1)
        phis = 0.5 * (gb @ xb[:, :, None])[:, :, 0]
        steps = solve(gb[:, :, :n], phis)
        c2s = np.einsum("ij,ij->i", steps, steps)
        conv = bound * c2s <= accept
        qs_b = preds - steps
        if conv[:SECOND_PASS].all():
            return qs_b, c2s, conv, 1
        # The residuals themselves (the bound is pessimistic, by about tenfold); if they do
        # not certify the first SECOND_PASS states either, a second Newton step for all of
        # them: a state is then converged when, as in `newton`, its residual dropped 100-fold
        # and the remainder bound of the second step certifies it.
        xb[:, :n] = qs_b
        gb = (xb @ self.hs_t).reshape(b, m, -1)
        phi1 = 0.5 * (gb @ xb[:, :, None])[:, :, 0]
        r1 = np.einsum("ij,ij->i", phi1, phi1)
        conv |= r1 <= tr.tol2
        if conv[:SECOND_PASS].all():
            return qs_b, c2s, conv, 1
        steps2 = solve(gb[:, :, :n], phi1)
        conv |= ((r1 <= CONTRACTION * np.einsum("ij,ij->i", phis, phis))
                 & (bound * np.einsum("ij,ij->i", steps2, steps2) <= accept))
        qs_b = qs_b - steps2
        dc = qs_b - preds
        return qs_b, np.einsum("ij,ij->i", dc, dc), conv, 2

    def _block(self, ring: FloatArray, slot: int, full: bool, q: FloatArray, u: FloatArray,
               d: FloatArray, left: int, xtab: FloatArray, first: int, direction: int,
               last_m2: float) -> tuple[FloatArray, FloatArray, int, int, int] | None:
        """Predict, correct and test the next block of steps from the state q at input u:
        from the ring when it holds HISTORY equal steps (`full`), else from the Taylor series
        (None when that reaches fewer than MIN_BLOCK steps). Returns (states, predicted
        motions², states accepted, iterations, single steps before the next block) and sets
        the next block's size."""
        if full:
            pw = _BLOCKS[slot] @ ring
            b = min(self.bsize, left)
            preds, dms = pw[:b], pw[BLOCK: BLOCK + b]
        else:
            tb = self._taylor_block(q, u, d, left)
            if tb is None:
                return None
            preds, dms = tb
        qs_b, c2s, conv, its = self._correct_block(
            preds, xtab[rows(first, preds.shape[0], direction)])
        m2s = np.einsum("ij,ij->i", dms, dms)
        prev = np.concatenate(((last_m2 if last_m2 > 0.0 else NO_PREVIOUS,), m2s[:-1]))
        good = conv & step_accepted(c2s, m2s, prev, self.tr.floor2)
        a, self.bsize, cool = _accepted_prefix(good)
        return qs_b, m2s, a, its, cool

    def run(self, index: int, direction: int, count: int, grid: FloatArray,
            xtab: FloatArray, out_q: FloatArray, out_it: NDArray[np.int64], pos: int) -> int:
        """Take up to `count` sweep steps from grid row `index` in `direction` (±1); return
        the number taken, their states in out_q[pos:], their iterations in out_it[pos:].
        `grid` holds the sweep's input rows and `xtab` x's driven entries for them. When a
        single step to the next row was tried and refused (as `attempt` would refuse it: same
        predictor, same Newton iterates, same tests), `stuck` holds its Newton iterations,
        else 0; `fold_ahead` says it stopped before a step that likely holds a fold."""
        tr = self.tr
        self.stuck = 0
        self.fold_ahead = False
        if tr.lsq:
            return 0
        hist = tr.hist
        hs_, ring, slot, run = hist.s, hist.ring, hist.slot, hist.run
        h = float(direction)
        if run >= 2 and abs(hs_[-1] - hs_[-2] - h) > 1e-9:
            run = 1  # the history does not end in equal steps of this sweep: start afresh
        x, n, hsm, m, d = tr.x, tr.n, self.hs, tr.m, h * tr.inc
        bound, accept, floor2 = tr.bound, tr.accept, tr.floor2
        last_m2 = tr.last_m2 if tr.last_h == 1.0 else 0.0
        s, taken, q, cool = hs_[-1], 0, tr.q, self.cool
        while taken < count:
            if cool == 0 and count - taken >= MIN_BLOCK:
                blk = self._block(ring, slot, run == HISTORY, q, grid[index + direction * taken],
                                  d, count - taken, xtab, index + direction * (taken + 1),
                                  direction, last_m2)
                if blk is None:  # the Taylor series reaches too few steps
                    cool = BLOCK
                    continue
                qs_b, m2s, a, its, cool = blk
                if a:
                    slot = _keep(ring, slot, hs_, qs_b[:a], s, h)
                    run = min(run + a, HISTORY)
                    s += h * a
                    last_m2 = float(m2s[a - 1])
                    q = qs_b[a - 1]
                    out_q[pos + taken: pos + taken + a] = qs_b[:a]
                    out_it[pos + taken: pos + taken + a] = its
                    taken += a
                    continue
            if run < 2:  # no history to extrapolate from: `attempt` takes this step
                break
            if run >= 3:
                d1 = ring[slot] - ring[(slot - 1) % HISTORY]
                d0 = ring[(slot - 1) % HISTORY] - ring[(slot - 2) % HISTORY]
                if float(d1 @ d1) >= FOLD_AHEAD * float(d0 @ d0):
                    self.fold_ahead = True  # `advance` looks for the fold first
                    break
            pred = UNIFORM[run, slot] @ ring  # (prediction, predicted motion)
            q_pred = pred[0]
            x[:n] = q_pred
            x[n:-1] = xtab[index + direction * (taken + 1)]
            gm = (hsm @ x).reshape(m, -1)
            step = solve(gm[:, :n], 0.5 * (gm @ x))
            c2 = float(step @ step)
            if not c2 < math.inf:  # singular Jacobian
                self.stuck = 1
                break
            q_new = q_pred - step
            its = 1
            if not bound * c2 <= accept:  # the bound is not enough: look at the residual
                more = newton_raw(tr.sys, x, q_new, tr.tol, tr.max_iter - 1)
                if not more.converged:
                    self.stuck = 1 + more.iterations
                    break
                if more.iterations:  # not converged yet at q_new: Newton carried on
                    q_new, its = more.q, 1 + more.iterations
                    dc = q_new - q_pred
                    c2 = float(dc @ dc)
            dm = pred[1]
            m2 = float(dm @ dm)
            if not step_accepted(c2, m2, last_m2 if last_m2 > 0.0 else NO_PREVIOUS, floor2):
                self.stuck = its
                break
            q = q_new
            slot = (slot + 1) % HISTORY
            ring[slot] = q
            s += h
            hs_.append(s)
            if len(hs_) > HISTORY:
                del hs_[0]
            if run < HISTORY:
                run += 1
            last_m2 = m2
            out_q[pos + taken] = q
            out_it[pos + taken] = its
            taken += 1
            if cool:
                cool -= 1
        self.cool = cool
        if taken:
            hist.slot, hist.run, tr.q = slot, run, q
            tr.u = grid[index + direction * taken]
            tr.last_m2, tr.last_h = last_m2, 1.0
            tr.tangent_cache = None
        return taken
