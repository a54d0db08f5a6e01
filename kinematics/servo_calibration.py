"""Calibration of a servo five-bar from a drawn pattern: each servo's pulse ↔ angle curve and
dead band, the link lengths and the pen's extension, with their uncertainties (pure numpy).

The stepper fit (`kinematics.calibration`) knows the angle of every commanded step; a hobby
servo does not: its angle is an unknown, non-linear function of the pulse, and where the arm
stops depends on the side it came from (the dead band, `kinematics.servo` Eq. S1). The model
(`kinematics.servo_model`, Eqs. SC1–SC2): a polynomial curve of order d_k per servo, a dead
band per servo, the geometry and the paper placement.

The fit is Levenberg–Marquardt with Marquardt's diagonal scaling, as for steppers, on a
central-difference Jacobian. The covariance is s²·(JᵀJ)⁻¹ with s the given measurement σ or
the residual standard deviation √(|r|²/(2N − n_free)) (`kinematics.calibration.covariance`,
F1/F2); fixed parameters (`free` = False, the coefficients above each servo's order among
them) get zero variance.

The orders are chosen from the marks (issue 38: a cubic misses a real servo's ripple by up
to 0.5 mm on the drawing): every (d_1, d_2) in 3…`MAX_ORDER` is fitted, each started from
the fitted lower order it extends, and the one with the least Bayesian information
criterion is kept (Schwarz 1978; Gaussian residuals, n = 2N, k free parameters):

    BIC = |r|²/σ² + k·ln n          with σ given                                (SC3)
    BIC = n·ln(|r|²/n) + k·ln n     with σ estimated from the residuals

An order is tried only while k ≤ N (at least two equations per unknown). The ln n per
parameter keeps a term only where it explains more than the noise: on a cubic true curve
the cubic is kept, on a rippled one the order that follows the ripple.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import BoolArray, FloatArray
from kinematics.calibration import CalibrationError, covariance, rigid_fit, rms_mm, rotation
from kinematics.servo_model import (
    COEFFS,
    DEAD,
    GEOMETRY_NAMES,
    MAX_ORDER,
    N_COEFFS,
    N_SERVO_PARAMS,
    PLACE,
    PULSE_SCALE_US,
    SERVO_PARAM_NAMES,
    ServoMachine,
    ServoMarks,
    approach_signs,
    commanded_pulses,
    pattern_points,
    pattern_shape_error,
    with_dead_band,
)

__all__ = ["COEFFS", "DEAD", "GEOMETRY_NAMES", "MAX_ORDER", "MIN_ORDER", "N_SERVO_PARAMS",
           "PLACE", "PULSE_SCALE_US", "SERVO_PARAM_NAMES", "ServoFit", "ServoMachine",
           "ServoMarks", "approach_signs", "commanded_pulses", "fit_servo", "pattern_points",
           "pattern_shape_error", "servo_model_points", "with_dead_band"]

#: Fewest marks a servo fit accepts (2N ≥ 2·20 equations).
MIN_SERVO_MARKS = 20
#: The lowest curve order tried (the issue's cubic).
MIN_ORDER = 3


def servo_model_points(x: FloatArray, marks: ServoMarks, centre_us: tuple[float, float]
                       ) -> FloatArray:
    """Predicted mark positions (N, 2) in the paper frame for parameters `x` (SC2)."""
    m = ServoMachine.from_vector(x, centre_us)
    p = m.pen_points(marks.pulses, marks.approach, marks.assembly)
    out = np.empty_like(p)
    sheet = marks.sheet_of()
    for j in range(marks.sheets):
        ph = x[_placement(j)]
        on = sheet == j
        out[on] = p[on] @ rotation(float(ph[0])).T + ph[1:]
    return out


def _placement(sheet: int) -> slice:
    """Where sheet `sheet`'s placement (φ, tx, ty) sits in the parameter vector."""
    start = PLACE.start if sheet == 0 else N_SERVO_PARAMS + 3 * (sheet - 1)
    return slice(start, start + 3)


