"""`fivebar calibrate pattern`: the test pattern (SVG) and its marks file (JSON).

Where the marks go: over the largest connected safe region of the profile's working mode
(`kinematics.calibration_analysis.safe_grid`, the same safety as every job), eroded by
`EROSION_MM` so each cross fits; the first marks are the region's extremes, the rest are
placed where the fit would otherwise extrapolate (`design_marks`), so the region's edges,
where a wrong geometry shows most, are covered. That eroded region is "the pattern's region"
the drawing-shape error is measured over.

Each mark is a cross (four arms, each a stroke that starts at the centre, so the centre is a
target of the job even after dense input is simplified) with its number drawn beside it as
stroke digits (no <text>: the pen must draw them), the label on the side where it stays
inside the safe region and clear of the other marks.

The SVG is placed 1:1: its page bottom-left is machine (X0, Y0) mm, so it must be plotted
with `--origin X0,Y0 --mode MODE` (written into the SVG, the JSON and the command's output).
The steps in pattern.json are not computed apart from the plot: the pattern is compiled by
the plot's own pipeline (`compile_job` with that origin and mode) and each mark's steps are
read from the job's targets at the mark's centre — exactly what `fivebar plot` commands.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.compile import CompileOptions, Job, compile_job, write_atomic
from fivebar_host.config import ConfigError, Profile
from fivebar_host.errors import FivebarError
from kinematics.arrays import BoolArray, FloatArray
from kinematics.calibration import MachineParams
from kinematics.calibration_analysis import SafeGrid, design_marks, safe_grid
from kinematics.extension import ExtendedFiveBar

FORMAT = "fivebar-calibration-pattern/1"
CROSS_MM = 1.5  # half the length of a cross arm
EROSION_MM = 3.0  # mark centres keep this far inside the safe region (the cross + 1.5 mm)
DIGIT_W, DIGIT_H, DIGIT_GAP = 1.2, 2.4, 0.6  # mm
DEFAULT_COUNT = 30
MIN_COUNT = 25
SEEDS = 10  # marks placed by farthest-point sampling before the D-optimal ones
GRID_MM = 1.0
SPACING_MM = 9.0  # fewest mm between two mark centres (room for a number between them)

#: Stroke digits on a 1 × 2 box (x right, y up): polylines per digit.
DIGITS: dict[str, tuple[tuple[tuple[float, float], ...], ...]] = {
    "0": (((0, 0), (1, 0), (1, 2), (0, 2), (0, 0)),),
    "1": (((0.2, 1.6), (0.6, 2), (0.6, 0)),),
    "2": (((0, 2), (1, 2), (1, 1), (0, 1), (0, 0), (1, 0)),),
    "3": (((0, 2), (1, 2), (1, 0), (0, 0)), ((0, 1), (1, 1))),
    "4": (((0, 2), (0, 1), (1, 1)), ((1, 2), (1, 0))),
    "5": (((1, 2), (0, 2), (0, 1), (1, 1), (1, 0), (0, 0)),),
    "6": (((1, 2), (0, 2), (0, 0), (1, 0), (1, 1), (0, 1)),),
    "7": (((0, 2), (1, 2), (1, 0)),),
    "8": (((0, 0), (1, 0), (1, 2), (0, 2), (0, 0)), ((0, 1), (1, 1))),
    "9": (((1, 1), (0, 1), (0, 2), (1, 2), (1, 0), (0, 0)),),
}


class PatternError(FivebarError, ValueError):
    """A pattern that cannot be made (no room for the marks, a mark the job does not hit)."""


@dataclass(frozen=True)
class Mark:
    """One mark: its number, nominal centre (machine mm) and the plot's steps there."""

    ident: int
    x_mm: float
    y_mm: float
    steps: tuple[int, int]


