"""The machine under test and the point sets every method is scored on.

`Scene` is the profile's machine with its working mode, page region and the domains of the
approximations; `ref_inverse` / `ref_forward` are the closed-form formulas in long double,
the reference of every error in the report; `sample_sets` draws the interior and the two
near-singularity sets.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from benchmarks.kinematics import bare_forward, bare_inverse
from benchmarks.speed_accuracy.config import (
    LD,
    NEAR_DEG,
    NEAR_TYPE1_MM,
    NEAR_TYPE2_MM,
    WELL_DEG,
    Box,
)
from fivebar_host.config import Profile, load_profile
from kinematics.arrays import BoolArray, FloatArray
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.workspace import (
    PageFit,
    find_page_rectangle,
    point_safety,
    type1_circles,
    type2_traces,
    workspace_bounds,
)


@dataclass(frozen=True, eq=False)
class Scene:
    """The machine of the profile, its working mode, page region and domains."""

    profile: Profile
    fb: FiveBar
    mode: str
    assembly: str
    sign: float
    page: PageFit
    region_pts: FloatArray  # grid nodes of the connected safe region holding the page
    ws_box: Box  # workspace bounding box (inverse tables and tiles)
    joint_box: Box  # joint-limit box (forward tables and tiles)
    tol_mm: float

    @property
    def region_box(self) -> Box:
        p = self.region_pts
        return (float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()),
                float(p[:, 1].max()))


def make_scene(profile: Profile | None = None) -> Scene:
    """The bundled profile (configs/default.toml) unless another is given."""
    prof = profile or load_profile()
    fb = prof.geometry
    kin = prof.kinematics
    mode = kin.working_mode if kin.working_mode in WORKING_MODES else WORKING_MODES[1]
    page = find_page_rectangle(fb, mode, kin.min_type1_margin_rad, kin.min_type2_margin_rad,
                               prof.motors.limits_rad)
    xx, yy = np.meshgrid(page.xs, page.ys)
    region = np.stack((xx[page.region], yy[page.region]), axis=1)
    lim = prof.motors.limits_rad
    return Scene(prof, fb, mode, page.assembly, 1.0 if page.assembly == "+" else -1.0, page,
                 region, workspace_bounds(fb), (lim[0][0], lim[0][1], lim[1][0], lim[1][1]),
                 prof.motion.tolerance_mm)


def signs(mode: str) -> tuple[float, float]:
    """The elbow signs (±1, ±1) of a working mode such as "+-"."""
    return (1.0 if mode[0] == "+" else -1.0, 1.0 if mode[1] == "+" else -1.0)


def ref_inverse(sc: Scene, pts: FloatArray) -> NDArray[Any]:
    """The closed-form inverse (benchmarks/kinematics.py's bare formulas) in long double."""
    s1, s2 = signs(sc.mode)
    with np.errstate(invalid="ignore"):
        return bare_inverse(sc.fb, pts.astype(LD), s1, s2)


def ref_forward(sc: Scene, th: FloatArray, sign: FloatArray | float) -> NDArray[Any]:
    """The closed-form forward kinematics (bare formulas) in long double; NaN where the
    floating links cannot meet."""
    sg = np.broadcast_to(np.asarray(sign, dtype=LD), (th.shape[0],))
    with np.errstate(invalid="ignore", divide="ignore"):
        return bare_forward(sc.fb, th.astype(LD), sg)


def dist(a: NDArray[Any], b: NDArray[Any]) -> FloatArray:
    """Row-wise distance in long double, returned as float64; inf where it is NaN."""
    d = np.asarray(a, dtype=LD) - np.asarray(b, dtype=LD)
    out = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]).astype(np.float64)
    return np.asarray(np.where(np.isnan(out), np.inf, out), dtype=np.float64)


def wrapped(d: FloatArray) -> FloatArray:
    """Angle differences wrapped into [−π, π)."""
    return np.asarray(np.mod(d + math.pi, 2.0 * math.pi) - math.pi, dtype=np.float64)


# ============================================================================ point sets
@dataclass(frozen=True, eq=False)
class PointSet:
    """Points of one region with their closed-form angles, assembly signs and references."""

    name: str
    points: FloatArray
    angles: FloatArray
    sign: FloatArray
    ref_angles: NDArray[Any]  # long double inverse of the points
    ref_points: NDArray[Any]  # long double forward of the (float64) angles


def _draw(rng: np.random.Generator, box: Box, n: int) -> FloatArray:
    return np.stack((rng.uniform(box[0], box[1], n), rng.uniform(box[2], box[3], n)), axis=1)


