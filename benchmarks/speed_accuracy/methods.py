"""Section 1, five-bar kinematics: the closed form, the bare formulas and every
approximation of `benchmarks.approx`, timed on the interior set and scored on every set.

Each method becomes a `Method` (a map inputs → values, valid mask); `kinematics_rows` turns
them into `MethodRow`s of time per point and pen error per set.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from benchmarks import approx
from benchmarks.kinematics import bare_forward, bare_inverse
from benchmarks.speed_accuracy.config import Config
from benchmarks.speed_accuracy.scene import (
    PointSet,
    Scene,
    closed_form,
    dist,
    ref_forward,
    signs,
    wrapped,
)
from benchmarks.speed_accuracy.timing import interleaved_medians, timed_build
from kinematics.arrays import BoolArray, FloatArray


@dataclass(frozen=True, eq=False)
class Method:
    """One way to compute the kinematics: fn(inputs (N, 2)) → (values (N, 2), valid (N,))."""

    name: str
    family: str
    direction: str  # "inverse" (points → angles) or "forward" (angles → points)
    size: str
    build_s: float
    nbytes: int
    fn: Callable[[FloatArray], tuple[FloatArray, BoolArray]]


@dataclass(frozen=True)
class SetError:
    """Pen error (mm) over the answered points of a set; angle error (rad) for inverse maps."""

    max_mm: float
    median_mm: float
    max_rad: float
    answered: float  # fraction of the set answered


@dataclass(frozen=True)
class MethodRow:
    name: str
    family: str
    direction: str
    size: str
    build_s: float
    nbytes: int
    ns_per_point: float
    errors: dict[str, SetError]



def build_methods(sc: Scene, cfg: Config) -> list[Method]:
    """The closed form, bare formulas and every approximation of benchmarks.approx."""
    fb, mode, asm = sc.fb, sc.mode, sc.assembly
    s1, s2 = signs(mode)
    sign = sc.sign

    closed_inv, closed_fwd = closed_form(sc)

    def bare_inv(p: FloatArray) -> tuple[FloatArray, BoolArray]:
        return bare_inverse(fb, p, s1, s2), np.ones(p.shape[0], dtype=bool)

    def bare_fwd(t: FloatArray) -> tuple[FloatArray, BoolArray]:
        return (bare_forward(fb, t, np.full(t.shape[0], sign)),
                np.ones(t.shape[0], dtype=bool))

    out = [
        Method("closed form", "closed form", "inverse", "—", 0.0, 0, closed_inv),
        Method("bare formulas", "bare formulas", "inverse", "—", 0.0, 0, bare_inv),
        Method("closed form", "closed form", "forward", "—", 0.0, 0, closed_fwd),
        Method("bare formulas", "bare formulas", "forward", "—", 0.0, 0, bare_fwd),
    ]
    linear_forms: tuple[tuple[approx.Form, str], ...] = (("similarity", "Eq. 25"),
                                                         ("affine", "affine"))
    for form, label in linear_forms:
        lin, t_b = timed_build(partial(approx.fit_linear, fb, mode, sc.region_pts, form))
        fam = f"linear {label}" if form == "affine" else "linear Eq. 25/26"
        out.append(Method(f"{fam}, page fit", fam, "inverse", "1", t_b, 48,
                          wrap(lin.inverse)))
        out.append(Method(f"{fam}, page fit", fam, "forward", "1", t_b, 48,
                          wrap(lin.forward)))
    for n in cfg.tile_counts:
        for form, _ in linear_forms:
            fam = "tiles Eq. 25" if form == "similarity" else "tiles affine"
            ti, t_b = timed_build(partial(approx.inverse_tiles, fb, mode, sc.ws_box, n, form))
            out.append(Method(f"{fam} {n}×{n}", fam, "inverse", f"{n}×{n}", t_b,
                              ti.matrix.nbytes + ti.offset.nbytes, wrap(ti)))
            tf, t_b = timed_build(partial(approx.forward_tiles, fb, asm, sc.joint_box, n, form))
            out.append(Method(f"{fam} {n}×{n}", fam, "forward", f"{n}×{n}", t_b,
                              tf.matrix.nbytes + tf.offset.nbytes, wrap(tf)))
    centre = sc.page.rect.center
    free = (math.inf, (0.0, 0.0))
    tables: tuple[tuple[approx.Order, tuple[int, ...], str,
                        tuple[float, tuple[float, float]]], ...] = (
        ("linear", cfg.lut_sizes, "LUT bilinear", free),
        ("cubic", cfg.cubic_sizes, "LUT bicubic", free),
        ("linear", cfg.guarded_sizes, GUARDED, guard_of(sc)))
    for order, sizes, fam, (cap, margins) in tables:
        for n in sizes:
            name = f"{fam} {n}²"
            li, t_b = timed_build(partial(approx.inverse_table, fb, mode, sc.ws_box, n, order,
                                           max_error=cap, centre=centre, min_margins=margins))
            out.append(Method(name, fam, "inverse", f"{n}²", t_b, li.nbytes, wrap(li)))
            lf, t_b = timed_build(partial(approx.forward_table, fb, asm, sc.joint_box, n,
                                           order, max_error=cap, min_margins=margins))
            out.append(Method(name, fam, "forward", f"{n}²", t_b, lf.nbytes, wrap(lf)))
    return out


#: Family name of the guarded tables (max_error = the tolerance, the profile's margins).
GUARDED = "LUT bilinear guarded"


def guard_of(sc: Scene) -> tuple[float, tuple[float, float]]:
    """(max_error, min_margins) of a guarded table: the job tolerance and the profile's
    minimum singularity margins, so it refuses where the job's pose checks would."""
    k = sc.profile.kinematics
    return sc.tol_mm, (k.min_type1_margin_rad, k.min_type2_margin_rad)


