"""Calibration of a servo five-bar from a drawn pattern: each servo's pulse ↔ angle curve and
dead band, the link lengths and the pen's extension, with their uncertainties (pure numpy).

The stepper fit (`kinematics.calibration`) knows the angle of every commanded step; a hobby
servo does not: its angle is an unknown, non-linear function of the pulse, and where the arm
stops depends on the side it came from (the dead band, `kinematics.servo` Eq. S1). So the
model of one mark i, drawn with the pulses p_ik (k = 1, 2) after a move in which joint k's
commanded angle went up (s_ik = +1) or down (s_ik = −1), is

    u = (p_ik − centre_k) / 500 µs
    θ_ik = c_k0 + c_k1·u + c_k2·u² + c_k3·u³ − s_ik·w_k/2                    (SC1)
    P_i = FK(a1, b1, a2, b2, w, e, γ; θ_i)   (kinematics.extension, the machine's assembly)
    m_i = Rot(φ)·P_i + (tx, ty),   r_i = m_i − y_i                                 (SC2)

— a cubic curve per servo (the issue's "low-order fit"), a dead band of width w_k per servo,
the seven lengths/angles of the geometry and the paper placement: `N_SERVO_PARAMS` = 20
unknowns, vector order `SERVO_PARAM_NAMES`. The dead band is told apart from the curve's
offset c_k0 only by marks approached from both sides, which is why the pattern
(`approach_signs`) alternates the approach of each joint from mark to mark.

The fit is Levenberg–Marquardt with Marquardt's diagonal scaling, as for steppers, on a
central-difference Jacobian (the model is 20 parameters × 2N residuals; the analytic one
would not pay). The covariance is s²·(JᵀJ)⁻¹ with s the given measurement σ or the residual
standard deviation √(|r|²/(2N − n_free)) (`kinematics.calibration.covariance`, F1/F2); fixed
parameters (`free` = False) get zero variance.

The drawing-shape error (`pattern_shape_error`): a model M draws intended point p with
approach s by commanding the pulses that, under M, put the arm there (the inverse curve of
the IK angle overshot by s·w/2, `commanded_pulses`); the true machine T turns them into
θ = T's curve − s·w_T/2 and draws FK_T(θ). The error is the max |aligned drawn − intended|
after the rigid alignment that fits all points best (the paper may sit anywhere).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from kinematics.arrays import BoolArray, FloatArray
from kinematics.calibration import CalibrationError, covariance, rigid_fit, rotation
from kinematics.extension import ExtendedFiveBar
from kinematics.servo import ServoCurve

__all__ = ["GEOMETRY_NAMES", "N_SERVO_PARAMS", "PULSE_SCALE_US", "SERVO_PARAM_NAMES",
           "ServoFit", "ServoMachine", "ServoMarks", "approach_signs", "commanded_pulses",
           "fit_servo", "pattern_points", "pattern_shape_error", "servo_model_points",
           "with_dead_band"]

GEOMETRY_NAMES: tuple[str, ...] = ("a1", "b1", "a2", "b2", "w", "e", "gamma")
SERVO_PARAM_NAMES: tuple[str, ...] = (
    *GEOMETRY_NAMES, "c10", "c11", "c12", "c13", "c20", "c21", "c22", "c23",
    "dead1", "dead2", "phi", "tx", "ty")
N_SERVO_PARAMS = len(SERVO_PARAM_NAMES)
N_MACHINE = N_SERVO_PARAMS - 3
#: The pulse scale of the curve's variable u (SC1), µs.
PULSE_SCALE_US = 500.0
#: Fewest marks a servo fit accepts (2N ≥ 2·20 equations).
MIN_SERVO_MARKS = 20


@dataclass(frozen=True)
class ServoMachine:
    """A servo five-bar's true (or modelled) parameters: geometry (7: a1, b1, a2, b2, w mm,
    extension e mm, γ rad), cubic curve coefficients (2, 4) rad per servo in u (SC1), the
    pulse each curve is centred on (2,) µs and the dead band widths (2,) rad."""

    geometry: tuple[float, ...]
    coeffs: FloatArray
    centre_us: tuple[float, float]
    dead_band: tuple[float, float]

    @classmethod
    def from_vector(cls, v: ArrayLike, centre_us: tuple[float, float]) -> ServoMachine:
        """From the first 17 entries of a parameter vector (`SERVO_PARAM_NAMES` order)."""
        x = np.asarray(v, dtype=np.float64)
        return cls(tuple(float(c) for c in x[:7]), x[7:15].reshape(2, 4).copy(), centre_us,
                   (float(x[15]), float(x[16])))

    @classmethod
    def from_curves(cls, geometry: ExtendedFiveBar, curves: tuple[ServoCurve, ServoCurve],
                    dead_band: tuple[float, float], centre_us: tuple[float, float]
                    ) -> ServoMachine:
        """A profile's servos: each curve (a table) replaced by its least-squares cubic in u."""
        g = (geometry.a1, geometry.b1, geometry.a2, geometry.b2, geometry.w,
             geometry.extension, geometry.extension_angle)
        co = np.zeros((2, 4))
        for k, c in enumerate(curves):
            ps = np.linspace(*c.range_us, 65)
            u = (ps - centre_us[k]) / PULSE_SCALE_US
            co[k] = np.polynomial.polynomial.polyfit(u, c.angle(ps), 3)
        return cls(g, co, centre_us, dead_band)

    def vector(self) -> FloatArray:
        """(17,) in `SERVO_PARAM_NAMES` order (no placement)."""
        return np.concatenate((self.geometry, self.coeffs.ravel(), self.dead_band))

    def fivebar(self) -> ExtendedFiveBar:
        """The geometry (raises ValueError when it cannot close)."""
        a1, b1, a2, b2, w, e, g = self.geometry
        return ExtendedFiveBar(a1, b1, a2, b2, w, extension=e, extension_angle=g)

    def curve_angles(self, pulses: ArrayLike) -> FloatArray:
        """The curves' angles (N, 2) rad of pulses (N, 2) µs, without the dead band."""
        p = np.asarray(pulses, dtype=np.float64).reshape(-1, 2)
        u = (p - np.asarray(self.centre_us)) / PULSE_SCALE_US
        return np.asarray(np.stack([np.polynomial.polynomial.polyval(u[:, k], self.coeffs[k])
                                    for k in range(2)], axis=1), dtype=np.float64)

    def angles(self, pulses: ArrayLike, approach: ArrayLike) -> FloatArray:
        """Joint angles (N, 2) rad reached with pulses (N, 2) after moves of sign `approach`
        (N, 2) in angle (SC1)."""
        s = np.asarray(approach, dtype=np.float64).reshape(-1, 2)
        return np.asarray(self.curve_angles(pulses) - 0.5 * s * np.asarray(self.dead_band),
                          dtype=np.float64)

    def pen_points(self, pulses: ArrayLike, approach: ArrayLike, assembly: str) -> FloatArray:
        """Pen positions (N, 2) mm; NaN rows where the loop cannot close."""
        fwd = self.fivebar().forward_batch(self.angles(pulses, approach), assembly)
        pts = np.asarray(fwd.points, dtype=np.float64).copy()
        pts[~fwd.valid] = np.nan
        return pts

    def pulses_for(self, angles: ArrayLike, range_us: tuple[float, float] = (500.0, 2500.0)
                   ) -> FloatArray:
        """Pulses (N, 2) µs whose curve angles are `angles` (N, 2) rad (taken within half a turn
        of each curve's centre angle c_k0), by bisection over `range_us` (each cubic taken as
        monotone there); NaN where the range cannot reach the angle."""
        th = np.asarray(angles, dtype=np.float64).reshape(-1, 2)
        c0 = self.coeffs[:, 0]
        th = c0 + (th - c0 + math.pi) % (2.0 * math.pi) - math.pi  # the turn nearest c_k0
        cu = np.asarray(self.centre_us)
        lo = np.broadcast_to((range_us[0] - cu) / PULSE_SCALE_US, th.shape).copy()
        hi = np.broadcast_to((range_us[1] - cu) / PULSE_SCALE_US, th.shape).copy()
        rising = np.array([np.polynomial.polynomial.polyval(1.0, c)
                           > np.polynomial.polynomial.polyval(-1.0, c) for c in self.coeffs])
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            f = np.stack([np.polynomial.polynomial.polyval(mid[:, k], self.coeffs[k])
                          for k in range(2)], axis=1)
            below = (f < th) == rising
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        u = 0.5 * (lo + hi)
        ends = ((np.asarray(range_us)[:, None] - cu) / PULSE_SCALE_US)  # (2 ends, 2 servos)
        f_ends = np.array([[np.polynomial.polynomial.polyval(ends[e, k], self.coeffs[k])
                            for k in range(2)] for e in range(2)])
        tol = 1e-9
        inside = ((th >= f_ends.min(axis=0) - tol) & (th <= f_ends.max(axis=0) + tol))
        return np.asarray(np.where(inside, cu + u * PULSE_SCALE_US, np.nan), dtype=np.float64)

    def curve(self, k: int, range_us: tuple[float, float], samples: int = 17) -> ServoCurve:
        """Servo k's cubic as a `ServoCurve` table over `range_us` (raises `ServoError` if it
        is not monotone there)."""
        ps = np.linspace(range_us[0], range_us[1], samples)
        u = (ps - self.centre_us[k]) / PULSE_SCALE_US
        return ServoCurve(ps, np.polynomial.polynomial.polyval(u, self.coeffs[k]))


