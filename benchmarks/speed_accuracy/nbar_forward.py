"""Section 1, the n-bar solver used as forward kinematics: time per pose along a raster over
the page, and the error of single continuation steps on every point set.

`nbar_step_check` is the step validation takes, and the stability map reuses it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from benchmarks.speed_accuracy.config import Config
from benchmarks.speed_accuracy.methods import SetError, set_error
from benchmarks.speed_accuracy.scene import PointSet, Scene, dist, ref_forward
from benchmarks.speed_accuracy.timing import interleaved_medians
from fivebar_host.compile import MAX_STEP_RAD
from kinematics.arrays import FloatArray
from kinematics.nbar import MechanismError, Status, fivebar_mechanism, simulate


def raster_angles(sc: Scene, lines: int) -> FloatArray:
    """Motor angles of a boustrophedon raster over the page (the n-bar timing path): `lines`
    rows, points spaced like the rows."""
    r = sc.page.rect
    ys = np.linspace(r.y0, r.y1, lines)
    pitch = r.height / max(lines - 1, 1)
    xs = np.linspace(r.x0, r.x1, max(2, round(r.width / pitch) + 1))
    pts = [np.stack((xs if k % 2 == 0 else xs[::-1], np.full(xs.size, y)), axis=1)
           for k, y in enumerate(ys)]
    p = np.concatenate(pts)
    return np.asarray(sc.fb.inverse_batch(p, sc.mode).require(p))


def nbar_step_check(sc: Scene, th: FloatArray, sign: float, tol: float,
                    step_rad: float = MAX_STEP_RAD) -> tuple[str, FloatArray]:
    """The n-bar solver as forward kinematics at one pose, the way validation uses it: a
    continuation step of `step_rad` (joint space, towards th from the homed angles' side)
    from an assembled pose. Returns (outcome, P): "ok", "limit", "start" (the start pose does
    not assemble in this assembly) with P NaN unless "ok"."""
    home = np.asarray(sc.profile.motors.home_rad)
    d = home - th
    nd = float(np.hypot(*d))
    start = th + (d / nd * step_rad if nd > 0 else np.array([step_rad, 0.0]))
    nan = np.full(2, np.nan)
    fw = sc.fb.forward_batch(start[None], "+" if sign > 0 else "-")
    if not fw.valid[0]:
        return "start", nan
    try:
        mech = fivebar_mechanism(sc.fb, start, "+" if sign > 0 else "-")
    except MechanismError:
        return "start", nan
    sim = simulate(mech, np.stack((start, th)), tolerance=tol)
    if sim.status[-1] not in (Status.OK, Status.SUBDIVIDED):
        return "limit", nan
    return "ok", np.asarray(sim.path("P")[-1])


@dataclass(frozen=True)
class NbarKinRow:
    """n-bar as forward kinematics at one tolerance: time per pose on the raster path, and per
    set the error of single continuation steps (and how many ended at a limit)."""

    tol: float
    us_per_pose: float
    iterations: float
    raster_max_mm: float
    errors: dict[str, SetError]
    limits: dict[str, int]
    flips: dict[str, int]


def nbar_kinematics_rows(sc: Scene, cfg: Config, sets: dict[str, PointSet]) -> list[NbarKinRow]:
    """Item 1 for the n-bar solver (kinematics.nbar) used as forward kinematics."""
    th = raster_angles(sc, cfg.raster_lines)
    mech = fivebar_mechanism(sc.fb, th[0], sc.assembly)
    ref = ref_forward(sc, th, sc.sign)
    rng = np.random.default_rng(7)
    picks = {k: rng.choice(s.points.shape[0], min(cfg.nbar_points, s.points.shape[0]),
                           replace=False) for k, s in sets.items()}
    rows = []
    medians = interleaved_medians([partial(simulate, mech, th, tolerance=tol)
                                   for tol in cfg.nbar_tols], cfg.repeats)
    for tol, t in zip(cfg.nbar_tols, medians, strict=True):
        assert isinstance(t, float), t
        sim = simulate(mech, th, tolerance=tol)
        raster = dist(sim.path("P"), ref)
        errs: dict[str, SetError] = {}
        lims: dict[str, int] = {}
        flips: dict[str, int] = {}
        for name, s in sets.items():
            vals = np.zeros((picks[name].size, 2))
            ok = np.zeros(picks[name].size, dtype=bool)
            lim = flip = 0
            for k, i in enumerate(picks[name]):
                outcome, p = nbar_step_check(sc, s.angles[i], s.sign[i], tol)
                if outcome == "ok":
                    other = ref_forward(sc, s.angles[i:i + 1], -s.sign[i])
                    if (dist(p[None], other)[0] < dist(p[None], s.ref_points[i:i + 1])[0]):
                        flip += 1
                    vals[k], ok[k] = p, True
                elif outcome == "limit":
                    lim += 1
            sub = PointSet(name, s.points[picks[name]], s.angles[picks[name]],
                           s.sign[picks[name]], s.ref_angles[picks[name]],
                           s.ref_points[picks[name]])
            errs[name] = set_error(sc, "forward", sub, vals, ok)
            lims[name], flips[name] = lim, flip
        rows.append(NbarKinRow(tol, 1e6 * t / th.shape[0],
                               float(np.mean(sim.iterations[1:])), float(raster.max()),
                               errs, lims, flips))
    return rows
