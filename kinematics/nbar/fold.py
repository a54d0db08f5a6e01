"""Locating a motion limit (fold, turning point) within a step directly, not by halving.

On the input line u(t) = u0 + t·(target − u0) the fold (q*, t*) solves the augmented system
Φ(q, u(t)) = 0, J(q, u(t))·v = 0, c·v = 1 (Newton with its exact Jacobian: Φ is quadratic in x
and J·v linear in it), from the current state and the null vector of J there (`_locate`). Near
a non-degenerate fold the branch is q ≈ q* + αv with α² = −2(w·Φ_t)(t − t*) / (w·vᵀ∇²Φv)
(w: left null vector; `_branch_model`), so the branch the tracker is on is the one whose α has
the sign of v·(q0 − q*), and the model must reproduce q0 (the continuity test of a step,
`kinematics.nbar.guard`). The state at t_r = t* − ¼·2^−max_halvings is then solved by Newton
from that model point and must stay within CONTINUITY·|α| of it (`_step_before`); the
tracker moves there, and the input at t* + ¼·2^−max_halvings is reported as failed (no real
solution on this branch beyond the fold). The bracket is tighter than the halving search's
(< 2^−max_halvings of a step).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from kinematics.arrays import FloatArray
from kinematics.nbar.guard import NO_PREVIOUS, step_accepted
from kinematics.nbar.system import newton_raw, solve

if TYPE_CHECKING:
    from kinematics.nbar.tracker import Tracker

#: Newton iterations allowed for locating a fold (`fold_limit`), and its convergence test:
#: squared step ≤ FOLD_STEP2·(1 + ‖q‖²).
FOLD_ITERATIONS = 12
FOLD_STEP2 = 1e-20
#: Why the motion stops at a located fold, and the reason reported for it.
FOLD_REASON = "no solution past the turning point"
FOLD_MESSAGE = (f"the constraint Jacobian is singular at the turning point (J·v = 0 there): "
                f"a dead centre, {FOLD_REASON} on this branch")


def fold_limit(tr: Tracker, target: FloatArray) -> tuple[int, FloatArray, float] | None:
    """Locate a fold between the tracker's state and `target` (see the module docstring)
    and move the tracker just before it. Returns (Newton iterations, failed input, residual
    bound) or None when no such fold is found (fold outside (0, 1], degenerate, not
    converged, other branch): the caller then subdivides as usual."""
    if tr.lsq or not tr.n or (tr.line is None and not tr.single):
        return None
    v = _start_vector(tr)
    if v is None:
        return None
    start = tr.u
    d = target - start
    found = _locate(tr, start, d, v)
    if found is None:
        return None
    its, q, t, v = found
    model = _branch_model(tr, q, t, v, start, d)
    if model is None:
        return None
    vn, k = model
    return _step_before(tr, q, t, vn, k, start, d, its)


def _start_vector(tr: Tracker) -> FloatArray | None:
    """The Newton start for the null vector v: the last step's direction (approaching a fold,
    q' = −J⁻¹Φ_u turns into the null vector of J, its smallest singular direction dominates),
    or without two states to take it from, the smallest right singular vector of J."""
    v = tr.hist.last_step()
    nv = math.sqrt(float(v @ v)) if len(tr.hist.s) >= 2 else 0.0
    if nv > 0.0:
        return np.asarray(v / nv, dtype=np.float64)
    try:
        return np.asarray(np.linalg.svd(tr.current_g()[:, :tr.n])[2][-1].copy(),
                          dtype=np.float64)
    except np.linalg.LinAlgError:
        return None


def _locate(tr: Tracker, start: FloatArray, d: FloatArray, v: FloatArray
            ) -> tuple[int, FloatArray, float, FloatArray] | None:
    """Newton on Φ = 0, J·v = 0, c·v = 1 (c: the start vector) in (q, t, v) from the current
    state at t = 0. Returns (iterations, q*, t*, v*) for a converged fold with 0 < t* ≤ 1."""
    n, m = tr.n, tr.m
    basis = tr.mech.basis
    q0 = tr.q
    q = q0.copy()
    t = 0.0
    c = v.copy()
    a_mat = np.zeros((2 * n + 1, 2 * n + 1))
    a_mat[2 * n, n + 1:] = c
    rhs = np.empty(2 * n + 1)
    # [J | Φ_t] and [vᵀ∇²Φ | (vᵀ∇²Φ)_t] in one product: columns x[:n] and x[n:-1]·ẋ.
    cols = np.zeros((tr.sys.size - 1, n + 1))
    cols[:n, :n] = np.eye(n)
    xv = np.zeros((2, tr.sys.size))
    xv[0, -1] = 1.0
    size2 = 1.0 + float(q0 @ q0)
    its = 0
    last2 = 0.0  # ‖δ‖² of the previous iteration (none yet)
    while its < FOLD_ITERATIONS:
        its += 1
        xs, xdot = basis.along(start + t * d, d)
        xv[0, :n] = q
        xv[0, n:-1] = xs
        xv[1, :n] = v
        cols[n:, n] = xdot
        gh = (xv @ tr.sys.hs_t).reshape(2, m, -1)  # G and hv: row r of hv is vᵀ(H_r + H_rᵀ)
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
            return (its, q, t, v) if 0.0 < t <= 1.0 else None
        last2 = s2
    return None


def _branch_model(tr: Tracker, q: FloatArray, t: float, v: FloatArray, start: FloatArray,
                  d: FloatArray) -> tuple[FloatArray, float] | None:
    """(unit null vector vn, k) of the branch through the fold, q ≈ q* ± √(k·(t* − t))·vn,
    or None when Φ(q*) misses the tolerance, or the fold is degenerate or turns the input the
    other way (k ≤ 0)."""
    n, m = tr.n, tr.m
    xv = np.zeros((2, tr.sys.size))
    xv[0, -1] = 1.0
    xs, xdot = tr.mech.basis.along(start + t * d, d)
    xv[0, :n] = q
    xv[0, n:-1] = xs
    vn = v / math.sqrt(float(v @ v))
    xv[1, :n] = vn
    gh = (xv @ tr.sys.hs_t).reshape(2, m, -1)
    g = gh[0]
    r = 0.5 * (g @ xv[0])
    if float(r @ r) > tr.tol2:
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
    return vn, k


def _step_before(tr: Tracker, q: FloatArray, t: float, vn: FloatArray, k: float,
                 start: FloatArray, d: FloatArray, its: int
                 ) -> tuple[int, FloatArray, float] | None:
    """Choose the tracker's branch of the model (the sign of α that reproduces q0), solve the
    state at t* − ¼·2^−max_halvings from the model point, and move the tracker there if both
    pass the continuity test."""
    off = tr.q - q
    sign = 1.0 if float(off @ vn) >= 0.0 else -1.0
    model0 = sign * math.sqrt(k * t) * vn
    e0 = off - model0
    if not step_accepted(float(e0 @ e0), float(off @ off), NO_PREVIOUS, tr.floor2):
        return None
    quarter = 0.25 * tr.min_frac
    t_r = t - quarter
    u_r = start + t_r * d
    alpha = sign * math.sqrt(k * quarter)
    q_start = q + alpha * vn
    tr.x[tr.n:-1] = tr.mech.basis.along(u_r, d)[0]
    res = newton_raw(tr.sys, tr.x, q_start, tr.tol, tr.max_iter)
    if not res.converged:
        return None
    dc = res.q - q_start
    if not step_accepted(float(dc @ dc), alpha * alpha, NO_PREVIOUS, tr.floor2):
        return None
    tr.moved_to(u_r, res.q, tr.param(u_r))
    return its + res.iterations, start + (t + quarter) * d, res.residual