def _near_curves(sc: Scene, rng: np.random.Generator, n: int) -> tuple[FloatArray, FloatArray]:
    """Candidates around the singular curves: within NEAR_TYPE1_MM of a reach circle (type
    1) and within NEAR_TYPE2_MM of a type-2 curve of the working mode (type 2)."""
    circles = type1_circles(sc.fb)
    k = rng.integers(0, len(circles), n)
    centre = np.array([c[2] for c in circles])[k]
    radius = np.array([c[3] for c in circles])[k] + rng.uniform(-NEAR_TYPE1_MM, NEAR_TYPE1_MM,
                                                                  n)
    ang = rng.uniform(0.0, 2.0 * math.pi, n)
    c1 = centre + radius[:, None] * np.stack((np.cos(ang), np.sin(ang)), axis=1)
    curves = [pl for tr in type2_traces(sc.fb) for pl in tr.polylines(sc.mode)]
    if not curves:
        return c1, np.zeros((0, 2))
    pts = np.concatenate(curves)
    r = NEAR_TYPE2_MM * np.sqrt(rng.uniform(0.0, 1.0, n))
    ang = rng.uniform(0.0, 2.0 * math.pi, n)
    c2 = pts[rng.integers(0, pts.shape[0], n)] + r[:, None] * np.stack((np.cos(ang),
                                                                         np.sin(ang)), axis=1)
    return c1, c2


def sample_sets(sc: Scene, n: int, rng: np.random.Generator) -> dict[str, PointSet]:
    """Three sets of `n` points of the page's working mode and assembly:

    - interior: uniform in the page region's box, kept where every margin is ≥ WELL_DEG and
      the joint limits hold;
    - near type 1: around the reach circles, kept where an arm is within NEAR_DEG of
      stretched/folded and the type-2 margin is ≥ NEAR_DEG;
    - near type 2: around the type-2 curves, kept where the floating links are within
      NEAR_DEG of collinear and both type-1 margins are ≥ NEAR_DEG.
    """
    fb, mode = sc.fb, sc.mode
    well = math.radians(WELL_DEG)
    near = math.radians(NEAR_DEG)
    lim = sc.profile.motors.limits_rad
    got: dict[str, list[FloatArray]] = {"interior": [], "near type 1": [], "near type 2": []}
    for _ in range(200):
        if all(sum(len(a) for a in v) >= n for v in got.values()):
            break
        p = _draw(rng, sc.region_box, 4 * n)
        ok = point_safety(fb, mode, p, well, well, lim, assembly=sc.assembly)
        got["interior"].append(p[ok])
        c1, c2 = _near_curves(sc, rng, 4 * n)
        for name, q in (("near type 1", c1), ("near type 2", c2)):
            inv = fb.inverse_batch(q, mode)
            q, th = q[inv.valid], inv.angles[inv.valid]
            m = np.abs(fb.singularity_margins(th, q))
            same = fb.assembly_of(th, q) == int(sc.sign)
            t1 = np.minimum(m[:, 0], m[:, 1])
            keep = (same & (t1 < near) & (m[:, 2] >= near) if name == "near type 1"
                    else same & (m[:, 2] < near) & (t1 >= near))
            got[name].append(q[keep])
    out: dict[str, PointSet] = {}
    for name, parts in got.items():
        p = np.concatenate(parts)[:n]
        if p.shape[0] == 0:
            raise RuntimeError(f"no points found for the set {name!r}")
        th = np.asarray(fb.inverse_batch(p, mode).require(p))
        sign = fb.assembly_of(th, p).astype(np.float64)
        out[name] = PointSet(name, p, th, sign, ref_inverse(sc, p), ref_forward(sc, th, sign))
    return out



def closed_form(sc: Scene) -> tuple[Callable[[FloatArray], tuple[FloatArray, BoolArray]],
                                      Callable[[FloatArray], tuple[FloatArray, BoolArray]]]:
    """The scene's closed-form inverse and forward kinematics as (values, valid mask) maps."""
    fb, mode, asm = sc.fb, sc.mode, sc.assembly

    def closed_inv(p: FloatArray) -> tuple[FloatArray, BoolArray]:
        r = fb.inverse_batch(p, mode)
        return r.angles, r.valid

    def closed_fwd(t: FloatArray) -> tuple[FloatArray, BoolArray]:
        r = fb.forward_batch(t, asm)
        return r.points, r.valid

    return closed_inv, closed_fwd
