"""G-code words: a line's text → its words → a `Block`, the words sorted into GRBL's modal
groups.

Two pre-parsers, one per kind of input, then one parser of the words (`parse`):

- `preparse`: a line from a GRBL sender, as GRBL 1.1 pre-parses it (protocol.c): blanks
  dropped, `(…)` comments (an unclosed one runs to the end of the line) and `;…` dropped,
  letters upper-cased; at most `LINE_MAX` characters may be left (`error:11`).
- `strip_file`: a line of a G-code file (RS274NGC, NIST IR 6556 §3.3): `;…` dropped, `(…)`
  comments that must close on their line, a checksum `*…` dropped, a `%` line (program
  delimiter) empty. Blanks stay: they may separate words and a letter from its number.
- `parse`: the words, each a letter and a number (`NUMBER`: digits with at most one point,
  an optional sign, no exponent; anything else is `error:1`, not a letter, or `error:2`, a
  letter without a number, the message quoting what cannot be read), then the `Block`:
  command words by GRBL's modal groups (`G_GROUPS`, `M_GROUPS`; G numbers as tenths: G28.1
  → 281), value words by letter. `strict` applies GRBL's word rules (gcode.c): one command
  per modal group (`error:21`), N, P, F, S, T not negative (`error:4`), N an integer up to
  9 999 999 (`error:27`), T up to 255 (`error:38`), L and T integers (`error:23`). Without
  it (the file reader) a later command of a group replaces an earlier one (`Block.gcodes`
  keeps them all), N words are skipped and the values are left to the caller's rules. A
  value word twice is `error:25` in both.

Which of the words it knows a front door honours is that front door's `Policy`: `parse`
passes every word through it, in order, before sorting it, and `Block.words` keeps them
all. A policy may also set a word aside (the file reader's words that cannot change the
drawn path, and the commands it turns into stops): such a word is not sorted, whatever it
is, and `Block.skipped` keeps it for the front door.

`whole_token` and `shorten` give an error the whole token a bad number was written as
(`X1e308`, `X1.2.3`), shortened when it is long, for the file reader's messages.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from math import isfinite
from operator import itemgetter
from typing import NamedTuple, NoReturn

from fivebar_host.gcode import errors
from fivebar_host.gcode.errors import GcodeError
from kinematics.errors import shorten as shorten_value

#: GRBL's line buffer is 80 bytes: 79 characters after pre-parsing, then the terminator.
LINE_MAX = 79
#: A word's number: digits with at most one decimal point, an optional sign, no exponent.
NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)")
_NUM = NUMBER.pattern
_WORD = re.compile(rf"([A-Za-z])\s*({_NUM})")
#: A word (the word, its letter, its number) or, where there is none, one character of junk.
_TOKEN = re.compile(rf"\s*(?:(([A-Za-z])\s*({_NUM}))|(\S))")
_JUNK = itemgetter(3)
_PAREN = re.compile(r"\([^)]*\)")

#: Value words GRBL 1.1 knows (A, B, C, D, E, H, O, Q, U, V, W are unsupported).
VALUE_WORDS = frozenset("FIJKLNPRSTXYZ")
AXES = "XYZ"

#: The G commands the interpreter knows, by modal group (GRBL's numbering), as tenths
#: (G18, G19 and G93 are known so that GRBL's answers hold; both front doors refuse them).
G_GROUPS: dict[int, str] = {
    40: "non_modal", 100: "non_modal", 280: "non_modal", 281: "non_modal",
    300: "non_modal", 301: "non_modal", 530: "non_modal", 920: "non_modal",
    921: "non_modal",
    0: "motion", 10: "motion", 20: "motion", 30: "motion", 800: "motion",
    170: "plane", 180: "plane", 190: "plane",
    900: "distance", 910: "distance", 901: "arc_distance", 911: "arc_distance",
    930: "feed_mode", 940: "feed_mode",
    200: "units", 210: "units",
    400: "cutter", 490: "tool_length",
    540: "wcs", 550: "wcs", 560: "wcs", 570: "wcs", 580: "wcs", 590: "wcs",
    610: "control",
}
#: The M commands, by modal group.
M_GROUPS: dict[int, str] = {0: "stopping", 1: "stopping", 2: "stopping", 30: "stopping",
                            3: "spindle", 4: "spindle", 5: "spindle",
                            7: "coolant", 8: "coolant", 9: "coolant"}


class Word(NamedTuple):
    """One word: its letter (upper case), its value and its text as written (blanks
    removed), which messages quote."""

    letter: str
    value: float
    text: str


_new_word = tuple.__new__  # `Word(...)` without its Python-level __new__: `parse` is hot


@dataclass(slots=True)
class Block:
    """One line's words: every word in order (`words`), the command of each modal group (`g`,
    G as tenths; `m`), every G command in order (`gcodes`) and the value words (`values`)."""

    words: list[Word]
    g: dict[str, int]
    m: dict[str, int]
    gcodes: list[int]
    values: dict[str, float]
    skipped: list[Word]


def preparse(raw: str) -> str:
    """A sender's line as GRBL pre-parses it (module doc); `error:11` when too long."""
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
        raise GcodeError(errors.LINE_OVERFLOW,
                         f"{len(text)} characters after pre-parsing (GRBL takes {LINE_MAX})")
    return text


