"""SVG fonts (SVG 1.1 chapter 20) as single-stroke glyphs: `Font`, `Glyph`, `load_svg_font`.

A single-stroke font is an SVG font whose glyph outlines are open paths (the Hershey fonts,
Relief SingleLine, the EMS fonts of the Hershey Text extension): each subpath of a glyph's `d`
is one pen-down run. SVG fonts are XML, so they are read with the SVG reader's own expat
parser (`svg.xmltree`) and path-data parser (`svg.pathdata`); no font library is needed.

Read (SVG 1.1 §20.3–20.8): `<font horiz-adv-x horiz-origin-x>`, `<font-face units-per-em
ascent descent x-height cap-height underline-position overline-position
strikethrough-position font-family>`,
`<missing-glyph>`, `<glyph unicode glyph-name horiz-adv-x d>` (a `unicode` of several
characters is a ligature, matched longest first, §20.4) and `<hkern u1 g1 u2 g2 k>` (kerning
pairs by character, unicode range or glyph name; `k` is subtracted from the advance, §20.7).
Coordinates are font units, y up from the baseline. Vertical metrics (`vert-*`, `<vkern>`),
`arabic-form` and `lang` are not used (horizontal Latin text only).

Glyph geometry is parsed on first use (a font of 600 glyphs loads in a few ms) and kept as
numpy arrays of the Drawing's primitive kinds, ready to be placed by one affine map.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import transform
from kinematics.arrays import FloatArray, IntArray

if TYPE_CHECKING:
    from fivebar_host.toolpath.svg.xmltree import Node

_RANGE = re.compile(r"^U\+([0-9A-Fa-f?]{1,6})(?:-([0-9A-Fa-f]{1,6}))?$")
#: Largest number of characters a unicode range may expand to in a kerning pair.
MAX_RANGE = 0x3000


@dataclass(frozen=True)
class Glyph:
    """One glyph: its name, characters, advance (font units) and strokes as primitives in font
    units (y up): `kinds` (N,), `params` (N, 8), `starts` (S,) the first primitive of each
    stroke (pen-down run)."""

    name: str
    unicode: str
    advance: float
    kinds: NDArray[np.int8]
    params: FloatArray
    starts: IntArray

    @property
    def n_strokes(self) -> int:
        return int(self.starts.shape[0])


@dataclass
class _Raw:
    """A glyph as read: geometry parsed on first use."""

    name: str
    unicode: str
    advance: float
    d: str
    line: int
    parsed: Glyph | None = None


@dataclass
class Font:
    """One SVG font face. `name`: the `<font>` id or the file stem; `family`: its
    `font-family`. Metrics in font units (y up)."""

    name: str
    family: str
    file: str
    units_per_em: float
    ascent: float
    descent: float  # negative: below the baseline
    x_height: float
    cap_height: float
    underline_position: float
    underline_thickness: float
    overline_position: float
    strikethrough_position: float
    origin_x: float
    missing_advance: float
    _by_char: dict[str, _Raw] = field(default_factory=dict, repr=False)
    _ligatures: dict[str, list[_Raw]] = field(default_factory=dict, repr=False)
    _by_name: dict[str, _Raw] = field(default_factory=dict, repr=False)
    _kern: dict[tuple[str, str], float] = field(default_factory=dict, repr=False)

    def has(self, ch: str) -> bool:
        """Whether the font has a glyph for this character."""
        return ch in self._by_char or ch in self._ligatures

    def match(self, text: str, i: int) -> tuple[Glyph, int] | None:
        """The glyph for the characters of `text` from index `i` and how many characters it
        covers (the longest ligature first, §20.4), or None when the font has no glyph for
        `text[i]`."""
        ch = text[i]
        for raw in self._ligatures.get(ch, ()):
            if text.startswith(raw.unicode, i):
                return self._parse(raw), len(raw.unicode)
        single = self._by_char.get(ch)
        return None if single is None else (self._parse(single), 1)

    def glyph(self, ch: str) -> Glyph | None:
        """The glyph of one character (None when the font has none)."""
        raw = self._by_char.get(ch)
        return None if raw is None else self._parse(raw)

    def kerning(self, a: Glyph, b: Glyph) -> float:
        """Kerning between two glyphs, font units to subtract from a's advance."""
        return self._kern.get((a.name, b.name), 0.0) if self._kern else 0.0

    @property
    def n_glyphs(self) -> int:
        return len(self._by_name)

    def characters(self) -> list[str]:
        """The characters the font has a glyph for (single code points), sorted."""
        return sorted(self._by_char)

    def _parse(self, raw: _Raw) -> Glyph:
        if raw.parsed is None:
            raw.parsed = _glyph_geometry(raw, self.origin_x, self.file)
        return raw.parsed


def _glyph_geometry(raw: _Raw, origin_x: float, file: str) -> Glyph:
    """Parse a glyph's path data into primitive arrays (font units, origin shifted by
    horiz-origin-x). Invalid path data in a font is an error naming the font and glyph."""
    # imported here: the SVG reader's package imports the font library (no import cycle)
    from fivebar_host.toolpath.svg.pathdata import parse_path

    res = parse_path(raw.d)
    if res.error is not None:
        raise InputError(f"font glyph {raw.name!r} has invalid path data at column "
                         f"{res.error.pos + 1}: {res.error.reason}", file, raw.line)
    kinds: list[int] = []
    params: list[tuple[float, ...]] = []
    starts: list[int] = []
    for sub in res.subpaths:
        starts.append(len(kinds))
        for kind, p in sub:
            kinds.append(kind)
            params.append(p + (0.0,) * (8 - len(p)))
    arr = np.array(params, dtype=np.float64).reshape(-1, 8)
    k = np.array(kinds, dtype=np.int8)
    if origin_x and arr.size:
        arr = transform(k, arr, np.identity(2), np.array([-origin_x, 0.0]))
    return Glyph(raw.name, raw.unicode, raw.advance, k, arr, np.array(starts, dtype=np.int64))


