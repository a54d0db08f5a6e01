"""`--controller grbl`: fivebar drives a stock GRBL 1.1 board (the `fivebar-grbl://` model)
in joint space — settings, refusal, the drawn path, the laser, character counting, holds."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import numpy as np
import pytest
import serial
from click.testing import CliRunner
from runs import run_with

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.controllers.grbl.link import GrblError, GrblLink
from fivebar_host.devices import grblmock, urls
from fivebar_host.program import line_param
from fivebar_host.report.text.executed import executed_path
from fivebar_host.run.resume import ResumePoint, resume_path

ROOT = Path(__file__).resolve().parents[1]
TEXT = ROOT / "examples" / "fivebar_text.svg"


@pytest.fixture(autouse=True)
def _boards() -> None:
    urls.register()
    grblmock.forget_boards()


def _cli(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args))
    return res.exit_code, res.output


def _configure(name: str) -> None:
    """Send `fivebar grbl-settings` to the board line by line, as a user would."""
    code, out = _cli("grbl-settings", "--config", str(ROOT / "configs" / "default.toml"))
    assert code == 0
    port = serial.serial_for_url(f"fivebar-grbl://{name}", timeout=1.0)
    try:
        port.readline(), port.readline()  # banner
        for line in out.splitlines():
            port.write((line + "\n").encode())
            assert port.readline() == b"ok\r\n", line
    finally:
        port.close()


def test_grbl_settings_match_an_independent_computation() -> None:
    code, out = _cli("grbl-settings", "--config", str(ROOT / "configs" / "default.toml"))
    assert code == 0 and out.isascii()  # GRBL takes bytes >= 0x80 as real-time commands
    got = {int(r.split("=")[0][1:]): float(r.split("=")[1].split()[0])
           for r in out.splitlines()}
    # configs/default.toml: 200 full steps × 16 microsteps × 4:1, 6 rad/s, 60 rad/s²,
    # limits [10, 170]° on both joints, no endstops, no servo pen.
    spd = 200 * 16 * 4 / 360
    assert got[100] == pytest.approx(spd, abs=1e-6) and got[101] == got[100]
    assert got[110] == pytest.approx(6 * 180 / math.pi * 60, abs=1e-3) == got[111]
    assert got[120] == pytest.approx(60 * 180 / math.pi, abs=1e-3) == got[121]
    assert got[130] == got[131] == 160.0
    assert (got[32], got[30], got[20], got[22], got[13], got[10]) == (1, 1000, 0, 0, 0, 1)


def test_plot_draws_the_job_with_the_laser_only_while_drawing() -> None:
    _configure("plot")
    code, out = _cli("plot", str(TEXT), "--controller", "grbl", "--laser", "--yes",
                     "--port", "fivebar-grbl://plot?speed=50")
    assert code == 0, out
    board = grblmock.board("plot")
    assert board.overflow == 0
    prof = load_profile()
    job = compile_job(TEXT, prof, CompileOptions())
    t, track, laser = grblmock.executed_steps(board.blocks)
    bound = job.tolerance_mm + job.step_quantum_mm
    ex = executed_path(job, prof, t, track)
    assert ex.segments_completed == job.n_segments
    measured = ex.deviation_mm[~np.isnan(ex.deviation_mm)]
    assert measured.size > 1000 and np.isfinite(measured).all()
    print(f"GRBL executed path: max deviation {ex.max_deviation_mm:.4f} mm over "
          f"{measured.size} step events (bound {bound:.4f} mm)")
    assert 0.0 < ex.max_deviation_mm <= bound
    on_draw = job.draw[np.maximum(ex.segment, 0)] & (ex.segment >= 0)
    assert not (laser & ~on_draw).any(), "laser on outside a drawing segment"
    drawing = on_draw & (job.power[np.maximum(ex.segment, 0)] > 0)
    assert laser[drawing].all(), "laser off while drawing"
    # the planned durations reach GRBL: its run time at nominal rates ≈ the plan
    ran = sum(b.duration_s for b in board.blocks)
    assert ran == pytest.approx(job.total_time_s, rel=0.01)


def test_plot_refuses_a_board_with_other_settings() -> None:
    grblmock.board("stock")  # GRBL's defaults: $100=250, $32=0 …
    code, out = _cli("plot", str(TEXT), "--controller", "grbl", "--laser", "--yes",
                     "--port", "fivebar-grbl://stock?speed=50")
    assert code == 3
    assert "$100: board 250, needed 35.555556" in out
    assert "$32: board 0, needed 1" in out and "$120: board 10, needed 3437.747" in out
    assert grblmock.board("stock").blocks == []


def test_character_counting_keeps_the_receive_buffer_from_overflowing() -> None:
    lines = [f"G1 X{120 + 0.01 * i:.4f} Y60.0000 F600" for i in range(60)]
    port = serial.serial_for_url("fivebar-grbl://raw?speed=1", timeout=0.2)
    port.write(("G10 L2 P1 X-120 Y-60\n" + "\n".join(lines) + "\n").encode())
    time.sleep(0.2)
    replies = port.read(4000).decode()
    port.close()
    blind = grblmock.board("raw")  # a sender that does not count: bytes and lines lost
    assert blind.overflow > 0 and len(blind.received) < 1 + len(lines)
    assert replies.count("ok") < 1 + len(lines)
    link = GrblLink.open("fivebar-grbl://counted?speed=200")
    try:
        link.command("G10 L2 P1 X-120 Y-60")
        st = link.stream(lines)
        link.wait_idle(10.0)
    finally:
        link.close()
    counted = grblmock.board("counted")
    assert counted.overflow == 0 and st.acked == len(lines) == len(counted.received) - 1


def test_mock_answers_as_grbl_documents() -> None:
    link = GrblLink.open("fivebar-grbl://doc")
    try:
        for bad, code in (("G1 X1", "error:22"), ("G2 X1 Y1 I1", "error:20"),
                          ("$20=1", "error:10"), ("$999=1", "error:3")):
            with pytest.raises(GrblError, match=code):
                link.command(bad)
        st = link.status()
        assert st.state == "Idle" and st.machine == (0.0, 0.0) and st.wco == (0.0, 0.0)
    finally:
        link.close()


def job_program_last(job: object, prof: object) -> str:
    """The job's last motion line as the board would log it."""
    from fivebar_host.controllers.grbl.program import job_program

    lines = [x for x in job_program(job, prof, True).lines  # type: ignore[arg-type]
             if x.startswith("G1")]
    return lines[-1].replace(" ", "")


