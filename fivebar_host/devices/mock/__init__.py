"""``fivebar-mock://`` — a pyserial port that is a fivebar controller written in Python.

The mock implements docs/protocol.md the way the firmware (firmware/fivebar/fb_main.c and
the fb_*.c beside it) does, so host code and tests can run without hardware and without
the AVR toolchain: the boot banner on open (as the Uno's DTR reset sends it), a receive
buffer of the banner's size whose excess bytes are lost (``error:18``), line framing with
line numbers, the checksum field (CRC-16 and length), strict framing and resend requests,
every command and setting, soft limits, homing and the endstop alarm against simulated
switches, the segment queue with its start rule and its blocking (its slots hold the
waiting blocks and the one executing; a line that needs a slot waits, unanswered, until one
frees), exact DDA step timing, hold / resume / reset, the laser safety rules, and status
reports in the firmware's format.  The contract suite (tests/contract/) runs the same tests
against this mock and the real firmware in simavr.

**Time.**  The simulation is lazy and single-threaded: every call (``read``, ``write``,
``in_waiting``, ``ledger`` ...) first advances the device from the last call to the current
clock, handling each event in time order (segment end, endstop alarm, the 20 ms queue
start delay, the laser silence timeout), so no background thread runs.  Motion runs
``speed`` times faster than the firmware would (a ``G1 … P<us>`` segment takes ``P/speed``
µs of wall time; ``speed=0`` executes every started segment at once); the protocol's own
timers (start delay, ``$6`` laser timeout) run in wall time, because the host's timing
(polling ``?`` every ``$6/2`` ms) is in wall time.  Bytes written arrive at the moment of
the ``write`` call; the main loop handles each byte before the next one arrives, as the
firmware does at 115200 baud.

**URL options** (``fivebar-mock://?speed=10&drop=0.01&seed=1``: faults, buffer sizes,
banner, ``machine=NAME``) are listed in ``fivebar_host.devices.mock.options``.

**Resets.**  A DTR edge, a reopen of a named machine, ``reset_after``, the watchdog's reset
of a ``stall_after`` hang (``watchdog`` ms after it, laser off then) and a stall revived by
DTR are resets with the RAM powered: the firmware's ``.noinit`` record brings back the position,
``H`` and ``Ln`` done; everything else restarts as at power-on.  Only the first open of a
machine, ``power_cut_after`` and ``Machine.power_cut`` are power-ons.

**What was executed** is recorded per block in ``port.ledger`` (line number, start/end
position, steps issued, laser power, fraction completed, why it stopped early), and the
laser output's changes in ``port.machine.laser_log``; ``port.snapshot()`` is the status
report the device would send now.  ``MockSerial.opened`` lists every port opened in this
process, for tests that need the port a command opened internally.

Known differences from the firmware, all about timing only: replies appear at once (the
firmware transmits at 115200 baud, so a burst of ``?`` can coalesce into fewer reports
there), homing travel is not split into chunks, and the firmware's 4 µs start latency is
not modelled.

**Layout.**  ``options`` parses the URL; ``parser`` is the line grammar (fb_proto.c);
``hardware`` the DDA schedule, the ledger and the named machines; ``motion`` the queue and
the running block (fb_motion.c); ``homing`` ``$H``; ``firmware`` the main loop, commands,
resets and faults (fb_main.c); ``port`` the pyserial port.  This package is the pyserial
protocol handler of the scheme: ``fivebar_host.devices.urls.register()`` installs it, and
pyserial takes its ``Serial``.
"""

from __future__ import annotations

from fivebar_host.devices.mock.codes import E_CHECKSUM, SCHEME
from fivebar_host.devices.mock.firmware import MockFirmware
from fivebar_host.devices.mock.hardware import (
    KeptRecord,
    LedgerEntry,
    Machine,
    forget_machines,
    machine,
    step_cycle,
    steps_done,
)
from fivebar_host.devices.mock.options import MockOptions, MockURLError, parse_mock_url
from fivebar_host.devices.mock.parser import Command, Parsed, parse_line
from fivebar_host.devices.mock.port import MockSerial

#: pyserial looks up ``Serial`` in a protocol handler module.
Serial = MockSerial

__all__ = [
    "E_CHECKSUM",
    "SCHEME",
    "Command",
    "KeptRecord",
    "LedgerEntry",
    "Machine",
    "MockFirmware",
    "MockOptions",
    "MockSerial",
    "MockURLError",
    "Parsed",
    "Serial",
    "forget_machines",
    "machine",
    "parse_line",
    "parse_mock_url",
    "step_cycle",
    "steps_done",
]
