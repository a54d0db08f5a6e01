"""SVG `<image>` placement against the browser: each SVG below (the test pattern of
`svgimage_support` placed by x/y/width/height, every kind of preserveAspectRatio, a missing
size, transforms with rotation and skew, a nested viewBox, a clip path) is rendered by
headless Chromium and turned into a scan grid by `raster.svgimage`; every lit cell lies
within one CSS pixel of the browser's dark pixels (darkness > 0.5) and every dark pixel
within one of a lit cell.  The page renders images `image-rendering: pixelated` (nearest
neighbour, as the burn samples them): a browser's smoothing of a 10× enlarged pattern
rounds its corners by up to half a source pixel, which is interpolation, not placement.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from svgimage_support import PAGE, data_uri, lit_mask, near, pattern, svg
from web_support import browser_missing, chromium

pytestmark = pytest.mark.skipif(browser_missing() is not None,
                                reason=browser_missing() or "")

URI = data_uri(pattern())
CASES = {
    "plain": f'<image href="{URI}" x="20" y="10" width="160" height="120"/>',
    "meet-default": f'<image href="{URI}" x="10" y="10" width="200" height="90"/>',
    "xMinYMax-meet": f'<image href="{URI}" x="10" y="10" width="120" height="160" '
                     'preserveAspectRatio="xMinYMax meet"/>',
    "xMaxYMin-slice": f'<image href="{URI}" x="30" y="20" width="90" height="140" '
                      'preserveAspectRatio="xMaxYMin slice"/>',
    "xMidYMid-slice": f'<image href="{URI}" x="30" y="20" width="180" height="60" '
                      'preserveAspectRatio="xMidYMid slice"/>',
    "none": f'<image href="{URI}" x="10" y="30" width="220" height="70" '
            'preserveAspectRatio="none"/>',
    "intrinsic": f'<image xlink:href="{URI}" x="40" y="50"/>',
    "width-only": f'<image href="{URI}" x="5" y="5" width="96"/>',
    "rotate-slice": f'<g transform="translate(120 90) rotate(30)"><image href="{URI}" '
                    'x="-70" y="-50" width="140" height="70" '
                    'preserveAspectRatio="xMinYMid slice"/></g>',
    "skew-flip": f'<g transform="translate(200 20) scale(-1 1) skewX(15)"><image '
                 f'href="{URI}" width="150" height="120"/></g>',
    "two-images": f'<image href="{URI}" x="0" y="0" width="120" height="90"/>'
                  f'<image href="{URI}" x="100" y="70" width="120" height="90" '
                  'transform="rotate(-10 160 115)"/>',
    "clip-path": '<defs><clipPath id="c"><circle cx="120" cy="90" r="60"/></clipPath></defs>'
                 f'<g clip-path="url(#c)"><image href="{URI}" x="20" y="10" width="200" '
                 'height="150"/></g>',
}
VIEWS = {"nested-viewbox": (f'<image href="{URI}" x="10" y="5" width="80" height="60"/>',
                            "0 0 120 90")}


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with chromium(tmp_path_factory.mktemp("chromium-svgimage")) as driver:
        yield driver


def rendered(driver: Any, text: str) -> np.ndarray:
    """The browser's dark pixels (darkness > 0.5) of an SVG page, rows top down."""
    from PIL import Image

    page = ("<html><head><style>image { image-rendering: pixelated }</style></head>"
            "<body style='margin:0;background:white'>" + text + "</body></html>")
    driver.get("data:text/html;charset=utf-8," + page.replace("#", "%23"))
    elem = driver.find_element("css selector", "svg")
    img = Image.open(io.BytesIO(elem.screenshot_as_png)).convert("L")
    assert img.size == PAGE, img.size
    out: np.ndarray = np.asarray(img, dtype=np.float64) < 127.5
    return out


@pytest.mark.parametrize("name", [*CASES, *VIEWS])
def test_lit_cells_are_the_browsers_dark_pixels(name: str, browser: Any) -> None:
    text = svg(CASES[name]) if name in CASES else svg(VIEWS[name][0], VIEWS[name][1])
    dark = rendered(browser, text)
    lit = lit_mask(text)
    print(f"{name}: browser {int(dark.sum())} dark px, grid {int(lit.sum())} lit px, "
          f"{near(lit, dark)} lit off the ink, {near(dark, lit)} ink off the lit cells")
    assert dark.sum() > 40
    assert near(lit, dark) == 0
    assert near(dark, lit) == 0
