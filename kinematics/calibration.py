"""Calibration of a five-bar from a drawn test pattern: the model, its Jacobian and the fit.

What is fitted: the machine's real link lengths a1, b1, a2, b2, w (mm) and home angles h1, h2
(rad: the true motor angles at the homed pose), together with the paper's rigid placement
(φ, tx, ty) — the user measures the marks in any frame laid on the paper, so that frame's
rotation and offset are unknown too. Ten parameters, vector order `PARAM_NAMES`.

Model (one mark i, commanded absolute steps (A_i, B_i) relative to the homed pose, q = 2π /
steps_per_rev):

    θ_i = (h1 + q·A_i, h2 + q·B_i)                              (steps, docs/architecture.md)
    P_i = FK(a1, b1, a2, b2, w; θ_i)   in the machine's assembly (kinematics.fivebar)
    m_i = Rot(φ)·P_i + (tx, ty)                                 (the paper frame)
    r_i = m_i − y_i                     residual against the measured position y_i      (M1)

The Jacobian is analytic. Differentiating the loop closures |P − R_k|² = b_k² (k = 1, 2) gives

    (P − R_k)·dP = b_k·db_k + (P − R_k)·dR_k                                            (J1)

with R1 = (a1 cos θ1, a1 sin θ1) and R2 = (w + a2 cos θ2, a2 sin θ2): a 2×2 system A·dP = c
whose rows are e_k = P − R_k (the matrix A of `FiveBar.jacobians`), solved for every
parameter's right-hand side c. The paper adds dm = Rot(φ)·dP, dm/dφ = Rot(φ + π/2)·P and
dm/dt = I (J2).

The fit is Levenberg–Marquardt with Marquardt's diagonal scaling (More 1978): each step
solves the augmented least-squares problem [J; √λ·D]·δ = [−r; 0] by an orthogonal
factorisation (never the normal equations, whose condition is the square of J's: ~10^8 for
the default pattern), D² = diag(JᵀJ) kept at its running maximum. The covariance of the
result is s²·(JᵀJ)⁻¹ (F1) with s either the measurement σ the user gives or the residual
standard deviation √(|r|² / (2N − 10)) (F2); `FitResult.sigma_source` says which. The
identifiability analysis, outliers and the drawing-shape error are in
`kinematics.calibration_analysis`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import FloatArray
from kinematics.errors import FivebarError
from kinematics.fivebar import FiveBar

#: Parameter order of every vector and matrix in this module.
PARAM_NAMES: tuple[str, ...] = ("a1", "b1", "a2", "b2", "w", "h1", "h2", "phi", "tx", "ty")
MACHINE_NAMES: tuple[str, ...] = PARAM_NAMES[:7]
N_PARAMS = len(PARAM_NAMES)
#: Which parameters are angles (rad); the others are lengths (mm).
IS_ANGLE = np.array([n in ("h1", "h2", "phi") for n in PARAM_NAMES])
#: Fewest marks a fit accepts: 2·10 = 20 equations for 10 unknowns.
MIN_MARKS = 10


class CalibrationError(FivebarError, ValueError):
    """A fit that cannot be done or did not converge; the message says why."""


@dataclass(frozen=True)
class MachineParams:
    """The seven machine parameters: link lengths (mm) and home angles (rad)."""

    a1: float
    b1: float
    a2: float
    b2: float
    w: float
    home1: float
    home2: float

    @classmethod
    def from_vector(cls, v: ArrayLike) -> MachineParams:
        """From the first seven entries of a parameter vector (`PARAM_NAMES` order)."""
        x = np.asarray(v, dtype=np.float64)
        return cls(*(float(c) for c in x[:7]))

    def vector(self) -> FloatArray:
        """(7,) in `MACHINE_NAMES` order."""
        return np.array([self.a1, self.b1, self.a2, self.b2, self.w, self.home1, self.home2])

    @property
    def home_rad(self) -> tuple[float, float]:
        return (self.home1, self.home2)

    def fivebar(self) -> FiveBar:
        """The geometry (raises ValueError when the loop can never close)."""
        return FiveBar(self.a1, self.b1, self.a2, self.b2, self.w)

    def pen_points(self, steps: ArrayLike, rad_per_step: float, assembly: str) -> FloatArray:
        """Pen positions (N, 2) mm of absolute steps (N, 2) on this machine; NaN rows where
        the loop cannot close."""
        th = self.angles(steps, rad_per_step)
        fwd = self.fivebar().forward_batch(th, assembly)
        pts = fwd.points.copy()
        pts[~fwd.valid] = np.nan
        return pts

    def angles(self, steps: ArrayLike, rad_per_step: float) -> FloatArray:
        """Motor angles (N, 2) rad of absolute steps: θ = home + q·steps (M1)."""
        s = np.asarray(steps, dtype=np.float64).reshape(-1, 2)
        return np.asarray(self.home_rad) + s * rad_per_step


@dataclass(frozen=True)
class MarkData:
    """What one fit sees: commanded steps (N, 2) of each mark, its measured position (N, 2)
    mm in the paper frame, the radians per step and the machine's assembly ("+"/"-")."""

    steps: FloatArray
    measured: FloatArray
    rad_per_step: float
    assembly: str

    @property
    def n(self) -> int:
        return int(self.steps.shape[0])