def _n_params(marks: ServoMarks) -> int:
    """The parameter vector's length: the machine, one placement per sheet."""
    return N_SERVO_PARAMS + 3 * (marks.sheets - 1)


def _residuals(x: FloatArray, marks: ServoMarks, centre_us: tuple[float, float]
               ) -> FloatArray | None:
    """Residuals (2N,), or None where the model cannot draw every mark at `x`."""
    if np.any(x[:5] <= 0.0) or x[5] < 0.0 or abs(x[6]) > math.pi:
        return None
    try:
        r = (servo_model_points(x, marks, centre_us) - marks.measured).ravel()
    except ValueError:  # a geometry whose loop can never close
        return None
    return np.asarray(r) if np.all(np.isfinite(r)) else None


def _jacobian(x: FloatArray, marks: ServoMarks, centre_us: tuple[float, float],
              free: BoolArray) -> FloatArray:
    """Central-difference d residuals / d parameters (2N, `N_SERVO_PARAMS`); zero columns
    where fixed."""
    jac = np.zeros((2 * marks.n, _n_params(marks)))
    for j in np.flatnonzero(free):
        h = 1e-6 * max(1.0, abs(float(x[j])))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        rp, rm = _residuals(xp, marks, centre_us), _residuals(xm, marks, centre_us)
        if rp is not None and rm is not None:
            jac[:, j] = (rp - rm) / (2.0 * h)
            continue
        r0 = _residuals(x, marks, centre_us)  # at the edge of the drawable: one-sided
        if r0 is None or (rp is None and rm is None):
            raise CalibrationError("the fit reached a geometry that cannot draw every mark")
        jac[:, j] = (rp - r0) / h if rp is not None else (r0 - rm) / h  # type: ignore[operator]
    return jac


def _levenberg_marquardt(x0: FloatArray, marks: ServoMarks, centre_us: tuple[float, float],
                         free: BoolArray, max_iterations: int) -> tuple[FloatArray, int]:
    """Minimise ½|r|² over the free parameters (scaled LM, `kinematics.calibration`)."""
    x = x0.copy()
    r = _residuals(x, marks, centre_us)
    if r is None:
        raise CalibrationError("the profile cannot draw every mark of the pattern")
    cost = 0.5 * float(r @ r)
    lam, d2 = 1e-3, np.zeros(int(free.sum()))
    for it in range(1, max_iterations + 1):
        jac = _jacobian(x, marks, centre_us, free)[:, free]
        d2 = np.maximum(d2, np.sum(jac * jac, axis=0))
        while True:
            aug = np.vstack((jac, np.diag(np.sqrt(lam * d2))))
            step = np.linalg.lstsq(aug, np.concatenate((-r, np.zeros(d2.size))), rcond=None)[0]
            xn = x.copy()
            xn[free] += step
            rn = _residuals(xn, marks, centre_us)
            new_cost = math.inf if rn is None else 0.5 * float(rn @ rn)
            if new_cost < cost:
                break
            lam *= 10.0
            if lam > 1e16:
                return x, it
        assert rn is not None
        small = float(np.linalg.norm(step * np.sqrt(d2))) <= 1e-10 * (
            1.0 + float(np.linalg.norm(x[free] * np.sqrt(d2))))
        converged = cost - new_cost <= 1e-12 * cost or small
        x, cost, r = xn, new_cost, rn
        lam = max(lam / 10.0, 1e-12)
        if converged:
            return x, it
    raise CalibrationError(f"the servo fit did not converge in {max_iterations} iterations; "
                           "nothing was written")


