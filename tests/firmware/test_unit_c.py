"""Host-side builds of the firmware: C unit tests, fuzz-corpus replay, Arduino core."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from fivebar_host.devices.sim import firmware_dir


def run_make(target: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["make", "-s", "-C", str(firmware_dir()), target],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )


def test_c_unit_tests_pass() -> None:
    proc = run_make("test")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert " 0 failed" in proc.stdout


def test_fuzz_corpus_replays_without_crash() -> None:
    proc = run_make("replay")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "replayed" in proc.stdout


ARDUINO_CORE = Path("/usr/share/arduino/hardware/arduino/avr/cores/arduino")


def test_sketch_builds_against_the_arduino_core() -> None:
    """The sketch compiles and links with Debian's Arduino core, as in the IDE."""
    if shutil.which("avr-gcc") is None:
        pytest.skip("avr-gcc not installed (apt-get install gcc-avr avr-libc)")
    if not ARDUINO_CORE.is_dir():
        pytest.skip("Arduino core not installed (apt-get install arduino-core-avr)")
    proc = run_make("arduino")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Program:" in proc.stdout