def strip_file(raw: str) -> str:
    """A file's line without its comments, checksum and surrounding blanks (module doc); an
    unclosed parenthesis is an error."""
    s = raw
    if ";" in s:
        s = s.split(";", 1)[0]
    if "(" in s:
        if s.count("(") != s.count(")"):
            raise GcodeError(errors.EXPECTED_COMMAND_LETTER, "unbalanced parenthesis comment")
        s = _PAREN.sub(" ", s)
    if "*" in s:
        s = s.split("*", 1)[0]
    s = s.strip()
    return "" if s == "%" else s


def _unreadable(text: str) -> NoReturn:
    """Raise for the first text between the words that is not a word."""
    pos, gap = 0, ""
    for m in _WORD.finditer(text):
        gap = text[pos:m.start()].strip()
        if gap:
            break
        pos = m.end()
    else:
        gap = text[pos:].strip()
    code = errors.BAD_NUMBER_FORMAT if gap[0].isascii() and gap[0].isalpha() else \
        errors.EXPECTED_COMMAND_LETTER
    raise GcodeError(code, f"cannot read {gap!r}", gap)


def g_tenths(value: float) -> int | None:
    """A G number as tenths (G28.1 → 281), None when it is not a whole number of tenths
    (GRBL's test: within 1e-6)."""
    tenths = round(value * 10)
    return tenths if abs(value * 10 - tenths) <= 1e-6 else None


class Policy(NamedTuple):
    """What a front door honours of the words the interpreter knows: a word whose letter is
    in `plain` is taken as the interpreter reads it; any other goes to `check` first, which
    refuses it by raising `GcodeError` (in the order of the line: the first refused word is
    the one named), or returns True to set it aside (`Block.skipped`: not sorted, for the
    front door to deal with), or a false value to let it be sorted."""

    plain: frozenset[str]
    check: Callable[[Word], bool | None]


def parse(text: str, strict: bool, policy: Policy | None = None) -> Block:
    """A pre-parsed line → `Block`: its words (`error:1`/`error:2` for anything else, before
    any other check), each passed by `policy`, then sorted (module doc: `strict`)."""
    found = _TOKEN.findall(text)
    if any(map(_JUNK, found)):
        _unreadable(text)
    words: list[Word] = []
    g: dict[str, int] = {}
    m: dict[str, int] = {}
    gcodes: list[int] = []
    values: dict[str, float] = {}
    skipped: list[Word] = []
    plain, check = policy or _HONOUR_ALL
    for as_written, letter, number, _ in found:
        letter, value, tok = letter.upper(), float(number), as_written.replace(" ", "")
        w = _new_word(Word, (letter, value, tok))
        words.append(w)
        if not isfinite(value):
            raise GcodeError(errors.BAD_NUMBER_FORMAT, f"{shorten(tok)}: not a finite number",
                             tok)
        if check is not None and letter not in plain and check(w):
            skipped.append(w)
            continue
        if letter == "G":
            tenths = value * 10
            if tenths.is_integer():  # exact tenths (G1, G17): both ways agree, no rounding
                code = int(tenths)
            else:
                code = _g_code(w) if strict else round(round(value, 1) * 10)
            group = G_GROUPS.get(code) or _unknown_g(w, code)
            if strict and group in g:
                _second_in_group(w, group)
            g[group] = code
            gcodes.append(code)
        elif letter == "M":
            code = _m_code(w)
            group = M_GROUPS.get(code) or _unknown(w, errors.UNSUPPORTED_COMMAND)
            if strict and group in m:
                _second_in_group(w, group)
            m[group] = code
        elif strict:
            _strict_value(values, w)
        elif letter != "N":
            if letter in values:
                _repeated(w)
            values[letter] = value
    return Block(words, g, m, gcodes, values, skipped)


