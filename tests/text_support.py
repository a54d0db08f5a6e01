"""Helpers of the text tests: a metrics-only TrueType font made from a bundled SVG font
(so headless Chromium lays text out with exactly the advances and vertical metrics fivebar
uses), and the browser's glyph origins of every `<text>` in a page.

Chromium does not render SVG fonts, so the reference layout needs a font format it reads.
fontTools (already installed: a dependency of matplotlib) builds a TrueType font whose
glyphs carry each SVG glyph's advance, whose cmap maps the same characters, whose hhea and
OS/2 metrics are the SVG font's ascent, descent and x-height, and whose outlines are empty
(only the metrics take part in the comparison). No kerning table: the layout tests use the
Hershey fonts, which have no kerning.
"""

from __future__ import annotations

import base64
import io
import json
from pathlib import Path
from typing import Any

from fivebar_host.toolpath.fonts.svgfont import Font


def metrics_ttf(font: Font, family: str) -> bytes:
    """A TrueType font with `font`'s advances and vertical metrics (module doc)."""
    from fontTools.fontBuilder import FontBuilder
    from fontTools.pens.ttGlyphPen import TTGlyphPen

    em = round(font.units_per_em)
    assert em == font.units_per_em, "integer units per em (TrueType)"
    chars = [c for c in font.characters() if len(c) == 1]
    names = [".notdef"] + [f"g{ord(c):04X}" for c in chars]
    fb = FontBuilder(em, isTTF=True)
    fb.setupGlyphOrder(names)
    fb.setupCharacterMap({ord(c): f"g{ord(c):04X}" for c in chars})
    empty = TTGlyphPen(None).glyph()
    fb.setupGlyf({n: empty for n in names})
    adv = {".notdef": (round(font.missing_advance), 0)}
    for c in chars:
        g = font.glyph(c)
        assert g is not None
        # TrueType advances are integers; the Hershey fonts' are multiples of 0.5 units
        # (1/2000 em): the test compares within 0.2 mm, this rounds by ≤ 0.5 unit
        adv[f"g{ord(c):04X}"] = (round(g.advance), 0)
    fb.setupHorizontalMetrics(adv)
    asc, desc = round(font.ascent), round(font.descent)
    fb.setupHorizontalHeader(ascent=asc, descent=desc, lineGap=0)
    fb.setupOS2(sTypoAscender=asc, sTypoDescender=desc, sTypoLineGap=0, usWinAscent=asc,
                usWinDescent=-desc, sxHeight=round(font.x_height),
                sCapHeight=round(font.cap_height), fsSelection=0x80, version=4)
    fb.setupNameTable({"familyName": family, "styleName": "Regular"})
    fb.setupPost()
    buf = io.BytesIO()
    fb.save(buf)
    return buf.getvalue()


def page(svg: str, fonts: dict[str, bytes]) -> str:
    """An HTML page with the SVG inline and the fonts as @font-face data URLs."""
    faces = "".join(
        f"@font-face {{ font-family: '{name}'; src: url(data:font/ttf;base64,"
        f"{base64.b64encode(data).decode()}) format('truetype'); }}"
        for name, data in fonts.items())
    return (f"<!doctype html><html><head><style>{faces} body {{ margin: 0 }}</style></head>"
            f"<body>{svg}</body></html>")


#: Per text element: its id, the map from its user space to the root <svg>'s viewport (px
#: from its top-left corner; a, b, c, d, e, f), and per character its start position and
#: rotation, and the extent of its glyph cell (x, y, width, height), in the text's user
#: space. The start position leaves out `dominant-baseline`; the cell's top is the
#: baseline less the ascent.
JS_ORIGINS = """
const svg = document.querySelector('svg');
const box = svg.getBoundingClientRect();
const out = [];
for (const t of document.querySelectorAll('text')) {
  const m = t.getScreenCTM();
  const n = t.getNumberOfChars();
  const chars = [];
  for (let i = 0; i < n; i++) {
    const p = t.getStartPositionOfChar(i);
    const e = t.getExtentOfChar(i);
    chars.push([p.x, p.y, t.getRotationOfChar(i), e.x, e.y, e.width, e.height]);
  }
  out.push({id: t.id, n: n, ctm: [m.a, m.b, m.c, m.d, m.e - box.left, m.f - box.top],
            chars: chars});
}
return JSON.stringify(out);
"""


def browser_origins(driver: Any, directory: Path, html: str) -> list[dict[str, Any]]:
    """The browser's glyph origins of every <text> in the page (see `JS_ORIGINS`), once the
    fonts are loaded."""
    f = directory / "layout.html"
    f.write_text(html, encoding="utf-8")
    driver.get(f.as_uri())
    driver.execute_async_script("const done = arguments[0]; document.fonts.ready.then("
                                "() => done(true));")
    return list(json.loads(driver.execute_script(JS_ORIGINS)))


def segments_of(points: list[Any]) -> Any:
    """The chords (n, 2, 2) of polylines (each an (m, 2) array)."""
    import numpy as np

    parts = [np.stack([p[:-1], p[1:]], axis=1) for p in points if len(p) > 1]
    return np.concatenate(parts) if parts else np.zeros((0, 2, 2))


def doubled(segs: Any, line_tol: float = 0.005, min_len: float = 0.05) -> int:
    """How many pairs of chords lie on one line (within `line_tol`) and overlap along more
    than `min_len`: a piece of stroke drawn twice. Chords are grouped by their line (angle
    and offset, rounded, neighbours included), so the count takes no quadratic time."""
    import math

    import numpy as np

    d = segs[:, 1] - segs[:, 0]
    length = np.hypot(d[:, 0], d[:, 1])
    keep = length > min_len
    a, d, length = segs[keep, 0], d[keep], length[keep]
    u = d / length[:, None]
    flip = (u[:, 0] < 0) | ((u[:, 0] == 0) & (u[:, 1] < 0))
    u[flip] *= -1
    theta = np.arctan2(u[:, 1], u[:, 0])
    rho = a[:, 0] * u[:, 1] - a[:, 1] * u[:, 0]
    t0 = a @ np.array([1.0, 0.0]) * u[:, 0] + a[:, 1] * u[:, 1]
    lo, hi = np.minimum(t0, t0 + np.where(flip, -length, length)), np.maximum(
        t0, t0 + np.where(flip, -length, length))
    tq, rq = np.round(theta / 1e-3).astype(int), np.round(rho / line_tol).astype(int)
    bins: dict[tuple[int, int], list[int]] = {}
    for i, key in enumerate(zip(tq.tolist(), rq.tolist(), strict=True)):
        bins.setdefault(key, []).append(i)
    count = 0
    for i, (q, r) in enumerate(zip(tq.tolist(), rq.tolist(), strict=True)):
        for dq in (-1, 0, 1):
            for dr in (-1, 0, 1):
                for j in bins.get((q + dq, r + dr), ()):
                    if j <= i or abs(rho[i] - rho[j]) > line_tol or \
                            abs(math.sin(theta[i] - theta[j])) * max(length[i], length[j]) > \
                            line_tol:
                        continue
                    if min(hi[i], hi[j]) - max(lo[i], lo[j]) > min_len:
                        count += 1
    return count
