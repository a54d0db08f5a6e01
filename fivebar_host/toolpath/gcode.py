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

Z follows G20/G21 and G90/G91 like X and Y; `G92 Z` sets the Z offset (the pen threshold
applies to Z as written, in work coordinates).

Every other word has a class (`toolpath.gcode_words`, docs/gcode.md "Word classes"): words that
cannot change the drawn path on this machine are skipped and told in one note naming their
lines; `M0`/`M1` and `T…`/`M6` become pen-change stops before the next cut; `G28`/`G30` are a
travel with the tool off (the stroke ends, the pen is up; fivebar plans the travel to the next
cut itself and parks at the home pose at the end of the job); `M300` servo pens set the pen
(their `G4 P` in milliseconds, RepRap's unit); what would change the path or the burn (other
axes, other planes' arcs, cutter compensation, canned cycles, units changed after the first
move, unknown words, a bad number) is an `InputError` naming the file, the line and the word
(the whole token as written, shortened when long). `strict=True` (`--strict`) keeps the older
reading: every word outside the honoured ones is refused.

The file's bytes are UTF-8 (a byte-order mark is dropped) or UTF-16 with its mark, as an
SVG may be.

The lines go through fivebar's one G-code interpreter (`fivebar_host.gcode`: words, modal
state, arcs) read the file reader's way (`RULES`: not GRBL's strict word checks, no feed
needed, this reader's arc tolerances); what is here is the reader's policy: which words it
honours (`_policy`), the checks above that GRBL does not make, and how moves become strokes.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from fivebar_host.errors import InputError
from fivebar_host.gcode import (
    ArcRules,
    Block,
    GcodeError,
    ModalState,
    Move,
    Policy,
    Rules,
    Word,
    check_target,
    execute,
    parse,
    strip_file,
)
from fivebar_host.gcode import Dwell as Wait
from fivebar_host.gcode.errors import UNSUPPORTED_COMMAND
from fivebar_host.gcode.words import shorten, whole_token
from fivebar_host.toolpath import gcode_words
from fivebar_host.toolpath.gcode_words import Kind, Skipped
from fivebar_host.toolpath.geometry import (
    ARC,
    LINE,
    MAX_COORD_MM,
    Drawing,
    DrawingBuilder,
    Dwell,
    read_source,
)

_PAREN = re.compile(r"\([^)]*\)")
_LASER_ON = re.compile(r"(?<![A-Za-z])[Mm]\s*0*[34](?![\d.])")

#: G codes that are accepted; values are what they select.
_G_OK = {0.0, 1.0, 2.0, 3.0, 4.0, 17.0, 20.0, 21.0, 90.0, 91.0, 90.1, 91.1, 92.0, 94.0, 54.0}
_M_OK = {2.0, 3.0, 4.0, 5.0, 30.0}
#: Motion commands as the interpreter numbers them (G tenths).
_MOTIONS = (0, 10, 20, 30)
#: Words that carry a value for this line (coordinates, arc centre or radius, feed, power).
_VALUE_WORDS = ("X", "Y", "I", "J", "R", "F", "S", "P")
#: Axis words of other machines: refused with a hint.
_OTHER_AXES = ("Z", "A", "B", "C", "U", "V", "W", "E")
#: Value words a skipped command may own on its line (`gcode_words.Rule.owns`); set aside.
_OWNABLE = frozenset("HTQ")

#: An arc's end must lie on its circle to within this (absolute mm, or relative to r).
ARC_END_TOL_MM = 0.005
ARC_END_TOL_REL = 1e-3

#: How this reader reads G-code (`fivebar_host.gcode.Rules`): not GRBL's strict word checks
#: (this reader's own are below); arcs: the end within ARC_END_TOL_MM or ARC_END_TOL_REL of
#: the circle, R as short as ARC_END_TOL_MM under half the chord, a chord under 1e-12 mm a
#: full circle, no zero radius, no R with I/J.
RULES = Rules(strict=False,
              arcs=ArcRules(end_tol_mm=ARC_END_TOL_MM, end_tol_rel=ARC_END_TOL_REL,
                            end_tol_cap_mm=math.inf, r_short_mm2=ARC_END_TOL_MM**2 + 1e-12,
                            same_point_mm=0.0, full_circle_rad=0.0, full_circle_chord_mm=1e-12,
                            zero_radius_ok=False, r_with_offsets_ok=False))


