"""GRBL's G-code interpreter with its modal state: a parsed `Block` → the machine-frame moves
and commands it stands for, in GRBL's order of execution (feed, spindle, coolant, dwell,
plane, units, coordinate system, distance mode, non-modal commands, motion, program flow).

Transactional like GRBL's parser: `execute` works on a copy of the state and returns it with
the actions; the caller commits the copy only when the actions were accepted (a refused move
leaves the modal state and the position as they were). Positions are machine millimetres in
fivebar's frame (motor M1 at (0, 0), y up); work coordinates add the G54–G59 offset and the
G92 offset to them, as GRBL does. Arcs (G2/G3, G17 plane only) are flattened here into chords
within a chord tolerance, the part of fivebar's tolerance budget that flattening may use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from fivebar_host.bridge import codes
from fivebar_host.bridge.codes import GrblError
from fivebar_host.bridge.gcode import AXES, Block

MM_PER_INCH = 25.4
WCS_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59")
Vec = tuple[float, float, float]


@dataclass(frozen=True)
class Move:
    """A straight or flattened move in machine mm: `points` after the start, the last being
    the target; `rapid` for G0/G28/G30 (never drawing); the modal tool state it runs with."""

    start: Vec
    points: tuple[tuple[float, float], ...]
    z: float
    rapid: bool
    feed_mm_min: float
    spindle: int  # 3, 4 or 5
    s: float
    z_seen: bool


@dataclass(frozen=True)
class Dwell:
    seconds: float


@dataclass(frozen=True)
class ProgramFlow:
    """M0/M1 (pause: a feed hold once everything before it ran) or M2/M30 (end)."""

    code: int


Action = Move | Dwell | ProgramFlow


@dataclass(frozen=True)
class ModalState:
    """GRBL's parser state (what `$G` reports) plus the position and the offsets (`$#`)."""

    motion: int = 0  # G tenths: 0, 10, 20, 30, 800
    distance: int = 900
    units: int = 210
    wcs: int = 0  # index into WCS_NAMES
    spindle: int = 5
    coolant: frozenset[int] = frozenset()
    feed: float = 0.0  # mm/min
    s: float = 0.0
    tool: int = 0
    position: Vec = (0.0, 0.0, 0.0)  # machine mm
    z_seen: bool = False
    g92: Vec = (0.0, 0.0, 0.0)
    offsets: tuple[Vec, ...] = field(default=((0.0, 0.0, 0.0),) * 6)
    g28: Vec = (0.0, 0.0, 0.0)
    g30: Vec = (0.0, 0.0, 0.0)

    def work_offset(self) -> Vec:
        """WCO: the active coordinate system's offset plus G92's."""
        o = self.offsets[self.wcs]
        return (o[0] + self.g92[0], o[1] + self.g92[1], o[2] + self.g92[2])

    def after_reset(self) -> ModalState:
        """GRBL's soft reset / M2: modal state to defaults; position, offsets kept."""
        return replace(self, motion=0, distance=900, units=210, wcs=self.wcs, spindle=5,
                       coolant=frozenset(), tool=0)


def _scale(state: ModalState, block: Block) -> float:
    units = block.g.get("units", state.units)
    return MM_PER_INCH if units == 200 else 1.0


def _target(state: ModalState, block: Block, scale: float, machine: bool) -> Vec:
    """The block's axis words as a machine-frame target (G53 machine, G91 incremental)."""
    pos = list(state.position)
    wco = (0.0, 0.0, 0.0) if machine else state.work_offset()
    incremental = block.g.get("distance", state.distance) == 910
    for i, a in enumerate(AXES):
        if a in block.values:
            v = block.values[a] * scale
            pos[i] = pos[i] + v if incremental and not machine else v + wco[i]
    return (pos[0], pos[1], pos[2])


def arc_points(start: Vec, end: Vec, centre: tuple[float, float], clockwise: bool,
               chord_tol: float) -> list[tuple[float, float]]:
    """Chords of the XY arc from `start` to `end` about `centre`, each within `chord_tol` of
    the arc (sagitta r(1 − cos(δ/2)) ≤ tol); a full circle when start == end."""
    cx, cy = centre
    r = math.hypot(start[0] - cx, start[1] - cy)
    a0 = math.atan2(start[1] - cy, start[0] - cx)
    a1 = math.atan2(end[1] - cy, end[0] - cx)
    sweep = a1 - a0
    if clockwise:
        if sweep >= -1e-9:
            sweep -= 2 * math.pi
    elif sweep <= 1e-9:
        sweep += 2 * math.pi
    step = 2 * math.acos(max(-1.0, 1 - chord_tol / r)) if r > chord_tol else math.pi / 2
    n = max(1, math.ceil(abs(sweep) / max(step, 1e-6)))
    pts = [(cx + r * math.cos(a0 + sweep * k / n), cy + r * math.sin(a0 + sweep * k / n))
           for k in range(1, n)]
    return [*pts, (end[0], end[1])]