def test_ctrl_c_holds_and_names_the_exact_segment(tmp_path: Path) -> None:
    _configure("hold")
    prof = load_profile()
    job = compile_job(TEXT, prof, CompileOptions())
    link = GrblLink.open("fivebar-grbl://hold?speed=5")
    calls = {"n": 0}

    def stop() -> bool:
        calls["n"] += 1
        return calls["n"] == 300

    try:
        with pytest.raises(GrblError, match=r"in segment (\d+) of") as info:
            run_with(link, job, prof, laser=True, confirm=lambda q: True,
                         should_stop=stop, on_interrupt=lambda: False,
                         drawing=tmp_path / "text.svg")
    finally:
        link.close()
    found = re.search(r"in segment (\d+) of", str(info.value))
    assert found is not None and "Laser off" in str(info.value)
    k = int(found.group(1))
    board = grblmock.board("hold")
    last = board.blocks[-1]
    pos = last.start[:2] if last.done == 0 else tuple(
        round(last.start[i] + last.done * (last.end[i] - last.start[i])) for i in range(2))
    assert 0 < k < job.n_segments
    assert line_param(job.steps[k], job.steps[k + 1], pos) is not None
    assert sum(b.done < 1.0 for b in board.blocks) <= 1  # stopped once, nothing after
    assert board.received[-1] != job_program_last(job, prof)  # the job did not finish


def test_home_jog_frame_and_convert_on_grbl(tmp_path: Path) -> None:
    _configure("mc")
    url = "fivebar-grbl://mc?speed=50"
    code, out = _cli("home", "--controller", "grbl", "--port", url, "--yes")
    assert code == 0 and "homed: X 120.000°, Y 60.000°" in out, out
    code, out = _cli("jog", "--controller", "grbl", "--port", url, "--yes", "--motor", "A",
                     "--steps", "200")
    assert code == 0, out
    board = grblmock.board("mc")
    assert board.blocks[-1].end[:2] == (200, 0)  # GRBL's steps are fivebar's steps
    code, out = _cli("frame", str(TEXT), "--controller", "grbl", "--port", url, "--yes")
    assert code == 0, out  # the board rebooted on open: the count restarted at the arms
    assert board.blocks[-1].end[:2] == (0, 0) and all(b.laser == 0 for b in board.blocks)
    out_file = tmp_path / "job.nc"
    code, out = _cli("convert", str(TEXT), "--controller", "grbl", "-o", str(out_file),
                     "--laser")
    assert code == 0, out
    text = out_file.read_text().splitlines()
    assert text[0].startswith("G21 G90") and any(x.startswith("M4 S") for x in text)
    assert not any(" A" in x and x.startswith("G1") for x in text)


def _abort(url: str, drawing: Path, at: int = 300) -> str:
    """Run the job on `url` and abort it (Ctrl-C, then "abort") after `at` polls."""
    prof = load_profile()
    job = compile_job(TEXT, prof, CompileOptions())
    calls = {"n": 0}

    def stop() -> bool:
        calls["n"] += 1
        return calls["n"] == at

    link = GrblLink.open(url)
    try:
        with pytest.raises(GrblError, match=r"in segment \d+ of") as info:
            run_with(link, job, prof, laser=True, confirm=lambda q: True,
                         should_stop=stop, on_interrupt=lambda: False, drawing=drawing)
    finally:
        link.close()
    return str(info.value)


