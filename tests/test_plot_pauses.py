"""Pen changes between layers, `--copies` and `--page-delay` on the mock device.

The drawing has two Inkscape layers whose strokes interleave in space, so ordering the whole
drawing at once would mix them: with a pen-change stop each layer is drawn on its own, in
document order. What the motors did is read from the mock's ledger (every block executed),
the pen from its servo model, so "stopped with the pen up and no motion" and "executed
exactly the plan" are checked on the machine, not on what the host believes.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from layers_support import PEN, layers_text
from runs import run_with

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.compile.model import LayerPause
from fivebar_host.config import load_profile
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices import mock
from fivebar_host.run.errors import SendError
from fivebar_host.run.resume import ResumePoint, resume_path
from fivebar_host.run.stops import Copies, pieces


@pytest.fixture(autouse=True)
def _clean_machines(clean_mock: None) -> None:
    """Every test here starts and ends with no named mock machine left over."""


def layers_svg(tmp_path: Path, first: str = "black", second: str = "red") -> Path:
    p = tmp_path / "layers.svg"
    p.write_text(layers_text(first, second), encoding="utf-8")
    return p


def url(name: str, speed: float = 0) -> str:
    return f"fivebar-mock://?machine={name}&speed={speed:g}"


def run(*args: str, stdin: str | None = None) -> tuple[int, str]:
    res = CliRunner().invoke(main, list(args), input=stdin, catch_exceptions=False)
    return res.exit_code, res.output


def compiled(path: Path, **opts: bool) -> Job:
    return compile_job(path, load_profile(PEN), CompileOptions(validate=False, **opts))


def moved_steps(m: mock.Machine) -> np.ndarray:
    """Sum of |steps| per motor of every move the machine made."""
    tot = np.zeros(2, dtype=np.int64)
    for e in m.ledger:
        if e.kind == "G1":
            tot += np.abs(np.asarray(e.steps))
    return tot


def plan_steps(job: Job) -> np.ndarray:
    return np.asarray(np.abs(np.diff(job.steps, axis=0)).sum(axis=0))


def assert_on_plan(m: mock.Machine, job: Job) -> None:
    """Every move of the machine ended on one of the job's targets (or a piece of a
    segment's joint-space line), and it is back at the homed pose."""
    targets = {tuple(t) for t in job.steps.tolist()}
    ends = [e.end for e in m.ledger if e.kind == "G1" and any(e.steps)]
    assert all(tuple(e) in targets for e in ends)
    assert m.phys == [0, 0]


# ------------------------------------------------------------------ compile
def test_layers_are_not_mixed_across_a_pen_change(tmp_path: Path) -> None:
    svg = layers_svg(tmp_path)
    free, paused = compiled(svg), compiled(svg, layer_pause=True)
    layer_of_path = [0, 0, 1, 1]  # source elements 0, 1 in layer 1; 2, 3 in layer 2
    mixed = [layer_of_path[int(s)] for s in free.paths.source]
    kept = [layer_of_path[int(s)] for s in paused.paths.source]
    assert mixed != sorted(mixed)  # travel-optimal order mixes the layers ...
    assert kept == [0, 0, 1, 1]  # ... a pen change keeps them in document order
    assert free.pauses == ()
    (p,) = paused.pauses
    assert (p.name, p.number, p.of) == ("red", 2, 2)
    # the stop is where the travel into layer 2's first path starts, the plan at rest there
    assert paused.path[p.segment] == 2 and not paused.draw[p.segment]
    assert paused.draw[p.segment - 1] and paused.path[p.segment - 1] == 1
    assert compiled(svg, layer_pause=True, no_pause=True).pauses == ()


def test_bang_layer_pauses_without_the_option(tmp_path: Path) -> None:
    job = compiled(layers_svg(tmp_path, first="!black", second="!red"))
    assert [(p.segment, p.name) for p in job.pauses] == [(0, "!black"),
                                                        (job.pauses[1].segment, "!red")]
    assert job.pauses[1].segment > 0
    assert compiled(layers_svg(tmp_path, "black", "!red"), no_pause=True).pauses == ()


