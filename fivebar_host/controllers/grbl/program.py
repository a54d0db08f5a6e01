"""A stock GRBL 1.1 board driving the five-bar in joint space: its `$` settings and the lines.

Pure (no I/O). GRBL's X and Y axes carry the motor angles A and B in degrees (`$100`/`$101`
steps per degree); the work coordinates are set at the home pose with `G10 L20 P1 X<home A>
Y<home B>`, so work X/Y = the motor angle from +x, and machine X/Y = the angle from the home
pose (GRBL's machine position restarts at 0 where the board boots; fivebar's absolute steps
count from the home pose too, so GRBL's machine steps *are* fivebar's steps).

Each job segment k (targets k → k+1, absolute steps quantised once by the compiler) becomes
`G1 X<θA> Y<θB> F<f>` with θ = home + steps / steps-per-degree (4 decimals: 0.0018 step) and
f = 60·|Δθ| / P deg/min, |Δθ| the Euclidean length of the segment in degrees and P its planned
duration: GRBL's feed is the vector rate over the block's axis units, so at its nominal rate
GRBL runs the block in exactly P. The path is exact (X and Y interpolate linearly in joint
space, and GRBL rounds the same targets to the same steps); the timing is not, because GRBL
plans its own acceleration ramps (`$120`/`$121`) and junction speeds (`$11`): docs/grbl.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fivebar_host import wire
from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.program import Kind, Program, line_param
from kinematics.arrays import FloatArray

#: GRBL's `$30` the host asks for (maximum S); laser power 0–255 is scaled onto 0…$30.
S_MAX = 1000
#: The board's settings are compared at the precision `$$` prints (3 decimals).
SETTING_TOLERANCE = 0.0015


@dataclass(frozen=True)
class Setting:
    """One `$N=value` the board needs, and why."""

    number: int
    value: float
    why: str
    decimals: int = 3

    def text(self) -> str:
        """`$100=35.555556` as it is written to the board (enough digits for float32)."""
        return f"${self.number}={self.value:.{self.decimals}f}"

    def matches(self, board: float) -> bool:
        """Whether the board's value (as `$$` prints it) is this one. `$10` needs bit 0
        (MPos reported) only."""
        if self.number == 10:
            return int(board) & 1 == 1
        return abs(board - self.value) <= SETTING_TOLERANCE * max(1.0, abs(self.value) / 1e4)


def steps_per_degree(profile: Profile) -> float:
    """Full steps × microsteps × gear ratio / 360."""
    return profile.motors.steps_per_rev / 360.0


def soft_limits(profile: Profile) -> tuple[bool, float, float]:
    """(enable `$20`, `$27` pull-off, travel) — GRBL's soft limits are machine 0 … −`$13x`
    after homing toward + (`$23=0`), machine 0 being where the switch released, `$27`
    beyond the homed pose. They mirror the profile's joint limits only when the board homes
    (endstops) and both joints' upper limits lie the same angle p above the home pose:
    `$27` = p, `$130`/`$131` = the joint ranges. Otherwise soft limits stay off (`$20=0`) and
    the host checks every target against the joint limits before sending (it always does)."""
    m = profile.motors
    hi = [math.degrees(v[1]) for v in m.limits_rad]
    home = [math.degrees(v) for v in m.home_rad]
    pull = [hi[i] - home[i] for i in range(2)]
    ok = bool(m.endstops) and abs(pull[0] - pull[1]) < 1e-6 and pull[0] > 0
    return ok, pull[0] if ok else 1.0, 0.0


def needed_settings(profile: Profile) -> list[Setting]:
    """The `$` settings the board needs for this profile (`fivebar grbl-settings`): laser
    mode on, unless the profile has a servo pen (a GRBL servo build, `$32=0`). The reasons
    are plain ASCII: they ride on the lines as `;` comments, and GRBL takes bytes ≥ 0x80 as
    real-time commands (UTF-8's 0x94 or 0x97 would be feed or rapid overrides)."""
    m, mo = profile.motors, profile.motion
    spd = steps_per_degree(profile)
    rate = math.degrees(mo.max_joint_rad_s) * 60.0
    acc = math.degrees(mo.max_joint_rad_s2)
    span = [math.degrees(v[1] - v[0]) for v in m.limits_rad]
    soft, pull, _ = soft_limits(profile)
    servo = profile.pen is not None
    motors = f"{m.full_steps:g} x {m.microsteps:g} x {m.gear_ratio:g} / 360"
    return [
        Setting(10, 1, "status reports MPos (machine position in degrees)", 0),
        Setting(13, 0, "report in the machine's units (degrees), not inches", 0),
        Setting(20, 1 if soft else 0, "soft limits = joint limits" if soft else
                "soft limits off: GRBL's 0...-travel cannot mirror these joint limits; the "
                "host checks every target", 0),
        Setting(22, 1 if m.endstops else 0, "homing cycle" if m.endstops else
                "no endstops: no homing cycle", 0),
        Setting(27, pull, "homing pull-off = upper joint limit - home angle" if soft else
                "homing pull-off (unused)"),
        Setting(30, S_MAX, "maximum S: laser power 255 = S1000" if not servo else
                "maximum S: servo pulse 0.5 ms = S0, 2.5 ms = S1000", 0),
        Setting(31, 0, "minimum S", 0),
        Setting(32, 0 if servo else 1,
                "laser mode (M4 power follows speed, off in G0 and holds)" if not servo
                else "laser mode off: a spindle/servo change waits for motion", 0),
        Setting(100, spd, f"A motor steps per degree: {motors}", 6),
        Setting(101, spd, f"B motor steps per degree: {motors}", 6),
        Setting(110, rate, f"A max rate, deg/min (max_joint_rad_s {mo.max_joint_rad_s:g})"),
        Setting(111, rate, f"B max rate, deg/min (max_joint_rad_s {mo.max_joint_rad_s:g})"),
        Setting(120, acc, f"A acceleration, deg/s^2 (max_joint_rad_s2 {mo.max_joint_rad_s2:g})"),
        Setting(121, acc, f"B acceleration, deg/s^2 (max_joint_rad_s2 {mo.max_joint_rad_s2:g})"),
        Setting(130, span[0], "A travel = joint range, degrees"),
        Setting(131, span[1], "B travel = joint range, degrees"),
    ]


def settings_differences(profile: Profile, board: dict[int, float]) -> list[str]:
    """Every needed setting the board's `$$` does not hold, as `$N: board X, needed Y
    (why)`. `$130`/`$131` matter only when soft limits are on."""
    soft = soft_limits(profile)[0]
    out = []
    for s in needed_settings(profile):
        if s.number in (27, 130, 131) and not soft:
            continue
        have = board.get(s.number)
        if have is None:
            out.append(f"${s.number}: not reported by the board, needed {s.text()} ({s.why})")
        elif not s.matches(have):
            out.append(f"${s.number}: board {have:g}, needed {s.text()[len(str(s.number)) + 2:]}"
                       f" ({s.why})")
    return out


def work_offset_line(profile: Profile) -> str:
    """At the home pose: work X/Y become the motor angles in degrees from +x."""
    h = [math.degrees(v) for v in profile.motors.home_rad]
    return f"G10 L20 P1 X{h[0]:.4f} Y{h[1]:.4f}"


def angles_deg(profile: Profile, steps: ArrayLike) -> FloatArray:
    """Absolute steps (from the home pose) → work X/Y degrees."""
    home = np.degrees(np.asarray(profile.motors.home_rad))
    out: FloatArray = home + np.asarray(steps, dtype=np.float64) / steps_per_degree(profile)
    return out


@dataclass(frozen=True)
class GrblProgram:
    """G-code lines for the board and, per line, the job segment it executes (−1: none)."""

    lines: list[str]
    segment: np.ndarray

    def segment_at(self, steps: tuple[int, int], job: Job, acked: int) -> int:
        """The first segment not finished when the machine stands at `steps` (machine
        steps), searching back from the last acknowledged line: GRBL acknowledges a line
        once planned, so the executing one is at most 15 blocks (plus what its ring holds)
        before it. Exact unless the path passes the same point twice in that window."""
        seg = self.segment[: max(acked, 0)]
        seg = seg[seg >= 0]
        if seg.size == 0:
            return 0
        last = int(seg.max())
        for k in range(last, max(-1, last - 64), -1):
            t = line_param(job.steps[k], job.steps[k + 1], steps)
            if t is not None:
                return k + 1 if t >= 1.0 else k
        return last + 1

    def candidates(self, steps: tuple[int, int], job: Job, lo: int, hi: int) -> list[int]:
        """Every first-unfinished segment the lines `lo` … `hi − 1` allow for a machine
        standing at `steps`: segment k when `steps` lies on k's joint-space line (k + 1 at
        its end), moved past zero-length segments (they have no line). One candidate: the
        stop is identified exactly; several: the path passes the same angles twice there."""
        found: set[int] = set()
        for k in self.segment[max(lo, 0): max(hi, 0)]:
            if k < 0:
                continue
            t = line_param(job.steps[k], job.steps[k + 1], steps)
            if t is None:
                continue
            nxt = int(k) + 1 if t >= 1.0 else int(k)
            while (nxt < job.n_segments
                   and np.array_equal(job.steps[nxt], job.steps[nxt + 1])):
                nxt += 1
            found.add(nxt)
        return sorted(found)


def job_program(job: Job, profile: Profile, laser: bool, start: int = 0,
                start_position: tuple[int, int] | None = None,
                end: int | None = None) -> GrblProgram:
    """Segments `start` … `end` − 1 (None: to the job's end) as GRBL lines: G21 G90 G94, then
    one G1 per moving segment (feed from its planned duration), a dwell as `G4 P<s>`, the
    laser (M4 S, dynamic: power follows GRBL's own ramps) on drawing runs only, or a servo
    pen (M3 S down / up with a G4 settle) — see module doc. The tool is off at the end.

    A resume starts at segment `start` from `start_position` (steps on that segment's line):
    its first G1 goes to the segment's end at the segment's own feed, i.e. in the remaining
    share of its planned duration; the tool is set as planned for it."""
    deg = angles_deg(profile, job.steps)
    if start_position is not None:
        deg = deg.copy()
        deg[start] = angles_deg(profile, np.asarray(start_position))
    lines = ["G21 G90 G94 M5 S0"]
    seg = [-1]
    tool_on = False
    stop = job.n_segments if end is None else end
    tool = job.tool_on
    dwell = job.is_dwell
    for k in range(start, stop):
        want = bool(tool[k]) and (profile.pen is not None or (laser and int(job.power[k]) > 0))
        if want != tool_on:
            for text in tool_lines(profile, laser, want, job, k):
                lines.append(text)
                seg.append(-1)
            tool_on = want
        if dwell[k]:
            lines.append(wire.grbl_dwell(float(job.duration_us[k]) * 1e-6))
            seg.append(k)
            continue
        d = deg[k + 1] - deg[k]
        length = float(np.hypot(d[0], d[1]))
        if length == 0.0:
            continue
        full = deg[k + 1] - angles_deg(profile, job.steps[k]) if k == start else d
        feed = 60.0 * float(np.hypot(full[0], full[1])) / (float(job.duration_us[k]) * 1e-6)
        s = int(job.power[k]) * S_MAX / 255.0 if tool_on and profile.pen is None else None
        lines.append(wire.grbl_g1(float(deg[k + 1, 0]), float(deg[k + 1, 1]), feed, s))
        seg.append(k)
    if tool_on:
        lines += tool_lines(profile, laser, False, job, stop - 1)
        seg += [-1] * (len(lines) - len(seg))
    lines.append("M5")
    seg.append(-1)
    return GrblProgram(lines, np.asarray(seg, dtype=np.int64))


def tool_lines(profile: Profile, laser: bool, on: bool, job: Job | None, k: int) -> list[str]:
    """Laser on/off (M4 S… at segment k's power / M5) or pen down/up (M3 S<pulse> then G4
    for the servo; no job needed)."""
    pen = profile.pen
    if pen is not None:
        pulse = pen.pulse_us(pen.down_position if on else pen.up_position)
        s = (pulse - 500.0) / 2000.0 * S_MAX
        return [wire.grbl_spindle("M3", s), wire.grbl_dwell(pen.move_ms(on) / 1000.0)]
    if not on:
        return ["M5"]
    assert job is not None
    return [wire.grbl_spindle("M4", int(job.power[k]) * S_MAX / 255.0)]


def from_program(profile: Profile, moves: Program, start: tuple[int, int]) -> list[str]:
    """fivebar's own checked, ramped laser-off moves (`run.moves`: jog, frame, travel) as
    GRBL lines with the same targets and planned durations; items that are not moves
    (G90, the tool) are dropped, the laser stays off (M5)."""
    out = ["G21 G90 G94 M5"]
    mv = np.flatnonzero(moves.kind == Kind.MOVE)
    tgt = moves.positions(start)[mv]
    prev = np.concatenate((np.asarray(start, dtype=np.int64)[None], tgt[:-1]))
    d = (tgt - prev) / steps_per_degree(profile)
    length = np.hypot(d[:, 0], d[:, 1])
    deg = angles_deg(profile, tgt)
    for i in np.flatnonzero(length > 0):
        feed = 60.0 * float(length[i]) / (int(moves.p_us[mv[i]]) * 1e-6)
        out.append(wire.grbl_g1(float(deg[i, 0]), float(deg[i, 1]), feed))
    return out
