"""Real G-code files from public repositories of real tools (tests/gcode_corpus/SOURCES.md):
each is drawn or refused with the right reason; a drawn file's geometry is within 0.1 % in
length and 0.001 % of its extent in bounding box of an independent interpreter
(`gcode_reference`); nothing is refused for a word that cannot change the path.

`python -m pytest tests/test_gcode_corpus.py -s` prints the table of figures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from gcode_reference import box, length, reference

from fivebar_host.errors import InputError
from fivebar_host.toolpath.extent import bbox
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import ARC, LINE, Drawing

CORPUS = Path(__file__).resolve().parent / "gcode_corpus"
#: file → None (drawn with a pen profile) or the refusal's reason (a part of the message).
OUTCOME: dict[str, str | None] = {
    "cncjs-arc-ijk.gcode": None,
    "cncjs-arc-xz-plane.gcode": ":3: K-20.0: K is the Z offset of an arc in the XZ or YZ",
    "cncjs-circle-inch.gcode": None,
    "cncjs-full-circle-without-xyz.gcode": ":11: arc without I/J or R",
    "cncjs-g2-arc.gcode": None,
    "cncjs-helical-thread-milling.gcode": ":5: G42: cutter radius compensation",
    "cncjs-shapeoko-calibration.gcode": ":624: arc end is 1.414 mm off the circle",
    "escriba-example1.gcode": None,
    "escriba-example6.gcode": None,
    "escriba-example11.gcode": None,
    "escriba-example12.gcode": None,
    "escriba-pants-cut.gcode": None,
    "jscut-jsdc.gcode": None,
    "jscut-jsdc-laser.gcode": None,
    "jscut-tball.gcode": None,
    "jscut-tball-engrave-laser.gcode": "no cutting moves to draw",  # M3 S0 only: no power
    "lasertools-bounding-box.gcode": None,
    "lasertools-crosshair.gcode": None,
    "lasertools-tsq-lc.gcode": None,
    "mrbeam-heart.gco": None,
    "mrbeam-line.gco": None,
    "pcb2gcode-drill.ngc": ":24: G81: a canned cycle",
    "pcb2gcode-front.ngc": None,
    "pcb2gcode-outline.ngc": None,
    "pcb2gcode-silkscreen-back.ngc": None,
}


def drawn_length(d: Drawing) -> float:
    """The drawing's length, exact: lines, and arcs as r·|sweep| (circles in G-code)."""
    p = d.params
    line = d.kind == LINE
    arc = d.kind == ARC
    total = float(np.hypot(p[line, 2] - p[line, 0], p[line, 3] - p[line, 1]).sum())
    r = np.linalg.svd(p[arc, 2:6].reshape(-1, 2, 2), compute_uv=False)[:, 0]
    return total + float((r * np.abs(p[arc, 7])).sum())


def test_the_corpus_is_what_the_sources_say() -> None:
    files = sorted(f.name for f in CORPUS.iterdir() if f.name != "SOURCES.md")
    assert files == sorted(OUTCOME)
    assert len(files) >= 20
    sources = (CORPUS / "SOURCES.md").read_text()
    assert all(f in sources for f in files)


@pytest.mark.parametrize("name", sorted(OUTCOME))
def test_drawn_or_refused_for_the_right_reason(name: str) -> None:
    f = CORPUS / name
    why = OUTCOME[name]
    if why is not None:
        with pytest.raises(InputError) as e:
            read_gcode(f, tool="pen")
        assert why in str(e.value), str(e.value)
        print(f"{name:40s} refused: {str(e.value).split(name, 1)[1][:90]}")
        return
    d = read_gcode(f, tool="pen")
    ref = reference(f)
    mine, theirs = drawn_length(d), length(ref)
    b, rb = np.array(bbox(d)), np.array(box(ref))
    extent = math.hypot(rb[2] - rb[0], rb[3] - rb[1])
    dl = abs(mine - theirs) / theirs
    db = float(np.abs(b - rb).max()) / extent
    print(f"{name:40s} drawn: length {mine:10.3f} mm ({dl:.1e}), box off {db:.1e} of "
          f"{extent:.1f} mm, stops {len({s.layer for s in d.sources if s.layer})}")
    assert dl <= 1e-3
    assert db <= 1e-5


def test_strict_refuses_what_the_policy_skips() -> None:
    """--strict keeps the older reading: the files drawn only thanks to the word classes."""
    for name in ("escriba-example1.gcode", "mrbeam-line.gco", "pcb2gcode-outline.ngc"):
        with pytest.raises(InputError, match=r"unsupported|cannot read"):
            read_gcode(CORPUS / name, tool="pen", strict=True)
