"""G-code Z words (issues 17, 21): pen up/down by the profile's threshold on a pen machine;
on a laser machine ignored with one warning, refused when they change Z during a cut."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_job, gcode_tool, read_drawing
from fivebar_host.config import load_profile
from fivebar_host.errors import InputError
from fivebar_host.server.jobs import read_upload
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import Drawing, flatten

CONFIGS = Path(__file__).resolve().parent.parent / "configs"

# vpype-gcode / gcodetools style: Z lifts and drops the pen, no M3 at all. Two strokes (an L
# and a line) drawn; the pen-up G1 X.. between them and the G0 moves are travel.
VPYPE = """G21
G90
G0 Z5
G0 X5 Y95
G1 Z0 F300
G1 X35 Y95 F1800
G1 X35 Y125
G0 Z5
G1 X5 Y125
G1 Z0
G1 X5 Y110
G0 Z5
G0 X0 Y0
M2
"""


def g(text: str, tool: str | None, z: float = 0.0) -> Drawing:
    return read_gcode(text.encode(), file="z.gcode", tool=tool, z_threshold_mm=z)


def polylines(d: Drawing) -> list[np.ndarray]:
    p = flatten(d, 1e-3)
    return [p.points[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]


def test_pen_file_draws_exactly_the_strokes_with_z_down() -> None:
    a, b = polylines(g(VPYPE, "pen"))
    assert np.allclose(a, [[5, 95], [35, 95], [35, 125]])
    assert np.allclose(b, [[5, 125], [5, 110]])  # the pen-up G1 to (5, 125) is not drawn


def test_z_on_the_move_line_changes_the_pen_at_its_start() -> None:
    d = g("G0 X0 Y0\nG1 X10 Z0 F600\nG1 X20 Z5\nG1 X30 Z-1\n", "pen")
    a, b = polylines(d)
    assert np.allclose(a, [[0, 0], [10, 0]])
    assert np.allclose(b, [[20, 0], [30, 0]])
    assert d.line.tolist() == [2, 4]


def test_pen_lift_and_drop_in_place_splits_the_stroke_and_inches_scale_z() -> None:
    d = g("G20\nG1 X1 Z0 F10\nG0 Z0.2\nG1 Z-0.01\nG1 X2\n", "pen", z=1.0)
    assert d.stroke.tolist() == [0, 1]  # 0.2 in = 5.08 mm > 1 mm: up; then down again


@pytest.mark.parametrize(("threshold", "drawn"), [(1.0, [[0, 0], [10, 0], [20, 0], [30, 0]]),
                                                (0.0, [[10, 0], [20, 0]])])
def test_the_profile_threshold_decides(threshold: float, drawn: list[list[float]]) -> None:
    # Z0.5 is down under a 1.0 mm threshold (every G1 draws), up under 0.0 (only after Z0).
    text = "G0 X0 Y0\nG1 Z0.5 F600\nG1 X10\nG0 Z0\nG1 X20\nG0 Z0.5\nG1 X30\n"
    (only,) = polylines(g(text, "pen", threshold))
    assert np.allclose(only, drawn)


def test_pen_z_combines_with_m3_m5() -> None:
    # gcodetools: an M3 header without S, then Z moves; M5 stops drawing even with Z down.
    d = g("M3\nG0 X0 Y0 Z5\nG1 Z0 F600\nG1 X10\nM5\nG1 X20\nM3\nG1 X30\nG0 Z5\nG1 X40\n",
          "pen")
    a, b = polylines(d)
    assert np.allclose(a, [[0, 0], [10, 0]])
    assert np.allclose(b, [[20, 0], [30, 0]])


def test_laser_z_change_during_a_cut_is_refused_with_its_line() -> None:
    text = "G0 X0 Y0 Z0\nM3 S500\nG1 X10 F600\nG1 X20 Z-1\n"
    with pytest.raises(InputError, match=r"z\.gcode:4: Z-1 changes Z during a cut.*laser "
                                         r"cannot follow Z"):
        g(text, "laser")
    with pytest.raises(InputError, match=r"z\.gcode:4:"):
        g("G0 X0 Y0 Z0\nM3 S500\nG1 X10 F600\nG1 Z2\n", "laser")


def test_laser_z_that_changes_nothing_is_ignored_with_one_warning() -> None:
    text = ("G0 X0 Y0 Z3\nM3 S500\nG1 X10 Z3 F600\nM5\nG0 Z8\nG0 X20 Z3\nM3\nG1 X30 Z3\n"
            "G1 Z3\n")
    d = g(text, "laser")
    a, b = polylines(d)
    assert np.allclose(a, [[0, 0], [10, 0]])
    assert np.allclose(b, [[20, 0], [30, 0]])
    z = [w for w in d.warnings if "largest S" not in w]  # and the note on the power's scale
    assert len(z) == 1 and "z.gcode:1: Z words ignored" in z[0]


def test_without_a_tool_z_is_refused_and_other_z_errors() -> None:
    with pytest.raises(InputError, match=r"z\.gcode:1: unsupported axis word Z5"):
        g("G0 Z5\n", None)
    for text, what in (("Z5\n", "Z before any G0"), ("G1 X0\nG4 P1 Z1\n", "G4 and a Z move")):
        with pytest.raises(InputError, match=what):
            g(text, "pen")
    with pytest.raises(InputError, match="G92 with"):  # --strict: G92 Z refused, as before
        read_gcode(b"G0 X0\nG92 X0 Z1\n", file="z.gcode", tool="pen", strict=True)


def test_g92_z_sets_the_pen_threshold_in_work_coordinates() -> None:
    # the pen is down at Z <= 0 as written: G92 Z0 at a machine Z of 5 makes Z0 mean 5
    d = g("G0 Z5\nG92 Z0\nG0 X1 Y1\nG1 Z0\nG1 X9 Y1\nG1 Z2\nG1 X9 Y9\n", "pen")
    assert d.kind.shape[0] == 1 and d.params[0, :4].tolist() == [1, 1, 9, 1]


def test_compile_and_daemon_pass_the_profile(tmp_path: Path) -> None:
    pen = load_profile(CONFIGS / "pen-servo.toml")
    laser = load_profile()
    assert gcode_tool(pen)["tool"] == "pen" and gcode_tool(laser)["tool"] == "laser"
    f = tmp_path / "pen.gcode"
    f.write_text(VPYPE)
    assert len(set(read_drawing(f, profile=pen).stroke.tolist())) == 2
    job = compile_job(f, pen, CompileOptions())
    assert len(job.path_modes) == 2
    assert len(set(read_upload(VPYPE.encode(), "pen.gcode", (), pen).stroke.tolist())) == 2
    cut = "G0 X5 Y95 Z0\nM3 S500\nG1 X35 F600\nG1 Y125 Z-2\n"
    with pytest.raises(InputError, match=r"up\.nc:4:"):
        read_upload(cut.encode(), "up.nc", (), laser)
