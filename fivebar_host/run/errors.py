"""The errors of running a job on the machine, and the kinds of link faults.

Kept apart from the link and the sender so that every module of `fivebar_host.run` (the
stream state machine, the link, the program builder, fault handling) can raise and catch them
without importing one another in a circle.

A fault's kind is a `FaultKind`, a `StrEnum`: its value is the word users read in messages
and that resume files and the daemon's store keep (``"disconnect: ..."``), unchanged from
when kinds were plain strings.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

from fivebar_host.errors import FivebarError
from fivebar_host.protocol import StatusReport


class FaultKind(StrEnum):
    """What stopped a stream; the value is the word printed and persisted."""

    ERROR = "error"  # the firmware refused a line (an error reply that is no resend request)
    TIMEOUT = "timeout"  # the device went silent
    DISCONNECT = "disconnect"  # a read or write on the port failed
    RESET = "reset"  # the firmware restarted (a banner arrived) while streaming
    ALARM = "alarm"  # an alarm push or a status report in Alarm
    INTERRUPT = "interrupt"  # the user (or the daemon) stopped the job


class LinkError(FivebarError, RuntimeError):
    """The link failed; the message says where (port, line) and why."""

    exit_code = 3


class NoBannerError(LinkError):
    """No fivebar banner arrived: not our firmware, wrong baud rate, or no device."""


class FirmwareMismatchError(LinkError):
    """The device speaks another protocol version than this host (protocol.PROTOCOL_VERSION).

    Versions are not mixed: version 2 changed the line checksum, so a version 1 firmware
    would refuse every numbered line of this host with ``error:8``.
    """


@dataclass
class LinkFaultError(LinkError):
    """A fault while streaming: an error reply, a timeout, a disconnect, a reset or an alarm.

    `acked` is the index of the first job line not yet answered `ok`; `sent` the number of
    job lines written at least once (the device may have accepted, and run, any of them);
    both are −1 for a fault outside a stream. `status` is the last status report received
    before the fault.
    """

    kind: FaultKind
    message: str
    acked: int
    code: int | None = None
    status: StatusReport | None = None
    sent: int = -1

    def __str__(self) -> str:
        return self.message


class SendError(LinkError):
    """A job could not be sent or finished; says what happened, where, and what to do."""


class PowerLossError(SendError):
    """A resume found a controller that lost power (`H:0`) and nobody confirmed where the
    arms are (`--yes` never does): refused before anything moved; says what to do."""
