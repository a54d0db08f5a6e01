"""Encoding a compiled `Job` for the firmware (`fivebar convert`, the sender): the G90/G91
`G1 A B P S` lines of docs/protocol.md with comment headers and pen/laser switching, plus
`write_atomic` for writing them out safely.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile.model import Job
from fivebar_host.config import Profile

#: Longest line the firmware accepts, bytes (docs/protocol.md section 5; the banner repeats it).
MAX_LINE_BYTES = 80


def _comment(text: str) -> str:
    """A comment line the firmware accepts (docs/protocol.md section 5: printable ASCII, at
    most `MAX_LINE_BYTES`): non-ASCII characters become '?', long text is cut."""
    line = "; " + text.encode("ascii", "replace").decode("ascii")
    return line[:MAX_LINE_BYTES]


def mode_sequence(job: Job, arrow: str = " → ") -> str:
    """The working modes a job draws in, in order: "+-", or "++ → +-" with mode changes."""
    seq: list[str] = []
    for m in job.path_modes or (job.mode,):
        if not seq or seq[-1] != m:
            seq.append(m)
    return arrow.join(seq)


def pen_switch_lines(profile: Profile) -> tuple[str, str]:
    """The lines that lower and raise the pen around a run of drawing segments: the servo's
    `M280` (with its move and settle time, docs/protocol.md 6.2) on a pen profile, else the
    laser-enable state at S0 (`M3 S0` / `M5`)."""
    if profile.pen is not None:
        return profile.pen.command(True), profile.pen.command(False)
    return "M3 S0", "M5"


def pen_setup_lines(profile: Profile) -> list[str]:
    """On a pen profile: `$14=<up pulse>` (the firmware parks the pen there at once, and at
    every boot, hold, alarm and silence, and keeps it in its EEPROM), then a pen up with its
    move and settle time, since the pen may have been anywhere before its first pulse."""
    if profile.pen is None:
        return []
    return [f"$14={profile.pen.pulse_us(profile.pen.up_position)}", profile.pen.command(False)]


def encode_lines(job: Job, profile: Profile, relative: bool = False,
                 laser: bool = False) -> list[str]:
    """Firmware-ready lines for a job (docs/protocol.md; each G1 body from
    `protocol.g1`, which checks the word ranges):

        G90 | G91                      absolute or relative step coordinates
        G1 A<steps> B<steps> P<µs> S<0-255>   one per segment, in job order
        G1 P<µs> S<0-255>              a dwell (G4; `compile.dwell`): no motion
        M5                             at the end

    Laser power is opt-in (issue 6): only with `laser=True` (the CLI's `--laser`) do the
    drawing segments carry the profile's power — `M3 S0` (or `M4 S0`, the profile's
    on_command) once at the start, `S<power>` on drawing segments and S0 on travel. Without
    it every line says S0 and the laser output never turns on; the job is a pen plot, and
    pen down / pen up are signalled by `M3 S0` before and `M5` after each run of drawing
    segments (the firmware's laser-enable state, which a pen-lift output can follow; at S0
    it switches no power). The header lines are comments the firmware ignores.

    The job starts at the homed pose (absolute steps 0, 0); the sender must make sure the
    firmware's position is that before streaming (e.g. after `fivebar home`)."""
    st = job.rel_or_abs(relative)
    power = job.power if laser else np.zeros_like(job.power)
    if not laser and job.power.size and int(power.max()) != 0:  # pragma: no cover
        raise AssertionError("pen mode must never send power")
    h = job.home_rad
    head = [
        _comment(f"fivebar job from {Path(job.file).name}"),
        _comment(f"working mode {mode_sequence(job, ' -> ')}, assembly "
                 f"{'+' if job.assembly > 0 else '-'}"
                 + (f", {len(job.mode_changes)} pen-up mode changes" if job.mode_changes
                    else "")),
        _comment(f"{job.n_segments} segments, {job.n_paths} paths, "
                 f"estimated {job.total_time_s:.1f} s"),
        _comment(f"tolerance {job.tolerance_mm:g} mm, max deviation {job.max_dev_mm:.4f} mm"),
        _comment(f"steps count from the homed pose ({math.degrees(h[0]):g}, "
                 f"{math.degrees(h[1]):g}) deg"),
        _comment(f"laser: power from the profile, S up to {int(power.max(initial=0))}"
                 if laser else "pen: S0 on every line; pen down/up = "
                 + " / ".join(pen_switch_lines(profile))),
        "G91" if relative else "G90",
    ]
    body = [protocol.g1(None if w else int(a), None if w else int(b), int(p), int(s))
            for a, b, p, s, w in zip(st[:, 0].tolist(), st[:, 1].tolist(),
                                     job.duration_us.tolist(), power.tolist(),
                                     job.is_dwell.tolist(), strict=True)]
    if laser:
        return [*head, f"{profile.laser.on_command} S0", *body, "M5"]
    out = [*head, *pen_setup_lines(profile), "M5"]
    down, up = pen_switch_lines(profile)
    draw = job.tool_on.tolist()
    n = len(draw)
    for k, line in enumerate(body):
        if draw[k] and (k == 0 or not draw[k - 1]):
            out.append(down)
        out.append(line)
        if draw[k] and (k == n - 1 or not draw[k + 1]):
            out.append(up)
    if out[-1] != "M5":
        out.append("M5")
    return out


def write_atomic(path: str | Path, text: str) -> None:
    """Write text to `path` through a temporary file in the same folder and a rename, so a
    failure never leaves a half-written file."""
    import os
    import tempfile

    out = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp",
                               dir=str(out.parent) if str(out.parent) else ".")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as f:
            f.write(text)
        os.replace(tmp, out)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