@dataclass(frozen=True)
class ServoMarks:
    """What one servo fit sees: the pulses (N, 2) µs each mark was drawn with, the sign (N, 2)
    of each joint's last commanded move into it, the measured positions (N, 2) mm in the
    paper frame and the machine's assembly ("+"/"-")."""

    pulses: FloatArray
    approach: FloatArray
    measured: FloatArray
    assembly: str

    @property
    def n(self) -> int:
        return int(self.pulses.shape[0])


def approach_signs(n: int) -> FloatArray:
    """The pattern's approach signs (n, 2): the four combinations (+,+), (−,−), (+,−), (−,+)
    in turn, so that every joint comes from both sides in every part of the pattern."""
    cycle = np.array([[1.0, 1.0], [-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]])
    return np.asarray(cycle[np.arange(n) % 4])


def pattern_points(model: ServoMachine, mode: str, assembly: str,
                   limits: tuple[tuple[float, float], tuple[float, float]],
                   margins: tuple[float, float], n: int) -> FloatArray:
    """`n` mark centres (n, 2) mm spread over the joint limits (rad) of a servo five-bar: a
    61×61 grid of joint angles, kept where the loop closes in `assembly`, the pen is in
    working mode `mode` and the type 1 / type 2 singularity margins (rad) hold, thinned by
    farthest-point sampling in joint space (so the marks cover each curve's range)."""
    fb = model.fivebar()
    g1 = np.linspace(*limits[0], 61)
    g2 = np.linspace(*limits[1], 61)
    th = np.stack(np.meshgrid(g1, g2, indexing="ij"), axis=-1).reshape(-1, 2)
    fwd = fb.forward_batch(th, assembly)
    th, pts = th[fwd.valid], np.asarray(fwd.points)[fwd.valid]
    want = np.array([1 if c == "+" else -1 for c in mode])
    sm = fb.singularity_margins(th, pts)
    ok = ((fb.mode_of(pts, th) == want).all(axis=1)
          & (np.abs(sm[:, :2]) >= margins[0]).all(axis=1) & (np.abs(sm[:, 2]) >= margins[1]))
    th, pts = th[ok], pts[ok]
    if th.shape[0] < n:
        raise CalibrationError(f"only {th.shape[0]} safe poses inside the joint limits; "
                               f"{n} marks asked for")
    pick = [int(np.argmin(np.linalg.norm(th - th.mean(axis=0), axis=1)))]
    dist = np.linalg.norm(th - th[pick[0]], axis=1)
    for _ in range(n - 1):
        pick.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(th - th[pick[-1]], axis=1))
    return np.asarray(pts[pick])


