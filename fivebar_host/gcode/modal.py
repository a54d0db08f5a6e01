"""The G-code interpreter: the modal state and `execute`, a `Block` → the moves and commands
it stands for, in GRBL's order of execution (gcode.c; NIST RS274NGC §3.8): feed, spindle
speed (S), tool, spindle/laser (M3/M4/M5), coolant, plane, units, coordinate system,
distance modes, non-modal commands (G4 dwell, G10, G28/G30, G53, G92), motion, program flow
(M0/M1/M2/M30).

Transactional like GRBL's parser: `execute` leaves the state it is given as it is and
returns the next one with the actions; the caller keeps the next state only when it accepts
the actions (a refused move leaves the modal state and the position as they were).
Positions are machine millimetres in fivebar's frame; work coordinates add the G54–G59
offset and the G92 offset to them, as GRBL does. An arc move carries its words
(`arcs.ArcWords`): `Move.exact_arc` checks and solves it, `Move.points` flattens it.

`Rules` is where the two front doors read the language differently: `strict` is GRBL's
(the bridge): GRBL's word checks (`words.parse`, `_check_words`), a feed rate before any
G1/G2/G3 (`error:22`), arcs with an X or Y word (`error:32`). Without it (the file reader)
an arc's I/J/R words alone make a move (a full circle) and no feed is needed (the profile
has one); what the reader refuses besides is the reader's own policy. `ArcRules` holds how
strictly each checks arcs. A target's range is each front door's own (`check_target`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

from fivebar_host.gcode import errors
from fivebar_host.gcode.arcs import Arc, ArcRules, ArcWords, Point, chords, solve
from fivebar_host.gcode.errors import GcodeError
from fivebar_host.gcode.words import AXES, Block

MM_PER_INCH = 25.4
WCS_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59")
Vec = tuple[float, float, float]
_ZERO: Vec = (0.0, 0.0, 0.0)
#: Non-modal commands that use the axis words themselves (no motion on their line).
_AXIS_USERS = (100, 280, 300, 920)
#: A NamedTuple made from its fields without its Python-level __new__ (`_make`'s checks): the
#: states and moves of every line are made so.
_new = tuple.__new__
#: Modal groups kept in the state under their own name.
_FIELDS = frozenset({"motion", "plane", "distance", "arc_distance", "feed_mode", "units"})


class Rules(NamedTuple):
    """A front door's reading of the language (module doc)."""

    strict: bool
    arcs: ArcRules


class ModalState(NamedTuple):
    """The parser state (what GRBL's `$G` reports: modal groups as G tenths, M codes, T, F
    in mm/min, S) plus the position and the offsets (`$#`). GRBL starts in G0; the file
    reader in G80 (no motion mode: axis words are an error until a G0–G3). Arcs are in the
    XY plane: G18, G19 and G93 are known words that both front doors refuse."""

    motion: int = 0
    plane: int = 170
    distance: int = 900
    arc_distance: int = 911
    feed_mode: int = 940
    units: int = 210
    wcs: int = 0  # index into WCS_NAMES
    spindle: int = 5
    coolant: frozenset[int] = frozenset()
    feed: float = 0.0
    s: float = 0.0
    tool: int = 0
    position: Vec = _ZERO
    z_seen: bool = False
    g92: Vec = _ZERO
    offsets: tuple[Vec, ...] = (_ZERO,) * 6
    g28: Vec = _ZERO
    g30: Vec = _ZERO

    def work_offset(self) -> Vec:
        """WCO: the active coordinate system's offset plus G92's."""
        o, g = self.offsets[self.wcs], self.g92
        return (o[0] + g[0], o[1] + g[1], o[2] + g[2])

    def updated(self, changes: dict[str, Any]) -> ModalState:
        """This state with `changes` (field → value): `_replace` at half its cost."""
        values = list(self)
        for name, value in changes.items():
            values[_INDEX[name]] = value
        return _new(ModalState, values)

    def moved(self, position: Vec, z_seen: bool) -> ModalState:
        """This state at another position (every move makes one: cheaper still)."""
        return _new(ModalState, (*self[:_AT], position, z_seen, *self[_AT + 2:]))

    def after_reset(self) -> ModalState:
        """GRBL's soft reset / M2: modal state to defaults; position, offsets kept."""
        return self._replace(motion=0, plane=170, distance=900, arc_distance=911,
                             feed_mode=940, units=210, spindle=5, coolant=frozenset(), tool=0)


