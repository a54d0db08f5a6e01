"""Speed against accuracy, charted; stability where methods fail (issue 7).

One run regenerates every chart in docs/img/ and docs/performance.md, all figures from that run:

1. Five-bar kinematics — time per point against the largest pen error, for the closed form
   (kinematics.fivebar), the n-bar solver as forward kinematics (kinematics.nbar), the thesis'
   linear approximation (Sec. 5.2, Eqs. 25–26, fitted by least squares; whole page region and
   per tile) and lookup tables (bilinear, bicubic) from kinematics.approx. Errors are measured
   in the well-conditioned interior and near each singularity type separately, against the
   same closed-form formulas evaluated in extended precision (np.longdouble, 64-bit mantissa).
2. n-bar solver — convergence tolerance and input step against run time and constraint
   residual (drift) per paper example, beside the scipy baseline of benchmarks/nbar.py.
3. Job compilation — tolerance against segment count, compile time, plot time and the
   deviation measured from the quantised steps; adaptive segmentation against a fixed spacing.
4. The physical limit — microstepping and gear ratio against the step quantum on the page.
5. Stability — a map over the workspace of where each method fails, and approaches towards
   each singularity type.

Run from the repository root: python -m benchmarks.speed_accuracy [--out-dir docs] [--quick]
(--quick: tiny sizes, seconds, for a smoke test; it still writes its report into --out-dir).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import math
import os
import platform
import re
import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # run as a file, or imported from elsewhere
    sys.path.insert(0, str(ROOT))

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import BoundaryNorm, ListedColormap  # noqa: E402
from matplotlib.patches import Patch, Rectangle  # noqa: E402
from matplotlib.ticker import NullFormatter  # noqa: E402

from benchmarks.kinematics import bare_forward, bare_inverse, median_time  # noqa: E402
from benchmarks.pipeline import make_svg  # noqa: E402
from fivebar_host.compile import (  # noqa: E402
    MAX_STEP_RAD,
    CompileOptions,
    Job,
    compile_job,
    deviations,
    nbar_opinion,
    validate,
)
from fivebar_host.config import Profile, load_profile  # noqa: E402
from fivebar_host.linkage import load_mechanism  # noqa: E402
from fivebar_host.toolpath.geometry import evaluate, nearest_distance  # noqa: E402
from kinematics import approx  # noqa: E402
from kinematics.analysis import (  # noqa: E402
    PageFit,
    find_page_rectangle,
    point_safety,
    step_quantum,
    type1_circles,
    type2_traces,
    workspace_bounds,
)
from kinematics.fivebar import WORKING_MODES, FiveBar  # noqa: E402
from kinematics.nbar import (  # noqa: E402
    MechanismError,
    Settings,
    Status,
    fivebar_mechanism,
    simulate,
    sweep,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Box = tuple[float, float, float, float]

#: "Well-conditioned interior": every singularity margin (kinematics.fivebar) at least this.
WELL_DEG = 15.0
#: "Near a singularity": the margin to that singularity type below this (the others ≥ it).
NEAR_DEG = 2.0
#: Candidates for the near sets are drawn this close to the singular curves (mm).
NEAR_TYPE1_MM = 0.5
NEAR_TYPE2_MM = 10.0
#: An exact method's error must stay at or below this (mm); above it counts as error growth.
EXACT_MM = 1e-6
#: The drawings of item 3 (name → what it is).
SCENE_NOTES = {
    "text": "examples/fivebar_text.svg, the word in single-stroke curves",
    "shapes": "examples/simple.svg: frame with rounded corners, circle, triangle, zigzag",
    "random strokes": "benchmarks/pipeline.py `make_svg`: short random lines and quadratic "
                      "curves, as in the pipeline benchmark",
}
#: Extended precision for the reference evaluation.
LD = np.longdouble
FIRMWARE_CONFIG = ROOT / "firmware" / "fivebar" / "config.h"


# ============================================================================ configuration
@dataclass(frozen=True)
class Config:
    """Sizes of one run. `full()` is the documented run (< 3 min on 2 cores); `quick()` is a
    smoke test of the same code paths in seconds."""

    n_time: int = 100_000  # points per timed call (item 1)
    repeats: int = 5  # timed repeats; the median is reported
    n_near: int = 20_000  # points per error set
    lut_sizes: tuple[int, ...] = (64, 128, 256, 512)
    cubic_sizes: tuple[int, ...] = (64, 128, 256, 512)
    guarded_sizes: tuple[int, ...] = (128, 256, 512)  # bilinear with max_error = tolerance
    tile_counts: tuple[int, ...] = (8, 16, 32, 64)
    nbar_tols: tuple[float, ...] = (1e-6, 1e-8, 1e-10, 1e-12)
    nbar_points: int = 150  # continuation checks per error set (n-bar)
    raster_lines: int = 30  # raster path over the page for the n-bar timing
    ex_tols: tuple[float, ...] = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
    ex_factors: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0)
    ex_runs: int = 5
    ex_base_runs: int = 3
    job_tols: tuple[float, ...] = (0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002)
    job_repeats: int = 3
    random_paths: int = 50
    microsteps: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
    gears: tuple[float, ...] = (1.0, 2.0, 4.0)
    map_pitch_mm: float = 2.0
    nbar_map_stride: int = 2
    map_lut: int = 256
    map_tiles: int = 32
    approach_exponents: tuple[float, ...] = tuple(-0.5 * k for k in range(-2, 25))
    job_scenes: tuple[str, ...] = ("text", "shapes", "random strokes")
    max_examples: int = 0  # n-bar example files to run (0: all)
    quick_run: bool = False

    @staticmethod
    def full() -> Config:
        return Config()

    @staticmethod
    def quick() -> Config:
        return Config(n_time=2_000, repeats=2, n_near=400, lut_sizes=(32, 64),
                      cubic_sizes=(32,), guarded_sizes=(32,), tile_counts=(8,),
                      nbar_tols=(1e-8, 1e-12),
                      nbar_points=6, raster_lines=4, ex_tols=(1e-6, 1e-12),
                      ex_factors=(1.0, 2.0), ex_runs=1, ex_base_runs=1, job_tols=(0.2, 0.05),
                      job_repeats=1, random_paths=10, microsteps=(1, 16), gears=(1.0,),
                      map_pitch_mm=12.0, nbar_map_stride=2, map_lut=64, map_tiles=8,
                      approach_exponents=(0.0, -3.0, -6.0, -9.0, -12.0),
                      job_scenes=("shapes",), max_examples=1, quick_run=True)


# ============================================================================ machine
def machine_info() -> dict[str, str]:
    """Date, CPU model (from /proc/cpuinfo), cores and library versions of this run."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import scipy

    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        usable = os.cpu_count() or 1
    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    return {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": cpu,
        "cores": f"{os.cpu_count()} logical, {usable} usable by this process",
        "os": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "matplotlib": matplotlib.__version__,
        "load": f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}",
    }


# ============================================================================ the machine scene
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


def _signs(mode: str) -> tuple[float, float]:
    return (1.0 if mode[0] == "+" else -1.0, 1.0 if mode[1] == "+" else -1.0)


def ref_inverse(sc: Scene, pts: FloatArray) -> NDArray[Any]:
    """The closed-form inverse (benchmarks/kinematics.py's bare formulas) in long double."""
    s1, s2 = _signs(sc.mode)
    with np.errstate(invalid="ignore"):
        return bare_inverse(sc.fb, pts.astype(LD), s1, s2)


def ref_forward(sc: Scene, th: FloatArray, sign: FloatArray | float) -> NDArray[Any]:
    """The closed-form forward kinematics (bare formulas) in long double; NaN where the
    floating links cannot meet."""
    sg = np.broadcast_to(np.asarray(sign, dtype=LD), (th.shape[0],))
    with np.errstate(invalid="ignore", divide="ignore"):
        return bare_forward(sc.fb, th.astype(LD), sg)


def _dist(a: NDArray[Any], b: NDArray[Any]) -> FloatArray:
    d = np.asarray(a, dtype=LD) - np.asarray(b, dtype=LD)
    out = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]).astype(np.float64)
    return np.asarray(np.where(np.isnan(out), np.inf, out), dtype=np.float64)


def _wrapped(d: FloatArray) -> FloatArray:
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


# ============================================================================ 1. methods
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


def interleaved_medians(fns: Sequence[Callable[[], object]], repeats: int
                        ) -> list[float | str]:
    """Median wall time of each call over `repeats` rounds, after one warm-up call each.
    The calls are interleaved — every round times each of them once — so a change of load
    on a shared machine falls on all of them alike, and they are compared side by side.
    A call that raises gets its exception text instead of a time."""
    out: list[float | str] = []
    live: list[int] = []
    for i, fn in enumerate(fns):
        try:
            fn()
        except Exception as e:  # reported, not hidden
            out.append(f"{type(e).__name__}: {e}")
            continue
        out.append(math.nan)
        live.append(i)
    times: dict[int, list[float]] = {i: [] for i in live}
    for _ in range(repeats):
        for i in live:
            t0 = time.perf_counter()
            fns[i]()
            times[i].append(time.perf_counter() - t0)
    for i in live:
        out[i] = statistics.median(times[i])
    return out


def _timed_build(fn: Callable[[], Any]) -> tuple[Any, float]:
    t0 = time.perf_counter()
    obj = fn()
    return obj, time.perf_counter() - t0


