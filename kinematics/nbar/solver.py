"""Simulation (Algorithm 1): perturb the inputs, solve by Newton–Raphson from the previous states.

On top of the paper's loop:
- predictor: the Newton start is extrapolated along the input path from the last states (up to
  seven equally spaced ones, else up to four with bounded Lagrange weights), or from the tangent
  q' = −J⁺ ∂Φ/∂u when there is no history; from the previous state alone Newton would need
  several more iterations. In sweeps, up to BLOCK equal steps are predicted and corrected
  together (one batched Newton step, a second one when the first did not certify the first
  SECOND_PASS states), each state passing the tests of a single step. A sweep's first block,
  with no history yet, is predicted by the Taylor series of the branch (`_Tracker.taylor`:
  Φ is quadratic, so its coefficients follow from one Jacobian, order by order);
- branch-flip guard: a step is accepted only if Newton's correction from the predictor is at
  most half the predicted motion, and the predicted motion at most MAX_SPEEDUP times the last
  step's (continuity). A jump to the other assembly is a correction of the order of the
  distance between the branches that does not shrink with the step, so the step is halved until
  the correction is small, or the step falls below the resolution;
- motion limit: when a step fails, a fold (turning point) of the solution curve within it is
  looked for directly (`_Tracker.fold_limit`: Newton on Φ = 0, J·v = 0; in sweeps already
  before the step when the last step's motion grew FOLD_AHEAD-fold, as it does next to a
  fold); if there is one on the
  branch being followed, the state just before it and the input just past it are reported, less
  than 2^-max_halvings of the step apart. Otherwise the step is halved, and when even the
  smallest step (2^-max_halvings of an input step) fails, the input value reached and the one
  that failed are reported with the reason (singular Jacobian or no convergence);
  `sweep(..., reverse_at_limit=True)` then runs the input back to trace a rocker's whole range;
- least squares: with more equations than unknowns the steps are Gauss–Newton steps; redundant
  equations that disagree on every motion (rounded data of an over-constrained linkage) are
  reported as `INCONSISTENT`, not as a limit.
Every solved state is checked again with the paper's exact equations (`Mechanism.residuals`);
that is the residual reported per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.nbar.constraints import FloatArray
from kinematics.nbar.model import Mechanism, Settings
from kinematics.nbar.system import CONTRACTION, newton_raw, solve

#: Newton may correct the predictor by at most this fraction of the predicted motion.
CONTINUITY = 0.5
#: Largest first-order inconsistency (relative) of redundant equations still taken as mobile.
LOCK_TOLERANCE = 1e-7
#: Largest sum of |Lagrange weights| accepted for the predictor (bounds noise amplification).
MAX_WEIGHT = 16.0
#: Several inputs: a turn of the input path sharper than 10° restarts the predictor.
CORNER_COS = math.cos(math.radians(10.0))


class Status(IntEnum):
    """Per-step outcome. OK and SUBDIVIDED rows hold a solved state."""

    OK = 0  # solved with the full step
    SUBDIVIDED = 1  # solved after splitting the step (continuity or convergence)
    LIMIT = 2  # motion limit: this row holds the last configuration reached, at its input value
    INCONSISTENT = 3  # redundant equations admit no motion (see LimitReport.reason)
    UNREACHED = 4  # after a limit: not attempted


@dataclass(frozen=True)
class LimitReport:
    """Where and why the motion stopped."""

    kind: Literal["limit", "inconsistent"]
    row: int
    reached: FloatArray
    failed: FloatArray
    requested: FloatArray
    reason: str
    residual: float

    def __str__(self) -> str:
        fmt = ", ".join
        if self.kind == "inconsistent":
            return (f"inconsistent constraints at input ({fmt(f'{v:.10g}' for v in self.reached)}"
                    f"): {self.reason}")
        return (f"motion limit between input ({fmt(f'{v:.10g}' for v in self.reached)}) and "
                f"({fmt(f'{v:.10g}' for v in self.failed)}) on the way to "
                f"({fmt(f'{v:.10g}' for v in self.requested)}): {self.reason}")


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated motion: per row the input values, every joint's coordinates (NaN where
    not solved), the exact scaled residual, Newton iterations, accepted sub-steps and status."""

    mechanism: Mechanism
    inputs: FloatArray
    coords: FloatArray
    residual: FloatArray
    iterations: NDArray[np.int64]
    substeps: NDArray[np.int64]
    status: NDArray[np.int8]
    limits: tuple[LimitReport, ...]
    reversed_at: int | None

    @property
    def completed(self) -> bool:
        """True when every requested row was solved."""
        return bool(np.all(self.status <= Status.SUBDIVIDED))

    @property
    def solved(self) -> NDArray[np.bool_]:
        """(N,) mask of rows that hold a configuration (OK, SUBDIVIDED or LIMIT)."""
        return np.asarray(self.status <= Status.LIMIT, dtype=bool)

    def path(self, name: str) -> FloatArray:
        """Trajectory (N, 2|3) of a point joint, or (N, 3) coordinates of a line / plane."""
        return self.mechanism.positions(self.coords, name)

    @property
    def status_names(self) -> list[str]:
        """Status per row as lower-case names."""
        return [Status(int(s)).name.lower() for s in self.status]


#: Newton iterations allowed for locating a fold (`_Tracker.fold_limit`), and its
#: convergence test: squared step ≤ FOLD_STEP2·(1 + ‖q‖²).
FOLD_ITERATIONS = 12
FOLD_STEP2 = 1e-20
#: Near a fold the branch moves as √(t* − t), so ‖Δq‖² per step grows like 1/(t* − t): when
#: it grew FOLD_AHEAD-fold in the last step, the fold is likely within the next one, and the
#: sweep looks for it before trying that step (saving the Newton iterations that would fail).
FOLD_AHEAD = 1.75
#: Why the motion stops at a located fold, and the reason reported for it.
FOLD_REASON = "no solution past the turning point"
FOLD_MESSAGE = (f"the constraint Jacobian is singular at the turning point (J·v = 0 there): "
                f"a dead centre, {FOLD_REASON} on this branch")


