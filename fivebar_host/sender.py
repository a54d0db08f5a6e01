"""Send compiled jobs to the machine: known start pose, streaming, faults and exact resume.

Pure pipeline step over an open `Link` (no click, no pyserial): the CLI and the daemon call it.

A job is a list of firmware lines, each mapped to the job segment it executes. While streaming,
the firmware's status reports say which line (so which segment) finished last. On a fault the
machine is held (laser off), its position read, the firmware reset (queue cleared, laser off)
and a resume file written next to the drawing: the job's fingerprint, the first segment not
known to be finished and the position. `--resume` continues from exactly there: when the pen
stopped inside that segment, one move finishes the rest of it along the same joint-space line
(nothing redrawn); otherwise a laser-off travel goes back to the segment's start.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fivebar_host import protocol
from fivebar_host.config import Profile
from fivebar_host.job import Job
from fivebar_host.link import Link, LinkError, LinkFaultError, StreamProgress, StreamResult
from fivebar_host.protocol import StatusReport
from fivebar_host.steps import step_angles

RESUME_SUFFIX = ".fivebar-resume.json"
#: Share of the joint speed and acceleration limits used by moves the host adds itself
#: (travel back on resume, jogs, framing): they are not timed by the job planner.
SAFE_SHARE = 0.5


class SendError(LinkError):
    """A job could not be sent or finished; says what happened, where, and what to do."""


@dataclass(frozen=True)
class ResumePoint:
    """Where an interrupted job stopped (written next to the drawing as JSON)."""

    drawing: str
    fingerprint: str
    next_segment: int  # first job segment not known to be finished (0-based)
    position: tuple[int, int] | None  # firmware steps when it stopped; None if unknown
    reason: str
    segments: int

    def save(self, path: Path) -> None:
        """Write atomically (temporary file + rename)."""
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(asdict(self), indent=2) + "\n", encoding="utf-8")
        tmp.replace(path)

    @staticmethod
    def load(path: Path) -> ResumePoint:
        """Read a resume file; SendError naming the file when it is missing or malformed."""
        try:
            d = json.loads(path.read_text(encoding="utf-8"))
            pos = d["position"]
            return ResumePoint(str(d["drawing"]), str(d["fingerprint"]),
                               int(d["next_segment"]),
                               None if pos is None else (int(pos[0]), int(pos[1])),
                               str(d["reason"]), int(d["segments"]))
        except FileNotFoundError:
            raise SendError(f"{path}: no resume file (nothing was interrupted?)") from None
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise SendError(f"{path}: unreadable resume file: {e}") from e


def resume_path(drawing: str | Path) -> Path:
    """The resume file of a drawing: `<drawing>.fivebar-resume.json` beside it."""
    p = Path(drawing)
    return p.with_name(p.name + RESUME_SUFFIX)


def fingerprint(job: Job) -> str:
    """Hash of what the machine would do (steps, durations, laser), to match resume files."""
    h = hashlib.sha256()
    for arr in (job.steps, job.duration_us, job.power, job.draw):
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True)
class Program:
    """Firmware line bodies and, per line, the job segment it executes (−1: no segment)."""

    bodies: list[str]
    segment: NDArray[np.int64]

    def finished_segments(self, first_line: int, done_line: int, start: int) -> int:
        """Index of the first segment not finished, given the firmware's last finished line."""
        idx = done_line - first_line
        if idx < 0:
            return start
        idx = min(idx, len(self.bodies) - 1)
        segs = self.segment[: idx + 1]
        segs = segs[segs >= 0]
        return int(segs.max()) + 1 if segs.size else start