@dataclass
class _Reader:
    """The reader's state while it goes through a file: the interpreter's modal state, the
    stroke being drawn and the drawing being built."""

    builder: DrawingBuilder
    name: str
    has_laser: bool  # any M3/M4 in the file: only moves with the laser on draw
    policy: Policy  # the words honoured (Z only with a tool)
    # no motion mode (G80) until the first G0-G3; the feed is the profile's until an F word
    state: ModalState = field(default_factory=lambda: ModalState(motion=800, feed=math.nan))
    stroke_open: bool = False
    stroke_key: tuple[float, float] | None = None
    max_s: float = 0.0
    last_stroke: int = -1  # the stroke that got the last primitive
    at_stroke_end: bool = False  # the position is that stroke's end
    pending: list[tuple[Dwell, int]] = field(default_factory=list)  # not yet placed, line
    tool: str | None = None  # "pen", "laser", or None: Z words refused
    z_threshold_mm: float = 0.0  # pen: Z above this is pen up
    pen_down: bool | None = None  # pen: from Z (None until a Z word: Z does not decide)
    s_given: bool = False  # an S word was read
    z_warned: bool = False  # the laser's "Z ignored" warning was given
    strict: bool = False  # every word outside the honoured ones refused (--strict)
    skipped: Skipped = field(default_factory=Skipped)  # for the one note
    layer: str | None = None  # the stop before the strokes now read ("!…": compile.layers)
    stop_open: bool = False  # `layer` names a stop no stroke has followed yet
    servo: tuple[float, float] | None = None  # an M300 servo pen: its (up, down) S values
    moved: bool = False  # a move was read (G20/G21 after it change the units mid-file)
    next_tool: str = ""  # the T word of the coming tool change


def read_gcode(source: str | Path | bytes, file: str | None = None, tool: str | None = None,
               z_threshold_mm: float = 0.0, strict: bool = False) -> Drawing:
    """Read a G-code file (path or bytes) into a `Drawing` in mm (frame as written, y up).

    `tool` ("pen" or "laser", the profile's `[tool] kind`) and `z_threshold_mm` (the
    profile's `[pen] z_threshold_mm`) decide what Z words mean (module doc); with no tool a Z
    word is refused. `strict`: refuse every word outside the honoured ones (module doc)."""
    if tool not in (None, "pen", "laser"):
        raise ValueError(f"tool must be 'pen', 'laser' or None; got {tool!r}")
    data, name = read_source(source, file, "<gcode>")
    text = decode_text(data, name)
    lines = text.splitlines()
    soft = [_strip_soft(s) for s in lines]
    has_laser = any(_LASER_ON.search(s) for s in soft)
    rd = _Reader(DrawingBuilder(name), name, has_laser,
                 _POLICIES[strict, tool is not None], tool=tool, z_threshold_mm=z_threshold_mm,
                 strict=strict)
    if not strict and any(_SERVO_PEN.search(s) for s in soft):
        rd.servo = gcode_words.unicorn_angles(text)
    for ln, raw in enumerate(lines, start=1):
        if _read_line(rd, raw, ln):
            break
    return _finish(rd)


#: Byte-order marks → the codec that reads past them.
_BOMS = ((b"\xef\xbb\xbf", "utf-8-sig"), (b"\xff\xfe", "utf-16"), (b"\xfe\xff", "utf-16"))


def decode_text(data: bytes, name: str) -> str:
    """The file's text: UTF-8 (its byte-order mark dropped), or UTF-16 with a byte-order
    mark, or UTF-16 without one when every other byte of the start is NUL (ASCII G-code)."""
    codec = next((c for bom, c in _BOMS if data.startswith(bom)), "utf-8")
    head = data[:64]
    if codec == "utf-8" and len(head) >= 4 and head[1::2].count(0) == len(head[1::2]):
        codec = "utf-16-le"
    elif codec == "utf-8" and len(head) >= 4 and head[0::2].count(0) == len(head[0::2]):
        codec = "utf-16-be"
    try:
        return data.decode(codec)
    except UnicodeDecodeError as e:
        raise InputError(f"not a text file (byte {e.start} is not {codec.upper()})",
                         name) from e


