"""The servo five-bar model the servo calibration fits (`kinematics.servo_calibration`): each
servo's pulse ↔ angle curve as a polynomial in the pulse, its dead band, the geometry; the
pattern's marks and approach signs; what a model draws on another (the shape error).

One mark i, drawn with the pulses p_ik (k = 1, 2) after a move in which joint k's commanded
angle went up (s_ik = +1) or down (s_ik = −1):

    u = (p_ik − centre_k) / 500 µs
    θ_ik = C_k(u) − s_ik·w_k/2,   C_k(u) = Σ_{j ≤ d_k} c_kj·uʲ                       (SC1)
    P_i = FK(a1, b1, a2, b2, w, e, γ; θ_i)   (kinematics.extension, the machine's assembly)
    m_i = Rot(φ)·P_i + (tx, ty),   r_i = m_i − y_i                                 (SC2)

— a polynomial of order d_k ≤ `MAX_ORDER` per servo (a cubic was the issue's "low-order
fit"; a real servo's curve also ripples, which only a higher order follows), a dead band of
width w_k per servo, the geometry and the paper placement. Coefficients above a servo's
order are zero. Beyond the pulses it was fitted on the polynomial extrapolates: the pulses
a drawing needs there are what a second round of the pattern measures
(`kinematics.servo_calibration`).

The parameter vector has a fixed layout whatever the orders (`SERVO_PARAM_NAMES`): geometry
(`GEOMETRY`), `MAX_ORDER` + 1 coefficients per servo (`COEFFS`), the dead bands (`DEAD`), the
placement (`PLACE`). The dead band is told apart from the offset c_k0 only by marks approached
from both sides, which is why the pattern (`approach_signs`) alternates the approach of each
joint from mark to mark.

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
from numpy.polynomial import polynomial as npoly
from numpy.typing import ArrayLike

from kinematics.arrays import FloatArray, IntArray
from kinematics.calibration import CalibrationError, rigid_fit, rotation
from kinematics.extension import ExtendedFiveBar
from kinematics.servo import ServoCurve

__all__ = ["COEFFS", "DEAD", "GEOMETRY", "GEOMETRY_NAMES", "MAX_ORDER", "N_COEFFS",
           "N_SERVO_PARAMS", "PLACE", "PULSE_SCALE_US", "SERVO_PARAM_NAMES", "ServoMachine",
           "ServoMarks", "approach_signs", "commanded_pulses", "pattern_points",
           "pattern_shape_error", "with_dead_band"]

#: Highest polynomial order a servo curve may take (SC1).
MAX_ORDER = 7
N_COEFFS = MAX_ORDER + 1
GEOMETRY_NAMES: tuple[str, ...] = ("a1", "b1", "a2", "b2", "w", "e", "gamma")
SERVO_PARAM_NAMES: tuple[str, ...] = (
    *GEOMETRY_NAMES, *(f"c{k}{j}" for k in (1, 2) for j in range(N_COEFFS)),
    "dead1", "dead2", "phi", "tx", "ty")
N_SERVO_PARAMS = len(SERVO_PARAM_NAMES)
#: Where each group sits in the parameter vector.
GEOMETRY = slice(0, 7)
COEFFS = slice(7, 7 + 2 * N_COEFFS)
DEAD = slice(COEFFS.stop, COEFFS.stop + 2)
PLACE = slice(DEAD.stop, DEAD.stop + 3)
#: The pulse scale of the curve's variable u (SC1), µs.
PULSE_SCALE_US = 500.0


@dataclass(frozen=True)
class ServoMachine:
    """A servo five-bar's true (or modelled) parameters: geometry (7: a1, b1, a2, b2, w mm,
    extension e mm, γ rad), curve coefficients (2, ≤ `N_COEFFS`) rad per servo in u (SC1,
    stored zero-padded to `N_COEFFS`), the pulse each curve is centred on (2,) µs and the
    dead band widths (2,) rad."""

    geometry: tuple[float, ...]
    coeffs: FloatArray
    centre_us: tuple[float, float]
    dead_band: tuple[float, float]

    def __post_init__(self) -> None:
        c = np.asarray(self.coeffs, dtype=np.float64)
        if c.ndim != 2 or c.shape[0] != 2 or not 1 <= c.shape[1] <= N_COEFFS:
            raise ValueError(f"servo curve coefficients must be (2, ≤ {N_COEFFS}); got "
                             f"{c.shape}")
        object.__setattr__(self, "coeffs", np.pad(c, ((0, 0), (0, N_COEFFS - c.shape[1]))))

    @classmethod
    def from_vector(cls, v: ArrayLike, centre_us: tuple[float, float]) -> ServoMachine:
        """From the machine entries of a parameter vector (`SERVO_PARAM_NAMES` order)."""
        x = np.asarray(v, dtype=np.float64)
        return cls(tuple(float(c) for c in x[GEOMETRY]),
                   x[COEFFS].reshape(2, N_COEFFS).copy(), centre_us,
                   (float(x[DEAD][0]), float(x[DEAD][1])))

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
            co[k] = npoly.polyfit(u, c.angle(ps), 3)
        return cls(g, co, centre_us, dead_band)

    def vector(self) -> FloatArray:
        """The machine entries of the parameter vector (no placement)."""
        return np.concatenate((self.geometry, self.coeffs.ravel(), self.dead_band))

    def fivebar(self) -> ExtendedFiveBar:
        """The geometry (raises ValueError when it cannot close)."""
        a1, b1, a2, b2, w, e, g = self.geometry
        return ExtendedFiveBar(a1, b1, a2, b2, w, extension=e, extension_angle=g)

    def curve_u(self, k: int, u: ArrayLike) -> FloatArray:
        """Servo k's curve angle (rad) at u (SC1)."""
        return np.asarray(npoly.polyval(np.asarray(u, dtype=np.float64), self.coeffs[k]),
                          dtype=np.float64)

    def curve_angles(self, pulses: ArrayLike) -> FloatArray:
        """The curves' angles (N, 2) rad of pulses (N, 2) µs, without the dead band."""
        p = np.asarray(pulses, dtype=np.float64).reshape(-1, 2)
        u = (p - np.asarray(self.centre_us)) / PULSE_SCALE_US
        return np.stack([self.curve_u(k, u[:, k]) for k in range(2)], axis=1)

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
        of each curve's centre angle c_k0), by bisection over `range_us` (each curve taken as
        monotone there); NaN where the range cannot reach the angle."""
        th = np.asarray(angles, dtype=np.float64).reshape(-1, 2)
        c0 = self.coeffs[:, 0]
        th = c0 + (th - c0 + math.pi) % (2.0 * math.pi) - math.pi  # the turn nearest c_k0
        cu = np.asarray(self.centre_us)
        ends = (np.asarray(range_us)[:, None] - cu) / PULSE_SCALE_US  # (2 ends, 2 servos)
        f_ends = np.stack([self.curve_u(k, ends[:, k]) for k in range(2)], axis=1)
        rising = f_ends[1] > f_ends[0]
        lo = np.broadcast_to(ends[0], th.shape).copy()
        hi = np.broadcast_to(ends[1], th.shape).copy()
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            f = np.stack([self.curve_u(k, mid[:, k]) for k in range(2)], axis=1)
            below = (f < th) == rising
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        u = 0.5 * (lo + hi)
        tol = 1e-9
        inside = ((th >= f_ends.min(axis=0) - tol) & (th <= f_ends.max(axis=0) + tol))
        return np.asarray(np.where(inside, cu + u * PULSE_SCALE_US, np.nan), dtype=np.float64)

    def curve(self, k: int, range_us: tuple[float, float], samples: int = 17) -> ServoCurve:
        """Servo k's curve as a `ServoCurve` table over `range_us` (raises `ServoError` if it
        is not monotone there)."""
        ps = np.linspace(range_us[0], range_us[1], samples)
        return ServoCurve(ps, self.curve_u(k, (ps - self.centre_us[k]) / PULSE_SCALE_US))


@dataclass(frozen=True)
class ServoMarks:
    """What one servo fit sees: the pulses (N, 2) µs each mark was drawn with, the sign (N, 2)
    of each joint's last commanded move into it, the measured positions (N, 2) mm in the
    paper frame, the machine's assembly ("+"/"-") and, for marks from several rounds of the
    pattern, the sheet (N,) each was drawn and measured on (None: one sheet). Each sheet has
    its own placement (φ, tx, ty): the first in `PLACE`, the others appended after it."""

    pulses: FloatArray
    approach: FloatArray
    measured: FloatArray
    assembly: str
    sheet: IntArray | None = None

    @property
    def n(self) -> int:
        return int(self.pulses.shape[0])

    @property
    def sheets(self) -> int:
        """How many sheets (rounds of the pattern, each measured in its own frame)."""
        return 1 if self.sheet is None else int(np.max(self.sheet)) + 1

    def sheet_of(self) -> IntArray:
        """The sheet (N,) each mark was measured on (0 … sheets − 1)."""
        return (np.zeros(self.n, dtype=np.int64) if self.sheet is None
                else np.asarray(self.sheet, dtype=np.int64))


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


def with_dead_band(m: ServoMachine, dead_band: tuple[float, float]) -> ServoMachine:
    """`m` with other dead band widths (rad)."""
    return replace(m, dead_band=dead_band)
