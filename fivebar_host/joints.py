"""The profile's `[joints]`: stepper joints (the `[motors]` drive train) or hobby servos.

Host side only (issue 38): a servo profile declares each arm servo's pulse range, centre,
direction, speed and dead band, the refresh rate, and a pulse ↔ angle curve (a measured
table, a low-order fit of it, or a straight line through the centre); `ServoJoints.pulses`
turns a job's joint angles into the pulse targets the servo firmware is to be sent (quantised
to its 0.5 µs, dead band compensated, `kinematics.servo`). fivebar's servo firmware runs it
(`controllers.fivebar.servo`: the step grid ↔ pulse ticks); another controller refuses it
(`require_stepper_joints`); the dry run plans and previews it in joint angles.

```toml
[joints]
kind = "servo"                        # "stepper" (default) or "servo"
refresh_hz = 50.0                     # pulses per second
pulse_range_us = [[600, 2400], [600, 2400]]
centre_us = [1500, 1500]              # the pulse at centre_deg
centre_deg = [90.0, 90.0]             # joint angle there (from +x, counter-clockwise)
direction = [1, 1]                    # +1: a longer pulse turns the joint counter-clockwise
us_per_deg = [10.0, 10.0]             # the straight line's slope (no table given)
speed_s_per_60deg = [0.12, 0.12]      # the servo's rated speed
dead_band_deg = [1.0, 1.0]            # width of the direction-dependent dead band
curve_us = [[600, 1050, 1500, 1950, 2400], [600, 1500, 2400]]  # optional: measured pulses …
curve_deg = [[2.0, 46.5, 90.0, 133.0, 178.5], [1.0, 90.0, 179.5]]  # … and joint angles
curve_fit = "table"                   # the table as measured, or "cubic": a cubic fit of it
```
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from fivebar_host.errors import FivebarError, UsageError
from kinematics.arrays import FloatArray
from kinematics.servo import ServoCurve, ServoError, dead_band_commands, quantise_us

JOINT_KINDS = ("stepper", "servo")
CURVE_FITS = ("table", "cubic")
#: The pulses a hobby servo takes (the pen servo's range too).
SERVO_LIMITS_US = (500.0, 2500.0)


@dataclass(frozen=True)
class ServoJoint:
    """One arm servo: its curve (over its pulse range), rated speed and dead band."""

    curve: ServoCurve
    speed_s_per_60deg: float
    dead_band_rad: float

    @property
    def max_rad_s(self) -> float:
        """The rated speed as a joint speed limit, rad/s."""
        return (math.pi / 3.0) / self.speed_s_per_60deg


@dataclass(frozen=True)
class ServoJoints:
    """Both arm servos and their refresh rate."""

    joints: tuple[ServoJoint, ServoJoint]
    refresh_hz: float

    def pulses(self, angles_rad: ArrayLike) -> FloatArray:
        """Pulse targets (N, 2) µs for joint angles (N, 2) rad visited in order: each joint's
        dead band compensated (`kinematics.servo.dead_band_commands`), mapped through its
        curve and quantised to 0.5 µs. Raises `ServoError` for an angle outside a servo's
        range (after the overshoot)."""
        th = np.asarray(angles_rad, dtype=np.float64).reshape(-1, 2)
        out = np.empty_like(th)
        for i, j in enumerate(self.joints):
            cmd = dead_band_commands(th[:, i], j.dead_band_rad)
            out[:, i] = quantise_us(j.curve.pulse(cmd))
        return out

    @property
    def max_joint_rad_s(self) -> float:
        """The slower servo's rated speed, rad/s."""
        return min(j.max_rad_s for j in self.joints)


class _Reader:
    """Reads `[joints]` keys with the profile's messages (a `config._Table`)."""

    def __init__(self, table: Any) -> None:
        self.t = table

    def pair_list(self, key: str, lo: float, hi: float) -> list[list[float]]:
        v = self.t.get(key)
        if (not isinstance(v, list) or len(v) != 2
                or not all(isinstance(r, list) and r and all(
                    isinstance(x, int | float) and not isinstance(x, bool) for x in r)
                    for r in v)):
            raise FivebarError(f"{self.t.where(key)}: must be two lists of numbers (one per "
                               f"servo); got {v!r}")
        for r in v:
            if not all(lo <= float(x) <= hi for x in r):
                raise FivebarError(f"{self.t.where(key)}: values must lie in [{lo:g}, {hi:g}]"
                                   f"; got {v!r}")
        return [[float(x) for x in r] for r in v]


