"""What a compiled job emits: its segments as a typed `Program` (`fivebar_host.program`), with
the pen or laser switching, and the setup every program starts with.

Built once for a job and used by `fivebar convert` (`compile.encode`), the sender and the
daemon (`run.moves.build_program`); written as text only by `fivebar_host.wire`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fivebar_host.compile.model import Job
from fivebar_host.config import Profile
from fivebar_host.program import FIELDS, Kind, Program
from kinematics.arrays import BoolArray


def pen_item(profile: Profile, down: bool) -> Program:
    """The item that lowers (`down`) or raises the pen around a run of drawing segments: the
    servo's `M280` with its move and settle time (docs/protocol.md 6.2) on a pen profile,
    else the laser-enable state at S0 (`M3 S0` / `M5`), which a pen-lift output can follow."""
    pen = profile.pen
    if pen is None:
        return Program.command(Kind.TOOL_ON, s=3) if down else Program.command(Kind.TOOL_OFF)
    pos = pen.down_position if down else pen.up_position
    return Program.command(Kind.PEN, a=pen.move_ms(down),
                           b=pen.down_delay_ms if down else pen.up_delay_ms,
                           s=pen.pulse_us(pos))


def pen_move(profile: Profile, down: bool) -> Program:
    """Move the servo pen on its own (`fivebar pen`, the page's pen buttons): the park
    pulse (`$14`, the pen's up position), then the pen down or up with its move and
    settle time."""
    assert profile.pen is not None
    up = profile.pen.pulse_us(profile.pen.up_position)
    return Program.command(Kind.PEN_PARK, s=up) + pen_item(profile, down)


def tool_on_item(profile: Profile) -> Program:
    """The laser's enable at S0 before a laser job (`[laser] on_command`: M3, or M4)."""
    return Program.command(Kind.TOOL_ON, s=int(profile.laser.on_command[1:]))


def setup(profile: Profile, laser: bool, *, stream: bool = True) -> Program:
    """What every program starts with: absolute targets (`G90`); on a pen profile the pen's
    park pulse (`$14`: the firmware parks the pen there at once and at every boot, hold,
    alarm and silence, and keeps it in its EEPROM) and a pen up with its move and settle
    time, since the pen may have been anywhere before; then the tool off (`M5`). A file
    (`stream=False`) for a laser job keeps only `G90`: it enables the laser next."""
    parts = [Program.command(Kind.ABSOLUTE)]
    if stream or not laser:
        if profile.pen is not None:
            up = profile.pen.pulse_us(profile.pen.up_position)
            parts += [Program.command(Kind.PEN_PARK, s=up), pen_item(profile, False)]
        parts.append(Program.command(Kind.TOOL_OFF))
    return Program.join(parts)


def job_program(job: Job, profile: Profile, laser: bool, first: int = 0,
                end: int | None = None, partial: Program | None = None) -> Program:
    """The items that run segments `first` … `end` − 1 (None: to the job's end) of `job`,
    ending with the tool off (a pen-change stop may cut a run of drawing segments).

    Laser (`laser`, the CLI's explicit `--laser`): the enable at S0 once, then the drawing
    segments carry their power. Pen: power 0 everywhere, the pen down before and up after
    each run of drawing segments (and dwells with the tool on, `Job.tool_on`; `pen_item`).
    A dwell (`compile.dwell`) is a DWELL item. `partial` replaces the first segment's move
    (a segment finished from where the machine stopped inside it, `run.moves`)."""
    if job.raster is not None:
        return raster_program(job, profile, laser, first, end)
    n = job.n_segments if end is None else end
    k = np.arange(first, n, dtype=np.int64)
    m = k.shape[0]
    dwell = job.is_dwell[first:n]
    cols = {"kind": np.where(dwell, Kind.DWELL, Kind.MOVE).astype(np.int64),
            "a": np.where(dwell, 0, job.steps[first + 1:n + 1, 0]).astype(np.int64),
            "b": np.where(dwell, 0, job.steps[first + 1:n + 1, 1]).astype(np.int64),
            "p_us": job.duration_us[first:n].astype(np.int64),
            "s": (job.power[first:n].astype(np.int64) if laser
                  else np.zeros(m, dtype=np.int64)),
            "segment": k}
    if partial is not None and m:
        for f in ("kind", "a", "b", "p_us", "s"):
            cols[f][0] = getattr(partial, f)[0]
    body = Program(cols["kind"], cols["a"], cols["b"], cols["p_us"], cols["s"],
                   cols["segment"])
    if laser:
        return Program.join([tool_on_item(profile), body, Program.command(Kind.TOOL_OFF)])
    return _bracket_pen(body, job.tool_on[first:n], profile)


#: The firmware's boot value of `$0`, the steps a second each motor may make (config.h).
DEFAULT_MAX_RATE = 20000


def raster_program(job: Job, profile: Profile, laser: bool, first: int = 0,
                   end: int | None = None, reached: int | None = None,
                   lead: Program | None = None, into: float = 0.0) -> Program:
    """The items of a raster job's segments `first` … `end` − 1 (`first` a G7 line's first
    segment or a travel segment): RASTER items for the G7 segments (the line's first
    carries its run's index), MOVE items for the moves between scanlines. With `laser` the
    laser is enabled (`M3 S0`) first and off (`M5`) at the end; without it every pixel is
    sent at power 0 (and the firmware, the laser not enabled, would burn none anyway): the
    scan is rehearsed, as a pen job without `--laser` sends S0 on every line.
    A raster faster than the firmware's boot step rate (`$0`) sets it
    first (the setting needs an idle machine: a program starts on one).  `reached`: a
    resumed run got as far as that segment (and `into` of the way through it); the pixels
    changed before that are burned at 0 (`RasterRuns.runs_after`).  `lead` (a resume's
    travel back) runs after the `$0` setting, which needs the machine idle, and before the
    laser is enabled."""
    r = job.raster
    assert r is not None
    runs = r.runs if reached is None else r.runs_after(first, reached, job.duration_us, into)
    if not laser:  # a rehearsal: nothing above power 0 leaves the host without --laser
        runs = tuple(replace(run, powers=bytes(len(run.powers))) for run in runs)
    n = job.n_segments if end is None else end
    g7 = r.g7[first:n]
    body = Program(np.where(g7, Kind.RASTER, Kind.MOVE).astype(np.int64),
                   job.steps[first + 1:n + 1, 0].astype(np.int64),
                   job.steps[first + 1:n + 1, 1].astype(np.int64),
                   job.duration_us[first:n].astype(np.int64),
                   np.where(g7, r.run[first:n], 0).astype(np.int64),
                   np.arange(first, n, dtype=np.int64), runs=runs)
    parts = []
    rate = max_step_rate(job, first, n)
    if rate > DEFAULT_MAX_RATE:
        parts.append(Program.text(f"$0={firmware_rate(rate)}"))
    if lead is not None:
        parts.append(lead)
    if laser:
        parts.append(tool_on_item(profile))
    parts += [body, Program.command(Kind.TOOL_OFF)]
    return Program.join(parts)


def firmware_rate(steps_s: float) -> int:
    """The firmware's `$0` (steps/s) for motion up to `steps_s`: 2 % above it, within the
    setting's 60,000 (docs/protocol.md, settings)."""
    return min(60000, int(steps_s * 1.02) + 1)


def max_step_rate(job: Job, first: int = 0, end: int | None = None) -> float:
    """The most steps a second either motor makes in segments `first` … `end` − 1."""
    n = job.n_segments if end is None else end
    d = np.abs(np.diff(job.steps[first:n + 1].astype(np.int64), axis=0)).max(axis=1, initial=0)
    t = job.duration_us[first:n].astype(np.float64) * 1e-6
    moving = t > 0
    return float((d[moving] / t[moving]).max()) if moving.any() else 0.0


def _bracket_pen(body: Program, draw: BoolArray, profile: Profile) -> Program:
    """`body` with the pen down before and up after each run of drawing items, and the tool
    off at the end (unless the last pen up already is `M5`)."""
    m = len(body)
    prev = np.concatenate(([False], draw[:-1]))
    nxt = np.concatenate((draw[1:], [False]))
    down = draw & ~prev
    up = draw & ~nxt
    # where each body item lands: after the downs up to it and the ups before it
    pos = np.arange(m) + np.cumsum(down) + np.concatenate(([0], np.cumsum(up)[:-1]))
    total = m + int(down.sum()) + int(up.sum())
    out = Program.of(np.zeros(total, dtype=np.int64))
    cols = {f: getattr(out, f) for f in FIELDS}
    for f in FIELDS:
        cols[f][pos] = getattr(body, f)
    for flags, offset, item in ((down, -1, pen_item(profile, True)),
                                (up, 1, pen_item(profile, False))):
        at = pos[flags] + offset
        for f in FIELDS:
            cols[f][at] = getattr(item, f)[0]
    prog = Program(**cols, texts=body.texts)
    if total == 0 or prog.kind[-1] != Kind.TOOL_OFF:
        prog = prog + Program.command(Kind.TOOL_OFF)
    return prog