def _ramped_move(start: ArrayLike, end: ArrayLike, rad_per_step: float,
                 max_rad_s: float, max_rad_s2: float, piece_s: float = 0.02
                 ) -> list[tuple[int, int, int]]:
    """A joint-space straight move from rest to rest as (A, B, P µs) pieces.

    Trapezoidal speed profile on the axis that moves most (v ≤ max_rad_s, a ≤ max_rad_s2),
    cut in pieces of `piece_s`; every piece ends on the straight line, rounded once to steps.
    """
    s0 = np.asarray(start, dtype=np.float64)
    d = np.asarray(end, dtype=np.float64) - s0
    dist = float(np.abs(d).max()) * rad_per_step
    if dist == 0.0:
        return []
    v, a = max_rad_s, max_rad_s2
    t_acc = v / a
    if a * t_acc * t_acc > dist:  # triangle profile
        t_acc = math.sqrt(dist / a)
        v = a * t_acc
    t_cruise = (dist - a * t_acc * t_acc) / v
    total = 2 * t_acc + t_cruise

    def s_at(t: float) -> float:
        if t < t_acc:
            return 0.5 * a * t * t
        if t < t_acc + t_cruise:
            return 0.5 * a * t_acc * t_acc + v * (t - t_acc)
        r = total - t
        return dist - 0.5 * a * r * r

    n = max(1, math.ceil(total / piece_s))
    times = np.linspace(0.0, total, n + 1)
    frac = np.array([min(1.0, s_at(float(t)) / dist) for t in times])
    frac[-1] = 1.0
    pts = np.rint(s0[None, :] + frac[:, None] * d[None, :]).astype(np.int64)
    out: list[tuple[int, int, int]] = []
    t_prev = 0.0
    for i in range(1, n + 1):
        if np.array_equal(pts[i], pts[i - 1]) and i < n:
            continue
        dt = times[i] - t_prev
        t_prev = times[i]
        out.append((int(pts[i, 0]), int(pts[i, 1]), max(protocol.P_MIN_US, round(dt * 1e6))))
    return out


def check_joint_move(profile: Profile, job_assembly: int, start: ArrayLike,
                     end: ArrayLike, what: str) -> None:
    """Refuse a host-added joint-space move that would leave the safe workspace.

    Samples the straight joint-space line every 0.005 rad: the loop must close in the job's
    assembly, the type-2 margin must clear the profile's minimum (the type-1 singularity is
    allowed: the motor drives through it) and the motor angles must stay within limits.
    """
    fb = profile.geometry
    spr = profile.motors.steps_per_rev
    home = profile.motors.home_rad
    th0 = step_angles(np.asarray([start]), home, spr)[0]
    th1 = step_angles(np.asarray([end]), home, spr)[0]
    n = max(2, math.ceil(float(np.abs(th1 - th0).max()) / 0.005) + 1)
    th = th0[None, :] + np.linspace(0.0, 1.0, n)[:, None] * (th1 - th0)[None, :]
    for i, (lo, hi) in enumerate(profile.motors.limits_rad):
        bad = np.flatnonzero((th[:, i] < lo - 1e-9) | (th[:, i] > hi + 1e-9))
        if bad.size:
            raise SendError(f"{what}: motor {i + 1} would reach "
                            f"{math.degrees(th[bad[0], i]):.2f}°, outside its limits "
                            f"[{math.degrees(lo):g}°, {math.degrees(hi):g}°]")
    fwd = fb.forward_batch(th, "+" if job_assembly > 0 else "-")
    if not fwd.valid.all():
        raise SendError(f"{what}: the linkage cannot close along the move (at motor angles "
                        f"{np.degrees(th[np.flatnonzero(~fwd.valid)[0]]).round(2).tolist()}°)")
    m2 = fb.singularity_margins(th, fwd.points)[:, 2] * job_assembly
    worst = int(np.argmin(m2))
    if m2[worst] < profile.kinematics.min_type2_margin_rad:
        p = fwd.points[worst]
        raise SendError(f"{what}: passes within {math.degrees(m2[worst]):.1f}° of a type-2 "
                        f"singularity at ({p[0]:.1f}, {p[1]:.1f}) mm (minimum "
                        f"{math.degrees(profile.kinematics.min_type2_margin_rad):g}°); "
                        "move the arms by hand to the home pose and run `fivebar home`")