def rotation(phi: float) -> FloatArray:
    """The 2×2 counter-clockwise rotation by `phi` rad."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


def model_points(x: FloatArray, data: MarkData) -> FloatArray:
    """Predicted mark positions (N, 2) in the paper frame for parameters `x` (M1); NaN rows
    where the loop cannot close."""
    p = MachineParams.from_vector(x).pen_points(data.steps, data.rad_per_step, data.assembly)
    return np.asarray(p @ rotation(float(x[7])).T + x[8:10], dtype=np.float64)


def residuals(x: FloatArray, data: MarkData) -> FloatArray:
    """Residual vector (2N,) = model − measured, interleaved (x0, y0, x1, y1, …) (M1)."""
    return np.asarray((model_points(x, data) - data.measured).ravel(), dtype=np.float64)


def _pen_derivatives(m: MachineParams, steps: FloatArray, rad_per_step: float,
                     assembly: str) -> tuple[FloatArray, FloatArray]:
    """Pen points P (N, 2) and dP/d(machine parameters) (N, 2, 7) by (J1)."""
    fb = m.fivebar()
    th = m.angles(steps, rad_per_step)
    p = fb.forward_batch(th, assembly).points
    r1, r2 = fb.elbows(th)
    e1, e2 = p - r1, p - r2
    c1, s1 = np.cos(th[:, 0]), np.sin(th[:, 0])
    c2, s2 = np.cos(th[:, 1]), np.sin(th[:, 1])
    n = p.shape[0]
    rhs = np.zeros((n, 2, 7))  # row k = loop k, column = parameter
    rhs[:, 0, 0] = e1[:, 0] * c1 + e1[:, 1] * s1  # a1: e1·(cos θ1, sin θ1)
    rhs[:, 0, 1] = m.b1  # b1: b1·db1
    rhs[:, 1, 2] = e2[:, 0] * c2 + e2[:, 1] * s2  # a2
    rhs[:, 1, 3] = m.b2  # b2
    rhs[:, 1, 4] = e2[:, 0]  # w: e2·(1, 0)
    rhs[:, 0, 5] = m.a1 * (-e1[:, 0] * s1 + e1[:, 1] * c1)  # h1: e1·a1(−sin θ1, cos θ1)
    rhs[:, 1, 6] = m.a2 * (-e2[:, 0] * s2 + e2[:, 1] * c2)  # h2
    a = np.stack((e1, e2), axis=1)  # (N, 2, 2), rows e_k
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    inv = np.empty_like(a)
    inv[:, 0, 0], inv[:, 1, 1] = a[:, 1, 1], a[:, 0, 0]
    inv[:, 0, 1], inv[:, 1, 0] = -a[:, 0, 1], -a[:, 1, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        dp = (inv @ rhs) / det[:, None, None]
    return p, np.asarray(dp, dtype=np.float64)


def jacobian(x: FloatArray, data: MarkData) -> FloatArray:
    """d residuals / d parameters (2N, 10), analytic by (J1) and (J2)."""
    m = MachineParams.from_vector(x)
    p, dp = _pen_derivatives(m, data.steps, data.rad_per_step, data.assembly)
    rot = rotation(float(x[7]))
    n = data.n
    jac = np.zeros((n, 2, N_PARAMS))
    jac[:, :, :7] = np.einsum("ij,njk->nik", rot, dp)
    jac[:, :, 7] = p @ rotation(float(x[7]) + math.pi / 2).T
    jac[:, 0, 8] = 1.0
    jac[:, 1, 9] = 1.0
    return jac.reshape(2 * n, N_PARAMS)


def rms_mm(residual: FloatArray) -> float:
    """RMS distance (mm) of residual vectors (N, 2): sqrt(mean ‖r_i‖²)."""
    return float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))


def rigid_fit(src: FloatArray, dst: FloatArray) -> tuple[float, FloatArray]:
    """Best rotation φ and translation t with Rot(φ)·src + t ≈ dst in least squares
    (the 2-D Kabsch/Procrustes solution, no reflection, no scale)."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    u, v = src - cs, dst - cd
    phi = math.atan2(float(np.sum(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])),
                     float(np.sum(u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1])))
    return phi, cd - rotation(phi) @ cs