#: Most states the predictor extrapolates through (order HISTORY − 1 on equal steps).
HISTORY = 7
#: The predicted motion may exceed the previous step's by at most this factor (per unit step).
MAX_SPEEDUP = 4.0


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


_UNIFORM = {(k, p): _ring_weights(k, p) for k in range(2, HISTORY + 1) for p in range(HISTORY)}

#: Equal sweep steps predicted and corrected together once HISTORY of them are known, and
#: the fewest worth a block.
BLOCK = 12
MIN_BLOCK = 4


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
#: Order of the Taylor series of the branch that predicts a block (`_Tracker.taylor`).
TAYLOR = 8
#: A block reaches as far as the Taylor series' last term stays below TAYLOR_TOL of its first.
TAYLOR_TOL = 1e-4
#: _POWERS[j, k] = j^k: the Taylor series at the grid steps j = 0 … BLOCK ahead.
_POWERS = np.arange(BLOCK + 1, dtype=np.float64)[:, None] ** np.arange(TAYLOR + 1)
#: _RING_SLOTS[slot][a]: ring slots of the last min(a, HISTORY) of a new states after `slot`.
_RING_SLOTS = [[np.arange(slot + 1 + a - min(a, HISTORY), slot + 1 + a) % HISTORY
                for a in range(BLOCK + 1)] for slot in range(HISTORY)]


def _rows(first: int, count: int, direction: int) -> slice:
    """Table rows first, first + direction, … (count of them) as a slice."""
    stop = first + direction * count
    return slice(first, stop if stop >= 0 else None, direction)


#: A block takes its second batched Newton step only when the first leaves one of its first
#: SECOND_PASS states uncertified (otherwise the states before the first uncertified one are kept).
SECOND_PASS = 8


class _Snapshot(NamedTuple):
    """A tracker's state and predictor history (`_Tracker.snapshot`)."""

    u: FloatArray
    q: FloatArray
    ring: FloatArray
    slot: int
    hist_s: list[float]
    run: int
    last_m2: float
    last_h: float
    arc: float
    direction: FloatArray


