"""The physical side of the mock: step timing, executed blocks, machines that outlive ports.

``steps_done``/``step_cycle`` are the firmware's DDA schedule (fb_motion.c), ``Block`` a
queued or running block, ``LedgerEntry`` what a step-pulse recorder would see of one block,
``KeptRecord`` the firmware's ``.noinit`` RAM record.  A ``Machine`` is the hardware under a
mock port: motor positions, the ledger and the laser log; named machines
(``fivebar-mock://?machine=NAME``, ``machine(NAME)``) survive a close and reopen of the port,
so tests can check what a job did across resets and power cuts.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from fivebar_host.devices.mock.codes import F_CPU
from fivebar_host.devices.mock.pen import PenServo

if TYPE_CHECKING:
    from fivebar_host.devices.mock.firmware import MockFirmware
    from fivebar_host.devices.mock.port import MockSerial


def steps_done(n: int, cycles: int, elapsed: int) -> int:
    """Steps an axis with ``n`` steps over ``cycles`` has made after ``elapsed`` cycles.

    The firmware's DDA puts step k (1..n) at cycle floor((2k-1)·C / 2n) of the segment.
    """
    if n <= 0 or elapsed < 0:
        return 0
    if elapsed >= cycles:
        return n
    x = 2 * n * (elapsed + 1)
    return min(n, ((x - 1) // cycles + 1) // 2)


def step_cycle(n: int, cycles: int, k: int) -> int:
    """Cycle of step k (1..n) of an axis with n steps over ``cycles``."""
    return ((2 * k - 1) * cycles) // (2 * n)


@dataclass
class Block:
    """A queued or running block: a segment, a homing move or a synchronous command."""

    kind: str  # G1 G92 M17 M18 M280 home-seek home-pulloff
    line: int
    delta: tuple[int, int] = (0, 0)  # signed steps (G92: the new position)
    cycles: tuple[int, int] = (0, 0)  # DDA length per motor, CPU cycles
    duration_us: float = 0.0  # when the block ends, firmware µs
    power: int = 0
    p_us: int = 0  # commanded duration (G1)
    pen: tuple[int, int, int] = (0, 0, 0)  # M280: pulse µs, move ms, settle ms
    #: G7 (mock/raster.py): its scan's id (0: not a G7 block), whether it starts the scan,
    #: and its pixel changes: µs from its start, power, the ring bytes each frees
    scan: int = 0
    scan_start: bool = False
    changes: tuple[tuple[float, int, int], ...] = ()


@dataclass
class LedgerEntry:
    """One block the device executed or started — what a step-pulse recorder would see.

    ``start``/``end`` are positions in the firmware's coordinates (G92 and homing move
    them without steps), ``steps`` the signed steps issued per motor.  ``fraction`` is the
    share of the block's time executed (1.0 = completed); ``stopped`` says why it ended
    early ("reset" for Ctrl-X, "alarm", "homing-abort", "reboot" for a reset that keeps the
    position, "power-cut") and is None for a completed or a still running block.
    ``boot`` counts firmware boots of the machine (1 = first).
    """

    boot: int
    kind: str  # G1 G92 M17 M18 home-seek home-pulloff home-set
    line: int
    start: tuple[int, int]
    end: tuple[int, int]
    steps: tuple[int, int]
    power: int
    duration_us: int
    fraction: float
    stopped: str | None = None
    started_s: float = 0.0  # clock time of the block start (time.monotonic by default)

    @property
    def complete(self) -> bool:
        """True when the block ran to its end."""
        return self.fraction >= 1.0


@dataclass(frozen=True)
class KeptRecord:
    """The firmware's ``.noinit`` RAM record: what a reset that leaves the RAM powered keeps
    (docs/protocol.md section 7, "kept across a reset")."""

    position: tuple[int, int]  # A, B in firmware steps
    homed: bool  # H
    done_line: int  # Ln done: the last line executed to its end


@dataclass
class Machine:
    """The physical machine under a mock: motor positions, what was executed, the laser."""

    name: str | None
    phys: list[int] = field(default_factory=lambda: [0, 0])
    ledger: list[LedgerEntry] = field(default_factory=list)
    laser_log: list[tuple[float, int]] = field(default_factory=list)  # (clock s, power)
    boots: int = 0
    pen_park_ee: int | None = None  # the $14 the EEPROM holds (None: blank)
    pen: PenServo = field(default_factory=PenServo)  # the servo pulse over time
    firmware: MockFirmware | None = None
    port: MockSerial | None = None
    true: tuple[float, ...] | None = None  # URL option true=: the real geometry (mm, deg)
    backlash: tuple[int, int] | None = None  # URL option backlash=: the real slack, steps

    @property
    def laser(self) -> int:
        """The laser output now (0 = off)."""
        return self.laser_log[-1][1] if self.laser_log else 0

    def power_cut(self) -> None:
        """Cut the controller's power: motion stops where it is, laser off, its RAM is lost.

        With a port open the controller boots again at once as at power-on (banner,
        position 0, ``H:0``, ``Ln:0,0``); otherwise the next open powers it up.  The motors
        stay where they physically are.  Nothing happens before the first open."""
        if self.port is not None:
            self.port.power_cut()


_MACHINES: dict[str, Machine] = {}
_MACHINES_LOCK = threading.Lock()


def machine(name: str) -> Machine:
    """The named machine of ``fivebar-mock://?machine=NAME`` (created if new)."""
    with _MACHINES_LOCK:
        return _MACHINES.setdefault(name, Machine(name))


def forget_machines() -> None:
    """Drop every named machine (tests call it to start from a clean state)."""
    with _MACHINES_LOCK:
        _MACHINES.clear()


def step_interval(rate: int) -> int:
    """CPU cycles per step at ``rate`` steps/s, rounded up (fb_settings.c settings_interval)."""
    return (F_CPU + rate - 1) // rate