def initial_guess(nominal: MachineParams, data: MarkData) -> FloatArray:
    """Start of the fit: the profile's machine parameters and the paper placement that best
    maps the profile's predicted marks onto the measured ones."""
    p = nominal.pen_points(data.steps, data.rad_per_step, data.assembly)
    if not np.all(np.isfinite(p)):
        raise CalibrationError("the profile cannot reach some of the pattern's commanded "
                               "steps: was the pattern made for another profile?")
    phi, t = rigid_fit(p, data.measured)
    return np.concatenate((nominal.vector(), [phi], t))


@dataclass(frozen=True)
class FitResult:
    """A converged fit: parameters (10,), covariance (10, 10), residuals (N, 2) before
    (profile with the best placement) and after, the σ used and where it came from
    ("given" or "residual"), the scaled Jacobian at the solution and the iterations."""

    x: FloatArray
    covariance: FloatArray
    residual_before: FloatArray
    residual_after: FloatArray
    sigma: float
    sigma_source: str
    jac: FloatArray
    iterations: int
    dof: int

    @property
    def machine(self) -> MachineParams:
        return MachineParams.from_vector(self.x)

    @property
    def std(self) -> FloatArray:
        """Standard deviations (10,) from the covariance (inf where undetermined)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @property
    def rms_before_mm(self) -> float:
        return rms_mm(self.residual_before)

    @property
    def rms_after_mm(self) -> float:
        return rms_mm(self.residual_after)


def _cost(x: FloatArray, data: MarkData) -> tuple[float, FloatArray]:
    """½|r|² and r; inf when some mark's loop cannot close at `x` (or a length ≤ 0)."""
    if np.any(x[:5] <= 0.0):
        return math.inf, np.empty(0)
    try:
        r = residuals(x, data)
    except ValueError:  # FiveBar refuses a geometry whose loop can never close
        return math.inf, np.empty(0)
    if not np.all(np.isfinite(r)):
        return math.inf, r
    return 0.5 * float(r @ r), r