def test_pieces_split_at_the_stops_and_resume_skips_the_one_it_starts_at(tmp_path: Path
                                                                         ) -> None:
    job = compiled(layers_svg(tmp_path, first="!black", second="red"), layer_pause=True)
    a, b = job.pauses
    n = job.n_segments
    assert pieces(job, 0, False) == [type(pieces(job, 0, False)[0])(0, b.segment, a),
                                     type(pieces(job, 0, False)[0])(b.segment, n, b)]
    assert [(pc.begin, pc.end, pc.pause) for pc in pieces(job, b.segment, True)] == [
        (b.segment, n, None)]
    assert [(pc.begin, pc.pause) for pc in pieces(job, 3, True)] == [(3, None),
                                                                      (b.segment, b)]


def test_dry_run_reports_pen_changes_and_copies(tmp_path: Path) -> None:
    code, out = run("plot", str(layers_svg(tmp_path)), "--dry-run", "--config", str(PEN),
                    "--layer-pause", "--copies", "3", "--page-delay", "10",
                    "--preview", str(tmp_path / "p.png"))
    assert code == 0, out
    job = compiled(layers_svg(tmp_path), layer_pause=True)
    total = 3 * job.total_time_s + 2 * 10.0
    assert f"≈ {total:.1f} s (3 copies of ≈ {job.total_time_s:.1f} s + 2 page delays" in out
    assert "+ 3 pen changes (wait for you)" in out
    assert "pen change    before layer 2/2 'red'" in out
    assert "tool          pen servo" in out