_INDEX = {name: i for i, name in enumerate(ModalState._fields)}
_AT = _INDEX["position"]
assert _INDEX["z_seen"] == _AT + 1  # `moved` replaces the two together


class Move(NamedTuple):
    """A move in machine mm from `start` to `end`: `motion` 0 (G0, G28, G30: rapid), 10
    (G1), 20/30 (G2/G3, `arc` its words); the feed (mm/min) and the tool state it runs with;
    `z_seen`: a Z word was ever read."""

    start: Vec
    end: Vec
    motion: int
    arc: ArcWords | None
    feed: float
    spindle: int
    s: float
    z_seen: bool

    @property
    def rapid(self) -> bool:
        """G0, G28, G30: at the machine's travel speed, never drawing."""
        return self.motion == 0

    def exact_arc(self) -> Arc:
        """The arc of a G2/G3 move, checked (`GcodeError` when its words are no arc)."""
        assert self.arc is not None
        return solve(self.start[:2], self.end[:2], self.arc)

    def points(self, chord_tol_mm: float) -> list[Point]:
        """The XY points after the start: the end, or an arc's chords within the
        tolerance."""
        end = (self.end[0], self.end[1])
        if self.arc is None:
            return [end]
        return chords(self.exact_arc(), self.start[:2], end, chord_tol_mm)


class Dwell(NamedTuple):
    """G4: wait `seconds`."""

    seconds: float


class ProgramFlow(NamedTuple):
    """M0/M1 (pause) or M2/M30 (end of program)."""

    code: int


Action = Move | Dwell | ProgramFlow


def execute(state: ModalState, block: Block, rules: Rules) -> tuple[ModalState,
                                                                    list[Action]]:
    """Run one block from `state`: (the next state, the actions), or `GcodeError`."""
    g = block.g
    scale = MM_PER_INCH if g.get("units", state.units) == 200 else 1.0
    nm = g.get("non_modal")
    if rules.strict:
        _check_words(state, block, nm)
    st = _modal(state, block, scale)
    acts: list[Action] = []
    if nm is not None:
        st = _non_modal(st, block, scale, nm, acts)
    values = block.values
    moves = "X" in values or "Y" in values or "Z" in values or (
        not rules.strict and ("I" in values or "J" in values or "R" in values))
    if moves and nm not in _AXIS_USERS:
        st = _motion(st, block, scale, nm == 530, rules, acts)
    flow = block.m.get("stopping")
    if flow is not None:
        acts.append(ProgramFlow(flow))
        if flow in (2, 30):
            st = st.after_reset()
    return st, acts


def _check_words(state: ModalState, block: Block, nm: int | None) -> None:
    """GRBL's word checks: value words no command uses (`error:36`), axis words nobody
    uses (`error:31`) or two commands using them (`error:24`), G53 with arcs (`error:30`)."""
    values = block.values
    has_axes = any(a in values for a in AXES)
    motion = block.g.get("motion", state.motion if has_axes else None)
    if nm in _AXIS_USERS and "motion" not in block.g:
        motion = None
    used = set("NFST")
    if motion in (20, 30):
        used |= set("IJKR")
    if nm in (40, 100):
        used.add("P")
    if nm == 100:
        used.add("L")
    if has_axes:
        if nm not in _AXIS_USERS and (motion is None or motion == 800):
            raise GcodeError(errors.AXIS_WORDS_EXIST, "axis words without a motion command")
        if nm in _AXIS_USERS and "motion" in block.g:
            raise GcodeError(errors.AXIS_COMMAND_CONFLICT, "two commands that use the axis words")
    unused = set(values) - used - set(AXES)
    if unused:
        raise GcodeError(errors.UNUSED_WORDS, "unused words " + "".join(sorted(unused)))
    if nm == 530 and motion not in (0, 10):
        raise GcodeError(errors.G53_INVALID_MOTION_MODE, "G53 needs G0 or G1")