def travel_lines(profile: Profile, job_assembly: int, start: ArrayLike,
                 end: ArrayLike, what: str) -> list[str]:
    """Checked, ramped, laser-off G1 lines from `start` to `end` (absolute steps)."""
    check_joint_move(profile, job_assembly, start, end, what)
    mo = profile.motors
    pieces = _ramped_move(start, end, mo.rad_per_step,
                          SAFE_SHARE * profile.motion.max_joint_rad_s,
                          SAFE_SHARE * profile.motion.max_joint_rad_s2)
    return [protocol.g1(a, b, p, 0) for a, b, p in pieces]


def job_bodies(job: Job, profile: Profile, laser: bool, first: int,
               first_line: str | None = None) -> tuple[list[str], list[int]]:
    """Firmware lines for segments `first`… of `job` and the segment of each (−1: none).

    Laser job (`laser`): `M3 S0` once, then drawing segments carry the profile's power.
    Pen job: S0 everywhere, pen down (`M3 S0`) before and pen up (`M5`) after each run of
    drawing segments. `first_line` replaces the first segment's G1 (a partial segment).
    The same encoding as `fivebar convert` (job.encode_lines)."""
    n = job.n_segments
    power = job.power if laser else np.zeros_like(job.power)
    draw = job.draw.tolist()
    bodies: list[str] = []
    seg: list[int] = []
    if laser:
        bodies.append(f"{profile.laser.on_command} S0")
        seg.append(-1)
    a = job.steps[1:, 0].tolist()
    b = job.steps[1:, 1].tolist()
    dur = job.duration_us.tolist()
    pw = power.tolist()
    for k in range(first, n):
        if not laser and draw[k] and (k == first or not draw[k - 1]):
            bodies.append("M3 S0")
            seg.append(-1)
        line = first_line if (k == first and first_line is not None) else protocol.g1(
            a[k], b[k], dur[k], pw[k])
        bodies.append(line)
        seg.append(k)
        if not laser and draw[k] and (k == n - 1 or not draw[k + 1]):
            bodies.append("M5")
            seg.append(-1)
    if not bodies or bodies[-1] != "M5":
        bodies.append("M5")
        seg.append(-1)
    return bodies, seg


def build_program(job: Job, profile: Profile, laser: bool, start_segment: int,
                  position: ArrayLike) -> Program:
    """The lines that run segments `start_segment`… of `job` from firmware steps `position`.

    If `position` lies inside segment `start_segment` (on its joint-space line, within one
    step) the first move finishes that segment with the remaining share of its duration;
    otherwise a checked laser-off travel reaches its start first. Power is sent only with
    `laser` (the CLI's explicit `--laser` opt-in).
    """
    bodies = ["G90", "M5"]
    seg: list[int] = [-1, -1]
    k = start_segment
    steps = job.steps
    pos = np.asarray(position, dtype=np.int64)
    partial: str | None = None
    if k < job.n_segments and not np.array_equal(pos, steps[k]):
        s0, s1 = steps[k].astype(np.float64), steps[k + 1].astype(np.float64)
        d = s1 - s0
        ax = int(np.argmax(np.abs(d)))
        t = (pos[ax] - s0[ax]) / d[ax] if d[ax] != 0 else -1.0
        on_line = 0.0 < t < 1.0 and bool(np.all(np.abs(s0 + t * d - pos) <= 1.0 + 1e-9))
        if on_line:
            rest = max(protocol.P_MIN_US, round(float(job.duration_us[k]) * (1.0 - t)))
            pw = int(job.power[k]) if laser else 0
            partial = protocol.g1(int(steps[k + 1, 0]), int(steps[k + 1, 1]), rest, pw)
        else:
            back = travel_lines(profile, job.assembly, pos, steps[k],
                                f"travel back to segment {k + 1}")
            bodies += back
            seg += [-1] * len(back)
    more, mseg = job_bodies(job, profile, laser, k, partial)
    return Program(bodies + more, np.asarray(seg + mseg, dtype=np.int64))