def test_abort_then_resume_draws_the_plan_exactly_once(tmp_path: Path) -> None:
    _configure("res")
    url = "fivebar-grbl://res?speed=5&dtr=0"  # a board that keeps its count on open
    drawing = tmp_path / "text.svg"
    _abort(url, drawing)
    rp = ResumePoint.load(resume_path(drawing))
    prof = load_profile()
    job = compile_job(TEXT, prof, CompileOptions())
    assert rp.position is not None and 0 < rp.next_segment < job.n_segments
    notes: list[str] = []
    link = GrblLink.open(url.replace("speed=5", "speed=200"))
    try:
        rep = run_with(link, job, prof, laser=True, confirm=lambda q: False,
                           confirm_placed=lambda q: False, drawing=drawing, resume=True,
                           on_note=notes.append)
    finally:
        link.close()
    assert "kept its position" in notes[0] and not resume_path(drawing).exists()
    assert rep.final == tuple(int(v) for v in job.steps[-1])
    blocks = grblmock.board("res").blocks
    partial = [i for i, b in enumerate(blocks) if b.done < 1.0]
    assert len(partial) == 1
    cut = blocks[partial[0]]
    stop = tuple(round(cut.start[i] + cut.done * (cut.end[i] - cut.start[i]))
                 for i in range(2))
    assert stop == rp.position and blocks[partial[0] + 1].start[:2] == stop
    moving = [k for k in range(job.n_segments)
              if not np.array_equal(job.steps[k], job.steps[k + 1])]
    # every planned line ran once, in order: a whole block each, or the cut one where the
    # abort came after its last step (a 1-step segment stopped past its middle: the resume
    # goes on with the next segment)
    cut_ran = stop == tuple(cut.end[:2])
    ran = [b for b in blocks if b.done >= 1.0 or (b is cut and cut_ran)][-len(moving):]
    for k, b in zip(moving, ran, strict=True):
        assert np.abs(np.subtract(b.end[:2], job.steps[k + 1])).max() <= 1, k
        assert (b.laser > 0) == bool(job.draw[k] and job.power[k] > 0), k
    if not cut_ran:  # the resume ran the cut segment again from where it stopped
        k = rp.next_segment
        assert (cut.laser > 0) == bool(job.draw[k] and job.power[k])


def test_resume_refused_for_another_job_or_a_board_that_lost_its_count(tmp_path: Path
                                                                        ) -> None:
    _configure("lost")
    drawing = tmp_path / "text.svg"
    drawing.write_bytes(TEXT.read_bytes())
    _abort("fivebar-grbl://lost?speed=5", drawing)
    n = len(grblmock.board("lost").blocks)
    url = "fivebar-grbl://lost?speed=50"  # opening the port reboots it: count lost
    code, out = _cli("plot", str(drawing), "--controller", "grbl", "--laser", "--yes",
                     "--resume", "--port", url)
    assert code != 0 and "--yes does not answer" in out and "Nothing was sent" in out, out
    code, out = _cli("plot", str(drawing), "--controller", "grbl", "--yes", "--resume",
                     "--tolerance", "0.2", "--port", url)
    assert code != 0 and "belongs to a different job" in out, out
    assert len(grblmock.board("lost").blocks) == n  # nothing moved


def test_a_stop_where_the_path_crosses_itself_is_not_resumable() -> None:
    from types import SimpleNamespace

    from fivebar_host.controllers.grbl.link import StreamState
    from fivebar_host.controllers.grbl.program import GrblProgram
    from fivebar_host.controllers.grbl.resume import identify

    job = SimpleNamespace(steps=np.array([[0, 0], [100, 0], [0, 0], [100, 40]]),
                          n_segments=3)
    prog = GrblProgram(["G21", "a", "b", "c"], np.array([-1, 0, 1, 2]))
    k, why = identify(prog, job, (50, 0), StreamState(sent=4, acked=4))  # type: ignore
    assert k is None and "ambiguous" in why and "0, 1" in why
    k, why = identify(prog, job, (50, 20), StreamState(sent=4, acked=4))  # type: ignore
    assert k == 2 and why == ""