def wrap(f: Callable[[FloatArray], approx.Approximation]
          ) -> Callable[[FloatArray], tuple[FloatArray, BoolArray]]:
    """An approximation's map as a (values, valid mask) map, like the closed form's."""
    def call(q: FloatArray) -> tuple[FloatArray, BoolArray]:
        r = f(q)
        return r.values, r.valid
    return call


def set_error(sc: Scene, direction: str, s: PointSet, values: FloatArray,
              valid: BoolArray) -> SetError:
    """Errors of a method's answers on a set (pen error in mm for both directions: inverse
    answers are pushed through the long-double forward kinematics in the point's assembly)."""
    if direction == "inverse":
        pen = dist(ref_forward(sc, values[valid], s.sign[valid]), s.points[valid])
        ang = np.abs(wrapped(values[valid] - s.ref_angles[valid].astype(np.float64)))
        max_rad = float(ang.max()) if ang.size else math.nan
    else:
        pen = dist(values[valid], s.ref_points[valid])
        max_rad = math.nan
    return SetError(float(pen.max()) if pen.size else math.nan,
                    float(np.median(pen)) if pen.size else math.nan, max_rad,
                    float(valid.mean()))


def _timing_input(s: PointSet, direction: str, n: int) -> FloatArray:
    src = s.points if direction == "inverse" else s.angles
    reps = -(-n // src.shape[0])
    return np.ascontiguousarray(np.tile(src, (reps, 1))[:n])


def kinematics_rows(sc: Scene, cfg: Config, sets: dict[str, PointSet],
                    methods: Sequence[Method]) -> list[MethodRow]:
    """Item 1 for the closed form and the approximations: time per point on the interior
    set (median of cfg.repeats) and the errors on every set."""
    rows = []
    inputs = {d: _timing_input(sets["interior"], d, cfg.n_time) for d in ("inverse", "forward")}
    medians = interleaved_medians([partial(m.fn, inputs[m.direction]) for m in methods],
                                  cfg.repeats)
    for m, t in zip(methods, medians, strict=True):
        assert isinstance(t, float), t
        q = inputs[m.direction]
        errs = {}
        for name, s in sets.items():
            v, ok = m.fn(s.points if m.direction == "inverse" else s.angles)
            errs[name] = set_error(sc, m.direction, s, v, ok)
        rows.append(MethodRow(m.name, m.family, m.direction, m.size, m.build_s, m.nbytes,
                              1e9 * t / q.shape[0], errs))
    return rows
