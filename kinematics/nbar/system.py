"""The constraint system in the form the Newton loop evaluates: one quadratic form per row.

With the points' homogenising factor w = 1, Eqs. 1, 2, 8 and 9 are quadratic polynomials in the
coordinates. Eqs. 4–7 also contain the norms ‖L_v‖ (and ‖L_v‖‖M_v‖) of lines and planes; here
‖L_v‖ is replaced by (‖L_v‖² + 1)/2 and ‖L_v‖‖M_v‖ by (‖L_v‖² + ‖M_v‖²)/2. Both substitutes have
the same value *and the same first derivatives* wherever the normalisation Eq. 8 holds, and Eq. 8
is itself one of the rows, so the system has exactly the paper's solutions and the paper's
Jacobian at every solution; only the path of the iterates off that manifold differs. The gain is
that every row becomes Φ_r = xᵀ H_r x in x = [q, driven coordinates, actuator lengths², 1], so
the residual of all rows and the whole Jacobian come from one matrix product:
G = (H + Hᵀ)·x gives ∂Φ/∂x row by row and Φ = ½ G·x.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray, IndexArray
from kinematics.nbar.constraints import Constraint


def _lapack_solve() -> Callable[[FloatArray, FloatArray], FloatArray]:
    """The LAPACK gesv gufunc that np.linalg.solve wraps, or np.linalg.solve itself.

    On the 2×2 … 18×18 systems here the public function spends ~3 of its ~5 µs on Python-level
    argument checks, a third of a whole simulation step. The gufunc lives in the private module
    numpy.linalg._umath_linalg (unchanged since numpy 1.8); it is used only if it exists and
    agrees with np.linalg.solve on a test system. A singular matrix gives NaN (with the
    floating-point 'invalid' flag) instead of LinAlgError; callers test the step for finiteness.
    """
    public = cast(Callable[[FloatArray, FloatArray], FloatArray], np.linalg.solve)
    try:
        fn = importlib.import_module("numpy.linalg._umath_linalg").solve1
        a = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, -1.0], [0.5, -1.0, 2.0]])
        b = np.array([1.0, -2.0, 0.5])
        with np.errstate(all="ignore"):
            ok = bool(np.allclose(fn(a, b), np.linalg.solve(a, b), rtol=1e-14))
            ok = ok and not np.all(np.isfinite(fn(np.ones((2, 2)), np.ones(2))))
    except (ImportError, AttributeError, TypeError, ValueError):
        return public
    return cast(Callable[[FloatArray, FloatArray], FloatArray], fn) if ok else public


#: With `monotone`, each Newton iteration must shrink ‖Φ‖² at least this much (‖Φ‖ by 10×):
#: from a good predictor Newton converges quadratically, slower progress means a bad step.
CONTRACTION = 0.01

#: Linear solve used by the Newton steps (see `_lapack_solve`).
solve = _lapack_solve()


@dataclass(frozen=True, eq=False)
class QuadraticSystem:
    """All constraint rows as stacked symmetric matrices, plus the layout of x.

    x = [q (n_u unknown coordinates), x_d (n_d driven coordinates), S (n_act squared actuator
    lengths), 1]. `hs` is (m·N, N): row block r holds w_r (H_r + H_rᵀ). `unknown_flat` and
    `driven_flat` index the flattened (n, 3) coordinate array.
    """

    hs: FloatArray
    m: int
    n_u: int
    n_d: int
    n_act: int
    unknown_flat: IndexArray
    driven_flat: IndexArray
    curvature: float

    @property
    def size(self) -> int:
        """Length N of x."""
        return self.n_u + self.n_d + self.n_act + 1

    @cached_property
    def hs_t(self) -> FloatArray:
        """hsᵀ, contiguous: rows of states times it give G for a whole batch in one product."""
        return np.ascontiguousarray(self.hs.T)

    @cached_property
    def hs_half(self) -> FloatArray:
        """½ hs: row block r is ∇²Φ_r / 2 (Taylor coefficients of the branch)."""
        return np.asarray(0.5 * self.hs, dtype=np.float64)

    def new_x(self) -> FloatArray:
        """A work vector x with its constant entry set."""
        x = np.zeros(self.size)
        x[-1] = 1.0
        return x

    def evaluate(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(G, Φ) at x: G (m, N) holds ∂Φ_r/∂x (its first n_u columns are the Jacobian),
        Φ (m,) the scaled residuals."""
        g = (self.hs @ x).reshape(self.m, -1)
        return g, 0.5 * (g @ x)


