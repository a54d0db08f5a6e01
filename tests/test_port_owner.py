"""One owner per port (`fivebar_host.controllers.ports`): a second opener is refused before it
opens the device or writes a byte, naming the owner; a stale lock is taken over with a note.

The end-to-end cases run `fivebar plot` and `fivebar serve` as processes against the mock
served on a pseudo-terminal (`server.ptydevice`), which records every byte it received: a
refused command must have added none.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.controllers import ports
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.devices import mock
from fivebar_host.server.client import ServerClient, follow, plot_options

ROOT = Path(__file__).resolve().parent.parent
SQUARE = ROOT / "examples" / "square.gcode"
CLI = [sys.executable, "-c", "from fivebar_host.cli import main; main()"]


@pytest.fixture
def lock_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    d = tmp_path / "locks"
    d.mkdir()
    monkeypatch.setenv("FIVEBAR_LOCK_DIR", str(d))
    return d


@pytest.fixture
def pty_device() -> Iterator[str]:
    """A pty slave's path (a device node nobody else uses)."""
    master, slave = os.openpty()
    try:
        yield os.ttyname(slave)
    finally:
        os.close(slave)
        os.close(master)


def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


# ------------------------------------------------------------------ the lock itself
def test_the_lock_file_names_the_owner_and_goes_with_it(lock_dir: Path, pty_device: str
                                                         ) -> None:
    with ports.hold_port(pty_device, "fivebar flash", "wait for the upload") as held:
        assert held.path is not None and held.path.parent == lock_dir
        assert held.path.name == "LCK.." + pty_device.removeprefix("/dev/").replace("/", "_")
        text = held.path.read_text()
        assert text.splitlines()[0] == f"{os.getpid():>10d}"  # uucp's PID line
        owner = ports.owner_of(pty_device)
        assert owner is not None and owner.pid == os.getpid()
        assert owner.command == "fivebar flash" and owner.hint == "wait for the upload"
        with pytest.raises(ports.PortBusyError, match=r"held by `fivebar flash` \(pid \d+\)"
                           r" since .*; wait for the upload"):
            ports.hold_port(pty_device, "fivebar plot")
    assert not held.path.exists()
    assert ports.owner_of(pty_device) is None
    ports.hold_port(pty_device).release()


def test_a_symlink_is_the_device_it_points_at(lock_dir: Path, pty_device: str,
                                              tmp_path: Path) -> None:
    link = tmp_path / "tty"
    link.symlink_to(pty_device)
    with ports.hold_port(str(link), "fivebar serve"), pytest.raises(ports.PortBusyError):
        ports.hold_port(pty_device)


def test_a_stale_lock_is_taken_over_with_a_note(lock_dir: Path, pty_device: str) -> None:
    path = ports.lock_path(Path(pty_device))
    gone = dead_pid()
    path.write_text(f"{gone:>10d}\ncommand=fivebar serve\nsince=2020-01-01 00:00:00\n")
    with ports.hold_port(pty_device, "fivebar plot") as held:
        assert held.note is not None
        assert f"stale lock ({path}) of `fivebar serve` pid {gone}" in held.note
        assert ports.parse_lock(path.read_text()) == ports.Owner(
            os.getpid(), "fivebar plot", held.owner.since)


def test_another_programs_lock_file_is_respected_while_its_pid_lives(
        lock_dir: Path, pty_device: str) -> None:
    path = ports.lock_path(Path(pty_device))
    path.write_text(f"{os.getppid():>10d}\n")  # minicom's format: the PID only
    with pytest.raises(ports.PortBusyError, match=f"held by pid {os.getppid()}"):
        ports.hold_port(pty_device)
    path.write_text(f"{dead_pid():>10d}\n")
    with ports.hold_port(pty_device) as held:
        assert held.note is not None and "stale lock" in held.note


def test_a_holder_in_another_process_is_named_and_its_death_frees_the_port(
        lock_dir: Path, pty_device: str) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom fivebar_host.controllers import ports\n"
         f"ports.hold_port({pty_device!r}, 'fivebar serve', 'use --server URL')\n"
         "print('held', flush=True)\ntime.sleep(60)"],
        stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        with pytest.raises(ports.PortBusyError) as e:
            ports.hold_port(pty_device, "fivebar plot")
        assert f"`fivebar serve` (pid {holder.pid})" in str(e.value)
        assert "use --server URL" in str(e.value)
        holder.kill()  # SIGKILL: the file stays, its flock goes
        holder.wait(10)
        with ports.hold_port(pty_device) as held:
            assert held.note is not None and f"pid {holder.pid}" in held.note
    finally:
        holder.kill()
        holder.wait(10)


def test_named_url_machines_are_one_port_unnamed_ones_are_not() -> None:
    url = "fivebar-mock://?machine=owner-test"
    try:
        first = Link.open(url, banner_timeout_s=1.0)
        with pytest.raises(ports.PortBusyError, match="held by"):
            Link.open(url, banner_timeout_s=1.0)
        first.close()
        Link.open(url, banner_timeout_s=1.0).close()  # free again
        a = Link.open("fivebar-mock://", banner_timeout_s=1.0)
        b = Link.open("fivebar-mock://", banner_timeout_s=1.0)
        a.close()
        b.close()
    finally:
        mock.forget_machines()
    assert ports.port_key("fivebar-sim://?realtime=1") is None
    key = ports.port_key("fivebar-sim://?machine=a&realtime=1")
    assert key is not None and key.device is None