class _Tracker:
    """Follows one branch of the solution set as the inputs change."""

    def __init__(self, mech: Mechanism, settings: Settings) -> None:
        self.mech = mech
        self.sys = mech.system
        self.settings = settings
        self.tol = settings.tolerance
        self.max_iter = settings.max_iterations
        self.min_frac = 2.0 ** -settings.max_halvings
        self.n = self.sys.n_u
        self.nd = self.sys.n_d
        self.single = len(mech.inputs) == 1
        self.lsq = mech.overdetermined
        self.x = self.sys.new_x()
        self.u = mech.input0.copy()
        self.q = mech.q0.copy()
        self.floor2 = (1e-9 * max(mech.size, 1.0)) ** 2
        self.ring = np.zeros((HISTORY, self.n))  # last states along the input path
        self.slot = HISTORY - 1  # ring slot of the newest state
        self.hist_s: list[float] = []  # their path parameters, oldest first
        self.run = 0  # trailing equally spaced states in the history
        self.last_m2 = 0.0  # predicted motion² and parameter step of the last accepted step
        self.last_h = 0.0
        self.origin = self.u.copy()
        self.direction = np.zeros_like(self.u)  # several inputs: direction of the last step
        self.arc = 0.0  # several inputs: arc length of the input path to the current state
        self.line: FloatArray | None = None  # sweeps: parameter = step index along `line`
        self.tangent_cache: FloatArray | None = None
        self.s_new = self.h_new = 0.0  # path parameter and length of the step being tried
        self.e_new = self.direction
        sysm = self.sys
        self.hs = sysm.hs
        self.hs_t = sysm.hs_t
        self.xs = np.ones((BLOCK, sysm.size))  # work rows for blocks (last column stays 1)
        self.tx = np.zeros((TAYLOR + 1, sysm.size))  # `taylor`'s work rows
        self.tx[0, -1] = 1.0
        self.thx = np.empty((sysm.m, TAYLOR - 1, sysm.size))
        self.hs_half = sysm.hs_half
        self.inc = np.zeros_like(self.u)  # sweeps: the input step
        self.bsize = BLOCK  # block size of `run_fast`
        self.stuck = 0  # `run_fast`: iterations of the refused step that stopped it (0: none)
        self.fold_ahead = False  # `run_fast` stopped because a fold is likely in the next step
        self.cool = 0  # single steps to take before the next block (after a poor block)
        self.m = sysm.m
        self.nact = sysm.n_act
        self.tol2 = self.tol * self.tol
        self.bound = 0.5 * sysm.curvature
        self.accept = 0.99 * self.tol  # remainder bound accepted (margin: solve's rounding)
        self._push(self.q, self._param(self.u))

    def set_line(self, base: FloatArray, inc: FloatArray) -> None:
        """Sweep mode: the inputs move along u = base + s·inc, and s is the parameter the
        predictor extrapolates in (the step index), whatever the number of inputs."""
        self.origin = np.asarray(base, dtype=np.float64).copy()
        self.inc = np.asarray(inc, dtype=np.float64).copy()
        self.line = self.inc / float(inc @ inc)
        self.hist_s = []
        self.run = 0
        self._push(self.q, self._param(self.u))

    # -- state helpers
    def _set_inputs(self, u: FloatArray, pre: FloatArray | None) -> None:
        """Put the driven coordinates and actuator entries for u into x (Eqs. 10–22); `pre`
        is them precomputed (`InputBasis.entries`)."""
        self.x[self.n: -1] = self.mech.basis.entries(u) if pre is None else pre

    def _param(self, u: FloatArray) -> float:
        """Path parameter of input u reached from the current state: the step index along a
        sweep, the input itself for one input, else the arc length along the input path."""
        if self.line is not None:
            return float((u - self.origin) @ self.line)
        if self.single:
            return float(u[0])
        return self.arc + float(np.linalg.norm(u - self.u))

    def _push(self, q: FloatArray, s: float) -> None:
        hs = self.hist_s
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

    def snapshot(self) -> _Snapshot:
        """The state and its history, to return to (see `restore`)."""
        return _Snapshot(self.u, self.q, self.ring.copy(), self.slot, list(self.hist_s),
                         self.run, self.last_m2, self.last_h, self.arc, self.direction)

    def restore(self, snap: _Snapshot) -> None:
        """Return to a `snapshot`: used to turn back at a limit from the last grid point
        instead of from the extreme, where the steps would have to grow again from tiny."""
        self.u, self.q, self.slot, self.run = snap.u, snap.q, snap.slot, snap.run
        self.ring[:] = snap.ring
        self.hist_s = list(snap.hist_s)
        self.last_m2, self.last_h, self.arc = snap.last_m2, snap.last_h, snap.arc
        self.direction = snap.direction
        self.tangent_cache = None

    def replay(self, us: FloatArray, qs: FloatArray) -> None:
        """Move to the last of `qs` (states at inputs `us`, in the order passed, one grid step
        apart along the sweep line), known without solving, with them as the predictor's
        history."""
        self.hist_s = []
        self.run = 0
        for u, q in zip(us, qs, strict=True):
            self._push(q, self._param(u))
        self.u, self.q = us[-1], qs[-1]
        self.bsize, self.cool = BLOCK, 0  # fresh history: blocks may start at once
        if len(qs) >= 2:
            d = qs[-1] - qs[-2]
            self.last_m2, self.last_h = float(d @ d), 1.0
        else:
            self.last_m2 = 0.0
        self.tangent_cache = None

    def _reset_history(self, direction: FloatArray) -> None:
        self.direction = direction
        self.arc = 0.0
        self.hist_s = []
        self._push(self.q, 0.0)

    def current_g(self) -> FloatArray:
        """G = ∂Φ/∂x at the current state."""
        self._set_inputs(self.u, None)
        self.x[: self.n] = self.q
        return self.sys.evaluate(self.x)[0]

    def tangent(self) -> tuple[FloatArray, float]:
        """(∂q/∂u (n, n_in), first-order inconsistency) at the current state.

        ∂Φ/∂u follows from G's driven columns and the input motion's derivative; the
        inconsistency ‖J q' + ∂Φ/∂u‖ / ‖∂Φ/∂u‖ is zero when the equations allow the motion and
        stays finite when redundant equations lock the mechanism.
        """
        n, nd = self.n, self.nd
        dxd, ds = self.mech.basis.derivatives(self.u)
        g = self.current_g()
        dphi = g[:, n: n + nd] @ dxd + g[:, n + nd: -1] @ ds
        jac = g[:, :n]
        scale = float(np.linalg.norm(dphi))
        if scale == 0.0:
            return np.zeros((n, dphi.shape[1])), 0.0
        try:
            if self.lsq:
                sens = -np.linalg.lstsq(jac, dphi, rcond=None)[0]
            elif dphi.shape[1] == 1:
                with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                    sens = -solve(jac, dphi[:, 0])[:, None]
            else:
                sens = -np.linalg.solve(jac, dphi)
        except np.linalg.LinAlgError:
            return np.zeros((n, dphi.shape[1])), math.inf
        if not np.all(np.isfinite(sens)):
            return np.zeros((n, dphi.shape[1])), math.inf
        return (np.asarray(sens, dtype=np.float64),
                float(np.linalg.norm(jac @ sens + dphi)) / scale)

    def predict(self, u_new: FloatArray) -> FloatArray:
        """Newton start for input u_new: polynomial extrapolation along the input path through
        the last states (up to HISTORY equally spaced ones, else up to four with bounded
        Lagrange weights), or the tangent when fewer than two lie on the current line."""
        if self.line is not None:
            s_new = float((u_new - self.origin) @ self.line)
            self.h_new = abs(s_new - self.hist_s[-1])
        elif self.single:
            s_new = float(u_new[0])
            self.h_new = abs(s_new - self.hist_s[-1])
        else:
            # Several inputs along a path: extrapolate in arc length while the path turns
            # gently; at a corner (> 10°) restart from the tangent.
            du = u_new - self.u
            nrm = math.sqrt(float(du @ du))
            e = du / nrm if nrm > 0 else du
            if len(self.hist_s) < 2 or float(e @ self.direction) < CORNER_COS:
                self._reset_history(e)
            s_new = self.arc + nrm
            self.h_new = nrm
            self.e_new = e
        self.s_new = s_new
        hs = self.hist_s
        k = len(hs)
        if k >= 2:
            h = s_new - hs[-1]
            if self.run >= 2 and abs(h - (hs[-1] - hs[-2])) <= 1e-9 * abs(h):
                return np.asarray(_UNIFORM[self.run, self.slot][0] @ self.ring,
                                  dtype=np.float64)
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
        if self.tangent_cache is None:
            self.tangent_cache = self.tangent()[0]
        return np.asarray(self.q + self.tangent_cache @ (u_new - self.u), dtype=np.float64)

    def attempt(self, u_new: FloatArray, pre: FloatArray | None = None
                ) -> tuple[bool, int, float, str]:
        """Try one step to u_new from the current state; on success the state moves.

        Returns (accepted, Newton iterations, residual bound at the end, why refused).
        """
        q_pred = self.predict(u_new)
        self._set_inputs(u_new, pre)
        res = newton_raw(self.sys, self.x, q_pred, self.tol, self.max_iter)
        if not res.converged:
            return False, res.iterations, res.residual, (
                "no convergence" if math.isfinite(res.residual) else "diverged")
        dm = q_pred - self.q
        m2 = float(dm @ dm)
        if res.iterations <= 1:
            c2 = res.last_step2  # one Newton step: the correction is that step
        else:
            dc = res.q - q_pred
            c2 = float(dc @ dc)
        if c2 > CONTINUITY * CONTINUITY * m2 + self.floor2:
            return False, res.iterations, res.residual, "discontinuous"
        s_new, h = self.s_new, self.h_new
        if self.last_m2 > 0.0 and m2 > (MAX_SPEEDUP * h / self.last_h) ** 2 * self.last_m2 \
                + self.floor2:
            return False, res.iterations, res.residual, "discontinuous"
        self.last_m2, self.last_h = m2, h
        if not self.single and self.line is None:
            if h > 0:
                self.direction = self.e_new
            self.arc = s_new
        self.u = u_new
        self.q = res.q
        self.tangent_cache = None
        self._push(res.q, s_new)
        return True, res.iterations, res.residual, ""

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
        n, m = self.n, self.m
        x = self.tx
        x[0, :n] = q
        x[:, n:-1] = self.mech.basis.taylor(u, d, TAYLOR)
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

    def run_fast(self, index: int, direction: int, count: int, grid: FloatArray,
                 xtab: FloatArray, out_q: FloatArray, out_it: NDArray[np.int64], pos: int
                 ) -> int:
        """Take up to `count` sweep steps in the common case, in a tight loop: the system is
        square, Newton converges from the predictor (a single step accepted by the quadratic
        remainder bound or by the residual, or more from there) and the result passes the same
        two continuity tests as `attempt`. Single steps extrapolate the equal steps of this
        sweep at the end of the history (binomial weights). Up to BLOCK steps are
        predicted and corrected together: extrapolated from the last HISTORY equal steps, or,
        with fewer, from the branch's Taylor series (as far as it is trusted). Stops at the
        first step that needs anything else (subdivision, a limit), leaving the state at the
        last accepted one, and returns the number of steps taken: their states go to
        out_q[pos:], their iterations to out_it[pos:]. `grid` holds the sweep's input rows and
        `xtab` x's driven entries for them, `index` is the current row, `direction` ±1. When a
        single step to the next row was tried and refused (as `attempt` would refuse it: same
        predictor, same Newton iterates, same tests), `stuck` holds its Newton iterations,
        else 0; `fold_ahead` says it stopped before a step that likely holds a fold."""
        hs_ = self.hist_s
        h = float(direction)
        self.stuck = 0
        self.fold_ahead = False
        if self.lsq:
            return 0
        x, n, hsm, hs_t, m = self.x, self.n, self.hs, self.hs_t, self.m
        ring, slot, run = self.ring, self.slot, self.run
        if run >= 2 and abs(hs_[-1] - hs_[-2] - h) > 1e-9:
            run = 1  # the history does not end in equal steps of this sweep: start afresh
        d = h * self.inc
        bound, accept, floor2, tol2 = self.bound, self.accept, self.floor2, self.tol2
        cont2, speed2 = CONTINUITY * CONTINUITY, MAX_SPEEDUP * MAX_SPEEDUP
        last_m2 = self.last_m2 if self.last_h == 1.0 else 0.0
        s = hs_[-1]
        taken = 0
        q = self.q
        xs = self.xs
        bsize, cool = self.bsize, self.cool
        while taken < count:
            if cool == 0 and count - taken >= MIN_BLOCK:
                # Several steps at once: predict b states from the ring, one Newton step for
                # all of them (one product evaluates every Φ and J, one call solves all the
                # systems), the same tests per state; accept those before the first failure.
                # A block costs about as much as four single steps whatever its size: after
                # one that accepts fewer than MIN_BLOCK states, take BLOCK single steps first.
                if run == HISTORY:
                    b = min(bsize, count - taken)
                    pw = _BLOCKS[slot] @ ring
                    preds, dms = pw[:b], pw[BLOCK: BLOCK + b]
                else:
                    # Too few equal steps to extrapolate from: predict from the Taylor series
                    # of the branch, as far as its last term stays below TAYLOR_TOL of its
                    # first (the truncation error is of that order while it converges).
                    coef = self.taylor(q, grid[index + direction * taken], d)
                    first2, last2 = float(coef[1] @ coef[1]), float(coef[-1] @ coef[-1])
                    if not (first2 > 0.0 and last2 < math.inf):  # no motion, or singular
                        reach = 0
                    elif last2 > 0.0:  # ‖c_K‖ jᴷ ≤ TAYLOR_TOL·‖c_1‖ j
                        reach = int((TAYLOR_TOL * TAYLOR_TOL * first2 / last2)
                                    ** (0.5 / (TAYLOR - 1)))
                    else:
                        reach = BLOCK
                    b = min(BLOCK, count - taken, reach)
                    if not b >= MIN_BLOCK:
                        cool = BLOCK
                        continue
                    pw = _POWERS[: b + 1] @ coef
                    preds = pw[1:]
                    dms = preds - pw[:-1]
                xb = xs[:b]
                xb[:, :n] = preds
                xb[:, n:-1] = xtab[_rows(index + direction * (taken + 1), b, direction)]
                gb = (xb @ hs_t).reshape(b, m, -1)
                phis = 0.5 * (gb @ xb[:, :, None])[:, :, 0]
                steps = solve(gb[:, :, :n], phis)
                c2s = np.einsum("ij,ij->i", steps, steps)
                conv = bound * c2s <= accept
                qs_b = preds - steps
                its = 1
                if not conv[:SECOND_PASS].all():
                    # The residuals themselves (the bound is pessimistic, by about tenfold);
                    # if they do not certify the first SECOND_PASS states either, a second
                    # Newton step for all of them: a state is then converged when, as in
                    # `newton`, its residual dropped 100-fold and the remainder bound of the
                    # second step certifies it.
                    xb[:, :n] = qs_b
                    gb = (xb @ hs_t).reshape(b, m, -1)
                    phi1 = 0.5 * (gb @ xb[:, :, None])[:, :, 0]
                    r1 = np.einsum("ij,ij->i", phi1, phi1)
                    conv |= r1 <= tol2
                    if not conv[:SECOND_PASS].all():
                        steps2 = solve(gb[:, :, :n], phi1)
                        conv |= ((r1 <= CONTRACTION * np.einsum("ij,ij->i", phis, phis))
                                 & (bound * np.einsum("ij,ij->i", steps2, steps2) <= accept))
                        qs_b = qs_b - steps2
                        its = 2
                        dc = qs_b - preds
                        c2s = np.einsum("ij,ij->i", dc, dc)
                m2s = np.einsum("ij,ij->i", dms, dms)
                prev = np.concatenate(((last_m2 if last_m2 > 0.0 else math.inf,), m2s[:-1]))
                good = conv & (c2s <= cont2 * m2s + floor2) & (m2s <= speed2 * prev + floor2)
                a = int(good.argmin())
                if good[a]:
                    a = b
                    bsize = BLOCK
                elif a >= MIN_BLOCK:
                    bsize = a
                else:
                    bsize, cool = BLOCK, BLOCK
                if a:
                    keep = min(a, HISTORY)
                    ring[_RING_SLOTS[slot][a]] = qs_b[a - keep:a]
                    slot = (slot + a) % HISTORY
                    run = min(run + a, HISTORY)
                    hs_.extend([s + h * (j + 1) for j in range(a - keep, a)])
                    s += h * a
                    del hs_[:-HISTORY]
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
            g_i = index + direction * (taken + 1)
            pred = _UNIFORM[run, slot] @ ring  # (prediction, predicted motion)
            q_pred = pred[0]
            x[:n] = q_pred
            x[n:-1] = xtab[g_i]
            gm = (hsm @ x).reshape(m, -1)
            step = solve(gm[:, :n], 0.5 * (gm @ x))
            c2 = float(step @ step)
            if not c2 < math.inf:  # singular Jacobian
                self.stuck = 1
                break
            q_new = q_pred - step
            its = 1
            if not bound * c2 <= accept:  # the bound is not enough: look at the residual
                more = newton_raw(self.sys, x, q_new, self.tol, self.max_iter - 1)
                if not more.converged:
                    self.stuck = 1 + more.iterations
                    break
                if more.iterations:  # not converged yet at q_new: Newton carried on
                    q_new, its = more.q, 1 + more.iterations
                    dc = q_new - q_pred
                    c2 = float(dc @ dc)
            dm = pred[1]
            m2 = float(dm @ dm)
            if c2 > cont2 * m2 + floor2 or (last_m2 > 0.0 and m2 > speed2 * last_m2 + floor2):
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
        self.bsize, self.cool = bsize, cool
        if taken:
            self.slot, self.run, self.q = slot, run, q
            self.u = grid[index + direction * taken]
            self.last_m2, self.last_h = last_m2, 1.0
            self.tangent_cache = None
        return taken

    def advance(self, target: FloatArray, pre: FloatArray | None = None,
                refused: int = 0, fold_first: bool = False
                ) -> tuple[Status, int, int, str, FloatArray, float]:
        """Move the inputs to `target`, subdividing the step as needed. `refused` > 0 says the
        whole step was already tried and refused after that many iterations (`run_fast`);
        `fold_first` looks for a fold in the step before trying it.

        Returns (status, iterations, accepted sub-steps, reason, failed input, residual).
        """
        fold = self.fold_limit(target) if fold_first else None
        if fold is not None:
            its, failed, res = fold
            return Status.LIMIT, its, 1, FOLD_REASON, failed, res
        if refused:
            iters = refused
        else:
            ok, iters, res, why = self.attempt(target, pre)
            if ok:
                return Status.OK, iters, 1, "", target, res
        fold = None if fold_first else self.fold_limit(target)
        if fold is not None:
            its, failed, res = fold
            return Status.LIMIT, iters + its, 1, FOLD_REASON, failed, res
        start = self.u
        delta = target - start
        done = 0.0
        frac = 0.5
        subs = 0
        streak = 0  # successes in a row since the last failure
        while True:
            last = done + frac >= 1.0
            u_try = target if last else start + (done + frac) * delta
            ok, it, res, why = self.attempt(u_try, pre if last else None)
            iters += it
            if ok:
                subs += 1
                if last:
                    return Status.SUBDIVIDED, iters, subs, "", target, res
                done += frac
                streak += 1
                # Grow only after two successes in a row: right after a failure, growing
                # would retry what just failed (near a limit it fails again).
                frac = min(2.0 * frac if streak >= 2 else frac, 1.0 - done)
                continue
            streak = 0
            frac *= 0.5
            if frac < self.min_frac:
                return Status.LIMIT, iters, subs, why, u_try, res

    def fold_limit(self, target: FloatArray) -> tuple[int, FloatArray, float] | None:
        """Locate a motion limit (fold, turning point) between the current state and `target`
        directly instead of by repeated halving of the step.

        On the input line u(t) = u0 + t·(target − u0) the fold (q*, t*) solves the augmented
        system Φ(q, u(t)) = 0, J(q, u(t))·v = 0, c·v = 1 (Newton with its exact Jacobian: Φ is
        quadratic in x and J·v linear in it), from the current state and the null vector of J
        there. Near a non-degenerate fold the branch is q ≈ q* + αv with α² = −2(w·Φ_t)(t − t*)
        / (w·vᵀ∇²Φv) (w: left null vector), so the branch the tracker is on is the one whose α has
        the sign of v·(q0 − q*), and the model must reproduce q0 (same continuity test as a
        step). The state at t_r = t* − ¼·2^−max_halvings is then solved by Newton from that
        model point and must stay within CONTINUITY·|α| of it; the tracker moves there, and the
        input at t* + ¼·2^−max_halvings is reported as failed (no real solution on this branch
        beyond the fold). The bracket is tighter than the halving search's (< 2^−max_halvings
        of a step). Returns (Newton iterations, failed input, residual bound) or None when no
        such fold is found (fold outside (0, 1], degenerate, not converged, other branch): the
        caller then subdivides as usual.
        """
        if self.lsq or not self.n or (self.line is None and not self.single):
            return None
        n, m = self.n, self.m
        basis = self.mech.basis
        start = self.u
        d = target - start
        q0 = self.q
        q = q0.copy()
        t = 0.0
        # Start from the last step's direction: approaching a fold, q' = −J⁻¹Φ_u turns into
        # the null vector of J (its smallest singular direction dominates). Without two
        # states to take it from, from the SVD of J.
        v = self.ring[self.slot] - self.ring[(self.slot - 1) % HISTORY]
        nv = math.sqrt(float(v @ v)) if len(self.hist_s) >= 2 else 0.0
        if nv > 0.0:
            v = v / nv
        else:
            try:
                v = np.linalg.svd(self.current_g()[:, :n])[2][-1].copy()
            except np.linalg.LinAlgError:
                return None
        c = v.copy()
        a_mat = np.zeros((2 * n + 1, 2 * n + 1))
        a_mat[2 * n, n + 1:] = c
        rhs = np.empty(2 * n + 1)
        # [J | Φ_t] and [vᵀ∇²Φ | (vᵀ∇²Φ)_t] in one product: columns x[:n] and x[n:-1]·ẋ.
        cols = np.zeros((self.sys.size - 1, n + 1))
        cols[:n, :n] = np.eye(n)
        xv = np.zeros((2, self.sys.size))
        xv[0, -1] = 1.0
        size2 = 1.0 + float(q0 @ q0)
        its = 0
        converged = False
        last2 = 0.0  # ‖δ‖² of the previous iteration (none yet)
        while its < FOLD_ITERATIONS:
            its += 1
            xs, xdot = basis.along(start + t * d, d)
            xv[0, :n] = q
            xv[0, n:-1] = xs
            xv[1, :n] = v
            cols[n:, n] = xdot
            gh = (xv @ self.hs_t).reshape(2, m, -1)  # G and hv: row r of hv is vᵀ(H_r + H_rᵀ)
            jac = gh[0, :, :n]
            a_mat[:2 * n, : n + 1] = (gh[:, :, :-1] @ cols).reshape(2 * n, n + 1)
            a_mat[n:2 * n, n + 1:] = jac
            rhs[:n] = 0.5 * (gh[0] @ xv[0])
            rhs[n:2 * n] = jac @ v
            rhs[2 * n] = c @ v - 1.0
            step = solve(a_mat, rhs)
            q = q - step[:n]
            t -= float(step[n])
            v = v - step[n + 1:]
            s2 = float(step[: n + 1] @ step[: n + 1])
            if not abs(t) < 4.0 or not s2 < math.inf:
                return None
            # Converged when the step is negligible, or when Newton's quadratic rate
            # (‖δ_k+1‖ ≈ C‖δ_k‖²) makes the next one so: ‖δ_k+1‖² ≈ s2³/last2².
            if s2 <= FOLD_STEP2 * size2 or s2 * s2 * s2 <= FOLD_STEP2 * size2 * last2 * last2:
                converged = True
                break
            last2 = s2
        if not converged or not 0.0 < t <= 1.0:
            return None
        # The branch through the fold: q ≈ q* + αv, α² = k·(t* − t).
        xs, xdot = basis.along(start + t * d, d)
        xv[0, :n] = q
        xv[0, n:-1] = xs
        vn = v / math.sqrt(float(v @ v))
        xv[1, :n] = vn
        gh = (xv @ self.hs_t).reshape(2, m, -1)
        g = gh[0]
        r = 0.5 * (g @ xv[0])
        if float(r @ r) > self.tol2:
            return None
        phi_t = g[:, n:-1] @ xdot
        # Left null vector w of J from the bordered system [Jᵀ v; Φ_tᵀ 0][w; s] = [0; 1]:
        # J v = 0 makes s = 0, so Jᵀw = 0 with w·Φ_t = 1 (non-singular at a simple fold).
        border = np.zeros((n + 1, n + 1))
        border[:n, :n] = g[:, :n].T
        border[:n, n] = vn
        border[n, :n] = phi_t
        e_last = np.zeros(n + 1)
        e_last[n] = 1.0
        w = solve(border, e_last)[:n]
        curv = float(w @ (gh[1, :, :n] @ vn))  # w·vᵀ∇²Φv
        k = 2.0 / curv if curv != 0.0 and math.isfinite(curv) else -1.0
        if not k > 0.0:  # degenerate, or the input turns the other way at this fold
            return None
        off = q0 - q
        sign = 1.0 if float(off @ vn) >= 0.0 else -1.0
        model0 = sign * math.sqrt(k * t) * vn
        e0 = off - model0
        if float(e0 @ e0) > CONTINUITY * CONTINUITY * float(off @ off) + self.floor2:
            return None
        quarter = 0.25 * self.min_frac
        t_r = t - quarter
        u_r = start + t_r * d
        alpha = sign * math.sqrt(k * quarter)
        q_start = q + alpha * vn
        self.x[n:-1] = basis.along(u_r, d)[0]
        res = newton_raw(self.sys, self.x, q_start, self.tol, self.max_iter)
        if not res.converged:
            return None
        dc = res.q - q_start
        if float(dc @ dc) > CONTINUITY * CONTINUITY * alpha * alpha + self.floor2:
            return None
        self.u = u_r
        self.q = res.q
        self.tangent_cache = None
        self.last_m2 = 0.0
        self._push(res.q, self._param(u_r))
        return its + res.iterations, start + (t + quarter) * d, res.residual

    def explain(self, why: str, residual: float) -> tuple[Literal["limit", "inconsistent"], str]:
        """Classify a failure at the smallest step: locked redundant equations, or a limit."""
        if why == FOLD_REASON:  # located by `fold_limit`: J·v = 0 there by construction
            return "limit", FOLD_MESSAGE
        if self.lsq:
            lock = self.tangent()[1]
            if lock > LOCK_TOLERANCE:
                return "inconsistent", _lock_reason(lock)
        g = self.current_g()
        sv = np.linalg.svd(g[:, : self.n], compute_uv=False) if self.n else np.ones(1)
        ratio = float(sv[-1] / sv[0]) if sv[0] > 0 else 0.0
        if ratio < 1e-3:
            return "limit", (f"the constraint Jacobian is nearly singular there (σmin/σmax = "
                             f"{ratio:.2g}): a dead centre, the mechanism cannot go further "
                             f"({why} beyond it)")
        return "limit", (f"Newton found no continuous solution beyond it ({why}, residual "
                         f"{residual:.2g}; σmin/σmax = {ratio:.2g})")


