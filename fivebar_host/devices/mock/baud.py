"""The mock firmware's UART rate and `$B` (fb_baud.c baud_request, switch_baud, baud_fallback).

`$B=<baud>` is answered `ok` at the old rate, then the rate changes; a valid line (one that
parses) must arrive within `protocol.BAUD_TRIAL_S`, else the firmware returns to
`protocol.BASE_BAUD`. A boot, a reset and Ctrl-X start at the base rate. The port tells the
firmware its own rate (`host_baud`); while the two differ every byte is lost both ways, as a
UART that samples at the wrong rate sees only framing errors (docs/protocol.md 1). A port
at a rate that is not one of `protocol.BAUD_RATES` counts as the base rate.
"""

from __future__ import annotations

from fivebar_host import protocol
from fivebar_host.devices.mock.codes import E_OUT_OF_RANGE, OK


class UartRate:
    """The rate in force, a switch waiting for its `ok`, and the trial of a new rate."""

    def __init__(self, host_baud: int = protocol.BASE_BAUD) -> None:
        self.baud = protocol.BASE_BAUD
        self.host_baud = host_baud  # the port's rate, set by MockSerial
        self.next_baud = 0
        self.trial_since_s: float | None = None

    def matches(self) -> bool:
        """Whether bytes pass: host and firmware at the same rate. A port at a rate that is
        not a link rate (pyserial's default 9600 of a test that never set one) counts as the
        base rate, as before rates were modelled."""
        host = self.host_baud if self.host_baud in protocol.BAUD_RATES else protocol.BASE_BAUD
        return self.baud == host

    def reset(self) -> None:
        """A boot, reset or Ctrl-X (fb_main.c do_reset): the base rate, no trial."""
        self.baud = protocol.BASE_BAUD
        self.next_baud = 0
        self.trial_since_s = None

    def request(self, value: int) -> int:
        """`$B=<value>`: OK and a switch after the reply, or out of range."""
        if value not in protocol.BAUD_RATES:
            return E_OUT_OF_RANGE
        self.next_baud = value
        return OK

    def after_reply(self, now_s: float) -> None:
        """The reply has left: switch, on trial unless it is the base rate."""
        if self.next_baud:
            self.baud, self.next_baud = self.next_baud, 0
            self.trial_since_s = None if self.baud == protocol.BASE_BAUD else now_s

    def valid_line(self) -> None:
        """A line parsed: the host speaks at this rate."""
        self.trial_since_s = None

    def fallback(self, now_s: float) -> None:
        """No valid line within the trial: back to the base rate."""
        if (self.trial_since_s is not None
                and now_s - self.trial_since_s > protocol.BAUD_TRIAL_S):
            self.trial_since_s = None
            self.baud = protocol.BASE_BAUD
