"""G2/G3 arcs in the XY plane (G17): the centre from I/J or R, the direction and the sweep,
the checks that the words describe an arc, then either the exact arc (the file reader keeps
arcs exact) or chords within a tolerance (the bridge streams straight moves).

- I/J: the centre, offsets from the start (G91.1) or coordinates (G90.1), is given; the end
  must lie on the circle through the start (GRBL gcode.c: within 0.005 mm, or 0.1 % of the
  radius up to 0.5 mm; the file reader: 0.005 mm or 0.1 %). An end equal to the start is a
  full circle (NIST RS274NGC §3.5.3).
- R: the centre is on the chord's perpendicular bisector, as GRBL computes it (gcode.c: h =
  √(4r² − x² − y²)/d): left of start → end for a G3 with R > 0 (the short way), right for a
  G2; R < 0 takes the long way. R must reach half the chord (`error:34`; the file reader
  allows `ArcRules.r_short_mm2` of slack) and the end must differ from the start.
- Sweep: G2 clockwise (negative), G3 counter-clockwise; an end at the start's angle (within
  `ArcRules.full_circle_rad`, or a chord shorter than `full_circle_chord_mm`) sweeps a full
  turn.

Where GRBL and the file reader check differently, `ArcRules` holds both choices.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from fivebar_host.gcode import errors
from fivebar_host.gcode.errors import GcodeError

Point = tuple[float, float]
TAU = 2 * math.pi


class ArcRules(NamedTuple):
    """How strictly a front door checks arc words (module doc)."""

    end_tol_mm: float  # an I/J arc's end may be this far off the circle ...
    end_tol_rel: float  # ... or this fraction of the radius ...
    end_tol_cap_mm: float  # ... but no more than this
    r_short_mm2: float  # an R arc needs 4r² − chord² ≥ −4·this
    same_point_mm: float  # an R arc's end nearer than this in X and Y is its start
    full_circle_rad: float  # a sweep within this of zero is a full turn ...
    full_circle_chord_mm: float  # ... and so is a chord shorter than this
    zero_radius_ok: bool  # an I/J centre at the start is accepted
    r_with_offsets_ok: bool  # R with I/J: R is used (GRBL); else refused


class ArcWords(NamedTuple):
    """What a G2/G3 move says about its arc: the direction, the centre from I/J in machine
    mm (None without them), the R word as written (None without it) and the mm per unit it
    is in, the rules."""

    clockwise: bool
    centre: Point | None
    r_word: float | None
    unit_mm: float
    rules: ArcRules


class Arc(NamedTuple):
    """An exact arc: centre, radius, start angle and signed sweep (radians, + = ccw)."""

    cx: float
    cy: float
    radius: float
    theta0: float
    sweep: float


def solve(start: Point, end: Point, words: ArcWords) -> Arc:
    """The arc from `start` to `end` that `words` describe, or `GcodeError` (module doc)."""
    rules = words.rules
    if words.r_word is not None:
        if words.centre is not None and not rules.r_with_offsets_ok:
            raise GcodeError(errors.UNUSED_WORDS, "arc with both R and I/J")
        r = words.r_word * words.unit_mm
        cx, cy = _r_centre(start, end, r, words, rules)
        radius = abs(r)
    else:
        if words.centre is None:
            raise GcodeError(errors.NO_OFFSETS_IN_PLANE, "arc without I/J or R")
        cx, cy = words.centre
        radius = _ij_radius(start, end, words.centre, rules)
    theta0 = math.atan2(start[1] - cy, start[0] - cx)
    sweep = math.atan2(end[1] - cy, end[0] - cx) - theta0
    eps = rules.full_circle_rad
    if words.clockwise and sweep >= -eps:
        sweep -= TAU
    elif not words.clockwise and sweep <= eps:
        sweep += TAU
    if sweep == 0.0 or math.hypot(end[0] - start[0], end[1] - start[1]) < \
            rules.full_circle_chord_mm:  # a zero sweep: the end angle was the start's ∓2π
        sweep = -TAU if words.clockwise else TAU
    return Arc(cx, cy, radius, theta0, sweep)


def _r_centre(start: Point, end: Point, r: float, words: ArcWords,
              rules: ArcRules) -> Point:
    """The centre of an R arc (GRBL gcode.c's radius mode)."""
    x0, y0 = start
    dx, dy = end[0] - x0, end[1] - y0
    tol = rules.same_point_mm
    if (dx == 0.0 and dy == 0.0) or (abs(dx) < tol and abs(dy) < tol):
        raise GcodeError(errors.INVALID_TARGET, "R-form arc with end = start (a full circle needs "
                                           "I/J)")
    h_x2 = 4.0 * r * r - dx * dx - dy * dy
    if h_x2 < -4.0 * rules.r_short_mm2:
        chord = math.hypot(dx, dy)
        raise GcodeError(errors.ARC_RADIUS_ERROR, f"arc radius R{words.r_word:g} is smaller than "
                                             f"half the chord ({chord / 2:.6g} mm)")
    h = -math.sqrt(max(h_x2, 0.0)) / math.hypot(dx, dy)
    if not words.clockwise:
        h = -h
    if r < 0:
        h = -h
    return (x0 + 0.5 * (dx - dy * h), y0 + 0.5 * (dy + dx * h))


def _ij_radius(start: Point, end: Point, centre: Point, rules: ArcRules) -> float:
    """The radius of an I/J arc, its end checked against the circle through its start."""
    cx, cy = centre
    radius = math.hypot(start[0] - cx, start[1] - cy)
    if radius == 0 and not rules.zero_radius_ok:
        raise GcodeError(errors.INVALID_TARGET, "arc with zero radius")
    off = abs(radius - math.hypot(end[0] - cx, end[1] - cy))
    if off > max(rules.end_tol_mm, min(rules.end_tol_cap_mm, rules.end_tol_rel * radius)):
        raise GcodeError(errors.INVALID_TARGET, f"arc end is {off:.4g} mm off the circle through "
                                           f"its start (r = {radius:.6g} mm)")
    return radius


def chords(arc: Arc, start: Point, end: Point, tol_mm: float) -> list[Point]:
    """The arc as chords, the points after `start` (the last is `end`): on the circle
    through `start`, as GRBL's mc_arc, each within `tol_mm` of it (sagitta
    r(1 − cos(δ/2)) ≤ tol)."""
    cx, cy, a0, sweep = arc.cx, arc.cy, arc.theta0, arc.sweep
    r = math.hypot(start[0] - cx, start[1] - cy)
    step = 2 * math.acos(max(-1.0, 1 - tol_mm / r)) if r > tol_mm else math.pi / 2
    n = max(1, math.ceil(abs(sweep) / max(step, 1e-6)))
    pts = [(cx + r * math.cos(a0 + sweep * k / n), cy + r * math.sin(a0 + sweep * k / n))
           for k in range(1, n)]
    return [*pts, end]
