"""Ctrl-C during a real-time plot on the emulator (`bash scripts/demo.sh`): the terminal's
SIGINT goes to the whole foreground process group. The emulator (fbsim) runs in its own
session, so only the host sees it: the host holds the machine and asks resume-or-abort
(without a terminal: abort), leaves a resume file and exits 3 — never "device gone" — and no
emulator outlives it."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fivebar_host.devices.sim import toolchain_missing

ROOT = Path(__file__).resolve().parents[1]

pytestmark = [
    pytest.mark.sim,
    pytest.mark.skipif(toolchain_missing() is not None,
                       reason=f"emulator unavailable: {toolchain_missing()}"),
]


def fbsim_children(pid: int) -> list[int]:
    """Processes whose parent is `pid` and whose command is the harness."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
            cmd = (d / "cmdline").read_bytes()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        if ppid == pid and b"fbsim" in cmd:
            out.append(int(d.name))
    return out


def test_sigint_to_the_process_group_reaches_the_hold_prompt(tmp_path: Path) -> None:
    drawing = tmp_path / "simple.svg"
    shutil.copy(ROOT / "examples" / "simple.svg", drawing)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", "from fivebar_host.cli import main; main()", "plot",
         str(drawing), "--port", "fivebar-sim://?realtime=1", "--yes", "--preview",
         str(tmp_path / "p.png")],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        env=env, start_new_session=True, cwd=tmp_path)  # its own group, like a terminal's job
    try:
        assert proc.stdout is not None
        seen = b""
        deadline = time.monotonic() + 60.0
        while b"plotting" not in seen:  # streaming has started
            assert time.monotonic() < deadline and proc.poll() is None, seen
            seen += proc.stdout.readline()
        time.sleep(1.5)  # mid-plot, in real time
        harness = fbsim_children(proc.pid)
        assert len(harness) == 1
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the terminal signals the whole group
        rest, _ = proc.communicate(timeout=60.0)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    out = (seen + rest).decode()
    assert "held: motion stopped, laser off." in out, out
    assert "device gone" not in out, out
    assert proc.returncode == 3, out
    assert (tmp_path / "simple.svg.fivebar-resume.json").exists()
    time.sleep(0.2)
    assert not Path(f"/proc/{harness[0]}").exists() or b"fbsim" not in Path(
        f"/proc/{harness[0]}/cmdline").read_bytes(), "the emulator outlived the host"