def commanded_pulses(model: ServoMachine, points: ArrayLike, approach: ArrayLike, mode: str
                     ) -> FloatArray:
    """The pulses (N, 2) µs a model sends to draw `points` (N, 2) after moves of sign
    `approach`: the IK angles overshot by s·w/2 (the dead-band take-up) through the inverse
    curves (NaN outside 500–2500 µs; raises `UnreachableError` off the model's reach)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    th = np.asarray(model.fivebar().inverse_batch(pts, mode).require(pts))
    s = np.asarray(approach, dtype=np.float64).reshape(-1, 2)
    return model.pulses_for(th + 0.5 * s * np.asarray(model.dead_band))


def pattern_shape_error(true: ServoMachine, model: ServoMachine, points: ArrayLike,
                        approach: ArrayLike, mode: str, assembly: str) -> FloatArray:
    """|aligned drawn − intended| (N,) mm when `model` draws `points` on the machine `true`
    (module doc); NaN where the model's pulses or the true machine cannot reach a point."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    s = np.asarray(approach, dtype=np.float64).reshape(-1, 2)
    pulses = commanded_pulses(model, pts, s, mode)
    drawn = np.full_like(pts, np.nan)
    have = np.isfinite(pulses).all(axis=1)
    drawn[have] = true.pen_points(pulses[have], s[have], assembly)
    ok = np.isfinite(drawn).all(axis=1)
    phi, t = rigid_fit(drawn[ok], pts[ok])
    err = np.full(pts.shape[0], np.nan)
    err[ok] = np.linalg.norm(drawn[ok] @ rotation(phi).T + t - pts[ok], axis=1)
    return err


