"""The bridge's machine thread outlives a batch the wire cannot write: a program item out of
the protocol's range (a `ProtocolError` while writing its line) stops the machine (laser
off), tells the GRBL side why, and the next batch runs as usual — before, the error ended
the thread and the bridge hung with every later line unanswered."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from fivebar_host.bridge.machine import MachineDriver
from fivebar_host.compile.incremental import Batch
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.program import Program
from fivebar_host.wire import P_MAX_US


def wait(cond: Callable[[], bool], what: str, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.01)
    raise AssertionError(f"timed out waiting for {what}")


def test_a_batch_the_wire_refuses_is_a_fault_and_the_thread_goes_on() -> None:
    link = Link.open("fivebar-mock://?speed=0")
    faults: list[tuple[str, int | None]] = []
    seen = threading.Event()

    def on_fault(msg: str, code: int | None) -> None:
        faults.append((msg, code))
        seen.set()

    m = MachineDriver(link, on_fault)
    m.start()
    try:
        good = Program.moves([10], [-10], [2000], 0, 0)
        bad = Program.moves([20], [-20], [P_MAX_US + 1], 0, 1)  # P beyond the protocol
        m.submit(Batch(bad, 1.0, (20, -20), moves=1))
        assert seen.wait(10.0), "no fault reported"
        assert "refused by the host" in faults[0][0] and "P" in faults[0][0], faults
        assert m.thread.is_alive()
        assert m.status.laser == 0
        m.submit(Batch(good, 0.002, (10, -10), moves=1))
        wait(lambda: m.idle and (m.status.a, m.status.b) == (10, -10), "the next batch")
    finally:
        m.close()
        link.close()