def _number(node: Node, key: str, default: float, file: str) -> float:
    text = node.get(key)
    if text is None or not text.strip():
        return default
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"<{node.tag}> {key}={text!r} is not a number", file,
                         node.line) from None
    if not math.isfinite(v):
        raise InputError(f"<{node.tag}> {key}={text!r} is not finite", file, node.line)
    return v


def _find_font(root: Node, file: str) -> Node:
    stack = [root]
    while stack:
        n = stack.pop()
        if n.tag == "font" and n.is_svg:
            return n
        stack.extend(reversed(n.children))
    raise InputError("not an SVG font: the file has no <font> element (SVG 1.1 chapter 20)",
                     file)


def load_svg_font(source: str | Path | bytes, file: str | None = None,
                  name: str | None = None) -> Font:
    """Read the first `<font>` of an SVG font file (a path, or bytes with `file` naming them
    in messages); `name` defaults to the font's id, else the file stem."""
    from fivebar_host.toolpath.svg.xmltree import Node, parse_xml  # as in _glyph_geometry

    if isinstance(source, bytes):
        data, fname = source, file or "<font>"
    else:
        fname = file or str(source)
        try:
            data = Path(source).read_bytes()
        except OSError as e:
            raise InputError(f"cannot read font file: {e.strerror or e}", fname) from e
    font_node = _find_font(parse_xml(data, fname), fname)
    face = next((c for c in font_node.children if c.tag == "font-face"), None) or Node(
        "font-face", "", {}, font_node.line)
    em = _number(face, "units-per-em", 1000.0, fname)
    if em <= 0:
        raise InputError(f"<font-face> units-per-em must be positive; got {em:g}", fname,
                         face.line)
    ascent = _number(face, "ascent", 0.8 * em, fname)
    adv = _number(font_node, "horiz-adv-x", 0.5 * em, fname)
    stem = Path(fname).stem
    font = Font(
        name=name or font_node.get("id") or stem, family=face.get("font-family") or stem,
        file=fname, units_per_em=em, ascent=ascent,
        descent=-abs(_number(face, "descent", -0.2 * em, fname)),  # signs vary by tool
        x_height=_number(face, "x-height", 0.5 * ascent, fname),
        cap_height=_number(face, "cap-height", 0.7 * ascent, fname),
        underline_position=_number(face, "underline-position", -0.1 * em, fname),
        underline_thickness=_number(face, "underline-thickness", 0.05 * em, fname),
        overline_position=_number(face, "overline-position", ascent, fname),
        strikethrough_position=_number(face, "strikethrough-position",
                                       0.5 * _number(face, "x-height", 0.5 * ascent, fname),
                                       fname),
        origin_x=_number(font_node, "horiz-origin-x", 0.0, fname), missing_advance=adv)
    for child in font_node.children:
        if child.tag == "missing-glyph":
            font.missing_advance = _number(child, "horiz-adv-x", adv, fname)
        elif child.tag == "glyph":
            _add_glyph(font, child, adv, fname)
    for child in font_node.children:
        if child.tag == "hkern":
            _add_kern(font, child, fname)
    return font


def _add_glyph(font: Font, node: Node, default_adv: float, file: str) -> None:
    uni = node.get("unicode") or ""
    name = node.get("glyph-name") or (f"uni{ord(uni):04X}" if len(uni) == 1 else
                                      f"glyph{len(font._by_name)}")
    raw = _Raw(name, uni, _number(node, "horiz-adv-x", default_adv, file), node.get("d") or "",
               node.line)
    font._by_name.setdefault(name, raw)
    if node.get("orientation", "h") == "v" or not uni:
        return  # vertical-only forms and unaddressable glyphs (an empty unicode) are not used
    if len(uni) == 1:
        font._by_char.setdefault(uni, raw)  # the first glyph for a character wins (§20.4)
    else:
        ligs = font._ligatures.setdefault(uni[0], [])
        ligs.append(raw)
        ligs.sort(key=lambda r: -len(r.unicode))


def _names(font: Font, node: Node, u: str, g: str, file: str) -> set[str]:
    """Glyph names of one side of a kerning pair (characters, ranges and glyph names)."""
    out = {n.strip() for n in (node.get(g) or "").split(",") if n.strip()}
    for item in (node.get(u) or "").split(","):
        item = item.strip()
        m = _RANGE.match(item)
        if m:
            lo_text = m.group(1)
            lo = int(lo_text.replace("?", "0"), 16)
            hi = int(m.group(2), 16) if m.group(2) else int(lo_text.replace("?", "F"), 16)
            if hi < lo or hi - lo > MAX_RANGE:
                raise InputError(f"<hkern> {u}: unicode range {item!r} is reversed or larger "
                                 f"than {MAX_RANGE} characters", file, node.line)
            chars = [chr(c) for c in range(lo, hi + 1)]
        else:
            chars = [item] if item else []
        out.update(font._by_char[c].name for c in chars if c in font._by_char)
    return out


def _add_kern(font: Font, node: Node, file: str) -> None:
    k = _number(node, "k", 0.0, file)
    if k == 0:
        return
    for a in _names(font, node, "u1", "g1", file):
        for b in _names(font, node, "u2", "g2", file):
            font._kern.setdefault((a, b), k)  # the first pair given wins
