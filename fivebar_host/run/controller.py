"""The controller seam: what a run needs of a machine, whatever firmware drives it.

fivebar drives two kinds of controller — its own firmware (`controllers.fivebar`: numbered,
checked lines, a record kept across resets, exact resume) and a stock GRBL 1.1 board in joint
space (`controllers.grbl`) — and every face (the CLI, the daemon, the vpype plugin) runs a job
the same way (`run.job.run_job`) through this protocol. A controller is chosen by name in one
place, `fivebar_host.controllers.controller_for`, the way pyserial finds a URL scheme's
handler or Klipper a kinematics module.

What a controller cannot do it says in its `Features`; `run.job.check_features` refuses such a
job before anything moves, with the reason, for every controller alike (`check_job`, the
part that needs no run: also before a port is opened, and by `fivebar convert`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Protocol

if TYPE_CHECKING:  # the CLI reads the controllers' names without loading the pipeline
    from fivebar_host.compile import Job
    from fivebar_host.config import Profile
    from fivebar_host.program import Program
    from fivebar_host.run.operator import Operator
    from fivebar_host.run.overrides import Overrides
    from fivebar_host.run.resume import ResumePoint
    from fivebar_host.run.store import ResumeStore

#: Absolute motor steps from the homed pose (A, B): fivebar's position everywhere.
Position = tuple[int, int]


@dataclass(frozen=True)
class Features:
    """What a controller can do beyond running a job from start to end (`None`: it can;
    otherwise the reason it cannot, which the refusal quotes)."""

    live_overrides: str | None = None
    tool_on_dwells: str | None = None  # a dwell with the laser on (G4 after M3 S>0)
    motors_off: str | None = None  # the stepper drivers switched off by command
    raster: str | None = None  # an image job: its pixels on a timeline inside the scan (G7)


def check_job(features: Features, job: Job) -> None:
    """Refuse (UsageError, the reason quoted) what a controller with these features cannot
    do with this job, whatever the run's options."""
    from fivebar_host.errors import UsageError

    if job.raster is not None and features.raster is not None:
        raise UsageError(f"{job.file}: an image (raster) job: {features.raster}")


@dataclass(frozen=True)
class Status:
    """A controller's state as every face shows it."""

    state: str  # Idle, Run, Hold, Alarm, Home …
    detail: int | None  # the alarm code or hold reason, if any
    position: Position
    homed: bool  # the position means the profile's steps (fivebar: `H:1`)
    laser: bool  # the laser output is on (False where the controller does not say)
    pen_us: int | None = None  # the pen servo's pulse now (0: never set; None: not known)


@dataclass
class Piece:
    """Segments `begin` … `end` − 1 of `job` to stream as one program from `position`, and
    what the stream answers to: the run's operator (hold, interrupt), its store (a stream's
    start, the resume point after a fault), the live overrides, and `done(k)` to call with
    the first segment not yet finished as the machine reports it."""

    job: Job
    begin: int
    end: int
    position: Position
    copy: int
    laser: bool
    operator: Operator
    store: ResumeStore
    overrides: Overrides | None
    done: Callable[[int], None]


@dataclass(frozen=True)
class Converted:
    """A job as the lines of a file for this controller (`fivebar convert`), and what they
    are in words ("372 segments, mode +-, pen …")."""

    lines: list[str]
    summary: str


@dataclass(frozen=True)
class Recording:
    """An emulated machine's recorded step pulses, for the executed-path report, and the
    geometry of the machine it emulates when that differs from the profile (`?true=`)."""

    path: Path
    true: tuple[float, ...] | None
    #: each motor's real slack in steps (`?backlash=`), None: the profile's backlash
    backlash: tuple[int, int] | None = None
    #: each true arm servo's dead band, degrees (`?deadband=`), None: none
    deadband: tuple[float, float] | None = None


@dataclass(frozen=True)
class PieceResult:
    """Where a piece left the machine (idle), and what its stream cost."""

    position: Position
    bytes_sent: int
    resends: int


class Controller(Protocol):
    """A machine a run drives (module doc)."""

    features: ClassVar[Features]
    url: str
    profile: Profile
    #: What the user should know about the connection (a faster rate refused), or None.
    notice: str | None

    @classmethod
    def open(cls, url: str, profile: Profile) -> Controller:
        """Open the machine at `url` (a device path, COM port or pyserial URL)."""
        ...

    @classmethod
    def convert(cls, job: Job, profile: Profile, laser: bool, relative: bool) -> Converted:
        """`job` as the lines this controller runs, for a file (no machine needed)."""
        ...

    def close(self) -> None:
        """Close the port (the machine keeps what it was doing)."""
        ...

    def status(self) -> Status:
        """Where the machine is and what it does (moves nothing)."""
        ...

    def describe(self, position: Position) -> str:
        """A position as this controller's user reads it."""
        ...

    def ensure_pose(self, operator: Operator) -> Position:
        """Make the controller's count mean the profile's steps before a job: home with
        endstops, else the operator confirms the arms' pose; refuse an alarm or a hold."""
        ...

    def home(self, operator: Operator) -> Position:
        """Home (`$H` with endstops), or set the count once the operator confirms the arms
        are at the home pose."""
        ...

    def resume_start(self, job: Job, point: ResumePoint, operator: Operator
                     ) -> tuple[int, Position]:
        """Where a resumed run of `job` starts (the segment) and the machine stands, from the
        saved `point` and what the controller says now; notes go to the operator."""
        ...

    def run_piece(self, piece: Piece) -> PieceResult:
        """Stream one piece and wait until the machine is idle. A fault or an interrupt:
        hold (laser off), save the resume point in `piece.store`, raise `SendError` naming
        the fault, the position and what to do."""
        ...

    def run_moves(self, moves: Program, position: Position) -> Position:
        """Run the host's own checked, laser-off moves (`run.moves`: jog, frame, travel)
        from `position` and wait until the machine is idle; where it stands."""
        ...

    def pen(self, down: bool) -> Status:
        """Lower or raise the servo pen (the profile's `[pen]`)."""
        ...

    def motors_off(self) -> Status:
        """Switch the stepper drivers off, so that the arms can be moved by hand (the
        position is lost: home afterwards)."""
        ...

    def poll(self) -> None:
        """Keep the link alive while the host waits (the page delay between copies)."""
        ...

    def recording(self) -> Recording | None:
        """An emulated machine's recorded step pulses (None for a real machine)."""
        ...