# ------------------------------------------------------------------ commands as processes
class Device:
    """The mock machine on a pty, in its own process, recording the bytes it receives."""

    def __init__(self, tmp: Path, speed: float) -> None:
        self.link = tmp / "tty"
        self.ledger_path = tmp / "ledger.json"
        self.record = tmp / "received.bin"
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "fivebar_host.server.ptydevice", "--url",
             f"fivebar-mock://?speed={speed}", "--link", str(self.link), "--ledger",
             str(self.ledger_path), "--record", str(self.record)],
            stdout=subprocess.PIPE, text=True, cwd=ROOT)
        assert self.proc.stdout is not None
        assert self.proc.stdout.readline().startswith("PTY ")

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


@pytest.fixture
def device(tmp_path: Path) -> Iterator[Device]:
    dev = Device(tmp_path, speed=2.0)
    yield dev
    dev.close()


def wait_held(url: str, timeout_s: float = 60.0) -> ports.Owner:
    deadline = time.monotonic() + timeout_s
    while (owner := ports.owner_of(url)) is None:
        assert time.monotonic() < deadline, f"nobody took {url}"
        time.sleep(0.02)
    return owner


def square_steps() -> tuple[int, list[int]]:
    import numpy as np

    job = compile_job(SQUARE, load_profile(None), CompileOptions())
    return job.n_segments, np.abs(np.diff(job.steps, axis=0)).sum(axis=0).tolist()


def test_two_plots_on_one_port_the_second_is_refused_before_writing(device: Device) -> None:
    first = subprocess.Popen([*CLI, "plot", str(SQUARE), "--port", str(device.link), "--yes"],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             cwd=ROOT)
    owner = wait_held(str(device.link))
    assert owner.pid == first.pid and owner.command == "fivebar plot"
    second = subprocess.run([*CLI, "plot", str(SQUARE), "--port", str(device.link), "--yes"],
                            capture_output=True, text=True, cwd=ROOT, timeout=60)
    out, _ = first.communicate(timeout=120)
    assert first.returncode == 0, out
    assert second.returncode == 3, second.stderr
    assert f"held by `fivebar plot` (pid {first.pid}) since" in second.stderr
    assert "nothing was sent" in second.stderr
    assert "job:" not in second.stdout  # refused before compiling, too
    received = device.record.read_bytes()
    ledger = device.ledger()
    n, steps = square_steps()
    # the first finished exactly: every segment whole, the planned steps, home again
    assert ledger["blocks"] >= n and ledger["partial_blocks"] == 0
    assert ledger["steps_abs"] == steps and ledger["position"] == [0, 0]
    # one host only ever wrote: one handshake, all the bytes the device received
    assert received.count(b"$I") == 1 and ledger["bytes_in"] == len(received)


def test_a_plot_on_the_daemons_port_is_refused_and_the_job_unharmed(
        device: Device, tmp_path: Path) -> None:
    ready = tmp_path / "ready"
    log = (tmp_path / "serve.log").open("w")
    daemon = subprocess.Popen(
        [*CLI, "serve", "--port", str(device.link), "--listen", "127.0.0.1:0", "--state-dir",
         str(tmp_path / "state"), "--banner-timeout", "0.6", "--ready-file", str(ready)],
        stdout=log, stderr=subprocess.STDOUT, cwd=ROOT)
    try:
        deadline = time.monotonic() + 30
        while not ready.exists():
            assert daemon.poll() is None and time.monotonic() < deadline
            time.sleep(0.02)
        url = ready.read_text().strip()
        client = ServerClient(url)
        owner = wait_held(str(device.link))
        assert owner.pid == daemon.pid and owner.command == "fivebar serve"
        job = client.submit(SQUARE.read_bytes(), "square.gcode", plot_options(confirm=True))
        while client.job(job["id"])["segments_done"] < 20:
            time.sleep(0.02)
        plot = subprocess.run([*CLI, "plot", str(SQUARE), "--port", str(device.link), "--yes"],
                              capture_output=True, text=True, cwd=ROOT, timeout=60)
        assert plot.returncode == 3, plot.stderr
        assert f"held by `fivebar serve` (pid {daemon.pid})" in plot.stderr
        assert f"use `fivebar plot --server {url}`" in plot.stderr
        done = follow(client, job["id"], lambda j: None, max_s=60)
        assert done["state"] == "done" and done["segments_done"] == done["segments_total"]
    finally:
        daemon.send_signal(signal.SIGTERM)
        daemon.wait(60)
        log.close()
    received = device.record.read_bytes()
    ledger = device.ledger()
    assert received.count(b"$I") == 1 and ledger["partial_blocks"] == 0
    assert ledger["steps_abs"] == square_steps()[1]