def _arc_centre(state: ModalState, block: Block, target: Vec, scale: float,
                clockwise: bool) -> tuple[float, float]:
    """The arc's centre from R (radius format) or I/J (offsets from the start)."""
    x0, y0 = state.position[0], state.position[1]
    dx, dy = target[0] - x0, target[1] - y0
    if "R" in block.values:
        if abs(dx) < 1e-9 and abs(dy) < 1e-9:
            raise GrblError(codes.INVALID_TARGET, "radius-format arc to its own start")
        r = block.values["R"] * scale
        h2 = 4 * r * r - dx * dx - dy * dy
        if h2 < 0:
            raise GrblError(codes.ARC_RADIUS_ERROR, "radius too small for the chord")
        h = -math.sqrt(h2) / math.hypot(dx, dy)
        if not clockwise:
            h = -h
        if r < 0:
            h = -h
        return (x0 + 0.5 * (dx - dy * h), y0 + 0.5 * (dy + dx * h))
    if "I" not in block.values and "J" not in block.values:
        raise GrblError(codes.NO_OFFSETS_IN_PLANE, "G2/G3 needs I, J or R")
    cx = x0 + block.values.get("I", 0.0) * scale
    cy = y0 + block.values.get("J", 0.0) * scale
    r0 = math.hypot(x0 - cx, y0 - cy)
    r1 = math.hypot(target[0] - cx, target[1] - cy)
    dr = abs(r1 - r0)
    if dr > 0.005 and (dr > 0.5 or dr > 0.001 * r0):
        raise GrblError(codes.INVALID_TARGET, "arc end not on the circle")
    return (cx, cy)


def _check_words(block: Block, motion: int | None, non_modal: int | None) -> None:
    """GRBL's word checks: unused value words, axis words nobody uses, G53 with arcs."""
    used = set("NFST")
    if motion in (20, 30):
        used |= set("IJKR")
    if non_modal in (40, 100):
        used.add("P")
    if non_modal == 100:
        used.add("L")
    has_axes = bool(block.axes)
    if has_axes:
        if non_modal not in (100, 280, 300, 920) and (motion is None or motion == 800):
            raise GrblError(codes.AXIS_WORDS_EXIST, "axis words without a motion")
        if non_modal in (100, 280, 300, 920) and "motion" in block.g:
            raise GrblError(codes.AXIS_COMMAND_CONFLICT, "two commands that use the axes")
    unused = set(block.values) - used - set(AXES)
    if unused:
        raise GrblError(codes.UNUSED_WORDS, "unused " + "".join(sorted(unused)))
    if non_modal == 530 and motion not in (0, 10):
        raise GrblError(codes.G53_INVALID_MOTION_MODE, "G53 needs G0 or G1")