def _lock_reason(lock: float) -> str:
    return (f"the equations outnumber the unknowns and the redundant ones admit no common "
            f"motion (first-order residual {lock:.2g} of the input's effect): the data of an "
            "over-constrained linkage does not close exactly (e.g. rounded coordinates)")


def _finish(mech: Mechanism, inputs: FloatArray, q: FloatArray, iters: NDArray[np.int64],
            subs: NDArray[np.int64], status: NDArray[np.int8], limits: list[LimitReport],
            reversed_at: int | None) -> Simulation:
    """Assemble the result and verify every solved row with the exact equations."""
    ok = status <= int(Status.LIMIT)
    every = bool(ok.all())
    coords = np.full((status.size, *mech.coords0.shape), np.nan)
    resid = np.full(status.size, np.nan)
    if every or ok.any():
        q_ok, u_ok = (q, inputs) if every else (q[ok], inputs[ok])
        c = mech.coords_batch(q_ok, u_ok)
        coords[ok] = c
        if mech.constraints:
            resid[ok] = np.max(np.abs(mech.residuals(c, u_ok)), axis=1)
        else:
            resid[ok] = 0.0
    return Simulation(mech, inputs, coords, resid, iters, subs, status, tuple(limits),
                      reversed_at)


def _settings(mech: Mechanism, tolerance: float | None, max_halvings: int | None) -> Settings:
    s = mech.settings
    return Settings(s.steps, s.tolerance if tolerance is None else tolerance, s.max_iterations,
                    s.max_halvings if max_halvings is None else max_halvings,
                    s.reverse_at_limit)


