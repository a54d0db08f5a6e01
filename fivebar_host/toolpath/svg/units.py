"""Lengths, number lists and viewports of SVG, converted once.

- `parse_length`: a page size (root `width`/`height`) in mm; unitless means px (96 px/in).
- `Lengths.user`: a length on a shape in user units, per CSS Values and SVG 2 §8.9: absolute
  units through px; `%` of the nearest viewport's width (x-like attributes), height (y-like)
  or normalised diagonal √((w² + h²)/2) (r, stroke-width); `em` = the element's font-size
  (default 16 px, as browsers), `ex` = em/2 (what resvg and browsers without font metrics use).
- `numbers`: SVG number lists (`points`, `viewBox`) by the SVG grammar, so compact lists such as
  `1-2`, `.5.5` or `1e-1-1e2` (what minifiers write) split as the spec says.
- `viewport_transform`: viewBox + preserveAspectRatio → 3×3 matrix (SVG 1.1 §7.8).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import MAX_COORD_MM

MM_PER_PX = 25.4 / 96.0
#: mm per unit for the absolute length units of CSS/SVG.
UNIT_MM = {"": MM_PER_PX, "px": MM_PER_PX, "mm": 1.0, "cm": 10.0, "in": 25.4,
           "pt": 25.4 / 72.0, "pc": 25.4 / 6.0, "q": 0.25}
NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_LENGTH_RE = re.compile(rf"\s*({NUMBER})\s*([a-zA-Z%]*)\s*$")
_NUMBER_RE = re.compile(NUMBER)
_SEP_RE = re.compile(r"\s*,?\s*")
_WSP_RE = re.compile(r"\s*")
#: A number list `number_prefix` reads to the end without an error: every number and
#: separator an atomic group and the repeat possessive, so each takes what the loop's own
#: match takes (a separator's comma must be followed by a number). ASCII text only.
_LIST_RE = re.compile(rf"\s*(?:(?>{NUMBER})(?:(?>\s*(?:,\s*)?)(?>{NUMBER}))*+\s*)?")
DEFAULT_FONT_PX = 16.0

#: Which viewport dimension a percentage of an attribute refers to (SVG 2 §8.9).
AXIS = {"x": "x", "x1": "x", "x2": "x", "cx": "x", "width": "x", "rx": "x", "dx": "x",
        "fx": "x", "y": "y", "y1": "y", "y2": "y", "cy": "y", "height": "y", "ry": "y",
        "dy": "y", "fy": "y"}


def _split(text: str, file: str, line: int, what: str) -> tuple[float, str]:
    m = _LENGTH_RE.match(text)
    if not m:
        raise InputError(f"{what} = {text!r} is not a length", file, line)
    value = float(m.group(1))
    if not math.isfinite(value):
        raise InputError(f"{what} = {text!r} is not a finite number", file, line)
    return value, m.group(2).lower()


def parse_length(text: str | None, file: str, line: int, what: str,
                 default_mm: float | None = None, percent_of_mm: float | None = None) -> float:
    """A CSS length → mm. Unitless means px (96 px/in); % needs `percent_of_mm`."""
    if text is None or not text.strip():
        if default_mm is None:
            raise InputError(f"missing {what}", file, line)
        return default_mm
    value, unit = _split(text, file, line, what)
    if unit == "%":
        if percent_of_mm is None:
            raise InputError(f"{what} = {text!r}: percent needs a reference size", file, line)
        return value / 100.0 * percent_of_mm
    if unit in ("em", "ex"):
        value *= DEFAULT_FONT_PX * (0.5 if unit == "ex" else 1.0)
        unit = "px"
    if unit not in UNIT_MM:
        raise InputError(f"{what} = {text!r}: unsupported unit {unit!r} "
                         f"(use mm, cm, in, pt, pc, px, em, ex or %)", file, line)
    mm = value * UNIT_MM[unit]
    if not math.isfinite(mm) or abs(mm) > MAX_COORD_MM:
        raise InputError(f"{what} = {text!r} is not a usable size", file, line)
    return mm


@dataclass(frozen=True)
class Lengths:
    """What relative lengths on an element refer to: the nearest viewport (user units) and
    the element's font-size (user units)."""

    width: float
    height: float
    font_px: float = DEFAULT_FONT_PX

    def user(self, text: str | None, file: str, line: int, what: str,
             default: float = 0.0) -> float:
        """A length attribute in user units (unitless = user unit; absolute units via px)."""
        if text is None or not text.strip():
            return default
        value, unit = _split(text, file, line, what)
        if unit == "%":
            axis = AXIS.get(what, "d")
            ref = (self.width if axis == "x" else self.height if axis == "y"
                   else math.sqrt((self.width ** 2 + self.height ** 2) / 2))
            v = value / 100.0 * ref
        elif unit == "em":
            v = value * self.font_px
        elif unit == "ex":
            v = value * self.font_px / 2
        elif unit in UNIT_MM:
            v = value * UNIT_MM[unit] / MM_PER_PX
        else:
            raise InputError(f"{what} = {text!r}: unsupported unit {unit!r}", file, line)
        if not math.isfinite(v):
            raise InputError(f"{what} = {text!r} is not a finite number", file, line)
        return v

    def font_size(self, text: str | None, file: str, line: int) -> float:
        """A `font-size` value → px, relative to this (the parent's) font-size."""
        if text is None or not text.strip():
            return self.font_px
        t = text.strip().lower()
        keywords = {"medium": 16.0, "small": 13.0, "large": 18.0, "x-small": 10.0,
                    "x-large": 24.0, "xx-small": 9.0, "xx-large": 32.0}
        if t in keywords:
            return keywords[t]
        if t in ("inherit", "smaller", "larger", "initial"):
            return self.font_px * {"smaller": 1 / 1.2, "larger": 1.2}.get(t, 1.0)
        value, unit = _split(t, file, line, "font-size")
        if unit == "%":
            return value / 100.0 * self.font_px
        if unit in ("em", "rem"):
            return value * (self.font_px if unit == "em" else DEFAULT_FONT_PX)
        if unit == "ex":
            return value * self.font_px / 2
        if unit in UNIT_MM:
            return value * UNIT_MM[unit] / MM_PER_PX
        raise InputError(f"font-size = {text!r}: unsupported unit {unit!r}", file, line)