def _policy(z_ok: bool, strict: bool) -> Policy:
    """The words this reader honours (Z only with `z_ok`); without `strict`, the words of a
    class in `gcode_words` are set aside for `_classify`; any other is refused, naming it."""
    def check(w: Word) -> bool:
        letter, value, tok = w
        if not strict and (letter in _OWNABLE or gcode_words.rule_of(w) is not None):
            return letter != "G" or round(value, 1) not in _G_KEPT
        why_not = None if strict else gcode_words.refusal(w)
        if why_not is not None:
            raise GcodeError(UNSUPPORTED_COMMAND, why_not, tok)
        if letter == "G":
            if value in _G_OK or round(value, 1) in _G_OK or (
                    not strict and round(value, 1) in _G_KEPT):
                return False
            why = (f"unsupported G-code word {tok} (supported: G0 G1 G2 G3 G4 G17 G20 G21 "
                   "G54 G90 G91 G90.1 G91.1 G92 G94)")
        elif letter == "M":
            if value in _M_OK:
                return False
            why = f"unsupported M-code word {tok} (supported: M2 M3 M4 M5 M30)"
        elif letter in _OTHER_AXES:
            why = (f"unsupported axis word {tok}: this machine draws in X and Y only (the pen "
                   "or laser follows M3/M5)")
        elif letter == "K" and not strict:
            why = (f"{tok}: K is the Z offset of an arc in the XZ or YZ plane; this machine "
                   "draws arcs in the XY plane (G17) only")
        else:
            why = f"unsupported word {tok}"
        raise GcodeError(UNSUPPORTED_COMMAND, why, tok)
    return Policy(frozenset(("N", *_VALUE_WORDS, *(("Z",) if z_ok else ()))), check)


#: G codes the interpreter runs for the reader outside strict mode: G28/G30 (home, the
#: reader draws nothing there) and the G18/G19 planes (an arc in them is refused).
_G_KEPT = {28.0, 30.0, 18.0, 19.0}
#: (strict, with a tool) → the policy.
_POLICIES = {(st, z): _policy(z, st) for st in (False, True) for z in (False, True)}
#: An M300 without P: a servo pen (with P it is Marlin's beep).
_SERVO_PEN = re.compile(r"(?<![A-Za-z])[Mm]\s*0*300(?![\d.])(?![^\n]*[Pp]\s*\d)")


def _read_line(rd: _Reader, raw: str, ln: int) -> bool:
    """Interpret one line; True at the end of the program (M2/M30: later lines are ignored)."""
    text = ""
    try:
        if not rd.strict and gcode_words.message_line(raw):
            rd.skipped.add("messages", raw.split()[0][:8], ln)
            return False
        text = strip_file(raw)
        if not text:
            return False
        if not rd.strict:
            what = gcode_words.system_line(text)
            if what is not None:
                rd.skipped.add(gcode_words.SYSTEM_KIND, what, ln)
                return False
        block = parse(text, False, rd.policy)
        if block.skipped and _classify(rd, block, ln):
            return False
        return _run(rd, block, ln)
    except GcodeError as e:
        raise InputError(_message(text, e), rd.name, ln) from e


def _message(text: str, e: GcodeError) -> str:
    """The error's message, naming the whole token a bad number was written as (`X1e308`,
    not `e308`), shortened when long."""
    part = e.word
    if part is None or not text:
        return e.message
    tok = whole_token(text, part)
    if tok != part and any(c.isdigit() for c in tok):
        return (f"cannot read {shorten(tok)!r}: a G-code number is digits with at most one "
                "decimal point and a sign (no exponent, no second point)")
    return e.message.replace(part, shorten(part)) if len(part) > 24 else e.message