_HONOUR_ALL: tuple[frozenset[str], Callable[[Word], bool | None] | None] = (frozenset(), None)
#: Characters a number may be written with (`X1e308`, `X1.2.3`, `X--5`: one token each).
_NUMBERISH = frozenset("0123456789.+-eE")
#: A token longer than this is shortened in messages.
SHORT_MAX = 24


def whole_token(text: str, part: str) -> str:
    """The token of `text` that `part` (a word or the junk a message names) was read from:
    the number-like characters around it, with the letter before them (`X1e308` for `e308`
    in `G1 X1e308`), so a message names what the user wrote, not a piece of it."""
    at = text.find(part)
    if at < 0:
        return part
    start, end = at, at + len(part)
    while start > 0 and text[start - 1] in _NUMBERISH:
        start -= 1
    if start > 0 and text[start - 1].isalpha():
        start -= 1
    while end < len(text) and text[end] in _NUMBERISH:
        end += 1
    return text[start:end]


def shorten(token: str) -> str:
    """A token as a message quotes it: whole when short, else its first 12 and last 6
    characters and its length (`kinematics.errors.shorten`: a megabyte of digits must not
    fill the terminal)."""
    return token if len(token) <= SHORT_MAX else shorten_value(token, 19)


def _g_code(w: Word) -> int:
    """A G word's number as tenths, `error:20` when it is no whole number of them."""
    tenths = g_tenths(w.value)
    return _unknown(w, errors.UNSUPPORTED_COMMAND) if tenths is None else tenths


def _m_code(w: Word) -> int:
    """An M word's number: a whole number (`error:23`)."""
    if w.value != int(w.value):
        raise GcodeError(errors.COMMAND_VALUE_NOT_INTEGER, f"{w.text}: M codes are whole numbers",
                         w.text)
    return int(w.value)


def _unknown_g(w: Word, tenths: int) -> NoReturn:
    """An unknown G command: `error:20`, or `error:23` for a decimal of a known one (GRBL's
    answer to G1.5)."""
    known_base = tenths % 10 and G_GROUPS.get(tenths - tenths % 10) is not None
    _unknown(w, errors.COMMAND_VALUE_NOT_INTEGER if known_base else errors.UNSUPPORTED_COMMAND)


def _unknown(w: Word, code: int) -> NoReturn:
    """A word the interpreter does not know."""
    kind = f"{w.letter}-code word" if w.letter in "GM" else "word"
    raise GcodeError(code, f"unsupported {kind} {w.text}", w.text)


def _second_in_group(w: Word, group: str) -> NoReturn:
    """GRBL: one command per modal group and line (`error:21`)."""
    raise GcodeError(errors.MODAL_GROUP_VIOLATION, f"{w.text}: a second {group} command on "
                                                   "the line", w.text)


def _repeated(w: Word) -> NoReturn:
    """A value word once per line (`error:25`)."""
    raise GcodeError(errors.WORD_REPEATED, f"word {w.letter} appears twice", w.text)


def _strict_value(values: dict[str, float], w: Word) -> None:
    """A value word with GRBL's checks (module doc), in GRBL's order."""
    letter, value, text = w
    if letter not in VALUE_WORDS:
        _unknown(w, errors.UNSUPPORTED_COMMAND)
    if letter in values:
        _repeated(w)
    values[letter] = value
    if letter in "FNPST" and value < 0:
        raise GcodeError(errors.NEGATIVE_VALUE, f"{text}: negative", text)
    if letter == "N" and (value != int(value) or value > 9_999_999):
        raise GcodeError(errors.INVALID_LINE_NUMBER, f"invalid line number {text}", text)
    if letter == "T" and value > 255:
        raise GcodeError(errors.TOOL_NUMBER_EXCEEDED, f"{text}: tool numbers go to 255", text)
    if letter in "LT" and value != int(value):
        raise GcodeError(errors.COMMAND_VALUE_NOT_INTEGER, f"{text}: not a whole number", text)