# ------------------------------------------------------------------ plotting on the mock
def test_pen_change_stops_idle_with_the_pen_up_then_finishes_exactly(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    svg = layers_svg(tmp_path)
    job = compiled(svg, layer_pause=True)
    seen: list[tuple[LayerPause, str, int, bool, list[int], int]] = []

    def ask(pause: LayerPause) -> bool:
        m = mock.machine("pc")
        assert m.port is not None
        before = len(m.ledger)
        time.sleep(0.1)  # nothing moves while the person changes the pen
        snap = m.port.snapshot()
        seen.append((pause, snap.state, snap.queued, m.pen.down, list(m.phys),
                     len(m.ledger) - before))
        return True

    monkeypatch.setattr("fivebar_host.cli.stops.terminal", lambda: True)
    monkeypatch.setattr("fivebar_host.cli.operator.ask_pen_change", ask)
    code, out = run("plot", str(svg), "--port", url("pc"), "--config", str(PEN),
                    "--layer-pause", "--yes")
    assert code == 0, out
    (pause, state, queued, down, phys, new_blocks), = seen
    assert pause == job.pauses[0]
    assert state == "Idle" and queued == 0 and not down and new_blocks == 0
    assert phys == job.steps[pause.segment].tolist()
    m = mock.machine("pc")
    assert np.array_equal(moved_steps(m), plan_steps(job))
    assert_on_plan(m, job)
    assert not resume_path(svg).exists()


def test_quit_at_the_pen_change_then_resume_finishes_exactly(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    svg = layers_svg(tmp_path)
    job = compiled(svg, layer_pause=True)
    monkeypatch.setattr("fivebar_host.cli.stops.terminal", lambda: True)
    code, out = run("plot", str(svg), "--port", url("q"), "--config", str(PEN),
                    "--layer-pause", "--yes", stdin="q\n")
    assert code == 3, out
    assert "Layer 2/2 'red': change the pen, then press Enter (q to stop)" in out
    assert "stopped at the pen change before layer 2/2 'red'" in out
    rp = ResumePoint.load(resume_path(svg))
    m = mock.machine("q")
    assert rp.next_segment == job.pauses[0].segment and rp.copy == 1
    assert rp.position is not None and list(rp.position) == m.phys
    assert not m.pen.down
    # --resume continues at the next layer without asking again, and ends exactly
    code, out = run("plot", str(svg), "--port", url("q"), "--config", str(PEN),
                    "--layer-pause", "--resume")
    assert code == 0, out
    assert "change the pen" not in out
    assert np.array_equal(moved_steps(m), plan_steps(job))
    assert_on_plan(m, job)
    assert not resume_path(svg).exists()


def test_enter_continues_and_ctrl_c_at_the_question_stops(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from fivebar_host.cli.operator import ask_pen_change

    p = LayerPause(10, "red", 2, 3)
    monkeypatch.setattr("click.prompt", lambda *a, **k: "")
    assert ask_pen_change(p) is True
    monkeypatch.setattr("click.prompt", lambda *a, **k: " Q ")
    assert ask_pen_change(p) is False

    def interrupted(*a: object, **k: object) -> str:
        raise KeyboardInterrupt

    monkeypatch.setattr("click.prompt", interrupted)
    assert ask_pen_change(p) is False


def test_without_a_terminal_a_pen_change_is_refused_up_front(tmp_path: Path) -> None:
    svg = layers_svg(tmp_path, second="!red")
    code, out = run("plot", str(svg), "--port", url("tty"), "--config", str(PEN), "--yes")
    assert code == 2
    assert "no terminal to confirm them" in out and "--no-pause" in out
    assert "layer 2/2 '!red'" in out
    assert mock.machine("tty").boots == 0  # refused before the port was opened
    # --no-pause draws through the stop (and --yes never answers a pen change)
    code, out = run("plot", str(svg), "--port", url("tty"), "--config", str(PEN), "--yes",
                    "--no-pause")
    assert code == 0, out
    assert np.array_equal(moved_steps(mock.machine("tty")),
                          plan_steps(compiled(svg, no_pause=True)))


def test_two_copies_with_a_page_delay_take_twice_the_steps(tmp_path: Path) -> None:
    svg = layers_svg(tmp_path)
    job = compiled(svg)
    t0 = time.monotonic()
    code, out = run("plot", str(svg), "--port", url("cp"), "--config", str(PEN), "--yes",
                    "--copies", "2", "--page-delay", "0.2")
    assert code == 0, out
    assert time.monotonic() - t0 >= 0.2
    assert "page delay: the next copy starts in 0.2 s" in out
    assert f"done: {2 * job.n_segments} segments" in out
    m = mock.machine("cp")
    assert np.array_equal(moved_steps(m), 2 * plan_steps(job))
    assert_on_plan(m, job)


def test_stop_during_the_page_delay_resumes_at_the_next_copy(tmp_path: Path) -> None:
    svg = layers_svg(tmp_path)
    prof = load_profile(PEN)
    job = compiled(svg)
    waiting = {"now": False}
    link = Link.open(url("cd"))
    try:
        with pytest.raises(SendError, match="stopped before copy 2 of 2") as e:
            run_with(link, job, prof, drawing=svg, laser=False, confirm=lambda q: True,
                    copies=Copies(2, 5.0), on_wait=lambda s: waiting.update(now=True),
                    should_stop=lambda: waiting["now"], on_interrupt=lambda: False)
        assert "resume file" in str(e.value)
        rp = ResumePoint.load(resume_path(svg))
        assert (rp.copy, rp.next_segment, rp.position) == (2, 0, (0, 0))
        rep = run_with(link, job, prof, drawing=svg, laser=False, confirm=lambda q: True,
                      resume=True, copies=Copies(2, 5.0))
        assert rep.segments == job.n_segments  # the second copy only
    finally:
        link.close()
    m = mock.machine("cd")
    assert np.array_equal(moved_steps(m), 2 * plan_steps(job))
    assert not resume_path(svg).exists()


def test_a_job_with_stops_needs_someone_to_answer(tmp_path: Path) -> None:
    svg = layers_svg(tmp_path)
    job = compiled(svg, layer_pause=True)
    link = Link.open(url("api"))
    try:
        with pytest.raises(SendError, match="nobody is there to answer"):
            run_with(link, job, load_profile(PEN), drawing=svg, laser=False,
                    confirm=lambda q: True)
    finally:
        link.close()
    assert mock.machine("api").ledger == [] or moved_steps(mock.machine("api")).sum() == 0