def _classify(rd: _Reader, block: Block, ln: int) -> bool:
    """The line's words set aside by the policy (`gcode_words`): owned values taken off the
    line, skipped kinds noted, stops and pens applied; True when nothing else is left on
    the line to run."""
    rules = [(w, r) for w in block.skipped
             if (r := gcode_words.rule_of(w)) is not None]
    owned = set("".join(r.owns for _, r in rules))
    tool = next((w.text for w in block.skipped if w.letter == "T"), "")
    for w in block.skipped:
        if w.letter in _OWNABLE and w.letter not in owned and w.letter != "T":
            raise GcodeError(UNSUPPORTED_COMMAND, f"unsupported word {w.text}", w.text)
    owned_values = {k: block.values.pop(k) for k in "PS" if k in owned and k in block.values}
    if tool and not any(r.kind is Kind.TOOL for _, r in rules):
        rd.next_tool = tool
        rd.skipped.add("tool select (the change is at M6)", tool, ln)
    for w, r in rules:
        if r.kind is Kind.SKIP:
            rd.skipped.add(r.what, w.text, ln)
        elif r.kind in (Kind.STOP, Kind.TOOL):
            name = f"{tool or rd.next_tool} {w.text}".strip() if r.kind is Kind.TOOL else w.text
            _stop(rd, f"{name} (line {ln}): {r.what}")
        elif r.kind is Kind.HOME:
            rd.skipped.add(f"{r.what}, a travel with the tool off,", w.text, ln)
            _home(rd)
        else:
            _servo_pen(rd, w, owned_values, ln)
    return not (block.g or block.m or block.values)


def _stop(rd: _Reader, label: str) -> None:
    """A pen-change stop before the next cut (`compile.layers`: a layer named "!…"); stops
    with no cut between them are one stop."""
    if rd.stop_open and rd.layer is not None:
        rd.layer += "; " + label
    else:
        rd.layer = "!" + label
    rd.stop_open = True
    rd.stroke_open = False
    _leave(rd)


def _home(rd: _Reader) -> None:
    """G28/G30 (or a vendor's go-home): travel with the tool off; the pen is up after it."""
    rd.stroke_open = False
    _leave(rd)
    if rd.tool == "pen" or rd.servo is not None:
        rd.pen_down = False


def _servo_pen(rd: _Reader, w: Word, owned: dict[str, float], ln: int) -> None:
    """`M300 S<v>`: the Unicorn servo pen down or up; with P a Marlin beep (skipped)."""
    if "P" in owned or rd.servo is None:
        rd.skipped.add("beep", w.text, ln)
        return
    s = owned.get("S")
    up, down = rd.servo
    if s == down:
        rd.pen_down = True
    elif s in (up, gcode_words.SERVO_OFF):
        rd.pen_down = False
        rd.stroke_open = False
    else:
        val = "no S" if s is None else f"S{s:g}"
        raise GcodeError(UNSUPPORTED_COMMAND, f"{w.text} {val}: the servo pen's values in this "
                         f"file are S{down:g} (down) and S{up:g} (up)", w.text)


def _run(rd: _Reader, block: Block, ln: int) -> bool:
    """This reader's checks of a line, then the interpreter, then its actions: moves become
    strokes or travel, dwells are placed; True for M2/M30 (the end: the reader stops there,
    so the interpreter is not asked for the modal reset that follows them)."""
    v = block.values
    if "F" in v or "S" in v:
        _check_values(rd, v, ln)
    if 920 in block.gcodes:
        _check_g92(rd, block, ln)
    elif len(block.gcodes) > 1 and sum(c in _MOTIONS for c in block.gcodes) > 1:
        raise InputError("more than one motion command on one line", rd.name, ln)
    elif 40 in block.gcodes or "P" in v:
        _check_dwell(rd, block, ln)
    if not rd.strict:
        _check_modes(rd, block, ln)
    end = block.m.pop("stopping", None) is not None
    before = rd.state
    rd.state, actions = execute(before, block, RULES)
    if block.g.get("non_modal") in (280, 300):
        _home(rd)
        rd.skipped.add("go home, a travel with the tool off,", f"G{block.g['non_modal'] // 10}", ln)
        return end
    for act in actions:
        if isinstance(act, Move):
            _move(rd, act, block, before, ln)
        elif isinstance(act, Wait):
            _dwell(rd, act.seconds / 1000.0 if rd.servo is not None else act.seconds, ln)
    return end


def _check_modes(rd: _Reader, block: Block, ln: int) -> None:
    """Units changed after the first move (every later number would mean another length)."""
    units = block.g.get("units")
    if units is not None and units != rd.state.units and rd.moved:
        word = f"G{units // 10}"
        raise InputError(f"{word} after the first move changes the units mid-file: the "
                         "drawing would change scale part-way (write the whole file in one "
                         "unit)", rd.name, ln)


