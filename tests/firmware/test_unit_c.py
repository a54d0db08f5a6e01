"""Run the firmware's C unit tests and the fuzz-corpus replay (host gcc only)."""

from __future__ import annotations

import subprocess

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
