"""Send compiled jobs to the machine: known start pose, streaming, faults and exact resume.

Pure pipeline step over an open `Link` (no click, no pyserial): the CLI and the daemon call it.

A job is a list of firmware lines, each mapped to the job segment it executes. While streaming,
the firmware's status reports say which line (so which segment) finished last. On a fault the
machine is held (laser off), its position read, the firmware reset (queue cleared, laser off)
and a resume file written next to the drawing: the job's fingerprint, the first segment not
known to be finished and the position. `--resume` continues from exactly there: when the pen
stopped inside that segment, one move finishes the rest of it along the same joint-space line
(nothing redrawn); otherwise a laser-off travel goes back to the segment's start.

When the controller restarts (a reset banner mid-stream, or a hung controller rebooted through
DTR) it keeps its position, `H` and `Ln` done (docs/protocol.md 7, kept across a reset): the
line it finished last maps back to the exact segment, as after a hold. When the link breaks
the position cannot be read at once; the resume file then also describes the stream (its line
numbers and `build_program`'s inputs), and `--resume` reads the kept record from the controller
(opening the port resets an Arduino, which keeps it) and maps it the same way. Only a
controller that lost power (`H:0`) falls back to the last segment a status report confirmed,
and segments after it may be drawn twice.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fivebar_host import protocol
from fivebar_host.compile import Job
from fivebar_host.config import Profile
from fivebar_host.link import Link, LinkError, LinkFaultError, StreamProgress, StreamResult
from fivebar_host.protocol import StatusReport
from fivebar_host.steps import step_angles

RESUME_SUFFIX = ".fivebar-resume.json"
#: Share of the joint speed and acceleration limits used by moves the host adds itself
#: (travel back on resume, jogs, framing): they are not timed by the job planner.
SAFE_SHARE = 0.5


class SendError(LinkError):
    """A job could not be sent or finished; says what happened, where, and what to do."""


def _pair(v: object) -> tuple[int, int] | None:
    """A JSON `[a, b]` as a pair of ints (None stays None); TypeError/ValueError otherwise."""
    if v is None:
        return None
    if not isinstance(v, list | tuple) or len(v) != 2:
        raise ValueError(f"expected [a, b], got {v!r}")
    return int(v[0]), int(v[1])


@dataclass(frozen=True)
class ResumePoint:
    """Where an interrupted job stopped (written next to the drawing as JSON).

    When the position was read after the fault, `next_segment` and `position` are exact.
    Otherwise `position` is None, `next_segment` is the first segment no status report
    confirmed finished, `sent_segment` the first segment none of whose lines had been sent
    (so at most the segments in between ran), and — when the controller may still hold its
    record of the stream (docs/protocol.md 7, kept across a reset) — the stream fields say
    which stream that was: its first and last firmware line numbers and `build_program`'s
    inputs (start segment, start position, laser), so a later run rebuilds the very program
    sent and maps the controller's `Ln` done back to the exact segment. Files written before
    these fields existed read with them None: no stream information.
    """

    drawing: str
    fingerprint: str
    next_segment: int  # first job segment not known to be finished (0-based)
    position: tuple[int, int] | None  # firmware steps when it stopped; None if unknown
    reason: str
    segments: int
    first_line: int | None = None  # firmware line number of the stream's first line
    last_line: int | None = None  # ... and of its last line
    stream_start: int | None = None  # segment the stream started at
    start_position: tuple[int, int] | None = None  # firmware steps the stream started from
    laser: bool | None = None  # the stream's laser flag (its lines depend on it)
    sent_segment: int | None = None  # first segment none of whose lines was sent

    @property
    def has_stream(self) -> bool:
        """True when the interrupted stream can be rebuilt (all stream fields present)."""
        return (self.first_line is not None and self.last_line is not None
                and self.stream_start is not None and self.start_position is not None
                and self.laser is not None)

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

            def opt_int(key: str) -> int | None:
                v = d.get(key)
                return None if v is None else int(v)

            laser = d.get("laser")
            if laser is not None and not isinstance(laser, bool):
                raise ValueError(f"laser must be true or false, got {laser!r}")
            return ResumePoint(str(d["drawing"]), str(d["fingerprint"]),
                               int(d["next_segment"]), _pair(d["position"]),
                               str(d["reason"]), int(d["segments"]),
                               opt_int("first_line"), opt_int("last_line"),
                               opt_int("stream_start"), _pair(d.get("start_position")), laser,
                               opt_int("sent_segment"))
        except FileNotFoundError:
            raise SendError(f"{path}: no resume file (nothing was interrupted?)") from None
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
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


def _line_param(p0: ArrayLike, p1: ArrayLike, pos: ArrayLike) -> float | None:
    """Where `pos` lies on the straight joint-space line p0 → p1: t in [0, 1] measured on
    the axis that moves most, when every axis is within one step of the line; else None.
    (The DDA spreads each motor's steps evenly, so a move stopped part-way sits there.)"""
    s0 = np.asarray(p0, dtype=np.float64)
    d = np.asarray(p1, dtype=np.float64) - s0
    q = np.asarray(pos, dtype=np.float64)
    if not d.any():
        return 0.0 if np.array_equal(q, s0) else None
    ax = int(np.argmax(np.abs(d)))
    t = float((q[ax] - s0[ax]) / d[ax])
    if not 0.0 <= t <= 1.0 or not bool(np.all(np.abs(s0 + t * d - q) <= 1.0 + 1e-9)):
        return None
    return t


_G1_WORDS = re.compile(r"\b([AB])(-?\d+)")


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

    def positions(self, start_position: ArrayLike) -> NDArray[np.int64]:
        """Firmware position after each line, from `start_position` (programs are absolute,
        `G90`; only `G1` lines move)."""
        pos = np.asarray(start_position, dtype=np.int64).copy()
        out = np.empty((len(self.bodies), 2), dtype=np.int64)
        for i, body in enumerate(self.bodies):
            if body.split(" ", 1)[0] == "G1":
                for axis, value in _G1_WORDS.findall(body):
                    pos["AB".index(axis)] = int(value)
            out[i] = pos
        return out

    def on_path(self, first_line: int, done_line: int, start_position: ArrayLike,
                position: ArrayLike) -> bool:
        """Whether `position` is where this program can leave the motors when `done_line`
        is the last line it executed to its end: on the straight joint-space line from the
        position after that line to the end of the next line that moves (within a step)."""
        pts = self.positions(start_position)
        idx = done_line - first_line
        if not -1 <= idx < len(self.bodies):
            return False
        p0 = np.asarray(start_position, dtype=np.int64) if idx < 0 else pts[idx]
        later = pts[idx + 1:]
        moving = np.flatnonzero(np.any(later != p0, axis=1))
        p1 = later[moving[0]] if moving.size else p0
        return _line_param(p0, p1, position) is not None


def kept_resume_segment(prog: Program, first_line: int, start: int, start_position: ArrayLike,
                        st: StatusReport, floor: int) -> tuple[int | None, str]:
    """The exact first unfinished segment from a controller's record kept across a reset.

    A reset that leaves the RAM powered keeps the position, `H` and `Ln` done
    (docs/protocol.md 7). `prog` is the stream that ran, from firmware line `first_line`,
    built from segment `start` at `start_position`; `st` is a status report read after the
    reset, motion over. The record is this stream's when `H:1`, its done line is one of the
    stream's lines (or the one before the first), the segment it maps to is not before
    `floor` (a segment a status report of the stream had already confirmed) and the position
    lies on the stream's path just after that line. Returns (segment, "") or (None, why not):
    power was lost, or something else ran on the controller since.
    """
    last = first_line + len(prog.bodies) - 1
    if not st.homed:
        return None, "it reports H:0, its position is unknown: it lost power"
    if not first_line - 1 <= st.done_line <= last:
        return None, (f"its last executed line {st.done_line} is not one of the stream's "
                      f"lines {first_line}..{last}")
    nxt = prog.finished_segments(first_line, st.done_line, start)
    if nxt < floor:
        return None, (f"its last executed line {st.done_line} would mean {nxt} segments done, "
                      f"fewer than the {floor} a status report had confirmed")
    if not prog.on_path(first_line, st.done_line, start_position, (st.a, st.b)):
        return None, (f"its position A = {st.a}, B = {st.b} is not on the stream's path after "
                      f"line {st.done_line}")
    return nxt, ""


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
    otherwise a checked laser-off travel reaches its start first. A position at the
    segment's end (its steps all issued, its time not yet over) gives a minimal laser-off
    line that stands for it, so nothing is redrawn. Power is sent only with `laser` (the
    CLI's explicit `--laser` opt-in).
    """
    bodies = ["G90", "M5"]
    seg: list[int] = [-1, -1]
    k = start_segment
    steps = job.steps
    pos = np.asarray(position, dtype=np.int64)
    partial: str | None = None
    if k < job.n_segments and not np.array_equal(pos, steps[k]):
        t = _line_param(steps[k], steps[k + 1], pos)
        if t is not None and t > 0.0:
            rest = max(protocol.P_MIN_US, round(float(job.duration_us[k]) * (1.0 - t)))
            at_end = np.array_equal(pos, steps[k + 1])
            pw = int(job.power[k]) if laser and not at_end else 0
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

    After power-up the firmware does not know where the arms are (`H:0`; a reset, such as
    the one opening an Arduino's port causes, keeps the position: docs/protocol.md 7): with
    endstops `$H` homes; without them the user confirms that the arms sit at the profile's
    home pose, and `G92 A0 B0` sets the position. Alarm or hold states are refused with what
    to do.
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
            on_interrupt: Callable[[], bool] | None = None,
            on_note: Callable[[str], None] | None = None) -> SendReport:
    """Stream `job` (or its remainder with `resume`) and wait until the machine is idle.

    On any fault: hold, read the position, reset the firmware, write the resume file and raise
    `SendError` naming the fault, the position and the last segment executed. `on_note`
    receives what the user should know before a resumed run starts (where it resumes from and
    whether segments may be drawn twice).
    """
    rpath = resume_path(drawing)
    fp = fingerprint(job)
    start = 0
    if resume:
        rp = ResumePoint.load(rpath)
        if rp.fingerprint != fp:
            raise SendError(f"{rpath}: the resume file belongs to a different job (drawing or "
                            "options changed); run the same command as before with --resume")
        start, st = _resume_start(link, job, profile, rp, confirm, on_note or (lambda _: None))
    else:
        st = ensure_known_pose(link, profile, confirm)
    start_position = (st.a, st.b)
    prog = build_program(job, profile, laser, start, start_position)
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
        stream = _Stream(prog, first_line, start, start_position, laser)
        raise _after_fault(link, job, stream, fault, rpath, fp) from fault
    if rpath.exists():
        rpath.unlink()
    return SendReport(job.n_segments - start, start, time.monotonic() - t0, res.bytes_sent,
                      res.resends, final)


def _redraw_text(next_segment: int, sent_segment: int | None) -> str:
    """How many segments a resume from `next_segment` may draw a second time."""
    if sent_segment is None:
        return "segments that ran after it before the fault will be drawn again"
    n = max(0, sent_segment - next_segment)
    return f"up to {n} segment{'' if n == 1 else 's'} after it may be drawn twice"


def _resume_start(link: Link, job: Job, profile: Profile, rp: ResumePoint,
                  confirm: Callable[[str], bool], note: Callable[[str], None]
                  ) -> tuple[int, StatusReport]:
    """The segment a resumed run starts at and the status it starts from.

    An exact resume point is used as it is. Without a position the controller's record
    kept across its reset (opening the port resets an Arduino) gives the exact segment when
    it belongs to the interrupted stream (`kept_resume_segment`); otherwise the run starts at
    the last segment a status report confirmed, after homing if the controller lost its
    position, and says how many segments may be drawn twice.
    """
    st = link.status()
    if st.state == "Run":
        # A controller that the port's opening did not reset may still be running the
        # interrupted stream's queue: let it finish, then read where it stopped.
        st = link.wait_idle(120.0)
    if st.state in ("Alarm", "Hold"):
        raise SendError(f"{link.url}: the machine is in {st.state} "
                        f"({_code_text(st.detail)}); clear it before resuming")
    start = rp.next_segment
    n = job.n_segments
    if rp.position is None and st.homed and rp.has_stream:
        assert (rp.first_line is not None and rp.last_line is not None
                and rp.stream_start is not None and rp.start_position is not None
                and rp.laser is not None)
        try:
            prog: Program | None = build_program(job, profile, rp.laser, rp.stream_start,
                                                 rp.start_position)
        except SendError as e:
            prog, why = None, f"the interrupted stream cannot be rebuilt: {e}"
        if prog is not None and len(prog.bodies) != rp.last_line - rp.first_line + 1:
            prog, why = None, "the interrupted stream cannot be rebuilt the same"
        if prog is not None:
            exact, why = kept_resume_segment(prog, rp.first_line, rp.stream_start,
                                             rp.start_position, st, rp.next_segment)
            if exact is not None:
                note(f"resume point read from the controller: it kept its position (A = "
                     f"{st.a}, B = {st.b} steps) and its last executed line ({st.done_line}) "
                     f"across its reset; {exact} of {n} segments were executed, continuing "
                     "exactly from there")
                return exact, st
        note(f"the controller's kept record does not belong to the interrupted job ({why}); "
             f"resuming after segment {start} of {n}, the last a status report confirmed, "
             f"from the controller's position (A = {st.a}, B = {st.b} steps): "
             + _redraw_text(start, rp.sent_segment))
        return start, st
    if not st.homed:
        # The controller lost power since the fault: its count is 0; the arms are where they
        # stopped, if that is known.
        if rp.position is not None and confirm(
                f"Are the arms still where the job stopped (A = {rp.position[0]}, "
                f"B = {rp.position[1]} steps)?"):
            link.command(f"G92 A{rp.position[0]} B{rp.position[1]}")
        else:
            if rp.position is None:
                note(f"the controller lost its position (H:0: power was cut since the fault); "
                     f"after homing, resuming after segment {start} of {n}, the last a status "
                     f"report confirmed: " + _redraw_text(start, rp.sent_segment))
            home(link, profile, confirm)
        st = link.wait_idle(10.0)  # G92 is queued: its ok comes before it takes effect
    elif rp.position is None:
        note(f"resuming after segment {start} of {n}, the last a status report confirmed, "
             f"from the controller's position (A = {st.a}, B = {st.b} steps): "
             + _redraw_text(start, rp.sent_segment))
    return start, st


@dataclass(frozen=True)
class _Stream:
    """A stream that ran: its program, first firmware line and `build_program`'s inputs."""

    prog: Program
    first_line: int
    start: int
    start_position: tuple[int, int]
    laser: bool

    def done_segments(self, done_line: int) -> int:
        """First segment not finished when `done_line` is the last line executed."""
        return self.prog.finished_segments(self.first_line, done_line, self.start)


def _after_fault(link: Link, job: Job, stream: _Stream, fault: LinkFaultError, rpath: Path,
                 fp: str) -> SendError:
    """Stop the machine safely, record where it stopped, and describe it.

    The controller answers: hold, read the position, Ctrl-X — exact. It restarted (a reset
    banner) or hung and was rebooted through DTR: the status read after the restart shows
    the record it kept (position, `H`, `Ln` done), exact when it maps onto this stream. The
    link broke, or the hung controller gave no status even after DTR: the position is not
    known yet; the resume file describes the stream so that `--resume` reads the kept record.
    """
    held: StatusReport | None = None  # after the hold: the controller answers
    after: StatusReport | None = None  # after a DTR reboot
    rebooted = False
    ctrl_x = False
    if fault.kind != "disconnect":
        try:
            link.realtime(protocol.RT_HOLD)
            held = _wait_stopped(link)
            ctrl_x = True  # Ctrl-X zeroes Ln done: the kept record is read before it
            link.reset()
        except LinkError:
            # No answer: reboot the controller through DTR so its laser output goes off.
            rebooted = link.hardware_reset()
            if rebooted:
                with contextlib.suppress(LinkError):
                    after = link.status(timeout_s=2.0)
    n = job.n_segments
    restarted = fault.kind == "reset" or rebooted
    # Conservative: the last segment a status report of the stream confirmed.
    seen = fault.status if restarted or held is None else held
    nxt = stream.done_segments(seen.done_line) if seen is not None else stream.start
    position = None if restarted or held is None else (held.a, held.b)
    kept = after if rebooted else (held if fault.kind == "reset" else None)
    kept_why = "the controller gave no status after restarting"
    if kept is not None:
        exact, kept_why = kept_resume_segment(stream.prog, stream.first_line, stream.start,
                                              stream.start_position, kept, nxt)
        if exact is not None:
            nxt, position = exact, (kept.a, kept.b)
    sent = fault.sent if fault.sent >= 0 else len(stream.prog.bodies)
    sent_segment = stream.done_segments(stream.first_line + sent - 1)
    if position is not None:
        rp = ResumePoint(str(job.file), fp, nxt, position, f"{fault.kind}: {fault}", n)
        if restarted:
            assert kept is not None
            where = (f"the controller kept its position and its last executed line "
                     f"({kept.done_line}) across the restart: stopped at A = {position[0]}, "
                     f"B = {position[1]} steps; last segment executed: {nxt} of {n}")
        else:
            where = (f"stopped at A = {position[0]}, B = {position[1]} steps; last segment "
                     f"executed: {nxt} of {n}")
    elif ctrl_x:
        # Restarted without a usable record, and the Ctrl-X has zeroed Ln done since.
        rp = ResumePoint(str(job.file), fp, nxt, None, f"{fault.kind}: {fault}", n,
                         sent_segment=sent_segment)
        where = (f"position unknown: the controller restarted without its position "
                 f"({kept_why}); home the machine before resuming. Segments known executed: "
                 f"{nxt} of {n}; {_redraw_text(nxt, sent_segment)}")
    else:
        rp = ResumePoint(str(job.file), fp, nxt, None, f"{fault.kind}: {fault}", n,
                         stream.first_line, stream.first_line + len(stream.prog.bodies) - 1,
                         stream.start, stream.start_position, stream.laser, sent_segment)
        cause = ("the link broke while the controller was running" if fault.kind ==
                 "disconnect" else f"the controller could not be read ({kept_why})")
        where = (f"position not known yet: {cause}. Segments known executed: {nxt} of {n}. "
                 "The controller keeps its position and its last executed line across a reset "
                 "(opening the port resets an Arduino): --resume reads them from it and "
                 "continues exactly; only if it loses power first, homing is needed and "
                 f"{_redraw_text(nxt, sent_segment)}")
    rp.save(rpath)
    if held is not None:
        laser = "laser off (held and reset)"
    elif rebooted:
        laser = "the controller did not answer and was rebooted through DTR: laser off"
    else:
        laser = "laser: the firmware switches it off after its silence timeout"
    return SendError(f"{fault}\n{where}; {laser}.\nresume file: {rpath} — continue with the "
                     "same command and --resume")


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
