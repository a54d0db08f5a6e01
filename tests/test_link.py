"""The link's handshake against the mock: a device that was not reset on open."""

from __future__ import annotations

import serial

from fivebar_host.devices import urls
from fivebar_host.link import Link
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
