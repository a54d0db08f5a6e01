"""The layout goal: SVG text laid out by fivebar agrees with headless Chromium's layout of
the same SVG, glyph origin by glyph origin, within 0.2 mm.

Chromium lays the text out with a metrics-only TrueType font made from the bundled SVG font
(`tests/text_support.py`: the same advances, ascent, descent and x-height), so both sides use
the same metrics and any difference is layout: white space, x/y/dx/dy/rotate lists,
text-anchor per chunk, letter- and word-spacing, font-size units, transforms and viewBox,
dominant-baseline, alignment-baseline, baseline-shift, text on a path. The browser's
reference point of a glyph is its start position (`getStartPositionOfChar`, which includes
baseline-shift and alignment-baseline); the start position leaves out `dominant-baseline`,
so in the case that tests it the baseline comes from the glyph cell (`getExtentOfChar`:
top = baseline − ascent), at 20 px where the fonts' ascent and descent are whole pixels
(Chromium rounds them, which would otherwise shift the cell by up to half a pixel). Both
sides are mapped to the page (px of the root viewport) by their own transforms. Each case
also checks that both count the same addressable characters and rotate each glyph alike
(0.5°).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fivebar_host.toolpath.fonts.library import FontLibrary, TextConfig
from fivebar_host.toolpath.svg import read_svg
from fivebar_host.toolpath.svg.text import CharLayout
from fivebar_host.toolpath.svg.units import MM_PER_PX
from tests.text_support import browser_origins, metrics_ttf, page
from tests.web_support import browser_missing, chromium, record

pytestmark = pytest.mark.browser
TOL_MM = 0.2
#: Test family → bundled face (the browser gets a metrics font of the same face).
FONTS = {"FBSans": "futural", "FBSerif": "timesr", "FBScript": "scripts"}
HEAD = ('<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
        'width="600" height="400" {extra} style="font-family:FBSans;font-size:20px">')
ARC = '<path id="arc" d="M 100 300 A 100 100 0 0 1 300 300" fill="none"/>'
LINE = '<path id="line" d="M 50 350 L 550 350" fill="none"/>'
WAVE = '<path id="wave" d="M 320 300 C 380 200 450 400 560 280" fill="none"/>'
CASES: dict[str, tuple[str, str]] = {
    "plain": ("", '<text id="a" x="10" y="40">Hello, World! 123</text>'),
    "anchors": ("", '<text id="s" x="300" y="40">Start</text>'
                    '<text id="m" x="300" y="80" text-anchor="middle">Middle text</text>'
                    '<text id="e" x="300" y="120" text-anchor="end">End.</text>'),
    "chunks": ("", '<text id="c" text-anchor="middle"><tspan x="300" y="40">First line'
                   '</tspan><tspan x="300" y="70" text-anchor="end">second</tspan>'
                   '<tspan x="300" dy="30" text-anchor="start">third</tspan></text>'),
    "lists": ("", '<text id="l" x="10 30 50" y="40 45" dx="0 2 4 6 8" dy="1 -1">'
                  'abcdefgh<tspan x="200" dx="3 3">ijk</tspan>lm</text>'),
    "nested": ("", '<text id="n" x="10" y="60" dx="1 1 1 1 1 1 1 1">ab<tspan dx="5">cd'
                   '<tspan dy="-8">ef</tspan></tspan>gh</text>'),
    "spacing": ("", '<text id="ls" x="10" y="40" letter-spacing="3">Spaced out</text>'
                    '<text id="ws" x="10" y="80" word-spacing="0.5em">word spacing here'
                    '</text><text id="neg" x="590" y="120" letter-spacing="-1px" '
                    'text-anchor="end">tight text</text>'),
    "sizes": ("", '<text id="z" x="10" y="60">a<tspan font-size="2em">b</tspan>'
                  '<tspan font-size="150%">c</tspan><tspan font-size="12pt">d</tspan>'
                  '<tspan font-size="5mm">e</tspan><tspan font-size="larger">f</tspan></text>'),
    "fonts": ("", '<text id="f" x="10" y="60" font-family="FBSerif">Serif <tspan '
                  'font-family="FBScript">script</tspan> and <tspan style="font: 30px FBSans">'
                  'sans</tspan></text>'),
    "whitespace": ("", '<text id="w1" x="10" y="40">  a   lot\n\tof   <tspan> space </tspan>'
                       ' here  </text><text id="w2" x="10" y="80" xml:space="preserve">  '
                       'kept  \n spaces </text>'),
    "transforms": ("", '<g transform="translate(50 20) scale(1.5)"><text id="t1" x="10" '
                       'y="40" transform="rotate(10)">Rotated</text></g><text id="t2" '
                       'x="300" y="200" transform="skewX(-20) scale(1 0.8)" '
                       'text-anchor="middle">Skewed</text><text id="t3" x="0" y="0" '
                       'transform="matrix(0.8 0.3 -0.3 0.8 200 300)">Matrix</text>'),
    "viewbox": ('viewBox="0 0 120 80" preserveAspectRatio="xMidYMid meet"',
                '<text id="v" x="60" y="40" font-size="8" text-anchor="middle">In a '
                'viewBox</text><text id="v2" x="2" y="70" font-size="5mm">mm font</text>'),
    "rotate": ("", '<text id="r1" x="10" y="60" rotate="15">all fifteen</text>'
                   '<text id="r2" x="10" y="120" rotate="0 10 20 30 -30">rotates</text>'),
    "baselines": ("", "".join(
        f'<text id="b{i}" x="{10 + 70 * (i % 8)}" y="{60 + 60 * (i // 8)}" '
        f'dominant-baseline="{b}">Ax</text>' for i, b in enumerate(
            ("auto", "alphabetic", "middle", "central", "mathematical", "hanging",
             "text-before-edge", "text-after-edge", "ideographic")))),
    "shifts": ("", '<text id="sh" x="10" y="60">E=mc<tspan baseline-shift="super">2'
                   '</tspan> H<tspan baseline-shift="sub">2</tspan>O <tspan '
                   'baseline-shift="5">up</tspan><tspan baseline-shift="-25%">down</tspan>'
                   '<tspan alignment-baseline="middle">mid</tspan></text>'),
    "path_line": ("", LINE + '<text id="p1"><textPath href="#line" startOffset="10">'
                             'along a line</textPath></text><text id="p2"><textPath '
                             'xlink:href="#line" startOffset="50%" text-anchor="middle">'
                             'centred</textPath></text>'),
    "path_arc": ("", ARC + '<text id="pa"><textPath href="#arc" startOffset="20">Round '
                           'and round</textPath></text>'),
    "path_curve": ("", WAVE + '<text id="pc" font-size="16"><textPath href="#wave" '
                              'startOffset="5%">on a cubic curve, far too long to fit '
                              '</textPath></text>'),
    "path_end": ("", ARC + '<text id="pe" text-anchor="end"><textPath href="#arc" '
                           'startOffset="100%">the end</textPath></text>'),
    "css": ("", '<style>.big { font-size: 28px; letter-spacing: 2px } text.c { '
                'text-anchor: middle } #k tspan { font-family: FBSerif }</style>'
                '<text id="k" class="c" x="300" y="60">CSS <tspan class="big">rules'
                '</tspan></text>'),
    "transform_case": ("", '<text id="u" x="10" y="60" style="text-transform:uppercase">'
                           'shout it</text>'),
}


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    why = browser_missing()
    if why is not None:
        pytest.skip(why)
    with chromium(tmp_path_factory.mktemp("chromium-text")) as driver:
        yield driver


@pytest.fixture(scope="module")
def ttfs() -> dict[str, bytes]:
    lib = FontLibrary()
    return {name: metrics_ttf(lib.load(face), name) for name, face in FONTS.items()}


def ours(svg: str) -> tuple[list[CharLayout], float]:
    """fivebar's layouts of the document, and the page height in mm."""
    layouts: list[CharLayout] = []
    d = read_svg(svg.encode(), text=TextConfig(aliases=FONTS), layouts=layouts)
    assert d.page_size_mm is not None
    return layouts, d.page_size_mm[1]


