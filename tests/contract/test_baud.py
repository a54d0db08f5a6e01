"""`$B=<baud>` (docs/protocol.md 1.1) on both implementations: the switch after its `ok`, a
rate kept once the host speaks it, the fallback to 115200 when it does not within 1 s, the
return to 115200 on Ctrl-X, and the rates the Uno cannot make refused.

Both devices model the line's rate: the emulator's harness compares the pty's speed with
the UART's (UBRR0/U2X0) and the mock its port's `baudrate` with its own; at different rates
every byte is lost both ways.
"""

from __future__ import annotations

import time

import pytest
from contract_devices import Device

from fivebar_host import protocol
from fivebar_host.protocol import ErrorReply, Ok


def silent_for(device: Device, seconds: float) -> bool:
    """Whether nothing at all arrives within `seconds`."""
    time.sleep(seconds)
    return device.port.in_waiting == 0


def info(device: Device) -> None:
    """`$I` at the port's rate brings the banner, then `ok`."""
    device.port.write(b"$I\n")
    assert device.session.read_message() == device.banner
    assert device.session.read_reply() == Ok()


@pytest.mark.parametrize("baud", [250000, 500000, 1000000])
def test_the_rate_is_kept_once_the_host_speaks_it(device: Device, baud: int) -> None:
    port, s = device.port, device.session
    assert s.send(f"$B={baud}") == Ok()  # answered at 115200, then the switch
    port.baudrate = baud
    info(device)
    assert silent_for(device, 1.5)  # no fallback banner, no reply: nothing changed
    info(device)  # still at the new rate after the trial second
    status = s.status()
    assert status.state == "Idle"
    port.write(protocol.RT_RESET)  # Ctrl-X: back to 115200 (the banner may be lost)
    port.flush()
    time.sleep(0.05)
    port.baudrate = protocol.BASE_BAUD
    time.sleep(0.05)
    port.reset_input_buffer()
    info(device)


def test_the_firmware_falls_back_when_the_host_never_speaks_the_new_rate(
        device: Device) -> None:
    port, s = device.port, device.session
    assert s.send("$B=1000000") == Ok()
    port.write(b"$I\n")  # still at 115200: lost on the wire, no reply
    assert silent_for(device, 0.3)
    time.sleep(1.2)  # the trial second is over: the firmware is back at 115200
    info(device)
    assert s.send("G90") == Ok()


def test_rates_the_uno_cannot_make_are_refused(device: Device) -> None:
    s = device.session
    for bad in (9600, 115201, 230400, 2000000, 0, -115200):
        assert s.send(f"$B={bad}") == ErrorReply(7), bad
    assert s.send("$B") == ErrorReply(4)
    assert s.send("$B=5x") == ErrorReply(5)
    assert s.send("$B=500000 1") == ErrorReply(5)
    assert silent_for(device, 1.2)
    info(device)  # every refusal left the link at 115200