# ------------------------------------------------------------------ start pose
def ensure_known_pose(link: Link, profile: Profile, confirm: Callable[[str], bool]
                      ) -> StatusReport:
    """Make sure the firmware's step count means what the job assumes (0 = homed pose).

    After power-up or a reset the firmware does not know where the arms are: with endstops
    `$H` homes; without them the user confirms that the arms sit at the profile's home pose,
    and `G92 A0 B0` sets the position. Alarm or hold states are refused with what to do.
    """
    st = link.status()
    if st.state == "Alarm":
        raise SendError(f"{link.url}: the machine is in alarm {st.detail} "
                        f"({_code_text(st.detail)}); clear it with `fivebar home`")
    if st.state == "Hold":
        raise SendError(f"{link.url}: the machine is on hold; resume or reset it first")
    if st.homed:
        return st
    return home(link, profile, confirm)


def home(link: Link, profile: Profile, confirm: Callable[[str], bool]) -> StatusReport:
    """Home: `$H` with endstops, otherwise confirmation then `G92 A0 B0`."""
    if profile.motors.endstops:
        link.command("$H", timeout_s=120.0)
        return link.wait_idle(120.0)
    h1, h2 = (math.degrees(v) for v in profile.motors.home_rad)
    if not confirm(f"The firmware does not know where the arms are. Are they at the home "
                   f"pose θ1 = {h1:g}°, θ2 = {h2:g}° (motor angles from +x)?"):
        raise SendError("position unknown: place the arms at the home pose and confirm, or "
                        "run `fivebar home`")
    link.command("G92 A0 B0")
    return link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect


def _code_text(code: int | None) -> str:
    info = protocol.CODES.get(code or -1)
    return info.description if info else "unknown code"


# ------------------------------------------------------------------ running a job
@dataclass(frozen=True)
class SendReport:
    """What a finished send did."""

    segments: int  # job segments executed by this run
    start_segment: int
    elapsed_s: float
    bytes_sent: int
    resends: int
    final: StatusReport


@dataclass(frozen=True)
class Progress:
    """Progress in job terms, for progress bars."""

    segments_done: int
    segments_total: int
    elapsed_s: float
    remaining_s: float


def run_job(link: Link, job: Job, profile: Profile, *, drawing: str | Path, laser: bool,
            confirm: Callable[[str], bool], resume: bool = False,
            on_progress: Callable[[Progress], None] | None = None,
            should_stop: Callable[[], bool] | None = None,
            on_interrupt: Callable[[], bool] | None = None) -> SendReport:
    """Stream `job` (or its remainder with `resume`) and wait until the machine is idle.

    On any fault: hold, read the position, reset the firmware, write the resume file and raise
    `SendError` naming the fault, the position and the last segment executed.
    """
    rpath = resume_path(drawing)
    fp = fingerprint(job)
    start = 0
    if resume:
        rp = ResumePoint.load(rpath)
        if rp.fingerprint != fp:
            raise SendError(f"{rpath}: the resume file belongs to a different job (drawing or "
                            "options changed); run the same command as before with --resume")
        start = rp.next_segment
        st = link.status()
        if st.state in ("Alarm", "Hold"):
            raise SendError(f"{link.url}: the machine is in {st.state} "
                            f"({_code_text(st.detail)}); clear it before resuming")
        if not st.homed:
            # The firmware restarted since the fault (opening the port resets an Arduino):
            # its count is 0, the arms are where they stopped, if that is known.
            if rp.position is not None and confirm(
                    f"Are the arms still where the job stopped (A = {rp.position[0]}, "
                    f"B = {rp.position[1]} steps)?"):
                link.command(f"G92 A{rp.position[0]} B{rp.position[1]}")
            else:
                home(link, profile, confirm)
            st = link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect
    else:
        st = ensure_known_pose(link, profile, confirm)
    prog = build_program(job, profile, laser, start, (st.a, st.b))
    durations = job.duration_us.astype(np.float64) * 1e-6
    remaining_after = np.concatenate((np.cumsum(durations[::-1])[::-1], [0.0]))
    t0 = time.monotonic()
    first_line = link.next_line
    last_line = first_line + len(prog.bodies) - 1

    def progress(p: StreamProgress) -> None:
        if on_progress is None:
            return
        done = prog.finished_segments(first_line, p.done_line, start)
        on_progress(Progress(done, job.n_segments, time.monotonic() - t0,
                             float(remaining_after[min(done, job.n_segments)])))

    try:
        res: StreamResult = link.stream(prog.bodies, on_progress=progress,
                                        should_stop=should_stop, on_interrupt=on_interrupt)
        final = link.wait_idle(max(30.0, 3.0 * job.total_time_s), last_line=last_line,
                               on_status=lambda s: progress(StreamProgress(
                                   len(prog.bodies), len(prog.bodies), len(prog.bodies),
                                   s.done_line, s, 0)))
    except LinkFaultError as fault:
        raise _after_fault(link, job, prog, fault, first_line, start, rpath, fp) from fault
    if rpath.exists():
        rpath.unlink()
    return SendReport(job.n_segments - start, start, time.monotonic() - t0, res.bytes_sent,
                      res.resends, final)