def number_prefix(text: str) -> tuple[list[float], int | None]:
    """The numbers of an SVG number list up to its first error, and the 0-based column of
    that error (None: the whole list is valid). Numbers are separated by whitespace and/or
    one comma, or by nothing where the grammar allows it (`1-2`, `.5.5`, `1e-1-1e2`)."""
    if text.isascii() and _LIST_RE.fullmatch(text):  # valid: the numbers at once
        return [float(x) for x in _NUMBER_RE.findall(text)], None
    return _scan_numbers(text)


def _scan_numbers(text: str) -> tuple[list[float], int | None]:
    """`number_prefix` by the scanner, number by number up to the first error."""
    out: list[float] = []
    m0 = _WSP_RE.match(text)
    i, n = (m0.end() if m0 else 0), len(text)
    while i < n:
        m = _NUMBER_RE.match(text, i)
        if not m:
            return out, i
        out.append(float(m.group()))
        i = m.end()
        sep = _SEP_RE.match(text, i)
        assert sep is not None
        if sep.end() == n and "," in sep.group():
            return out, i
        i = sep.end()
    return out, None


def numbers(text: str, file: str, line: int, what: str) -> list[float]:
    """An SVG number list (see `number_prefix`); any error is an `InputError`."""
    out, err = number_prefix(text)
    if err is not None:
        raise InputError(f"{what}: {text[err:err + 12]!r} (column {err + 1}) is not a number",
                         file, line)
    return out


def viewport_transform(viewbox: Sequence[float] | None, width: float, height: float,
                       par: str | None) -> np.ndarray:
    """3×3 map from viewBox user units to the viewport (width × height, same units),
    per SVG 1.1 §7.8 (preserveAspectRatio: align and meet|slice, or none)."""
    t = np.identity(3)
    if viewbox is None:
        return t
    vx, vy, vw, vh = viewbox
    sx, sy = width / vw, height / vh
    words = (par or "xMidYMid meet").split()
    align = words[0] if words else "xMidYMid"
    if align == "defer" and len(words) > 1:
        words = words[1:]
        align = words[0]
    slice_ = len(words) > 1 and words[1] == "slice"
    if align == "none":
        t[0, 0], t[1, 1] = sx, sy
        t[0, 2], t[1, 2] = -vx * sx, -vy * sy
        return t
    s = max(sx, sy) if slice_ else min(sx, sy)
    tx, ty = -vx * s, -vy * s
    ax = align[1:4].lower() if len(align) >= 8 else "mid"
    ay = align[5:8].lower() if len(align) >= 8 else "mid"
    if ax == "mid":
        tx += (width - vw * s) / 2
    elif ax == "max":
        tx += width - vw * s
    if ay == "mid":
        ty += (height - vh * s) / 2
    elif ay == "max":
        ty += height - vh * s
    t[0, 0] = t[1, 1] = s
    t[0, 2], t[1, 2] = tx, ty
    return t
