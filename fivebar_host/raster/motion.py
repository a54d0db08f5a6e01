"""Each scanline as joint-space segments: a ramp up, the image at one constant pen speed,
a ramp down.

A scanline is the straight Cartesian line P(σ) = P₀ + σ·d (d = ±u, σ mm from the entry
boundary of its first burned pixel to L at the exit of its last).  The five-bar moves the
pen along it through joint space, so the joint rates are g(σ)·v with g = dθ/dσ = J⁻¹d
(rad/mm, both motors changing along the line) — the firmware runs each segment at constant
joint rates, so the line is cut into *pieces*, each a joint-space chord between the inverse
kinematics of two points on the line, quantised to steps once:

* **scan pieces** cover [0, L], k pixels each (the last the rest), k the largest for which
  every chord stays within `RasterCtx.chord_mm` of the line (the pen's bow between its
  ends) and the piece's pixels fit one G7 line; each lasts k·h/v: constant pen speed over
  the image, so every pixel gets the same dose;
* **overscan**: a ramp from rest up to v before σ = 0 and down after L, at a Cartesian
  acceleration a chosen so that the joints' accelerations g·a + (dg/dσ)·v² stay within
  `ACCEL_SHARE` of `max_joint_rad_s2`; the overscan distance is v²/2a, so every pixel is
  burned at the scan speed.  Each ramp is N pieces of equal time t_r/N (t_r = v/a), N
  enough that the joint-speed step between neighbours (≈ g·v/N) stays within
  `JUMP_SHARE` of the junction jump and at least `protocol.P_MIN_US` each.

The chain is then checked on the staircase the firmware runs joint by joint: the jump and
each joint's average acceleration between the pieces' midpoints at every boundary, from rest
to rest (the rule drawings were planned by before issue 39's second round: stricter than
`compile.staircase`'s path-speed rules but for the junction caps the pieces' rounding makes,
which a 1-megapixel photo's scanlines failed at any ramp; the burn is measured on this one);
where it fails, a is lowered by `RELAX` and the scanline planned again.  Every
target is checked like a drawing's (reach, joint limits, both singularity margins:
`toolpath.segment.PoseChecker`); a failure names the scanline's row and the pixel column.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.config import Profile
from fivebar_host.errors import JobError
from fivebar_host.raster.grid import ScanGrid, Scanline
from fivebar_host.raster.linegeo import (
    SAMPLE_MM,
    LineGeo,
    gains,
    line_frame,
    piece_ends,
    solve_bounds,
)
from fivebar_host.toolpath.segment import PoseChecker
from kinematics.arrays import FloatArray, IntArray

__all__ = ["SAMPLE_MM", "LineGeo", "gains", "line_frame", "piece_ends", "solve_bounds"]  # (linegeo)

#: Share of the joint acceleration limit the ramps plan with (the rest absorbs the step
#: quantisation of the staircase).
ACCEL_SHARE = 0.8
#: Share of the junction jump between neighbouring ramp pieces.
JUMP_SHARE = 0.6
#: Factor on the acceleration when the staircase check fails, and how often.
RELAX = 0.8
TRIES = 12
#: Piece kinds.
RAMP_IN, SCAN, RAMP_OUT = 0, 1, 2
_KINDS = np.array([RAMP_IN, SCAN, RAMP_OUT], dtype=np.int64)


@dataclass(frozen=True)
class RasterCtx:
    """What every scanline is planned with."""

    profile: Profile
    checker: PoseChecker
    grid: ScanGrid
    v: float  # scan speed, mm/s
    chord_mm: float  # the largest bow of a scan piece's chord off the line
    k_max: int  # the most pixels of one scan piece (what one G7 line carries)

    @property
    def home(self) -> tuple[float, float]:
        return self.profile.motors.home_rad

    @property
    def spr(self) -> float:
        return self.profile.motors.steps_per_rev


@dataclass(frozen=True)
class ScanMotion:
    """One scanline planned: piece ends (K+1) as ideal points, along-track σ and absolute
    steps; per piece its duration (µs) and kind (RAMP_IN, SCAN, RAMP_OUT); the line's
    start P₀ and direction d, its pixel count and the acceleration it was planned with."""

    line: Scanline
    p0: FloatArray
    d: FloatArray
    sigma: FloatArray
    points: FloatArray
    steps: IntArray
    duration_us: IntArray
    kind: IntArray
    n_px: int
    accel: float

    @property
    def time_us(self) -> int:
        return int(self.duration_us.sum())


def ramp_accel(geo: LineGeo) -> float:
    """The Cartesian acceleration of the scanline's ramps (module docstring)."""
    ctx, sl, length = geo.ctx, geo.sl, geo.length
    alpha = ACCEL_SHARE * ctx.profile.motion.max_joint_rad_s2
    a, v = math.inf, ctx.v
    for _ in range(3):  # the overscan's own gains count too
        over = 0.0 if math.isinf(a) else v * v / (2 * a)
        g, dg = geo.gains(-over - SAMPLE_MM, length + over + SAMPLE_MM)
        room = alpha - dg * v * v
        if room <= 0.1 * alpha:
            raise JobError(f"scanline of row {sl.row}: at {v:.0f} mm/s the joints' "
                           "acceleration along the line alone exceeds max_joint_rad_s2; "
                           "lower --speed", None, "too_fast")
        a = room / g
    return a


