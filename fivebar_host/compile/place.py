"""The first stages of a compile: the machine-side constants (`Setup`), the drawing placed in
machine mm and flattened (`Placed`), and the homed pose (`Home`); plus `fail`, which turns a
failed pose check anywhere in the pipeline into a `JobError` that names the source element,
its line, the point in drawing and machine coordinates, and a layout hint.

Flattening uses tol_f = tol/2 of the one tolerance `tol` (the budget is explained in
`fivebar_host.compile.job`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fivebar_host.compile import fill
from fivebar_host.compile.model import AUTO_ORDER, CompileOptions
from fivebar_host.compile.modes import mode_at
from fivebar_host.config import Profile
from fivebar_host.errors import JobError, OptionError, Where
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.geometry import Drawing, Polylines, flatten
from fivebar_host.toolpath.segment import CheckFailedError
from fivebar_host.toolpath.svg.reader import DEFAULT_MAX_SEGMENTS
from kinematics.arrays import FloatArray
from kinematics.fivebar import FiveBar

#: Flattened points allowed per path segment of `--max-segments` (curves flatten into a few
#: chords each; a huge arc at a fine tolerance into many).
POINTS_PER_SEGMENT = 4


@dataclass(frozen=True)
class Setup:
    """What one compile checks against: the profile, the working mode it places for, the
    tolerance budget (tol, tol_f = tol/2) and the checks' margins, limits and assembly."""

    profile: Profile
    mode: str
    tol: float
    tol_f: float
    min1: float
    min2: float
    limits: tuple[tuple[float, float], tuple[float, float]]
    asm: str  # the machine's assembly, "+" or "-"
    assembly: int  # the same as a sign, +1 or −1

    @property
    def fb(self) -> FiveBar:
        return self.profile.geometry


@dataclass(frozen=True)
class Placed:
    """The drawing as read, its placement, the placed drawing (machine mm) and its flattened
    strokes."""

    drawing: Drawing
    pl: layout.Placement
    mdraw: Drawing
    poly: Polylines

    def without_strokes(self) -> Placed:
        """This placement without its flattened strokes (only `route` reads them): frees
        their memory once the paths are ordered."""
        z = np.zeros(0, dtype=np.int64)
        return replace(self, poly=Polylines(np.zeros((0, 2)), np.zeros(1, dtype=np.int64), z,
                                            np.zeros(0), np.zeros(0), z))


@dataclass(frozen=True)
class Home:
    """The homed pose: joint angles (1, 2), pen position (2,) and its working mode."""

    th: FloatArray
    pt: FloatArray
    mode: str


def setup(profile: Profile, opts: CompileOptions, mode: str) -> Setup:
    """The tolerance (options, else the profile's; must be a positive number of mm) and the
    profile's margins, joint limits and assembly."""
    kin = profile.kinematics
    tol = float(opts.tolerance_mm if opts.tolerance_mm is not None
                else profile.motion.tolerance_mm)
    if not (math.isfinite(tol) and tol > 0):
        raise OptionError("tolerance", f"must be a positive number of mm; got {tol!r}")
    asm = kin.assembly
    return Setup(profile=profile, mode=mode, tol=tol, tol_f=tol / 2.0,
                 min1=kin.min_type1_margin_rad, min2=kin.min_type2_margin_rad,
                 limits=profile.motors.limits_rad, asm=asm, assembly=1 if asm == "+" else -1)


def place(su: Setup, drawing: Drawing, opts: CompileOptions, consume: bool = False) -> Placed:
    """Place the drawing for `su.mode` (`toolpath.layout`) and flatten it within tol_f.
    `consume`: the caller gives the drawing up, so it is placed in place (its primitives
    replaced by the placed ones; every other array is shared with the placed copy anyway)
    and a large drawing's primitives are not held twice."""
    pl = layout.place(drawing, su.fb, su.mode, su.min1, su.min2, su.limits,
                      origin_mm=opts.origin_mm, scale=opts.scale, rotate_deg=opts.rotate_deg,
                      fit=opts.fit, assembly=su.asm)
    mdraw = drawing.transformed(pl.matrix, pl.offset)
    if fill.wanted(opts):
        mdraw = fill.apply(mdraw, pl, su.tol, opts, su.profile, su.mode)
        inv = np.asarray(np.linalg.inv(pl.matrix), dtype=np.float64)  # the twin messages read
        drawing = mdraw.transformed(inv, -inv @ pl.offset)
    elif consume:
        drawing.params = mdraw.params
    limit = DEFAULT_MAX_SEGMENTS if opts.max_segments is None else int(opts.max_segments)
    return Placed(drawing=drawing, pl=pl, mdraw=mdraw,
                  poly=flatten(mdraw, su.tol_f, POINTS_PER_SEGMENT * limit))


def find_home(su: Setup, file: str) -> Home:
    """The homed pose in the machine's assembly (every pose must have it; the checker refuses
    a point that is only reachable in the other one)."""
    kin = su.profile.kinematics
    home = np.array(su.profile.motors.home_rad, dtype=np.float64).reshape(1, 2)
    home_fk = su.fb.forward_batch(home, su.asm)
    if not home_fk.valid[0]:  # pragma: no cover - the profile parser checks the homed pose
        raise JobError(f"the homed pose {np.degrees(home[0]).round(3).tolist()}° has no pen "
                       f"position in assembly {su.asm}",
                       Where(file=file, what="move from home"), "assembly")
    home_pt = home_fk.points[0]
    home_mode = mode_at(su.fb, home[0], home_pt,
                         kin.working_mode if kin.working_mode != "auto" else AUTO_ORDER[0])
    return Home(th=home, pt=home_pt, mode=home_mode)


def where_at(job_file: str, drawing: Drawing, pl: layout.Placement, point: tuple[float, float],
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


def fail(su: Setup, placed: Placed, cf: CheckFailedError, prim: int, what: str = "path",
         in_mode: str | None = None) -> JobError:
    """The `JobError` for a failed check on primitive `prim` (−1: unknown) in working mode
    `in_mode` (default: the mode placed for); reach, limit and margin failures add the
    layout's does-not-fit hint."""
    m = in_mode or su.mode
    w = where_at(placed.drawing.file, placed.drawing, placed.pl, cf.point, prim, what)
    msg = f"{cf.message} (working mode {m})"
    if cf.reason in ("reach", "joint_limit", "type1_margin", "type2_margin", "assembly"):
        msg += "; " + layout.does_not_fit_hint(placed.pl, su.fb, m, su.min1, su.min2,
                                               su.limits, su.asm)
    return JobError(msg, w, cf.reason)