@dataclass(frozen=True)
class Pattern:
    """The marks, the placement the SVG must be plotted with and the region they cover."""

    marks: list[Mark]
    origin_mm: tuple[float, float]
    page_mm: tuple[float, float]
    mode: str
    strokes: list[FloatArray]  # machine mm polylines, cross strokes and digits
    region: SafeGrid


def nominal_params(profile: Profile) -> MachineParams:
    """The profile's seven machine parameters. A pen off the joint (`[geometry] extension`)
    is refused: the calibration model has the pen at the joint (not done yet, issue 38)."""
    g = profile.geometry
    if isinstance(g, ExtendedFiveBar) and g.extension > 0.0:
        raise ConfigError(f"{profile.source}: calibration does not model a pen off the joint "
                          "([geometry] extension) yet; measure and set the lengths by hand")
    return MachineParams(g.a1, g.b1, g.a2, g.b2, g.w, *profile.motors.home_rad)


def pattern_mode(profile: Profile, mode: str | None) -> str:
    """The working mode the pattern is made for: the option, else the profile's (the first
    of --mode auto's order when the profile says auto)."""
    m = mode or profile.kinematics.working_mode
    return "+-" if m == "auto" else m


def pattern_region(profile: Profile, mode: str) -> SafeGrid:
    """The pattern's region: the safe region, eroded by `EROSION_MM` (module doc)."""
    k = profile.kinematics
    grid = safe_grid(nominal_params(profile), mode, k.min_type1_margin_rad,
                     k.min_type2_margin_rad, profile.motors.limits_rad, k.assembly, GRID_MM)
    return grid.eroded(EROSION_MM)


def digit_strokes(number: int, x0: float, y0: float) -> list[FloatArray]:
    """Polylines of `number` in stroke digits with the bottom-left at (x0, y0) mm."""
    out: list[FloatArray] = []
    s = DIGIT_H / 2.0
    for i, ch in enumerate(str(number)):
        dx = x0 + i * (DIGIT_W + DIGIT_GAP)
        for line in DIGITS[ch]:
            out.append(np.array([(dx + u * DIGIT_W, y0 + v * s) for u, v in line]))
    return out


def _inside(mask_grid: SafeGrid, pts: FloatArray) -> BoolArray:
    """Nearest-node lookup of points in a safe grid."""
    i = np.rint((pts[:, 0] - mask_grid.xs[0]) / GRID_MM).astype(int)
    j = np.rint((pts[:, 1] - mask_grid.ys[0]) / GRID_MM).astype(int)
    ok = (i >= 0) & (i < mask_grid.xs.size) & (j >= 0) & (j < mask_grid.ys.size)
    res = np.zeros(pts.shape[0], dtype=bool)
    res[ok] = mask_grid.mask[j[ok], i[ok]]
    return res


def _label_box(c: FloatArray, digits: int, side: tuple[float, float],
               gap: float) -> FloatArray:
    """Bottom-left and top-right of a label of `digits` digits on `side` of centre `c`,
    `gap` mm from it."""
    bw = digits * DIGIT_W + (digits - 1) * DIGIT_GAP
    x0 = c[0] + (gap if side[0] > 0 else -gap - bw if side[0] < 0 else -bw / 2)
    y0 = c[1] + (gap if side[1] > 0 else -gap - DIGIT_H if side[1] < 0 else -DIGIT_H / 2)
    return np.array([[x0, y0], [x0 + bw, y0 + DIGIT_H]])


SIDES = ((1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (-1, 1), (-1, -1), (1, -1))


def _place_label(c: FloatArray, digits: int, safe: SafeGrid, taken: list[FloatArray]) -> FloatArray:
    """The first label box (SIDES order, nearest first) inside the safe region and ≥ 0.8 mm
    from every box in `taken` (crosses and labels placed so far)."""
    for gap in (CROSS_MM + 1.0, CROSS_MM + 3.0, CROSS_MM + 6.0):
        for side in SIDES:
            box = _label_box(c, digits, side, gap)
            u, v = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 3))
            corners = box[0] + np.stack((u.ravel(), v.ravel()), axis=1) * (box[1] - box[0])
            if not _inside(safe, corners).all():
                continue
            if all(np.any(box[0] > t[1] + 0.8) or np.any(t[0] > box[1] + 0.8)
                   for t in taken):
                return box
    raise PatternError(f"no room for the number of the mark at ({c[0]:.1f}, {c[1]:.1f}) mm "
                       "inside the safe region; make fewer marks (--count)")