def _closed_form(sc: Scene) -> tuple[Callable[[FloatArray], tuple[FloatArray, BoolArray]],
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


def build_methods(sc: Scene, cfg: Config) -> list[Method]:
    """The closed form, bare formulas and every approximation of kinematics.approx."""
    fb, mode, asm = sc.fb, sc.mode, sc.assembly
    s1, s2 = _signs(mode)
    sign = sc.sign

    closed_inv, closed_fwd = _closed_form(sc)

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
        lin, t_b = _timed_build(partial(approx.fit_linear, fb, mode, sc.region_pts, form))
        fam = f"linear {label}" if form == "affine" else "linear Eq. 25/26"
        out.append(Method(f"{fam}, page fit", fam, "inverse", "1", t_b, 48,
                          _wrap(lin.inverse)))
        out.append(Method(f"{fam}, page fit", fam, "forward", "1", t_b, 48,
                          _wrap(lin.forward)))
    for n in cfg.tile_counts:
        for form, _ in linear_forms:
            fam = "tiles Eq. 25" if form == "similarity" else "tiles affine"
            ti, t_b = _timed_build(partial(approx.inverse_tiles, fb, mode, sc.ws_box, n, form))
            out.append(Method(f"{fam} {n}×{n}", fam, "inverse", f"{n}×{n}", t_b,
                              ti.matrix.nbytes + ti.offset.nbytes, _wrap(ti)))
            tf, t_b = _timed_build(partial(approx.forward_tiles, fb, asm, sc.joint_box, n, form))
            out.append(Method(f"{fam} {n}×{n}", fam, "forward", f"{n}×{n}", t_b,
                              tf.matrix.nbytes + tf.offset.nbytes, _wrap(tf)))
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
            li, t_b = _timed_build(partial(approx.inverse_table, fb, mode, sc.ws_box, n, order,
                                           max_error=cap, centre=centre, min_margins=margins))
            out.append(Method(name, fam, "inverse", f"{n}²", t_b, li.nbytes, _wrap(li)))
            lf, t_b = _timed_build(partial(approx.forward_table, fb, asm, sc.joint_box, n,
                                           order, max_error=cap, min_margins=margins))
            out.append(Method(name, fam, "forward", f"{n}²", t_b, lf.nbytes, _wrap(lf)))
    return out


#: Family name of the guarded tables (max_error = the tolerance, the profile's margins).
GUARDED = "LUT bilinear guarded"


def guard_of(sc: Scene) -> tuple[float, tuple[float, float]]:
    """(max_error, min_margins) of a guarded table: the job tolerance and the profile's
    minimum singularity margins, so it refuses where the job's pose checks would."""
    k = sc.profile.kinematics
    return sc.tol_mm, (k.min_type1_margin_rad, k.min_type2_margin_rad)


def _wrap(f: Callable[[FloatArray], approx.Approximation]
          ) -> Callable[[FloatArray], tuple[FloatArray, BoolArray]]:
    def call(q: FloatArray) -> tuple[FloatArray, BoolArray]:
        r = f(q)
        return r.values, r.valid
    return call


def set_error(sc: Scene, direction: str, s: PointSet, values: FloatArray,
              valid: BoolArray) -> SetError:
    """Errors of a method's answers on a set (pen error in mm for both directions: inverse
    answers are pushed through the long-double forward kinematics in the point's assembly)."""
    if direction == "inverse":
        pen = _dist(ref_forward(sc, values[valid], s.sign[valid]), s.points[valid])
        ang = np.abs(_wrapped(values[valid] - s.ref_angles[valid].astype(np.float64)))
        max_rad = float(ang.max()) if ang.size else math.nan
    else:
        pen = _dist(values[valid], s.ref_points[valid])
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
        raster = _dist(sim.path("P"), ref)
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
                    if (_dist(p[None], other)[0] < _dist(p[None], s.ref_points[i:i + 1])[0]):
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


# ============================================================================ 2. n-bar examples
@dataclass(frozen=True)
class ExampleRow:
    """One (example, step factor, tolerance) run of `sweep`, or the scipy baseline (tol NaN)."""

    example: str
    factor: float
    steps: int
    tol: float
    ms: float
    iterations: float
    residual: float
    tracer_dev: float
    limits: int
    solver: str  # "n-bar" or "scipy"
    error: str = ""  # the exception, if the run raised one


def example_rows(cfg: Config) -> tuple[list[ExampleRow], str]:
    """Item 2: every mechanism file, input step × factor (steps adjusted to cover the same
    input range) × tolerance: median time of `sweep`, Newton iterations per step, the largest
    exact-equation residual (the constraint drift) and the tracer's deviation from the run at
    the tightest tolerance that completed; beside scipy (benchmarks/nbar.py's baseline) on the
    same inputs. A run that raises is recorded with its exception, not hidden."""
    baseline: Callable[[Any, FloatArray, bool], tuple[FloatArray, int, int]] | None
    try:
        from benchmarks.nbar import baseline
    except ImportError as e:  # pragma: no cover - benchmarks/nbar.py missing
        baseline = None
        note = f"scipy baseline unavailable ({e})"
    else:
        note = "scipy baseline: benchmarks/nbar.py `baseline` (fsolve / least_squares)"
    rows: list[ExampleRow] = []
    files = sorted((ROOT / "configs" / "mechanisms").glob("*.toml"))
    if cfg.max_examples:
        files = files[:cfg.max_examples]
    for path in files:
        mech = load_mechanism(path)
        tracer = mech.tracers[0] if mech.tracers else mech.joints[-1].name
        for f in cfg.ex_factors:
            steps = max(2, round(mech.settings.steps / f))
            step = mech.step * f
            runs: list[tuple[float, float, Any]] = []  # (tol, median s, Simulation | error)
            tols = sorted(cfg.ex_tols, reverse=True)
            meds = interleaved_medians([partial(sweep, mech, steps, step, tolerance=tol)
                                        for tol in tols], cfg.ex_runs)
            for tol, t in zip(tols, meds, strict=True):
                if isinstance(t, str):  # an undocumented failure is a finding: report it
                    runs.append((tol, math.nan, t))
                else:
                    runs.append((tol, t, sweep(mech, steps, step, tolerance=tol)))
            done = [r for r in runs if not isinstance(r[2], str)]
            ref = done[-1][2] if done else None
            for tol, t, sim in runs:
                if isinstance(sim, str):
                    rows.append(ExampleRow(path.stem, f, steps, tol, math.nan, math.nan,
                                           math.nan, math.nan, 0, "n-bar", sim))
                    continue
                dev = math.nan
                if (ref is not None and sim.inputs.shape == ref.inputs.shape
                        and np.allclose(sim.inputs, ref.inputs)):
                    dev = float(np.nanmax(np.abs(sim.path(tracer) - ref.path(tracer))))
                rows.append(ExampleRow(path.stem, f, len(sim.status) - 1, tol, 1e3 * t,
                                       float(np.mean(sim.iterations[1:])),
                                       float(np.nanmax(sim.residual)), dev, len(sim.limits),
                                       "n-bar"))
            if baseline is not None and ref is not None:
                inputs = ref.inputs
                t = median_time(partial(baseline, mech, inputs, False), cfg.ex_base_runs)
                qb, nfev, fails = baseline(mech, inputs, False)
                cb = mech.coords_batch(qb, inputs)
                res = float(np.max(np.abs(mech.residuals(cb, inputs))))
                dev = float(np.nanmax(np.abs(mech.positions(cb, tracer) - ref.path(tracer))))
                rows.append(ExampleRow(path.stem, f, inputs.shape[0] - 1, math.nan, 1e3 * t,
                                       nfev / max(inputs.shape[0] - 1, 1), res, dev, fails,
                                       "scipy"))
    return rows, note


# ============================================================================ 3. jobs
@dataclass(frozen=True)
class JobRow:
    """One compile of a scene at one tolerance, and the fixed-spacing segmentation that
    meets the same tolerance (`fixed_spacing`)."""

    scene: str
    tol: float
    segments: int
    draw_segments: int
    compile_s: float
    plot_s: float
    ideal_max_mm: float
    quant_max_mm: float
    quantum_mm: float
    uniform_segments: int
    uniform_h_mm: float
    uniform_dev_mm: float
    error: str = ""  # the exception, if compiling raised one
    off_chord_mm: float = math.nan  # largest distance of a draw segment's start from its chord


def _segment_distance(e: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance of points e from the segments a → b (row by row)."""
    ab = b - a
    den = np.maximum((ab * ab).sum(axis=1), 1e-300)
    t = np.clip(((e - a) * ab).sum(axis=1) / den, 0.0, 1.0)
    return np.asarray(np.hypot(*(e - a - t[:, None] * ab).T), dtype=np.float64)


def fixed_spacing(job: Job, fb: FiveBar, tol: float, samples: int = 16,
                  iterations: int = 10) -> tuple[int, float, float]:
    """The fixed-point-count alternative to adaptive segmentation: cut every primitive of the
    placed drawing into k = ⌈length/h⌉ equal-parameter pieces (one spacing h for the whole
    drawing), take the closed-form inverse at the piece ends and let the machine interpolate
    in joint space between them. Returns the segment count, the largest h whose deviation
    from the drawing (measured like `fivebar_host.job.deviations`: `samples` + 1 points per
    piece through the forward kinematics, distance to the primitive) stays ≤ tol (to 0.1 %
    in h), and that deviation."""
    dr = job.drawing
    kind, params = dr.kind, dr.params
    n = kind.shape[0]
    t64 = np.linspace(0.0, 1.0, 65)
    poly = evaluate(np.repeat(kind, 65), np.repeat(params, 65, axis=0), np.tile(t64, n))
    length = np.hypot(*np.diff(poly.reshape(n, 65, 2), axis=1).transpose(2, 0, 1)).sum(axis=1)
    asm = "+" if job.assembly > 0 else "-"
    s = np.arange(samples + 1) / samples

    def trial(h: float) -> tuple[float, int]:
        k = np.maximum(np.ceil(length / h).astype(np.int64), 1)
        prim = np.repeat(np.arange(n), k)
        m = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
        ta, tb = m / k[prim], (m + 1) / k[prim]
        inv_a = fb.inverse_batch(evaluate(kind[prim], params[prim], ta), job.mode)
        inv_b = fb.inverse_batch(evaluate(kind[prim], params[prim], tb), job.mode)
        if not (inv_a.valid.all() and inv_b.valid.all()):
            return math.inf, int(k.sum())
        tha, thb = inv_a.angles, inv_b.angles
        q = (tha[:, None, :] + s[None, :, None] * (thb - tha)[:, None, :]).reshape(-1, 2)
        fk = fb.forward_batch(q, asm)
        rep = np.repeat(prim, samples + 1)
        tg = (ta[:, None] + s[None, :] * (tb - ta)[:, None]).ravel()
        d = nearest_distance(kind[rep], params[rep], np.asarray(fk.points), tg)
        d[~fk.valid] = np.inf
        return float(d.max()), int(k.sum())

    # Halve h from the longest element until the tolerance is met, then bisect (log h)
    # between the last failing and the first passing spacing; coarse trials are cheap.
    h = max(float(length.max()), 1e-3)
    best = trial(h)
    fail = math.inf
    while best[0] > tol:
        if h < 1e-4:
            raise RuntimeError(f"no fixed spacing ≥ 1e-4 mm meets {tol} mm")
        fail, h = h, 0.5 * h
        best = trial(h)
    lo, hi = math.log(h), math.log(fail) if math.isfinite(fail) else math.log(h)
    for _ in range(iterations):
        if hi - lo < 1e-3:
            break
        mid = 0.5 * (lo + hi)
        d_mid, c_mid = trial(math.exp(mid))
        if d_mid <= tol:
            lo, best = mid, (d_mid, c_mid)
        else:
            hi = mid
    return best[1], math.exp(lo), best[0]


def job_rows(sc: Scene, cfg: Config, scenes: dict[str, Path]) -> list[JobRow]:
    """Item 3: compile each scene at every tolerance (median time of cfg.job_repeats), count
    segments, plot time, deviation from the ideal and the quantised steps (16 samples per
    segment) and the fixed spacing that would meet the same tolerance."""
    rows = []
    prof = sc.profile
    for name, path in scenes.items():
        for tol in cfg.job_tols:
            opts = CompileOptions(tolerance_mm=tol, fit=True, validate=False)
            times = []
            job: Job | None = None
            try:
                for _ in range(cfg.job_repeats):
                    t0 = time.perf_counter()
                    job = compile_job(path, prof, opts)
                    times.append(time.perf_counter() - t0)
            except Exception as e:  # an undocumented failure is a finding: report it
                nan = math.nan
                rows.append(JobRow(name, tol, 0, 0, nan, nan, nan, nan, nan, 0, nan, nan,
                                   f"{type(e).__name__}: {e}"))
                continue
            assert job is not None
            ideal, _ = deviations(job, prof, samples=16, quantised=False)
            quant, _ = deviations(job, prof, samples=16, quantised=True)
            n_u, h_u, d_u = fixed_spacing(job, sc.fb, tol)
            di = np.flatnonzero(job.draw)
            off = _segment_distance(job.points_mm[di], job.seg_ca, job.seg_cb)
            rows.append(JobRow(name, tol, job.n_segments, int(job.draw.sum()),
                               statistics.median(times), job.total_time_s,
                               float(ideal.max()), float(quant.max()), job.step_quantum_mm,
                               n_u, h_u, d_u, "", float(off.max()) if off.size else 0.0))
    return rows


@dataclass(frozen=True)
class ValidationCost:
    """Closed-form validation against the n-bar second opinion on one job."""

    scene: str
    poses: int
    closed_s: float
    nbar_s: float
    closed_max_mm: float
    nbar_max_mm: float
    disagreement_mm: float


def validation_cost(sc: Scene, path: Path, name: str, repeats: int) -> ValidationCost | None:
    """Time `validate` (closed form) and `nbar_opinion` (n-bar continuation) on one job
    (None if the job does not compile: job_rows reports why)."""
    prof = sc.profile
    try:
        job = compile_job(path, prof, CompileOptions(fit=True, validate=False))
    except Exception:
        return None
    t_c = median_time(lambda: validate(job, prof), repeats)
    vj = validate(job, prof)
    t0 = time.perf_counter()
    op = nbar_opinion(job, prof)
    t_n = time.perf_counter() - t0
    assert op is not None
    return ValidationCost(name, op.poses, t_c, t_n, vj.max_dev_mm, op.max_dev_mm,
                          op.max_disagreement_mm)


# ============================================================================ 4. step quantum
@dataclass(frozen=True)
class StepRow:
    microsteps: int
    gear: float
    steps_per_rev: float
    quantum_max_mm: float
    quantum_median_mm: float
    rate_needed: float  # steps/s at the profile's max joint speed
    joint_speed_cap: float  # rad/s the firmware's default step-rate cap allows


def firmware_rate_cap() -> float:
    """The firmware's default step-rate limit per motor (`DEF_MAX_RATE`, $0), steps/s."""
    m = re.search(r"#define\s+DEF_MAX_RATE\s+(\d+)", FIRMWARE_CONFIG.read_text())
    if m is None:
        raise RuntimeError(f"DEF_MAX_RATE not found in {FIRMWARE_CONFIG}")
    return float(m.group(1))


def step_rows(sc: Scene, cfg: Config, rng: np.random.Generator) -> list[StepRow]:
    """Item 4: the step quantum (largest pen move of one step of either motor, exact forward
    kinematics, kinematics.analysis.step_quantum) over the page region, per drive setting."""
    pts = sc.region_pts
    if pts.shape[0] > 6000:
        pts = pts[rng.choice(pts.shape[0], 6000, replace=False)]
    full = sc.profile.motors.full_steps
    vmax = sc.profile.motion.max_joint_rad_s
    cap = firmware_rate_cap()
    gears = sorted(set(cfg.gears) | {sc.profile.motors.gear_ratio})
    rows = []
    for g in gears:
        for ms in cfg.microsteps:
            spr = full * ms * g
            rad = 2.0 * math.pi / spr
            q = step_quantum(sc.fb, sc.mode, pts, rad)
            rows.append(StepRow(ms, g, spr, float(np.nanmax(q)), float(np.nanmedian(q)),
                                vmax / rad, cap * rad))
    return rows


# ============================================================================ 5. stability
class Cat(IntEnum):
    """Outcome of a method at one place of the stability map."""

    NO_ANSWER = 0  # no answer exists (closed form refuses) and the method refused too
    OTHER_ASSEMBLY = 1  # forward maps: the point belongs to the other assembly, not asked
    EXACT = 2  # error ≤ EXACT_MM
    WITHIN_TOL = 3  # error ≤ the job tolerance
    OVER_TOL = 4  # error > the job tolerance
    REFUSED = 5  # refused a point that has an answer (documented refusal)
    LIMIT = 6  # n-bar: motion limit / no convergence
    FLIP = 7  # n-bar: converged on the other assembly's branch
    FALSE_ANSWER = 8  # answered where no answer exists


CAT_STYLE: dict[Cat, tuple[str, str]] = {
    Cat.NO_ANSWER: ("#ffffff", "unreachable, refused"),
    Cat.OTHER_ASSEMBLY: ("#d9d9d9", "other assembly (not asked)"),
    Cat.EXACT: ("#1a9850", "error ≤ 1e-6 mm"),
    Cat.WITHIN_TOL: ("#a6d96a", "error ≤ tolerance"),
    Cat.OVER_TOL: ("#fdae61", "error > tolerance"),
    Cat.REFUSED: ("#74add1", "refused (documented)"),
    Cat.LIMIT: ("#313695", "n-bar: motion limit"),
    Cat.FLIP: ("#d73027", "branch flip"),
    Cat.FALSE_ANSWER: ("#000000", "answered, no answer exists"),
}


def _categorise(err: FloatArray, tol: float) -> NDArray[np.int8]:
    c = np.where(err <= EXACT_MM, Cat.EXACT, np.where(err <= tol, Cat.WITHIN_TOL, Cat.OVER_TOL))
    return np.asarray(c, dtype=np.int8)


@dataclass(frozen=True, eq=False)
class StabilityMap:
    xs: FloatArray
    ys: FloatArray
    codes: dict[str, NDArray[np.int8]]  # method → (ny, nx) Cat codes
    nbar_xs: FloatArray
    nbar_ys: FloatArray
    nbar_codes: NDArray[np.int8]
    nbar_tol: float

    def counts(self) -> dict[str, dict[Cat, int]]:
        out = {m: {c: int((v == c).sum()) for c in Cat} for m, v in self.codes.items()}
        out["n-bar forward (coarser grid)"] = {c: int((self.nbar_codes == c).sum())
                                               for c in Cat}
        return out


def map_methods(sc: Scene, cfg: Config
                ) -> dict[str, tuple[str, Callable[[FloatArray], tuple[FloatArray, BoolArray]]]]:
    """The methods drawn on the stability map and along the approaches (name → (direction,
    fn)): the closed form, Eq. 25/26 fitted on the page region, and bilinear tables over the
    workspace / joint-limit box, unguarded and guarded (`max_error` = the job tolerance)."""
    fb, mode, asm = sc.fb, sc.mode, sc.assembly
    n = cfg.map_lut
    centre = sc.page.rect.center
    lin = approx.fit_linear(fb, mode, sc.region_pts, "similarity")
    lut_i = approx.inverse_table(fb, mode, sc.ws_box, n, "linear", centre=centre)
    cap, margins = guard_of(sc)
    lut_ig = approx.inverse_table(fb, mode, sc.ws_box, n, "linear", max_error=cap,
                                  centre=centre, min_margins=margins)
    lut_fg = approx.forward_table(fb, asm, sc.joint_box, n, "linear", max_error=cap,
                                  min_margins=margins)

    closed_inv, closed_fwd = _closed_form(sc)

    guard = "guarded"
    return {
        "closed form inverse": ("inverse", closed_inv),
        "closed form forward": ("forward", closed_fwd),
        "Eq. 25 inverse (page fit)": ("inverse", _wrap(lin.inverse)),
        "Eq. 26 forward (page fit)": ("forward", _wrap(lin.forward)),
        f"LUT bilinear {n}² inverse": ("inverse", _wrap(lut_i)),
        f"LUT bilinear {n}² inverse, {guard}": ("inverse", _wrap(lut_ig)),
        f"LUT bilinear {n}² forward, {guard}": ("forward", _wrap(lut_fg)),
    }


def stability_map(sc: Scene, cfg: Config) -> StabilityMap:
    """Item 5: every method at every node of a grid over the workspace box (working mode of
    the profile). Inverse maps are asked everywhere; forward maps at the closed-form angles of
    reachable points of the page's assembly. The n-bar solver (a continuation step of
    MAX_STEP_RAD, as validation uses it, at its default tolerance) on every
    cfg.nbar_map_stride-th node."""
    fb, mode = sc.fb, sc.mode
    x0, x1, y0, y1 = sc.ws_box
    xs = np.arange(x0, x1 + 1e-9, cfg.map_pitch_mm)
    ys = np.arange(y0, y1 + 1e-9, cfg.map_pitch_mm)
    xx, yy = np.meshgrid(xs, ys)
    p = np.stack((xx.ravel(), yy.ravel()), axis=1)
    inv = fb.inverse_batch(p, mode)
    reach = inv.valid
    th = inv.angles
    sign = np.where(reach, fb.assembly_of(th, p), 0).astype(np.float64)
    same = reach & (sign == sc.sign)
    ref_p = ref_forward(sc, th, np.where(sign == 0, 1.0, sign))
    codes: dict[str, NDArray[np.int8]] = {}
    for name, (direction, fn) in map_methods(sc, cfg).items():
        c = np.full(p.shape[0], Cat.NO_ANSWER, dtype=np.int8)
        if direction == "inverse":
            v, ok = fn(p)
            err = _dist(ref_forward(sc, v, np.where(sign == 0, 1.0, sign)), p)
            c[reach] = _categorise(err[reach], sc.tol_mm)
            c[reach & ~ok] = Cat.REFUSED
            c[~reach & ok] = Cat.FALSE_ANSWER
        else:
            c[reach & ~same] = Cat.OTHER_ASSEMBLY
            v, ok = fn(th)
            err = _dist(v, ref_p)
            c[same] = _categorise(err[same], sc.tol_mm)
            c[same & ~ok] = Cat.REFUSED
        codes[name] = c.reshape(xx.shape)
    # n-bar on a coarser sub-grid
    st = cfg.nbar_map_stride
    sub = np.zeros(xx.shape, dtype=bool)
    sub[::st, ::st] = True
    idx = np.flatnonzero(sub.ravel())
    nb = np.full(idx.size, Cat.NO_ANSWER, dtype=np.int8)
    tol = fivebar_mechanism(fb, sc.profile.motors.home_rad, sc.assembly).settings.tolerance
    for k, i in enumerate(idx):
        if not reach[i]:
            continue
        if not same[i]:
            nb[k] = Cat.OTHER_ASSEMBLY
            continue
        outcome, q = nbar_step_check(sc, th[i], sign[i], tol)
        if outcome == "limit":
            nb[k] = Cat.LIMIT
        elif outcome == "start":
            nb[k] = Cat.REFUSED
        else:
            e = _dist(q[None], ref_p[i:i + 1])[0]
            other = _dist(q[None], ref_forward(sc, th[i:i + 1], -sign[i]))[0]
            nb[k] = Cat.FLIP if other < e and e > sc.tol_mm else int(_categorise(
                np.array([e]), sc.tol_mm)[0])
    ny2, nx2 = xx[::st, ::st].shape
    return StabilityMap(xs, ys, codes, xs[::st], ys[::st], nb.reshape(ny2, nx2), tol)


# ----------------------------------------------------------------------------- approaches
@dataclass(frozen=True, eq=False)
class Approach:
    """Poses closing in on one singularity: δ (mm) the distance parameter (reach circle:
    distance of P inside it; type 2: how much shorter |R1R2| is than b1 + b2, or |R1R2|
    itself for Mode 1b), the poses, and the angular margin to that singularity."""

    name: str
    deltas: FloatArray
    points: FloatArray
    angles: FloatArray
    sign: float
    margin_deg: FloatArray
    on: tuple[FloatArray, FloatArray]  # (point, angles) exactly at the singularity (δ = 0)
    beyond: tuple[FloatArray, FloatArray]  # δ = −1e-9: past it (point or angles)


def _type1_approach(sc: Scene, arm: int, folded: bool, deltas: FloatArray) -> Approach | None:
    fb = sc.fb
    a, b, mx = (fb.a1, fb.b1, 0.0) if arm == 1 else (fb.a2, fb.b2, fb.w)
    if folded and a == b:
        return None
    radius = abs(a - b) if folded else a + b
    sgn = 1.0 if folded else -1.0  # δ > 0 is inside the reachable annulus
    cx, cy = sc.page.rect.center
    phi0 = math.atan2(cy, cx - mx)
    for dphi in np.radians(np.concatenate(([0.0], np.arange(5, 180, 5),
                                           -np.arange(5, 180, 5)))):
        phi = phi0 + dphi
        u = np.array([math.cos(phi), math.sin(phi)])
        allp = np.array([mx, 0.0]) + (radius + sgn * np.concatenate((deltas, [0.0, -1e-9])))[
            :, None] * u
        inv = fb.inverse_batch(allp[:-1], sc.mode)
        if not inv.valid.all():
            continue
        th = np.asarray(inv.angles)
        m = fb.singularity_margins(th, allp[:-1])
        other = [j for j in range(3) if j != arm - 1]
        if (np.abs(m[:, other]).min() < math.radians(10.0)
                or not np.all(fb.assembly_of(th[:-1], allp[:-2]) == int(sc.sign))):
            continue
        kind = "folded" if folded else "stretched"
        return Approach(f"type 1: arm {arm} {kind}", deltas, allp[:-2], th[:-1], sc.sign,
                        np.degrees(np.abs(m[:-1, arm - 1])), (allp[-2], th[-1]),
                        (allp[-1], np.full(2, np.nan)))
    return None


def _type2_approach(sc: Scene, mode_1b: bool, deltas: FloatArray) -> Approach | None:
    """Joint-space poses closing in on a type-2 singularity, P by the closed-form forward
    kinematics in the page's assembly, in the page's working mode and ≥ 10° from type 1.

    Mode 1a (|R1R2| → b1 + b2): θ1 from a scan over its limits, θ2 solving
    |R1R2| = b1 + b2 − δ (R2 = circle |R2 − M2| = a2 ∩ circle of radius L about R1).
    Mode 1b class I (b1 = b2, R1 = R2 = X at an intersection of the two elbow circles):
    θ = θ_X + δ·(σ1/a1, σ2/a2), so the elbows part along σ2·t2 − σ1·t1 (t_i the circles'
    tangents at X), not along a tangent — along one, P would close in on a type-1
    singularity of the other arm at the same time; δ is then the elbow distance's scale."""
    fb = sc.fb
    if mode_1b and fb.b1 != fb.b2:
        return None
    asm = sc.assembly
    s1, s2 = _signs(sc.mode)
    dd = np.concatenate((deltas, [0.0, -1e-9]))
    cands: list[FloatArray] = []
    if mode_1b:
        for xp in approx_elbow_meets(fb):
            tx = np.array([math.atan2(xp[1], xp[0]), math.atan2(xp[1], xp[0] - fb.w)])
            for sg1 in (1.0, -1.0):
                for sg2 in (1.0, -1.0):
                    cands.append(tx + dd[:, None] * np.array([sg1 / fb.a1, sg2 / fb.a2]))
    else:
        lim = sc.profile.motors.limits_rad
        lengths = fb.b1 + fb.b2 - dd
        for th1 in np.linspace(lim[0][0], lim[0][1], 33):
            r1 = np.array([fb.a1 * math.cos(th1), fb.a1 * math.sin(th1)])
            d = np.array([fb.w, 0.0]) - r1
            dn = float(np.hypot(*d))
            kk = ((lengths + fb.a2 + dn) * (lengths + fb.a2 - dn) * (lengths - fb.a2 + dn)
                  * (-lengths + fb.a2 + dn))
            if np.any(kk[:-1] < 0):
                continue
            along = (dn * dn + lengths ** 2 - fb.a2 ** 2) / (2 * dn * dn)
            across = np.sqrt(np.maximum(kk, 0.0)) / (2 * dn * dn)
            for branch in (1.0, -1.0):
                r2 = (r1 + along[:, None] * d
                      + branch * across[:, None] * np.array([-d[1], d[0]]))
                th2 = np.arctan2(r2[:, 1], r2[:, 0] - fb.w)
                cands.append(np.stack((np.full(th2.size, th1), th2), axis=1))
    for th in cands:
        fw = fb.forward_batch(th[:-2], asm)
        if not fw.valid.all():
            continue
        pts = np.asarray(fw.points)
        modes = fb.mode_of(pts, th[:-2])
        if not (np.all(modes[:, 0] == s1) and np.all(modes[:, 1] == s2)):
            continue
        m = fb.singularity_margins(th[:-2], pts)
        if np.abs(m[:, :2]).min() < math.radians(10.0):
            continue
        on = fb.forward_batch(th[-2:-1], asm)
        on_p = np.asarray(on.points[0]) if on.valid[0] else np.full(2, np.nan)
        name = "type 2: Mode 1b (R1 = R2)" if mode_1b else "type 2: Mode 1a"
        beyond = th[-1]  # 1a: the links cannot meet; 1b: the elbows have crossed
        return Approach(name, deltas, pts, th[:-2], sc.sign, np.degrees(np.abs(m[:, 2])),
                        (on_p, th[-2]), (np.full(2, np.nan), beyond))
    return None


def approx_elbow_meets(fb: FiveBar) -> list[FloatArray]:
    """Points X where the elbow circles |X| = a1 and |X − M2| = a2 meet (R1 = R2 = X)."""
    d = fb.w
    a = (d * d + fb.a1 ** 2 - fb.a2 ** 2) / (2 * d)
    h2 = fb.a1 ** 2 - a * a
    if h2 < 0:
        return []
    h = math.sqrt(h2)
    return [np.array([a, h]), np.array([a, -h])]


def approaches(sc: Scene, cfg: Config) -> list[Approach]:
    """One approach per singularity the machine has in its working mode."""
    deltas = 10.0 ** np.asarray(cfg.approach_exponents)
    found = [_type1_approach(sc, 1, False, deltas), _type1_approach(sc, 1, True, deltas),
             _type2_approach(sc, False, deltas), _type2_approach(sc, True, deltas)]
    return [a for a in found if a is not None]


def variant_scene(sc: Scene) -> Scene | None:
    """If the machine has no Mode 1a singularity (b1 + b2 > a1 + a2 + w: the floating links
    can never be stretched into one line), the same profile with floating links of
    (a1 + a2 + w)/2 − 10 mm each, which has one; None if it has one already."""
    fb = sc.fb
    reach = fb.a1 + fb.a2 + fb.w
    if fb.b1 + fb.b2 < reach:
        return None
    b = 0.5 * reach - 10.0
    geo = FiveBar(fb.a1, b, fb.a2, b, fb.w)
    return make_scene(dataclasses.replace(sc.profile, geometry=geo))


@dataclass(frozen=True, eq=False)
class ApproachResult:
    approach: Approach
    machine: str  # which machine ("profile" or the variant's links)
    errors: dict[str, FloatArray]  # method → (K,) pen error mm, NaN where refused
    at: dict[str, str]  # method → outcome exactly at the singularity
    past: dict[str, str]  # method → outcome just beyond it


def _outcome(call: Callable[[], Any]) -> str:
    try:
        call()
    except Exception as e:  # the exception type is the outcome reported
        return f"{type(e).__name__}"
    return "answer"


def run_approaches(sc: Scene, cfg: Config, only: tuple[str, ...] | None = None,
                   machine: str = "profile") -> list[ApproachResult]:
    """Every method along every approach (all, or those named in `only`). The n-bar solver
    follows each approach by continuation (one simulate over the δ sequence from the
    farthest pose), then one more step onto the singular pose and, separately, past it;
    there it is judged by continuity: the distance of its answer from the closed-form
    point of the nearest approach pose, and the assembly sign it ends in."""
    methods = map_methods(sc, cfg)
    fb = sc.fb
    out = []
    for ap in approaches(sc, cfg):
        if only is not None and ap.name not in only:
            continue
        errs: dict[str, FloatArray] = {}
        at: dict[str, str] = {}
        past: dict[str, str] = {}
        ref_p = ref_forward(sc, ap.angles, ap.sign)
        for name, (direction, fn) in methods.items():
            if direction == "inverse":
                v, ok = fn(ap.points)
                e = _dist(ref_forward(sc, v, ap.sign), ap.points)
                on_q, past_q = ap.on[0], ap.beyond[0]
            else:
                v, ok = fn(ap.angles)
                e = _dist(v, ref_p)
                on_q, past_q = ap.on[1], ap.beyond[1]
            errs[name] = np.where(ok, e, np.nan)
            for q, store in ((on_q, at), (past_q, past)):
                if np.isnan(q).any():
                    store[name] = "—"
                    continue
                _, okk = fn(q[None])
                store[name] = "answer" if okk[0] else "refused"
        # the single-pose closed form raises its documented errors
        for k, (q, store) in enumerate(((ap.on[0], at), (ap.beyond[0], past),
                                        (ap.on[1], at), (ap.beyond[1], past))):
            if np.isnan(q).any():
                continue
            if k < 2:
                store["closed form inverse"] = _outcome(partial(fb.inverse, q, sc.mode))
            else:
                store["closed form forward"] = _outcome(partial(fb.forward, q, sc.assembly))
        mech = fivebar_mechanism(fb, ap.angles[0], sc.assembly)
        sim = simulate(mech, ap.angles)
        good = np.isin(sim.status, (Status.OK, Status.SUBDIVIDED))
        errs["n-bar"] = np.where(good, _dist(sim.path("P"), ref_p), np.nan)
        last = ap.points[-1]
        for q, store in ((ap.on[1], at), (ap.beyond[1], past)):
            if np.isnan(q).any():
                store["n-bar"] = "—"
                continue
            s2 = simulate(mech, np.concatenate((ap.angles, q[None])))
            st = Status(int(s2.status[-1])).name.lower()
            if st in ("ok", "subdivided"):
                p2 = s2.path("P")[-1]
                r1, r2 = fb.elbows(q)
                d, e = r2[0] - r1[0], p2 - r1[0]
                sg = float(np.sign(d[0] * e[1] - d[1] * e[0]))
                side = "same" if sg == ap.sign else "other" if sg == -ap.sign else "no"
                st = (f"{st}: {float(np.hypot(*(p2 - last))):.2g} mm from the last approach "
                      f"pose, {side} assembly")
            elif s2.limits:
                before = "motion limit before it" if st == "unreached" else st
                st = f"{before} ({s2.limits[-1].reason.split(':')[0]})"
            store["n-bar"] = st
        out.append(ApproachResult(ap, machine, errs, at, past))
    return out


# ============================================================================ charts
def _save(fig: Any, path: Path) -> None:
    fig.savefig(path, dpi=100)
    plt.close(fig)


FAMILY_STYLE: dict[str, tuple[str, str]] = {
    "closed form": ("#000000", "*"),
    "bare formulas": ("#555555", "P"),
    "n-bar": ("#7b3294", "D"),
    "linear Eq. 25/26": ("#d7191c", "s"),
    "linear affine": ("#fdae61", "s"),
    "tiles Eq. 25": ("#e66101", "^"),
    "tiles affine": ("#b2abd2", "^"),
    "LUT bilinear": ("#2c7bb6", "o"),
    "LUT bicubic": ("#1a9641", "o"),
}
GUARDED_STYLE = ("#00bcd4", "v")
FAMILY_STYLE["LUT bilinear guarded"] = GUARDED_STYLE
FLOOR_MM = 1e-16


def chart_tradeoff(rows: Sequence[MethodRow], nrows: Sequence[NbarKinRow], tol: float,
                   path: Path) -> None:
    """Item 1 chart: ns per point against max pen error, per direction and per set."""
    sets = list(rows[0].errors)
    fig, axes = plt.subplots(2, len(sets), figsize=(5.2 * len(sets), 8.4), sharex=True,
                             sharey=True)
    for r, direction in enumerate(("inverse", "forward")):
        for c, sname in enumerate(sets):
            ax = axes[r, c]
            fams: dict[str, list[tuple[float, float, str]]] = {}
            for row in rows:
                if row.direction != direction:
                    continue
                e = row.errors[sname].max_mm
                if not math.isfinite(e):
                    continue
                fams.setdefault(row.family, []).append((row.ns_per_point, max(e, FLOOR_MM),
                                                        row.size))
            if direction == "forward":
                for nr in nrows:
                    e = nr.errors[sname].max_mm
                    if math.isfinite(e):
                        fams.setdefault("n-bar", []).append((1e3 * nr.us_per_pose,
                                                             max(e, FLOOR_MM),
                                                             f"{nr.tol:.0e}"))
            for fam, pts in fams.items():
                col, mk = FAMILY_STYLE.get(fam, GUARDED_STYLE)
                # tables/tiles by size, n-bar by tolerance (loosest first)
                pts.sort(key=lambda t: -float(t[2]) if fam == "n-bar" else float(
                    t[2].split("×")[0].split("²")[0].split(" ")[0]) if t[2][0].isdigit()
                    else 0.0)
                ax.plot([t[0] for t in pts], [t[1] for t in pts], marker=mk, color=col,
                        label=fam, lw=1, ms=6)
                if fam.startswith(("LUT", "tiles", "n-bar")):
                    for x, y, s in pts if fam == "n-bar" else (pts[0], pts[-1]):
                        ax.annotate(s, (x, y), fontsize=7, xytext=(3, 3),
                                    textcoords="offset points", color=col)
            ax.axhline(tol, color="k", ls="--", lw=0.8)
            ax.axhline(EXACT_MM, color="k", ls=":", lw=0.8)
            ax.text(0.99, tol, f"tolerance {tol:g} mm", fontsize=7, va="bottom", ha="right",
                    transform=ax.get_yaxis_transform())
            ax.text(0.99, EXACT_MM, "1e-6 mm", fontsize=7, va="bottom", ha="right",
                    transform=ax.get_yaxis_transform())
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="major", alpha=0.3)
            ax.set_title(f"{direction}, {sname}", fontsize=10)
            if r == 1:
                ax.set_xlabel("time per point, ns (log)")
            if c == 0:
                ax.set_ylabel(f"max pen error, mm (log; floor {FLOOR_MM:g})")
    handles, labels = [], []
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8)
    fig.suptitle("Five-bar kinematics: time per point against max pen error "
                 "(inverse answers are measured through the exact forward kinematics)",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    _save(fig, path)


def chart_examples(rows: Sequence[ExampleRow], path: Path) -> None:
    """Item 2 chart: per example, ms per run against max residual; one line per step factor
    (points at the tolerances), scipy baseline as black crosses."""
    names = sorted({r.example for r in rows})
    ncol = min(4, len(names))
    nrow = -(-len(names) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.6 * nrow), squeeze=False)
    factors = sorted({r.factor for r in rows})
    cmap = plt.get_cmap("viridis")
    for k, name in enumerate(names):
        ax = axes[k // ncol, k % ncol]
        for j, f in enumerate(factors):
            rs = sorted((r for r in rows if r.example == name and r.factor == f
                         and r.solver == "n-bar"), key=lambda r: -r.tol)
            col = cmap(j / max(len(factors) - 1, 1))
            ax.plot([r.ms for r in rs], [max(r.residual, FLOOR_MM) for r in rs], "o-",
                    color=col, ms=4, label=f"step ×{f:g}")
            for r in rs[:1] + rs[-1:]:
                ax.annotate(f"{r.tol:.0e}", (r.ms, max(r.residual, FLOOR_MM)), fontsize=6,
                            xytext=(2, 2), textcoords="offset points", color=col)
            bs = [r for r in rows if r.example == name and r.factor == f
                  and r.solver == "scipy"]
            if bs:
                ax.plot([b.ms for b in bs], [max(b.residual, FLOOR_MM) for b in bs], "x",
                        color=col, ms=8, mew=2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, alpha=0.3)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("wall time per run, ms (log)")
        ax.set_ylabel("max relative residual (log)")
    for k in range(len(names), nrow * ncol):
        axes[k // ncol, k % ncol].axis("off")
    h, lab = axes[0, 0].get_legend_handles_labels()
    h.append(plt.Line2D([], [], color="k", marker="x", ls="", mew=2))
    lab.append("scipy baseline (same step)")
    fig.legend(h, lab, loc="lower center", ncol=len(lab), fontsize=8)
    fig.suptitle("n-bar solver: tolerance (labels) and input step against time and constraint "
                 "residual", fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 0.96))
    _save(fig, path)


def chart_jobs(rows: Sequence[JobRow], path: Path) -> None:
    """Item 3 chart: tolerance against segments (adaptive and fixed spacing), compile time,
    plot time and measured deviation."""
    scenes = list(dict.fromkeys(r.scene for r in rows))
    fig, axes = plt.subplots(1, 4, figsize=(18, 4.8))
    cols = plt.get_cmap("tab10")
    ok_rows = [r for r in rows if not r.error]
    for k, sname in enumerate(scenes):
        rs = sorted((r for r in ok_rows if r.scene == sname), key=lambda r: r.tol)
        tol = [r.tol for r in rs]
        col = cols(k)
        axes[0].plot(tol, [r.draw_segments for r in rs], "o-", color=col,
                     label=f"{sname}: adaptive")
        axes[0].plot(tol, [r.uniform_segments for r in rs], "s--", color=col,
                     label=f"{sname}: fixed spacing")
        axes[1].plot(tol, [1e3 * r.compile_s for r in rs], "o-", color=col, label=sname)
        axes[2].plot(tol, [r.plot_s for r in rs], "^-", color=col, label=sname)
        axes[3].plot(tol, [r.quant_max_mm for r in rs], "o-", color=col,
                     label=f"{sname}: from quantised steps")
        axes[3].plot(tol, [r.ideal_max_mm for r in rs], "^:", color=col,
                     label=f"{sname}: ideal joint targets")
        axes[3].plot(tol, [r.quantum_mm for r in rs], "-", color=col, alpha=0.35, lw=3,
                     label=f"{sname}: step quantum")
    if ok_rows:
        lo = min(r.tol for r in ok_rows)
        hi = max(r.tol for r in ok_rows)
        axes[3].plot([lo, hi], [lo, hi], "k--", lw=0.8, label="deviation = tolerance")
    titles = ("draw segments: adaptive vs fixed spacing meeting the same tolerance",
              "compile time (drawing → steps)", "plot time of the job",
              "max deviation from the drawing")
    ylabels = ("segments (log)", "compile time, ms (log)", "plot time, s (log)",
               "max deviation, mm (log)")
    for ax, t, yl in zip(axes, titles, ylabels, strict=True):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("tolerance, mm (log)")
        ax.set_ylabel(yl)
        ax.set_title(t, fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.legend(fontsize=7)
    fig.suptitle("Job compilation: one tolerance against segments, time and measured deviation",
                 fontsize=11)
    fig.tight_layout()
    _save(fig, path)


def chart_steps(sc: Scene, rows: Sequence[StepRow], path: Path, pitch: float) -> None:
    """Item 4 chart: quantum against microstepping per gear ratio, and the profile's map."""
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    ax = axes[0]
    gears = sorted({r.gear for r in rows})
    cmap = plt.get_cmap("plasma")
    for k, g in enumerate(gears):
        rs = sorted((r for r in rows if r.gear == g), key=lambda r: r.microsteps)
        col = cmap(k / max(len(gears), 1))
        ax.plot([r.microsteps for r in rs], [r.quantum_max_mm for r in rs], "o-", color=col,
                label=f"gear {g:g}: max over the page region")
        ax.plot([r.microsteps for r in rs], [r.quantum_median_mm for r in rs], "s--",
                color=col, label=f"gear {g:g}: median")
    ax.axhline(sc.tol_mm, color="k", ls=":", lw=1)
    ax.text(0.99, sc.tol_mm, f"tolerance {sc.tol_mm:g} mm", fontsize=8, va="bottom",
            ha="right", transform=ax.get_yaxis_transform())
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("microsteps per full step (log₂)")
    ax.set_ylabel("step quantum: pen move of one step, mm (log)")
    ax.set_title(f"{sc.profile.motors.full_steps} full steps/rev; one step of either motor",
                 fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    # map for the profile's own setting
    ax = axes[1]
    x0, x1, y0, y1 = sc.ws_box
    xs = np.arange(x0, x1 + 1e-9, pitch)
    ys = np.arange(max(y0, 0.0), y1 + 1e-9, pitch)
    xx, yy = np.meshgrid(xs, ys)
    pts = np.stack((xx.ravel(), yy.ravel()), axis=1)
    q = step_quantum(sc.fb, sc.mode, pts, sc.profile.motors.rad_per_step).reshape(xx.shape)
    asm = np.full(pts.shape[0], 0)
    inv = sc.fb.inverse_batch(pts, sc.mode)
    asm[inv.valid] = sc.fb.assembly_of(inv.angles[inv.valid], pts[inv.valid])
    q = np.where(asm.reshape(xx.shape) == int(sc.sign), q, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        lq = np.log10(q)
    finite = lq[np.isfinite(lq)]
    lo, hi = (np.percentile(finite, [1, 99]) if finite.size else (-3.0, 0.0))
    im = ax.pcolormesh(xs, ys, lq, cmap="viridis", shading="nearest", vmin=lo, vmax=hi)
    cb = fig.colorbar(im, ax=ax)
    cb.set_label("log₁₀ step quantum, mm")
    _overlay(ax, sc)
    m = sc.profile.motors
    ax.set_title(f"profile: {m.microsteps} microsteps, gear {m.gear_ratio:g} "
                 f"(assembly {sc.assembly} of mode {sc.mode})", fontsize=10)
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_aspect("equal")
    ax.set_xlim(x0, x1)
    ax.set_ylim(ys[0], y1)
    fig.suptitle("Physical limit of accuracy: step resolution against the pen's step quantum",
                 fontsize=11)
    fig.tight_layout()
    _save(fig, path)


def _overlay(ax: Any, sc: Scene) -> None:
    """Singularity curves of the working mode, reach circles, motors and the page."""
    for tr in type2_traces(sc.fb):
        for pl in tr.polylines(sc.mode):
            ax.plot(pl[:, 0], pl[:, 1], color="#d73027", lw=1.0)
    for _, _, (cx, cy), r in type1_circles(sc.fb):
        t = np.linspace(0, 2 * np.pi, 361)
        ax.plot(cx + r * np.cos(t), cy + r * np.sin(t), color="#4d4d4d", lw=0.6, ls="--")
    rc = sc.page.rect
    ax.add_patch(Rectangle((rc.x0, rc.y0), rc.width, rc.height, fill=False, ec="k", lw=1.2))
    ax.plot([0.0, sc.fb.w], [0.0, 0.0], "ks", ms=4)


def chart_stability(sc: Scene, smap: StabilityMap, path: Path) -> None:
    """Item 5 map: categorical outcome per method over the workspace."""
    panels = list(smap.codes.items())
    panels.insert(2, (f"n-bar forward (step {MAX_STEP_RAD:g} rad, tol {smap.nbar_tol:g})",
                      smap.nbar_codes))
    ncol = 4
    nrow = -(-len(panels) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 4.3 * nrow + 0.8), squeeze=False)
    colors = [CAT_STYLE[c][0] for c in Cat]
    cmap = ListedColormap(colors)
    norm = BoundaryNorm(np.arange(len(Cat) + 1) - 0.5, len(Cat))
    x0, x1, y0, y1 = sc.ws_box
    for k, (name, codes) in enumerate(panels):
        ax = axes[k // ncol, k % ncol]
        is_nbar = name.startswith("n-bar")
        xs, ys = (smap.nbar_xs, smap.nbar_ys) if is_nbar else (smap.xs, smap.ys)
        ax.pcolormesh(xs, ys, codes, cmap=cmap, norm=norm, shading="nearest")
        _overlay(ax, sc)
        ax.set_title(name, fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_xlabel("x, mm", fontsize=8)
        ax.set_ylabel("y, mm", fontsize=8)
        ax.tick_params(labelsize=7)
    for k in range(len(panels), nrow * ncol):
        axes[k // ncol, k % ncol].axis("off")
    used = set()
    for _, codes in panels:
        used |= {int(c) for c in np.unique(codes)}
    handles: list[Any] = [Patch(facecolor=CAT_STYLE[c][0], edgecolor="k",
                                label=CAT_STYLE[c][1]) for c in Cat if int(c) in used]
    handles += [plt.Line2D([], [], color="#d73027", label="type-2 curve (this mode)"),
                plt.Line2D([], [], color="#4d4d4d", ls="--", label="reach circles (type 1)"),
                Patch(facecolor="none", edgecolor="k", label="page rectangle")]
    fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=8)
    fig.suptitle(f"Stability map, working mode {sc.mode}: where each method fails "
                 f"(pen error vs long-double closed form; tolerance {sc.tol_mm:g} mm)",
                 fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 0.97))
    _save(fig, path)


def chart_approaches(results: Sequence[ApproachResult], tol: float, path: Path) -> None:
    """Item 5 approaches: pen error against distance to each singularity."""
    n = len(results)
    ncol = 2
    nrow = -(-n // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(13, 4.4 * nrow + 0.6), squeeze=False)
    names = list(dict.fromkeys(m for r in results for m in r.errors))
    cmap = plt.get_cmap("tab10")
    styles = {m: (cmap(k % 10), "os^vDP*Xh"[k % 9]) for k, m in enumerate(names)}
    for k, res in enumerate(results):
        ax = axes[k // ncol, k % ncol]
        d = res.approach.deltas
        for m, e in res.errors.items():
            col, mk = styles[m]
            ax.plot(d, np.maximum(e, FLOOR_MM), marker=mk, color=col, lw=1, ms=4, label=m)
            refused = np.isnan(e)
            if refused.any():
                ax.plot(d[refused], np.full(refused.sum(), FLOOR_MM), marker=mk, ls="",
                        mfc="none", color=col, ms=7)
        ax.axhline(tol, color="k", ls="--", lw=0.8)
        ax.axhline(EXACT_MM, color="k", ls=":", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.invert_xaxis()
        ax.grid(True, alpha=0.3)
        where = "" if res.machine == "profile" else f", machine with {res.machine}"
        ax.set_title(f"{res.approach.name}{where} (margin {res.approach.margin_deg[0]:.2g}° → "
                     f"{res.approach.margin_deg[-1]:.2g}°)", fontsize=10)
        ax.set_xlabel("δ: distance parameter to the singularity, mm (log, decreasing →)")
        ax.set_ylabel("pen error, mm (log; hollow at floor = refused)")
    for k in range(n, nrow * ncol):
        axes[k // ncol, k % ncol].axis("off")
    handles = [plt.Line2D([], [], color=styles[m][0], marker=styles[m][1], label=m)
               for m in names]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8)
    fig.suptitle("Approaching each singularity: error growth and refusals "
                 f"(dashed: tolerance {tol:g} mm, dotted: 1e-6 mm)", fontsize=11)
    fig.tight_layout(rect=(0, 0.07, 1, 0.96))
    _save(fig, path)


# ============================================================================ report
@dataclass
class Results:
    """Everything one run measured (the report and the charts read only this)."""

    info: dict[str, str]
    cfg: Config
    scene: Scene
    sets: dict[str, PointSet]
    linear: approx.LinearApprox
    kin: list[MethodRow]
    nbar: list[NbarKinRow]
    examples: list[ExampleRow]
    examples_note: str
    jobs: list[JobRow]
    validation: ValidationCost | None
    steps: list[StepRow]
    smap: StabilityMap
    appr: list[ApproachResult]
    timings: dict[str, float] = field(default_factory=dict)


def _g(x: float, digits: int = 2) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    if math.isinf(x):
        return "∞"
    if x == 0:
        return "0"
    return f"{x:.{digits}g}" if 1e-3 <= abs(x) < 1e5 else f"{x:.{digits - 1}e}"


def _bytes(n: int) -> str:
    if n == 0:
        return "—"
    if n < 1024:
        return f"{n} B"
    return f"{n / 1024:.0f} KiB" if n < 2**20 else f"{n / 2**20:.1f} MiB"


def _pct(x: float) -> str:
    return "—" if math.isnan(x) else f"{100 * x:.0f} %"


def _best(rows: Sequence[MethodRow], direction: str, family: str) -> MethodRow:
    return next(r for r in rows if r.direction == direction and r.family == family)


def _fastest_meeting(rows: Sequence[MethodRow], direction: str, tol: float,
                     exclude: tuple[str, ...], safe: bool = False) -> MethodRow | None:
    """The fastest method that answers every interior point within `tol`; with `safe`, also
    never answers any point of any set with more than `tol` (it refuses instead)."""
    ok = [r for r in rows if r.direction == direction and r.family not in exclude
          and r.errors["interior"].max_mm <= tol and r.errors["interior"].answered >= 0.999
          and (not safe or all(math.isnan(e.max_mm) or e.max_mm <= tol
                               for e in r.errors.values()))]
    return min(ok, key=lambda r: r.ns_per_point) if ok else None


def _approx_sentence(a: MethodRow, c: MethodRow, direction: str, tol: float,
                     safe: bool) -> str:
    cmp = "slower" if a.ns_per_point > c.ns_per_point else "faster"
    ratio = (a.ns_per_point / c.ns_per_point if cmp == "slower"
             else c.ns_per_point / a.ns_per_point)
    n1, n2 = a.errors["near type 1"], a.errors["near type 2"]
    if n1.answered == 0 and n2.answered == 0:
        near = "it refuses every near-singular point of both sets"
    else:
        worst = max(x for x in (n1.max_mm, n2.max_mm) if not math.isnan(x))
        near = (f"near singularities it answers {_pct(n1.answered)} of the type-1 and "
                f"{_pct(n2.answered)} of the type-2 set, with errors up to {_g(worst)} mm"
                + (", far beyond the tolerance and without a warning" if worst > tol
                   else ""))
    what = ("The fastest" if not safe else "The fastest *guarded*") + f" {direction} "
    what += ("approximation that answers every interior point within "
             f"{tol:g} mm" + (" and never answers worse than that anywhere" if safe else ""))
    return (f"  {what} is the {a.name} ({a.ns_per_point:.0f} ns per point, {ratio:.1f}× "
            f"{cmp} than the closed form, interior error {_g(a.errors['interior'].max_mm)} mm, "
            f"{_bytes(a.nbytes)}, built in {_g(a.build_s)} s); {near}.")


def _validation_sentence(res: Results) -> str:
    v = res.validation
    if v is None:
        return "(The validation timing was skipped: the job did not compile.) "
    return (f"On the {v.scene} job the closed-form validation of the quantised steps takes "
            f"{1e3 * v.closed_s:.1f} ms; the n-bar second opinion over {v.poses} poses takes "
            f"{1e3 * v.nbar_s:.0f} ms and differs from it by at most "
            f"{_g(v.disagreement_mm)} mm. ")


def policy_section(res: Results) -> list[str]:
    """"Model no more than a scene needs", with the figures of this run."""
    tol = res.scene.tol_mm
    ci = _best(res.kin, "inverse", "closed form")
    cf = _best(res.kin, "forward", "closed form")
    exact = ("closed form", "bare formulas")
    default_tol = Settings().tolerance
    dflt = min(res.nbar, key=lambda r: abs(math.log10(r.tol / default_tol)))
    us = [r.us_per_pose for r in res.nbar]
    lin = res.linear
    worst_ci = max(ci.errors[s].max_mm for s in ci.errors)
    worst_cf = max(cf.errors[s].max_mm for s in cf.errors)
    lines = [
        "## Model no more than a scene needs",
        "",
        "The job pipeline uses the cheapest model that meets the tolerance, and this run's "
        "figures say which one that is:",
        "",
        f"- **Closed form for the five-bar.** Inverse kinematics take {ci.ns_per_point:.0f} ns "
        f"per point with every check, forward {cf.ns_per_point:.0f} ns; their largest pen "
        f"error over all three sets is {_g(worst_ci)} mm (inverse) and {_g(worst_cf)} mm "
        "(forward) against the long-double evaluation — exact for any tolerance a plotter "
        "can have.",
    ]
    for direction, c in (("inverse", ci), ("forward", cf)):
        picks = [(False, _fastest_meeting(res.kin, direction, tol, exact)),
                 (True, _fastest_meeting(res.kin, direction, tol, exact, safe=True))]
        if all(a is None for _, a in picks):
            lines.append(f"  No approximation of the {direction} kinematics answered every "
                         f"interior point within the {tol:g} mm tolerance.")
        for safe, a in picks:
            if a is not None and not (safe and a is picks[0][1]):
                lines.append(_approx_sentence(a, c, direction, tol, safe))
    ai = _fastest_meeting(res.kin, "inverse", tol, exact)
    af = _fastest_meeting(res.kin, "forward", tol, exact)
    faster = [a for a, c in ((ai, ci), (af, cf)) if a is not None
              and a.ns_per_point < c.ns_per_point]
    lin_pen = _best(res.kin, "inverse", "linear Eq. 25/26").errors["interior"].max_mm
    lines.append(
        f"  The thesis' linear transform (Eq. 25) fitted to this machine's page region by least "
        f"squares gives γ = {math.degrees(lin.gamma):.1f}°, B = {lin.scale:.4g} rad/mm, "
        f"A = ({lin.shift[0]:.4g}, {lin.shift[1]:.4g}) mm, but misses the motor angles by up "
        f"to {lin.max_rad:.2f} rad ({math.degrees(lin.max_rad):.0f}°) on its own fit points: "
        f"{_g(lin_pen)} mm of pen error in the interior. " + (
            "So in this run no approximation is both faster than the closed form and within "
            "the tolerance: in numpy a table lookup (index arithmetic, gathers, the reach "
            "test) costs about as much as the closed form's square roots and arctangents, and "
            "every approximation adds build time, memory, an error that is estimated rather "
            "than proven, and refusals near singularities that need the closed form as a "
            "fallback anyway." if not faster else
            f"The {' and the '.join(a.name for a in faster)} ran faster than the closed form "
            "in this run, but only inside its guard: refused points need the closed form as "
            "a fallback and its error is estimated at build time, not proven; the pipeline "
            "keeps the closed form, exact everywhere with nothing to fall back on.")
        + " The firmware computes no kinematics at all (the host sends steps), so there is "
        "no small-processor case to approximate for either.")
    lines += [
        f"- **n-bar only to validate.** As forward kinematics the general solver needs "
        f"{min(us):.0f}–{max(us):.0f} µs per pose along a raster path over the page "
        f"(tolerances {max(r.tol for r in res.nbar):g} to {min(r.tol for r in res.nbar):g}); "
        f"at its default tolerance {dflt.tol:g} that is {dflt.us_per_pose:.1f} µs, "
        f"{1e3 * dflt.us_per_pose / cf.ns_per_point:.0f}× the closed form's time, and its "
        f"answers agree with the closed form to {_g(dflt.raster_max_mm)} mm there. "
        + _validation_sentence(res)
        + "So the pipeline computes with the closed form and runs the n-bar solver only as an "
        "independent check (dry-run report), never in the compile loop.",
    ]
    jr = [r for r in res.jobs if abs(r.tol - tol) < 1e-12 and not r.error]
    parts = [f"{r.scene}: {r.draw_segments} adaptive draw segments against "
             f"{r.uniform_segments} at a fixed spacing of {_g(r.uniform_h_mm)} mm "
             f"({r.uniform_segments / max(r.draw_segments, 1):.1f}×)" for r in jr]
    lines.append(
        f"- **Adaptive segmentation instead of fixed point counts.** At the profile's "
        f"tolerance of {tol:g} mm — " + "; ".join(parts) + ". A fixed spacing has to be fine "
        "enough for the worst place of the drawing (where a curve bends most, or where the "
        "forward map bends most, close to a singularity) and spends that density everywhere; "
        "the adaptive flattening and joint-space split are dense only where the error needs "
        "it. Where a drawing is made of elements shorter than the spacing anyway, one point "
        "per element is already enough and both give the same count.")
    stepr = [r for r in res.steps if r.microsteps == res.scene.profile.motors.microsteps
             and r.gear == res.scene.profile.motors.gear_ratio]
    if stepr:
        s = stepr[0]
        below = sorted({r.tol for r in res.jobs if r.tol < s.quantum_max_mm}, reverse=True)
        lines.append(
            f"- **No tolerance below the step quantum.** With the profile's drive "
            f"({s.microsteps} microsteps, gear {s.gear:g}) one step moves the pen by up to "
            f"{_g(s.quantum_max_mm)} mm on the page region (median "
            f"{_g(s.quantum_median_mm)} mm). " + (
                f"Tolerances below that ({', '.join(f'{t:g}' for t in below)} mm) "
                "multiply segments without lowering the measured deviation much: the "
                "quantised steps set the floor (chart 3, right)." if below else ""))
    return lines


def write_report(res: Results, out_dir: Path, img_rel: str = "img") -> Path:
    """docs/performance.md from `res` (every number in it comes from this run)."""
    sc = res.scene
    info = res.info
    fb = sc.fb
    prof = sc.profile
    L: list[str] = [
        "# Performance: speed against accuracy, and stability where methods fail",
        "",
        "<!-- generated by `python -m benchmarks.speed_accuracy`; do not edit by hand -->",
        "",
        f"Generated by `python -m benchmarks.speed_accuracy` on {info['date']} in "
        f"{res.timings.get('total', math.nan):.0f} s"
        + (" (**--quick smoke-test sizes: not the documented run**)" if res.cfg.quick_run
           else "") + ".",
        "",
        "| machine | |",
        "|---|---|",
        f"| CPU | {info['cpu']} |",
        f"| cores | {info['cores']} |",
        f"| OS | {info['os']} |",
        f"| Python / numpy / scipy / matplotlib | {info['python']} / {info['numpy']} / "
        f"{info['scipy']} / {info['matplotlib']} |",
        f"| load average (1, 5, 15 min) at start / end | {info['load']} / "
        f"{info.get('load_end', '—')} (other work on the machine slows every timing alike)"
        " |",
        "",
        f"Machine profile: `{Path(prof.source).name}` — a1 = {fb.a1:g}, b1 = {fb.b1:g}, "
        f"a2 = {fb.a2:g}, b2 = {fb.b2:g}, w = {fb.w:g} mm; working mode {sc.mode}, page "
        f"assembly {sc.assembly}; page rectangle {sc.page.rect.width:.1f} × "
        f"{sc.page.rect.height:.1f} mm at ({sc.page.rect.x0:.1f}, {sc.page.rect.y0:.1f}); "
        f"tolerance {sc.tol_mm:g} mm. Times are medians of {res.cfg.repeats} runs after a "
        "warm-up, all methods side by side in this one run, single-threaded numpy.",
        "",
        *policy_section(res),
        "",
        "## 1. Five-bar kinematics: time per point against error",
        "",
        f"![time against error]({img_rel}/perf_kinematics.png)",
        "",
        "Sets (each in the page's working mode and assembly): **interior** — "
        f"{res.sets['interior'].points.shape[0]} random points of the page region whose three "
        f"singularity margins are all ≥ {WELL_DEG:g}°; **near type 1** — "
        f"{res.sets['near type 1'].points.shape[0]} points of the workspace with an arm within "
        f"{NEAR_DEG:g}° of stretched or folded; **near type 2** — "
        f"{res.sets['near type 2'].points.shape[0]} points with the floating links within "
        f"{NEAR_DEG:g}° of collinear. Error = pen position error in mm against the same "
        "closed-form formulas evaluated in long double (64-bit mantissa); an inverse answer θ̂ "
        "is scored by where it puts the pen, |FK(θ̂) − P|, so angle errors are weighed by the "
        "machine's sensitivity. *answered* = share of the set not refused. Time = ns per "
        f"point for {res.cfg.n_time} interior points. Tables and tiles cover the workspace "
        "box (inverse) or the joint-limit box (forward); the linear fits use the page region's "
        f"{sc.region_pts.shape[0]} grid nodes.",
        "",
    ]
    for direction in ("inverse", "forward"):
        L += [f"**{direction.capitalize()}**" + (" — max pen error in mm, the max angle error "
                                                 "in brackets" if direction == "inverse"
                                                 else " — max pen error in mm"), ""]
        L.append("| method | ns/point | build s | memory | interior max | interior median | "
                 "answered | near type 1 max | answered | near type 2 max | answered |")
        L.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for r in res.kin:
            if r.direction != direction:
                continue
            e = r.errors

            def cell(name: str, e: dict[str, SetError] = e, inv: bool = direction == "inverse"
                     ) -> str:
                txt = _g(e[name].max_mm)
                if inv and not math.isnan(e[name].max_rad):
                    txt += f" ({_g(e[name].max_rad)} rad)"
                return txt

            L.append(
                f"| {r.name} | {r.ns_per_point:.0f} | {_g(r.build_s)} | {_bytes(r.nbytes)} | "
                f"{cell('interior')} | {_g(e['interior'].median_mm)} | "
                f"{_pct(e['interior'].answered)} | {cell('near type 1')} | "
                f"{_pct(e['near type 1'].answered)} | {cell('near type 2')} | "
                f"{_pct(e['near type 2'].answered)} |")
        if direction == "forward":
            for nr in res.nbar:
                ne = nr.errors
                L.append(
                    f"| n-bar solver, tol {nr.tol:g} | {1e3 * nr.us_per_pose:.0f} | — | — | "
                    f"{_g(ne['interior'].max_mm)} | {_g(ne['interior'].median_mm)} | "
                    f"{_pct(ne['interior'].answered)} | {_g(ne['near type 1'].max_mm)} | "
                    f"{_pct(ne['near type 1'].answered)} | {_g(ne['near type 2'].max_mm)} | "
                    f"{_pct(ne['near type 2'].answered)} |")
        L.append("")
    L += [
        "n-bar rows: time per pose of one continuation along a raster over the page ("
        f"{res.cfg.raster_lines} lines; mean Newton iterations per pose "
        + ", ".join(f"{r.iterations:.2f} at {r.tol:g}" for r in res.nbar) + "); errors from "
        f"{res.cfg.nbar_points} points per set, each reached by one continuation step of "
        f"{MAX_STEP_RAD:g} rad (the largest joint step of a job segment) from an assembled "
        "pose. Limits reported (not answered): "
        + "; ".join(f"tol {r.tol:g}: " + ", ".join(f"{k} {v}" for k, v in r.limits.items())
                    for r in res.nbar)
        + ". Branch flips: "
        + ", ".join(f"{sum(r.flips.values())} at {r.tol:g}" for r in res.nbar) + ".",
        "",
        f"Linear fits on the page region (angle residual on the fit points): Eq. 25 "
        f"γ = {math.degrees(res.linear.gamma):.2f}°, B = {res.linear.scale:.5g} rad/mm, "
        f"A = ({res.linear.shift[0]:.4g}, {res.linear.shift[1]:.4g}) mm, RMS "
        f"{res.linear.rms_rad:.3g} rad, max {res.linear.max_rad:.3g} rad. The thesis read "
        "γ = 135° off its Fig. 25 for its own machine; θ2 is converted to the thesis' "
        "interior angle π − θ2 for the fit.",
        "",
    ]
    # ---- 2
    L += ["## 2. n-bar solver: tolerance and input step against time and constraint drift",
          "", f"![n-bar examples]({img_rel}/perf_nbar.png)", "",
          "Each paper example (configs/mechanisms) swept over the same input range with the "
          "file's input step × factor (steps adjusted), at each tolerance: median wall time "
          f"of `sweep` ({res.cfg.ex_runs} runs), Newton iterations per step, the largest "
          "residual of the exact equations over the run (constraint drift, relative to the "
          f"mechanism's size) and the tracer's largest deviation from the run at tolerance "
          f"{min(res.cfg.ex_tols):g} with the same step. {res.examples_note}, same inputs, "
          f"median of {res.cfg.ex_base_runs} runs; its iterations column is function "
          "evaluations per step.", ""]
    L.append("| example | step × | steps | solver | tol | ms | it/step | max residual | "
             "tracer dev | limits/fails |")
    L.append("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|")
    for er in res.examples:
        L.append(f"| {er.example} | {er.factor:g} | {er.steps} | {er.solver} | "
                 f"{'—' if math.isnan(er.tol) else f'{er.tol:g}'} | {_g(er.ms, 3)} | "
                 f"{er.iterations:.2f} | {_g(er.residual)} | {_g(er.tracer_dev)} | "
                 f"{er.limits if not er.error else '**raised** ' + er.error} |")
    raised = [er for er in res.examples if er.error]
    if raised:
        L += ["", f"**{len(raised)} run(s) raised an exception** instead of a documented "
              "outcome: " + "; ".join(f"{r.example}, step ×{r.factor:g}, tol {r.tol:g}: "
                                      f"`{r.error}`" for r in raised) + "."]
    L.append("")
    # ---- 3
    L += ["## 3. Job compilation: tolerance against segments, time and deviation", "",
          f"![jobs]({img_rel}/perf_jobs.png)", "",
          "Scenes fitted to the page (`--fit`): " + ", ".join(
              f"*{k}* ({SCENE_NOTES[k]})" for k in res.cfg.job_scenes)
          + ". Compile = read → place → flatten → order → inverse kinematics with checks → "
          "adaptive joint-space "
          "segmentation → travel → steps → plan (median of "
          f"{res.cfg.job_repeats}). Deviations with 16 samples per segment through the "
          "closed-form forward kinematics, measured to the requested curves: from the ideal "
          "joint targets (what the tolerance bounds) and from the quantised steps (what the "
          "machine draws). *fixed spacing*: the same drawing cut into equal pieces of one "
          "spacing for every element (a fixed point count per length) — the segments needed, "
          "the largest spacing that meets the tolerance, and its deviation measured the same "
          "way.", ""]
    L.append("| scene | tol mm | segments | draw | compile ms | plot s | dev ideal mm | "
             "dev quantised mm | step quantum mm | fixed spacing: draw segments | spacing mm "
             "| its dev mm |")
    L.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for jb in res.jobs:
        if jb.error:
            L.append(f"| {jb.scene} | {jb.tol:g} | **raised** `{jb.error}` |" + " |" * 9)
            continue
        L.append(f"| {jb.scene} | {jb.tol:g} | {jb.segments} | {jb.draw_segments} | "
                 f"{1e3 * jb.compile_s:.0f} | {jb.plot_s:.1f} | {_g(jb.ideal_max_mm, 3)} | "
                 f"{_g(jb.quant_max_mm, 3)} | {_g(jb.quantum_mm, 3)} | {jb.uniform_segments} | "
                 f"{_g(jb.uniform_h_mm, 3)} | {_g(jb.uniform_dev_mm, 3)} |")
    over = [jb for jb in res.jobs if not jb.error and jb.ideal_max_mm > jb.tol]
    if over:
        held = all(jb.quant_max_mm <= jb.tol + jb.quantum_mm for jb in over)
        offs = [jb for jb in over if jb.off_chord_mm > jb.tol]
        L += ["", f"*dev ideal* exceeds the tolerance in {len(over)} row(s) ("
              + ", ".join(f"{jb.scene} {jb.tol:g} mm" for jb in over) + "). "
              + (f"In {len(offs)} of them a draw segment starts off its own chord by more "
                 "than the tolerance (up to "
                 f"{_g(max(jb.off_chord_mm for jb in offs))} mm): the compiler drops targets "
                 "that move no motor after quantisation (segments shorter than a step), so "
                 "the ideal joint path between the remaining targets is no longer the one "
                 "the tolerance bound covers. " if offs else "")
              + ("What the machine draws — *dev quantised* — stays within tolerance + step "
                 "quantum in every one of them." if held else
                 "**The quantised deviation exceeds tolerance + step quantum in some of "
                 "them.**")]
    v = res.validation
    if v is not None:
        L += ["", f"Validation of the {v.scene} job at the profile's tolerance: closed form "
              f"{1e3 * v.closed_s:.1f} ms (max deviation {_g(v.closed_max_mm, 3)} mm); n-bar "
              f"second opinion {1e3 * v.nbar_s:.0f} ms over {v.poses} poses (max deviation "
              f"{_g(v.nbar_max_mm, 3)} mm, differs from the closed form by "
              f"{_g(v.disagreement_mm)} mm).", ""]
    else:
        L += ["", "The validation timing was skipped: the job did not compile (see the table)."]
    # ---- 4
    cap = firmware_rate_cap()
    L += ["## 4. The physical limit: step resolution against the step quantum", "",
          f"![steps]({img_rel}/perf_steps.png)", "",
          "Step quantum = the largest pen displacement from one step of either motor in "
          "either direction (exact forward kinematics, `kinematics.analysis.step_quantum`), "
          f"over the {sc.region_pts.shape[0]} grid nodes of the page region (sub-sampled). "
          f"Step rate needed at the profile's max joint speed "
          f"({prof.motion.max_joint_rad_s:g} rad/s) against the firmware's default cap "
          f"(`DEF_MAX_RATE` = {cap:.0f} steps/s, firmware/fivebar/config.h), and the joint "
          "speed that cap allows.", ""]
    L.append("| microsteps | gear | steps/rev | quantum max mm | quantum median mm | "
             "steps/s at max joint speed | joint speed at the cap, rad/s |")
    L.append("|---:|---:|---:|---:|---:|---:|---:|")
    for st in res.steps:
        flag = " (over the cap)" if st.rate_needed > cap else ""
        L.append(f"| {st.microsteps} | {st.gear:g} | {st.steps_per_rev:.0f} | "
                 f"{_g(st.quantum_max_mm, 3)} | {_g(st.quantum_median_mm, 3)} | "
                 f"{st.rate_needed:.0f}{flag} | {st.joint_speed_cap:.3g} |")
    L.append("")
    # ---- 5
    L += ["## 5. Stability: where each method fails", "",
          f"![stability map]({img_rel}/perf_stability.png)", "",
          f"Grid of {res.cfg.map_pitch_mm:g} mm over the workspace box in working mode "
          f"{sc.mode}. Inverse maps are asked at every node; forward maps at the closed-form "
          "angles of the nodes in the page's assembly (the other assembly is grey: given "
          "angles and one assembly, its points are not asked). Pen error against the "
          f"long-double closed form: ≤ {EXACT_MM:g} mm, ≤ tolerance, or more. The n-bar "
          f"solver runs one continuation step of {MAX_STEP_RAD:g} rad into each node (every "
          f"{res.cfg.nbar_map_stride}nd node) at its default tolerance {res.smap.nbar_tol:g}. "
          "Counts per outcome:", ""]
    counts = res.smap.counts()
    used = [c for c in Cat if any(cc[c] for cc in counts.values())]
    L.append("| method | " + " | ".join(CAT_STYLE[c][1] for c in used) + " |")
    L.append("|---|" + "---:|" * len(used))
    for m, cc in counts.items():
        L.append(f"| {m} | " + " | ".join(str(cc[c]) for c in used) + " |")
    d0 = res.appr[0].approach.deltas if res.appr else np.array([math.nan])
    L += ["", f"![approaches]({img_rel}/perf_approach.png)", "",
          f"Approaching each singularity, δ from {d0[0]:g} mm down to {d0[-1]:g} mm (type 1: "
          "distance of P inside the reach circle; Mode 1a: how much shorter |R1R2| is than "
          "b1 + b2; Mode 1b: the scale of the elbows' distance). Per method: the largest pen "
          "error on the way (∞: the answer's angles put the pen nowhere — the floating links "
          "cannot meet), the smallest δ still within 1e-6 mm, how many poses were answered, "
          "and what it does exactly at the singularity (δ = 0) and just past it (δ = −1e-9 "
          "mm: past a reach circle the point is out of reach, past Mode 1a the links cannot "
          "meet, past Mode 1b the elbows have crossed). The n-bar solver follows each "
          "approach by continuation; at and past the singularity it is judged by continuity "
          "(distance from the closed-form point of the last approach pose, and the assembly "
          "sign it ends in)." + (
              " Mode 1a needs b1 + b2 < a1 + a2 + w, which the profile's machine does not "
              "have; it is shown on the same machine with shorter floating links."
              if any(ar.machine != "profile" for ar in res.appr) else "")
          if res.appr else "No approach found.", ""]
    L.append("| approach | method | max error mm | error ≤ 1e-6 mm down to δ mm | answered | "
             "at δ = 0 | past it |")
    L.append("|---|---|---:|---:|---:|---|---|")
    for ar in res.appr:
        d = ar.approach.deltas
        where = "" if ar.machine == "profile" else f" ({ar.machine})"
        for meth, ev in ar.errors.items():
            ok = ~np.isnan(ev)
            good = ok & (ev <= EXACT_MM)
            down = _g(float(d[good].min())) if good.any() else "never"
            L.append(f"| {ar.approach.name}{where} | {meth} | "
                     f"{_g(float(np.nanmax(ev))) if ok.any() else '—'} | {down} | "
                     f"{int(ok.sum())}/{ev.size} | {ar.at.get(meth, '—')} | "
                     f"{ar.past.get(meth, '—')} |")
    L += ["", "### Failure modes and the tests that hold them", "",
          "`tests/test_stability.py` asserts the documented behaviour at each place this "
          "run found a failure mode (the test names are in brackets):", "",
          *FAILURE_MODES, "",
          "## Reproduce", "",
          "    python -m benchmarks.speed_accuracy          # this page and docs/img/perf_*.png",
          "    python -m benchmarks.speed_accuracy --quick --out-dir /tmp/perf   # smoke test",
          "", "Section timings of this run: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in res.timings.items()) + "."]
    out = out_dir / "performance.md"
    out.write_text("\n".join(L) + "\n")
    return out


#: Failure modes found by the stability map and approaches, with their tests. The wording is
#: qualitative on purpose; the figures are in the tables above.
FAILURE_MODES: tuple[str, ...] = (
    "- **Closed-form inverse at a reach circle (type 1).** θ has a square-root branch point "
    "there; the factored discriminant keeps the answer exact to rounding up to the circle, "
    "and past it the point is refused (`UnreachableError` with the excess in mm) "
    "[`test_closed_inverse_stays_exact_up_to_a_reach_circle_then_refuses`].",
    "- **Closed-form forward near coincident elbows (Mode 1b, b1 = b2).** The error grows "
    "like 1/δ and passes 1e-6 mm close to the coincidence — bounded by the problem's own "
    "conditioning (one ulp of the motor angles moves the exact P as much); exactly "
    "coincident elbows raise `DegenerateError` "
    "[`test_closed_forward_near_coincident_elbows_errs_only_as_the_problem_does`; "
    "`tests/test_fivebar.py::test_coincident_elbows_b1_equals_b2`].",
    "- **Closed-form forward at Mode 1a** (machine with short floating links). Error grows "
    "like 1/√δ within the conditioning bound; past it the links cannot meet: "
    "`UnreachableError` [`test_closed_forward_stays_exact_up_to_mode_1a_then_refuses`].",
    "- **n-bar solver towards a reach circle.** No singularity of the forward problem: "
    "bounded by its residual tolerance [`test_nbar_approaching_a_reach_circle_stays_bounded`].",
    "- **n-bar solver towards Mode 1a.** A residual ε moves P by ~√(ε·L) there, so its "
    "error grows towards √tolerance × size (bounded), then it reports a motion limit at the "
    "singular Jacobian and never answers past it "
    "[`test_nbar_approaching_mode_1a_has_bounded_error_then_reports_the_limit`].",
    "- **n-bar solver: false motion limit next to coincident elbows.** A joint step of the "
    "size a job segment may take that passes very close to R1 = R2 makes P swing round the "
    "elbows faster than the continuity guard accepts: the solver reports a motion limit "
    "(\"no continuous solution\") where the closed form answers — a refusal, never a wrong "
    "point (table of section 1: *limits reported*) "
    "[`test_nbar_step_passing_coincident_elbows_refuses_rather_than_answers_wrong`].",
    "- **n-bar solver exactly through coincident elbows.** P is free on a circle there; the "
    "continuation keeps it continuous, which lands on the other assembly sign past the "
    "coincidence (a branch change the continuity guard cannot see), while the closed form "
    "in the job's assembly jumps to the far side; validation against the closed form "
    "reports the disagreement "
    "[`test_nbar_through_coincident_elbows_keeps_p_continuous_and_validation_sees_it`].",
    "- **Linear approximation (Eqs. 25–26).** Bounded by its fit residual, which is far above "
    "a plotter's tolerance over a page; refuses outside its fit box and out of reach "
    "[`test_linear_approximation_refuses_outside_and_misses_the_tolerance_inside`].",
    "- **Lookup tables at a reach circle.** Cells with a node out of reach are refused; next "
    "to the circle the error grows (square-root branch point) and the build-time estimate "
    "tracks it; the margin guard refuses the band "
    "[`test_table_refuses_cells_at_a_reach_circle_and_estimates_the_error_next_to_it`].",
    "- **Lookup tables near type 2.** Any angle error moves the pen far there: an unguarded "
    "inverse table answers with pen errors far beyond its sampled cell estimate (a point "
    "singularity escapes sampling — the *error > tolerance* cells of the map); with the "
    "profile's singularity margins as guard those points are refused. Forward tables refuse "
    "cells past Mode 1a (nodes without a solution) "
    "[`test_table_near_type_2_escapes_its_estimate_and_the_margin_guard_refuses`].",
)


# ============================================================================ main
def run(cfg: Config, out_dir: Path, profile: Profile | None = None) -> Results:
    """Run every item, draw the charts into out_dir/img and write out_dir/performance.md."""
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    info = machine_info()
    img = out_dir / "img"
    img.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(2026)

    def lap(name: str, t0: float) -> None:
        timings[name] = time.perf_counter() - t0
        print(f"  {name}: {timings[name]:.1f} s", flush=True)

    t0 = time.perf_counter()
    sc = make_scene(profile)
    sets = sample_sets(sc, cfg.n_near, rng)
    lap("setup", t0)
    t0 = time.perf_counter()
    methods = build_methods(sc, cfg)
    kin = kinematics_rows(sc, cfg, sets, methods)
    nbar = nbar_kinematics_rows(sc, cfg, sets)
    lin = approx.fit_linear(sc.fb, sc.mode, sc.region_pts, "similarity")
    chart_tradeoff(kin, nbar, sc.tol_mm, img / "perf_kinematics.png")
    lap("1 kinematics", t0)
    t0 = time.perf_counter()
    examples, note = example_rows(cfg)
    chart_examples(examples, img / "perf_nbar.png")
    lap("2 n-bar examples", t0)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        strokes = Path(tmp) / "strokes.svg"
        strokes.write_text(make_svg(cfg.random_paths))
        every = {"text": ROOT / "examples" / "fivebar_text.svg",
                 "shapes": ROOT / "examples" / "simple.svg", "random strokes": strokes}
        scenes = {k: every[k] for k in cfg.job_scenes}
        jobs = job_rows(sc, cfg, scenes)
        first = cfg.job_scenes[0]
        vcost = validation_cost(sc, scenes[first], first, cfg.job_repeats)
    chart_jobs(jobs, img / "perf_jobs.png")
    lap("3 jobs", t0)
    t0 = time.perf_counter()
    steps = step_rows(sc, cfg, rng)
    chart_steps(sc, steps, img / "perf_steps.png", max(cfg.map_pitch_mm, 1.0))
    lap("4 steps", t0)
    t0 = time.perf_counter()
    smap = stability_map(sc, cfg)
    appr = run_approaches(sc, cfg)
    var = variant_scene(sc)
    if var is not None:
        appr += run_approaches(var, cfg, ("type 2: Mode 1a",),
                               f"b1 = b2 = {var.fb.b1:g} mm")
    chart_stability(sc, smap, img / "perf_stability.png")
    chart_approaches(appr, sc.tol_mm, img / "perf_approach.png")
    lap("5 stability", t0)
    timings["total"] = time.perf_counter() - t_start
    load = os.getloadavg() if hasattr(os, "getloadavg") else (math.nan,) * 3
    info["load_end"] = f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"
    res = Results(info, cfg, sc, sets, lin, kin, nbar, examples, note, jobs, vcost, steps,
                  smap, appr, timings)
    write_report(res, out_dir)
    return res


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", type=Path, default=ROOT / "docs",
                    help="where performance.md and img/ go (default: docs/)")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (smoke test)")
    args = ap.parse_args(argv)
    cfg = Config.quick() if args.quick else Config.full()
    print(f"speed/accuracy benchmark ({'quick' if args.quick else 'full'}) → {args.out_dir}")
    res = run(cfg, args.out_dir)
    print(f"wrote {args.out_dir / 'performance.md'} in {res.timings['total']:.0f} s")


if __name__ == "__main__":
    main()

