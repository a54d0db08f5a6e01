"""The device interface of the contract suite: a booted mock or emulated firmware.

Kept out of conftest.py so test modules can import ``Device`` for their type hints.
"""

from __future__ import annotations

import itertools
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import serial

from fivebar_host.devices import urls
from fivebar_host.devices.mock import MockSerial
from fivebar_host.devices.sim import FirmwareSession
from fivebar_host.devices.simport import Serial as SimSerial
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.protocol import Banner

Endstops = tuple[int | None, int | None]

#: Motion speed of the mock: about as much faster than real time as the unthrottled emulator.
MOCK_SPEED = 10


@dataclass(frozen=True)
class Executed:
    """What the device physically did, from step pulses and the laser output."""

    steps: tuple[int, int]  # step pulses issued per motor (either direction)
    net: tuple[int, int]  # signed sum of the steps per motor
    laser_on_s: float  # time the laser output was on, in device seconds
    laser_periods: int  # separate laser-on periods


class Device:
    """A booted device (banner read) under test: mock or emulated firmware.

    Both are named machines (``machine=`` of their URL), so ``port.dtr`` and
    ``port.machine.power_cut()`` work alike on both: a reset that keeps the RAM, a power-on.
    """

    def __init__(self, kind: str, port: Any) -> None:
        self.kind = kind
        self.port = port
        self.session = FirmwareSession(port, timeout=10.0)
        self.session.wait_banner()
        assert self.session.banner is not None
        self.banner: Banner = self.session.banner

    def power_cut(self) -> None:
        """Cut the controller's power and read the banner of its power-on boot."""
        self.port.machine.power_cut()
        self.session.wait_banner()

    def executed(self) -> Executed:
        """Stop the device and return what it executed (call once, at the end of a test)."""
        if self.kind == "sim":
            machine = self.port.machine
            machine.stop()
            trace = read_trace(machine.trace_path)
            steps = tuple(trace.steps(axis) for axis in ("A", "B"))
            intervals = trace.laser_intervals()
            return Executed(
                (len(steps[0]), len(steps[1])),
                (sum(s.direction for s in steps[0]), sum(s.direction for s in steps[1])),
                sum(e - s for s, e in intervals) / trace.freq,
                len(intervals),
            )
        ledger = self.port.ledger
        self.port.close()
        laser_log = self.port.machine.laser_log
        periods = sum(1 for (_, p0), (_, p1) in itertools.pairwise(laser_log)
                      if p0 == 0 and p1 > 0)
        return Executed(
            (sum(abs(e.steps[0]) for e in ledger), sum(abs(e.steps[1]) for e in ledger)),
            (sum(e.steps[0] for e in ledger), sum(e.steps[1] for e in ledger)),
            sum(e.duration_us * e.fraction for e in ledger if e.kind == "G1" and e.power)
            / 1e6,
            periods,
        )

    def close(self) -> None:
        """Release the port / stop the emulator (idempotent)."""
        machine = self.port.machine if self.kind == "sim" else None
        self.port.close()
        if machine is not None:
            machine.stop()


def _endstops_option(endstops: Endstops) -> str:
    if endstops == (None, None):
        return ""
    return "&endstops=" + ",".join("" if e is None else str(e) for e in endstops)


def open_mock(endstops: Endstops = (None, None)) -> Device:
    """Boot ``fivebar-mock://`` (through pyserial's URL lookup) as its own named machine and
    read its banner."""
    urls.register()
    url = f"fivebar-mock://?speed={MOCK_SPEED}&machine=contract-{uuid.uuid4().hex}"
    port = serial.serial_for_url(url + _endstops_option(endstops), timeout=0.5)
    assert isinstance(port, MockSerial)
    return Device("mock", port)


def open_sim(trace: Path, endstops: Endstops = (None, None)) -> Device:
    """Boot the firmware in simavr as a named machine of ``fivebar-sim://``, recording its pins
    to ``trace``, and read its banner."""
    urls.register()
    url = f"fivebar-sim://?machine=contract-{uuid.uuid4().hex}&trace={trace}"
    port = serial.serial_for_url(url + _endstops_option(endstops), timeout=0.5)
    assert isinstance(port, SimSerial)
    return Device("sim", port)
