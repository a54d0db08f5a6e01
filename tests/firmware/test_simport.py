"""`fivebar-sim://` options of fivebar_host/devices/simport.py on the real firmware: named
machines that outlive their port (a reopen is a DTR reset that keeps the firmware's RAM),
DTR edges, power cuts, and the line-counted faults."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import serial

from fivebar_host.devices import sim, simport, urls
from fivebar_host.devices.sim import FirmwareSession
from fivebar_host.protocol import Ok, SettingLine, StatusReport

pytestmark = pytest.mark.sim


@pytest.fixture(autouse=True)
def _machines(build: sim.BuildPaths) -> Iterator[None]:
    """Built firmware (skips without the toolchain); no machine left over before or after."""
    urls.register()
    simport.forget_machines()
    yield
    simport.forget_machines()


def open_url(url: str) -> tuple[Any, FirmwareSession]:
    """Open a port and read its banner."""
    port = serial.serial_for_url(url, timeout=0.5)
    session = FirmwareSession(port, timeout=5.0)
    session.wait_banner()
    return port, session


def where(s: FirmwareSession) -> tuple[str, int, int, bool, int, int]:
    r: StatusReport = s.status()
    return (r.state, r.a, r.b, r.homed, r.done_line, r.accepted_line)


def test_a_named_machine_outlives_its_port(tmp_path: Path) -> None:
    trace = tmp_path / "pins.trace"
    port, s = open_url(f"fivebar-sim://?machine=m&trace={trace}")
    assert port.trace_path is None and simport.machine("m").trace_path == trace
    assert s.stream(["G92 A10 B20", "G1 A50 P10000"]) == [Ok(), Ok()]
    assert s.wait_idle().a == 50
    with pytest.raises(serial.SerialException, match="busy"):
        serial.serial_for_url("fivebar-sim://?machine=m")
    port.close()
    with pytest.raises(serial.SerialException, match="cannot change"):
        serial.serial_for_url("fivebar-sim://?machine=m&realtime=1")
    port, s = open_url(f"fivebar-sim://?machine=m&trace={trace}")  # DTR reset: RAM kept
    assert where(s) == ("Idle", 50, 20, True, 2, 0)
    port.dtr = False
    port.dtr = True
    s.wait_banner()
    assert where(s) == ("Idle", 50, 20, True, 2, 0)
    assert len(simport.machine("m").trace().steps("A")) == 40  # read while it runs
    simport.machine("m").power_cut()
    s.wait_banner()
    assert where(s) == ("Idle", 0, 0, False, 0, 0)
    port.close()
    simport.forget_machines()
    with pytest.raises(KeyError):
        simport.machine("m")
    assert trace.read_text().count("stepA 1") == 40  # the trace stays


def test_faults_fire_after_their_line() -> None:
    port, s = open_url("fivebar-sim://?machine=f&reset_after=2")
    assert s.send("G92 A7 B7") == Ok()
    s.wait_idle()
    port.write(b"$0=100\n$0=200\n")  # the reset after line 2; line 3 is lost
    s.wait_banner()
    assert where(s) == ("Idle", 7, 7, True, 1, 0)
    assert s.send("$$") == Ok() and SettingLine(0, 20000) in s.messages  # boot settings
    port.close()

    port, s = open_url("fivebar-sim://?machine=f&stall_after=1")
    assert s.send("G90") == Ok()  # the line reached the firmware before it hung
    port.write(b"?")  # lost: the firmware spins with interrupts off
    s.wait_banner()  # its watchdog reset it (about 256 ms of emulated time)
    assert not [m for m in s.messages if isinstance(m, StatusReport)]  # no status
    assert where(s) == ("Idle", 7, 7, True, 1, 0)  # the record survived
    trace = simport.machine("f").trace()
    (hang, _), = trace.pin("hang")
    (wdt, _), = trace.pin("wdt")
    assert 0.9 * 0.256 <= (wdt - hang) / trace.freq <= 0.26
    port.close()

    port, s = open_url("fivebar-sim://?machine=f&power_cut_after=1")
    port.write(b"G90\n")
    s.wait_banner()
    assert where(s) == ("Idle", 0, 0, False, 0, 0)
    port.close()

    port, s = open_url("fivebar-sim://?machine=f&disconnect_after=1")
    with pytest.raises(serial.SerialException, match="disconnect_after=1"):
        port.write(b"G92 A3 B4\nG90\n")
    for broken in (lambda: port.read(1), lambda: port.write(b"?"), lambda: port.in_waiting):
        with pytest.raises(serial.SerialException, match="disconnected"):
            broken()
    port.close()
    time.sleep(0.2)  # the firmware runs the line it got (the queue starts after 20 ms)
    port, s = open_url("fivebar-sim://?machine=f")
    assert where(s) == ("Idle", 3, 4, True, 1, 0)
    port.close()


def test_url_options_are_checked() -> None:
    for bad in ("fivebar-sim://?reset_after=0", "fivebar-sim://?stall_after=x",
                "fivebar-sim://?machine=", "fivebar-sim://?bogus=1",
                "fivebar-sim://?endstops=1"):
        with pytest.raises(serial.SerialException):
            serial.serial_for_url(bad)


def test_url_options_are_parsed_and_bad_ones_named() -> None:
    opts = simport.parse_sim_url("fivebar-sim://?machine=m&drop=0.01&corrupt=0.002&seed=5"
                                 "&reset_after=3")
    assert (opts.machine, opts.drop, opts.corrupt, opts.seed) == ("m", 0.01, 0.002, 5)
    assert opts.faults == {"reset_after": 3}
    for url, word in [("fivebar-sim://?drop=1.5", "drop"), ("fivebar-sim://?corrupt=x", "corrupt"),
                      ("fivebar-sim://?seed=-1", "seed"), ("fivebar-sim://?stall_after=0",
                                                          "stall_after"),
                      ("fivebar-sim://?speed=2", "unknown option 'speed'")]:
        with pytest.raises(ValueError, match=word):
            simport.parse_sim_url(url)
