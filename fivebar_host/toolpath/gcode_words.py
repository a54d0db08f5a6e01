"""The G-code file reader's policy by word class: what each word the reader does not draw with
means on a five-bar pen plotter or laser (docs/gcode.md, "Word classes"), in one table.

Real files carry words for machines with more axes, spindles, coolant and tool changers. A
word falls in one class:

- **honoured**: drawn or followed as the reader's module doc says (G0–G3, G4, G17, G20/G21
  before the first move, G90/G91, G90.1/G91.1, G92, G94, G54, M2/M30, M3/M4/M5, F, S, X, Y,
  I, J, R, Z by the tool's rules).
- **skipped** (`SKIP`): cannot change the drawn path on this machine — coolant, air assist,
  fans, motor power, path blending and exact-stop modes, compensation and cycle cancels,
  messages and vendor set-up codes (the tables below), GRBL `$` commands and `?`/`~` query
  lines at the top of a file. Skipped words are collected and told in ONE note naming each
  kind and its lines (`Skipped.note`).
- **stop** (`STOP`, `TOOL`): `M0`/`M1`/`M60` pause the program, `T…`+`M6` change the tool:
  both become a pen-change stop before the next cut, naming the line (`compile.layers`: the
  pen goes up, the machine waits for the operator; `--no-pause` drops them). A `T` word
  alone only selects the next tool (skipped: the change is at `M6`).
- **home** (`HOME`): `G28`/`G30` travel to the stored position with the tool off (the reader
  draws nothing there and the pen is up after it; fivebar parks at its own homed pose at
  the end of every job).
- **pen** (`PEN`): `M300 S…` (the Makerbot Unicorn plug-in's servo pen) sets the pen state;
  `M300` with `P` is a Marlin beep (skipped).
- **refused**: words that would change the path or the burn (cutter compensation, canned
  cycles, other planes' arcs, inverse-time feed, other work coordinate systems, machine
  coordinates, probing, subroutines, other axes, G20/G21 after the first move): an error
  naming the line and the word, as before.

`--strict` (`read_gcode(strict=True)`) keeps the reader's older reading: every word outside
the honoured class is refused.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import Enum

from fivebar_host.gcode import GcodeError, Word, words
from fivebar_host.gcode.errors import UNSUPPORTED_COMMAND


class Kind(Enum):
    """A word class (module doc)."""

    SKIP = "skip"
    STOP = "stop"
    TOOL = "tool change"
    HOME = "home"
    PEN = "pen"


@dataclass(frozen=True)
class Rule:
    """A command's class, what it is (for the note and messages) and the value letters it
    owns on its line (taken away from the line, never read as X/Y/S/P of the drawing)."""

    kind: Kind
    what: str
    owns: str = ""


_SKIP = Kind.SKIP
#: G commands (as tenths, G64 → 640) the reader does not draw with, by class.
G_RULES: dict[int, Rule] = {
    400: Rule(_SKIP, "cutter compensation off"),
    490: Rule(_SKIP, "tool length offset off"),
    430: Rule(_SKIP, "tool length offset (Z is a pen state or ignored here)", "H"),
    431: Rule(_SKIP, "dynamic tool length offset (Z is a pen state or ignored here)", "Z"),
    610: Rule(_SKIP, "exact path mode"),
    611: Rule(_SKIP, "exact stop mode"),
    640: Rule(_SKIP, "path blending (fivebar keeps its own tolerance)", "PQ"),
    800: Rule(_SKIP, "canned cycle cancel"),
    980: Rule(_SKIP, "canned cycle return level"),
    990: Rule(_SKIP, "canned cycle return level"),
    280: Rule(Kind.HOME, "go home"),
    300: Rule(Kind.HOME, "go to the second home"),
}
#: M commands the reader does not draw with, by class (vendor codes named).
M_RULES: dict[int, Rule] = {
    0: Rule(Kind.STOP, "program pause"),
    1: Rule(Kind.STOP, "optional program pause"),
    60: Rule(Kind.STOP, "pallet change pause"),
    6: Rule(Kind.TOOL, "tool change", "T"),
    7: Rule(_SKIP, "mist coolant on"),
    8: Rule(_SKIP, "flood coolant on (air assist)"),
    9: Rule(_SKIP, "coolant off"),
    10: Rule(_SKIP, "air assist on (Marlin laser)"),
    11: Rule(_SKIP, "air assist off (Marlin laser)"),
    17: Rule(_SKIP, "motors on"),
    18: Rule(_SKIP, "motors off"),
    84: Rule(_SKIP, "motors off"),
    48: Rule(_SKIP, "overrides on"),
    49: Rule(_SKIP, "overrides off"),
    62: Rule(_SKIP, "digital output on (LinuxCNC)", "PQ"),
    63: Rule(_SKIP, "digital output off (LinuxCNC)", "PQ"),
    64: Rule(_SKIP, "digital output on (LinuxCNC)", "PQ"),
    65: Rule(_SKIP, "digital output off (LinuxCNC)", "PQ"),
    100: Rule(_SKIP, "Mr Beam air compressor", "P"),
    106: Rule(_SKIP, "fan speed (Marlin)", "PS"),
    107: Rule(_SKIP, "fan off (Marlin)", "P"),
    114: Rule(_SKIP, "position report (Marlin)"),
    115: Rule(_SKIP, "firmware report (Marlin)"),
    117: Rule(_SKIP, "display message (Marlin)"),
    118: Rule(_SKIP, "serial message (Marlin)"),
    300: Rule(Kind.PEN, "servo pen (Makerbot Unicorn)", "SP"),
    400: Rule(_SKIP, "wait for moves (Marlin)"),
    2000: Rule(_SKIP, "DexArm straight-line mode"),
    888: Rule(_SKIP, "DexArm tool head select", "P"),
    1112: Rule(Kind.HOME, "DexArm go home"),
}
#: G commands refused with the reason they would change the path or the burn (G tenths).
G_REFUSED: dict[int, str] = {
    410: "cutter radius compensation offsets the path by the tool's radius",
    420: "cutter radius compensation offsets the path by the tool's radius",
    930: "inverse-time feed (F is not a speed)",
    530: "a move in machine coordinates (fivebar draws in the file's frame)",
    100: "setting work offsets (the file's frame would move)",
    **{t: "another work coordinate system (its offset is the controller's, unknown here)"
       for t in (550, 560, 570, 580, 590, 591, 592, 593)},
    **{t: "a canned cycle (drilling or boring: a dot or hole at every point)"
       for t in (730, 760, 810, 820, 830, 840, 850, 860, 870, 880, 890)},
    **{t: "probing" for t in (382, 383, 384, 385)},
}
#: M commands refused with the reason.
M_REFUSED: dict[int, str] = {
    98: "a subroutine call (not followed here)",
    99: "a subroutine return (not followed here)",
    280: "a Marlin servo (its pen positions are not known here; map them to M3/M5 or Z)",
}


def refusal(w: Word) -> str | None:
    """Why a G or M word is refused, when the table says (None: an unknown word)."""
    if w.letter == "G":
        tenths = words.g_tenths(w.value)
        why = None if tenths is None else G_REFUSED.get(tenths)
    elif w.letter == "M" and w.value == int(w.value):
        why = M_REFUSED.get(int(w.value))
    else:
        why = None
    return None if why is None else f"{w.text}: {why}"


#: Marlin's message codes: the rest of the line is text, not words.
_MESSAGE = re.compile(r"^\s*(?:N\d+\s*)?M0*11[78](?![\d.])", re.IGNORECASE)
#: A GRBL `$` command or a real-time query typed on its own line.
_SYSTEM = re.compile(r"^\s*(\$.*|\?|~)\s*$")
#: Makerbot Unicorn's pen angles as its plug-in writes them in the file's header comment.
_UNICORN = re.compile(r"--pen-(up|down)-angle=([\d.]+)")
#: The Unicorn plug-in's defaults and its "servo off" value.
UNICORN_UP, UNICORN_DOWN, SERVO_OFF = 50.0, 30.0, 255.0


#: The note's name for GRBL's `$` lines and `?`/`~` typed on their own.
SYSTEM_KIND = "GRBL queries and settings"


def system_line(text: str) -> str | None:
    """A line that is a GRBL `$` command (not a jog) or a `?`/`~` typed on its own: its
    command as written for the note, else None. A `$J=` jog moves the machine and is refused."""
    m = _SYSTEM.match(text)
    if m is None:
        return None
    cmd = m.group(1)
    if cmd.upper().startswith("$J="):
        raise GcodeError(UNSUPPORTED_COMMAND, f"GRBL jog {words.shorten(cmd.strip())}: a jog "
                                              "moves the machine outside the program", cmd)
    return words.shorten(cmd.strip().split()[0] if cmd.strip() else cmd)


def message_line(text: str) -> bool:
    """A Marlin `M117`/`M118` message line (its text is not G-code)."""
    return _MESSAGE.match(text) is not None


def unicorn_angles(text: str) -> tuple[float, float]:
    """The servo pen's (up, down) `M300 S` values: the Unicorn plug-in's header comment
    (`--pen-up-angle=50 --pen-down-angle=30`) when the file has one, else its defaults."""
    found = dict(_UNICORN.findall(text[:4096]))
    return float(found.get("up", UNICORN_UP)), float(found.get("down", UNICORN_DOWN))


def rule_of(w: Word) -> Rule | None:
    """The class of a G or M word outside the honoured ones (None: refused)."""
    if w.letter == "G":
        tenths = words.g_tenths(w.value)
        return None if tenths is None else G_RULES.get(tenths)
    if w.letter == "M" and w.value == int(w.value):
        return M_RULES.get(int(w.value))
    return None


def _spans(lines: list[int]) -> str:
    """Line numbers as short spans: 1–4, 9, 12 (at most 8 spans, then the count)."""
    spans: list[tuple[int, int]] = []
    for ln in sorted(set(lines)):
        if spans and ln == spans[-1][1] + 1:
            spans[-1] = (spans[-1][0], ln)
        else:
            spans.append((ln, ln))
    text = ", ".join(f"{a}" if a == b else f"{a}–{b}" for a, b in spans[:8])
    if len(spans) > 8:
        text += f", … ({len(set(lines))} lines)"
    return text


@dataclass
class Skipped:
    """What was skipped: kind ("coolant off") → the words as written and their lines, for
    the one note."""

    kinds: dict[str, tuple[list[str], list[int]]] = field(default_factory=dict)

    def add(self, what: str, word: str, line: int) -> None:
        said, lines = self.kinds.setdefault(what, ([], []))
        if word and word not in said and len(said) < 6:
            said.append(word)
        if line > 0:
            lines.append(line)

    def note(self, file: str) -> str | None:
        """One warning naming each skipped kind, its words and lines (None: nothing)."""
        if not self.kinds:
            return None
        parts = []
        for what, (said, ls) in self.kinds.items():
            where = f" (line{'s' if len(set(ls)) > 1 else ''} {_spans(ls)})" if ls else ""
            parts.append(f"{what}{' ' if said else ''}{' '.join(said)}{where}")
        return (f"{file}: skipped what cannot change the drawn path on this machine: "
                + "; ".join(parts) + " (--strict refuses these)")
