"""Computed style of the SVG reader: which properties inherit, what makes an element invisible,
and the luminance of a colour (for masks).

A pen draws outlines, so of the paint only "is anything painted" matters: a shape is drawn
when its stroke or its fill is painted (colour or paint server, opacity above zero, and for the
stroke a positive width). Partial opacity and dashes cannot be drawn by a pen; the reader says
so once per kind (see `walk`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

#: Inherited properties (CSS/SVG) and their initial values.
INHERITED = {"visibility": "visible", "stroke": "none", "fill": "black", "stroke-width": "1",
             "fill-opacity": "1", "stroke-opacity": "1", "clip-rule": "nonzero",
             "fill-rule": "nonzero", "stroke-dasharray": "none",
             "marker-start": "none", "marker-mid": "none", "marker-end": "none"}
#: Inherited text properties and their initial values (CSS Fonts 4, CSS Text 3, SVG 2 §11).
#: They enter an element's properties only where some element sets them (`text_prop`
#: reads the initial value otherwise), so drawings without text copy no more per element.
#: font-family "" is the profile's default family (CSS leaves the initial value to the UA);
#: white-space "" defers to `xml:space`.
TEXT_INHERITED = {"font-family": "", "font-weight": "normal", "font-style": "normal",
                  "text-anchor": "start", "dominant-baseline": "auto",
                  "letter-spacing": "normal", "word-spacing": "normal", "white-space": "",
                  "font-kerning": "auto", "text-transform": "none", "direction": "ltr",
                  "writing-mode": "horizontal-tb", "font-variant": "normal"}

_NAMED = {"black": (0, 0, 0), "white": (255, 255, 255), "red": (255, 0, 0),
          "lime": (0, 255, 0), "green": (0, 128, 0), "blue": (0, 0, 255),
          "yellow": (255, 255, 0), "cyan": (0, 255, 255), "aqua": (0, 255, 255),
          "magenta": (255, 0, 255), "fuchsia": (255, 0, 255), "gray": (128, 128, 128),
          "grey": (128, 128, 128), "silver": (192, 192, 192)}
_RGB = re.compile(r"rgba?\(\s*([^,\s]+)\s*,?\s*([^,\s]+)\s*,?\s*([^,\s/)]+)\s*"
                  r"(?:[,/]\s*([^)\s]+)\s*)?\)$")


def inherit(parent: dict[str, str], specified: dict[str, str]) -> dict[str, str]:
    """Inherited properties of an element from its parent's and its own specified values
    (`inherit` takes the parent's, `initial` the initial value)."""
    out = dict(parent)
    for k, v in specified.items():
        initial = INHERITED.get(k, TEXT_INHERITED.get(k))
        if initial is None or v == "inherit":
            continue
        out[k] = initial if v == "initial" else v
    return out


def text_prop(props: dict[str, str], key: str) -> str:
    """An inherited text property (its initial value where no element set it)."""
    return props.get(key, TEXT_INHERITED[key]).strip()


def number_or_percent(text: str | None, default: float = 1.0) -> float:
    """An opacity-like value clamped to 0…1; invalid values fall back to `default`, as CSS
    ignores an invalid declaration."""
    if text is None:
        return default
    t = text.strip()
    try:
        v = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        return default
    return min(max(v, 0.0), 1.0) if v == v else default


def painted(value: str) -> bool:
    """A fill or stroke value that paints something."""
    v = value.strip().lower()
    return v not in ("none", "transparent") and not re.fullmatch(
        r"rgba\(.*[,/]\s*0*\.?0*%?\s*\)|#[0-9a-f]{6}00|#[0-9a-f]{3}0", v)


@dataclass(frozen=True)
class Colour:
    """A solid colour's luminance and alpha (0…1); `known` False for a colour this reader
    cannot evaluate (a paint server `url(...)`, `currentColor`, an unlisted name)."""

    luminance: float
    alpha: float
    known: bool = True


def colour(value: str) -> Colour:
    """Luminance (sRGB coefficients, as CSS Masking's luminance mask) and alpha of a colour."""
    v = value.strip().lower()
    if v in ("none", "transparent"):
        return Colour(0.0, 0.0)
    rgb: tuple[float, float, float] | None = None
    alpha = 1.0
    if v in _NAMED:
        rgb = _NAMED[v]
    elif re.fullmatch(r"#[0-9a-f]{3,4}|#[0-9a-f]{6}|#[0-9a-f]{8}", v):
        h = v[1:]
        if len(h) in (3, 4):
            h = "".join(c * 2 for c in h)
        rgb = (int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16))
        alpha = int(h[6:8], 16) / 255 if len(h) == 8 else 1.0
    elif m := _RGB.match(v):
        try:
            rgb = tuple(_channel(m.group(i)) for i in (1, 2, 3))  # type: ignore[assignment]
            alpha = number_or_percent(m.group(4)) if m.group(4) else 1.0
        except ValueError:
            rgb = None
    if rgb is None:
        return Colour(0.0, 1.0, known=False)
    r, g, b = (c / 255.0 for c in rgb)
    return Colour(0.2125 * r + 0.7154 * g + 0.0721 * b, alpha)


def _channel(t: str) -> float:
    v = float(t[:-1]) * 2.55 if t.endswith("%") else float(t)
    return min(max(v, 0.0), 255.0)
