"""GRBL's line parser: a sender's line → a `Block` of command and value words, with GRBL's
error codes (gcode.c of GRBL 1.1, as its documentation describes the rules).

Pre-parsing as GRBL does: spaces and tabs dropped, `(...)` and `;...` comments dropped,
letters upper-cased; what is left may be at most `LINE_MAX` characters (`error:11`). Every
word is a letter and a number (`error:1`, `error:2`); command words are sorted into GRBL's
modal groups (two in one group: `error:21`); a value word twice is `error:25`; words GRBL
does not know are `error:20`. Nothing is skipped silently.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from fivebar_host.bridge import codes
from fivebar_host.bridge.codes import GrblError

#: GRBL's line buffer is 80 bytes: 79 characters after pre-parsing, then the terminator.
LINE_MAX = 79
#: Value words GRBL 1.1 accepts (A, B, C, D, E, H, O, Q, U, V, W are unsupported).
VALUE_WORDS = frozenset("FIJKLNPRSTXYZ")
AXES = "XYZ"
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)")

#: Command words by modal group (GRBL's numbering); G values as tenths (G28.1 → 281).
G_GROUPS: dict[int, str] = {
    40: "non_modal", 100: "non_modal", 280: "non_modal", 281: "non_modal",
    300: "non_modal", 301: "non_modal", 530: "non_modal", 920: "non_modal",
    921: "non_modal",
    0: "motion", 10: "motion", 20: "motion", 30: "motion", 800: "motion",
    170: "plane", 180: "plane", 190: "plane",
    900: "distance", 910: "distance", 911: "arc_distance",
    930: "feed_mode", 940: "feed_mode",
    200: "units", 210: "units",
    400: "cutter", 490: "tool_length",
    540: "wcs", 550: "wcs", 560: "wcs", 570: "wcs", 580: "wcs", 590: "wcs",
    610: "control",
}
#: G-codes GRBL 1.1 knows that the bridge refuses: probing, dynamic tool length offset,
#: inverse-time feed, the XZ and YZ planes (a pen or laser five-bar has no such arcs),
#: G92.2/G92.3 do not exist in GRBL either.
G_REFUSED = {382, 383, 384, 385, 431, 930, 180, 190}
M_GROUPS = {0: "stopping", 1: "stopping", 2: "stopping", 30: "stopping",
            3: "spindle", 4: "spindle", 5: "spindle", 7: "coolant", 8: "coolant",
            9: "coolant"}


@dataclass
class Block:
    """One parsed line: command words by modal group (G as tenths), value words, and the
    axis words it holds."""

    g: dict[str, int] = field(default_factory=dict)
    m: dict[str, int] = field(default_factory=dict)
    values: dict[str, float] = field(default_factory=dict)

    @property
    def axes(self) -> dict[str, float]:
        return {a: self.values[a] for a in AXES if a in self.values}


def preparse(raw: str) -> str:
    """Drop blanks and comments, upper-case; `error:11` when too long for GRBL's buffer."""
    out: list[str] = []
    depth = False
    for ch in raw:
        if depth:
            depth = ch != ")"
            continue
        if ch == "(":
            depth = True
        elif ch == ";":
            break
        elif ch not in " \t\r":
            out.append(ch.upper())
    text = "".join(out)
    if len(text) > LINE_MAX:
        raise GrblError(codes.LINE_OVERFLOW, f"{len(text)} characters after pre-parsing")
    return text


def words(text: str) -> list[tuple[str, float, str]]:
    """(letter, value, number text) of each word of a pre-parsed line."""
    out: list[tuple[str, float, str]] = []
    i = 0
    while i < len(text):
        letter = text[i]
        if not ("A" <= letter <= "Z"):
            raise GrblError(codes.EXPECTED_COMMAND_LETTER, f"{letter!r} is not a word letter")
        m = _NUMBER.match(text, i + 1)
        if m is None:
            raise GrblError(codes.BAD_NUMBER_FORMAT, f"{letter} without a number")
        out.append((letter, float(m.group()), m.group()))
        i = m.end()
    return out


def _g_word(block: Block, value: float) -> None:
    tenths = round(value * 10)
    if abs(value * 10 - tenths) > 1e-6:
        raise GrblError(codes.UNSUPPORTED_COMMAND, f"G{value:g}")
    if tenths in G_REFUSED:
        raise GrblError(codes.UNSUPPORTED_COMMAND, f"G{value:g} is not supported by the bridge")
    group = G_GROUPS.get(tenths)
    if group is None:
        if tenths % 10 and G_GROUPS.get(tenths - tenths % 10) is not None:
            raise GrblError(codes.COMMAND_VALUE_NOT_INTEGER, f"G{value:g}")
        raise GrblError(codes.UNSUPPORTED_COMMAND, f"G{value:g}")
    if group in block.g:
        raise GrblError(codes.MODAL_GROUP_VIOLATION, f"two {group} commands")
    block.g[group] = tenths


def _m_word(block: Block, value: float) -> None:
    if value != int(value):
        raise GrblError(codes.COMMAND_VALUE_NOT_INTEGER, f"M{value:g}")
    group = M_GROUPS.get(int(value))
    if group is None:
        raise GrblError(codes.UNSUPPORTED_COMMAND, f"M{value:g}")
    if group in block.m:
        raise GrblError(codes.MODAL_GROUP_VIOLATION, f"two {group} commands")
    block.m[group] = int(value)


def _value_word(block: Block, letter: str, value: float) -> None:
    if letter not in VALUE_WORDS:
        raise GrblError(codes.UNSUPPORTED_COMMAND, f"word {letter}")
    if letter in block.values:
        raise GrblError(codes.WORD_REPEATED, f"{letter} twice")
    if letter in "FNPST" and value < 0:
        raise GrblError(codes.NEGATIVE_VALUE, f"{letter}{value:g}")
    if letter == "N" and (value != int(value) or value > 9_999_999):
        raise GrblError(codes.INVALID_LINE_NUMBER, f"N{value:g}")
    if letter == "T" and value > 255:
        raise GrblError(38, f"T{value:g}")
    if letter in "LT" and value != int(value):
        raise GrblError(codes.COMMAND_VALUE_NOT_INTEGER, f"{letter}{value:g}")
    block.values[letter] = value


def parse(text: str) -> Block:
    """A pre-parsed line → `Block` (module doc: the errors)."""
    block = Block()
    for letter, value, _ in words(text):
        if letter == "G":
            _g_word(block, value)
        elif letter == "M":
            _m_word(block, value)
        else:
            _value_word(block, letter, value)
    return block