def _after_fault(link: Link, job: Job, prog: Program, fault: LinkFaultError, first_line: int,
                 start: int, rpath: Path, fp: str) -> SendError:
    """Stop the machine safely, record where it stopped, and describe it."""
    st: StatusReport | None = None
    rebooted = False
    if fault.kind != "disconnect":
        try:
            link.realtime(protocol.RT_HOLD)
            st = _wait_stopped(link)
            link.reset()
        except LinkError:
            st = None
            # No answer: reboot the controller through DTR so its laser output goes off.
            rebooted = link.hardware_reset()
    known = st is not None and fault.kind != "reset"
    ref = st if st is not None else fault.status
    if fault.kind == "reset":
        ref = fault.status
    nxt = prog.finished_segments(first_line, ref.done_line, start) if ref is not None else start
    position = (st.a, st.b) if known and st is not None else None
    rp = ResumePoint(str(job.file), fp, nxt, position, f"{fault.kind}: {fault}", job.n_segments)
    rp.save(rpath)
    where = (f"stopped at A = {position[0]}, B = {position[1]} steps" if position
             else "position unknown (home the machine before resuming)")
    if st is not None:
        laser = "laser off (held and reset)"
    elif rebooted:
        laser = "the controller did not answer and was rebooted through DTR: laser off"
    else:
        laser = "laser: the firmware switches it off after its silence timeout"
    return SendError(f"{fault}\n{where}; last segment executed: {nxt} of {job.n_segments}; "
                     f"{laser}.\nresume file: {rpath} — continue with the same command and "
                     "--resume")


def _wait_stopped(link: Link, timeout_s: float = 5.0) -> StatusReport:
    """After `!`, poll until two consecutive reports show the same position (motion over)."""
    deadline = time.monotonic() + timeout_s
    prev = link.status(timeout_s=1.0)
    while time.monotonic() < deadline:
        time.sleep(0.05)
        st = link.status(timeout_s=1.0)
        if (st.a, st.b) == (prev.a, prev.b) and st.state in ("Hold", "Idle", "Alarm"):
            return st
        prev = st
    raise LinkError(f"{link.url}: the machine did not stop within {timeout_s:g} s of hold")


