"""Long compiles say how far they are: a time estimate before the long work, then a line
every few seconds without a terminal (a bar on one); short compiles say nothing. The
daemon's submissions show the same as `compiling` in `GET /api/status`."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from fivebar_host import progress
from fivebar_host.cli import progress as cli_progress
from fivebar_host.compile import CompileOptions, budget, compile_job
from fivebar_host.config import load_profile

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_lines_without_a_terminal_and_nothing_for_a_quick_compile(
        monkeypatch: pytest.MonkeyPatch) -> None:
    clock = Clock()
    monkeypatch.setattr(cli_progress.time, "monotonic", clock)
    out = io.StringIO()
    shown = cli_progress.CompileProgress(out, tty=False)
    with progress.listening_with(shown):
        progress.report("reading", 0.1)  # within the quiet time: nothing
        assert out.getvalue() == ""
        progress.estimate("1,000,000 paths of 1,000,000 lines and curves: about 35 s")
        clock.t += 2.5
        progress.report("reading", 0.5)
        clock.t += 1.0
        progress.report("reading", 0.7)  # within a line's interval: nothing
        clock.t += 2.5
        progress.report("ordering paths", 0.25)
    shown.close()
    assert out.getvalue().splitlines() == [
        "compiling: 1,000,000 paths of 1,000,000 lines and curves: about 35 s",
        "compiling: reading 50% (2 s)", "compiling: ordering paths 25% (6 s)"]


def test_a_bar_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = Clock()
    monkeypatch.setattr(cli_progress.time, "monotonic", clock)
    out = io.StringIO()
    shown = cli_progress.CompileProgress(out, tty=True)
    with progress.listening_with(shown):
        clock.t += 3.0
        progress.report("solving", 0.5)
    shown.close()
    text = out.getvalue()
    assert text.startswith("\r\x1b[Kcompiling: solving [" + "#" * 12 + "." * 12 + "] 50% (3 s)")
    assert text.endswith("\r\x1b[K")


def test_the_pipeline_reports_its_stages_in_order() -> None:
    heard: list[progress.Event] = []
    with progress.listening_with(heard.append):
        compile_job(EXAMPLES / "square.gcode", load_profile(None), CompileOptions())
    stages = list(dict.fromkeys(e.stage for e in heard))
    assert stages == ["reading", "placing", "ordering paths", "solving", "travel",
                      "segments", "timing", "validating"]
    assert progress.listening() is False  # nobody listens outside the `with`


def test_the_estimate_is_told_for_large_work_only(monkeypatch: pytest.MonkeyPatch) -> None:
    notes: list[str | None] = []
    assert budget.duration_text(35) == "35 s" and budget.duration_text(400) == "7 min"
    with progress.listening_with(lambda e: notes.append(e.note)):
        budget.told(1.0, "small")
        budget.told(150.0, "1,000,000 paths")
    assert notes == ["1,000,000 paths: about 2 min"]


def tiny_paths_svg(n: int) -> bytes:
    """`n` tiny separate paths on a 40 mm page (benchmarks/tiny_paths.py's kind)."""
    side = int(n ** 0.5) + 1
    rows = [f'<path d="M{(i % side) * 100 / side:.3f} {(i // side) * 100 / side:.3f}h.05"/>'
            for i in range(n)]
    return ('<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="40mm" '
            'viewBox="0 0 100 100">\n' + "\n".join(rows) + "\n</svg>\n").encode()


def test_the_daemon_shows_a_submission_compiling(tmp_path: Path) -> None:
    import threading
    import time

    from serve_support import running_daemon, wait_for

    from fivebar_host.server.client import ServerClient, plot_options

    body = tiny_paths_svg(40_000)
    with running_daemon(tmp_path, "compiling") as d:  # compiles in child processes
        c = ServerClient(d.url)
        done: list[dict[str, object]] = []
        t = threading.Thread(target=lambda: done.append(
            c.submit(body, "tiny.svg", plot_options(confirm=True))))
        t.start()
        seen: list[dict[str, object]] = []
        deadline = time.monotonic() + 120
        while t.is_alive() and time.monotonic() < deadline:
            seen += c.status().get("compiling", [])
            time.sleep(0.02)
        t.join(120)
        assert done and done[0]["name"] == "tiny.svg"
        wait_for(lambda: c.status()["compiling"] == [], what="the entry gone")
    assert {s["name"] for s in seen} == {"tiny.svg"}
    stages = {s["stage"] for s in seen}
    assert stages & {"reading", "placing", "ordering paths", "solving", "validating"}, stages