def test_pen_change_stops_and_copies_run_on_grbl_as_on_fivebar(tmp_path: Path) -> None:
    """The same run (`run.job.run_job`) on both controllers: at each pen-change stop the
    board is idle at the stop's first segment with the laser off; every moving segment of
    every copy runs once, in order, the laser on exactly where the job draws."""
    from layers_support import layers_text

    from fivebar_host.run.stops import Copies

    _configure("pc")
    prof = load_profile()
    svg = tmp_path / "layers.svg"
    svg.write_text(layers_text())
    job = compile_job(svg, prof, CompileOptions(layer_pause=True))
    assert len(job.pauses) == 1
    seen: list[tuple[int, float, str]] = []

    def pause(p: object) -> bool:
        board = grblmock.board("pc")
        lines = [r for r in board.received if not r.startswith("$")]  # $#: the offsets
        seen.append((len(board.blocks), board.blocks[-1].done, lines[-1]))
        return True

    link = GrblLink.open("fivebar-grbl://pc?speed=200")
    try:
        rep = run_with(link, job, prof, drawing=svg, laser=True, confirm=lambda q: True,
                       on_pause=pause, copies=Copies(2, 0.0))
    finally:
        link.close()
    assert rep.segments == 2 * job.n_segments and rep.final == tuple(job.steps[-1])
    assert len(seen) == 2 and all(done == 1.0 for _, done, _ in seen)
    blocks = [b for b in grblmock.board("pc").blocks if not b.rapid]
    moving = [k for k in range(job.n_segments)
              if not np.array_equal(job.steps[k], job.steps[k + 1])]
    assert len(blocks) == 2 * len(moving)
    for copy in range(2):
        run = blocks[copy * len(moving):(copy + 1) * len(moving)]
        for k, b in zip(moving, run, strict=True):
            assert b.done == 1.0 and b.end[:2] == tuple(job.steps[k + 1]), (copy, k)
            assert (b.laser > 0) == bool(job.draw[k] and job.power[k] > 0), (copy, k)
    stop = job.pauses[0].segment
    first_copy = blocks[:len(moving)]
    before = sum(1 for k in moving if k < stop)
    assert first_copy[before - 1].end[:2] == tuple(job.steps[stop])
    assert all(last == "M5" for _, _, last in seen)  # the laser off, the board idle


def test_what_grbl_cannot_do_is_refused_before_anything_moves(tmp_path: Path) -> None:
    """A laser dwell (GRBL's M4 is off at rest) and live overrides are refused, naming the
    line and the reason; the board received no motion."""
    from test_dwell import TWO_STROKES

    from fivebar_host.errors import UsageError
    from fivebar_host.run.overrides import Overrides

    _configure("no")
    prof = load_profile()
    gcode = tmp_path / "dwell.gcode"
    gcode.write_text(TWO_STROKES)
    job = compile_job(gcode, prof, CompileOptions())
    link = GrblLink.open("fivebar-grbl://no?speed=200")
    try:
        with pytest.raises(UsageError, match=r"line 5: a dwell with the laser on: GRBL's "):
            run_with(link, job, prof, drawing=gcode, laser=True, confirm=lambda q: True)
        plain = compile_job(TEXT, prof, CompileOptions())
        with pytest.raises(UsageError, match="live feed and power overrides: a stock GRBL"):
            run_with(link, plain, prof, drawing=TEXT, laser=True, confirm=lambda q: True,
                     overrides=Overrides())
    finally:
        link.close()
    assert grblmock.board("no").blocks == []
    # without the laser the dwells are waits with the tool off: G4 on the board
    link = GrblLink.open("fivebar-grbl://no?speed=200")
    try:
        run_with(link, job, prof, drawing=gcode, laser=False, confirm=lambda q: True)
    finally:
        link.close()
    assert sum(r.startswith("G4") for r in grblmock.board("no").received) == 2


def test_an_image_is_refused_before_anything_reaches_the_board(tmp_path: Path) -> None:
    """A raster job's pixels are a timeline inside the scan's moves (G7), which fivebar does
    not write as GRBL lines: plotting it on a GRBL board ran the scan with the laser never on
    and said "done"; `convert` wrote the moves alone. Now both refuse, naming the file, and
    nothing is sent or written; the dry run says so."""
    from PIL import Image

    img = tmp_path / "grey.png"
    Image.fromarray(np.full((4, 20), 100, dtype=np.uint8)).save(img)
    _configure("img")
    code, out = _cli("plot", str(img), "--laser", "--width", "4mm", "--controller", "grbl",
                     "--yes", "--port", "fivebar-grbl://img?speed=50")
    assert code == 2 and f"{img}: an image (raster) job" in out, out
    assert grblmock.board("img").blocks == []
    code, out = _cli("convert", str(img), "--laser", "--width", "4mm", "--controller", "grbl",
                     "-o", str(tmp_path / "out.gcode"))
    assert code == 2 and "an image (raster) job" in out and not (tmp_path / "out.gcode").exists()
    code, out = _cli("plot", str(img), "--laser", "--width", "4mm", "--controller", "grbl",
                     "--dry-run", "--preview", str(tmp_path / "p.png"))
    assert code == 0 and "--controller grbl cannot engrave it" in out, out