# ------------------------------------------------------------------ framing and jogging
def frame_program(job: Job, profile: Profile, position: Sequence[int],
                  spacing_mm: float = 0.5) -> Program:
    """Lines that trace the job's bounding box with the laser off, then return home.

    The outline is sampled every `spacing_mm`, solved in the job's working mode and checked
    like the job itself (reach, limits, margins); the returns are checked ramped travels.
    """
    fb = profile.geometry
    x0, y0, x1, y1 = job.placement.machine_bbox
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], dtype=np.float64)
    pts = [corners[:1]]
    for p, q in itertools.pairwise(corners):
        n = max(1, math.ceil(float(np.hypot(*(q - p))) / spacing_mm))
        pts.append(p + (q - p) * (np.arange(1, n + 1) / n)[:, None])
    outline = np.concatenate(pts)
    inv = fb.inverse_batch(outline, job.mode)
    if not inv.valid.all():
        i = int(np.flatnonzero(~inv.valid)[0])
        raise SendError(f"frame: outline point ({outline[i, 0]:.2f}, {outline[i, 1]:.2f}) mm "
                        "is out of reach in working mode " + job.mode)
    m = fb.singularity_margins(inv.angles, outline)
    kin = profile.kinematics
    if (np.abs(m[:, :2]).min() < kin.min_type1_margin_rad
            or (m[:, 2] * job.assembly).min() < kin.min_type2_margin_rad):
        raise SendError("frame: the drawing's bounding box comes closer to a singularity than "
                        "the profile allows (the drawing itself may still be fine)")
    from fivebar_host.steps import absolute_steps

    st = absolute_steps(inv.angles, profile.motors.home_rad, profile.motors.steps_per_rev)
    bodies = ["G90", f"{profile.laser.on_command} S0"]
    bodies += travel_lines(profile, job.assembly, position, st[0], "frame: travel to the outline")
    feed = profile.motion.travel_feed_mm_s
    wmax = SAFE_SHARE * profile.motion.max_joint_rad_s
    seglen = np.hypot(*np.diff(outline, axis=0).T)
    dth = np.abs(np.diff(inv.angles, axis=0)).max(axis=1)
    dur = np.maximum(seglen / feed, dth / wmax)
    for k in range(1, st.shape[0]):
        if np.array_equal(st[k], st[k - 1]):
            continue
        bodies.append(protocol.g1(int(st[k, 0]), int(st[k, 1]),
                                  max(protocol.P_MIN_US, round(float(dur[k - 1]) * 1e6)), 0))
    bodies += travel_lines(profile, job.assembly, st[-1], (0, 0), "frame: return home")
    bodies.append("M5")
    return Program(bodies, np.full(len(bodies), -1, dtype=np.int64))


def jog_lines(profile: Profile, assembly: int, mode: str, position: Sequence[int], *,
              motor: str | None = None, steps: int = 0,
              dxy_mm: tuple[float, float] | None = None, checked: bool = True) -> list[str]:
    """Ramped lines that move one motor by `steps` or the pen by `dxy_mm`.

    `checked=False` is for a motor jog while the position is unknown (setting the arms up
    before homing): the move is not checked against limits or singularities, since nothing
    is known to check against; a pen jog always needs a known position."""
    pos = np.asarray(position, dtype=np.int64)
    if motor is not None:
        target = pos.copy()
        target["AB".index(motor)] += steps
        what = f"jog motor {motor} by {steps} steps"
        if not checked:
            mo = profile.motors
            pieces = _ramped_move(pos, target, mo.rad_per_step,
                                  SAFE_SHARE * profile.motion.max_joint_rad_s,
                                  SAFE_SHARE * profile.motion.max_joint_rad_s2)
            return ["G90", *(protocol.g1(a, b, p, 0) for a, b, p in pieces)]
    else:
        assert dxy_mm is not None
        fb = profile.geometry
        mo = profile.motors
        th = step_angles(pos[None, :], mo.home_rad, mo.steps_per_rev)
        p = fb.forward_batch(th, "+" if assembly > 0 else "-")
        if not p.valid[0]:
            raise SendError("jog: the current motor position does not close the linkage")
        goal = p.points[0] + np.asarray(dxy_mm)
        inv = fb.inverse_batch(goal[None, :], mode)
        if not inv.valid[0]:
            raise SendError(f"jog: ({goal[0]:.2f}, {goal[1]:.2f}) mm is out of reach in "
                            f"working mode {mode}")
        from fivebar_host.steps import absolute_steps

        target = absolute_steps(inv.angles, mo.home_rad, mo.steps_per_rev)[0]
        what = f"jog the pen to ({goal[0]:.2f}, {goal[1]:.2f}) mm"
    return ["G90", *travel_lines(profile, assembly, pos, target, what)]
