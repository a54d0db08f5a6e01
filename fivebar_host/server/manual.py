"""Manual machine actions between jobs: jog, motors off, clear an alarm; and the pen's pose.

Like `home` (server.control), each action is queued with `run_action` and runs on the
machine thread between jobs, so it never interleaves with a job's stream; a request while a
job runs is refused at once (nothing is queued). The moves are the CLI's: `fivebar jog`'s
`run.moves.jog_program` (laser off; a pen move is checked against reach, joint limits and
singularity margins, and needs a known position; a motor move before homing is not checked,
as `fivebar jog` says), `M18` for motors off and `$X` to clear an alarm.

Motors off leaves the arms free to move, so the daemon forgets the pose; the next motion
(a job, a jog, homing) switches the motors on first (`M17`, `MachineState._motors_on`).

`pose_mm` turns firmware steps into the pen's point and the elbows (machine mm) for the web
page's live view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from fivebar_host.compile.emit import pen_move
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError
from fivebar_host.protocol import StatusReport
from fivebar_host.run.errors import SendError
from fivebar_host.run.moves import jog_program
from fivebar_host.server.control import Control
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.machine import ActionError

log = logging.getLogger("fivebar.serve")

#: Longest a manual action may wait for its turn and run, s.
ACTION_TIMEOUT_S = 120.0


@dataclass(frozen=True)
class Pose:
    """The linkage at a motor position, machine mm: M1, R1, P, R2, M2 and the working mode."""

    pen: tuple[float, float]
    points: tuple[tuple[float, float], ...]  # M1, R1, P, R2, M2
    mode: str


def pose_mm(profile: Profile, a: int, b: int) -> Pose | None:
    """The pen point and linkage for firmware steps (A, B); None where the loop does not close."""
    fb, mo = profile.geometry, profile.motors
    th = step_angles(np.array([[a, b]]), mo.home_rad, mo.steps_per_rev)
    fk = fb.forward_batch(th, profile.kinematics.assembly)
    if not fk.valid[0]:
        return None
    p = fk.points[0]
    r1, r2 = fb.elbows(th)
    signs = fb.mode_of(fk.points, th)[0]
    mode = "".join("+" if s >= 0 else "-" for s in signs)
    pts = ((0.0, 0.0), (float(r1[0, 0]), float(r1[0, 1])), (float(p[0]), float(p[1])),
           (float(r2[0, 0]), float(r2[0, 1])), (float(fb.w), 0.0))
    return Pose((float(p[0]), float(p[1])), pts, mode)


class Manual(Control):
    """Jog, motors off and clear alarm (any thread asks; the machine thread acts)."""

    def _idle_machine(self, what: str) -> None:
        """Refuse an action while a job runs or the machine is not connected."""
        if self.current is not None:
            raise ActionError(f"job {self.current} is running: pause and cancel it, or wait "
                              f"for it to end, before you {what}")
        if self.link is None:
            raise ActionError(f"the machine is not connected ({self.error})")

    def jog(self, *, motor: str | None = None, steps: int = 0,
            dxy_mm: tuple[float, float] | None = None) -> StatusReport:
        """Move one motor by `steps`, or the pen by `dxy_mm` (laser off), as `fivebar jog`."""
        if (motor is None) == (dxy_mm is None):
            raise ActionError("jog either a motor (motor and steps) or the pen (dx, dy mm)")
        self._idle_machine("jog")

        def act(link: JournalLink) -> StatusReport:
            if self.current is not None:
                raise ActionError(f"job {self.current} is running")
            st = link.status()
            if st.state == "Alarm":
                raise ActionError("the machine is in alarm: clear the alarm first")
            prof = self.cfg.profile
            checked = self.pose_known
            if motor is None and not checked:
                raise ActionError("the pen's position is unknown: home the machine first "
                                  "(a motor jog works before homing)")
            mode = prof.kinematics.working_mode
            if checked:
                pose = pose_mm(prof, st.a, st.b)
                if pose is None:
                    raise ActionError("the motor position does not close the linkage: home "
                                      "the machine")
                mode = pose.mode
            assembly = 1 if prof.kinematics.assembly == "+" else -1
            try:
                prog = jog_program(prof, assembly, mode, (st.a, st.b), motor=motor,
                                   steps=steps, dxy_mm=dxy_mm, checked=checked)
            except (SendError, FivebarError) as e:
                raise ActionError(str(e)) from e
            self._motors_on(link)
            res = link.stream(prog)
            st = link.wait_idle(max(30.0, 3.0 * res.elapsed_s), last_line=res.last_line)
            if checked:
                self._set_pose(True, st)
            log.info("jog %s: now at A = %d, B = %d%s", motor or f"pen {dxy_mm}", st.a, st.b,
                     "" if checked else " (position unknown: not checked)")
            return st

        result: StatusReport = self.run_action(act, ACTION_TIMEOUT_S)
        return result

    def motors_off(self) -> StatusReport:
        """Switch the motors off (`M18`): the arms move freely, the pose is forgotten."""
        self._idle_machine("switch the motors off")

        def act(link: JournalLink) -> StatusReport:
            link.command("M18")
            st = link.wait_idle(30.0)
            self.motors_disabled = True
            self._set_pose(False, st)
            log.info("motors off (M18): the pose is unknown until the machine is homed")
            return st

        result: StatusReport = self.run_action(act, ACTION_TIMEOUT_S)
        return result

    def pen(self, down: bool) -> StatusReport:
        """Lower or raise the servo pen (the profile's [pen]: `$14` park pulse, then the
        `M280` block, docs/protocol.md 6.2), as `fivebar pen up|down`."""
        pen = self.cfg.profile.pen
        if pen is None:
            raise ActionError(f"{self.cfg.profile.source}: no [pen] table: this machine's "
                              "tool is a laser")
        self._idle_machine("move the pen")

        def act(link: JournalLink) -> StatusReport:
            link.command(pen_move(self.cfg.profile, down))
            st = link.wait_idle(30.0)
            log.info("pen %s (%d µs)", "down" if down else "up",
                     pen.pulse_us(pen.down_position if down else pen.up_position))
            return st

        result: StatusReport = self.run_action(act, ACTION_TIMEOUT_S)
        return result

    def clear_alarm(self) -> StatusReport:
        """Clear an alarm (`$X`; the position is kept)."""
        self._idle_machine("clear the alarm")

        def act(link: JournalLink) -> StatusReport:
            link.status()
            link.take_alarm_pushes()  # the alarm being cleared, not a fault of `$X`
            link.command("$X")
            st = link.status()
            log.info("alarm cleared ($X): %s", st.state)
            return st

        result: StatusReport = self.run_action(act, ACTION_TIMEOUT_S)
        return result
