"""The daemon as a real process: SIGKILL mid-job and SIGTERM mid-job, then a restart.

The machine is the Python mock served on a pseudo-terminal by its own process
(`fivebar_host.server.ptydevice`), so it outlives the daemon like a controller on a USB
adapter that is not reset when the port is reopened; its ledger says what the motors did.
After the restart the job must continue from exactly where the machine stopped: the steps
executed over both runs equal the plan, no block was cut short, and the machine ends home.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import closing
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.server.client import ServerClient, follow, plot_options

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SQUARE = EXAMPLES / "square.gcode"
ROOT = Path(__file__).resolve().parent.parent


class Device:
    """The pty-hosted mock machine (a subprocess)."""

    def __init__(self, tmp: Path, speed: float) -> None:
        self.link = tmp / "tty"
        self.ledger_path = tmp / "ledger.json"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fivebar_host.server.ptydevice", "--url",
             f"fivebar-mock://?speed={speed}", "--link", str(self.link), "--ledger",
             str(self.ledger_path)], stdout=subprocess.PIPE, text=True, cwd=ROOT)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        assert line.startswith("PTY "), line

    def ledger(self) -> dict[str, Any]:
        """Stop the device and read what it executed."""
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(10)
        out: dict[str, Any] = json.loads(self.ledger_path.read_text())
        return out

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)


class DaemonProc:
    """`fivebar serve` as a subprocess on 127.0.0.1 (port chosen by the OS)."""

    def __init__(self, tmp: Path, port: Path | str, name: str) -> None:
        self.ready = tmp / f"{name}.ready"
        self.log_path = tmp / f"{name}.log"
        self.log = self.log_path.open("w")
        self.proc = subprocess.Popen(
            [sys.executable, "-c", "from fivebar_host.cli import main; main()", "serve",
             "--port", str(port), "--listen", "127.0.0.1:0", "--state-dir", str(tmp / "state"),
             "--banner-timeout", "0.6", "--ready-file", str(self.ready)],
            stdout=self.log, stderr=subprocess.STDOUT, cwd=ROOT)
        deadline = time.monotonic() + 30
        while not self.ready.exists():
            assert self.proc.poll() is None, self.log_text()
            assert time.monotonic() < deadline, self.log_text()
            time.sleep(0.02)
        self.url = self.ready.read_text().strip()
        self.client = ServerClient(self.url)

    def log_text(self) -> str:
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text()

    def stop(self, sig: int) -> int:
        self.proc.send_signal(sig)
        code = self.proc.wait(60)
        self.log.close()
        return code


@pytest.fixture
def device(tmp_path: Path) -> Iterator[Device]:
    dev = Device(tmp_path, speed=2.0)
    yield dev
    dev.close()


def plan() -> tuple[Any, np.ndarray]:
    job = compile_job(SQUARE, load_profile(None), CompileOptions())
    return job, np.abs(np.diff(job.steps, axis=0)).sum(axis=0)


def wait_segments(client: ServerClient, job_id: int, n: int, copy: int = 1) -> dict[str, Any]:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        j = client.job(job_id)
        if j["copy_number"] > copy or (j["copy_number"] == copy and j["segments_done"] >= n):
            return j
        time.sleep(0.02)
    raise AssertionError(f"job {job_id} never reached segment {n} of copy {copy}")


def saved_progress(tmp: Path, job_id: int) -> int:
    """Wait until the daemon's database holds some progress of the job, and return it: the
    daemon hands progress to its writer every 0.25 s and the writer commits every 0.5 s, so
    a job's live count can be well ahead of its record (under load, 40 segments seen live
    with none yet on disk)."""
    db = tmp / "state" / "fivebar.db"
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        with closing(sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5.0)) as c:
            row = c.execute("SELECT segments_done FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is not None and row[0] > 0:
            return int(row[0])
        time.sleep(0.05)
    raise AssertionError(f"job {job_id}: no progress recorded in {db}")


def restart_and_finish(tmp_path: Path, device: Device, job_id: int) -> dict[str, Any]:
    d = DaemonProc(tmp_path, device.link, "second")
    try:
        deadline = time.monotonic() + 30
        while (held := d.client.job(job_id))["state"] == "running":  # recovery under way
            assert time.monotonic() < deadline, d.log_text()
            time.sleep(0.05)
        assert held["state"] == "held", held
        d.client.resume(job_id)
        done = follow(d.client, job_id, lambda j: None, max_s=60)
        assert done["state"] == "done", (done, d.log_text())
        return held
    finally:
        d.stop(signal.SIGTERM)


def test_sigkill_mid_job_then_restart_resumes_exactly(tmp_path: Path, device: Device) -> None:
    job, steps_plan = plan()
    d = DaemonProc(tmp_path, device.link, "first")
    j = d.client.submit(SQUARE.read_bytes(), "square.gcode", plot_options(confirm=True))
    seen = wait_segments(d.client, j["id"], 40)
    assert seen["state"] == "running"
    os.kill(d.proc.pid, signal.SIGKILL)
    d.proc.wait(10)
    d.log.close()
    held = restart_and_finish(tmp_path, device, j["id"])
    # The controller ran what it had been sent, then stopped at a segment boundary; the
    # restarted daemon read its line counter and knows exactly which segment that was.
    rp = held["resume"]
    assert rp is not None and rp["position"] is not None, held
    assert rp["next_segment"] >= seen["segments_done"]
    assert rp["position"] == job.steps[rp["next_segment"]].tolist()
    led = device.ledger()
    assert led["steps_abs"] == steps_plan.tolist(), (led, steps_plan)
    assert led["steps_net"] == [0, 0] and led["position"] == [0, 0]
    assert led["partial_blocks"] == 0  # no segment cut short, none drawn twice
    assert led["blocks"] == job.n_segments
    assert led["boots"] == 1


def kill(d: DaemonProc) -> None:
    os.kill(d.proc.pid, signal.SIGKILL)
    d.proc.wait(10)
    d.log.close()


@pytest.mark.parametrize("during", ["copy 2", "page delay"])
def test_sigkill_in_a_later_copy_resumes_in_that_copy(tmp_path: Path, device: Device,
                                                      during: str) -> None:
    """Copies: a crash in the second copy, or in the page delay before it, resumes in the
    second copy; nothing of the first is drawn again and no third copy follows."""
    job, steps_plan = plan()
    d = DaemonProc(tmp_path, device.link, "first")
    j = d.client.submit(SQUARE.read_bytes(), "square.gcode",
                        plot_options(confirm=True, copies=2, page_delay_s=3.0))
    if during == "copy 2":
        seen = wait_segments(d.client, j["id"], 40, copy=2)
        assert (seen["copy_number"], seen["state"]) == (2, "running"), seen
    else:
        seen = wait_segments(d.client, j["id"], job.n_segments)
        assert (seen["copy_number"], seen["state"]) == (1, "running"), seen
    kill(d)
    held = restart_and_finish(tmp_path, device, j["id"])
    rp = held["resume"]
    assert rp is not None and rp["position"] is not None and rp["copy_number"] == 2, held
    assert "of copy 2 of 2" in held["message"], held
    if during == "page delay":
        assert rp["next_segment"] == 0 and "copy 1 of 2 was finished" in held["message"]
    assert rp["position"] == job.steps[rp["next_segment"]].tolist()
    led = device.ledger()
    assert led["steps_abs"] == (2 * steps_plan).tolist(), (led, steps_plan)
    assert led["partial_blocks"] == 0 and led["blocks"] == 2 * job.n_segments
    assert led["boots"] == 1


def test_sigterm_stops_at_a_segment_boundary_and_resumes(tmp_path: Path,
                                                         device: Device) -> None:
    job, steps_plan = plan()
    d = DaemonProc(tmp_path, device.link, "first")
    j = d.client.submit(SQUARE.read_bytes(), "square.gcode",
                        plot_options(laser=True, confirm=True))
    wait_segments(d.client, j["id"], 40)
    t0 = time.monotonic()
    code = d.stop(signal.SIGTERM)
    assert code == 0, d.log_text()
    assert time.monotonic() - t0 < 15
    log = d.log_text()
    assert "SIGTERM: stopping" in log and "stopped for shutdown" in log, log
    held = restart_and_finish(tmp_path, device, j["id"])
    rp = held["resume"]
    assert rp is not None and "told to stop" in held["message"]
    # a segment boundary: the position is the start of the next segment
    assert rp["position"] == job.steps[rp["next_segment"]].tolist()
    led = device.ledger()
    assert led["steps_abs"] == steps_plan.tolist(), (led, steps_plan)
    assert led["partial_blocks"] == 0 and led["laser_now"] == 0
    assert led["boots"] == 1


def test_sigkill_with_a_reset_controller_asks_for_home(tmp_path: Path) -> None:
    """The mock inside the daemon dies with it: the restarted daemon meets a freshly booted
    controller (line counter 0, position unknown), as after an Arduino's reset on open."""
    job, _ = plan()
    d = DaemonProc(tmp_path, "fivebar-mock://?speed=2", "first")
    j = d.client.submit(SQUARE.read_bytes(), "square.gcode", plot_options(confirm=True))
    wait_segments(d.client, j["id"], 40)
    saved_progress(tmp_path, j["id"])
    seen = d.client.job(j["id"])
    os.kill(d.proc.pid, signal.SIGKILL)
    d.proc.wait(10)
    d.log.close()
    d2 = DaemonProc(tmp_path, "fivebar-mock://?speed=2", "second")
    try:
        deadline = time.monotonic() + 30
        while (held := d2.client.job(j["id"]))["state"] == "running":
            assert time.monotonic() < deadline, d2.log_text()
            time.sleep(0.05)
        assert held["state"] == "held", held
        rp = held["resume"]
        # conservative: the last segment the daemon saw finish, position unknown
        assert rp["position"] is None and 0 < rp["next_segment"] <= seen["segments_done"] + 20
        assert "home the machine" in held["message"]
        assert d2.client.status()["machine"]["pose_known"] is False
        # resuming without homing first asks (nothing moves); home, then it finishes
        d2.client.resume(j["id"])
        again = follow(d2.client, j["id"], lambda x: None, max_s=30)
        assert again["state"] == "held" and "home pose" in (again["question"] or "")
        d2.client.home(at_home=True)
        d2.client.resume(j["id"])
        done = follow(d2.client, j["id"], lambda x: None, max_s=60)
        assert done["state"] == "done", (done, d2.log_text())
        assert done["segments_done"] == job.n_segments
    finally:
        d2.stop(signal.SIGTERM)
