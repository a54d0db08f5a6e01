"""Fixtures for the firmware tests: build once per session, one emulator per test.

Tests that need the AVR toolchain skip (with the reason) only when avr-gcc is
missing; CI installs it (apt-get install gcc-avr avr-libc simavr
libsimavr-dev libelf-dev), so there they run.  Any other build problem is an
error, not a skip.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from fivebar_host.devices import sim
from fivebar_host.devices.sim import SimDevice


@pytest.fixture(scope="session")
def build() -> sim.BuildPaths:
    """Firmware .elf/.hex and the simavr harness, built once per session."""
    if shutil.which("avr-gcc") is None:
        pytest.skip(f"avr-gcc not installed (apt-get install {sim.APT_PACKAGES})")
    return sim.ensure_built()


@pytest.fixture
def start_device(build: sim.BuildPaths, tmp_path: Path) -> Iterator[Callable[..., SimDevice]]:
    """Factory: start the firmware (optionally with simulated endstops).

    ``realtime=True`` throttles emulation to wall-clock speed, so a test that
    streams a job is not at the mercy of how fast Python runs on a busy machine.
    """
    started: list[SimDevice] = []

    def start(
        endstop_a: int | None = None, endstop_b: int | None = None, realtime: bool = False
    ) -> SimDevice:
        trace = tmp_path / f"fw{len(started)}.trace"
        dev = sim.start_device(build, trace, endstop_a, endstop_b, realtime=realtime)
        started.append(dev)
        return dev

    yield start
    for dev in started:
        dev.close()


@pytest.fixture
def device(start_device: Callable[..., SimDevice]) -> SimDevice:
    """The firmware, booted, banner read, no endstops."""
    return start_device()
