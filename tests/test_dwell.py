"""G-code dwells (`G4 P<seconds>`): read, placed, planned after a stop, encoded as `G1 P…`
without motion, and run by the mock device as a block of zero steps for exactly that long."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fivebar_host import protocol, wire
from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, compile_job, encode_lines, planner
from fivebar_host.compile.dwell import dwell_pieces
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.run.moves import build_program
from fivebar_host.toolpath.gcode import read_gcode

#: Two laser strokes with a dwell between them (laser on: a dot at the first stroke's end),
#: then a cool-down dwell with the laser off at the end of the second.
TWO_STROKES = """G21 G90
G0 X0 Y100
M3 S1000
G1 X10 Y100 F600
G4 P0.5
G1 X10 Y110
M5
G0 X20 Y100
M3 S500
G1 X30 Y100
M5
G4 P0.25
"""


@pytest.fixture(autouse=True)
def _clean_machines(clean_mock: None) -> None:
    """Every test here starts and ends with no named mock machine left over."""


@pytest.fixture
def dwell_file(tmp_path: Path) -> Path:
    p = tmp_path / "dwell.gcode"
    p.write_text(TWO_STROKES)
    return p


def test_reader_places_dwells_with_the_tool_state() -> None:
    d = read_gcode(TWO_STROKES.encode())
    assert d.n_strokes == 3  # the dwell ends the first stroke: X10 Y100 → Y110 is a new one
    first, last = d.dwells
    assert (first.stroke, first.after, first.seconds, first.tool_on, first.line) == (
        0, True, 0.5, True, 5)
    assert first.power == pytest.approx(1.0)  # S1000 of the file's largest S1000
    assert (last.stroke, last.after, last.tool_on, last.power) == (2, True, False, 0.0)


def test_reader_dwell_before_a_stroke_and_m4_and_pen_files() -> None:
    pierce = read_gcode(b"G0 X5 Y100\nM3 S400\nG1\nG4 P0.2\nG1 X9 Y100 S800\n")
    (d,) = pierce.dwells
    assert (d.stroke, d.after, d.tool_on) == (0, False, True)
    assert d.power == pytest.approx(0.5)  # S400 of the file's largest S800
    m4 = read_gcode(b"M4 S400\nG1 X5 Y100\nG4 P0.2\n")
    assert not m4.dwells[0].tool_on  # GRBL's dynamic power: zero at rest
    pen = read_gcode(b"G1 X5 Y100\nG4 P1.5\nG0 X9\nG4 P1\nG1 X12\n")
    assert [(x.stroke, x.after, x.tool_on, x.seconds) for x in pen.dwells] == [
        (0, True, True, 1.5), (1, False, False, 1.0)]  # pen up, at the next stroke's start
    away = read_gcode(b"G1 X5 Y100\nG0 X9\nG4 P1\nG0 X20\nG1 X25\n")
    assert [(x.stroke, x.after, x.tool_on) for x in away.dwells] == [(0, True, False)]


@pytest.mark.parametrize(("text", "line", "what"), [
    ("G1 X1\nG4\n", 2, "G4 needs P"),
    ("G1 X1\nG4 S2\n", 2, "G4 needs P"),  # Marlin's seconds word: S is the power here
    ("G1 X1 P2\n", 1, "P word without G4"),
    ("G1 X1\nG4 P-1\n", 2, "must not be negative"),
    ("G1 X1\nG4 X2 P1\n", 2, "G4 and a move"),
    ("M3 S100\nG1 X1\nG0 X5\nG1\nG4 P1\nG0 X9\nG1 X10\n", 5, "where no cut starts or ends"),
])
def test_reader_refuses_bad_dwells(text: str, line: int, what: str) -> None:
    from fivebar_host.errors import InputError
    with pytest.raises(InputError) as ei:
        read_gcode(text.encode(), "f.gcode")
    assert what in str(ei.value) and f"f.gcode:{line}" in str(ei.value)


def test_dwell_pieces_stay_within_the_protocol() -> None:
    assert dwell_pieces(0.5) == [500_000]
    assert dwell_pieces(1e-6) == [protocol.P_MIN_US]
    long = dwell_pieces(250.0)
    assert sum(long) == 250_000_000 and max(long) <= protocol.P_MAX_US and len(long) == 3


def test_compiled_dwell_is_a_stop_then_a_segment_without_motion(dwell_file: Path) -> None:
    prof = load_profile()
    job = compile_job(dwell_file, prof, CompileOptions())
    k = np.flatnonzero(job.is_dwell)
    assert k.size == 2
    assert np.array_equal(job.steps[k], job.steps[k + 1])  # no motion
    assert job.duration_us[k].tolist() == [500_000, 250_000]
    assert job.power[k].tolist() == [prof.laser.power, 0]
    assert not job.draw[k].any() and job.dwell_time_s == pytest.approx(0.75)
    assert job.total_time_s >= 0.75 + float(job.duration_us[~job.is_dwell].sum()) * 1e-6 - 1e-9
    # the segment before each dwell ends at rest (the planner's rest limit, docs in planner)
    dth = np.abs(np.diff(job.steps * (2 * np.pi / job.steps_per_rev), axis=0)).max(axis=1)
    speed_before = dth[k - 1] / (job.duration_us[k - 1] * 1e-6)
    assert (speed_before <= planner.JUNCTION_JUMP_RAD_S + 1e-9).all()
    # encoded as G1 P… without A/B, with the laser power of the dwell (pen: S0)
    laser = encode_lines(job, prof, laser=True)
    assert f"G1 P500000 S{prof.laser.power}" in laser and "G1 P250000 S0" in laser
    pen = encode_lines(job, prof)
    assert "G1 P500000 S0" in pen
    i = pen.index("G1 P500000 S0")
    assert pen[i - 1].startswith("G1 A") and pen[i + 1].startswith("G1 A")  # pen stays down


def test_dwell_with_keep_order_off_keeps_the_file_order(dwell_file: Path) -> None:
    job = compile_job(dwell_file, load_profile(), CompileOptions())
    assert not job.paths.reversed.any()
    assert job.paths.source.tolist() == sorted(job.paths.source.tolist())


def test_resume_maps_a_dwell_like_any_segment(dwell_file: Path) -> None:
    prof = load_profile()
    job = compile_job(dwell_file, prof, CompileOptions(validate=False))
    k = int(np.flatnonzero(job.is_dwell)[0])
    prog = build_program(job, prof, True, k, job.steps[k])
    first = [i for i, s in enumerate(prog.segment.tolist()) if s == k]
    assert first and wire.bodies(prog)[first[0]] == f"G1 P500000 S{prof.laser.power}"
    assert prog.finished_segments(1, 1 + first[0], k) == k + 1


def test_plot_on_the_mock_runs_the_dwell(dwell_file: Path) -> None:
    prof = load_profile()
    job = compile_job(dwell_file, prof, CompileOptions(validate=False))
    res = CliRunner().invoke(main, ["plot", str(dwell_file), "--port",
                                    "fivebar-mock://?machine=dw&speed=10", "--laser", "--yes"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.output
    ledger = mock.machine("dw").ledger
    g1 = [e for e in ledger if e.kind == "G1"]
    dwells = [e for e in g1 if e.steps == (0, 0)]
    assert [(e.duration_us, e.power, e.fraction) for e in dwells] == [
        (500_000, prof.laser.power, 1.0), (250_000, 0, 1.0)]
    # the executed blocks' time is the plan's (the job's segments, dwells included)
    job_blocks = g1[-job.n_segments:]
    assert sum(e.duration_us for e in job_blocks) == int(job.duration_us.sum())
    # the mock really waited: the block after the 0.5 s dwell started ≥ 0.5 s / speed later
    i = g1.index(dwells[0])
    assert g1[i + 1].started_s - dwells[0].started_s >= 0.5 / 10 - 1e-3