def _modal(state: ModalState, block: Block, scale: float) -> ModalState:
    """Feed, S, tool, spindle, coolant and the modal G groups of the block."""
    values = block.values
    upd: dict[str, Any] = {}  # field → new value: one update, none when nothing changes
    if "F" in values:
        upd["feed"] = values["F"] * scale
    if "S" in values:
        upd["s"] = values["S"]
    if "T" in values:
        upd["tool"] = int(values["T"])
    for group, code in block.m.items():
        if group == "spindle":
            upd["spindle"] = code
        elif group == "coolant":
            upd["coolant"] = frozenset() if code == 9 else state.coolant | {code}
    for group, code in block.g.items():
        if group in _FIELDS:
            if getattr(state, group) != code:
                upd[group] = code
        elif group == "wcs":
            upd["wcs"] = (code - 540) // 10
    return state.updated(upd) if upd else state


def _non_modal(st: ModalState, block: Block, scale: float, nm: int,
               acts: list[Action]) -> ModalState:
    """G4, G10, G28/G30 (and .1), G92 (and .1); G53 acts in `_motion`."""
    if nm == 40:
        if "P" not in block.values:
            raise GcodeError(errors.VALUE_WORD_MISSING, "G4 needs P")
        acts.append(Dwell(block.values["P"]))
    elif nm == 100:
        st = _g10(st, block, scale)
    elif nm == 920:
        st = _g92(st, block, scale)
    elif nm == 921:
        st = st._replace(g92=_ZERO)
    elif nm == 281:
        st = st._replace(g28=st.position)
    elif nm == 301:
        st = st._replace(g30=st.position)
    elif nm in (280, 300):
        st = _go_home(st, block, scale, st.g28 if nm == 280 else st.g30, acts)
    return st


def _g10(st: ModalState, block: Block, scale: float) -> ModalState:
    """G10 L2 P<n> (set offsets) / L20 P<n> (so the current position reads the words)."""
    values = block.values
    if "L" not in values or "P" not in values:
        raise GcodeError(errors.VALUE_WORD_MISSING, "G10 needs L and P")
    p = values["P"]
    if p != int(p) or not 0 <= p <= 6:
        raise GcodeError(errors.UNSUPPORTED_COORD_SYS, f"G10 P{p:g}")
    n = st.wcs if p == 0 else int(p) - 1
    lval = int(values["L"])
    if lval not in (2, 20):
        raise GcodeError(errors.UNSUPPORTED_COMMAND, f"G10 L{lval}")
    off = list(st.offsets[n])
    for i, a in enumerate(AXES):
        if a in values:
            v = values[a] * scale
            off[i] = v if lval == 2 else st.position[i] - st.g92[i] - v
    offsets = list(st.offsets)
    offsets[n] = (off[0], off[1], off[2])
    return st._replace(offsets=tuple(offsets))


def _g92(st: ModalState, block: Block, scale: float) -> ModalState:
    """G92: offsets so that the current position reads the axis words."""
    values = block.values
    if not any(a in values for a in AXES):
        raise GcodeError(errors.NO_AXIS_WORDS, "G92 needs axis words")
    g92 = list(st.g92)
    wcs = st.offsets[st.wcs]
    for i, a in enumerate(AXES):
        if a in values:
            g92[i] = st.position[i] - wcs[i] - values[a] * scale
    return st._replace(g92=(g92[0], g92[1], g92[2]))


