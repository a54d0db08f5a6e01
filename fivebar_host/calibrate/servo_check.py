"""`fivebar calibrate check` on servo profiles: how wrong the old profile draws, taking the
fitted one (its geometry, pulse ↔ angle curves and dead bands) as the true machine.

A servo joint has no home: its angle is the curve's at the pulse it is sent. The old
profile draws a point p approached with joint signs s ∈ {±1}² by sending the pulses of its
own inverse kinematics overshot by its dead band (`kinematics.servo.dead_band_commands`,
what a run sends):

    u = curve_old⁻¹(IK_old(p) + s·w_old/2)                                          (C1)

and the fitted machine turns to θ = curve_fit(u) − s·w_fit/2 (Eq. S1: it stops short by
half its band on the side it came from) and puts the pen at FK_fit(θ). The four
approaches are drawn on one sheet of paper, so one rigid alignment of all of them onto the
intended points (the paper may sit anywhere: `kinematics.calibration.rigid_fit`) is taken,
and each point's error is its worst over the four approaches: a dead band that is wrong
shows as points that land apart depending on the side the pen came from.

The region: the fitted machine's pen positions, on a `pitch` mm grid, in the working mode,
in the machine's assembly, inside the joint limits and the singularity margins
(the checks a plot makes), and where
both profiles' pulses stay within their curves.
"""

from __future__ import annotations

import math

import numpy as np

from fivebar_host.calibrate.check import ErrorMap
from fivebar_host.calibrate.pattern import pattern_mode
from fivebar_host.config import Profile
from fivebar_host.joints import ServoJoints
from kinematics.arrays import BoolArray, FloatArray
from kinematics.calibration import CalibrationError, rigid_fit, rotation

#: Approach signs: both joints up, both down, and the two mixed ones.
APPROACHES = np.array([[1.0, 1.0], [-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]])


def _joints(p: Profile, role: str) -> ServoJoints:
    if p.joints is None:
        raise CalibrationError(f"{p.source} ({role}): a stepper profile; calibrate check "
                               "compares a servo profile with a servo profile")
    return p.joints


def servo_region(fitted: Profile, mode: str, pitch_mm: float
                 ) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Grid xs (nx,), ys (ny,) mm and the mask (ny, nx) of the fitted machine's safe pen
    positions (module doc): assembly, joint limits, working mode, type 1 / type 2 margins."""
    fb, k = fitted.geometry, fitted.kinematics
    lim = fitted.motors.limits_rad
    g = np.stack(np.meshgrid(np.linspace(*lim[0], 121), np.linspace(*lim[1], 121)),
                 -1).reshape(-1, 2)
    fwd = fb.forward_batch(g, k.assembly)
    pts = np.asarray(fwd.points)[fwd.valid]
    if not pts.size:
        raise CalibrationError(f"{fitted.source}: no pen position inside the joint limits")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    xs = np.arange(math.floor(lo[0]), math.ceil(hi[0]) + pitch_mm, pitch_mm)
    ys = np.arange(math.floor(lo[1]), math.ceil(hi[1]) + pitch_mm, pitch_mm)
    gx, gy = np.meshgrid(xs, ys)
    p = np.stack((gx.ravel(), gy.ravel()), axis=1)
    inv = fb.inverse_batch(p, mode)
    th = np.where(inv.valid[:, None], inv.angles, 0.0)
    ok = inv.valid.copy()
    for j in (0, 1):
        ok &= (th[:, j] >= lim[j][0]) & (th[:, j] <= lim[j][1])
    back = fb.forward_batch(th, k.assembly)  # the pose in the machine's assembly
    ok &= back.valid & (np.hypot(*(np.asarray(back.points) - p).T) < 1e-6)
    sm = fb.singularity_margins(th, p)
    ok &= (np.abs(sm[:, :2]) >= k.min_type1_margin_rad).all(axis=1)
    ok &= np.abs(sm[:, 2]) >= k.min_type2_margin_rad
    return xs, ys, ok.reshape(gx.shape)


def drawn_by(fitted: Profile, old: Profile, points: FloatArray, approach: FloatArray,
             mode: str) -> FloatArray:
    """Where the fitted machine puts the pen (N, 2) when the old profile draws `points`
    (N, 2) approached with signs `approach` (2,) (Eq. C1); NaN where a pulse leaves a
    curve or the loop cannot close."""
    jo, jf = _joints(old, "old"), _joints(fitted, "fitted")
    inv = old.geometry.inverse_batch(points, mode)
    th = np.full(points.shape, np.nan)
    ok = inv.valid.copy()
    for j in (0, 1):
        co, cf = jo.joints[j].curve, jf.joints[j].curve
        cmd = inv.angles[:, j] + 0.5 * approach[j] * jo.joints[j].dead_band_rad
        lo, hi = co.range_rad
        inside = ok & (cmd >= lo) & (cmd <= hi)
        u = np.full(points.shape[0], np.nan)
        u[inside] = co.pulse(cmd[inside])
        plo, phi = cf.range_us
        inside &= (u >= plo) & (u <= phi)
        th[inside, j] = cf.angle(u[inside]) - 0.5 * approach[j] * jf.joints[j].dead_band_rad
        ok &= inside
    out = np.full(points.shape, np.nan)
    if ok.any():
        fwd = fitted.geometry.forward_batch(th[ok], fitted.kinematics.assembly)
        pts = np.asarray(fwd.points, dtype=np.float64).copy()
        pts[~fwd.valid] = np.nan
        out[ok] = pts
    return out


def servo_error_map(fitted: Profile, old: Profile, mode: str | None = None,
                    pitch_mm: float = 1.0) -> ErrorMap:
    """The old servo profile's predicted drawing-shape error over the fitted machine's safe
    region, the worst of the four approaches at each point (module doc)."""
    _joints(fitted, "fitted")
    _joints(old, "old")
    m = pattern_mode(fitted, mode)
    xs, ys, mask = servo_region(fitted, m, pitch_mm)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack((gx[mask], gy[mask]), axis=1)
    drawn = np.stack([drawn_by(fitted, old, pts, s, m) for s in APPROACHES])  # (4, N, 2)
    ok = np.isfinite(drawn).all(axis=(0, 2))
    if ok.sum() < 3:
        raise CalibrationError(f"{old.source} cannot draw the region of {fitted.source} in "
                               f"working mode {m} (its pulses leave the curves)")
    d = drawn[:, ok].reshape(-1, 2)
    want = np.tile(pts[ok], (len(APPROACHES), 1))
    phi, t = rigid_fit(d, want)
    e = np.linalg.norm(d @ rotation(phi).T + t - want, axis=1).reshape(len(APPROACHES), -1)
    err = np.full(mask.shape, np.nan)
    where = np.flatnonzero(mask.ravel())[ok]
    err.ravel()[where] = e.max(axis=0)
    return ErrorMap(xs, ys, err, m)