def _check_values(rd: _Reader, v: dict[str, float], ln: int) -> None:
    """F positive, S not negative (and the file's largest S)."""
    if "F" in v and v["F"] <= 0:
        raise InputError(f"feed F{v['F']:g} must be positive", rd.name, ln)
    if "S" in v:
        if v["S"] < 0:
            raise InputError(f"power S{v['S']:g} must not be negative", rd.name, ln)
        rd.s_given = True
        rd.max_s = max(rd.max_s, v["S"])


def _check_g92(rd: _Reader, block: Block, ln: int) -> None:
    """G92 X.. Y.. (and Z, but for `strict`) alone. Only its modal words and the offset act:
    a G4, P or M2/M30 on a G92 line is ignored, as this reader always did."""
    v = block.values
    if "X" not in v and "Y" not in v and (rd.strict or "Z" not in v):
        raise InputError("G92 needs X and/or Y" + ("" if rd.strict else " or Z"), rd.name, ln)
    if "I" in v or "J" in v or "R" in v or ("Z" in v and rd.strict):
        raise InputError("G92 with I, J, R or Z", rd.name, ln)
    if any(c in _MOTIONS for c in block.gcodes):
        raise InputError("G92 and a motion command on the same line", rd.name, ln)
    block.g["non_modal"] = 920
    block.m.pop("stopping", None)  # not the end either


def _check_dwell(rd: _Reader, block: Block, ln: int) -> None:
    """`G4 P<seconds>` alone on its line (module doc)."""
    v = block.values
    if "Z" in v:
        raise InputError("G4 and a Z move on the same line", rd.name, ln)
    if 40 not in block.gcodes:
        raise InputError("P word without G4 (P is the dwell time of G4)", rd.name, ln)
    if "P" not in v:
        raise InputError("G4 needs P, the dwell time in seconds (GRBL 1.1; S is the laser "
                         "power here, not a time)", rd.name, ln)
    if any(a in v for a in "XYIJR") or any(c in _MOTIONS for c in block.gcodes):
        raise InputError("G4 and a move on the same line", rd.name, ln)
    if v["P"] < 0:
        raise InputError(f"dwell P{v['P']:g} must not be negative", rd.name, ln)


def _move(rd: _Reader, mv: Move, block: Block, before: ModalState, ln: int) -> None:
    """A move: its Z word first (the pen state changes at the start of the move), then the
    X/Y move, drawn when it cuts, else travel (which ends the stroke)."""
    v = block.values
    if "Z" in v:
        _z_move(rd, mv, before, v["Z"], ln)
    if not ("X" in v or "Y" in v or "I" in v or "J" in v or "R" in v):
        return
    rd.moved = True
    check_target(mv.end, MAX_COORD_MM, None)  # Z is a pen state here, not a position
    motion = mv.motion
    if motion in (0, 10) and ("I" in v or "J" in v or "R" in v):
        raise InputError(f"I, J or R on a G{motion // 10} move", rd.name, ln)
    if motion in (20, 30) and before.plane != 170:
        raise InputError(f"G{motion // 10} arc in the G{before.plane // 10} plane: this "
                         "machine draws arcs in the XY plane (G17) only", rd.name, ln)
    if motion != 0 and _tool_on(rd):
        _draw(rd, mv, ln)
    else:
        rd.stroke_open = False
        if mv.end[0] != mv.start[0] or mv.end[1] != mv.start[1]:
            _leave(rd)


def _draw(rd: _Reader, mv: Move, ln: int) -> None:
    """Add a cutting G1/G2/G3 move to the drawing, starting a stroke when the power or the
    feed changed (or none is open)."""
    st = rd.state
    key = (st.s, st.feed)
    b = rd.builder
    if not rd.stroke_open or key != rd.stroke_key:
        src = b.add_source(None, ln, "gcode", rd.layer)
        rd.stop_open = False
        b.begin_stroke(src, power=st.s, feed_mm_s=st.feed / 60.0)
        rd.stroke_open = True
        rd.stroke_key = key
    (x0, y0, _), (x1, y1, _) = mv.start, mv.end
    if mv.motion == 10:
        if (x1, y1) == (x0, y0):
            return
        b.add(LINE, (x0, y0, x1, y1), ln)
    else:
        a = mv.exact_arc()
        b.add(ARC, (a.cx, a.cy, a.radius, 0.0, 0.0, a.radius, a.theta0, a.sweep), ln)
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
        st = rd.state
        powered = st.s > 0 or (rd.pen_down is not None and not rd.s_given)
        on = st.spindle in (3, 4) and powered and not (dwell and st.spindle == 4)
    return on and rd.pen_down is not False