def _go_home(st: ModalState, block: Block, scale: float, stored: Vec,
             acts: list[Action]) -> ModalState:
    """G28/G30: rapid through the optional intermediate point to the stored position (only
    the axes named, when some are)."""
    values = block.values
    named = [a in values for a in AXES]
    pos = st.position
    if any(named):
        mid = _target(st, values, scale, machine=False)
        acts.append(_rapid(st, pos, mid))
        pos = mid
    end = tuple(stored[i] if named[i] or not any(named) else pos[i] for i in range(3))
    target = (end[0], end[1], end[2])
    acts.append(_rapid(st, pos, target))
    return st._replace(position=target, motion=0)


def _rapid(st: ModalState, start: Vec, end: Vec) -> Move:
    """A G28/G30 rapid."""
    return Move(start, end, 0, None, st.feed, st.spindle, st.s, st.z_seen)


def _target(st: ModalState, values: dict[str, float], scale: float, machine: bool) -> Vec:
    """The axis words as a machine-frame target (G53: machine coordinates; G91: relative)."""
    x, y, z = st.position
    if st.distance == 910 and not machine:
        if "X" in values:
            x = x + values["X"] * scale
        if "Y" in values:
            y = y + values["Y"] * scale
        if "Z" in values:
            z = z + values["Z"] * scale
        return (x, y, z)
    wx, wy, wz = _ZERO if machine else st.work_offset()
    if "X" in values:
        x = values["X"] * scale + wx
    if "Y" in values:
        y = values["Y"] * scale + wy
    if "Z" in values:
        z = values["Z"] * scale + wz
    return (x, y, z)


def _motion(st: ModalState, block: Block, scale: float, machine: bool, rules: Rules,
            acts: list[Action]) -> ModalState:
    """The move of a block with axis words (or, not `strict`, arc words) in the modal
    motion mode."""
    values = block.values
    motion = st.motion
    if motion == 800:  # (strict: `_check_words` refused it already)
        what = "Z" if "Z" in values else "coordinates"
        raise GcodeError(errors.AXIS_WORDS_EXIST, f"{what} before any G0/G1/G2/G3")
    if rules.strict and motion != 0 and st.feed <= 0:
        raise GcodeError(errors.UNDEFINED_FEED_RATE, "G1/G2/G3 without a feed rate")
    arc = None
    if motion in (20, 30):
        if rules.strict and "X" not in values and "Y" not in values:
            raise GcodeError(errors.NO_AXIS_WORDS_IN_PLANE, "G2/G3 without X or Y")
        arc = ArcWords(motion == 20, _centre(st, values, scale), values.get("R"), scale,
                       rules.arcs)
    target = _target(st, values, scale, machine)
    z_seen = st.z_seen or "Z" in values
    acts.append(_new(Move, (st.position, target, motion, arc, st.feed, st.spindle, st.s,
                            z_seen)))
    return st.moved(target, z_seen)


def _centre(st: ModalState, values: dict[str, float], scale: float) -> Point | None:
    """An arc's centre from I/J: offsets from the start (G91.1) or work coordinates
    (G90.1); None without them."""
    if "I" not in values and "J" not in values:
        return None
    i, j = values.get("I", 0.0) * scale, values.get("J", 0.0) * scale
    if st.arc_distance == 901:
        wco = st.work_offset()
        return (i + wco[0], j + wco[1])
    return (st.position[0] + i, st.position[1] + j)


def check_target(target: Vec, max_xy_mm: float, max_z_mm: float | None) -> None:
    """`error:33` for a target with a coordinate larger than the front door takes (or not a
    number); `max_z_mm` None: Z is not checked. Each front door checks its moves' targets
    where its own order of checks puts it (the interpreter does not)."""
    x, y, z = target
    if not (abs(x) <= max_xy_mm and abs(y) <= max_xy_mm):
        raise GcodeError(errors.INVALID_TARGET, f"coordinate ({x:g}, {y:g}) mm is larger "
                                                f"than {max_xy_mm:g} mm")
    if max_z_mm is not None and not abs(z) <= max_z_mm:
        raise GcodeError(errors.INVALID_TARGET, f"coordinate Z{z:g} mm is larger than "
                                                f"{max_z_mm:g} mm")
