"""fivebar's own firmware as a `run.controller.Controller`: a known pose, streaming a piece of
a job, exact resume, the host's own moves, the pen.

Over an open `Link` (numbered lines with CRC and length, character counting, resends:
`controllers.fivebar.link`). A piece is a program (`run.moves.build_program`) streamed with
the operator's hold and interrupt and the live overrides; the firmware's status reports say
which line (so which segment) finished last. On a fault the machine is held (laser off), its
position read, the firmware reset (queue cleared, laser off) and the resume point saved
(`controllers.fivebar.faults`). A resumed run continues from exactly there: when the pen
stopped inside a segment, one move finishes the rest of it along the same joint-space line
(nothing redrawn); otherwise a laser-off travel goes back to the segment's start.

When the controller restarts (a reset banner mid-stream, or a hung controller rebooted
through DTR) it keeps its position, `H` and `Ln` done (docs/protocol.md 7, kept across a
reset): the line it finished last maps back to the exact segment (`controllers.fivebar.kept`).
When the link breaks the position cannot be read at once; the resume point then describes
the stream, and a resume reads the kept record from the controller (opening the port resets
an Arduino, which keeps it) and maps it the same way. Only a controller that lost power
(`H:0`) falls back to the last segment a status report confirmed, and segments after it may
be drawn twice.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, ClassVar

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.compile.emit import pen_move
from fivebar_host.compile.steps import pen_position_mm
from fivebar_host.config import Profile
from fivebar_host.controllers.fivebar.faults import StreamRun, after_fault
from fivebar_host.controllers.fivebar.kept import kept_stream_segment
from fivebar_host.controllers.fivebar.link import Link
from fivebar_host.controllers.fivebar.stream import StreamProgress
from fivebar_host.errors import UsageError
from fivebar_host.program import Program
from fivebar_host.protocol import StatusReport
from fivebar_host.run.controller import (
    Converted,
    Features,
    Piece,
    PieceResult,
    Position,
    Recording,
    Status,
)
from fivebar_host.run.errors import LinkFaultError, PowerLossError, SendError
from fivebar_host.run.moves import build_program
from fivebar_host.run.operator import Operator
from fivebar_host.run.overrides import FEED_MAX_PCT, FEED_MIN_PCT
from fivebar_host.run.resume import ResumePoint, fingerprint, redraw_text
from fivebar_host.run.store import StreamStart


def code_text(code: int | None) -> str:
    """An alarm or error code in words, from the protocol's table."""
    info = protocol.CODES.get(code if code is not None else -1)
    return info.description if info else "unknown code"


def position_text(profile: Profile, a_steps: int, b_steps: int, homed: bool = True) -> str:
    """A machine position as the user reads it: motor steps and, by forward kinematics of
    the profile's assembly, the pen in mm ("A = 120 steps, B = -40 steps (x 12.3 mm,
    y 95.0 mm)"). Without a known position (not homed) the mm are not shown."""
    text = f"A = {a_steps} steps, B = {b_steps} steps"
    if not homed:
        return text + " (position unknown: not homed)"
    xy = pen_position_mm(profile.geometry, profile.kinematics.assembly, profile.motors.home_rad,
                         profile.motors.steps_per_rev, a_steps, b_steps)
    if xy is None:
        return text + " (no pen position: the links cannot close there)"
    return f"{text} (x {xy[0]:.1f} mm, y {xy[1]:.1f} mm)"