def simulate(mech: Mechanism, inputs: ArrayLike, *, tolerance: float | None = None,
             max_halvings: int | None = None) -> Simulation:
    """Follow the mechanism through the given input values (N,) or (N, n_inputs).

    Starts from the initial configuration (moving first to inputs[0] if that differs, without
    recording the way there). Rows after a motion limit are UNREACHED; the limit row holds the
    last configuration reached and its input value.
    """
    u_all = np.asarray(inputs, dtype=np.float64)
    n_in = len(mech.inputs)
    if u_all.ndim == 1 and n_in == 1:
        u_all = u_all[:, None]
    if u_all.ndim != 2 or u_all.shape[1] != n_in:
        raise ValueError(f"inputs must have shape (N, {n_in}); got {np.shape(inputs)}")
    if not np.all(np.isfinite(u_all)):
        raise ValueError("inputs must be finite")
    tr = _Tracker(mech, _settings(mech, tolerance, max_halvings))
    n_rows = u_all.shape[0]
    xtab = mech.basis.entries_batch(u_all)
    q = np.full((n_rows, mech.system.n_u), np.nan)
    out_u = u_all.copy()
    iters = [0] * n_rows
    subs = [0] * n_rows
    status = [Status.UNREACHED] * n_rows
    limits: list[LimitReport] = []
    locked = _locked(tr)
    same = np.all(u_all == np.vstack((tr.u, u_all[:-1])), axis=1)  # input unchanged
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        _follow(tr, u_all, xtab, same, locked, q, out_u, iters, subs, status, limits)
    return _finish(mech, out_u, q, np.array(iters, dtype=np.int64),
                   np.array(subs, dtype=np.int64),
                   np.fromiter(status, dtype=np.int8, count=len(status)), limits, None)