def levenberg_marquardt(x0: FloatArray, data: MarkData, *, max_iterations: int = 100,
                        rtol: float = 1e-12) -> tuple[FloatArray, int]:
    """Minimise ½|r(x)|² from `x0` (module doc: scaled LM). Returns (x, iterations);
    raises CalibrationError if it has not converged within `max_iterations`."""
    x = np.asarray(x0, dtype=np.float64).copy()
    cost, r = _cost(x, data)
    if not math.isfinite(cost):
        raise CalibrationError("the starting parameters cannot reach every mark")
    lam, d2 = 1e-3, np.zeros(N_PARAMS)
    for it in range(1, max_iterations + 1):
        jac = jacobian(x, data)
        d2 = np.maximum(d2, np.sum(jac * jac, axis=0))  # Marquardt/More scaling
        while True:
            aug = np.vstack((jac, np.diag(np.sqrt(lam * d2))))
            rhs = np.concatenate((-r, np.zeros(N_PARAMS)))
            step = np.linalg.lstsq(aug, rhs, rcond=None)[0]
            new_cost, new_r = _cost(x + step, data)
            if new_cost < cost:
                break
            lam *= 10.0
            if lam > 1e16:  # no descent left: a minimum to machine precision
                return x, it
        small_step = float(np.linalg.norm(step * np.sqrt(d2))) <= 1e-10 * (
            1.0 + float(np.linalg.norm(x * np.sqrt(d2))))
        converged = cost - new_cost <= rtol * cost or small_step
        x, cost, r = x + step, new_cost, new_r
        lam = max(lam / 10.0, 1e-12)
        if converged:
            return x, it
    raise CalibrationError(
        f"the fit did not converge in {max_iterations} iterations (rms residual "
        f"{math.sqrt(2.0 * cost / max(data.n, 1)):.4g} mm): the marks may be mis-numbered "
        "or measured in another unit; nothing was written")


def covariance(jac: FloatArray, sigma: float) -> FloatArray:
    """s²·(JᵀJ)⁻¹ (F1) through the SVD of the column-scaled J; directions with a singular
    value below 1e-12 of the largest get infinite variance (undetermined)."""
    scale = np.sqrt(np.sum(jac * jac, axis=0))
    scale[scale == 0.0] = 1.0
    _, sv, vt = np.linalg.svd(jac / scale, full_matrices=False)
    inv = np.where(sv > 1e-12 * sv[0], 1.0 / np.where(sv > 0, sv, 1.0) ** 2, np.inf)
    vs = vt.T / scale[:, None]
    with np.errstate(invalid="ignore"):
        cov = (vs * inv) @ vs.T
    cov[~np.isfinite(cov)] = np.inf
    return np.asarray(cov * sigma * sigma, dtype=np.float64)


def fit(nominal: MachineParams, data: MarkData, *, sigma: float | None = None,
        max_iterations: int = 100) -> FitResult:
    """Fit the ten parameters to the measured marks (module doc). `sigma` (mm), if given, is
    the measurement standard deviation the covariance is scaled by; otherwise the residual
    standard deviation is used (F2)."""
    if data.n < MIN_MARKS:
        raise CalibrationError(f"{data.n} marks measured; the fit needs at least {MIN_MARKS}")
    if sigma is not None and not (math.isfinite(sigma) and sigma > 0):
        raise CalibrationError(f"measurement sigma must be a positive number of mm; got "
                               f"{sigma!r}")
    x0 = initial_guess(nominal, data)
    before = model_points(x0, data) - data.measured
    x, its = levenberg_marquardt(x0, data, max_iterations=max_iterations)
    r = residuals(x, data)
    jac = jacobian(x, data)
    dof = 2 * data.n - N_PARAMS
    s_res = math.sqrt(float(r @ r) / dof)
    s, source = (sigma, "given") if sigma is not None else (s_res, "residual")
    return FitResult(x=x, covariance=covariance(jac, s), residual_before=before,
                     residual_after=r.reshape(-1, 2), sigma=s, sigma_source=source, jac=jac,
                     iterations=its, dof=dof)
