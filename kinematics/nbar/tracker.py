"""Following one branch of the solution set (Algorithm 1, per step): predict, correct, accept.

`Tracker` holds the current state (inputs u, unknowns q) and the predictor's `History`, and
takes single steps (`attempt`: predictor, Newton, the branch-flip guard of
`kinematics.nbar.guard`), subdividing a refused step (`advance`) down to 2^-max_halvings of it
before it reports a motion limit (`explain` says why). This is the reference algorithm: the
plain per-step path that `sweep(..., fast=False)` and `simulate` run; the fast path of sweeps
(`kinematics.nbar.fast`) takes the same steps in blocks and must agree with it.

- predictor: the Newton start is extrapolated along the input path from the last states
  (`History.predict`), or from the tangent q' = −J⁺ ∂Φ/∂u when there is no history; from the
  previous state alone Newton would need several more iterations;
- motion limit: when a step fails, a fold (turning point) of the solution curve within it is
  looked for directly (`kinematics.nbar.fold.fold_limit`); otherwise the step is halved;
- least squares: with more equations than unknowns the steps are Gauss–Newton steps; redundant
  equations that disagree on every motion are reported as inconsistent, not as a limit.
"""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

import numpy as np

from kinematics.arrays import FloatArray
from kinematics.nbar.fold import FOLD_MESSAGE, FOLD_REASON, fold_limit
from kinematics.nbar.guard import NO_PREVIOUS, step_accepted
from kinematics.nbar.history import History
from kinematics.nbar.model import Mechanism, Settings
from kinematics.nbar.results import Status
from kinematics.nbar.system import newton_raw, solve

#: Largest first-order inconsistency (relative) of redundant equations still taken as mobile.
LOCK_TOLERANCE = 1e-7
#: Several inputs: a turn of the input path sharper than 10° restarts the predictor.
CORNER_COS = math.cos(math.radians(10.0))


class Snapshot(NamedTuple):
    """A tracker's state and predictor history (`Tracker.snapshot`)."""

    u: FloatArray
    q: FloatArray
    hist: History
    last_m2: float
    last_h: float
    arc: float
    direction: FloatArray


