"""A stock GRBL 1.1 board as a `run.controller.Controller` (`--controller grbl`): settings,
a known pose, streaming a piece of a job, resume, the host's own moves.

Over an open `GrblLink` (no click). fivebar's own firmware (`controllers.fivebar`) is the
other controller; a run drives both through the same protocol (`run.job.run_job`).

**Settings.** Opening the board checks its `$$` against what the profile needs (`fivebar
grbl-settings`): a wrong `$100` would put every later move elsewhere.

**Known pose.** GRBL keeps no position across a reboot (opening an Uno's port reboots it: the
machine position restarts at 0 wherever the arms are) and no "position known" flag. With
endstops (`$22=1`) the board boots in alarm and `$H` homes; then `G10 L20 P1 X<home A>
Y<home B>` makes work X/Y the motor angles. Without endstops, machine 0 is where the board
booted, so a person confirms that the arms are where the count says (the home pose after a
boot; `--yes` answers), and `G10 L2 P1 X<−home A> Y<−home B>` sets the same work frame.

**Faults.** GRBL's `ok` means "planned", not "done", and carries no line number, so the count
of `ok`s bounds progress from above only. On an `error:N`, an alarm or the user's abort the
host holds (`!`: GRBL decelerates, and in laser mode turns the laser off while held), resets
(Ctrl-X: queue cleared, laser off; the position is kept because motion had stopped) and
reads MPos: the position is exact, and the segment it lies on is found by searching the
program's joint-space lines around the last acknowledged one, and the resume point is
saved; a resume continues from it (`controllers.grbl.resume`: what is exact and what is
not).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.controllers.grbl import dialects
from fivebar_host.controllers.grbl.link import (
    GrblError,
    GrblLink,
    GrblSettingsError,
    GrblStatus,
    GrblStreamError,
    StreamState,
)
from fivebar_host.controllers.grbl.program import (
    GrblProgram,
    from_program,
    job_program,
    steps_per_degree,
    tool_lines,
    work_offset_line,
)
from fivebar_host.controllers.grbl.resume import GrblResumeError, check_point, fault_point
from fivebar_host.errors import UsageError
from fivebar_host.program import Program, line_param
from fivebar_host.run.controller import (
    Converted,
    Features,
    Piece,
    PieceResult,
    Position,
    Recording,
    Status,
    check_job,
)
from fivebar_host.run.errors import PowerLossError
from fivebar_host.run.moves import travel
from fivebar_host.run.operator import Operator
from fivebar_host.run.resume import ResumePoint
from fivebar_host.run.store import ResumeStore


def angles_text(profile: Profile, pos: Position) -> str:
    """Steps → the motor angles the board's work coordinates show."""
    h = np.degrees(np.asarray(profile.motors.home_rad))
    a = h + np.asarray(pos) / steps_per_degree(profile)
    return f"X {a[0]:.3f}°, Y {a[1]:.3f}°"