def _label_fits(cands: FloatArray, safe: SafeGrid, digits: int = 2) -> BoolArray:
    """Which candidate centres have room for a `digits`-digit label on some side (the
    nearest gap) inside the safe region — a mark in a narrow cusp has none."""
    u, v = np.meshgrid(np.linspace(0, 1, 4), np.linspace(0, 1, 3))
    grid = np.stack((u.ravel(), v.ravel()), axis=1)
    fits = np.zeros(cands.shape[0], dtype=bool)
    for side in SIDES:
        ok = np.ones(cands.shape[0], dtype=bool)
        for g in grid:
            box = np.array([_label_box(c, digits, side, CROSS_MM + 1.0) for c in cands[:1]])
            size = box[0, 1] - box[0, 0]
            off = box[0, 0] - cands[0]
            ok &= _inside(safe, cands + off + g * size)
        fits |= ok
    return fits


def layout_marks(profile: Profile, mode: str, count: int) -> tuple[FloatArray, list[FloatArray],
                                                                    SafeGrid]:
    """Mark centres (N, 2) numbered row by row from the top, their strokes, the region."""
    k = profile.kinematics
    region = pattern_region(profile, mode)
    full = safe_grid(nominal_params(profile), mode, k.min_type1_margin_rad,
                     k.min_type2_margin_rad, profile.motors.limits_rad, k.assembly,
                     GRID_MM).eroded(1.5)  # labels keep 1.5 mm inside too
    cand = region.points()
    cand = cand[_label_fits(cand, full)]
    if cand.shape[0] < 4 * count:
        raise PatternError(f"the safe region of mode {mode} has room for too few marks "
                           f"({cand.shape[0]} candidate positions for {count} marks)")
    try:
        centres = design_marks(nominal_params(profile), cand, count, SEEDS,
                               profile.motors.rad_per_step, mode, k.assembly, SPACING_MM)
    except ValueError as e:
        raise PatternError(f"working mode {mode}: {e} in the safe region; make fewer marks "
                           "(--count)") from e
    order = np.lexsort((centres[:, 0], -np.floor(centres[:, 1] / 15.0)))
    centres = centres[order]
    taken = [np.array([c - CROSS_MM, c + CROSS_MM]) for c in centres]
    strokes: list[FloatArray] = []
    for n, c in enumerate(centres, start=1):
        for arm in (np.array([CROSS_MM, 0.0]), np.array([0.0, CROSS_MM])):
            # each arm starts at the centre: a stroke's end is a target of the job even
            # after dense input is simplified (a collinear middle vertex would not be)
            strokes.extend((np.array([c, c + arm]), np.array([c, c - arm])))
        box = _place_label(c, len(str(n)), full, taken)
        taken.append(box)
        strokes.extend(digit_strokes(n, float(box[0, 0]), float(box[0, 1])))
    return centres, strokes, region


def svg_text(strokes: list[FloatArray], origin: tuple[float, float], page: tuple[float, float],
             note: str) -> str:
    """The SVG (mm, viewBox 1:1; y flipped: SVG y = page height − (y − Y0))."""
    x0, y0 = origin
    w, h = page
    paths = []
    for s in strokes:
        pts = " L ".join(f"{x - x0:.3f} {h - (y - y0):.3f}" for x, y in s)
        paths.append(f'    <path d="M {pts}"/>')
    return ("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:g}mm" height="{h:g}mm" '
            f'viewBox="0 0 {w:g} {h:g}">\n'
            "  <title>fivebar calibration pattern</title>\n"
            f"  <desc>{note}</desc>\n"
            '  <g fill="none" stroke="black" stroke-width="0.3">\n'
            + "\n".join(paths) + "\n  </g>\n</svg>\n")