def parse_joints(t: Any) -> ServoJoints | None:
    """`[joints]` (a `config._Table`, None when the profile has none): None for stepper
    joints, else the servos. Errors name the key (the caller makes them `ConfigError`)."""
    if t is None:
        return None
    joints = _parse_servos(t) if t.choice("kind", JOINT_KINDS) == "servo" else None
    t.done()
    return joints


def _parse_servos(t: Any) -> ServoJoints:
    """The servo keys of `[joints]` (module doc)."""
    rd = _Reader(t)
    lo, hi = SERVO_LIMITS_US
    refresh = t.number("refresh_hz", 1.0, 1000.0)
    rng = rd.pair_list("pulse_range_us", lo, hi)
    centre_us = t.pair("centre_us", lo, hi)
    centre_deg = t.pair("centre_deg", -360.0, 360.0)
    direction = t.pair("direction", -1.0, 1.0)
    us_per_deg = t.pair("us_per_deg", 0.1, 1000.0)
    speed = t.pair("speed_s_per_60deg", 0.01, 10.0)
    dead = t.pair("dead_band_deg", 0.0, 30.0)
    table = None
    if "curve_us" in t.raw or "curve_deg" in t.raw:
        table = (rd.pair_list("curve_us", lo, hi), rd.pair_list("curve_deg", -360.0, 360.0))
        fit = t.choice("curve_fit", CURVE_FITS) if "curve_fit" in t.raw else "table"
    joints = []
    for i in range(2):
        if len(rng[i]) != 2 or not rng[i][0] < rng[i][1]:
            raise FivebarError(f"{t.where('pulse_range_us')}[{i}]: must be [low, high] µs, "
                               f"low < high; got {rng[i]!r}")
        if direction[i] not in (-1.0, 1.0):
            raise FivebarError(f"{t.where('direction')}[{i}]: must be 1 or -1; got "
                               f"{direction[i]:g}")
        try:
            if table is None:
                curve = ServoCurve.linear(centre_us[i], math.radians(centre_deg[i]),
                                          direction[i] * us_per_deg[i] * 180.0 / math.pi,
                                          (rng[i][0], rng[i][1]))
            else:
                p, a = np.array(table[0][i]), np.radians(table[1][i])
                curve = (ServoCurve(p, a) if fit == "table" else ServoCurve.fit(p, a, 3))
        except ServoError as e:
            raise FivebarError(f"{t.where('curve_us' if table else 'us_per_deg')}[{i}]: "
                               f"{e}") from e
        if curve.range_us[0] < rng[i][0] or curve.range_us[1] > rng[i][1]:
            raise FivebarError(f"{t.where('curve_us')}[{i}]: pulses outside pulse_range_us "
                               f"{rng[i]!r}")
        rising = curve.angle_rad[-1] > curve.angle_rad[0]
        if rising != (direction[i] > 0):
            raise FivebarError(f"{t.where('direction')}[{i}] = {direction[i]:g} disagrees with "
                               "the curve table (a longer pulse turns that joint the other way)")
        joints.append(ServoJoint(curve, speed[i], math.radians(dead[i])))
    return ServoJoints((joints[0], joints[1]), refresh)


def servo_backlash_steps(joints: ServoJoints, motors: Any, source: str) -> tuple[int, int]:
    """A servo profile's `[motors] backlash_steps`: its dead bands on the step grid. A servo's
    output stays within ±w/2 of its command (kinematics.servo Eq. S1): the play j ∈ [m − B,
    m] of a count m = command + B/2 with B = w in steps (compile/backlash.py Eq. B1). So the
    dead bands, rounded to whole steps, are taken up at every reversal like a stepper's
    slack, and `ServoMap` sends each count less B/2 (controllers/fivebar/servo.py).
    `motors` (a `config.Motors`) must have its own backlash_steps (0, 0)."""
    if any(motors.backlash_steps):
        raise FivebarError(f"{source}: [motors] backlash_steps: a servo profile's slack is "
                           "its [joints] dead_band_deg (leave backlash_steps at [0, 0])")
    b = [round(j.dead_band_rad / motors.rad_per_step) for j in joints.joints]
    return b[0], b[1]


def require_stepper_joints(joints: ServoJoints | None, source: str) -> None:
    """Refuse to run a job on servo joints with a controller other than fivebar's (only
    fivebar's servo build drives arm servos: docs/protocol.md 6.5)."""
    if joints is not None:
        raise UsageError(f"{source}: [joints] kind = \"servo\": only fivebar's servo "
                         "firmware drives arm servos (--controller fivebar, make -C firmware "
                         "SERVO=1); --dry-run plans and previews the job")
