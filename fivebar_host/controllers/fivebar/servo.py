"""fivebar's servo firmware (`make -C firmware SERVO=1`, docs/protocol.md 6.5) behind the
same `Link`: the host plans a servo profile's job on the `[motors]` step grid as for
steppers (steps from the home pose), and `ServoLink` turns every position it sends into
the firmware's steps — pulse ticks of 0.5 µs — and every position it reads back into
steps again, so the controller, the stream, exact resume and the reports are unchanged.

    ticks = rint(2 · curve.pulse(θ_home + (steps − B/2) · rad_per_step))                (T1)
    steps = rint((curve.angle(ticks / 2) − θ_home) / rad_per_step + B/2)               (T2)

A segment is a straight line in ticks between its two targets (the firmware's DDA), a
chord of the servo curve: on a straight-line curve exactly the planned joint line, on a
table or a fit within the curve's bend over one segment. T2∘T1 is the identity while one
step is at least a tick's angle (the `[motors]` grid no finer than the pulse quantum), so
a position read back is the one sent.

The dead band is compensated on a run as a stepper's backlash is: a servo's output stays
within ±w/2 of its command (kinematics.servo Eq. S1), which is the play j ∈ [m − B, m]
(compile/backlash.py Eq. B1) of a count m = command + B/2 with B = w in steps. The profile
makes the dead bands its `[motors] backlash_steps` (config.py), the compiler takes the slack
up at every reversal (the counts step by ±B while the arm stays), and T1/T2 shift by B/2: a
joint that last moved up is sent its target + w/2, one that last moved down its target −
w/2, the overshoot `kinematics.servo.dead_band_commands` plans.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fivebar_host.errors import FivebarError
from fivebar_host.program import ABSENT, Kind, Program
from fivebar_host.protocol import Message, StatusReport
from fivebar_host.wire import read_lines
from kinematics.arrays import IntArray
from kinematics.servo import ServoCurve, ServoError

from .link import Link

if TYPE_CHECKING:
    from fivebar_host.config import Profile
    from fivebar_host.joints import ServoJoints

#: Pulse ticks per µs of the servo firmware (config.h CFG_SERVO_TICKS_US).
TICKS_PER_US = 2


@dataclass(frozen=True)
class ServoMap:
    """Steps on the profile's grid ↔ the servo firmware's pulse ticks, per joint (T1, T2)."""

    curves: tuple[ServoCurve, ServoCurve]
    home_rad: tuple[float, float]
    rad_per_step: float
    #: B/2 per joint, steps: the counts exceed the command by half the dead band (T1, T2)
    offset_steps: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def of(cls, joints: ServoJoints, profile: Profile) -> ServoMap:
        """The map of a servo profile (its dead bands as `[motors] backlash_steps`)."""
        c = (joints.joints[0].curve, joints.joints[1].curve)
        b = profile.motors.backlash_steps
        return cls(c, profile.motors.home_rad, profile.motors.rad_per_step,
                   (0.5 * b[0], 0.5 * b[1]))

    def ticks(self, joint: int, steps: IntArray) -> IntArray:
        """T1: the pulse ticks of positions in steps (ABSENT stays ABSENT)."""
        s = np.asarray(steps, dtype=np.int64)
        keep = s == ABSENT
        th = self.home_rad[joint] + (np.where(keep, 0, s) - self.offset_steps[joint]) * (
            self.rad_per_step)
        try:
            us = self.curves[joint].pulse(th)
        except ServoError as e:
            raise FivebarError(f"servo {'AB'[joint]}: {e}") from e
        return np.where(keep, ABSENT, np.rint(us * TICKS_PER_US).astype(np.int64))

    def steps(self, joint: int, ticks: int) -> int:
        """T2: the position in steps of a servo at `ticks` (outside the curve: clipped)."""
        lo, hi = self.curves[joint].range_us
        us = min(max(ticks / TICKS_PER_US, lo), hi)
        th = float(self.curves[joint].angle(us))
        return math.floor((th - self.home_rad[joint]) / self.rad_per_step
                          + self.offset_steps[joint] + 0.5)

    def program(self, prog: Program) -> Program:
        """A program with its moves' targets and its set positions (`G92`) in ticks."""
        mapped = (prog.kind == Kind.MOVE) | (prog.kind == Kind.SET_POSITION)
        a, b = prog.a.copy(), prog.b.copy()
        a[mapped] = self.ticks(0, a[mapped])
        b[mapped] = self.ticks(1, b[mapped])
        return replace(prog, a=a, b=b)


class ServoLink(Link):
    """A `Link` to the servo firmware: positions out in ticks, back in steps (module doc)."""

    servo: ServoMap | None = None

    def _parse(self, raw: str) -> Message:  # type: ignore[override]
        msg = Link._parse(raw)
        if isinstance(msg, StatusReport) and self.servo is not None:
            return dataclasses.replace(msg, a=self.servo.steps(0, msg.a),
                                       b=self.servo.steps(1, msg.b))
        return msg

    def stream(self, program: Program | Sequence[str], **kwargs: Any) -> Any:
        """`Link.stream` of the program in ticks."""
        if not isinstance(program, Program):
            program = read_lines(program)
        if self.servo is not None:
            program = self.servo.program(program)
        return super().stream(program, **kwargs)


def open_servo_link(url: str, profile: Profile, joints: ServoJoints, **kwargs: Any) -> Link:
    """Open the servo firmware at `url` (an emulator URL gets `servo=1`: the servo build)
    and check that its banner says `joints:servo`."""
    from fivebar_host.devices.simport import SCHEME

    if url.startswith(f"{SCHEME}://") and "servo=" not in url:
        url += ("&" if "?" in url else "?") + "servo=1"
    link = ServoLink.open(url, **kwargs)
    assert isinstance(link, ServoLink)
    if link.banner is None or link.banner.joints != "servo":
        link.close()
        raise FivebarError(f"{url}: the profile's joints are servos ([joints] kind = "
                           "\"servo\") but the firmware is the stepper build: flash the "
                           "servo build (make -C firmware SERVO=1, docs/protocol.md 6.5)")
    link.servo = ServoMap.of(joints, profile)
    return link