def _sym(u: FloatArray, v: FloatArray) -> FloatArray:
    """u vᵀ + v uᵀ: the symmetric matrix of the bilinear form (u·x)(v·x)."""
    o = np.outer(u, v)
    return np.asarray(o + o.T, dtype=np.float64)


def build_system(coords: FloatArray, is_line: NDArray[np.bool_], planar: bool,
                 constraints: tuple[Constraint, ...], unknown: NDArray[np.bool_],
                 driven: NDArray[np.bool_]) -> QuadraticSystem:
    """Assemble the quadratic forms of all rows.

    coords (n, 3) are the initial stored coordinates; entries that are neither unknown nor
    driven (fixed joints, the planar w = 1) are folded in as constants. `unknown` and `driven`
    are (n, 3) masks. ACT rows get one x entry each for the squared actuator length.
    """
    n_u = int(unknown.sum())
    n_d = int(driven.sum())
    n_act = sum(1 for c in constraints if c.kind == "ACT")
    size = n_u + n_d + n_act + 1
    slot = np.full(coords.size, -1, dtype=np.intp)
    slot[np.flatnonzero(unknown.ravel())] = np.arange(n_u)
    slot[np.flatnonzero(driven.ravel())] = n_u + np.arange(n_d)
    flat = coords.ravel()
    one = np.zeros(size)
    one[-1] = 1.0

    def e(i: int, c: int) -> FloatArray:
        """Coordinate c of primitive i as a linear form in x."""
        v = np.zeros(size)
        k = int(slot[3 * i + c])
        if k >= 0:
            v[k] = 1.0
        else:
            v[-1] = flat[3 * i + c]
        return v

    pc = (0, 1) if planar else (0, 1, 2)  # point coordinates (w = 1 is coords[:, 2] in plane)
    lc = (0, 1) if planar else (0, 1, 2)  # normal part L_v of a line / plane
    m = len(constraints)
    hs = np.zeros((m, size, size))
    act = 0
    for r, con in enumerate(constraints):
        h = np.zeros((size, size))
        if con.kind in ("RR", "ACT"):
            i, j = con.prims
            for c in pc:
                d = e(i, c) - e(j, c)
                h -= _sym(d, d)
            if con.kind == "RR":
                h += _sym(one, one) * con.value**2
            else:
                s = np.zeros(size)
                s[n_u + n_d + act] = 1.0
                act += 1
                h += _sym(s, one)
        elif con.kind == "RP":
            i, ln = con.prims
            for c in (*lc, 2) if planar else lc:
                h += _sym(e(i, c), e(ln, c))
            sq = _sym(one, one)
            for c in lc:
                sq += _sym(e(ln, c), e(ln, c))
            h -= 0.5 * con.value * sq
        elif con.kind in ("PP", "PPsin"):
            ln, mn = con.prims
            if con.kind == "PP":
                for c in lc:
                    h += _sym(e(ln, c), e(mn, c))
            else:
                h += _sym(e(ln, 0), e(mn, 1)) - _sym(e(ln, 1), e(mn, 0))
            sq = np.zeros((size, size))
            for c in lc:
                sq += _sym(e(ln, c), e(ln, c)) + _sym(e(mn, c), e(mn, c))
            h -= 0.5 * con.value * sq
        else:  # NORM on a line / plane, SPHERE on a point
            (i,) = con.prims
            for c in lc if con.kind == "NORM" else pc:
                h += _sym(e(i, c), e(i, c))
            h -= _sym(one, one)
        # Each term c·(u·x)(v·x) contributed c·(u vᵀ + v uᵀ), so h is already H + Hᵀ.
        hs[r] = h * con.scale
    # Φ is quadratic with constant Hessians ∇²Φ_r = H_r + H_rᵀ (the blocks of hs), so after a
    # Newton step Δ the new residual is exactly ½Δᵀ∇²Φ_rΔ per row (square systems, up to
    # rounding): ‖Φ‖₂ ≤ ½·curvature·‖Δ‖² with curvature = (Σ_r ‖∇²Φ_r‖₂²)^½ on the unknowns.
    qq = hs[:, :n_u, :n_u]
    curvature = float(np.sqrt(np.sum(np.linalg.norm(qq, ord=2, axis=(1, 2)) ** 2))) if n_u else 0.0
    return QuadraticSystem(np.ascontiguousarray(hs.reshape(m * size, size)), m, n_u, n_d,
                           n_act, np.flatnonzero(unknown.ravel()),
                           np.flatnonzero(driven.ravel()), curvature)