@dataclass(frozen=True)
class ServoFit:
    """A converged servo fit: parameters (`N_SERVO_PARAMS` and 3 per further sheet), covariance
    (zero rows for fixed
    parameters), residuals (N, 2) before (the profile, best placement) and after, σ and its
    source ("given"/"residual"), the free mask, iterations, degrees of freedom, centres, each
    servo's curve order and the criterion (SC3) of every pair of orders tried."""

    x: FloatArray
    covariance: FloatArray
    residual_before: FloatArray
    residual_after: FloatArray
    sigma: float
    sigma_source: str
    free: BoolArray
    iterations: int
    dof: int
    centre_us: tuple[float, float]
    orders: tuple[int, int] = (3, 3)
    criteria: tuple[tuple[tuple[int, int], float], ...] = ()

    @property
    def machine(self) -> ServoMachine:
        return ServoMachine.from_vector(self.x, self.centre_us)

    @property
    def std(self) -> FloatArray:
        """Standard deviations (as `x`) (inf where undetermined, 0 where fixed)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @property
    def dead_band(self) -> FloatArray:
        """The fitted dead band widths (2,) rad."""
        return np.asarray(self.x[DEAD])

    @property
    def dead_band_std(self) -> FloatArray:
        """Their standard deviations (2,) rad."""
        return np.asarray(self.std[DEAD])

    @property
    def rms_before_mm(self) -> float:
        return rms_mm(self.residual_before)

    @property
    def rms_after_mm(self) -> float:
        return rms_mm(self.residual_after)

    def curve_std(self, k: int, pulses: ArrayLike) -> FloatArray:
        """Standard deviation (N,) rad of servo k's fitted curve angle at `pulses`, from the
        covariance of its coefficients (and their correlations)."""
        u = (np.asarray(pulses, dtype=np.float64) - self.centre_us[k]) / PULSE_SCALE_US
        basis = np.stack([u ** j for j in range(N_COEFFS)], axis=-1)
        sl = slice(COEFFS.start + N_COEFFS * k, COEFFS.start + N_COEFFS * (k + 1))
        cov = self.covariance[sl, sl]
        return np.asarray(np.sqrt(np.maximum(np.einsum("...i,ij,...j->...", basis, cov,
                                                       basis), 0.0)))


def _free_mask(orders: tuple[int, int], fit_dead_band: bool, fit_extension: bool,
               n_params: int) -> BoolArray:
    """Free parameters: all but the coefficients above each servo's order, the dead bands
    unless fitted, the extension unless fitted."""
    free = np.ones(n_params, dtype=bool)
    free[COEFFS] = (np.arange(N_COEFFS)[None, :] <= np.array(orders)[:, None]).ravel()
    free[DEAD] = fit_dead_band
    free[5:7] = fit_extension
    return free


def _criterion(cost: float, n: int, k: int, sigma: float | None) -> float:
    """The Bayesian information criterion (SC3) of a fit with ½|r|² = `cost`."""
    if sigma is not None:
        return 2.0 * cost / sigma ** 2 + k * math.log(n)
    return n * math.log(max(2.0 * cost, 1e-300) / n) + k * math.log(n)


def _select_orders(x0: FloatArray, marks: ServoMarks, cu: tuple[float, float],
                   orders: tuple[int, int] | None, fit_dead_band: bool, fit_extension: bool,
                   sigma: float | None, max_iterations: int
                   ) -> tuple[FloatArray, tuple[int, int], int, dict[tuple[int, int], float]]:
    """Fit every pair of orders (or the given pair) and keep the least BIC (module doc):
    the parameters, the orders, the iterations of that fit and every pair's criterion."""
    tried = range(MIN_ORDER, MAX_ORDER + 1)
    pairs = [orders] if orders is not None else [(a, b) for a in tried for b in tried]
    n = 2 * marks.n
    fits: dict[tuple[int, int], tuple[FloatArray, float, int]] = {}
    crit: dict[tuple[int, int], float] = {}
    for d in sorted(pairs, key=lambda p: (p[0] + p[1], p)):
        free = _free_mask(d, fit_dead_band, fit_extension, x0.size)
        if int(free.sum()) > marks.n and d != (MIN_ORDER, MIN_ORDER) and orders is None:
            continue  # fewer than two equations per unknown
        below = [fits[p] for p in ((d[0] - 1, d[1]), (d[0], d[1] - 1)) if p in fits]
        start = min(below, key=lambda f: f[1])[0] if below else x0
        try:
            x, its = _levenberg_marquardt(start, marks, cu, free, max_iterations)
        except CalibrationError:
            if orders is not None or d == (MIN_ORDER, MIN_ORDER):
                raise
            continue  # a high order that does not settle is not the answer
        r = _residuals(x, marks, cu)
        assert r is not None
        cost = 0.5 * float(r @ r)
        fits[d] = (x, cost, its)
        crit[d] = _criterion(cost, n, int(free.sum()), sigma)
    best = min(crit, key=lambda p: crit[p])
    return fits[best][0], best, fits[best][2], crit


