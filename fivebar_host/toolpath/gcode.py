"""Cartesian G-code reader (as written by common CAM and laser tools) → exact primitives.

Honoured: G0/G1 lines, G2/G3 arcs (I/J centre offsets, or R with R < 0 meaning the long way
round; a full circle when the end equals the start with I/J), G17 (the XY plane), G20/G21
(inch/mm), G90/G91 (absolute/relative distances), G90.1/G91.1 (absolute/relative arc
centres), G92 (set the current position, shifting the coordinate frame), G94 (feed per
minute), G54 (the default frame, no-op), M3/M4 with S (laser/spindle on), M5 (off), M2/M30
(end of program: later lines are ignored), F (feed, units/min), comments `(…)` and `; …`,
line numbers `N…`, checksums `*…` and `%` lines.

What draws: a G1/G2/G3 move while the laser is on (M3/M4 active with S > 0) — or, in a file
with no M3/M4 at all (pen-plotter style), every G1/G2/G3 move. G0 moves and moves with the
laser off are travel: the job compiler plans its own travel, so their geometry is not kept.

Anything else (Z or other axes, G18/G19, G28, G4, tool changes, unknown words, a bad number)
is an `InputError` naming the file, the line and the word: it is refused, never ignored.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import (
    ARC,
    LINE,
    MAX_COORD_MM,
    Drawing,
    DrawingBuilder,
    read_source,
)

_WORD = re.compile(r"([A-Za-z])\s*([+-]?(?:\d+\.?\d*|\.\d+))")
_PAREN = re.compile(r"\([^)]*\)")

#: G codes that are accepted; values are what they select.
_G_OK = {0.0, 1.0, 2.0, 3.0, 17.0, 20.0, 21.0, 90.0, 91.0, 90.1, 91.1, 92.0, 94.0, 54.0}
_M_OK = {2.0, 3.0, 4.0, 5.0, 30.0}

#: An arc's end must lie on its circle to within this (absolute mm, or relative to r).
ARC_END_TOL_MM = 0.005
ARC_END_TOL_REL = 1e-3


def _strip(raw: str, file: str, ln: int) -> str:
    """Remove comments, a checksum and the line number; return the words part."""
    s = raw
    if ";" in s:
        s = s.split(";", 1)[0]
    if "(" in s:
        if s.count("(") != s.count(")"):
            raise InputError("unbalanced parenthesis comment", file, ln)
        s = _PAREN.sub(" ", s)
    if "*" in s:
        s = s.split("*", 1)[0]
    return s.strip()


def read_gcode(source: str | Path | bytes, file: str | None = None) -> Drawing:
    """Read a G-code file (path or bytes) into a `Drawing` in mm (frame as written, y up)."""
    data, name = read_source(source, file, "<gcode>")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"not a text file (byte {e.start} is not UTF-8)", name) from e
    lines = text.splitlines()
    has_laser = any(re.search(r"(?<![A-Za-z])[Mm]\s*0*[34](?![\d.])", _strip_soft(s))
                    for s in lines)
    b = DrawingBuilder(name)

    unit = 1.0  # mm per file unit
    absolute = True
    arc_abs = False
    motion = -1.0  # no motion mode until the first G0-G3
    laser_on = False
    power_s = 0.0
    feed_mm_s = math.nan
    pos = (0.0, 0.0)  # current position, mm, in the drawing frame
    offset = (0.0, 0.0)  # G92: drawing = file coordinate (mm) + offset
    stroke_open = False
    stroke_key: tuple[float, float] | None = None
    max_s = 0.0

    for ln, raw in enumerate(lines, start=1):
        s = _strip(raw, name, ln)
        if not s or s == "%":
            continue
        words: list[tuple[str, float, str]] = []
        pos_in = 0
        for m in _WORD.finditer(s):
            gap = s[pos_in:m.start()]
            if gap.strip():
                raise InputError(f"cannot read {gap.strip()!r}", name, ln)
            letter = m.group(1).upper()
            value = float(m.group(2))
            words.append((letter, value, m.group(0).replace(" ", "")))
            pos_in = m.end()
        rest = s[pos_in:]
        if rest.strip():
            raise InputError(f"cannot read {rest.strip()!r}", name, ln)
        axes: dict[str, float] = {}
        gs: list[float] = []
        ms: list[float] = []
        for letter, value, tok in words:
            if not math.isfinite(value):
                raise InputError(f"{tok}: not a finite number", name, ln)
            if letter == "N":
                continue
            if letter == "G":
                if round(value, 1) not in _G_OK:
                    raise InputError(f"unsupported G-code word {tok} (supported: G0 G1 G2 G3 "
                                     "G17 G20 G21 G54 G90 G91 G90.1 G91.1 G92 G94)", name, ln)
                gs.append(round(value, 1))
            elif letter == "M":
                if value not in _M_OK:
                    raise InputError(f"unsupported M-code word {tok} (supported: M2 M3 M4 M5 "
                                     "M30)", name, ln)
                ms.append(value)
            elif letter in ("X", "Y", "I", "J", "R", "F", "S"):
                if letter in axes:
                    raise InputError(f"word {letter} appears twice", name, ln)
                axes[letter] = value
            elif letter in ("Z", "A", "B", "C", "U", "V", "W"):
                raise InputError(f"unsupported axis word {tok}: this machine draws in X and Y "
                                 "only (the pen or laser follows M3/M5)", name, ln)
            else:
                raise InputError(f"unsupported word {tok}", name, ln)

        end_program = False
        for g in gs:
            if g == 20.0:
                unit = 25.4
            elif g == 21.0:
                unit = 1.0
            elif g == 90.0:
                absolute = True
            elif g == 91.0:
                absolute = False
            elif g == 90.1:
                arc_abs = True
            elif g == 91.1:
                arc_abs = False
        if "F" in axes:
            if axes["F"] <= 0:
                raise InputError(f"feed F{axes['F']:g} must be positive", name, ln)
            feed_mm_s = axes["F"] * unit / 60.0
        if "S" in axes:
            if axes["S"] < 0:
                raise InputError(f"power S{axes['S']:g} must not be negative", name, ln)
            power_s = axes["S"]
            max_s = max(max_s, power_s)
        for mcode in ms:
            if mcode in (3.0, 4.0):
                laser_on = True
            elif mcode == 5.0:
                laser_on = False
            else:
                end_program = True

        if 92.0 in gs:
            if not ({"X", "Y"} & axes.keys()):
                raise InputError("G92 needs X and/or Y", name, ln)
            # G92 X.. Y..: the current point now has these file coordinates.
            fx = axes.get("X", (pos[0] - offset[0]) / unit) * unit
            fy = axes.get("Y", (pos[1] - offset[1]) / unit) * unit
            offset = (pos[0] - fx, pos[1] - fy)
            if {"I", "J", "R"} & axes.keys():
                raise InputError("G92 with I, J or R", name, ln)
            if any(g in (0.0, 1.0, 2.0, 3.0) for g in gs):
                raise InputError("G92 and a motion command on the same line", name, ln)
            continue
        motions = [g for g in gs if g in (0.0, 1.0, 2.0, 3.0)]
        if len(motions) > 1:
            raise InputError("more than one motion command on one line", name, ln)
        if motions:
            motion = motions[0]
        if not ({"X", "Y", "I", "J", "R"} & axes.keys()):
            if end_program:
                break
            continue
        if motion < 0:
            raise InputError("coordinates before any G0/G1/G2/G3", name, ln)

        x = _target(axes, "X", pos[0], offset[0], unit, absolute)
        y = _target(axes, "Y", pos[1], offset[1], unit, absolute)
        if max(abs(x), abs(y)) > MAX_COORD_MM:
            raise InputError(f"coordinate ({x:g}, {y:g}) mm is larger than {MAX_COORD_MM:g} "
                             "mm", name, ln)
        cutting = motion != 0.0 and (laser_on and power_s > 0 if has_laser else True)
        if motion in (0.0, 1.0) and {"I", "J", "R"} & axes.keys():
            raise InputError(f"I, J or R on a G{int(motion)} move", name, ln)
        if cutting:
            key = (power_s, feed_mm_s)
            if not stroke_open or key != stroke_key:
                src = b.add_source(None, ln, "gcode")
                b.begin_stroke(src, power=power_s, feed_mm_s=feed_mm_s)
                stroke_open = True
                stroke_key = key
            if motion == 1.0:
                if (x, y) != pos:
                    b.add(LINE, (pos[0], pos[1], x, y), ln)
            else:
                prim = _arc(pos, (x, y), axes, unit, arc_abs, offset, motion == 2.0, name, ln)
                b.add(ARC, prim, ln)
        else:
            stroke_open = False
        pos = (x, y)
        if end_program:
            break

    drawing = b.build()
    if drawing.kind.shape[0] == 0:
        raise InputError("no cutting moves to draw (G1/G2/G3 with the laser on, M3/M4 S>0)",
                         name)
    # Powers as fractions of the file's largest S (the profile's power is full scale).
    if max_s > 0:
        drawing.stroke_power[:] = drawing.stroke_power / max_s
    else:
        drawing.stroke_power[:] = 1.0
    return drawing


def _target(axes: dict[str, float], letter: str, cur: float, off: float, unit: float,
            absolute: bool) -> float:
    """New coordinate (mm, drawing frame) of one axis for a move."""
    if letter not in axes:
        return cur
    v = axes[letter] * unit
    return v + off if absolute else cur + v


def _strip_soft(raw: str) -> str:
    s = raw.split(";", 1)[0]
    return _PAREN.sub(" ", s)


def _arc(p0: tuple[float, float], p1: tuple[float, float], axes: dict[str, float], unit: float,
         arc_abs: bool, offset: tuple[float, float], clockwise: bool, file: str,
         ln: int) -> tuple[float, ...]:
    """G2/G3 arc from p0 to p1 (mm) as an ARC primitive (c, r·I, θ0, Δθ)."""
    x0, y0 = p0
    x1, y1 = p1
    if "R" in axes:
        if "I" in axes or "J" in axes:
            raise InputError("arc with both R and I/J", file, ln)
        r = axes["R"] * unit
        dx, dy = x1 - x0, y1 - y0
        chord = math.hypot(dx, dy)
        if chord == 0:
            raise InputError("R-form arc with end = start (a full circle needs I/J)", file, ln)
        h2 = r * r - chord * chord / 4
        if h2 < -(ARC_END_TOL_MM**2) - 1e-12:
            raise InputError(f"arc radius R{axes['R']:g} is smaller than half the chord "
                             f"({chord / 2:.6g} mm)", file, ln)
        h = math.sqrt(max(h2, 0.0))
        # Centre left of p0→p1 for a counter-clockwise short arc; R < 0 takes the long way.
        side = (1.0 if not clockwise else -1.0) * (1.0 if r > 0 else -1.0)
        cx = (x0 + x1) / 2 - side * h * dy / chord
        cy = (y0 + y1) / 2 + side * h * dx / chord
        radius = abs(r)
    else:
        if "I" not in axes and "J" not in axes:
            raise InputError("arc without I/J or R", file, ln)
        i, j = axes.get("I", 0.0) * unit, axes.get("J", 0.0) * unit
        if arc_abs:
            cx, cy = i + offset[0], j + offset[1]
        else:
            cx, cy = x0 + i, y0 + j
        radius = math.hypot(x0 - cx, y0 - cy)
        r_end = math.hypot(x1 - cx, y1 - cy)
        if radius == 0:
            raise InputError("arc with zero radius", file, ln)
        if abs(radius - r_end) > max(ARC_END_TOL_MM, ARC_END_TOL_REL * radius):
            raise InputError(f"arc end is {abs(radius - r_end):.4g} mm off the circle through "
                             f"its start (r = {radius:.6g} mm)", file, ln)
    th0 = math.atan2(y0 - cy, x0 - cx)
    th1 = math.atan2(y1 - cy, x1 - cx)
    dth = -((th0 - th1) % (2 * math.pi)) if clockwise else (th1 - th0) % (2 * math.pi)
    if dth == 0.0 or (math.hypot(x1 - x0, y1 - y0) < 1e-12):
        dth = -2 * math.pi if clockwise else 2 * math.pi
    return (cx, cy, radius, 0.0, 0.0, radius, th0, dth)