class GrblController:
    """A stock GRBL board behind `link`, driven in joint space (module doc)."""

    features: ClassVar[Features] = Features(
        live_overrides="a stock GRBL board is driven with its own planner; fivebar's live "
        "feed and power keys change fivebar's firmware lines only",
        tool_on_dwells="GRBL's laser mode switches the laser off at rest (M4), so a dwell "
        "with the laser on would burn nothing; plot it on fivebar's firmware",
        motors_off="GRBL switches its drivers off only after its idle delay ($1) or in "
        "sleep ($SLP, which needs a reset); send those to the board yourself",
        raster="its pixels need fivebar's firmware (G7: the power changes timed inside the "
        "scan's moves, docs/raster.md); fivebar does not write them as GRBL lines, so the "
        "board would run the scan with the laser off. Engrave it on fivebar's firmware")

    def __init__(self, link: GrblLink, profile: Profile) -> None:
        self.link = link
        self.profile = profile
        self.url = link.url
        self.notice: str | None = link.lock.note if link.lock is not None else None
        diff = dialects.differences(link, profile)
        if diff:
            how = ("set each item in its config.yaml or with `$/item=value`"
                   if link.dialect == dialects.FLUIDNC else "send each line to the board")
            raise GrblSettingsError(
                f"{link.url}: the {link.dialect} board's settings differ from what the "
                f"profile needs (`fivebar grbl-settings` prints them; {how}):\n  "
                + "\n  ".join(diff))
        if link.dialect == dialects.FLUIDNC:
            self.notice = f"FluidNC: check by hand that {dialects.FLUIDNC_MANUAL}"

    @classmethod
    def open(cls, url: str, profile: Profile) -> GrblController:
        """Open the board at `url` and check its settings."""
        ser = profile.serial
        link = GrblLink.open(url, baud=ser.baud, banner_timeout_s=ser.banner_timeout_s,
                             reply_timeout_s=ser.reply_timeout_s)
        try:
            return cls(link, profile)
        except BaseException:
            link.close()
            raise

    @classmethod
    def convert(cls, job: Job, profile: Profile, laser: bool, relative: bool) -> Converted:
        """The board's lines (`controllers.grbl.program.job_program`): absolute work X/Y in
        degrees, so `relative` is refused."""
        if relative:
            raise UsageError("--relative: GRBL's lines are absolute motor angles (G90); "
                             "leave --relative out")
        check_job(cls.features, job)
        lines = job_program(job, profile, laser).lines
        return Converted(lines, f"{len(lines)} GRBL lines (G1 X/Y = motor angles in degrees) "
                         f"for {job.n_segments} segments, ≈ {job.total_time_s:.1f} s planned")

    def close(self) -> None:
        self.link.close()

    # ------------------------------------------------------------------ state
    def position_steps(self, st: GrblStatus) -> Position:
        """fivebar's absolute steps (from the home pose) of a status report: work X/Y are
        the motor angles in degrees (module doc)."""
        if st.work_reported:
            work = st.machine
        else:
            off = self.link.work_offset()
            work = (st.machine[0] - off[0], st.machine[1] - off[1])
        spd = steps_per_degree(self.profile)
        h = [math.degrees(v) for v in self.profile.motors.home_rad]
        return (round((work[0] - h[0]) * spd), round((work[1] - h[1]) * spd))

    def status(self) -> Status:
        st = self.link.status()
        return Status(st.state, None, self.position_steps(st), st.state != "Alarm", False)

    def describe(self, position: Position) -> str:
        return angles_text(self.profile, position)

    def poll(self) -> None:
        self.link.status()

    def recording(self) -> Recording | None:
        return None

    # ------------------------------------------------------------------ pose
    def ensure_pose(self, operator: Operator) -> Position:
        """A known pose (module doc) → the position in fivebar's steps."""
        link, profile = self.link, self.profile
        st = link.status()
        h = [math.degrees(v) for v in profile.motors.home_rad]
        if profile.motors.endstops:
            if st.state == "Alarm":
                link.command("$H", timeout_s=120.0)
                link.command(work_offset_line(profile))
                st = link.status()
            return self.position_steps(st)
        if st.state not in ("Idle",):
            raise GrblError(f"{link.url}: the board is in {st.state}; clear it (`$X` in a "
                            "terminal, or reset it) before a job")
        where = (h[0] + st.machine[0], h[1] + st.machine[1])
        at_home = st.machine == (0.0, 0.0)
        question = (f"GRBL restarted its count when the port opened. Are the arms at the "
                    f"home pose θ1 = {h[0]:g}°, θ2 = {h[1]:g}° (motor angles from +x)?"
                    if at_home else f"Are the arms at θ1 = {where[0]:.3f}°, θ2 = "
                    f"{where[1]:.3f}° (GRBL's count since it booted at the home pose)?")
        if not operator.confirm(question):
            raise GrblError("position unknown: place the arms at the home pose, reset the "
                            "board (or reopen its port) and confirm")
        link.command(f"G10 L2 P1 X{-h[0]:.4f} Y{-h[1]:.4f}")
        return self.position_steps(link.status())

    def home(self, operator: Operator) -> Position:
        """`$H` with endstops, else the confirmation."""
        if self.profile.motors.endstops:
            self.link.command("$H", timeout_s=120.0)
            self.link.command(work_offset_line(self.profile))
            return self.position_steps(self.link.status())
        return self.ensure_pose(operator)

    # ------------------------------------------------------------------ a job's pieces
    def run_piece(self, piece: Piece) -> PieceResult:
        """Travel to the piece's first segment if the arms are elsewhere (laser off; on its
        line a resumed segment is finished from there), stream the piece and wait for idle.
        Progress counts the segments GRBL acknowledged (planned; up to 15 blocks ahead of
        the pen)."""
        job, k, pos = piece.job, piece.begin, piece.position
        at: Position | None = None
        if pos != (int(job.steps[k, 0]), int(job.steps[k, 1])):
            if (k < job.n_segments
                    and line_param(job.steps[k], job.steps[k + 1], pos) is not None):
                at = pos
            else:
                self._travel(job.assembly, pos, (int(job.steps[k, 0]), int(job.steps[k, 1])))
        end = None if piece.end >= job.n_segments else piece.end
        prog = job_program(job, self.profile, piece.laser, k, at, end)

        def progress(s: StreamState) -> None:
            seg = prog.segment[: s.acked]
            piece.done(int(seg.max()) + 1 if seg.size and seg.max() >= 0 else k)

        op = piece.operator
        try:
            res = self.link.stream(prog.lines, on_progress=progress,
                                   should_stop=op.should_stop, on_interrupt=op.interrupted)
            st = self.link.wait_idle(max(30.0, 3.0 * job.total_time_s))
        except GrblStreamError as e:
            raise self._after_fault(job, prog, e, piece.store, piece.copy) from e
        return PieceResult(self.position_steps(st), res.bytes_sent, 0)

    def _after_fault(self, job: Job, prog: GrblProgram, e: GrblStreamError,
                     store: ResumeStore, copy: int) -> GrblError:
        """Hold, reset (laser off, queue cleared, position kept), read where the pen
        stopped, save the resume point. After an alarm or a reboot GRBL's position is not
        trusted."""
        link = self.link
        pos: Position | None = None
        reason = f"{e.code or 'fault'}: {e}"
        try:
            if not e.code.startswith(("ALARM", "Grbl")):
                link.hold()
                link.reset()
            pos = self.position_steps(link.status())
            if e.code.startswith(("ALARM", "Grbl")):
                reason += (f" (GRBL may have lost its position; it reports A = {pos[0]}, "
                           f"B = {pos[1]} steps)")
                pos = None
        except GrblError as again:
            reason += f"; then the board could not be read ({again})"
        rp, where = fault_point(job, prog, e.state, pos, reason, copy)
        store.save(rp)
        hint = store.hint()
        return GrblError(f"{e}. Laser off, queue cleared. {where}."
                         + (f"\n{hint}" if hint else ""))

    def resume_start(self, job: Job, point: ResumePoint, operator: Operator
                     ) -> tuple[int, Position]:
        """Make the board's count agree with the stop position (`controllers.grbl.resume`):
        kept since the stop, or homed and travelled back, or confirmed by a person."""
        stop = check_point(point, job)
        link, profile = self.link, self.profile
        st = link.status()
        if st.state != "Idle" and not profile.motors.endstops:
            raise GrblResumeError(f"{link.url}: the board is in {st.state}; clear it ($X) and "
                                  "run this command again. Nothing was sent.")
        n = job.n_segments
        if st.state == "Idle" and self.position_steps(st) == stop:
            operator.note(f"resuming segment {point.next_segment} of {n} from A = {stop[0]}, "
                          f"B = {stop[1]} steps: the board kept its position since the stop "
                          "(exact)")
            return point.next_segment, stop
        if profile.motors.endstops:
            link.command("$H", timeout_s=120.0)
            link.command(work_offset_line(profile))
            pos = self.position_steps(link.status())
            operator.note("the board lost its position: homed; travelling back to the stop, "
                          "laser off")
            self._travel(job.assembly, pos, stop)
            return point.next_segment, stop
        a, b = (math.degrees(profile.motors.home_rad[i]) + stop[i] * 360.0
                / profile.motors.steps_per_rev for i in range(2))
        if not operator.confirm_placed(
                f"GRBL lost its count since the stop (it rebooted when the port opened, or "
                f"lost power). Are the arms still exactly where the job stopped (θ1 = "
                f"{a:.4f}°, θ2 = {b:.4f}°)?"):
            raise PowerLossError(
                f"{link.url}: GRBL's position since the stop is unknown, and --yes does not "
                "answer for where the arms are after a reboot or power loss. Run this "
                "command on a terminal without --yes and confirm there, or home and run the "
                "job again. Nothing was sent.")
        st = link.status()
        link.command(f"G10 L2 P1 X{st.machine[0] - a:.4f} Y{st.machine[1] - b:.4f}")
        pos = self.position_steps(link.status())
        if pos != stop:
            raise GrblResumeError(f"{link.url}: the work offset did not take (A = {pos[0]}, "
                                  f"B = {pos[1]} steps, wanted {stop}). Nothing was sent.")
        operator.note(f"resuming segment {point.next_segment} of {n} from the confirmed stop "
                      f"position A = {stop[0]}, B = {stop[1]} steps")
        return point.next_segment, stop

    # ------------------------------------------------------------------ the host's moves
    def _travel(self, assembly: int, start: Position, end: Position) -> None:
        """A checked laser-off joint-space travel (fivebar's own, ramped) and wait for it."""
        self.run_moves(travel(self.profile, assembly, start, end, "travel to the job's start"),
                       start)

    def run_moves(self, moves: Program, position: Position) -> Position:
        """Run fivebar's checked laser-off moves (jog, frame, travel) on the board."""
        self.link.stream(from_program(self.profile, moves, position))
        return self.position_steps(self.link.wait_idle(120.0))

    def motors_off(self) -> Status:
        raise UsageError(f"motors off: {self.features.motors_off}")

    def pen(self, down: bool) -> Status:
        """Lower or raise a servo pen on GRBL's spindle output (M3 S<position>, then the
        servo's move time as G4)."""
        self.link.stream(tool_lines(self.profile, False, down, None, 0))
        self.link.wait_idle(30.0)
        return self.status()
