"""The fill corpus (tests/svg_fills/) measured against headless Chromium: the area the browser
inks for each file against the area fivebar's hatch covers (hatch length × spacing, the
Cavalieri estimate, so the figure comes from the drawn lines, not from fivebar's regions),
and whether any hatch line leaves the browser's ink. Shared by `tests/test_fill_browser.py`
and `benchmarks/fill.py`.

Every corpus file is 800 × 800 px with a 100-unit viewBox (8 px a unit, 0.2646 mm a px),
its fills black on white, so the browser's coverage of a pixel is 1 − grey/255.
"""

from __future__ import annotations

import io
import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.compile.fill import Hatch, fill_drawing
from fivebar_host.toolpath.geometry import Drawing, flatten
from fivebar_host.toolpath.svg import read_svg

ROOT = Path(__file__).resolve().parent.parent
CORPUS = ROOT / "tests" / "svg_fills"
SIZE_PX = 800
MM_PER_PX = 25.4 / 96
#: Hatch spacing of the area measurement, mm (fine: the estimate's own error stays far
#: below 1 % even on the 1-unit slivers).
SPACING = 0.05
#: The tolerance the corpus is hatched with, mm.
TOL = 0.01


@dataclass(frozen=True)
class Figures:
    """One file's figures: areas in mm², the relative difference, and the hatch points
    farther than `far_px` from the browser's ink (count and the largest distance, px)."""

    name: str
    browser_mm2: float
    hatch_mm2: float
    far_points: int
    worst_px: float

    @property
    def error(self) -> float:
        return (self.hatch_mm2 - self.browser_mm2) / self.browser_mm2


def render(driver: Any, svg: str) -> np.ndarray:
    """The browser's coverage (0…1) of every pixel, rows top down."""
    from PIL import Image

    page = ("<html><body style='margin:0;background:white'>" + svg + "</body></html>")
    driver.get("data:text/html;charset=utf-8," + page.replace("#", "%23"))
    elem = driver.find_element("css selector", "svg")
    img = Image.open(io.BytesIO(elem.screenshot_as_png)).convert("L")
    assert img.size == (SIZE_PX, SIZE_PX), img.size
    return 1.0 - np.asarray(img, dtype=np.float64) / 255.0


def hatched(path: Path, spacing: float = SPACING, angle: float = 45.0) -> Drawing:
    """The file read and hatched with hidden lines removed (so overlapping fills count once,
    as the browser paints them)."""
    return fill_drawing(read_svg(path), Hatch(spacing, angle, False, 0.0), True, TOL)


def hatch_points(d: Drawing, step_mm: float = 0.05) -> np.ndarray:
    """Points every `step_mm` along the hatch lines (not the links), page px (y down)."""
    hatch_src = np.array([s.role == "hatch" for s in d.sources], dtype=bool)
    poly = flatten(d, TOL)
    pts = d.to_file_frame(poly.points) / MM_PER_PX
    out = []
    for i, (a, b) in enumerate(zip(poly.offsets[:-1], poly.offsets[1:], strict=True)):
        if not hatch_src[d.stroke_source[poly.stroke[i]]]:
            continue
        run = pts[a:b]
        for p0, p1 in itertools.pairwise(run):
            n = max(2, int(np.hypot(*(p1 - p0)) * MM_PER_PX / step_mm) + 2)
            out.append(p0 + (p1 - p0) * np.linspace(0, 1, n)[:, None])
    return np.concatenate(out) if out else np.zeros((0, 2))


def measure(driver: Any, path: Path, far_px: float = 1.5) -> Figures:
    """`Figures` of one corpus file (module doc). A hatch point is far when the nearest
    pixel the browser inks (coverage above 1 %: a sliver's tip is inked faintly) is more
    than `far_px` away (the tolerance is 0.04 px; the rest is the pixel grid)."""
    from scipy.ndimage import distance_transform_edt

    cov = render(driver, path.read_text())
    browser = float(cov.sum()) * MM_PER_PX ** 2
    d = hatched(path)
    assert d.fill is not None
    mine = d.fill.hatch_mm * SPACING
    dist = distance_transform_edt(cov <= 0.01)
    pts = hatch_points(d)
    ij = np.clip(np.rint(pts[:, ::-1] - 0.5).astype(int), 0, SIZE_PX - 1)
    far = dist[ij[:, 0], ij[:, 1]]
    return Figures(path.stem, browser, mine, int((far > far_px).sum()),
                   float(far.max(initial=0.0)))


def scan_area(path: Path, cell_mm: float = 0.1) -> tuple[float, float]:
    """(mm² the `--fill scan` grid burns, mm² of the painted region) of a corpus file in its
    own frame: the painted region (`raster.fill.painted_region`, white erasing) on a scan
    grid of `cell_mm` cells, each lit when its centre is inside (what `burn_grid` burns)."""
    from fivebar_host.raster.fill import fill_grid, painted_region

    region = painted_region(read_svg(path), TOL)
    grid = fill_grid(region, cell_mm, cell_mm, 0.0, 255)
    return float((grid.powers > 0).sum()) * cell_mm * cell_mm, float(region.area)