def scan_k(geo: LineGeo) -> int:
    """The most pixels a scan piece may hold (module docstring: its chord's bow)."""
    ctx = geo.ctx
    k = min(ctx.k_max, geo.n_px)
    while k > 1:
        ends = piece_ends(geo.n_px, k)
        mids = 0.5 * (ends[:-1] + ends[1:]) * ctx.grid.pitch
        th = geo.bounds[ends]
        pts, _ = ctx.checker.forward(0.5 * (th[:-1] + th[1:]))
        off = pts - geo.p0
        across = np.abs(off[:, 0] * geo.d[1] - off[:, 1] * geo.d[0])
        along = np.abs(off @ geo.d - mids)
        if float(np.maximum(across, along).max()) <= ctx.chord_mm:
            return k
        k = max(1, k * 3 // 4)
    return 1


def _ramp_sigma(v: float, a: float, n: int) -> tuple[FloatArray, FloatArray]:
    """Ramp-in piece ends: σ (−v²/2a … 0) and times (0 … t_r) at n equal steps of time."""
    t_r = v / a
    t = np.linspace(0.0, t_r, n + 1)
    return 0.5 * a * t * t - v * v / (2 * a), t


def _cum_us(times_s: FloatArray) -> IntArray:
    """Whole-µs durations between consecutive times, rounded on the running time (no drift)."""
    us = np.rint(np.asarray(times_s) * 1e6).astype(np.int64)
    return us[1:] - us[:-1]


def plan_scanline(geo: LineGeo, k: int, a: float) -> ScanMotion:
    """The scanline at ramp acceleration `a` with scan pieces of k pixels (module docstring),
    not yet checked on the staircase."""
    ctx, sl, p0, d, length = geo.ctx, geo.sl, geo.p0, geo.d, geo.length
    v, jump = ctx.v, ctx.profile.motion.junction_jump_rad_s
    g, _ = geo.gains(-v * v / (2 * a), length + v * v / (2 * a))
    n = max(1, math.ceil(g * v / (JUMP_SHARE * jump)))
    t_r = v / a
    if t_r / n < protocol.P_MIN_US * 1e-6:  # pieces of at least the shortest P
        n = max(1, math.floor(t_r / (protocol.P_MIN_US * 1e-6)))
    s_in, t_in = _ramp_sigma(v, a, n)
    s_out = length - s_in[::-1]
    ramps = absolute_steps(geo.ik(np.concatenate((s_in, s_out[1:]))), ctx.home, ctx.spr)
    ends, scan_steps, s_exec = geo.scan_part(k, ramps[n])
    scan = ends * ctx.grid.pitch
    sigma = np.concatenate((s_in, scan[1:], s_out[1:]))
    kind = np.repeat(_KINDS, (n, scan.shape[0] - 1, n))
    steps = np.concatenate((ramps[:n + 1], scan_steps, ramps[n + 1:]))
    # the scan pieces last what the pen really travels along the line between their
    # quantised ends (s_exec), at v: every pixel boundary is crossed at σ/v from one time
    # origin, across pieces too, so one G7 line's U + i·T spans several pieces
    times = np.concatenate((t_in, t_in[-1] + (s_exec[1:] - s_exec[0]) / v))
    times = np.concatenate((times, times[-1] + t_in[1:]))
    dur = np.maximum(_cum_us(times), protocol.P_MIN_US)
    return ScanMotion(sl, p0, d, sigma, p0 + np.multiply.outer(sigma, d), steps, dur, kind,
                      geo.n_px, a)


def staircase_ok(ctx: RasterCtx, sm: ScanMotion, th: FloatArray | None = None) -> bool:
    """Whether the firmware's staircase of the scanline keeps the jump and acceleration
    limits at every boundary, from rest to rest (`th`: its steps' angles, when known)."""
    if th is None:
        th = step_angles(sm.steps, ctx.home, ctx.spr)
    mo = ctx.profile.motion
    dth = th[1:] - th[:-1]
    # one run from rest to rest (every piece lasts ≥ P_MIN, so no piece is motionless),
    # joint by joint (module doc): the largest ratio is the largest difference divided by
    # the limit (rounding is monotone)
    t = sm.duration_us * 1e-6
    w = dth / t[:, None]
    aw = np.abs(w)
    dw = np.abs(w[1:] - w[:-1])
    dw = np.maximum(dw[:, 0], dw[:, 1])
    wn = np.maximum(aw[[0, -1], 0], aw[[0, -1], 1])  # into the first, out of the last
    tb = 0.5 * (t[1:] + t[:-1])
    jump = max(float(dw.max()) if dw.size else 0.0, float(wn.max())) / mo.junction_jump_rad_s
    acc = max(float((dw / tb).max()) if dw.size else 0.0,
              float((wn / (0.5 * t[[0, -1]])).max())) / mo.max_joint_rad_s2
    rate = np.maximum(np.abs(dth[:, 0]), np.abs(dth[:, 1])) / t
    return (jump <= 1.0 and acc <= 1.0
            and float(rate.max()) <= mo.max_joint_rad_s * (1 + 1e-9))


def plan(geo: LineGeo, k: int) -> ScanMotion:
    """The scanline planned with scan pieces of k pixels and checked (module docstring)."""
    ctx = geo.ctx
    a = geo.accel if geo.accel is not None else ramp_accel(geo)
    for _ in range(TRIES):
        sm = plan_scanline(geo, k, a)
        th = step_angles(sm.steps, ctx.home, ctx.spr)
        if staircase_ok(ctx, sm, th):
            geo.accel = a
            geo.check(sm.sigma, th)
            return sm
        a *= RELAX
    raise JobError(f"scanline of row {geo.sl.row}: no ramp keeps the joints within "
                   f"max_joint_rad_s2 and the junction jump at {ctx.v:.0f} mm/s; lower --speed",
                   None, "too_fast")