class NewtonResult(NamedTuple):
    """Outcome of one Newton solve: the state, the number of linear solves, a bound on
    ‖Φ‖₂ at the returned state (the evaluated norm, or the exact quadratic remainder bound),
    whether that met the tolerance, and ‖Δ‖² of the last step (0 if none was taken)."""

    q: FloatArray
    iterations: int
    residual: float
    converged: bool
    last_step2: float


def newton(system: QuadraticSystem, x: FloatArray, q0: FloatArray, tol: float,
           max_iter: int, monotone: bool = True) -> NewtonResult:
    """`newton_raw` with the floating-point warnings of a singular step silenced."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return newton_raw(system, x, q0, tol, max_iter, monotone)


def newton_raw(system: QuadraticSystem, x: FloatArray, q0: FloatArray, tol: float,
               max_iter: int, monotone: bool = True) -> NewtonResult:
    """Algorithm 1, lines 4–12: Newton–Raphson (Eq. 24) from q0, the driven part of x set.

    Converged when ‖Φ‖₂ ≤ tol (which bounds every scaled residual). For a square system the
    residual after a step Δ is ½Δᵀ∇²Φ_rΔ row by row, so a step with ½·curvature·‖Δ‖² < tol
    is accepted without evaluating Φ again (the caller verifies stored states with the exact
    equations). With more rows than unknowns each step is the least-squares (Gauss–Newton) step
    from the normal equations JᵀJΔ = JᵀΦ. `monotone` gives up as soon as an iteration fails to
    cut ‖Φ‖ tenfold: from a good predictor Newton converges quadratically, so slower progress
    means the step was too large (or past a limit) and the caller should subdivide. x is
    overwritten. A singular Jacobian gives a non-finite step (reported as not converged) and
    raises numpy's floating-point flags: the caller runs this under `np.errstate` (once per
    sweep rather than once per step, which would cost a third of a step).
    """
    n = system.n_u
    m = system.m
    hs = system.hs
    tol2 = tol * tol
    lsq = m > n
    bound = 0.5 * system.curvature
    accept = 0.99 * tol
    q = q0
    prev = math.inf
    it = 0
    d2 = 0.0
    while True:
        x[:n] = q
        g = (hs @ x).reshape(m, -1)
        phi = 0.5 * (g @ x)
        r2 = float(phi @ phi)
        if r2 <= tol2:
            return NewtonResult(q, it, math.sqrt(r2), True, d2)
        if it >= max_iter or not r2 < math.inf or (monotone and r2 > CONTRACTION * prev):
            return NewtonResult(q, it, math.sqrt(r2), False, d2)
        prev = r2
        jac = g[:, :n]
        try:
            step = solve(jac.T @ jac, jac.T @ phi) if lsq else solve(jac, phi)
        except np.linalg.LinAlgError:
            return NewtonResult(q, it, math.sqrt(r2), False, d2)
        d2 = float(step @ step)
        if not d2 < math.inf:  # singular Jacobian
            return NewtonResult(q, it, math.sqrt(r2), False, d2)
        q = q - step
        it += 1
        if not lsq and bound * d2 <= accept:
            x[:n] = q
            return NewtonResult(q, it, bound * d2, True, d2)