def servo_model_points(x: FloatArray, marks: ServoMarks, centre_us: tuple[float, float]
                       ) -> FloatArray:
    """Predicted mark positions (N, 2) in the paper frame for parameters `x` (SC2)."""
    m = ServoMachine.from_vector(x, centre_us)
    p = m.pen_points(marks.pulses, marks.approach, marks.assembly)
    return np.asarray(p @ rotation(float(x[17])).T + x[18:20], dtype=np.float64)


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
    """Central-difference d residuals / d parameters (2N, 20); zero columns where fixed."""
    jac = np.zeros((2 * marks.n, N_SERVO_PARAMS))
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
    """A converged servo fit: parameters (20,), covariance (20, 20) (zero rows for fixed
    parameters), residuals (N, 2) before (the profile, best placement) and after, σ and its
    source ("given"/"residual"), the free mask, iterations, degrees of freedom, centres."""

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

    @property
    def machine(self) -> ServoMachine:
        return ServoMachine.from_vector(self.x, self.centre_us)

    @property
    def std(self) -> FloatArray:
        """Standard deviations (20,) (inf where undetermined, 0 where fixed)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    @property
    def rms_before_mm(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.residual_before ** 2, axis=1))))

    @property
    def rms_after_mm(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.residual_after ** 2, axis=1))))

    def curve_std(self, k: int, pulses: ArrayLike) -> FloatArray:
        """Standard deviation (N,) rad of servo k's fitted curve angle at `pulses`, from the
        covariance of its four coefficients (and its correlations)."""
        u = (np.asarray(pulses, dtype=np.float64) - self.centre_us[k]) / PULSE_SCALE_US
        basis = np.stack([u ** j for j in range(4)], axis=-1)
        sl = slice(7 + 4 * k, 11 + 4 * k)
        cov = self.covariance[sl, sl]
        return np.asarray(np.sqrt(np.maximum(np.einsum("...i,ij,...j->...", basis, cov,
                                                       basis), 0.0)))


def fit_servo(nominal: ServoMachine, marks: ServoMarks, *, sigma: float | None = None,
              fit_dead_band: bool = True, fit_extension: bool = True,
              max_iterations: int = 200) -> ServoFit:
    """Fit the servo model (module doc) to the measured marks, starting from `nominal` and
    the paper placement that best maps its predicted marks onto the measured ones.
    `fit_dead_band` False keeps the nominal dead band (what a fit that ignores it gets);
    `fit_extension` False keeps e and γ (a pen at the joint has none to fit)."""
    if marks.n < MIN_SERVO_MARKS:
        raise CalibrationError(f"{marks.n} marks measured; the servo fit needs at least "
                               f"{MIN_SERVO_MARKS}")
    if sigma is not None and not (math.isfinite(sigma) and sigma > 0):
        raise CalibrationError(f"measurement sigma must be a positive number of mm; got "
                               f"{sigma!r}")
    p0 = nominal.pen_points(marks.pulses, marks.approach, marks.assembly)
    if not np.all(np.isfinite(p0)):
        raise CalibrationError("the profile cannot reach some of the pattern's pulses")
    phi, t = rigid_fit(p0, marks.measured)
    x0 = np.concatenate((nominal.vector(), [phi], t))
    free = np.ones(N_SERVO_PARAMS, dtype=bool)
    free[15:17] = fit_dead_band
    free[5:7] = fit_extension
    cu = nominal.centre_us
    before = servo_model_points(x0, marks, cu) - marks.measured
    x, its = _levenberg_marquardt(x0, marks, cu, free, max_iterations)
    r = _residuals(x, marks, cu)
    assert r is not None
    jac = _jacobian(x, marks, cu, free)
    dof = 2 * marks.n - int(free.sum())
    s_res = math.sqrt(float(r @ r) / dof)
    s, source = (sigma, "given") if sigma is not None else (s_res, "residual")
    cov = np.zeros((N_SERVO_PARAMS, N_SERVO_PARAMS))
    cov[np.ix_(free, free)] = covariance(jac[:, free], s)
    return ServoFit(x=x, covariance=cov, residual_before=before,
                    residual_after=r.reshape(-1, 2), sigma=s, sigma_source=source, free=free,
                    iterations=its, dof=dof, centre_us=cu)


def with_dead_band(m: ServoMachine, dead_band: tuple[float, float]) -> ServoMachine:
    """`m` with other dead band widths (rad)."""
    return replace(m, dead_band=dead_band)