def _modal_updates(state: ModalState, block: Block, scale: float) -> ModalState:
    """Feed, spindle, tool, coolant, units, coordinate system and distance mode."""
    st = state
    if "F" in block.values:
        st = replace(st, feed=block.values["F"] * scale)
    if "S" in block.values:
        st = replace(st, s=block.values["S"])
    if "T" in block.values:
        st = replace(st, tool=int(block.values["T"]))
    if "spindle" in block.m:
        st = replace(st, spindle=block.m["spindle"])
    cool = block.m.get("coolant")
    if cool is not None:
        st = replace(st, coolant=frozenset() if cool == 9 else st.coolant | {cool})
    if "units" in block.g:
        st = replace(st, units=block.g["units"])
    if "wcs" in block.g:
        st = replace(st, wcs=(block.g["wcs"] - 540) // 10)
    if "distance" in block.g:
        st = replace(st, distance=block.g["distance"])
    if "motion" in block.g:
        st = replace(st, motion=block.g["motion"])
    return st


def _g10(state: ModalState, block: Block, scale: float) -> ModalState:
    """G10 L2 P<n> (set offsets) / L20 P<n> (so the current position reads the words)."""
    if "L" not in block.values or "P" not in block.values:
        raise GrblError(codes.VALUE_WORD_MISSING, "G10 needs L and P")
    p = block.values["P"]
    if p != int(p) or not 0 <= p <= 6:
        raise GrblError(codes.UNSUPPORTED_COORD_SYS, f"G10 P{p:g}")
    n = state.wcs if p == 0 else int(p) - 1
    lval = int(block.values["L"])
    if lval not in (2, 20):
        raise GrblError(codes.UNSUPPORTED_COMMAND, f"G10 L{lval}")
    off = list(state.offsets[n])
    for i, a in enumerate(AXES):
        if a in block.values:
            v = block.values[a] * scale
            off[i] = v if lval == 2 else state.position[i] - state.g92[i] - v
    offsets = list(state.offsets)
    offsets[n] = (off[0], off[1], off[2])
    return replace(state, offsets=tuple(offsets))


def _g92(state: ModalState, block: Block, scale: float) -> ModalState:
    """G92: offsets so the current position reads the axis words."""
    if not block.axes:
        raise GrblError(codes.NO_AXIS_WORDS, "G92 needs axis words")
    g92 = list(state.g92)
    wcs = state.offsets[state.wcs]
    for i, a in enumerate(AXES):
        if a in block.values:
            g92[i] = state.position[i] - wcs[i] - block.values[a] * scale
    return replace(state, g92=(g92[0], g92[1], g92[2]))


def _rapid(st: ModalState, start: Vec, to: Vec) -> Move:
    return Move(start, ((to[0], to[1]),), to[2], True, st.feed, st.spindle, st.s,
                st.z_seen)


def _go_home(st: ModalState, block: Block, scale: float, stored: Vec) -> tuple[ModalState,
                                                                             list[Action]]:
    """G28/G30: rapid through the optional intermediate point to the stored position."""
    acts: list[Action] = []
    pos = st.position
    if block.axes:
        mid = _target(st, block, scale, machine=False)
        acts.append(_rapid(st, pos, mid))
        pos = mid
    end = list(pos)
    for i, a in enumerate(AXES):
        if not block.axes or a in block.values:
            end[i] = stored[i]
    target = (end[0], end[1], end[2])
    acts.append(_rapid(st, pos, target))
    return replace(st, position=target, motion=0), acts


def _non_modal(st: ModalState, block: Block, scale: float,
               nm: int | None) -> tuple[ModalState, list[Action]]:
    acts: list[Action] = []
    if nm == 40:
        if "P" not in block.values:
            raise GrblError(codes.VALUE_WORD_MISSING, "G4 needs P")
        acts.append(Dwell(block.values["P"]))
    elif nm == 100:
        st = _g10(st, block, scale)
    elif nm == 920:
        st = _g92(st, block, scale)
    elif nm == 921:
        st = replace(st, g92=(0.0, 0.0, 0.0))
    elif nm == 281:
        st = replace(st, g28=st.position)
    elif nm == 301:
        st = replace(st, g30=st.position)
    elif nm in (280, 300):
        st, acts = _go_home(st, block, scale, st.g28 if nm == 280 else st.g30)
    return st, acts


def _motion(st: ModalState, block: Block, scale: float, machine: bool,
            chord_tol: float) -> tuple[ModalState, list[Action]]:
    """The motion command of the block (or the modal one, when axis words are given)."""
    if not block.axes or st.motion == 800:
        return st, []
    target = _target(st, block, scale, machine)
    z_seen = st.z_seen or "Z" in block.values
    if st.motion == 0:
        move = _rapid(replace(st, z_seen=z_seen), st.position, target)
    else:
        if st.feed <= 0:
            raise GrblError(codes.UNDEFINED_FEED_RATE, "G1/G2/G3 without a feed rate")
        if st.motion == 10:
            pts = [(target[0], target[1])]
        else:
            if "X" not in block.values and "Y" not in block.values:
                raise GrblError(codes.NO_AXIS_WORDS_IN_PLANE, "G2/G3 without X or Y")
            cw = st.motion == 20
            centre = _arc_centre(st, block, target, scale, cw)
            pts = arc_points(st.position, target, centre, cw, chord_tol)
        move = Move(st.position, tuple(pts), target[2], False, st.feed, st.spindle, st.s,
                    z_seen)
    if not all(math.isfinite(v) and abs(v) < 1e6 for v in target):
        raise GrblError(codes.INVALID_TARGET, "target out of range")
    return replace(st, position=target, z_seen=z_seen), [move]


def execute(state: ModalState, block: Block, chord_tol: float) -> tuple[ModalState,
                                                                       list[Action]]:
    """Run one block on a copy of `state`: (new state, actions), or `GrblError`."""
    scale = _scale(state, block)
    nm = block.g.get("non_modal")
    motion = block.g.get("motion", state.motion if block.axes else None)
    if nm in (100, 280, 300, 920) and "motion" not in block.g:
        motion = None
    _check_words(block, motion, nm)
    st = _modal_updates(state, block, scale)
    st, acts = _non_modal(st, block, scale, nm)
    if nm not in (100, 280, 300, 920):
        st, more = _motion(st, block, scale, nm == 530, chord_tol)
        acts += more
    flow = block.m.get("stopping")
    if flow is not None:
        acts.append(ProgramFlow(flow))
        if flow in (2, 30):
            st = replace(st.after_reset(), g92=st.g92)
    return st, acts