class FivebarController:
    """fivebar's firmware behind `link` (module doc)."""

    features: ClassVar[Features] = Features()

    def __init__(self, link: Link, profile: Profile) -> None:
        self.link = link
        self.profile = profile
        self.url = link.url
        #: What the user should know about the connection (a faster rate refused).
        self.notice = "; ".join(n for n in (link.baud_warning, link.lock and link.lock.note)
                                if n) or None

    @classmethod
    def open(cls, url: str, profile: Profile) -> FivebarController:
        """Open `url` at the profile's rates and wait for the firmware's banner."""
        ser = profile.serial
        opts: dict[str, Any] = {
            "baud": ser.baud, "banner_timeout_s": ser.banner_timeout_s,
            "reply_timeout_s": ser.reply_timeout_s, "link_baud": ser.link_baud}
        if profile.joints is not None:  # servo joints: the servo build (servo.py)
            from .servo import open_servo_link

            return cls(open_servo_link(url, profile, profile.joints, **opts), profile)
        return cls(Link.open(url, **opts), profile)

    @classmethod
    def convert(cls, job: Job, profile: Profile, laser: bool, relative: bool) -> Converted:
        """The firmware's lines (`compile.encode`), absolute or relative."""
        from fivebar_host.compile import encode_lines, mode_sequence

        if job.raster is not None:
            # wire.body writes a G7 item only as a message; its line is binary (protocol.md
            # 6.4) and numbered and checksummed for one session, so no file holds it
            raise UsageError(
                f"{job.file}: an image (raster) job cannot be written as firmware lines: its "
                "G7 lines carry binary pixel data, numbered and checksummed for one session "
                "(docs/protocol.md 6.4). Engrave it with `fivebar plot` (or the web page); "
                "`fivebar plot --dry-run` shows the job")
        lines = encode_lines(job, profile, relative=relative, laser=laser)
        top = int(job.power.max(initial=0))
        tool = f"laser (power up to S{top})" if laser else "pen (S0, no laser power)"
        changes = (f" ({len(job.mode_changes)} pen-up mode changes)" if job.mode_changes
                   else "")
        pauses = ("; the file runs through its pen-change stops (`fivebar plot` stops "
                  "there): " + ", ".join(f"segment {p.segment} before {p.describe()}"
                                         for p in job.pauses) if job.pauses else "")
        return Converted(lines, f"{job.n_segments} segments, mode {mode_sequence(job)}"
                         f"{changes}, {tool}, ≈ {job.total_time_s:.1f} s, "
                         f"max deviation {job.max_dev_mm:.4f} mm" + pauses)

    def close(self) -> None:
        self.link.close()

    # ------------------------------------------------------------------ state
    def status(self) -> Status:
        st = self.link.status()
        return _status(st)

    def describe(self, position: Position) -> str:
        return position_text(self.profile, *position)

    def poll(self) -> None:
        self.link.status()

    def recording(self) -> Recording | None:
        trace = getattr(self.link.port, "trace_path", None)
        if trace is None:
            return None
        opts = getattr(self.link.port, "options", None)
        true = getattr(opts, "true", None)
        return Recording(Path(trace), None if true is None else tuple(true),
                         getattr(opts, "backlash", None), getattr(opts, "deadband", None))

    # ------------------------------------------------------------------ pose
    def ensure_pose(self, operator: Operator) -> Position:
        """Make sure the firmware's step count means what the job assumes (0 = homed pose).

        After power-up the firmware does not know where the arms are (`H:0`; a reset, such
        as the one opening an Arduino's port causes, keeps the position: docs/protocol.md
        7): with endstops `$H` homes; without them the operator confirms that the arms sit
        at the profile's home pose, and `G92 A0 B0` sets the position. Alarm or hold states
        are refused with what to do."""
        st = self.link.status()
        if st.state == "Alarm":
            raise SendError(f"{self.url}: the machine is in alarm {st.detail} "
                            f"({code_text(st.detail)}); clear it with `fivebar home`")
        if st.state == "Hold":
            raise SendError(f"{self.url}: the machine is on hold; resume or reset it first")
        if st.homed:
            return (st.a, st.b)
        return self.home(operator)

    def home(self, operator: Operator) -> Position:
        """Home: `$H` with endstops, otherwise confirmation then `G92 A0 B0`."""
        link = self.link
        if self.profile.motors.endstops:
            link.command("$H", timeout_s=120.0)
            st = link.wait_idle(120.0)
            return (st.a, st.b)
        h1, h2 = (math.degrees(v) for v in self.profile.motors.home_rad)
        if not operator.confirm(f"The firmware does not know where the arms are. Are they at "
                                f"the home pose θ1 = {h1:g}°, θ2 = {h2:g}° (motor angles "
                                "from +x)?"):
            raise SendError("position unknown: place the arms at the home pose and confirm, "
                            "or run `fivebar home`")
        link.command(Program.set_position(0, 0))
        st = link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect
        return (st.a, st.b)

    # ------------------------------------------------------------------ a job's pieces
    def run_piece(self, piece: Piece) -> PieceResult:
        """Stream segments `piece.begin` … `piece.end` − 1 from the machine's position and
        wait until it is idle. A fault saves the resume point (`after_fault`)."""
        link, job = self.link, piece.job
        end = None if piece.end >= job.n_segments else piece.end
        prog = build_program(job, self.profile, piece.laser, piece.begin, piece.position, end)
        link.number_past_kept()
        first_line = link.next_line
        last_line = first_line + len(prog) - 1
        if len(prog) > 1:
            piece.store.stream_started(StreamStart(first_line, len(prog), piece.begin, end,
                                                   piece.position, piece.copy))

        def progress(p: StreamProgress) -> None:
            piece.done(prog.finished_segments(first_line, p.done_line, piece.begin))

        op = piece.operator
        try:
            res = link.stream(prog, on_progress=progress, should_stop=op.should_stop,
                              on_interrupt=op.interrupted, overrides=piece.overrides)
            slowest = FEED_MAX_PCT / FEED_MIN_PCT if piece.overrides is not None else 1.0
            final = link.wait_idle(
                max(30.0, 3.0 * slowest * job.total_time_s), last_line=last_line,
                on_status=lambda s: piece.done(prog.finished_segments(first_line, s.done_line,
                                                                      piece.begin)))
        except LinkFaultError as fault:
            stream = StreamRun(prog, first_line, piece.begin, piece.position, piece.laser, end,
                               piece.copy)
            raise after_fault(link, job, stream, fault, piece.store, fingerprint(job)) from fault
        return PieceResult((final.a, final.b), res.bytes_sent, res.resends)

    def resume_start(self, job: Job, point: ResumePoint, operator: Operator
                     ) -> tuple[int, Position]:
        """The segment a resumed run starts at and where the machine stands.

        An exact resume point is used as it is. Without a position the controller's record
        kept across its reset (opening the port resets an Arduino) gives the exact segment
        when it belongs to the interrupted stream (`kept_stream_segment`); otherwise the run
        starts at the last segment a status report confirmed, after homing if the controller
        lost its position, and says how many segments may be drawn twice."""
        st = self._resumable_status()
        start, n = point.next_segment, job.n_segments
        if point.position is None and st.homed and point.has_stream:
            exact, why = kept_stream_segment(job, self.profile, point, st)
            if exact is not None:
                operator.note(f"resume point read from the controller: it kept its position "
                              f"(A = {st.a}, B = {st.b} steps) and its last executed line "
                              f"({st.done_line}) across its reset; {exact} of {n} segments "
                              "were executed, continuing exactly from there")
                return exact, (st.a, st.b)
            operator.note(f"the controller's kept record does not belong to the interrupted "
                          f"job ({why}); resuming after segment {start} of {n}, the last a "
                          f"status report confirmed, from the controller's position (A = "
                          f"{st.a}, B = {st.b} steps): "
                          + redraw_text(start, point.sent_segment))
            return start, (st.a, st.b)
        if not st.homed:
            return start, self._restore_position(job, point, operator)
        if point.position is None:
            operator.note(f"resuming after segment {start} of {n}, the last a status report "
                          f"confirmed, from the controller's position (A = {st.a}, B = "
                          f"{st.b} steps): " + redraw_text(start, point.sent_segment))
        return start, (st.a, st.b)

    def _resumable_status(self) -> StatusReport:
        """The status a resume starts from, once the machine is neither running nor
        stopped."""
        st = self.link.status()
        if st.state == "Run":
            # A controller that the port's opening did not reset may still be running the
            # interrupted stream's queue: let it finish, then read where it stopped.
            st = self.link.wait_idle(120.0)
        if st.state in ("Alarm", "Hold"):
            raise SendError(f"{self.url}: the machine is in {st.state} "
                            f"({code_text(st.detail)}); clear it before resuming")
        return st

    def _restore_position(self, job: Job, point: ResumePoint, operator: Operator
                          ) -> Position:
        """The controller lost power since the fault: its count is 0 and the arms are
        wherever they stopped (or were pushed). With endstops `$H` homes; otherwise a person
        confirms where the arms are (where the job stopped, when that is known, or the home
        pose). When nobody confirms, `PowerLossError` says what to do; nothing has moved."""
        link, start = self.link, point.next_segment

        def homed_note() -> None:
            if point.position is None:
                operator.note(f"the controller lost its position (H:0: power was cut since "
                              f"the fault); after homing, resuming after segment {start} of "
                              f"{job.n_segments}, the last a status report confirmed: "
                              + redraw_text(start, point.sent_segment))

        if self.profile.motors.endstops:
            link.command("$H", timeout_s=120.0)
            homed_note()
            st = link.wait_idle(120.0)
            return (st.a, st.b)
        pos = point.position
        if pos is not None and operator.confirm_placed(
                f"The controller lost power. Are the arms still exactly where the job stopped "
                f"(A = {pos[0]}, B = {pos[1]} steps)?"):
            link.command(Program.set_position(pos[0], pos[1]))
            st = link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect
            return (st.a, st.b)
        h1, h2 = (math.degrees(v) for v in self.profile.motors.home_rad)
        if operator.confirm_placed(f"The controller lost power. Are the arms at the home pose "
                                   f"θ1 = {h1:g}°, θ2 = {h2:g}° (motor angles from +x)?"):
            homed_note()
            link.command(Program.set_position(0, 0))
            st = link.wait_idle(10.0)
            return (st.a, st.b)
        raise PowerLossError(
            f"{self.url}: the controller lost power since the job stopped (H:0): its position "
            "is unknown, and --yes does not answer for where the arms are after a power loss. "
            f"Place the arms at the home pose (θ1 = {h1:g}°, θ2 = {h2:g}°) and run `fivebar "
            f"home --port {self.url}`, then this command again with --resume (or run it on a "
            "terminal without --yes and confirm there). Nothing was sent.")

    # ------------------------------------------------------------------ the host's moves
    def run_moves(self, moves: Program, position: Position) -> Position:
        res = self.link.stream(moves)
        st = self.link.wait_idle(max(60.0, 3.0 * res.elapsed_s), last_line=res.last_line)
        return (st.a, st.b)

    def motors_off(self) -> Status:
        """`M18`: the drivers off (docs/protocol.md 6)."""
        self.link.command("M18")
        return _status(self.link.wait_idle(10.0))

    def pen(self, down: bool) -> Status:
        """Lower or raise the servo pen: the park pulse (`$14`), then the `M280` block
        (docs/protocol.md 6.2)."""
        self.link.command(pen_move(self.profile, down))
        return _status(self.link.wait_idle(30.0))


def _status(st: StatusReport) -> Status:
    """fivebar's status report as every face shows it."""
    return Status(st.state, st.detail, (st.a, st.b), st.homed, bool(st.laser), st.pen)

