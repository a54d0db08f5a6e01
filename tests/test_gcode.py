"""G-code reader: lines, I/J and R arcs, units, distance modes, G92, laser on/off strokes,
comments and line numbers; every unsupported word is an error naming its line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.errors import InputError
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.geometry import ARC, LINE, Drawing, flatten


def g(text: str, strict: bool = False) -> Drawing:
    return read_gcode(text.encode(), file="t.gcode", strict=strict)


def polylines(d: Drawing, tol: float = 1e-3) -> list[np.ndarray]:
    p = flatten(d, tol)
    return [p.points[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]


def test_lines_without_laser_words_draw_every_g1() -> None:
    d = g("G21 G90\nG0 X1 Y1\nG1 X11 Y1 F600\nG1 Y11\nG0 X20\nG1 X30\n")
    a, b = polylines(d)
    assert np.allclose(a, [[1, 1], [11, 1], [11, 11]])
    assert np.allclose(b, [[20, 11], [30, 11]])
    assert d.stroke_feed_mm_s[0] == pytest.approx(10.0)  # F600 mm/min
    assert d.sources[0].line == 3 and d.line.tolist() == [3, 4, 6]


def test_laser_on_off_decides_what_draws() -> None:
    d = g("M5\nG1 X10 Y0\nM3 S500\nG1 X10 Y10\nG1 X0 Y10 S1000\nM5\nG1 X0 Y0\n"
          "M4 S0\nG1 X5\n")
    a, b = polylines(d)
    assert np.allclose(a, [[10, 0], [10, 10]])
    assert np.allclose(b, [[10, 10], [0, 10]])  # a power change starts a new stroke
    assert d.stroke_power.tolist() == [0.5, 1.0]  # fractions of the file's largest S
    assert any("laser power as a fraction of the file's largest S, S1000" in w
               for w in d.warnings)  # and the job says which S is full power


@pytest.mark.parametrize(("code", "sign"), [("G2", -1.0), ("G3", 1.0)])
def test_ij_arcs_exact(code: str, sign: float) -> None:
    d = g(f"G0 X10 Y0\n{code} X0 Y10 I-10 J0\n")
    (pts,) = polylines(d)
    assert np.allclose(np.hypot(*pts.T), 10.0, atol=1e-12)
    assert d.kind.tolist() == [ARC]
    swept = d.params[0, 7]
    # G3 (counter-clockwise) takes the quarter turn, G2 the three-quarter turn.
    assert swept == pytest.approx(sign * (math.pi / 2 if sign > 0 else 3 * math.pi / 2))
    assert np.allclose(pts[-1], [0, 10], atol=1e-12)


def test_full_circle_and_absolute_centre() -> None:
    d = g("G0 X5 Y0\nG2 X5 Y0 I-5 J0\n")
    assert d.params[0, 7] == pytest.approx(-2 * math.pi)
    d2 = g("G90.1\nG0 X5 Y0\nG3 X0 Y5 I0 J0\n")
    (pts,) = polylines(d2)
    assert np.allclose(np.hypot(*pts.T), 5.0)


@pytest.mark.parametrize(("r", "code", "centre"), [
    (5, "G3", (0, 0)),   # short ccw arc from (5,0) to (0,5): centre left of the chord
    (5, "G2", (5, 5)),   # short cw arc: centre to the right
    (-5, "G3", (5, 5)),  # negative R: the long way round
])
def test_r_arcs(r: float, code: str, centre: tuple[float, float]) -> None:
    d = g(f"G0 X5 Y0\n{code} X0 Y5 R{r}\n")
    assert np.allclose(d.params[0, 0:2], centre, atol=1e-12)
    (pts,) = polylines(d)
    assert np.allclose(np.hypot(pts[:, 0] - centre[0], pts[:, 1] - centre[1]), 5.0)
    long_way = abs(d.params[0, 7]) > math.pi
    assert long_way == (r < 0)


def test_inches_relative_and_g92() -> None:
    d = g("G20 G91\nG1 X1 Y0\nG1 Y1\nG21 G90\nG92 X0 Y0\nG1 X10\n", strict=True)
    (pts,) = polylines(d)
    assert np.allclose(pts, [[0, 0], [25.4, 0], [25.4, 25.4], [35.4, 25.4]])


def test_comments_line_numbers_checksums() -> None:
    d = g("%\n(header) ; more\nN10 G1 X1 (move) Y2 *57\nN20 G1 X2 ; go\n")
    (pts,) = polylines(d)
    assert np.allclose(pts, [[0, 0], [1, 2], [2, 2]])


@pytest.mark.parametrize(("text", "line", "what"), [
    ("G1 X1\nG1 Z-1\n", 2, "unsupported axis word Z-1"),
    ("G1 X1\nG28\n", 2, "unsupported G-code word G28"),
    ("G1 X1\nG4 P1 G28\n", 2, "unsupported G-code word G28"),
    ("M6 T1\n", 1, "unsupported M-code word M6"),
    ("G1 X1 Q5\n", 1, "unsupported word Q5"),
    ("G1 X1\nG1 X$\n", 2, "cannot read"),
    ("G18\n", 1, "unsupported G-code word G18"),
    ("G0 X10 Y0\nG2 X0 Y10 I-9 J0\n", 2, "off the circle"),
    ("G0 X10\nG2 X0 Y0 R2\n", 2, "smaller than half the chord"),
    ("G1 X1 (unclosed\n", 1, "unbalanced"),
    ("G1 X" + "9" * 400 + "\n", 1, r"X99999999999…999999 \(401 characters\): not a finite"),
    ("G1 X5000000000\n", 1, "larger than"),
    ("G1 X5e9\n", 1, "cannot read 'X5e9': a G-code number"),  # no exponents in G-code
])
def test_errors_name_the_line(text: str, line: int, what: str) -> None:
    """--strict: the reader's older reading, every word outside the honoured ones refused."""
    with pytest.raises(InputError, match=rf"t\.gcode:{line}: .*{what}"):
        g(text, strict=True)


def test_nothing_to_cut_and_unreadable(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no cutting moves"):
        g("M3 S0\nG1 X10\nM5\nG0 X0\n")
    with pytest.raises(InputError, match="cannot read file"):
        read_gcode(tmp_path / "none.gcode")
    bad = tmp_path / "bin.gcode"
    bad.write_bytes(b"\xff\xfe\x00G1")
    with pytest.raises(InputError, match="not a text file"):
        read_gcode(bad)


def test_program_end_stops_reading() -> None:
    d = g("G1 X1\nM2\nG1 X99 Z4\n")
    assert d.kind.tolist() == [LINE]
