"""The compiled job: from a drawing file to checked, timed, quantised joint targets.

`compile_job(path, profile, options)` runs the whole pipeline:

    read (SVG / G-code) → place (layout) → flatten curves (tol_f = tol/2) → order and join
    paths → [--mode auto when no single mode clears every check: working mode per path,
    `_plan_modes`] → inverse kinematics + checks on every vertex → refine chords in joint
    space (interpolation budget tol_i, `toolpath.segment`) → pen-up travel (checked
    joint-space moves, Cartesian fallback; planned pen-up moves for working-mode changes) →
    absolute steps (quantised once) → plan durations (`planner`: speed-up and slow-down cut
    into pieces on the same joint-space lines, the firmware's rate staircase within the joint
    acceleration and junction-jump limits at every boundary) → validate: forward kinematics
    of the *quantised* steps, including the joint-space interpolation between them, against
    the requested curves.

Tolerance budget (one `tol`, default from the profile): a curve is flattened so every chord is
within tol_f = tol/2 of it; each chord is refined so the joint-interpolated pen path stays
within tol_i of the chord: tol_i = tol − tol_f for chords of curves, tol for straight input
lines (nothing was flattened), tol − gap/2 for the short pen-down bridge that joins two paths
whose ends are closer than tol. By the triangle inequality every pen point is within tol of
the requested path; rounding to whole steps adds at most one step quantum (reported).

`Job` holds everything streaming, resuming and the reports need, indexed per target (row 0 =
the homed pose, absolute steps (0, 0)) and per segment k (target k → k+1).
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fivebar_host import planner, protocol, steps
from fivebar_host.config import Profile
from fivebar_host.errors import InputError, JobError, Where
from fivebar_host.toolpath import layout, order
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import (
    LINE,
    Drawing,
    Polylines,
    flatten,
    nearest_distance,
)
from fivebar_host.toolpath.segment import (
    REASON_KEY,
    CheckFailedError,
    Intervals,
    PoseChecker,
    joint_moves,
    refine,
    wrap_to_limits,
)
from fivebar_host.toolpath.svg import read_svg
from kinematics.fivebar import WORKING_MODES, FiveBar
from kinematics.modes import plan_joint_move, plan_working_modes
from kinematics.workspace import NoSafeRegionError, point_safety

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

#: Order in which `--mode auto` tries the working modes (ties keep this order).
AUTO_ORDER = ("+-", "-+", "++", "--")
#: Joint-space step cap per segment (rad): keeps the planner's rate staircase fine.
MAX_STEP_RAD = 0.05
#: Timing (see `fivebar_host.planner`): the continuous profile plans with this share of the
#: joint acceleration limit and of the junction jump for direction changes; the rest (and a
#: corner cap from the remaining acceleration) absorbs the staircase the firmware runs.
PLAN_ACCEL_SHARE = 0.75
PLAN_JUMP_SHARE = 0.5
#: Speed-up and slow-down parts are cut into pieces whose planned speed changes by at most
#: this share of the junction jump from one piece to the next, and of at least this many
#: steps (rounding a shorter piece to whole steps would shake its rate too much).
PLAN_PIECE_JUMP_SHARE = 0.6
PLAN_MIN_PIECE_STEPS = 3
#: Interpolation tolerance for the Cartesian fallback of pen-up travel, mm.
TRAVEL_TOL_MM = 1.0
#: Largest spacing (mm) of the pen points at which `--mode auto` tests the working modes when
#: it plans working-mode changes (every chord is sampled at least this finely).
MODE_SAMPLE_MM = 0.5
GCODE_SUFFIXES = {".gcode", ".nc", ".ngc", ".gc", ".g", ".tap", ".cnc"}


@dataclass(frozen=True)
class CompileOptions:
    """What the command line can change (None: the profile's value)."""

    mode: str | None = None  # "++", "+-", "-+", "--", "auto"
    tolerance_mm: float | None = None
    origin_mm: tuple[float, float] | None = None
    scale: float | None = None
    rotate_deg: float = 0.0
    fit: bool = False
    layers: tuple[str, ...] = ()
    keep_order: bool = False
    validate: bool = True
    validation_samples: int = 4


@dataclass(frozen=True)
class PathStats:
    """Per job path (in drawing order): where it came from and how well it is drawn."""

    source: IntArray  # (P,) index of the first source element of the path
    reversed: BoolArray  # (P,)
    first_seg: IntArray  # (P,) first draw segment
    end_seg: IntArray  # (P,) one past the last draw segment
    max_dev_mm: FloatArray  # (P,) from the quantised steps (validation), NaN if not validated
    mean_dev_mm: FloatArray


@dataclass(frozen=True)
class ModeChange:
    """A pen-up change of working mode compiled into the job (thesis Sec. 7.2), planned by
    `kinematics.modes.plan_working_modes` (or `plan_joint_move` for a move home): travel
    segments `first_seg` … `end_seg` − 1, laser off, drive the arm(s) whose working-mode sign
    changes through their type-1 singularity (stretched or folded) on the way into job path
    `path` (= `Job.n_paths`: the park move back to the homed pose). Measured on the executed
    move (quantised steps, sampled ≤ 0.5° apart): where each arm crosses (arm, "stretched" /
    "folded", x, y mm) and the smallest type-2 margin."""

    from_mode: str
    to_mode: str
    path: int
    first_seg: int
    end_seg: int
    lift_mm: tuple[float, float]
    land_mm: tuple[float, float]
    crossings: tuple[tuple[int, str, float, float], ...]
    min_type2_rad: float
    duration_s: float

    def describe(self, n_paths: int) -> str:
        """One line for the dry-run report."""
        into = "back to the homed pose" if self.path >= n_paths else f"into path #{self.path}"
        how = "; ".join(f"arm {a} {k} at ({x:.1f}, {y:.1f}) mm"
                        for a, k, x, y in self.crossings) or "no arm crossing"
        return (f"{self.from_mode} → {self.to_mode} {into}: pen up at ({self.lift_mm[0]:.1f}, "
                f"{self.lift_mm[1]:.1f}) mm, {how}, pen down at ({self.land_mm[0]:.1f}, "
                f"{self.land_mm[1]:.1f}) mm; segments {self.first_seg}–{self.end_seg - 1} "
                f"(laser off), {self.duration_s:.2f} s, type-2 margin ≥ "
                f"{math.degrees(self.min_type2_rad):.1f}°")


@dataclass(frozen=True)
class Job:
    """A compiled job (see module doc). Per target (T+1 rows; row 0 = homed pose):
    `points_mm`, `angles_rad`, `steps` (absolute, int64). Per segment (T rows, target k →
    k+1): `draw`, `power` (0–255, 0 on travel), `path` (job path the segment draws or travels
    to; P for the final park move), `source` (source element index, −1 on travel),
    `source_line` (0 if unknown), `duration_us` (int64), `length_mm` (requested pen path)."""

    file: str
    mode: str
    assembly: int
    tolerance_mm: float
    flatten_tol_mm: float
    placement: layout.Placement
    drawing: Drawing
    steps_per_rev: float
    home_rad: tuple[float, float]
    points_mm: FloatArray
    angles_rad: FloatArray
    steps: IntArray
    draw: BoolArray
    power: NDArray[np.uint8]
    path: IntArray
    source: IntArray
    source_line: IntArray
    duration_us: IntArray
    length_mm: FloatArray
    paths: PathStats
    min_margin_rad: FloatArray  # (3,) smallest margins on targets and samples (draw+travel)
    step_quantum_mm: float
    travel_before_mm: float
    travel_after_mm: float
    joined: int
    notes: list[str] = field(default_factory=list)
    # validation data (requested geometry of each draw segment)
    seg_prim: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    seg_tlo: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_thi: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_rev: BoolArray = field(default_factory=lambda: np.zeros(0, bool))
    seg_sa: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_sb: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_ca: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    seg_cb: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    max_dev_mm: float = math.nan
    mean_dev_mm: float = math.nan
    ideal_max_dev_mm: float = math.nan
    # working modes: per job path, at the homed pose, and the pen-up changes between them
    path_modes: tuple[str, ...] = ()
    home_mode: str = ""
    mode_changes: tuple[ModeChange, ...] = ()

    # ------------------------------------------------------------------ derived
    @property
    def n_segments(self) -> int:
        return int(self.draw.shape[0])

    @property
    def relative_steps(self) -> IntArray:
        """Per-segment step differences (T, 2): their running sum is `steps[1:]` exactly."""
        return steps.relative_steps(self.steps)

    @property
    def total_time_s(self) -> float:
        return float(self.duration_us.sum()) * 1e-6

    @property
    def draw_length_mm(self) -> float:
        return float(self.length_mm[self.draw].sum())

    @property
    def travel_length_mm(self) -> float:
        return float(self.length_mm[~self.draw].sum())

    @property
    def n_paths(self) -> int:
        return int(self.paths.source.shape[0])

    def rel_or_abs(self, relative: bool) -> IntArray:
        """Per-segment step words: absolute targets `steps[1:]` or relative moves."""
        return self.relative_steps if relative else self.steps[1:]

    def executed_points(self, fb: FiveBar, samples: int = 4) -> FloatArray:
        """Pen positions along the whole job from the quantised steps, `samples` per segment
        plus the final target (forward kinematics of the joint-space interpolation)."""
        th = steps.step_angles(self.steps, self.home_rad, self.steps_per_rev)
        s = np.arange(samples) / samples
        dth = np.diff(th, axis=0)
        q = (th[:-1, None, :] + s[None, :, None] * dth[:, None, :]).reshape(-1, 2)
        q = np.concatenate((q, th[-1:]))
        return fb.forward_batch(q, "+" if self.assembly > 0 else "-").points


@dataclass(frozen=True)
class _Chords:
    """The ordered, joined polylines in machine mm with per-chord provenance."""

    pts: FloatArray  # (M, 2)
    offsets: IntArray  # (P+1,)
    vert_prim: IntArray  # (M,) primitive the vertex lies on (for messages)
    chord_from: IntArray  # (C,) vertex index a of chord a → a+1
    prim: IntArray  # (C,) primitive, −1 for a join bridge
    tlo: FloatArray
    thi: FloatArray
    rev: BoolArray
    tol_i: FloatArray
    path_of_chord: IntArray  # (C,) job path
    path_source: IntArray  # (P,) first source element
    path_reversed: BoolArray
    power: FloatArray  # (P,) fraction
    feed: FloatArray  # (P,) mm/s or NaN
    joined: int
    travel_before: float
    travel_after: float


def read_drawing(path: str | Path, layers: tuple[str, ...] = ()) -> Drawing:
    """Read an SVG or G-code file, chosen by suffix (or by content when unknown)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".svg":
        return read_svg(p, layers or None)
    if suffix in GCODE_SUFFIXES:
        if layers:
            raise InputError("--layer applies to SVG files only", str(p))
        return read_gcode(p)
    try:
        head = p.read_bytes()[:512].lstrip()
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", str(p)) from e
    if head.startswith((b"<?xml", b"<svg", b"<!--", b"<!DOCTYPE")):
        return read_svg(p, layers or None)
    return read_gcode(p)


def _where(job_file: str, drawing: Drawing, pl: layout.Placement, point: tuple[float, float],
           prim: int, what: str = "path") -> Where:
    """Where for a failing point on primitive `prim` (−1: unknown)."""
    pm = np.array(point, dtype=np.float64)
    dxy: tuple[float, float] | None = None
    mxy: tuple[float, float] | None = None
    if np.all(np.isfinite(pm)):
        d = drawing.to_file_frame(pl.to_drawing(pm.reshape(1, 2)))[0]
        dxy = (float(d[0]), float(d[1]))
        mxy = (float(pm[0]), float(pm[1]))
    if prim < 0:
        return Where(file=job_file, drawing_xy=dxy, machine_xy=mxy, what=what)
    src = drawing.sources[int(drawing.stroke_source[drawing.stroke[prim]])]
    return Where(file=job_file, path_index=src.index, path_id=src.ident,
                 source_line=int(drawing.line[prim]) or src.line, drawing_xy=dxy,
                 machine_xy=mxy, what=what)


def _prepare_chords(drawing: Drawing, poly: Polylines, tol: float, tol_f: float,
                    start: FloatArray, keep_order: bool) -> _Chords:
    """Order, reverse and join the flattened strokes; per-chord provenance and budgets."""
    pts0 = poly.points
    offs = poly.offsets
    npath = offs.shape[0] - 1
    starts = pts0[offs[:-1]]
    ends = pts0[offs[1:] - 1]
    od = order.order_paths(starts, ends, start, start, keep_order=keep_order)
    lens = np.diff(offs)
    ordered_lens = lens[od.order]
    # Vertex index map in the new order (reversed paths walk their vertices backwards).
    base = np.repeat(offs[:-1][od.order], ordered_lens)
    k = np.arange(int(ordered_lens.sum())) - np.repeat(np.cumsum(ordered_lens) - ordered_lens,
                                                       ordered_lens)
    revv = np.repeat(od.reverse, ordered_lens)
    idx = np.where(revv, base + np.repeat(ordered_lens, ordered_lens) - 1 - k, base + k)
    pts = pts0[idx]
    new_offs = np.concatenate(([0], np.cumsum(ordered_lens))).astype(np.int64)
    # Per-vertex chord metadata (chord v → v+1 in the new order).
    # forward: chord lies on prim[idx[v+1]] over [t0, t] of idx[v+1]; reversed: on idx[v].
    m = pts.shape[0]
    nxt = np.minimum(np.arange(m) + 1, m - 1)
    owner = np.where(revv, idx, idx[nxt])
    c_prim = poly.prim[owner]
    c_tlo = poly.t0[owner]
    c_thi = poly.t[owner]
    is_end = np.zeros(m, dtype=bool)
    is_end[new_offs[1:] - 1] = True
    path_idx = np.repeat(np.arange(npath), ordered_lens)
    stroke = poly.stroke[od.order]
    power = drawing.stroke_power[stroke]
    feed = drawing.stroke_feed_mm_s[stroke]
    source = drawing.stroke_source[stroke]
    # Join consecutive paths whose gap is below the tolerance and whose settings match.
    gap = np.hypot(*(pts[new_offs[1:-1]] - pts[new_offs[1:-1] - 1]).T)
    same = (power[1:] == power[:-1]) & ((feed[1:] == feed[:-1])
                                        | (np.isnan(feed[1:]) & np.isnan(feed[:-1])))
    join = (gap < tol) & same
    bridge_tol = np.full(m, np.nan)
    bridge_at = new_offs[1:-1][join] - 1  # vertex that ends path p and starts the bridge
    is_end[bridge_at] = False
    bridge_tol[bridge_at] = tol - gap[join] / 2
    c_prim = c_prim.copy()
    c_prim[bridge_at] = -1
    keep_path = np.concatenate(([True], ~join))
    new_path_of_old = np.cumsum(keep_path) - 1
    joined_offs = np.concatenate((new_offs[:-1][keep_path], [m])).astype(np.int64)
    chord_from = np.flatnonzero(~is_end)
    # Drop zero-length chords by merging their vertices (keeps paths ≥ 1 chord if possible).
    kind = drawing.kind
    is_line = np.zeros(chord_from.shape[0], dtype=bool)
    cp = c_prim[chord_from]
    is_line[cp >= 0] = kind[cp[cp >= 0]] == LINE
    tol_i = np.where(is_line, tol, tol - tol_f)
    bt = bridge_tol[chord_from]
    tol_i = np.where(np.isnan(bt), tol_i, bt)
    return _Chords(pts=pts, offsets=joined_offs, vert_prim=poly.prim[idx],
                   chord_from=chord_from, prim=cp, tlo=c_tlo[chord_from],
                   thi=c_thi[chord_from], rev=revv[chord_from], tol_i=tol_i,
                   path_of_chord=new_path_of_old[path_idx[chord_from]],
                   path_source=source[keep_path], path_reversed=od.reverse[keep_path],
                   power=power[keep_path], feed=feed[keep_path], joined=int(join.sum()),
                   travel_before=od.travel_before_mm, travel_after=od.travel_after_mm)


def _mode_at(fb: FiveBar, angles: FloatArray, point: FloatArray, fallback: str) -> str:
    """Working mode of one pose; `fallback` if an arm sits exactly on a type-1 singularity."""
    s = fb.mode_of(point.reshape(1, 2), angles.reshape(1, 2))[0]
    if (s == 0).any():
        return fallback
    return ("+" if s[0] > 0 else "-") + ("+" if s[1] > 0 else "-")


def _merge_intervals(parts: list[Intervals]) -> Intervals:
    """Intervals refined per working mode, merged back into job order (chord, then σ)."""
    if len(parts) == 1:
        return parts[0]
    cat = [np.concatenate([getattr(p, f) for p in parts])
           for f in ("chord", "sa", "sb", "tha", "thb", "min_margin", "dev_mm")]
    o = np.lexsort((cat[1], cat[0]))
    return Intervals(*(c[o] for c in cat))


def _transition_targets(path: FloatArray, start: FloatArray, end: FloatArray,
                        max_step_rad: float) -> FloatArray:
    """Targets (K, 2) that execute a planned pen-up joint path (samples of straight legs, as
    `plan_joint_move` returns it) exactly under the firmware's linear interpolation: the
    corners of the path, each leg split into pieces of at most `max_step_rad`. The first and
    last samples are replaced by the job's own poses `start`, `end` (they agree to rounding)."""
    p = np.asarray(path, dtype=np.float64).copy()
    if (np.abs(p[0] - start).max() > 1e-6 or np.abs(p[-1] - end).max() > 1e-6):
        raise JobError("internal: the planned working-mode change does not start and end at "
                       "the job's poses", None, "internal")
    p[0], p[-1] = start, end
    d = np.diff(p, axis=0)
    scale = max(float(np.abs(d).max(initial=0.0)), 1e-12)
    turn = np.flatnonzero(np.abs(np.diff(d, axis=0)).max(axis=1) > 1e-9 * scale) + 1
    way = p[np.concatenate(([0], turn, [p.shape[0] - 1]))]
    out = []
    for q0, q1 in itertools.pairwise(way):
        n = max(1, math.ceil(float(np.abs(q1 - q0).max()) / max_step_rad))
        out.append(q0 + (np.arange(1, n + 1) / n)[:, None] * (q1 - q0))
    return np.concatenate(out)


def _type1_crossings(fb: FiveBar, th: FloatArray,
                     pts: FloatArray) -> tuple[tuple[int, str, float, float], ...]:
    """Where an arm's type-1 margin changes sign along sampled poses: (arm, "stretched" or
    "folded", x, y), the pen position interpolated linearly between the samples."""
    mar = fb.singularity_margins(th, pts)
    out: list[tuple[int, str, float, float]] = []
    for arm in (0, 1):
        m = mar[:, arm]
        for k in np.flatnonzero(np.sign(m[:-1]) * np.sign(m[1:]) < 0).tolist():
            t = m[k] / (m[k] - m[k + 1])
            q = pts[k] + t * (pts[k + 1] - pts[k])
            a, b = (fb.a1, fb.b1) if arm == 0 else (fb.a2, fb.b2)
            d = math.hypot(float(q[0]) - (0.0 if arm == 0 else fb.w), float(q[1]))
            kind = "stretched" if abs(d - (a + b)) < abs(d - abs(a - b)) else "folded"
            out.append((arm + 1, kind, float(q[0]), float(q[1])))
    return tuple(out)


def _break_paths(ch: _Chords, brk_chord: IntArray, brk_frac: FloatArray) -> _Chords:
    """Start a new job path at each break: chord `brk_chord[k]` at chord parameter
    `brk_frac[k]` ∈ (0, 1] (1: at the chord's end vertex). The break point ends one path and
    starts the next (it appears twice, once in each), an interior break also splits its
    chord in two collinear chords. Geometry is unchanged; every new chord keeps its source
    chord's primitive, budget and direction, with the parameter range cut to its part."""
    o = np.lexsort((brk_frac, brk_chord))
    bc, bf = np.asarray(brk_chord, np.int64)[o], np.asarray(brk_frac, np.float64)[o]
    nb = bc.shape[0]
    a = ch.chord_from
    m_old = ch.pts.shape[0]
    interior = bf < 1.0
    at = np.where(interior[:, None],
                  ch.pts[a[bc]] + bf[:, None] * (ch.pts[a[bc] + 1] - ch.pts[a[bc]]),
                  ch.pts[a[bc] + 1])
    count = np.where(interior, 2, 1)
    rep = np.repeat(np.arange(nb), count)
    copy_k = np.arange(rep.shape[0]) - np.repeat(np.cumsum(count) - count, count)
    start_copy = ~interior[rep] | (copy_k == 1)
    ins_pos = np.where(interior, a[bc] + 1, a[bc] + 2)[rep]
    prim_at = np.where(interior, np.where(ch.prim[bc] >= 0, ch.prim[bc], ch.vert_prim[a[bc]]),
                       ch.vert_prim[a[bc] + 1])
    pts = np.insert(ch.pts, ins_pos, at[rep], axis=0)
    vert_prim = np.insert(ch.vert_prim, ins_pos, prim_at[rep])
    m_new = pts.shape[0]
    old_new = np.arange(m_old) + np.searchsorted(ins_pos, np.arange(m_old), side="right")
    ins_new = ins_pos + np.arange(ins_pos.shape[0])
    is_start = np.zeros(m_new, bool)
    is_start[old_new[ch.offsets[:-1]]] = True
    is_start[ins_new[start_copy]] = True
    is_end = np.zeros(m_new, bool)
    is_end[old_new[ch.offsets[1:] - 1]] = True
    is_end[ins_new[~start_copy]] = True
    is_end[old_new[a[bc[~interior]] + 1]] = True
    offsets = np.concatenate((np.flatnonzero(is_start), [m_new])).astype(np.int64)
    # Per new vertex: the source chord of the chord that starts there and its σ there; per
    # interior end copy: the chord and σ it ends.
    src = np.full(m_new, -1, np.int64)
    f0 = np.zeros(m_new)
    src[old_new[a]] = np.arange(a.shape[0])
    isc = start_copy & interior[rep]
    src[ins_new[isc]] = bc[rep[isc]]
    f0[ins_new[isc]] = bf[rep[isc]]
    vsc = ~interior[rep]
    nxt = np.searchsorted(a, a[bc[rep[vsc]]] + 1)
    src[ins_new[vsc]] = nxt
    end_c = np.full(m_new, -1, np.int64)
    end_f = np.ones(m_new)
    iec = ~start_copy
    end_c[ins_new[iec]] = bc[rep[iec]]
    end_f[ins_new[iec]] = bf[rep[iec]]
    cf = np.flatnonzero(~is_end)
    c = src[cf]
    lo = f0[cf]
    hi = np.where(end_c[cf + 1] == c, end_f[cf + 1], 1.0)
    span = ch.thi[c] - ch.tlo[c]
    rev = ch.rev[c]
    tlo = np.where(rev, ch.thi[c] - hi * span, ch.tlo[c] + lo * span)
    thi = np.where(rev, ch.thi[c] - lo * span, ch.tlo[c] + hi * span)
    old_path_v = np.insert(np.repeat(np.arange(offsets.shape[0] - 1 - nb),
                                     np.diff(ch.offsets)),
                           ins_pos, ch.path_of_chord[bc][rep])
    po = old_path_v[offsets[:-1]]
    return replace(ch, pts=pts, offsets=offsets, vert_prim=vert_prim, chord_from=cf,
                   prim=ch.prim[c], tlo=tlo, thi=thi, rev=rev, tol_i=ch.tol_i[c],
                   path_of_chord=np.searchsorted(offsets, cf, side="right") - 1,
                   path_source=ch.path_source[po], path_reversed=ch.path_reversed[po],
                   power=ch.power[po], feed=ch.feed[po])


def _point_text(points: FloatArray, match: re.Match[str]) -> str:
    """'point (x, y) mm' for a 'point <index>' in a planner message."""
    x, y = points[int(match[1])]
    return f"point ({x:.3f}, {y:.3f}) mm"


def _plan_modes(ch: _Chords, fb: FiveBar, home_th: FloatArray, home_mode: str, asm: str,
                min1: float, min2: float,
                limits: tuple[tuple[float, float], tuple[float, float]],
                where_of: Callable[[int, FloatArray], Where]
                ) -> tuple[_Chords, NDArray[np.str_], dict[int, FloatArray]]:
    """Working modes per job path with pen-up changes (`--mode auto` when no single mode
    clears every check): every path, sampled at most `MODE_SAMPLE_MM` apart, goes through
    `kinematics.modes.plan_working_modes` in job order, from the homed pose, in the
    machine's assembly. Paths that change mode inside are broken there (`_break_paths`).
    Returns the new chords, the mode of each job path and the planned joint path of each
    mode change by the travel that runs it (travel j goes into path j)."""
    offs = ch.offsets
    npath = offs.shape[0] - 1
    a = ch.chord_from
    d = ch.pts[a + 1] - ch.pts[a]
    n = np.maximum(1, np.ceil(np.hypot(*d.T) / MODE_SAMPLE_MM)).astype(np.int64)
    rep = np.repeat(np.arange(a.shape[0]), n)
    frac = (np.arange(rep.shape[0]) - np.repeat(np.cumsum(n) - n, n) + 1) / n[rep]
    dense = ch.pts[a[rep]] + frac[:, None] * d[rep]
    c_off = np.searchsorted(a, offs)
    s_off = np.concatenate(([0], np.cumsum(n)))[c_off]
    modes = WORKING_MODES
    cur, pose = home_mode, home_th
    brk_c: list[int] = []
    brk_f: list[float] = []
    path_mode: list[str] = []
    changes: dict[int, FloatArray] = {}
    for p in range(npath):
        g0, g1 = int(s_off[p]), int(s_off[p + 1])
        stroke = np.concatenate((ch.pts[offs[p]][None], dense[g0:g1]))
        safe = np.zeros(stroke.shape[0], bool)
        for m in modes:
            safe |= point_safety(fb, m, stroke, min1, min2, limits, assembly=asm)
        if not safe.all():
            k = int(np.flatnonzero(~safe)[0])
            why = []
            for m in modes:
                try:
                    PoseChecker(fb, m, 1 if asm == "+" else -1, min1, min2,
                                limits).inverse(stroke[k:k + 1])
                except CheckFailedError as cf:
                    why.append(f"{m}: {cf.message}")
            raise JobError("no working mode is safe at this point in assembly "
                           f"{asm}, so no working-mode change can help (" + "; ".join(why)
                           + ")", where_of(p, stroke[k]), "no_mode")
        try:
            mp = plan_working_modes(fb, [stroke], cur, min1, min2, limits, assembly=asm,
                                    start_angles=pose, modes=modes)
        except NoSafeRegionError as e:
            msg = re.sub(r"stroke 0:? ", "", str(e))
            msg = re.sub(r"point (\d+)", partial(_point_text, stroke), msg)
            raise JobError(f"working-mode change impossible: {msg}", where_of(p, stroke[0]),
                           "no_mode") from None
        for i, pc in enumerate(mp.pieces):
            if pc.stop - pc.start < 2 or (i > 0 and pc.start == 0):
                raise JobError("internal: the working-mode plan has a piece without a "
                               "chord", where_of(p, stroke[pc.start]), "internal")
            if i > 0:
                g = g0 + pc.start - 1
                brk_c.append(int(rep[g]))
                brk_f.append(float(frac[g]))
            if pc.transition is not None:
                changes[len(path_mode)] = pc.transition.joint_path
            path_mode.append(pc.mode)
        last = mp.pieces[-1]
        cur = last.mode
        pose = np.asarray(fb.inverse(stroke[last.stop - 1], cur), dtype=np.float64)
    if brk_c:
        ch = _break_paths(ch, np.array(brk_c, np.int64), np.array(brk_f))
    return ch, np.array(path_mode), changes


def _compile_mode(drawing: Drawing, profile: Profile, opts: CompileOptions,
                  mode: str, plan_modes: bool = False) -> Job:
    """Compile `drawing`, placed for working mode `mode`. Without `plan_modes` every path is
    drawn in `mode`. With it (`--mode auto` when no single mode clears every check), the
    modes come from `_plan_modes` and every change of mode becomes a checked pen-up
    joint-space move (`ModeChange`)."""
    fb = profile.geometry
    kin = profile.kinematics
    mot = profile.motors
    motion = profile.motion
    tol = float(opts.tolerance_mm if opts.tolerance_mm is not None else motion.tolerance_mm)
    if not (math.isfinite(tol) and tol > 0):
        raise ValueError(f"tolerance must be a positive number of mm; got {tol!r}")
    tol_f = tol / 2.0
    min1, min2, limits = kin.min_type1_margin_rad, kin.min_type2_margin_rad, mot.limits_rad
    file = drawing.file
    asm = kin.assembly
    pl = layout.place(drawing, fb, mode, min1, min2, limits, origin_mm=opts.origin_mm,
                      scale=opts.scale, rotate_deg=opts.rotate_deg, fit=opts.fit,
                      assembly=asm)
    mdraw = drawing.transformed(pl.matrix, pl.offset)
    poly = flatten(mdraw, tol_f)

    def fail(cf: CheckFailedError, prim: int, what: str = "path",
             in_mode: str | None = None) -> JobError:
        m = in_mode or mode
        w = _where(file, drawing, pl, cf.point, prim, what)
        msg = f"{cf.message} (working mode {m})"
        if cf.reason in ("reach", "joint_limit", "type1_margin", "type2_margin", "assembly"):
            msg += "; " + layout.does_not_fit_hint(pl, fb, m, min1, min2, limits, asm)
        return JobError(msg, w, cf.reason)

    # Assembly: the machine's, from the profile (every pose must have it; the checker
    # refuses a point that is only reachable in the other one).
    assembly = 1 if asm == "+" else -1
    home = np.array(mot.home_rad, dtype=np.float64).reshape(1, 2)
    home_fk = fb.forward_batch(home, asm)
    if not home_fk.valid[0]:  # pragma: no cover - the profile parser checks the homed pose
        raise JobError(f"the homed pose {np.degrees(home[0]).round(3).tolist()}° has no pen "
                       f"position in assembly {asm}", Where(file=file, what="move from home"),
                       "assembly")
    home_pt = home_fk.points[0]
    home_mode = _mode_at(fb, home[0], home_pt,
                         kin.working_mode if kin.working_mode != "auto" else AUTO_ORDER[0])

    ch = _prepare_chords(drawing, poly, tol, tol_f, home_pt, opts.keep_order)
    changes: dict[int, FloatArray] = {}
    if plan_modes:
        def where_of(p: int, point: FloatArray) -> Where:
            return _where(file, drawing, pl, (float(point[0]), float(point[1])),
                          int(ch.vert_prim[ch.offsets[p]]))

        ch, path_mode, changes = _plan_modes(ch, fb, home[0], home_mode, asm, min1, min2,
                                             limits, where_of)
    else:
        path_mode = np.full(ch.offsets.shape[0] - 1, mode)
    npath = ch.offsets.shape[0] - 1
    checkers = {m: PoseChecker(fb, m, assembly, min1, min2, limits)
                for m in dict.fromkeys(path_mode.tolist())}
    checker = next(iter(checkers.values()))  # forward kinematics (the same in every mode)
    # Checked inverse kinematics of every vertex, in its path's working mode.
    vert_mode = np.repeat(path_mode, np.diff(ch.offsets))
    th_v = np.empty_like(ch.pts)
    for m, chk in checkers.items():
        idx = np.flatnonzero(vert_mode == m)
        try:
            th_v[idx] = chk.inverse(ch.pts[idx], idx)
        except CheckFailedError as cf:
            raise fail(cf, int(ch.vert_prim[cf.index]), in_mode=m) from None
    a = ch.chord_from
    chord_mode = path_mode[ch.path_of_chord]
    parts: list[Intervals] = []
    for m, chk in checkers.items():
        cs = np.flatnonzero(chord_mode == m)
        try:
            r = refine(chk, ch.pts[a[cs]], ch.pts[a[cs] + 1], th_v[a[cs]], th_v[a[cs] + 1],
                       ch.tol_i[cs], MAX_STEP_RAD)
        except CheckFailedError as cf:
            c = int(cs[cf.index])
            raise fail(cf, int(ch.prim[c]) if ch.prim[c] >= 0
                       else int(ch.vert_prim[a[c]]), in_mode=m) from None
        parts.append(r if len(checkers) == 1 else replace(r, chord=cs[r.chord]))
    iv = _merge_intervals(parts)

    # ------------------------------------------------------------ travel
    p_start = ch.offsets[:-1]
    p_end = ch.offsets[1:] - 1
    t_from = np.concatenate((home, th_v[p_end]))  # travel j goes into path j (j = P: park)
    t_to = np.concatenate((th_v[p_start], home))
    is_home_move = np.zeros(npath + 1, dtype=bool)
    is_home_move[0] = is_home_move[-1] = True
    t_mode = path_mode[np.minimum(np.arange(npath + 1), npath - 1)]
    is_change = np.zeros(npath + 1, dtype=bool)
    is_change[list(changes)] = True
    pieces = np.ones(npath + 1, dtype=np.int64)
    ok = np.ones(npath + 1, dtype=bool)
    code = np.zeros(npath + 1, dtype=np.int64)
    tmarg = np.full((npath + 1, 3), np.inf)
    for m, chk in checkers.items():
        js = np.flatnonzero((t_mode == m) & ~is_change)
        if js.size:
            pieces[js], ok[js], code[js], tmarg[js] = joint_moves(
                chk, t_from[js], t_to[js], MAX_STEP_RAD, check_type1=~is_home_move[js])
    if plan_modes:
        # A move from or to the homed pose that fails in a straight line: plan it like a
        # working-mode change (through a type-1 singularity if need be).
        for j in np.flatnonzero(~ok & is_home_move).tolist():
            planned = plan_joint_move(fb, t_from[j], t_to[j], asm, min2, limits)
            if planned is not None:
                changes[j] = planned[0]
                is_change[j] = ok[j] = True
    notes: list[str] = []
    travel_targets: dict[int, FloatArray] = {}  # travel j → its targets (K, 2), last = t_to[j]
    bad = np.flatnonzero(~ok)
    for j in bad.tolist():
        what = ("move from home" if j == 0 else "move to home" if j == npath
                else "travel")
        if is_home_move[j]:
            pt = (math.nan, math.nan)
            home_fail = CheckFailedError(
                0, pt, REASON_KEY.get(int(code[j]), "reach"),
                "the joint-space move between the homed pose and the drawing fails the "
                "checks: " + checkers[str(t_mode[j])].explain(int(code[j]), home[0], home_pt,
                                                              tmarg[j]))
            raise fail(home_fail, -1, what, str(t_mode[j]))
    for m, chk in checkers.items():
        bm = bad[t_mode[bad] == m]
        if not bm.size:
            continue
        # Cartesian fallback for the inter-path travels that fail in joint space.
        try:
            civ = refine(chk, ch.pts[p_end[bm - 1]], ch.pts[p_start[bm]], t_from[bm],
                         t_to[bm], np.full(bm.size, max(TRAVEL_TOL_MM, tol)), MAX_STEP_RAD)
        except CheckFailedError as cf:
            j = int(bm[cf.index])
            raise fail(cf, -1, f"travel to path #{int(ch.path_source[j])}", m) from None
        for n_, j in enumerate(bm.tolist()):
            travel_targets[j] = civ.thb[civ.chord == n_]
    if bad.size:
        notes.append(f"{bad.size} pen-up travel(s) run as straight lines (a joint-space move "
                     "would have passed too close to a singularity)")
    # Working-mode changes: the planned joint paths, checked again here sample by sample
    # (joint limits, type-2 margin, assembly; type-1 singularities may be crossed).
    for j, jpath in sorted(changes.items()):
        tg = _transition_targets(jpath, t_from[j], t_to[j], MAX_STEP_RAD)
        legs_a = np.concatenate((t_from[j][None], tg[:-1]))
        _, okc, cc, mc = joint_moves(checker, legs_a, tg, MAX_STEP_RAD, check_type1=False)
        if not okc.all():
            k = int(np.flatnonzero(~okc)[0])
            pt = checker.forward(tg[k:k + 1])[0][0]
            change_fail = CheckFailedError(
                0, (float(pt[0]), float(pt[1])), REASON_KEY.get(int(cc[k]), "reach"),
                "the pen-up working-mode change fails the checks: "
                + checker.explain(int(cc[k]), tg[k], pt, mc[k]))
            raise fail(change_fail, -1, "working-mode change", str(t_mode[j])) from None
        tmarg[j] = mc.min(axis=0)
        travel_targets[j] = tg

    # ------------------------------------------------------------ assemble segments
    # Draw segments, in order (intervals are sorted by chord, chords by job order).
    dc = iv.chord
    d_path = ch.path_of_chord[dc]
    d_end_pts = ch.pts[a[dc]] + iv.sb[:, None] * (ch.pts[a[dc] + 1] - ch.pts[a[dc]])
    # Travel pieces: uniform in joint space, or the given targets (Cartesian, mode change).
    t_pieces = pieces.copy()
    for j, tg in travel_targets.items():
        t_pieces[j] = tg.shape[0]
    t_move = np.repeat(np.arange(npath + 1), t_pieces)
    t_k = np.arange(t_move.shape[0]) - np.repeat(np.cumsum(t_pieces) - t_pieces, t_pieces)
    frac = (t_k + 1) / t_pieces[t_move]
    t_th = t_from[t_move] + frac[:, None] * (t_to[t_move] - t_from[t_move])
    for j, tg in travel_targets.items():
        t_th[t_move == j] = tg
    t_pts = checker.forward(t_th)[0]
    # Merge: key (path, part, sequence); travel into path j precedes its draw segments.
    n_d, n_t = dc.shape[0], t_move.shape[0]
    key_path = np.concatenate((d_path, t_move))
    key_part = np.concatenate((np.ones(n_d, np.int64), np.zeros(n_t, np.int64)))
    key_seq = np.concatenate((np.arange(n_d), t_k))
    perm = np.lexsort((key_seq, key_part, key_path))
    seg_draw = np.concatenate((np.ones(n_d, bool), np.zeros(n_t, bool)))[perm]
    end_th = np.concatenate((iv.thb, t_th))[perm]
    end_pts = np.concatenate((d_end_pts, t_pts))[perm]
    seg_path = key_path[perm]
    th_all = np.concatenate((home, end_th))
    pts_all = np.concatenate((home_pt[None], end_pts))
    # Per-segment provenance (draw only; −1 / 0 on travel).
    d_prim = ch.prim[dc]
    d_vprim = np.where(d_prim >= 0, d_prim, ch.vert_prim[a[dc]])
    d_src = drawing.stroke_source[drawing.stroke[d_vprim]]
    d_line = drawing.line[d_vprim]
    seg_source = np.concatenate((d_src, np.full(n_t, -1)))[perm]
    seg_line = np.concatenate((d_line, np.zeros(n_t, np.int64)))[perm]
    length = np.concatenate((
        (iv.sb - iv.sa) * np.hypot(*(ch.pts[a[dc] + 1] - ch.pts[a[dc]]).T),
        np.zeros(n_t)))[perm]
    # Travel length: distance between consecutive target points.
    tl = np.hypot(*np.diff(pts_all, axis=0).T)
    length = np.where(seg_draw, length, tl)

    # ------------------------------------------------------------ steps
    st = steps.absolute_steps(th_all, mot.home_rad, mot.steps_per_rev)
    rel = np.diff(st, axis=0)
    moving = (rel != 0).any(axis=1)
    keep_t = np.concatenate(([True], moving))
    st = st[keep_t]
    th_all = th_all[keep_t]
    pts_all = pts_all[keep_t]
    seg_draw, seg_path = seg_draw[moving], seg_path[moving]
    seg_source, seg_line, length = seg_source[moving], seg_line[moving], length[moving]
    perm_kept = perm[moving]

    # ------------------------------------------------------------ plan
    power_frac = np.where(seg_draw, ch.power[np.minimum(seg_path, npath - 1)], 0.0)
    power = np.where(seg_draw, np.clip(np.rint(power_frac * profile.laser.power), 0, 255),
                     0).astype(np.uint8)
    pfeed = ch.feed[np.minimum(seg_path, npath - 1)]
    feed = np.where(seg_draw, np.where(np.isnan(pfeed), motion.draw_feed_mm_s, pfeed),
                    motion.travel_feed_mm_s)
    stop = np.zeros(seg_draw.shape[0], dtype=bool)
    stop[:-1] = (seg_draw[1:] != seg_draw[:-1]) | (power[1:] != power[:-1])
    # 1. A continuous speed profile (junction passes) with part of the limits; 2. its
    # speed-up and slow-down parts cut into short pieces (new targets on the same joint-space
    # lines, so the path does not change); 3. the profile again on the pieces; 4. every
    # boundary of the staircase the firmware runs (constant rate per G1) made exact.
    a_c = PLAN_ACCEL_SHARE * motion.max_joint_rad_s2
    j_lim = planner.JUNCTION_JUMP_RAD_S
    prof_kw = {"junction_jump_rad_s": PLAN_JUMP_SHARE * j_lim,
               "min_duration_s": protocol.P_MIN_US * 1e-6,
               "corner_accel_rad_s2": (1.0 - PLAN_ACCEL_SHARE) * motion.max_joint_rad_s2}
    dq = np.diff(steps.step_angles(st, mot.home_rad, mot.steps_per_rev), axis=0)
    pln = planner.plan(dq, length, feed, motion.max_joint_rad_s, a_c, stop_after=stop,
                       **prof_kw)
    counts, f1 = planner.ramp_fractions(pln, np.abs(dq).max(axis=1), a_c,
                                        PLAN_PIECE_JUMP_SHARE * j_lim / a_c,
                                        PLAN_MIN_PIECE_STEPS * mot.rad_per_step)
    seg_of = np.repeat(np.arange(counts.shape[0]), counts)
    inner = np.concatenate((seg_of[1:] == seg_of[:-1], [False]))  # not a segment's last piece
    # new targets on the ideal joint-space line of their segment, rounded once
    k_in = seg_of[inner]
    th_in = th_all[k_in] + f1[inner, None] * (th_all[k_in + 1] - th_all[k_in])
    order_t = np.argsort(np.concatenate((np.arange(th_all.shape[0]) * 1.0,
                                         k_in + f1[inner])), kind="stable")
    th_all = np.concatenate((th_all, th_in))[order_t]
    pts_all = np.concatenate((pts_all, checker.forward(th_in)[0]))[order_t]
    st = steps.absolute_steps(th_all, mot.home_rad, mot.steps_per_rev)
    keep = np.concatenate(([True], (np.diff(st, axis=0) != 0).any(axis=1)))
    st, th_all, pts_all = st[keep], th_all[keep], pts_all[keep]
    seg_of, f1 = seg_of[keep[1:]], f1[keep[1:]]
    f1[np.concatenate((seg_of[1:] != seg_of[:-1], [True]))] = 1.0
    f0 = np.where(np.concatenate(([True], seg_of[1:] != seg_of[:-1])), 0.0,
                  np.concatenate(([0.0], f1[:-1])))
    seg_draw, seg_path, seg_source = seg_draw[seg_of], seg_path[seg_of], seg_source[seg_of]
    seg_line, power, feed = seg_line[seg_of], power[seg_of], feed[seg_of]
    stop = stop[seg_of] & np.concatenate((seg_of[1:] != seg_of[:-1], [True]))
    perm_kept = perm_kept[seg_of]
    length = np.where(seg_draw, length[seg_of] * (f1 - f0),
                      np.hypot(*np.diff(pts_all, axis=0).T))
    dq = np.diff(steps.step_angles(st, mot.home_rad, mot.steps_per_rev), axis=0)
    pln = planner.plan(dq, length, feed, motion.max_joint_rad_s, a_c, stop_after=stop,
                       **prof_kw)
    duration_us = planner.enforce_staircase(dq, pln.duration_us, stop,
                                            motion.max_joint_rad_s2, j_lim)

    # ------------------------------------------------------------ per-path bookkeeping
    draw_idx = np.flatnonzero(seg_draw)
    dp = seg_path[draw_idx]
    first_seg = np.full(npath, -1, dtype=np.int64)
    end_seg = np.full(npath, -1, dtype=np.int64)
    if draw_idx.size:
        u, fi = np.unique(dp, return_index=True)
        first_seg[u] = draw_idx[fi]
        li = np.unique(dp[::-1], return_index=True)[1]
        end_seg[u] = draw_idx[::-1][li] + 1
    # Requested geometry per draw segment (for validation and previews).
    src_rows = perm_kept[seg_draw]  # rows into the draw-interval arrays
    chord_rows = dc[src_rows]
    sa_d, sb_d = iv.sa[src_rows], iv.sb[src_rows]  # a piece's part of its interval
    sa_d, sb_d = sa_d + f0[seg_draw] * (sb_d - sa_d), sa_d + f1[seg_draw] * (sb_d - sa_d)
    # Smallest margins over targets and samples; the moves from/to home and the working-mode
    # changes may pass a type-1 singularity on purpose (pen up, changing working mode), so
    # their type-1 columns and targets are left out.
    free1 = is_home_move | is_change
    tmarg_rep = tmarg.copy()
    tmarg_rep[free1, :2] = np.inf
    jmargin = np.minimum(iv.min_margin.min(axis=0) if iv.min_margin.size else np.inf,
                         tmarg_rep.min(axis=0))
    seg_mode = np.where(seg_draw, path_mode[np.minimum(seg_path, npath - 1)],
                        t_mode[seg_path])
    sgn = np.stack([np.where(np.char.startswith(seg_mode, "+"), 1.0, -1.0),
                    np.where(np.char.endswith(seg_mode, "+"), 1.0, -1.0),
                    np.full(seg_mode.shape[0], float(assembly))], axis=1)
    tm = fb.singularity_margins(th_all, pts_all) * np.concatenate(
        ([[1.0, 1.0, float(assembly)]], sgn))
    home_leg = np.concatenate(([True], ~seg_draw & free1[seg_path]))
    tm[home_leg, :2] = np.inf
    jmargin = np.minimum(jmargin, tm.min(axis=0))
    jac = fb.jacobian(th_all, pts_all)
    quantum = float(steps.step_quantum_mm(jac, mot.rad_per_step).max())
    # The working-mode changes as executed (quantised steps, sampled ≤ 0.5° apart).
    mode_changes: list[ModeChange] = []
    th_q = steps.step_angles(st, mot.home_rad, mot.steps_per_rev)
    for j in sorted(changes):
        segs = np.flatnonzero(~seg_draw & (seg_path == j))
        if not segs.size:
            continue
        s0, s1 = int(segs[0]), int(segs[-1]) + 1
        q = th_q[s0:s1 + 1]
        dense = _densify_joint(q, math.radians(0.5))
        fk = fb.forward_batch(dense, asm)
        marg = (fb.singularity_margins(dense, fk.points)[:, 2] * assembly if fk.valid.all()
                else np.array([-np.inf]))
        lim_ok = wrap_to_limits(dense, limits)[1:]
        if not (fk.valid.all() and (marg > 0).all() and lim_ok[0].all() and lim_ok[1].all()):
            raise JobError("the working-mode change before path "
                           f"#{j} leaves the assembly mode or the joint limits once its "
                           "targets are rounded to whole steps", Where(file=file),
                           "assembly")
        mode_changes.append(ModeChange(
            from_mode=str(path_mode[j - 1]) if j > 0 else home_mode,
            to_mode=str(path_mode[j]) if j < npath else home_mode,
            path=j, first_seg=s0, end_seg=s1,
            lift_mm=(float(pts_all[s0, 0]), float(pts_all[s0, 1])),
            land_mm=(float(pts_all[s1, 0]), float(pts_all[s1, 1])),
            crossings=_type1_crossings(fb, dense, fk.points),
            min_type2_rad=float(marg.min()),
            duration_s=float(duration_us[s0:s1].sum()) * 1e-6))
    if mode_changes:
        seq = [str(path_mode[0])]
        for m in path_mode[1:].tolist():
            if m != seq[-1]:
                seq.append(m)
        mode_note = (f"working modes {' → '.join(seq)} with {len(mode_changes)} pen-up "
                     f"working-mode change(s), assembly {asm}")
    else:
        mode_note = f"working mode {path_mode[0]}, assembly {asm}"
    notes.insert(0, f"{mode_note}; at the homed pose the pen is at ({home_pt[0]:.1f}, "
                    f"{home_pt[1]:.1f}) mm (working mode {home_mode})")
    notes.extend(drawing.warnings)
    job = Job(
        file=file, mode=str(path_mode[0]), assembly=assembly, tolerance_mm=tol,
        flatten_tol_mm=tol_f,
        placement=pl, drawing=mdraw, steps_per_rev=mot.steps_per_rev, home_rad=mot.home_rad,
        points_mm=pts_all, angles_rad=th_all, steps=st, draw=seg_draw, power=power,
        path=seg_path, source=seg_source, source_line=seg_line, duration_us=duration_us,
        length_mm=length,
        paths=PathStats(ch.path_source, ch.path_reversed, first_seg, end_seg,
                        np.full(npath, np.nan), np.full(npath, np.nan)),
        min_margin_rad=jmargin, step_quantum_mm=quantum,
        travel_before_mm=ch.travel_before, travel_after_mm=ch.travel_after, joined=ch.joined,
        notes=notes,
        seg_prim=ch.prim[chord_rows], seg_tlo=ch.tlo[chord_rows], seg_thi=ch.thi[chord_rows],
        seg_rev=ch.rev[chord_rows], seg_sa=sa_d, seg_sb=sb_d,
        seg_ca=ch.pts[a[chord_rows]], seg_cb=ch.pts[a[chord_rows] + 1],
        ideal_max_dev_mm=float(iv.dev_mm.max()) if iv.dev_mm.size else 0.0,
        path_modes=tuple(path_mode.tolist()), home_mode=home_mode,
        mode_changes=tuple(mode_changes),
    )
    if opts.validate:
        job = validate(job, profile, opts.validation_samples)
    return job


def _densify_joint(q: FloatArray, step_rad: float) -> FloatArray:
    """The firmware's joint-space polyline through targets q (N, 2), sampled at most
    `step_rad` apart (every target included)."""
    d = np.diff(q, axis=0)
    n = np.maximum(1, np.ceil(np.abs(d).max(axis=1) / step_rad)).astype(np.int64)
    rep = np.repeat(np.arange(d.shape[0]), n)
    s = (np.arange(rep.shape[0]) - np.repeat(np.cumsum(n) - n, n)) / n[rep]
    return np.concatenate((q[rep] + s[:, None] * d[rep], q[-1:]))


def deviations(job: Job, profile: Profile, samples: int = 4,
               quantised: bool = True) -> tuple[FloatArray, IntArray]:
    """Deviation (mm) of the executed pen path from the requested path, measured on the
    quantised steps: for every draw segment, `samples` points of the joint-space
    interpolation between its quantised end targets (s = 0, 1/samples, …) plus each path's
    last target, through forward kinematics, each measured to the requested curve (Newton's
    method on the primitive; a join bridge is measured to its two end points). Returns the
    distances and the segment index of each. `quantised=False` measures the ideal
    (unrounded) joint targets instead: the tolerance bound itself, without the step quantum."""
    fb = profile.geometry
    th = (steps.step_angles(job.steps, job.home_rad, job.steps_per_rev) if quantised
          else job.angles_rad)
    di = np.flatnonzero(job.draw)
    s = np.arange(samples + 1) / samples
    tha, thb = th[di], th[di + 1]
    q = (tha[:, None, :] + s[None, :, None] * (thb - tha)[:, None, :]).reshape(-1, 2)
    fk = fb.forward_batch(q, "+" if job.assembly > 0 else "-")
    return _deviation_of(job, fk.points, fk.valid, di, samples)


def _deviation_of(job: Job, e: FloatArray, valid: BoolArray, di: IntArray,
                  samples: int) -> tuple[FloatArray, IntArray]:
    """Distances of pen points e ((len(di)·(samples+1), 2), samples s = 0, 1/S, …, 1 of each
    draw segment di) to the requested curves; invalid rows count as infinitely far."""
    s = np.tile(np.arange(samples + 1) / samples, di.shape[0])
    rank = np.repeat(np.arange(di.shape[0]), samples + 1)
    dist = distance_to_request(job, e, rank, s)
    dist[~valid] = np.inf
    return dist, di[rank]


def distance_to_request(job: Job, e: FloatArray, rank: IntArray, s: FloatArray) -> FloatArray:
    """Distance of pen points `e` to the requested curve of draw segment number `rank`
    (counted among draw segments), at fraction `s` ∈ [0, 1] along it as the parameter guess
    for Newton's method on the primitive (a join bridge: distance to its nearer end)."""
    sig = job.seg_sa[rank] + s * (job.seg_sb - job.seg_sa)[rank]
    span = job.seg_thi - job.seg_tlo
    tg = np.where(job.seg_rev[rank], job.seg_thi[rank] - sig * span[rank],
                  job.seg_tlo[rank] + sig * span[rank])
    prim = job.seg_prim[rank]
    dist = np.empty(e.shape[0])
    real = prim >= 0
    if real.any():
        dist[real] = nearest_distance(job.drawing.kind[prim[real]],
                                      job.drawing.params[prim[real]], e[real], tg[real])
    if (~real).any():
        ca, cb = job.seg_ca[rank[~real]], job.seg_cb[rank[~real]]
        dist[~real] = np.minimum(np.hypot(*(e[~real] - ca).T), np.hypot(*(e[~real] - cb).T))
    return dist


#: Most poses the n-bar second opinion follows (continuation is ~25 µs per pose).
NBAR_MAX_POSES = 20_000


@dataclass(frozen=True)
class NbarOpinion:
    """The general n-bar solver's view of the executed path (quantised steps, `samples` per
    segment): its largest deviation from the requested path, its largest disagreement with the
    closed form, and how many poses were followed (of how many)."""

    max_dev_mm: float
    max_disagreement_mm: float
    poses: int
    total_poses: int

    def describe(self) -> str:
        part = ("" if self.poses == self.total_poses
                else f" (the first {self.poses} of {self.total_poses} poses)")
        return (f"n-bar solver: max deviation {self.max_dev_mm:.4f} mm, differs from the closed "
                f"form by at most {self.max_disagreement_mm:.2g} mm{part}")


def nbar_opinion(job: Job, profile: Profile, samples: int = 4,
                 max_poses: int = NBAR_MAX_POSES) -> NbarOpinion | None:
    """Second opinion on the validation through `kinematics.nbar` (continuation along the
    whole executed path from the homed pose); None if that solver is not installed."""
    try:
        from kinematics.nbar.validate import validate_fivebar_path
    except ImportError:  # pragma: no cover - the n-bar package ships with the project
        return None
    th = steps.step_angles(job.steps, job.home_rad, job.steps_per_rev)
    s = np.arange(samples) / samples
    q = (th[:-1, None, :] + s[None, :, None] * np.diff(th, axis=0)[:, None, :]).reshape(-1, 2)
    q = np.concatenate((q, th[-1:]))
    total = q.shape[0]
    n = min(total, max_poses)
    v = validate_fivebar_path(profile.geometry, q[:n], job.assembly)
    pts, ok = v.nbar_points, v.valid
    # draw segments whose samples (incl. the end, the next segment's first) were all followed
    di = np.flatnonzero(job.draw)
    di = di[(di + 1) * samples < n]
    idx = (di[:, None] * samples + np.arange(samples + 1)[None, :]).ravel()
    dist, _ = _deviation_of(job, pts[idx], ok[idx], di, samples)
    dis = v.deviation[ok]
    return NbarOpinion(float(dist.max()) if dist.size else 0.0,
                       float(dis.max()) if dis.size else math.nan, n, total)


def validate(job: Job, profile: Profile, samples: int = 4) -> Job:
    """Fill the per-path and overall max/mean deviation from the quantised steps."""
    if not job.draw.any():
        return job
    dist, seg = deviations(job, profile, samples)
    path = job.path[seg]
    n = job.n_paths
    mx = np.full(n, -np.inf)
    np.maximum.at(mx, path, dist)
    cnt = np.bincount(path, minlength=n)
    mean = np.bincount(path, weights=dist, minlength=n) / np.maximum(cnt, 1)
    mx[cnt == 0] = np.nan
    mean[cnt == 0] = np.nan
    ps = replace(job.paths, max_dev_mm=mx, mean_dev_mm=mean)
    return replace(job, paths=ps, max_dev_mm=float(dist.max()), mean_dev_mm=float(dist.mean()))


def compile_drawing(drawing: Drawing, profile: Profile, opts: CompileOptions) -> Job:
    """Compile an already-read drawing; `opts.mode` "auto" tries every working mode."""
    mode = opts.mode or profile.kinematics.working_mode
    if mode != "auto":
        if mode not in WORKING_MODES:
            raise ValueError(f"working mode must be one of {', '.join(WORKING_MODES)} or "
                             f"auto; got {mode!r}")
        return _compile_mode(drawing, profile, opts, mode)
    results: list[Job] = []
    failures: list[tuple[str, JobError]] = []
    for m in AUTO_ORDER:
        try:
            results.append(_compile_mode(drawing, profile, opts, m))
        except JobError as e:
            failures.append((m, e))
    if not results:
        lines = "\n".join(f"  mode {m}: {e}" for m, e in failures)
        try:
            job = _compile_with_mode_changes(drawing, profile, opts)
        except JobError as e:
            raise JobError("no working mode clears every check (--mode auto):\n" + lines
                           + f"\n  with pen-up working-mode changes: {e}",
                           Where(file=drawing.file), "no_mode") from None
        used = ", ".join(dict.fromkeys(job.path_modes))
        notes = [f"--mode auto: no single working mode clears every check, so the paths are "
                 f"drawn in modes {used} with {len(job.mode_changes)} pen-up working-mode "
                 "change(s) (thesis Sec. 7.2)"]
        notes += [f"  single mode {m}: {e.detail.split(';')[0]}" for m, e in failures]
        return replace(job, notes=notes + job.notes)
    best = max(results, key=lambda j: float(np.min(j.min_margin_rad)))
    why = (f"--mode auto chose {best.mode}: it clears every check with the largest smallest "
           f"singularity margin ({math.degrees(float(np.min(best.min_margin_rad))):.1f}°)")
    others = [f"{j.mode}: passes, smallest margin "
              f"{math.degrees(float(np.min(j.min_margin_rad))):.1f}°"
              for j in results if j is not best]
    others += [f"{m}: {e.detail.split(';')[0]}" for m, e in failures]
    notes = [why] + ([f"  other modes — {o}" for o in others]) + best.notes
    return replace(best, notes=notes)


def _compile_with_mode_changes(drawing: Drawing, profile: Profile,
                               opts: CompileOptions) -> Job:
    """`--mode auto`'s second try: working modes per path with pen-up changes. With
    `--origin` the placement does not depend on the mode; otherwise the placements of the
    modes are tried in `AUTO_ORDER` (centred in, or fitted to, that mode's safe rectangle)
    and the first that can be planned wins. Raises the first mode's `JobError` if none can."""
    placements = AUTO_ORDER[:1] if opts.origin_mm is not None else AUTO_ORDER
    errors: list[JobError] = []
    for m in placements:
        try:
            return _compile_mode(drawing, profile, opts, m, plan_modes=True)
        except JobError as e:
            errors.append(e)
    raise errors[0]


def compile_job(path: str | Path, profile: Profile, opts: CompileOptions | None = None) -> Job:
    """Read and compile a drawing file (see module doc). Raises `InputError` or `JobError`."""
    o = opts or CompileOptions()
    drawing = read_drawing(path, o.layers)
    return compile_drawing(drawing, profile, o)


# ---------------------------------------------------------------------- firmware lines
#: Longest line the firmware accepts, bytes (docs/protocol.md section 5; the banner repeats it).
MAX_LINE_BYTES = 80


def _comment(text: str) -> str:
    """A comment line the firmware accepts (docs/protocol.md section 5: printable ASCII, at
    most `MAX_LINE_BYTES`): non-ASCII characters become '?', long text is cut."""
    line = "; " + text.encode("ascii", "replace").decode("ascii")
    return line[:MAX_LINE_BYTES]


def mode_sequence(job: Job, arrow: str = " → ") -> str:
    """The working modes a job draws in, in order: "+-", or "++ → +-" with mode changes."""
    seq: list[str] = []
    for m in job.path_modes or (job.mode,):
        if not seq or seq[-1] != m:
            seq.append(m)
    return arrow.join(seq)


def encode_lines(job: Job, profile: Profile, relative: bool = False,
                 laser: bool = False) -> list[str]:
    """Firmware-ready lines for a job (docs/protocol.md; each G1 body from
    `protocol.g1`, which checks the word ranges):

        G90 | G91                      absolute or relative step coordinates
        G1 A<steps> B<steps> P<µs> S<0-255>   one per segment, in job order
        M5                             at the end

    Laser power is opt-in (issue 6): only with `laser=True` (the CLI's `--laser`) do the
    drawing segments carry the profile's power — `M3 S0` (or `M4 S0`, the profile's
    on_command) once at the start, `S<power>` on drawing segments and S0 on travel. Without
    it every line says S0 and the laser output never turns on; the job is a pen plot, and
    pen down / pen up are signalled by `M3 S0` before and `M5` after each run of drawing
    segments (the firmware's laser-enable state, which a pen-lift output can follow; at S0
    it switches no power). The header lines are comments the firmware ignores.

    The job starts at the homed pose (absolute steps 0, 0); the sender must make sure the
    firmware's position is that before streaming (e.g. after `fivebar home`)."""
    st = job.rel_or_abs(relative)
    power = job.power if laser else np.zeros_like(job.power)
    if not laser and job.power.size and int(power.max()) != 0:  # pragma: no cover
        raise AssertionError("pen mode must never send power")
    h = job.home_rad
    head = [
        _comment(f"fivebar job from {Path(job.file).name}"),
        _comment(f"working mode {mode_sequence(job, ' -> ')}, assembly "
                 f"{'+' if job.assembly > 0 else '-'}"
                 + (f", {len(job.mode_changes)} pen-up mode changes" if job.mode_changes
                    else "")),
        _comment(f"{job.n_segments} segments, {job.n_paths} paths, "
                 f"estimated {job.total_time_s:.1f} s"),
        _comment(f"tolerance {job.tolerance_mm:g} mm, max deviation {job.max_dev_mm:.4f} mm"),
        _comment(f"steps count from the homed pose ({math.degrees(h[0]):g}, "
                 f"{math.degrees(h[1]):g}) deg"),
        _comment(f"laser: power from the profile, S up to {int(power.max(initial=0))}"
                 if laser else "pen: S0 on every line; pen down = M3, pen up = M5"),
        "G91" if relative else "G90",
    ]
    body = [protocol.g1(int(a), int(b), int(p), int(s)) for a, b, p, s in
            zip(st[:, 0].tolist(), st[:, 1].tolist(), job.duration_us.tolist(),
                power.tolist(), strict=True)]
    if laser:
        return [*head, f"{profile.laser.on_command} S0", *body, "M5"]
    out = [*head, "M5"]
    draw = job.draw.tolist()
    n = len(draw)
    for k, line in enumerate(body):
        if draw[k] and (k == 0 or not draw[k - 1]):
            out.append("M3 S0")
        out.append(line)
        if draw[k] and (k == n - 1 or not draw[k + 1]):
            out.append("M5")
    if out[-1] != "M5":
        out.append("M5")
    return out


def write_atomic(path: str | Path, text: str) -> None:
    """Write text to `path` through a temporary file in the same folder and a rename, so a
    failure never leaves a half-written file."""
    import os
    import tempfile

    out = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp",
                               dir=str(out.parent) if str(out.parent) else ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
        os.replace(tmp, out)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
