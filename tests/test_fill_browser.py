"""Fill rules against the browser: every file of tests/svg_fills/ (even-odd and nonzero
stars, nested holes, concentric arcs, self-intersections, slivers, compound arc paths,
`<use>` with transforms, CSS, `<polygon>`, clip paths and masks) is rendered by headless
Chromium and hatched by fivebar; the area the hatch covers (length × spacing) agrees with
the browser's inked area within 1 %, and no hatch line leaves the browser's ink
(`benchmarks/fillcorpus.py`; `python benchmarks/fill.py --corpus` prints the figures).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from web_support import browser_missing, chromium

from benchmarks.fillcorpus import CORPUS, measure

FILES = sorted(CORPUS.glob("*.svg"))

pytestmark = pytest.mark.skipif(browser_missing() is not None,
                                reason=browser_missing() or "")


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    with chromium(tmp_path_factory.mktemp("chromium-fill")) as driver:
        yield driver


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_hatched_area_matches_the_browser(path: Path, browser: Any) -> None:
    f = measure(browser, path)
    print(f"{f.name}: browser {f.browser_mm2:.1f} mm², hatch {f.hatch_mm2:.1f} mm² "
          f"({100 * f.error:+.3f} %), {f.far_points} points off the ink (worst "
          f"{f.worst_px:.2f} px)")
    assert abs(f.error) < 0.01
    assert f.far_points == 0
