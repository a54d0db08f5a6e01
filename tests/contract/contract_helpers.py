"""Helpers shared by the protocol contract tests (test_*.py in this folder).

Polling the status, collecting replies, checking that nothing was executed, the
DTR reset and filling the queue: used on the mock and the firmware alike.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest
from contract_devices import Device

from fivebar_host.protocol import ErrorReply, Message, Ok, StatusReport

#: Boot values of the settings, docs/protocol.md section 8.
DOC_DEFAULTS = [20000, -100000, 100000, -100000, 100000, 1, 2000, 0, 2000, 100, 0, 0, 20000, 0,
                0]


def poll(dev: Device, until: Callable[[StatusReport], bool], timeout: float = 10.0,
         what: str = "the expected state") -> StatusReport:
    """Poll ``?`` until ``until(report)``; fail with the last report after ``timeout``."""
    deadline = time.monotonic() + timeout
    report = dev.session.status()
    while not until(report):
        if time.monotonic() > deadline:
            pytest.fail(f"{dev.kind}: never reached {what}; last status {report}")
        time.sleep(0.002)
        report = dev.session.status()
    return report


def idle(dev: Device) -> StatusReport:
    """Wait until Idle with an empty queue."""
    return poll(dev, lambda r: r.state == "Idle" and r.queued == 0, what="Idle")


def replies_to(dev: Device, data: bytes, count: int) -> list[Message]:
    """Write ``data`` at once and collect ``count`` replies plus anything between them."""
    dev.port.write(data)
    got: list[Message] = []
    while sum(isinstance(m, Ok | ErrorReply) for m in got) < count:
        got.append(dev.session.read_message())
    return got


def assert_nothing_executed(dev: Device) -> None:
    """No motion, no laser; the device still answers."""
    report = dev.session.status()
    assert (report.state, report.a, report.b, report.queued, report.laser) == (
        "Idle", 0, 0, 0, 0)
    assert dev.session.send("M110") == Ok()  # accepted in any mode; ends numbered mode
    assert dev.session.send("$I") == Ok()
    done = dev.executed()
    assert done.steps == (0, 0), f"{dev.kind}: motors stepped after refused input"
    assert done.laser_periods == 0



def dtr_reset(dev: Device) -> None:
    """Pulse DTR as ``Link.hardware_reset`` does (an Uno's auto-reset) and read the banner."""
    dev.port.dtr = False
    dev.port.dtr = True
    assert dev.session.wait_banner() == dev.banner



def fill_queue(dev: Device, p_us: int = 1_000_000, first_us: int = 10_000_000) -> int:
    """Take every queue slot with dwells (streamed: fast); return the lines sent.

    The banner's ``queue:`` counts the block executing as well: once one runs,
    ``queue - 1`` wait (``Q:`` counts only those).  The queue stays full until the first
    dwell ends, which the tests' next steps rely on: both devices run about ten times
    faster than real time, so a 1 s first dwell left ~0.1 s of wall clock, and a busy
    machine stalling the test that long let it end early (CI saw ``Q:14``, line 2 done).
    The first dwell lasts ``first_us`` (~1 s of wall clock) instead.
    """
    n = dev.banner.queue
    lines = [f"G1 P{first_us}"] + [f"G1 P{p_us}"] * (n - 1)
    assert dev.session.stream(lines) == [Ok()] * n
    r = dev.session.status()
    assert (r.state, r.queued, r.done_line) == ("Run", n - 1, 0), r  # (what it was, if not)
    return n