def _z_move(rd: _Reader, mv: Move, before: ModalState, z_word: float, ln: int) -> None:
    """A Z word, before the line's X/Y move (if any): the pen state on a pen machine; on a
    laser machine ignored (one warning) unless it changes Z during a cut (module doc)."""
    z = mv.end[2]
    if rd.servo is not None:
        rd.skipped.add("Z words (the pen follows M300)", "", ln)
    elif rd.tool == "pen":
        down = z - before.work_offset()[2] <= rd.z_threshold_mm  # Z as written
        if not down:
            rd.stroke_open = False  # a lift ends the stroke, even where it started again
        rd.pen_down = down
    elif before.z_seen and z != before.position[2] and mv.motion != 0 and _tool_on(rd):
        raise InputError(f"Z{z_word:g} changes Z during a cut with the laser on: a "
                         "laser cannot follow Z (turn it off with M5 before moving Z, or "
                         "remove the Z words)", rd.name, ln)
    elif not rd.z_warned:
        rd.z_warned = True
        rd.builder.warnings.append(f"{rd.name}:{ln}: Z words ignored: a laser machine has "
                                   "no Z axis (Z may change only while the laser is off)")


def _dwell(rd: _Reader, seconds: float, ln: int) -> None:
    """`G4 P<seconds>`: a dwell with the tool as it is now (module doc), placed after the
    stroke that ends here, or kept until the next stroke starts or the tool travels away."""
    if seconds == 0:
        return
    st = rd.state
    tool_on = st.motion in (10, 20, 30) and _tool_on(rd, dwell=True)
    power = (st.s if rd.has_laser else 1.0) if tool_on else 0.0
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
    if not rd.strict and rd.tool == "pen" and any(d.tool_on for d, _ in rd.pending):
        for d, ln in rd.pending:  # a spindle's warm-up: no dot to burn with a pen
            if d.tool_on:
                rd.skipped.add("dwells with the spindle on where no cut starts or ends "
                               "(warm-up)", "G4", ln)
        rd.pending = [(d, ln) for d, ln in rd.pending if not d.tool_on]
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
    if rd.stop_open and rd.layer is not None:
        rd.skipped.add("a stop after the last cut (nothing left to stop before):",
                       rd.layer[1:], 0)
    note = rd.skipped.note(rd.name)
    if note is not None:
        rd.builder.warnings.append(note)
    drawing = rd.builder.build()
    if drawing.kind.shape[0] == 0:
        raise InputError("no cutting moves to draw (G1/G2/G3 with the laser on, M3/M4 S>0)",
                         rd.name)
    scale = 1.0 / rd.max_s if rd.max_s > 0 else 0.0
    if rd.max_s > 0:
        drawing.stroke_power[:] = drawing.stroke_power / rd.max_s
        if rd.has_laser:
            # a file's S counts up to its controller's own maximum (GRBL's $30, 1000 by
            # default; Marlin's 255), which the file does not name: say which S is full power
            drawing.warnings.append(
                f"{rd.name}: laser power as a fraction of the file's largest S, S{rd.max_s:g}, "
                "which burns at the profile's [laser] power (with --laser; `fivebar bridge` "
                "maps S by its $30 instead)")
    else:
        drawing.stroke_power[:] = 1.0
    drawing.dwells = [replace(d, power=d.power * scale if rd.max_s > 0 and rd.has_laser
                              else float(d.tool_on)) for d in drawing.dwells]
    return drawing


def _strip_soft(raw: str) -> str:
    """A line without its comments, for the look for M3/M4 before reading (no errors)."""
    s = raw.split(";", 1)[0]
    return _PAREN.sub(" ", s)
