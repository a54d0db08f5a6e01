"""`fivebar serve` with pen-change stops and copies (mock device, pen-servo profile): a stop
puts the job into the paused state with a reason naming the layer, with the machine idle and
the pen up; the resume request goes on and the job ends exactly on plan; a cancel at the stop
cancels; copies with a page delay run the job twice."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from layers_support import PEN, layers_text
from serve_support import wait_for

from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.server.client import ServerClient, follow, plot_options
from fivebar_host.server.daemon import Daemon, ServeConfig

SVG = layers_text().encode()


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[Callable[[str], Daemon]]:
    """A daemon over the named mock machine with the pen-servo profile."""
    started: list[Daemon] = []

    def start(machine: str, **kw: Any) -> Daemon:
        d = Daemon(ServeConfig(port_url=f"fivebar-mock://?speed=0&machine={machine}",
                               listen="127.0.0.1:0", state_dir=tmp_path / machine,
                               banner_timeout_s=1.0, profile_path=PEN, **kw))
        d.start()
        started.append(d)
        return d

    yield start
    for d in started:
        d.stop(hurry=True, timeout_s=15.0)
    mock.forget_machines()


def compiled(tmp_path: Path, **opts: bool) -> Job:
    p = tmp_path / "layers.svg"
    p.write_bytes(SVG)
    return compile_job(p, load_profile(PEN), CompileOptions(**opts))


def moved_steps(machine: str) -> np.ndarray:
    tot = np.zeros(2, dtype=np.int64)
    for e in mock.machine(machine).ledger:
        if e.kind == "G1":
            tot += np.abs(np.asarray(e.steps))
    return tot


def plan_steps(job: Job) -> np.ndarray:
    return np.asarray(np.abs(np.diff(job.steps, axis=0)).sum(axis=0))


def test_pen_change_pauses_the_job_naming_the_layer_then_resumes_exactly(
        daemon: Callable[..., Daemon], tmp_path: Path) -> None:
    c = ServerClient(daemon("pc").url)
    job = compiled(tmp_path, layer_pause=True)
    j = c.submit(SVG, "layers.svg", plot_options(layer_pause=True, confirm=True))
    paused = wait_for(lambda: (x := c.job(j["id"]))["state"] == "paused" and x,
                      what="the pen-change pause")
    assert paused["message"].startswith("pen change: layer 2/2 'red'")
    m = mock.machine("pc")
    n = len(m.ledger)
    time.sleep(0.3)
    st = c.status()["machine"]
    assert st["state"] == "Idle" and not m.pen.down and len(m.ledger) == n
    assert m.phys == job.steps[job.pauses[0].segment].tolist()
    c.resume(j["id"])
    done = follow(c, j["id"], lambda x: None, max_s=60)
    assert done["state"] == "done", done
    assert np.array_equal(moved_steps("pc"), plan_steps(job))
    assert m.phys == [0, 0]


def test_cancel_at_the_pen_change_cancels(daemon: Callable[..., Daemon],
                                          tmp_path: Path) -> None:
    c = ServerClient(daemon("cx").url)
    job = compiled(tmp_path, layer_pause=True)
    j = c.submit(SVG, "layers.svg", plot_options(layer_pause=True, confirm=True))
    wait_for(lambda: c.job(j["id"])["state"] == "paused", what="the pen-change pause")
    c.cancel(j["id"])
    done = wait_for(lambda: (x := c.job(j["id"]))["state"] == "cancelled" and x,
                    what="cancelled")
    assert f"segment {job.pauses[0].segment} of {job.n_segments}" in done["message"]
    k = job.pauses[0].segment
    assert np.array_equal(moved_steps("cx"),
                          np.abs(np.diff(job.steps[:k + 1], axis=0)).sum(axis=0))


def test_copies_with_a_page_delay_run_the_job_twice(daemon: Callable[..., Daemon],
                                                    tmp_path: Path) -> None:
    c = ServerClient(daemon("cp").url)
    job = compiled(tmp_path)
    j = c.submit(SVG, "layers.svg", plot_options(copies=2, page_delay_s=0.2, confirm=True))
    assert j["estimated_s"] == pytest.approx(2 * job.total_time_s + 0.2, rel=1e-6)
    assert (j["options"]["copies"], j["options"]["page_delay_s"]) == (2, 0.2)  # every option
    copy_seen: list[int] = []
    done = follow(c, j["id"], lambda x: copy_seen.append(x["copy_number"]), poll_s=0.05,
                  max_s=60)
    assert done["state"] == "done", done
    assert copy_seen == sorted(copy_seen) and done["copy_number"] == 2, copy_seen
    assert np.array_equal(moved_steps("cp"), 2 * plan_steps(job))
    assert mock.machine("cp").phys == [0, 0]


def test_plot_server_progress_counts_every_copy() -> None:
    """`plot --server`'s bar runs over all copies, its text naming the copy (as `plot`)."""
    from fivebar_host.cli.remote import _bar_updater

    class Bar:
        def __init__(self) -> None:
            self.pos, self.text = 0, ""

        def update(self, n: int, text: str) -> None:
            self.pos, self.text = self.pos + n, text

    bar = Bar()
    update = _bar_updater(bar)
    view = {"segments_total": 10, "elapsed_s": 1.0, "remaining_s": 5.0, "state": "running",
            "options": {"copies": 3}}
    update({**view, "copy_number": 1, "segments_done": 10})
    update({**view, "copy_number": 2, "segments_done": 4})
    assert bar.pos == 14 and bar.text.startswith("copy 2/3, segment 4/10"), bar.text
    update({**view, "copy_number": 2, "segments_done": 3})  # never back
    assert bar.pos == 14


def test_plot_server_asks_for_the_pen_change_on_a_terminal(
        daemon: Callable[..., Daemon], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from click.testing import CliRunner

    from fivebar_host.cli import main

    d = daemon("rm")
    svg = tmp_path / "layers.svg"
    svg.write_bytes(SVG)
    monkeypatch.setattr("fivebar_host.cli.remote.terminal", lambda: True)
    res = CliRunner().invoke(main, ["plot", str(svg), "--server", d.url, "--layer-pause",
                                    "--yes"], input="\n", catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "pen change: layer 2/2 'red'" in res.output
    job = compiled(tmp_path, layer_pause=True)
    assert np.array_equal(moved_steps("rm"), plan_steps(job))