class Tracker:
    """Follows one branch of the solution set as the inputs change."""

    def __init__(self, mech: Mechanism, settings: Settings) -> None:
        self.mech = mech
        self.sys = sysm = mech.system
        self.settings = settings
        self.tol = settings.tolerance
        self.max_iter = settings.max_iterations
        self.min_frac = 2.0 ** -settings.max_halvings
        self.n = sysm.n_u
        self.nd = sysm.n_d
        self.m = sysm.m
        self.single = len(mech.inputs) == 1
        self.lsq = mech.overdetermined
        self.x = sysm.new_x()
        self.u = mech.input0.copy()
        self.q = mech.q0.copy()
        self.floor2 = (1e-9 * max(mech.size, 1.0)) ** 2
        self.hist = History(self.n)  # last states along the input path
        self.last_m2 = 0.0  # predicted motion² and parameter step of the last accepted step
        self.last_h = 0.0
        self.origin = self.u.copy()
        self.direction = np.zeros_like(self.u)  # several inputs: direction of the last step
        self.arc = 0.0  # several inputs: arc length of the input path to the current state
        self.line: FloatArray | None = None  # sweeps: parameter = step index along `line`
        self.tangent_cache: FloatArray | None = None
        self.s_new = self.h_new = 0.0  # path parameter and length of the step being tried
        self.e_new = self.direction
        self.inc = np.zeros_like(self.u)  # sweeps: the input step
        self.tol2 = self.tol * self.tol
        self.bound = 0.5 * sysm.curvature
        self.accept = 0.99 * self.tol  # remainder bound accepted (margin: solve's rounding)
        self.hist.push(self.q, self.param(self.u))

    def set_line(self, base: FloatArray, inc: FloatArray) -> None:
        """Sweep mode: the inputs move along u = base + s·inc, and s is the parameter the
        predictor extrapolates in (the step index), whatever the number of inputs."""
        self.origin = np.asarray(base, dtype=np.float64).copy()
        self.inc = np.asarray(inc, dtype=np.float64).copy()
        self.line = self.inc / float(inc @ inc)
        self.hist.restart()
        self.hist.push(self.q, self.param(self.u))

    # -- state helpers
    def _set_inputs(self, u: FloatArray, pre: FloatArray | None) -> None:
        """Put the driven coordinates and actuator entries for u into x (Eqs. 10–22); `pre`
        is them precomputed (`InputBasis.entries`)."""
        self.x[self.n: -1] = self.mech.basis.entries(u) if pre is None else pre

    def param(self, u: FloatArray) -> float:
        """Path parameter of input u reached from the current state: the step index along a
        sweep, the input itself for one input, else the arc length along the input path."""
        if self.line is not None:
            return float((u - self.origin) @ self.line)
        if self.single:
            return float(u[0])
        return self.arc + float(np.linalg.norm(u - self.u))

    def snapshot(self) -> Snapshot:
        """The state and its history, to return to (see `restore`)."""
        return Snapshot(self.u, self.q, self.hist.copy(), self.last_m2, self.last_h,
                         self.arc, self.direction)

    def restore(self, snap: Snapshot) -> None:
        """Return to a `snapshot`: used to turn back at a limit from the last grid point
        instead of from the extreme, where the steps would have to grow again from tiny."""
        self.u, self.q = snap.u, snap.q
        self.hist.set_to(snap.hist)
        self.last_m2, self.last_h, self.arc = snap.last_m2, snap.last_h, snap.arc
        self.direction = snap.direction
        self.tangent_cache = None

    def replay(self, us: FloatArray, qs: FloatArray) -> None:
        """Move to the last of `qs` (states at inputs `us`, in the order passed, one grid step
        apart along the sweep line), known without solving, with them as the predictor's
        history."""
        self.hist.restart()
        for u, q in zip(us, qs, strict=True):
            self.hist.push(q, self.param(u))
        self.u, self.q = us[-1], qs[-1]
        if len(qs) >= 2:
            d = qs[-1] - qs[-2]
            self.last_m2, self.last_h = float(d @ d), 1.0
        else:
            self.last_m2 = 0.0
        self.tangent_cache = None

    def moved_to(self, u: FloatArray, q: FloatArray, s: float) -> None:
        """Take the solved state q at input u (path parameter s) as the current one, with no
        predicted motion to compare the next step with (after a located fold)."""
        self.u = u
        self.q = q
        self.tangent_cache = None
        self.last_m2 = 0.0
        self.hist.push(q, s)

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

    def _step_param(self, u_new: FloatArray) -> float:
        """Path parameter of u_new; sets the step length h_new (and, for several inputs off a
        sweep line, the step's direction e_new, restarting the history at a corner)."""
        if self.line is not None:
            s_new = float((u_new - self.origin) @ self.line)
            self.h_new = abs(s_new - self.hist.s[-1])
        elif self.single:
            s_new = float(u_new[0])
            self.h_new = abs(s_new - self.hist.s[-1])
        else:
            # Several inputs along a path: extrapolate in arc length while the path turns
            # gently; at a corner (> 10°) restart from the tangent.
            du = u_new - self.u
            nrm = math.sqrt(float(du @ du))
            e = du / nrm if nrm > 0 else du
            if len(self.hist.s) < 2 or float(e @ self.direction) < CORNER_COS:
                self.direction = e
                self.arc = 0.0
                self.hist.restart()
                self.hist.push(self.q, 0.0)
            s_new = self.arc + nrm
            self.h_new = nrm
            self.e_new = e
        return s_new

    def predict(self, u_new: FloatArray) -> FloatArray:
        """Newton start for input u_new: polynomial extrapolation along the input path through
        the last states (`History.predict`), or the tangent when fewer than two lie on the
        current line."""
        self.s_new = s_new = self._step_param(u_new)
        q_pred = self.hist.predict(s_new)
        if q_pred is not None:
            return q_pred
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
        s_new, h = self.s_new, self.h_new
        prev2 = (h / self.last_h) ** 2 * self.last_m2 if self.last_m2 > 0.0 else NO_PREVIOUS
        if not step_accepted(c2, m2, prev2, self.floor2):
            return False, res.iterations, res.residual, "discontinuous"
        self.last_m2, self.last_h = m2, h
        if not self.single and self.line is None:
            if h > 0:
                self.direction = self.e_new
            self.arc = s_new
        self.u = u_new
        self.q = res.q
        self.tangent_cache = None
        self.hist.push(res.q, s_new)
        return True, res.iterations, res.residual, ""

    def advance(self, target: FloatArray, pre: FloatArray | None = None,
                refused: int = 0, fold_first: bool = False
                ) -> tuple[Status, int, int, str, FloatArray, float]:
        """Move the inputs to `target`, subdividing the step as needed. `refused` > 0 says the
        whole step was already tried and refused after that many iterations (the fast path);
        `fold_first` looks for a fold in the step before trying it.

        Returns (status, iterations, accepted sub-steps, reason, failed input, residual).
        """
        fold = fold_limit(self, target) if fold_first else None
        if fold is not None:
            its, failed, res = fold
            return Status.LIMIT, its, 1, FOLD_REASON, failed, res
        if refused:
            iters = refused
        else:
            ok, iters, res, _ = self.attempt(target, pre)
            if ok:
                return Status.OK, iters, 1, "", target, res
        fold = None if fold_first else fold_limit(self, target)
        if fold is not None:
            its, failed, res = fold
            return Status.LIMIT, iters + its, 1, FOLD_REASON, failed, res
        return self._subdivide(target, pre, iters)

    def _subdivide(self, target: FloatArray, pre: FloatArray | None, iters: int
                   ) -> tuple[Status, int, int, str, FloatArray, float]:
        """`advance` after the whole step failed: halve it until a part is accepted, grow it
        again after two successes in a row, and report a limit below 2^-max_halvings."""
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

    def explain(self, why: str, residual: float) -> tuple[Literal["limit", "inconsistent"], str]:
        """Classify a failure at the smallest step: locked redundant equations, or a limit."""
        if why == FOLD_REASON:  # located by `fold_limit`: J·v = 0 there by construction
            return "limit", FOLD_MESSAGE
        if self.lsq:
            lock = self.tangent()[1]
            if lock > LOCK_TOLERANCE:
                return "inconsistent", lock_reason(lock)
        g = self.current_g()
        sv = np.linalg.svd(g[:, : self.n], compute_uv=False) if self.n else np.ones(1)
        ratio = float(sv[-1] / sv[0]) if sv[0] > 0 else 0.0
        if ratio < 1e-3:
            return "limit", (f"the constraint Jacobian is nearly singular there (σmin/σmax = "
                             f"{ratio:.2g}): a dead centre, the mechanism cannot go further "
                             f"({why} beyond it)")
        return "limit", (f"Newton found no continuous solution beyond it ({why}, residual "
                         f"{residual:.2g}; σmin/σmax = {ratio:.2g})")

    def locked(self) -> str | None:
        """For over-determined systems: the reason if the redundant equations lock the
        current state (no motion possible), else None."""
        if not self.lsq:
            return None
        lock = self.tangent()[1]
        return lock_reason(lock) if lock > LOCK_TOLERANCE else None


def lock_reason(lock: float) -> str:
    """The reason reported for redundant equations that admit no common motion."""
    return (f"the equations outnumber the unknowns and the redundant ones admit no common "
            f"motion (first-order residual {lock:.2g} of the input's effect): the data of an "
            "over-constrained linkage does not close exactly (e.g. rounded coordinates)")
