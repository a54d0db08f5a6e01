"""Manual machine actions between jobs: home, jog, pen, motors off, clear an alarm; the pose.

Each action comes as a request (server.requests) and `Manual.perform` carries it out on the
machine thread, which takes requests between jobs, so an action never interleaves with a
job's stream; one asked for while a job runs (or the machine is not connected, or the daemon
stops) is refused with what to do. The moves are the CLI's, through fivebar's controller:
homing as `fivebar home` (`$H` with endstops, else `G92 A0 B0` once the person confirms the
arms are at the home pose), `fivebar jog`'s `run.moves.jog_program` (laser off; a pen move is
checked against reach, joint limits and singularity margins, and needs a known position; a
motor move before homing is not checked, as `fivebar jog` says), the pen as `fivebar pen`,
`M18` for motors off; and `$X` on the link to clear an alarm.

Motors off leaves the arms free to move, so the daemon forgets the pose; the next motion
(a job, a jog, homing) switches the motors on first (`M17`, `PoseKeeper.motors_on`).

`pose_mm` turns firmware steps into the pen's point and the elbows (machine mm) for the web
page's live view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError
from fivebar_host.run.errors import SendError
from fivebar_host.run.moves import jog_program
from fivebar_host.run.operator import Answering
from fivebar_host.server.pose import PoseKeeper
from fivebar_host.server.requests import ClearAlarm, Home, Jog, MachineAction, MotorsOff, Pen
from fivebar_host.server.state import ActionError, Connection, MachineRecord

log = logging.getLogger("fivebar.serve")


@dataclass(frozen=True)
class Pose:
    """The linkage at a motor position, machine mm: M1, R1, P, R2, M2 (with the joint J of
    the distal links after P when the pen is off it) and the working mode."""

    pen: tuple[float, float]
    points: tuple[tuple[float, float], ...]  # M1, R1, P, [J,] R2, M2
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
    j = fb.joint_from_pen(r1, fk.points)[0]
    joint = () if np.array_equal(j, p) else ((float(j[0]), float(j[1])),)
    pts = ((0.0, 0.0), (float(r1[0, 0]), float(r1[0, 1])), (float(p[0]), float(p[1])),
           *joint, (float(r2[0, 0]), float(r2[0, 1])), (float(fb.w), 0.0))
    return Pose((float(p[0]), float(p[1])), pts, mode)




class Manual:
    """The manual actions (module docstring); machine thread only."""

    def __init__(self, record: MachineRecord, profile: Profile, pose: PoseKeeper) -> None:
        self.record = record
        self.profile = profile
        self.pose = pose

    def perform(self, action: MachineAction) -> None:
        """Carry out `action` now, or refuse it (`ActionError`, saying why)."""
        if isinstance(action, Home):
            self._home(action.at_home)
        elif isinstance(action, Jog):
            self._jog(action)
        elif isinstance(action, Pen):
            self._pen(action.down)
        elif isinstance(action, MotorsOff):
            self._motors_off()
        else:
            assert isinstance(action, ClearAlarm)
            self._clear_alarm()

    def _connection(self) -> Connection:
        """The connection, unless the machine is not connected or the daemon stops."""
        rec = self.record
        if rec.conn is None:
            raise ActionError(f"the machine is not connected ({rec.error})")
        if rec.terminate:
            raise ActionError("the daemon is stopping")
        return rec.conn

    def _idle_machine(self, what: str) -> Connection:
        """The connection, unless a job runs, the machine is not connected or the daemon
        stops."""
        if self.record.current is not None:
            raise ActionError(f"job {self.record.current} is running: pause and cancel it, or "
                              f"wait for it to end, before you {what}")
        return self._connection()

    def _home(self, at_home: bool) -> None:
        """Home the machine: `$H` with endstops, else `G92 A0 B0` once the person confirms."""
        conn = self._connection()
        if self.record.current is not None:
            raise ActionError(f"job {self.record.current} is running: cancel it before homing")
        if not self.profile.motors.endstops and not at_home:
            raise ActionError("the machine has no endstops: place the arms at the home pose "
                              "and confirm with at_home=true")
        self.pose.motors_on(conn.link)
        conn.controller.home(Answering(at_home))
        self.pose.set(True, conn.link.last_status)

    def _jog(self, jog: Jog) -> None:
        """Move one motor by steps, or the pen by mm (laser off), as `fivebar jog`."""
        motor, dxy_mm = jog.motor, jog.dxy_mm
        if (motor is None) == (dxy_mm is None):
            raise ActionError("jog either a motor (motor and steps) or the pen (dx, dy mm)")
        conn = self._idle_machine("jog")
        st = conn.controller.status()
        if st.state == "Alarm":
            raise ActionError("the machine is in alarm: clear the alarm first")
        prof = self.profile
        checked = self.record.pose_known
        if motor is None and not checked:
            raise ActionError("the pen's position is unknown: home the machine first "
                              "(a motor jog works before homing)")
        mode = prof.kinematics.working_mode
        if checked:
            pose = pose_mm(prof, *st.position)
            if pose is None:
                raise ActionError("the motor position does not close the linkage: home "
                                  "the machine")
            mode = pose.mode
        assembly = 1 if prof.kinematics.assembly == "+" else -1
        try:
            prog = jog_program(prof, assembly, mode, st.position, motor=motor,
                               steps=jog.steps, dxy_mm=dxy_mm, checked=checked)
        except (SendError, FivebarError) as e:
            raise ActionError(str(e)) from e
        self.pose.motors_on(conn.link)
        a, b = conn.controller.run_moves(prog, st.position)
        if checked:
            self.pose.set(True, conn.link.last_status)
        log.info("jog %s: now at A = %d, B = %d%s", motor or f"pen {dxy_mm}", a, b,
                 "" if checked else " (position unknown: not checked)")

    def _motors_off(self) -> None:
        """Switch the motors off (`M18`): the arms move freely, the pose is forgotten."""
        conn = self._idle_machine("switch the motors off")
        conn.controller.motors_off()
        self.record.motors_off = True
        self.pose.set(False, conn.link.last_status)
        log.info("motors off (M18): the pose is unknown until the machine is homed")

    def _pen(self, down: bool) -> None:
        """Lower or raise the servo pen (the profile's [pen]: `$14` park pulse, then the
        `M280` block, docs/protocol.md 6.2), as `fivebar pen up|down`."""
        pen = self.profile.pen
        if pen is None:
            raise ActionError(f"{self.profile.source}: no [pen] table: this machine's "
                              "tool is a laser")
        conn = self._idle_machine("move the pen")
        conn.controller.pen(down)
        log.info("pen %s (%d µs)", "down" if down else "up",
                 pen.pulse_us(pen.down_position if down else pen.up_position))

    def _clear_alarm(self) -> None:
        """Clear an alarm (`$X` on the link: fivebar's firmware; the position is kept)."""
        link = self._idle_machine("clear the alarm").link
        link.status()
        link.take_alarm_pushes()  # the alarm being cleared, not a fault of `$X`
        link.command("$X")
        st = link.status()
        log.info("alarm cleared ($X): %s", st.state)
