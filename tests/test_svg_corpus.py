"""The SVG corpus (tests/svg_corpus/): small files written by SVG rule, each carrying its
expected pen runs in its `<desc>` ("expect: {...}", page coordinates, worked out by hand from
the specification); every file must read to exactly those runs (and warn where said)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.toolpath.geometry import flatten
from fivebar_host.toolpath.svg import read_svg

CORPUS = Path(__file__).parent / "svg_corpus"
FILES = sorted(CORPUS.glob("*.svg"))


def expectation(path: Path) -> dict[str, object]:
    m = re.search(r"expect: (\{.*?\})</desc>", path.read_text(), re.S)
    assert m, f"{path.name} has no expectation"
    return dict(json.loads(m.group(1)))


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_corpus_file_reads_to_its_expected_runs(path: Path) -> None:
    want = expectation(path)
    d = read_svg(path)
    p = flatten(d, 1e-4)
    pts = d.to_file_frame(p.points)
    runs = [pts[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]
    expected = [np.array(r, dtype=float) for r in want["runs"]]  # type: ignore[attr-defined]
    assert len(runs) == len(expected)
    atol = float(want.get("atol", 1e-6))  # type: ignore[arg-type]
    for got, exp in zip(runs, expected, strict=True):
        # the run's vertices at the expected corners (curves: their flattened points)
        assert got.shape == exp.shape and np.allclose(got, exp, atol=atol), (got, exp)
    if "warning" in want:
        assert any(str(want["warning"]) in w for w in d.warnings), d.warnings
