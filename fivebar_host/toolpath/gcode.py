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

Dwells: `G4 P<seconds>` as GRBL 1.1 reads it (P in seconds, a decimal allowed; LinuxCNC
agrees; Marlin's P in milliseconds and S in seconds are not followed: S is the laser power
word here, so a Marlin `G4 S2` is refused for want of P). The machine waits there with the
tool as it is at that line: on (a laser at the current S burns a dot, as GRBL's M3 does; a
pen stays down) when a G1 move would cut now — the motion mode is G1/G2/G3 and, in a file with
M3/M4, `M3` is on with S > 0 (`M4` is GRBL's dynamic power, zero at rest: off) — else off. A
dwell ends the stroke it follows (`geometry.Dwell`: after a stroke's end, or before the start
of the stroke that begins where it was read); one with the tool off between strokes waits at
the end of the stroke before it. A dwell with the tool on where no cut starts or ends is
refused: fivebar plans its own travel, so it has no such point to burn.

Z words need the machine's tool (`read_gcode(..., tool=, z_threshold_mm=)`, from the
profile's `[tool] kind` and `[pen] z_threshold_mm`; without a tool they are refused):

- pen: Z sets the pen state. Z above the threshold is pen up (later moves are travel), Z at
  or below it pen down (later G1/G2/G3 moves draw), as pen-plotter G-code (vpype-gcode,
  Inkscape gcodetools: `G0 Z5` / `G1 Z0`) gives it. Before the first Z the pen follows the
  rules above alone. Combined with M3/M5: in a file with M3/M4 a move draws when the pen is
  down *and* M3/M4 is on (an `M3` with no S word yet counts as on: gcodetools' header); a
  file without M3/M4 follows Z alone. A Z word on a line with X/Y: the pen state changes at
  the start of that move (`G1 X10 Z0` draws to X10; `G0 X10 Z5` travels pen up).
- laser: Z cannot be followed. A Z word that changes nothing (the same Z, or a move with the
  laser off or a G0) is accepted and ignored, with one warning for the file; a Z change on a
  move that burns (G1/G2/G3 with the laser on, `M3` S > 0) is refused with its line. The
  first Z word sets the reference height.

Z follows G20/G21 and G90/G91 like X and Y; `G92 Z` is refused.

Anything else (other axes, G18/G19, G28, tool changes, unknown words, a bad number) is an
`InputError` naming the file, the line and the word: it is refused, never ignored.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import (
    ARC,
    LINE,
    MAX_COORD_MM,
    Drawing,
    DrawingBuilder,
    Dwell,
    read_source,
)

_WORD = re.compile(r"([A-Za-z])\s*([+-]?(?:\d+\.?\d*|\.\d+))")
_PAREN = re.compile(r"\([^)]*\)")
_LASER_ON = re.compile(r"(?<![A-Za-z])[Mm]\s*0*[34](?![\d.])")

#: G codes that are accepted; values are what they select.
_G_OK = {0.0, 1.0, 2.0, 3.0, 4.0, 17.0, 20.0, 21.0, 90.0, 91.0, 90.1, 91.1, 92.0, 94.0, 54.0}
_M_OK = {2.0, 3.0, 4.0, 5.0, 30.0}
_MOTIONS = (0.0, 1.0, 2.0, 3.0)
#: Words that carry a value for this line (coordinates, arc centre or radius, feed, power).
_VALUE_WORDS = ("X", "Y", "I", "J", "R", "F", "S", "P")
#: Axis words of other machines: refused with a hint.
_OTHER_AXES = ("Z", "A", "B", "C", "U", "V", "W")

#: An arc's end must lie on its circle to within this (absolute mm, or relative to r).
ARC_END_TOL_MM = 0.005
ARC_END_TOL_REL = 1e-3


@dataclass
class _Words:
    """The words of one line, sorted by kind: value words, G codes and M codes in order."""

    axes: dict[str, float] = field(default_factory=dict)
    gs: list[float] = field(default_factory=list)
    ms: list[float] = field(default_factory=list)

    def has(self, *letters: str) -> bool:
        """Whether any of ``letters`` is among the value words."""
        return any(letter in self.axes for letter in letters)


@dataclass
class _Reader:
    """The reader's state while it goes through a file: the modal state of the G-code
    interpreter (units, distance modes, motion mode, laser, feed, position, G92 offset), the
    stroke being drawn and the drawing being built."""

    builder: DrawingBuilder
    name: str
    has_laser: bool  # any M3/M4 in the file: only moves with the laser on draw
    unit: float = 1.0  # mm per file unit
    absolute: bool = True
    arc_abs: bool = False
    motion: float = -1.0  # no motion mode until the first G0-G3
    laser_on: bool = False
    laser_m4: bool = False  # M4 (dynamic power: off at rest, so during a dwell)
    power_s: float = 0.0
    feed_mm_s: float = math.nan
    pos: tuple[float, float] = (0.0, 0.0)  # current position, mm, in the drawing frame
    offset: tuple[float, float] = (0.0, 0.0)  # G92: drawing = file coordinate (mm) + offset
    stroke_open: bool = False
    stroke_key: tuple[float, float] | None = None
    max_s: float = 0.0
    last_stroke: int = -1  # the stroke that got the last primitive
    at_stroke_end: bool = False  # the position is that stroke's end
    pending: list[tuple[Dwell, int]] = field(default_factory=list)  # not yet placed, line
    tool: str | None = None  # "pen", "laser", or None: Z words refused
    z_threshold_mm: float = 0.0  # pen: Z above this is pen up
    z_mm: float | None = None  # the last Z, mm (None until a Z word)
    pen_down: bool | None = None  # pen: from Z (None until a Z word: Z does not decide)
    s_given: bool = False  # an S word was read
    z_warned: bool = False  # the laser's "Z ignored" warning was given


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


def read_gcode(source: str | Path | bytes, file: str | None = None, tool: str | None = None,
               z_threshold_mm: float = 0.0) -> Drawing:
    """Read a G-code file (path or bytes) into a `Drawing` in mm (frame as written, y up).

    `tool` ("pen" or "laser", the profile's `[tool] kind`) and `z_threshold_mm` (the
    profile's `[pen] z_threshold_mm`) decide what Z words mean (module doc); with no tool a Z
    word is refused."""
    if tool not in (None, "pen", "laser"):
        raise ValueError(f"tool must be 'pen', 'laser' or None; got {tool!r}")
    data, name = read_source(source, file, "<gcode>")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"not a text file (byte {e.start} is not UTF-8)", name) from e
    lines = text.splitlines()
    has_laser = any(_LASER_ON.search(_strip_soft(s)) for s in lines)
    rd = _Reader(DrawingBuilder(name), name, has_laser, tool=tool,
                 z_threshold_mm=z_threshold_mm)
    for ln, raw in enumerate(lines, start=1):
        if _read_line(rd, raw, ln):
            break
    return _finish(rd)


def _read_line(rd: _Reader, raw: str, ln: int) -> bool:
    """Interpret one line; True at the end of the program (M2/M30: later lines are ignored)."""
    s = _strip(raw, rd.name, ln)
    if not s or s == "%":
        return False
    w = _classify(_tokens(s, rd.name, ln), rd.name, ln, rd.tool is not None)
    end_program = _apply_modal(rd, w, ln)
    if 92.0 in w.gs:
        _apply_g92(rd, w, ln)
        return False
    _select_motion(rd, w, ln)
    if 4.0 in w.gs or "P" in w.axes:
        if "Z" in w.axes:
            raise InputError("G4 and a Z move on the same line", rd.name, ln)
        _dwell(rd, w, ln)
        return end_program
    if "Z" in w.axes:
        _z_move(rd, w, ln)
    if not w.has("X", "Y", "I", "J", "R"):
        return end_program
    if rd.motion < 0:
        raise InputError("coordinates before any G0/G1/G2/G3", rd.name, ln)
    _move(rd, w, ln)
    return end_program


def _tokens(s: str, file: str, ln: int) -> list[tuple[str, float, str]]:
    """The words of a stripped line as (upper-case letter, value, word as written without
    spaces); anything between or after the words is an error."""
    words: list[tuple[str, float, str]] = []
    pos_in = 0
    for m in _WORD.finditer(s):
        gap = s[pos_in:m.start()]
        if gap.strip():
            raise InputError(f"cannot read {gap.strip()!r}", file, ln)
        words.append((m.group(1).upper(), float(m.group(2)), m.group(0).replace(" ", "")))
        pos_in = m.end()
    rest = s[pos_in:]
    if rest.strip():
        raise InputError(f"cannot read {rest.strip()!r}", file, ln)
    return words


def _classify(words: list[tuple[str, float, str]], file: str, ln: int,
              z_ok: bool = False) -> _Words:
    """Sort a line's words into G codes, M codes and value words, refusing what this reader
    does not honour (in the order the words appear; Z only with `z_ok`)."""
    w = _Words()
    for letter, value, tok in words:
        if not math.isfinite(value):
            raise InputError(f"{tok}: not a finite number", file, ln)
        if letter == "N":
            continue
        if letter == "G":
            w.gs.append(_g_code(value, tok, file, ln))
        elif letter == "M":
            w.ms.append(_m_code(value, tok, file, ln))
        elif letter in _VALUE_WORDS or (letter == "Z" and z_ok):
            if letter in w.axes:
                raise InputError(f"word {letter} appears twice", file, ln)
            w.axes[letter] = value
        elif letter in _OTHER_AXES:
            raise InputError(f"unsupported axis word {tok}: this machine draws in X and Y "
                             "only (the pen or laser follows M3/M5)", file, ln)
        else:
            raise InputError(f"unsupported word {tok}", file, ln)
    return w


def _g_code(value: float, tok: str, file: str, ln: int) -> float:
    """A supported G code's number (rounded to one decimal: G90.1), else an error."""
    g = round(value, 1)
    if g not in _G_OK:
        raise InputError(f"unsupported G-code word {tok} (supported: G0 G1 G2 G3 G4 "
                         "G17 G20 G21 G54 G90 G91 G90.1 G91.1 G92 G94)", file, ln)
    return g


def _m_code(value: float, tok: str, file: str, ln: int) -> float:
    """A supported M code's number, else an error."""
    if value not in _M_OK:
        raise InputError(f"unsupported M-code word {tok} (supported: M2 M3 M4 M5 "
                         "M30)", file, ln)
    return value


def _apply_modal(rd: _Reader, w: _Words, ln: int) -> bool:
    """Apply a line's modal words (G units and distance modes, F, S, M); True for M2/M30."""
    for g in w.gs:
        _apply_g_mode(rd, g)
    if "F" in w.axes:
        if w.axes["F"] <= 0:
            raise InputError(f"feed F{w.axes['F']:g} must be positive", rd.name, ln)
        rd.feed_mm_s = w.axes["F"] * rd.unit / 60.0
    if "S" in w.axes:
        if w.axes["S"] < 0:
            raise InputError(f"power S{w.axes['S']:g} must not be negative", rd.name, ln)
        rd.power_s = w.axes["S"]
        rd.s_given = True
        rd.max_s = max(rd.max_s, rd.power_s)
    end_program = False
    for mcode in w.ms:
        if mcode in (3.0, 4.0):
            rd.laser_on = True
            rd.laser_m4 = mcode == 4.0
        elif mcode == 5.0:
            rd.laser_on = False
        else:
            end_program = True
    return end_program


def _apply_g_mode(rd: _Reader, g: float) -> None:
    """G20/G21 units, G90/G91 distances, G90.1/G91.1 arc centres; other G codes: nothing."""
    if g == 20.0:
        rd.unit = 25.4
    elif g == 21.0:
        rd.unit = 1.0
    elif g == 90.0:
        rd.absolute = True
    elif g == 91.0:
        rd.absolute = False
    elif g == 90.1:
        rd.arc_abs = True
    elif g == 91.1:
        rd.arc_abs = False


def _apply_g92(rd: _Reader, w: _Words, ln: int) -> None:
    """G92 X.. Y..: the current point now has these file coordinates."""
    if not w.has("X", "Y"):
        raise InputError("G92 needs X and/or Y", rd.name, ln)
    pos, offset, unit = rd.pos, rd.offset, rd.unit
    fx = w.axes.get("X", (pos[0] - offset[0]) / unit) * unit
    fy = w.axes.get("Y", (pos[1] - offset[1]) / unit) * unit
    rd.offset = (pos[0] - fx, pos[1] - fy)
    if w.has("I", "J", "R", "Z"):
        raise InputError("G92 with I, J, R or Z", rd.name, ln)
    if any(g in _MOTIONS for g in w.gs):
        raise InputError("G92 and a motion command on the same line", rd.name, ln)


def _select_motion(rd: _Reader, w: _Words, ln: int) -> None:
    """A G0-G3 word sets the motion mode (at most one per line)."""
    motions = [g for g in w.gs if g in _MOTIONS]
    if len(motions) > 1:
        raise InputError("more than one motion command on one line", rd.name, ln)
    if motions:
        rd.motion = motions[0]


def _move(rd: _Reader, w: _Words, ln: int) -> None:
    """A move to the line's X/Y in the current motion mode: drawn when it cuts, else travel
    (which ends the stroke)."""
    x = _target(w.axes, "X", rd.pos[0], rd.offset[0], rd.unit, rd.absolute)
    y = _target(w.axes, "Y", rd.pos[1], rd.offset[1], rd.unit, rd.absolute)
    if max(abs(x), abs(y)) > MAX_COORD_MM:
        raise InputError(f"coordinate ({x:g}, {y:g}) mm is larger than {MAX_COORD_MM:g} "
                         "mm", rd.name, ln)
    motion = rd.motion
    cutting = motion != 0.0 and _tool_on(rd)
    if motion in (0.0, 1.0) and w.has("I", "J", "R"):
        raise InputError(f"I, J or R on a G{int(motion)} move", rd.name, ln)
    if cutting:
        _draw(rd, w, (x, y), ln)
    else:
        rd.stroke_open = False
        if (x, y) != rd.pos:
            _leave(rd)
    rd.pos = (x, y)


def _draw(rd: _Reader, w: _Words, end: tuple[float, float], ln: int) -> None:
    """Add a cutting G1/G2/G3 move to the drawing, starting a stroke when the power or the
    feed changed (or none is open)."""
    key = (rd.power_s, rd.feed_mm_s)
    b = rd.builder
    if not rd.stroke_open or key != rd.stroke_key:
        src = b.add_source(None, ln, "gcode")
        b.begin_stroke(src, power=rd.power_s, feed_mm_s=rd.feed_mm_s)
        rd.stroke_open = True
        rd.stroke_key = key
    pos = rd.pos
    if rd.motion == 1.0:
        if end == pos:
            return
        b.add(LINE, (pos[0], pos[1], end[0], end[1]), ln)
    else:
        prim = _arc(pos, end, w.axes, rd.unit, rd.arc_abs, rd.offset, rd.motion == 2.0,
                    rd.name, ln)
        b.add(ARC, prim, ln)
    stroke = len(b.stroke_source) - 1
    if stroke != rd.last_stroke:  # the stroke's first primitive: it starts here
        b.dwells += [replace(d, stroke=stroke, after=False) for d, _ in rd.pending]
        rd.pending.clear()
    rd.last_stroke = stroke
    rd.at_stroke_end = True


def _tool_on(rd: _Reader, dwell: bool = False) -> bool:
    """Whether a G1/G2/G3 move (or a dwell: M4 is off at rest) would cut now: M3/M4 with
    S > 0 in a file with M3/M4 (on a pen whose Z was read, an M3 before any S word counts),
    and the pen down by Z once Z was read (module doc)."""
    on = True
    if rd.has_laser:
        powered = rd.power_s > 0 or (rd.pen_down is not None and not rd.s_given)
        on = rd.laser_on and powered and not (dwell and rd.laser_m4)
    return on and rd.pen_down is not False


def _z_move(rd: _Reader, w: _Words, ln: int) -> None:
    """A Z word, before the line's X/Y move (if any): the pen state on a pen machine; on a
    laser machine ignored (one warning) unless it changes Z during a cut (module doc)."""
    if rd.motion < 0:
        raise InputError("Z before any G0/G1/G2/G3", rd.name, ln)
    v = w.axes["Z"] * rd.unit
    z = v if rd.absolute or rd.z_mm is None else rd.z_mm + v
    if rd.tool == "pen":
        down = z <= rd.z_threshold_mm
        if not down:
            rd.stroke_open = False  # a lift ends the stroke, even where it started again
        rd.pen_down = down
    elif rd.z_mm is not None and z != rd.z_mm and rd.motion != 0.0 and _tool_on(rd):
        raise InputError(f"Z{w.axes['Z']:g} changes Z during a cut with the laser on: a "
                         "laser cannot follow Z (turn it off with M5 before moving Z, or "
                         "remove the Z words)", rd.name, ln)
    elif not rd.z_warned:
        rd.z_warned = True
        rd.builder.warnings.append(f"{rd.name}:{ln}: Z words ignored: a laser machine has "
                                   "no Z axis (Z may change only while the laser is off)")
    rd.z_mm = z


def _dwell(rd: _Reader, w: _Words, ln: int) -> None:
    """`G4 P<seconds>`: a dwell with the tool as it is now (module doc), placed after the
    stroke that ends here, or kept until the next stroke starts or the tool travels away."""
    if 4.0 not in w.gs:
        raise InputError("P word without G4 (P is the dwell time of G4)", rd.name, ln)
    if "P" not in w.axes:
        raise InputError("G4 needs P, the dwell time in seconds (GRBL 1.1; S is the laser "
                         "power here, not a time)", rd.name, ln)
    if w.has("X", "Y", "I", "J", "R") or any(g in _MOTIONS for g in w.gs):
        raise InputError("G4 and a move on the same line", rd.name, ln)
    seconds = w.axes["P"]
    if seconds < 0:
        raise InputError(f"dwell P{seconds:g} must not be negative", rd.name, ln)
    if seconds == 0:
        return
    tool_on = rd.motion in (1.0, 2.0, 3.0) and _tool_on(rd, dwell=True)
    power = (rd.power_s if rd.has_laser else 1.0) if tool_on else 0.0
    d = Dwell(rd.last_stroke, True, seconds, tool_on, power, ln)
    if rd.at_stroke_end:
        rd.builder.dwells.append(d)
        rd.stroke_open = False  # a dwell ends the stroke: the next cut starts a new one
    else:
        rd.pending.append((d, ln))


def _leave(rd: _Reader) -> None:
    """The tool travels away: dwells read here with the tool off wait at the end of the
    stroke before them (or before the next stroke when none was drawn yet); one with the
    tool on has no cut to burn at and is refused."""
    rd.at_stroke_end = False
    for d, ln in rd.pending:
        if d.tool_on:
            raise InputError("G4 with the tool on (laser burning, pen down) where no cut "
                             "starts or ends: fivebar plans its own travel and has no such "
                             "point; turn the laser off (M5) or dwell at a cut's end",
                             rd.name, ln)
    if rd.last_stroke >= 0:
        rd.builder.dwells += [d for d, _ in rd.pending]
        rd.pending.clear()


def _finish(rd: _Reader) -> Drawing:
    """The drawing, with stroke powers as fractions of the file's largest S (the profile's
    power is full scale); an error when nothing cuts."""
    if rd.pending:
        _leave(rd)
    drawing = rd.builder.build()
    if drawing.kind.shape[0] == 0:
        raise InputError("no cutting moves to draw (G1/G2/G3 with the laser on, M3/M4 S>0)",
                         rd.name)
    scale = 1.0 / rd.max_s if rd.max_s > 0 else 0.0
    if rd.max_s > 0:
        drawing.stroke_power[:] = drawing.stroke_power / rd.max_s
    else:
        drawing.stroke_power[:] = 1.0
    drawing.dwells = [replace(d, power=d.power * scale if rd.max_s > 0 and rd.has_laser
                              else float(d.tool_on)) for d in drawing.dwells]
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
    if "R" in axes:
        if "I" in axes or "J" in axes:
            raise InputError("arc with both R and I/J", file, ln)
        cx, cy, radius = _r_centre(p0, p1, axes["R"], unit, clockwise, file, ln)
    else:
        if "I" not in axes and "J" not in axes:
            raise InputError("arc without I/J or R", file, ln)
        cx, cy, radius = _ij_centre(p0, p1, axes, unit, arc_abs, offset, file, ln)
    x0, y0 = p0
    x1, y1 = p1
    th0 = math.atan2(y0 - cy, x0 - cx)
    th1 = math.atan2(y1 - cy, x1 - cx)
    dth = -((th0 - th1) % (2 * math.pi)) if clockwise else (th1 - th0) % (2 * math.pi)
    if dth == 0.0 or (math.hypot(x1 - x0, y1 - y0) < 1e-12):
        dth = -2 * math.pi if clockwise else 2 * math.pi
    return (cx, cy, radius, 0.0, 0.0, radius, th0, dth)


def _r_centre(p0: tuple[float, float], p1: tuple[float, float], r_word: float, unit: float,
              clockwise: bool, file: str, ln: int) -> tuple[float, float, float]:
    """Centre and radius of an R-form arc (R < 0: the long way round)."""
    x0, y0 = p0
    x1, y1 = p1
    r = r_word * unit
    dx, dy = x1 - x0, y1 - y0
    chord = math.hypot(dx, dy)
    if chord == 0:
        raise InputError("R-form arc with end = start (a full circle needs I/J)", file, ln)
    h2 = r * r - chord * chord / 4
    if h2 < -(ARC_END_TOL_MM**2) - 1e-12:
        raise InputError(f"arc radius R{r_word:g} is smaller than half the chord "
                         f"({chord / 2:.6g} mm)", file, ln)
    h = math.sqrt(max(h2, 0.0))
    # Centre left of p0→p1 for a counter-clockwise short arc; R < 0 takes the long way.
    side = (1.0 if not clockwise else -1.0) * (1.0 if r > 0 else -1.0)
    cx = (x0 + x1) / 2 - side * h * dy / chord
    cy = (y0 + y1) / 2 + side * h * dx / chord
    return cx, cy, abs(r)


def _ij_centre(p0: tuple[float, float], p1: tuple[float, float], axes: dict[str, float],
               unit: float, arc_abs: bool, offset: tuple[float, float], file: str,
               ln: int) -> tuple[float, float, float]:
    """Centre and radius of an I/J-form arc (offsets from the start, or absolute with
    G90.1); its end must lie on the circle through its start."""
    x0, y0 = p0
    x1, y1 = p1
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
    return cx, cy, radius
