"""The emulated machine between commands, as a real one: its controller stays powered (its
RAM, so its position and last line, are kept across the DTR reset of the next port open)
and its arms stay where they stopped. Before, every `fivebar-sim://` command started a new
machine at home, so a resume after a fault asked whether the arms were still where the job
stopped, and the natural "yes" drew ~99 mm off with exit 0. Each command here is its own
process, as on a terminal."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def fivebar(*args: str, state: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "FIVEBAR_SIM_STATE": str(state)}
    return subprocess.run([sys.executable, "-c", "from fivebar_host.cli import main; main()",
                           *args], capture_output=True, text=True, env=env, timeout=300,
                          check=False)


@pytest.fixture
def drawing(tmp_path: Path, sim_build: object) -> Path:
    svg = tmp_path / "simple.svg"
    shutil.copy(ROOT / "examples" / "simple.svg", svg)
    return svg


def test_a_resume_in_the_next_command_is_exact(drawing: Path, tmp_path: Path) -> None:
    state = tmp_path / "state"
    first = fivebar("plot", str(drawing), "--port", "fivebar-sim://?disconnect_after=40",
                    "--yes", state=state)
    assert first.returncode != 0 and "--resume" in first.stdout + first.stderr
    assert (state / "default-firmware.state").exists()
    second = fivebar("plot", str(drawing), "--port", "fivebar-sim://", "--yes", "--resume",
                     state=state)
    assert second.returncode == 0, second.stdout + second.stderr
    assert "resume point read from the controller" in second.stdout
    assert "lost power" not in second.stdout + second.stderr
    status = fivebar("status", "--port", "fivebar-sim://", state=state)
    assert "position unknown" not in status.stdout  # still homed, a command later


def test_a_power_loss_happens_only_when_asked(drawing: Path, tmp_path: Path) -> None:
    state = tmp_path / "state"
    fivebar("plot", str(drawing), "--port", "fivebar-sim://?disconnect_after=40", "--yes",
            state=state)
    lost = fivebar("plot", str(drawing), "--port", "fivebar-sim://?power_loss=1", "--yes",
                   "--resume", state=state)
    assert lost.returncode == 3
    assert "lost power" in lost.stderr and "Nothing was sent" in lost.stderr
    fresh = fivebar("status", "--port", "fivebar-sim://?fresh=1", state=state)
    assert "A = 0 steps, B = 0 steps (position unknown" in fresh.stdout