def fit_servo(nominal: ServoMachine, marks: ServoMarks, *, sigma: float | None = None,
              fit_dead_band: bool = True, fit_extension: bool = True,
              max_iterations: int = 200, orders: tuple[int, int] | None = None) -> ServoFit:
    """Fit the servo model (module doc) to the measured marks, starting from `nominal` and
    the paper placement that best maps its predicted marks onto the measured ones.
    `orders` fixes each servo's curve order (3 ≤ d ≤ `MAX_ORDER`; None: chosen by SC3).
    `fit_dead_band` False keeps the nominal dead band (what a fit that ignores it gets);
    `fit_extension` False keeps e and γ (a pen at the joint has none to fit)."""
    if marks.n < MIN_SERVO_MARKS:
        raise CalibrationError(f"{marks.n} marks measured; the servo fit needs at least "
                               f"{MIN_SERVO_MARKS}")
    if sigma is not None and not (math.isfinite(sigma) and sigma > 0):
        raise CalibrationError(f"measurement sigma must be a positive number of mm; got "
                               f"{sigma!r}")
    if orders is not None and not all(MIN_ORDER <= d <= MAX_ORDER for d in orders):
        raise CalibrationError(f"servo curve orders must be {MIN_ORDER}–{MAX_ORDER}; got "
                               f"{orders!r}")
    p0 = nominal.pen_points(marks.pulses, marks.approach, marks.assembly)
    if not np.all(np.isfinite(p0)):
        raise CalibrationError("the profile cannot reach some of the pattern's pulses")
    sheet = marks.sheet_of()
    if sheet.min() < 0 or np.bincount(sheet).min() < 2:
        raise CalibrationError("every sheet of marks needs at least two marks to place it")
    place = [np.concatenate(([phi], t)) for phi, t in
             (rigid_fit(p0[sheet == j], marks.measured[sheet == j])
              for j in range(marks.sheets))]
    x0 = np.concatenate((nominal.vector(), *place))
    cu = nominal.centre_us
    before = servo_model_points(x0, marks, cu) - marks.measured
    x, best, its, crit = _select_orders(x0, marks, cu, orders, fit_dead_band, fit_extension,
                                        sigma, max_iterations)
    free = _free_mask(best, fit_dead_band, fit_extension, x.size)
    r = _residuals(x, marks, cu)
    assert r is not None
    jac = _jacobian(x, marks, cu, free)
    dof = 2 * marks.n - int(free.sum())
    s_res = math.sqrt(float(r @ r) / dof)
    s, source = (sigma, "given") if sigma is not None else (s_res, "residual")
    cov = np.zeros((x.size, x.size))
    cov[np.ix_(free, free)] = covariance(jac[:, free], s)
    return ServoFit(x=x, covariance=cov, residual_before=before,
                    residual_after=r.reshape(-1, 2), sigma=s, sigma_source=source, free=free,
                    iterations=its, dof=dof, centre_us=cu, orders=best,
                    criteria=tuple(sorted(crit.items())))
