"""Markers against the browser (tests/svg_markers/): each file is rendered by headless
Chromium and read by fivebar; every point fivebar draws has browser ink within 1.5 px
(0.19 user units at 8 px per unit) and every inked pixel of the browser lies within the
stroke's half width + 1.5 px of fivebar's lines. The marker content's strokes are made
1 px wide in the browser (`vector-effect: non-scaling-stroke`), its fills none: a pen draws
outlines. `python -m pytest tests/test_svg_markers.py -s` prints the figures.
"""

from __future__ import annotations

import io
import itertools
import re
from pathlib import Path

import numpy as np
import pytest
from web_support import browser_missing, chromium

from fivebar_host.toolpath.geometry import flatten
from fivebar_host.toolpath.svg import read_svg

CORPUS = Path(__file__).resolve().parent / "svg_markers"
FILES = sorted(CORPUS.glob("*.svg"))
PX_PER_MM = 96 / 25.4
#: Browser ink must be this close to fivebar's lines beyond the stroke's half width, px.
TOL_PX = 1.5
#: Inside markers: 1 px lines, no fill (the reader draws outlines).
STYLE = ("<style>marker * { vector-effect: non-scaling-stroke; stroke-width: 1px "
         "!important; fill: none !important }</style>")

pytestmark = pytest.mark.skipif(browser_missing() is not None,
                                reason=browser_missing() or "")


def _render(driver: object, svg: str, size: tuple[int, int]) -> np.ndarray:
    """The browser's pixels of the SVG (grey levels, rows top down)."""
    from PIL import Image

    page = ("<html><body style='margin:0;background:white'>"
            + svg.replace(">", ">" + STYLE, 1) + "</body></html>")
    driver.get("data:text/html;charset=utf-8," + page.replace("#", "%23"))  # type: ignore[attr-defined]
    elem = driver.find_element("css selector", "svg")  # type: ignore[attr-defined]
    img = Image.open(io.BytesIO(elem.screenshot_as_png)).convert("L")
    assert img.size == size, img.size
    return np.asarray(img, dtype=np.float64)


def _half_width_px(svg: str) -> float:
    """The widest stroke of the file's shapes, half of it in px (user unit = 8 px)."""
    widths = [float(w) for w in re.findall(r'stroke-width="([\d.]+)"', svg)]
    return max(widths) * 8 / 2


def _dense(d: object, step_px: float = 0.25) -> np.ndarray:
    """fivebar's drawn lines as points every `step_px` along every chord (page px)."""
    poly = flatten(d, 0.0005)  # type: ignore[arg-type]
    pts = d.to_file_frame(poly.points) * PX_PER_MM  # type: ignore[attr-defined]
    out = []
    for a, b in zip(poly.offsets[:-1], poly.offsets[1:], strict=True):
        run = pts[a:b]
        for p0, p1 in itertools.pairwise(run):
            n = max(2, int(np.hypot(*(p1 - p0)) / step_px) + 2)
            out.append(p0 + (p1 - p0) * np.linspace(0, 1, n)[:, None])
    return np.concatenate(out)


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_markers_match_the_browser(path: Path, tmp_path: Path) -> None:
    from scipy.ndimage import distance_transform_edt

    svg = path.read_text()
    size = (800, 600)
    d = read_svg(path)
    assert not [w for w in d.warnings if "marker" in w]
    pts = _dense(d)  # page px, y down
    with chromium(tmp_path / "profile") as driver:
        ink = _render(driver, svg, size) < 160
    # every drawn point near browser ink
    far_from_ink = distance_transform_edt(~ink)
    ij = np.clip(np.rint(pts[:, ::-1] - 0.5).astype(int), 0, [size[1] - 1, size[0] - 1])
    miss = far_from_ink[ij[:, 0], ij[:, 1]]
    # every browser pixel near a drawn line (the lines rasterised densely)
    dense = pts
    mine = np.zeros((size[1], size[0]), dtype=bool)
    k = np.clip(np.rint(dense[:, ::-1] - 0.5).astype(int), 0, [size[1] - 1, size[0] - 1])
    mine[k[:, 0], k[:, 1]] = True
    far_from_mine = distance_transform_edt(~mine)[ink]
    bound = _half_width_px(svg) + TOL_PX
    print(f"{path.name}: {d.n_strokes} strokes; drawn points from browser ink max "
          f"{miss.max():.2f} px, browser ink from drawn lines max {far_from_mine.max():.2f} px "
          f"(bound {bound:.2f} px = {bound / 8:.3f} units)")
    assert miss.max() <= TOL_PX + 0.5
    assert far_from_mine.max() <= bound