def steps_at(job: Job, centres: FloatArray) -> list[tuple[int, int]]:
    """The job's commanded steps at each mark centre (a target of both its cross strokes)."""
    out = []
    for n, c in enumerate(centres, start=1):
        hit = np.flatnonzero(np.max(np.abs(job.points_mm - c), axis=1) < 1e-6)
        hit = hit[hit > 0]
        if hit.size == 0:
            raise PatternError(f"mark {n} at ({c[0]:.3f}, {c[1]:.3f}) mm is not a target of "
                               "the compiled pattern")
        st = {(int(job.steps[i, 0]), int(job.steps[i, 1])) for i in hit}
        if len(st) != 1:
            raise PatternError(f"mark {n}: the compiled pattern reaches its centre with "
                               f"different steps {sorted(st)}")
        out.append(st.pop())
    return out


def make_pattern(profile: Profile, svg_path: Path, *, mode: str | None = None,
                 count: int = DEFAULT_COUNT) -> Pattern:
    """Lay out the marks, write the SVG and compile it the way `fivebar plot` will."""
    if count < MIN_COUNT:
        raise PatternError(f"--count {count}: a pattern has at least {MIN_COUNT} marks")
    m = pattern_mode(profile, mode)
    centres, strokes, region = layout_marks(profile, m, count)
    allpts = np.concatenate(strokes)
    x0, y0 = (float(math.floor(v)) - 2.0 for v in allpts.min(axis=0))
    x1, y1 = (float(math.ceil(v)) + 2.0 for v in allpts.max(axis=0))
    origin, page = (x0, y0), (x1 - x0, y1 - y0)
    note = (f"fivebar calibration pattern, {count} marks, working mode {m}: plot 1:1 with "
            f"--origin {x0:g},{y0:g} --mode {m} (page bottom-left at machine ({x0:g}, {y0:g}) "
            f"mm) and the profile {profile.source}")
    write_atomic(svg_path, svg_text(strokes, origin, page, note))
    job = compile_job(svg_path, profile, CompileOptions(origin_mm=origin, mode=m,
                                                        validate=False))
    steps = steps_at(job, centres)
    marks = [Mark(n, float(c[0]), float(c[1]), s)
             for n, (c, s) in enumerate(zip(centres, steps, strict=True), start=1)]
    return Pattern(marks, origin, page, m, strokes, region)


def plot_command(svg: Path, profile: Profile, pattern: Pattern) -> str:
    """The command that plots the pattern as the marks file assumes."""
    return (f"fivebar plot {svg} --config {profile.source} --origin "
            f"{pattern.origin_mm[0]:g},{pattern.origin_mm[1]:g} --mode {pattern.mode} "
            "--port PORT")


def marks_document(profile: Profile, pattern: Pattern, svg: Path) -> dict[str, Any]:
    """The pattern.json document."""
    return {
        "format": FORMAT,
        "profile": profile.source,
        "svg": str(svg),
        "plot_command": plot_command(svg, profile, pattern),
        "origin_mm": list(pattern.origin_mm),
        "mode": pattern.mode,
        "assembly": profile.kinematics.assembly,
        "steps_per_rev": profile.motors.steps_per_rev,
        "home_deg": [math.degrees(v) for v in profile.motors.home_rad],
        "erosion_mm": EROSION_MM,
        "marks": [{"id": mk.ident, "steps": list(mk.steps), "x_mm": mk.x_mm, "y_mm": mk.y_mm}
                  for mk in pattern.marks],
    }


def write_marks(path: Path, doc: dict[str, Any]) -> None:
    """Write pattern.json."""
    write_atomic(path, json.dumps(doc, indent=1) + "\n")
