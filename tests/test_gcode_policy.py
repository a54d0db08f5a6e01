"""The G-code reader's word classes (docs/gcode.md): skipped words told in one note naming
their lines, M0/M1 and T/M6 as pen-change stops, G28 home, M300 servo pens, refusals that
name the line and the word; UTF-16 and BOM files; exact bounding boxes of arcs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.compile.job import compile_job
from fivebar_host.compile.model import CompileOptions
from fivebar_host.config import load_profile
from fivebar_host.errors import InputError
from fivebar_host.toolpath.extent import bbox
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import ARC, Drawing, flatten

SQUARE = "G1 X10 Y0 F600\nG1 X10 Y10\nG1 X0 Y10\n"


def g(text: str, tool: str | None = "pen", strict: bool = False) -> Drawing:
    return read_gcode(text.encode(), file="t.nc", tool=tool, strict=strict)


def test_words_that_cannot_change_the_path_are_skipped_in_one_note() -> None:
    text = ("$I\n$G\n?\nM8\nG64 P0.01\nM100 P100\nM2000\nM888 P0\nM17\nG0 X0 Y0\n"
            "M117 Hello, world 3.5 X\n" + SQUARE + "M9\nG28\n")
    d = g(text)
    assert d.kind.shape[0] == 3
    (note,) = [w for w in d.warnings if "skipped" in w]
    for part in ("GRBL queries and settings $I $G ? (lines 1–3)", "M8 (line 4)",
                 "G64 (line 5)", "Mr Beam air compressor M100 (line 6)",
                 "DexArm straight-line mode M2000 (line 7)", "M888 (line 8)",
                 "messages M117 (line 11)", "coolant off M9 (line 15)", "G28 (line 16)"):
        assert part in note, (part, note)
    with pytest.raises(InputError, match=r"t\.nc:1: cannot read '\$I'"):
        g(text, strict=True)


def test_owned_values_do_not_leak_into_the_drawing() -> None:
    # M106's S is a fan speed, M888's P a tool head: neither is laser power nor a dwell
    d = g("M3 S100\nM106 S255\nM888 P1\nG1 X10 F600\n", tool="laser")
    assert d.stroke_power.tolist() == [1.0] and not d.dwells


@pytest.mark.parametrize(("text", "line", "what"), [
    ("G41 D1\nG1 X1\n", 1, "G41: cutter radius compensation"),
    ("G0 X1\nG81 R1 Z-1 X2 Y2\n", 2, "G81: a canned cycle"),
    ("G18\nG2 X10 Y0 I5 J0\n", 2, "G2 arc in the G18 plane"),
    ("G21\nG1 X1 F100\nG20\nG1 X2\n", 3, "G20 after the first move changes the units"),
    ("$J=G91 X10 F100\n", 1, "GRBL jog"),
    ("G1 X1 E0.5 F100\n", 1, "unsupported axis word E0.5"),
    ("G55\nG1 X1\n", 1, "G55: another work coordinate system"),
    ("M280 P0 S90\n", 1, "M280: a Marlin servo"),
    ("G1 X1 H2\n", 1, "unsupported word H2"),  # H without G43 owning it
    ("M123\n", 1, "unsupported M-code word M123"),
    ("G1 X1e308\n", 1, "cannot read 'X1e308'"),
    ("G1 X1.2.3\n", 1, "cannot read 'X1.2.3'"),
    ("G1 X1" + "0" * 60 + "e5\n", 1, r"cannot read 'X10000000000…0000e5 \(64 characters\)'"),
])
def test_path_changing_words_are_refused_naming_line_and_word(text: str, line: int,
                                                               what: str) -> None:
    with pytest.raises(InputError, match=rf"t\.nc:{line}: .*{what}"):
        g(text)


def test_m0_and_tool_changes_become_pen_change_stops() -> None:
    d = g("G0 X0 Y0\nG1 X5 F600\nM0\nG1 X5 Y5\nT2\nM6\nM0\nG1 X0 Y5\nM0\n")
    layers = [d.sources[int(s)].layer for s in d.stroke_source.tolist()]
    assert layers == [None, "!M0 (line 3): program pause",
                      "!T2 M6 (line 6): tool change; M0 (line 7): program pause"]
    (note,) = [w for w in d.warnings if "skipped" in w]
    assert "tool select (the change is at M6) T2 (line 5)" in note
    assert "a stop after the last cut (nothing left to stop before): M0 (line 9)" in note


def test_stops_reach_the_job_as_pen_changes(tmp_path: Path) -> None:
    f = tmp_path / "stops.nc"
    f.write_text("G0 X5 Y100\nG1 X30 Y100 F600\nM0\nG1 X30 Y120\nT1 M6\nG1 X5 Y120\n")
    job = compile_job(f, load_profile(), CompileOptions())
    assert [p.describe() for p in job.pauses] == [
        "layer 2/3 '!M0 (line 3): program pause'", "layer 3/3 '!T1 M6 (line 5): tool change'"]
    assert not compile_job(f, load_profile(), CompileOptions(no_pause=True)).pauses


def test_g28_travels_home_with_the_pen_up() -> None:
    d = g("G0 X1 Y1 Z1\nG1 Z-1 F100\nG1 X9 Y1\nG28\nG1 X9 Y9\nG1 Z-1\nG1 X1 Y9\n")
    # after G28 the pen is up (the travel from home to X9 Y9 draws nothing) until Z goes down
    assert d.params[:, :4].tolist() == [[1, 1, 9, 1], [9, 9, 1, 9]]


UNICORN = """(Scribbled version of x.svg @ 3500.00)
( unicorn.py --pen-up-angle=50 --pen-down-angle=30 --start-delay=150 )
G21 (metric ftw)
G90 (absolute mode)
G92 X0 Y0 Z0 (zero all axes)
G92 Z0.00 F150.00 (go to printing level)
M300 S30 (pen down)
G4 P150 (wait 150ms)
M300 S50 (pen up)
G4 P150 (wait 150ms)
M18 (disengage drives)
M01 (Was registration test successful?)
M17 (engage drives if YES, and continue)
G1 X10 Y0 F3500.00
M300 S30.00 (pen down)
G4 P150 (wait 150ms)
G1 X10 Y10 F3500.00
G1 X0 Y10 F3500.00
M300 S50.00 (pen up)
G4 P150 (wait 150ms)
M300 S255 (turn off servo)
G1 X0 Y0 F3500.00
G1 Z0.00 F150.00 (go up to finished level)
G1 X0.00 Y0.00 F3500.00 (go home)
M300 S300 (beep) P200
M18 (drives off)
"""


def test_makerbot_unicorn_servo_pen() -> None:
    d = g(UNICORN)
    assert d.kind.shape[0] == 2
    assert d.params[:, :4].tolist() == [[10, 0, 10, 10], [10, 10, 0, 10]]
    assert d.sources[0].layer == "!M01 (line 12): optional program pause"
    assert all(dw.seconds == pytest.approx(0.15) for dw in d.dwells)  # P in ms (RepRap)
    (note,) = [w for w in d.warnings if "skipped" in w]
    assert "Z words (the pen follows M300)" in note and "beep M300" in note
    with pytest.raises(InputError, match=r"t\.nc:5:.*(unsupported|G92)"):
        g(UNICORN, strict=True)
    with pytest.raises(InputError, match=r"t\.nc:2: M300 S40: the servo pen's values"):
        g("(unicorn.py --pen-up-angle=50 --pen-down-angle=30)\nM300 S40\n")


@pytest.mark.parametrize("codec", ["utf-8-sig", "utf-16", "utf-16-le", "utf-16-be"])
def test_utf16_and_bom_files_are_read(codec: str) -> None:
    text = "(é: a comment)\nG21\n" + SQUARE
    d = read_gcode(text.encode(codec), file="t.nc")
    assert d.kind.shape[0] == 3


def test_a_nearly_straight_arc_has_an_exact_box() -> None:
    # gcodetools writes radii up to 35.7 m for nearly straight pieces
    r = 35_700.0
    half = math.asin(20.0 / r)
    d = g(f"G0 X-20 Y0\nG2 X20 Y0 R{r}\n")
    assert d.kind.tolist() == [ARC]
    x0, y0, x1, y1 = bbox(d)
    sag = r * (1 - math.cos(half))
    assert (x0, x1) == pytest.approx((-20.0, 20.0), abs=1e-9)
    assert (y0, y1) == pytest.approx((0.0, sag), abs=1e-9)


def test_bbox_matches_dense_sampling_of_random_curves() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        kind = int(rng.integers(1, 3))
        if kind == ARC:
            p = np.array([[*rng.normal(size=2) * 10, *(rng.normal(size=4) * 20),
                           rng.uniform(-9, 9), rng.uniform(-7, 7)]])
        else:
            p = rng.normal(size=(1, 8)) * 20
        one = np.zeros(1, np.int64)
        d = Drawing("x", np.array([kind], np.int8), p, one, one, one, np.ones(1), np.ones(1),
                    [])
        pts = flatten(d, 1e-7).points
        ref = [pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()]
        assert np.allclose(bbox(d), ref, atol=1e-6)