def _follow(tr: _Tracker, u_all: FloatArray, xtab: FloatArray,
            same: NDArray[np.bool_], locked: str | None, q: FloatArray, out_u: FloatArray,
            iters: list[int], subs: list[int], status: list[Status],
            limits: list[LimitReport]) -> None:
    """`simulate`'s loop: advance through every row, filling the output lists in place."""
    for k in range(u_all.shape[0]):
        if same[k] and (k == 0 or status[k - 1] <= Status.SUBDIVIDED):
            st, it, sb, why, failed, res = Status.OK, 0, 0, "", tr.u, 0.0
        elif locked is not None:
            status[k] = Status.INCONSISTENT
            limits.append(LimitReport("inconsistent", k, tr.u.copy(), u_all[k].copy(),
                                      u_all[k].copy(), locked, math.nan))
            break
        else:
            st, it, sb, why, failed, res = tr.advance(u_all[k], xtab[k])
        iters[k], subs[k] = it, sb
        if st == Status.LIMIT:
            kind, reason = tr.explain(why, res)
            limits.append(LimitReport(kind, k, tr.u.copy(), failed.copy(), u_all[k].copy(),
                                      reason, res))
            if kind == "inconsistent":
                status[k] = Status.INCONSISTENT
                break
            status[k] = Status.LIMIT
            out_u[k] = tr.u
            q[k] = tr.q
            break
        status[k] = st
        q[k] = tr.q