#: The case whose baselines come from the glyph cells (module doc).
CELL_BASELINES = {"baselines"}


def reference(t: dict[str, Any], cells: bool) -> tuple[np.ndarray, np.ndarray]:
    """The browser's glyph origins (page px) and rotations of one text element; with
    `cells`, upright glyphs' baselines from their cells (module doc)."""
    a, b, c, d, e, f = t["ctm"]
    pts, rot = [], []
    for sx, sy, r, _ex, ey, _ew, eh in t["chars"]:
        # the cell's top is the baseline less the ascent, 0.8 of the cell's height: every
        # test font has ascent 800 and descent −200
        ux, uy = (sx, ey + 0.8 * eh) if cells and r == 0 else (sx, sy)
        pts.append((a * ux + c * uy + e, b * ux + d * uy + f))
        rot.append(r)
    return np.array(pts).reshape(-1, 2), np.array(rot)


@pytest.mark.parametrize("case", list(CASES))
def test_layout_matches_chromium(case: str, browser: Any, ttfs: dict[str, bytes],
                                 tmp_path: Path) -> None:
    extra, body = CASES[case]
    svg = HEAD.format(extra=extra) + body + "</svg>"
    got, height_mm = ours(svg)
    want = [t for t in browser_origins(browser, tmp_path, page(svg, ttfs))
            if any(g.ident == t["id"] for g in got)]
    assert [t["id"] for t in want] == [g.ident for g in got]
    worst = 0.0
    for g, t in zip(got, want, strict=True):
        assert t["n"] == len(g.chars), (g.ident, g.chars)
        ref, rot = reference(t, case in CELL_BASELINES)
        mine = np.column_stack([g.drawing[:, 0], height_mm - g.drawing[:, 1]]) / MM_PER_PX
        dev = np.hypot(*(mine - ref).T) * MM_PER_PX
        dev[~g.placed] = 0.0  # off its path: not rendered by either (Chromium: no position)
        assert dev.max(initial=0.0) <= TOL_MM, (g.ident, g.chars, dev.round(3))
        drot = (g.rotate - rot + 180.0) % 360.0 - 180.0
        assert np.abs(drot[g.placed]).max(initial=0.0) <= 0.5, (g.ident, drot.round(2))
        worst = max(worst, float(dev.max(initial=0.0)))
    record(f"text_layout_{case}", {"max_origin_mm": round(worst, 4),
                                   "chars": sum(len(g.chars) for g in got)})
