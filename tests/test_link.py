"""The link against the mock: a device that was not reset on open, a hung one rebooted,
another protocol version."""

from __future__ import annotations

import pytest
import serial

from fivebar_host import protocol
from fivebar_host.devices import urls
from fivebar_host.link import FirmwareMismatchError, Link, LinkFaultError
from fivebar_host.protocol import Banner


def test_handshake_with_a_device_left_in_numbered_mode() -> None:
    """A second session on a port that was not reset (no DTR) meets strict framing: its
    unnumbered ``$I`` is refused with ``error:10 resend:<n>``; it asks again as line n."""
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?speed=0", timeout=0.02)
    try:
        first = Link(port, url="first")
        assert isinstance(first.handshake(1.5), Banner)  # the boot banner
        first.command("G90")
        first.command("G91")
        assert first.next_line == 3
        again = Link(port, url="again")
        assert again.handshake(1.5) == first.banner  # no banner until it asked as N3
        assert again.next_line == 4
        again.command("G90")
        assert again.status().accepted_line == 4
    finally:
        port.close()


def test_hardware_reset_revives_a_hung_controller_and_restarts_the_numbering() -> None:
    """DTR reboots a hung controller: a banner, laser off, the line counter back to 0 (the
    next line is 1) and the position, H and Ln done kept (docs/protocol.md 7)."""
    urls.register()
    port = serial.serial_for_url("fivebar-mock://?speed=0&stall_after=3", timeout=0.02)
    try:
        link = Link(port, url="hung", reply_timeout_s=0.3)
        link.handshake(1.5)
        link.command("G92 A5 B6")
        link.command("G1 A25 B-4 P10000")
        link.wait_idle(1.0)
        link.command("G90")  # answered, then the controller hangs
        with pytest.raises(LinkFaultError, match="no status report"):
            link.status()
        assert link.next_line == 4
        assert link.hardware_reset()
        assert link.next_line == 1
        st = link.status()
        assert (st.a, st.b, st.homed, st.done_line, st.accepted_line) == (25, -4, True, 2, 0)
        link.command("G90")
        assert link.status().accepted_line == 1
    finally:
        port.close()


@pytest.mark.parametrize("proto", [1, 3])
def test_the_host_accepts_only_the_protocol_it_speaks(proto: int) -> None:
    urls.register()
    with pytest.raises(FirmwareMismatchError) as e:
        Link.open(f"fivebar-mock://?proto={proto}", banner_timeout_s=1.5)
    assert (f"speaks protocol {proto}; this host needs protocol {protocol.PROTOCOL_VERSION}"
            in str(e.value))
