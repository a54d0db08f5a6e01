"""Host-side builds of the firmware: C unit tests, fuzz-corpus replay, Arduino core."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from fivebar_host.devices.sim import firmware_dir


def run_make(target: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["make", "-s", "-C", str(firmware_dir()), target, *args],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )


def fast_summary(out: str) -> tuple[dict[str, int], int, int]:
    """The counts of tests/fast_tests.c's summary, its checks and failed checks."""
    line = re.search(r"^fast form: .*$", out, flags=re.M)
    assert line, out
    counts = {
        name: int(n) for n, name in re.findall(r"(\d+) (blocks|fast|refused|events|tiny|close|far)",
                                               line.group(0))
    }
    early = re.search(r"(\d+) of \d+ steps one tick", line.group(0))
    assert early, out
    counts["early"] = int(early.group(1))
    checks = re.search(r"^(\d+) checks, (\d+) failed$", out, flags=re.M)
    assert checks, out
    return counts, int(checks.group(1)), int(checks.group(2))


def test_c_unit_tests_pass() -> None:
    proc = run_make("test")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert " 0 failed" in proc.stdout


def test_fast_form_matches_the_dda_on_random_blocks() -> None:
    """tests/fast_tests.c: the fast form's one-event step (fb_fast.c) run over random
    blocks gives every step on the schedule and every pair the pick defines; the job
    covers refused blocks, pairs of each kind and steps the fraction's cut moves."""
    build = run_make("build/host/fast_tests")
    assert build.returncode == 0, build.stdout + build.stderr
    proc = subprocess.run([str(firmware_dir() / "build" / "host" / "fast_tests")],
                          capture_output=True, text=True, check=False, timeout=300)
    counts, checks, failed = fast_summary(proc.stdout)
    assert proc.returncode == 0 and failed == 0, proc.stdout
    assert checks > 1_000_000
    for kind in ("refused", "tiny", "close", "far", "early"):
        assert counts[kind] > 0, (kind, proc.stdout)


@pytest.mark.parametrize("mutant", [1, 2])
def test_fast_form_test_fails_on_a_broken_fast_form(mutant: int) -> None:
    """The same test against fb_fast.c built with one deliberate fault
    (-DFB_FAST_MUTANT, see fb_fast.c: 1 the pick's pair bound off by one, 2 the
    fraction's carry dropped) builds, runs and reports failed checks."""
    proc = run_make("fast-mutant", f"MUTANT={mutant}")
    assert proc.returncode != 0, proc.stdout
    _, checks, failed = fast_summary(proc.stdout)
    assert checks > 0 and failed > 0, proc.stdout + proc.stderr
    assert "FAIL tests/fast_tests.c" in proc.stdout


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