def _locked(tr: _Tracker) -> str | None:
    """For over-determined systems: the reason if the redundant equations lock the start."""
    if not tr.lsq:
        return None
    lock = tr.tangent()[1]
    return _lock_reason(lock) if lock > LOCK_TOLERANCE else None


def sweep(mech: Mechanism, steps: int | None = None, step: ArrayLike | None = None, *,
          reverse_at_limit: bool | None = None, tolerance: float | None = None,
          max_halvings: int | None = None) -> Simulation:
    """Drive every input from its initial value by `step` (default: the file's) per step.

    Rows: the initial configuration, then one per step taken. At a motion limit a LIMIT row
    holds the extreme configuration reached; with `reverse_at_limit` the inputs then run back
    (and past the start) until the other limit or until `steps` steps were taken, so a
    rocker's whole range is traced.
    """
    s = mech.settings
    n_steps = s.steps if steps is None else int(steps)
    inc = mech.step if step is None else np.broadcast_to(
        np.asarray(step, dtype=np.float64), (len(mech.inputs),)).copy()
    rev = s.reverse_at_limit if reverse_at_limit is None else reverse_at_limit
    tr = _Tracker(mech, _settings(mech, tolerance, max_halvings))
    base = tr.u.copy()
    tr.set_line(base, inc)
    # Driven entries of x for every grid point the sweep can visit, in one batch.
    offset = n_steps + 1
    grid = base + np.arange(-offset, offset + 1)[:, None] * inc
    xtab = mech.basis.entries_batch(grid)
    # Rows: the start, one per step, and at most one more when the sweep turns back.
    cap = n_steps + 3
    out = _Rows(np.empty((cap, inc.size)), np.full((cap, tr.n), np.nan),
                np.zeros(cap, dtype=np.int64), np.zeros(cap, dtype=np.int64),
                np.full(cap, Status.UNREACHED, dtype=np.int8), [])
    out.u[0] = tr.u
    out.q[0] = tr.q
    out.status[0] = Status.OK
    pos = 1
    reversed_at: int | None = None
    locked = _locked(tr)
    if locked is not None:
        out.limits.append(LimitReport("inconsistent", 1, tr.u.copy(), tr.u + inc, tr.u + inc,
                                      locked, math.nan))
        out.u[1] = tr.u + inc
        out.status[1] = Status.INCONSISTENT
        pos = 2
        n_steps = 0
    index = 0
    direction = 1
    taken = 0
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        while taken < n_steps:
            if reversed_at is not None and 0 < index < reversed_at:
                # Back over the grid points solved on the way out: the same branch, the same
                # inputs, so the same states; replay them rather than solve them again (row r
                # of the way out holds grid point r).
                k = min(index, n_steps - taken)
                out.u[pos: pos + k] = out.u[index - k: index][::-1]
                out.q[pos: pos + k] = out.q[index - k: index][::-1]
                out.status[pos: pos + k] = Status.OK
                pos += k
                index -= k
                taken += k
                j = min(k, HISTORY)
                tr.replay(grid[offset + index + np.arange(j - 1, -1, -1)], out.q[pos - j: pos])
                continue
            k = tr.run_fast(offset + index, direction, n_steps - taken, grid, xtab, out.q,
                            out.iterations, pos)
            if k:
                out.u[pos: pos + k] = grid[_rows(offset + index + direction, k, direction)]
                out.substeps[pos: pos + k] = 1
                out.status[pos: pos + k] = Status.OK
                pos += k
                index += direction * k
                taken += k
                if not (tr.stuck or tr.fold_ahead):
                    continue
            taken += 1
            g = offset + index + direction
            target = grid[g]
            before = tr.snapshot() if rev and reversed_at is None else None
            st, it, sb, why, failed, res = tr.advance(target, xtab[g], tr.stuck,
                                                      tr.fold_ahead)
            stop = _record(tr, st, it, sb, why, failed, res, target, out, pos)
            pos += 1
            if stop:
                break
            if st == Status.LIMIT:
                if before is None:
                    break
                # Turn back: the next row is the grid point before the limit again. Its state
                # is known; resume from it (not from the extreme, where the steps would have
                # to grow again from the smallest) and run the inputs the other way.
                reversed_at = pos - 1
                tr.restore(before)
                out.u[pos] = tr.u
                out.q[pos] = tr.q
                out.status[pos] = Status.OK
                pos += 1
                direction = -direction
                continue
            index += direction
    return _finish(mech, out.u[:pos], out.q[:pos], out.iterations[:pos], out.substeps[:pos],
                   out.status[:pos], out.limits, reversed_at)


class _Rows(NamedTuple):
    """A sweep's output rows, preallocated: inputs, unknowns (NaN where none), Newton
    iterations, accepted sub-steps, status, and the limits met."""

    u: FloatArray
    q: FloatArray
    iterations: NDArray[np.int64]
    substeps: NDArray[np.int64]
    status: NDArray[np.int8]
    limits: list[LimitReport]


def _record(tr: _Tracker, st: Status, it: int, sb: int, why: str, failed: FloatArray,
            res: float, target: FloatArray, out: _Rows, pos: int) -> bool:
    """Fill sweep row `pos`; at a failure classify it. True when the sweep must stop."""
    out.iterations[pos] = it
    out.substeps[pos] = sb
    if st != Status.LIMIT:
        out.u[pos] = target
        out.q[pos] = tr.q
        out.status[pos] = st
        return False
    kind, reason = tr.explain(why, res)
    out.limits.append(LimitReport(kind, pos, tr.u.copy(), failed.copy(), target.copy(),
                                  reason, res))
    out.u[pos] = tr.u
    if kind == "inconsistent":
        out.status[pos] = Status.INCONSISTENT
        return True
    out.q[pos] = tr.q
    out.status[pos] = Status.LIMIT
    return False
