"""Fixtures of the protocol contract suite: one device interface over two implementations.

Every test of this folder runs twice: against the Python mock
(``fivebar-mock://``, fivebar_host/devices/mock/) and against the real firmware running
in simavr (fivebar_host/devices/sim.py).  A test sees a ``Device``: the open port, a
``FirmwareSession`` on it, and ``executed()`` — what the motors and the laser really did,
from the mock's ledger or from the emulator's recorded pin trace.  The sim
parametrization skips, naming the reason, only when the AVR toolchain or simavr is
missing (CI installs them); a failing build is an error.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from contract_devices import Device, Endstops, open_mock, open_sim


@pytest.fixture(params=["mock", pytest.param("sim", marks=pytest.mark.sim)])
def device_kind(request: pytest.FixtureRequest) -> str:
    """Which implementation the test runs against."""
    return str(request.param)


@pytest.fixture
def open_device(
    device_kind: str, request: pytest.FixtureRequest, tmp_path: Path
) -> Iterator[Callable[..., Device]]:
    """Factory: boot a device, optionally with endstops at physical positions (A, B)."""
    started: list[Device] = []

    def start(endstops: Endstops = (None, None)) -> Device:
        if device_kind == "sim":
            request.getfixturevalue("sim_build")  # built once; skips without the toolchain
            dev = open_sim(tmp_path / f"pins{len(started)}.trace", endstops)
        else:
            dev = open_mock(endstops)
        started.append(dev)
        return dev

    yield start
    for dev in started:
        dev.close()


@pytest.fixture
def device(open_device: Callable[..., Device]) -> Device:
    """A booted device without endstops."""
    return open_device()
