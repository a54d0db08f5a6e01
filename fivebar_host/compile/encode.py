"""A compiled `Job` as a file for the firmware (`fivebar convert`): the job's program
(`fivebar_host.program`) written by `fivebar_host.wire` under comment headers, plus `write_atomic`
for writing it out safely.
"""

from __future__ import annotations

import math
from pathlib import Path

from fivebar_host.compile.emit import job_program, pen_item, setup
from fivebar_host.compile.model import Job
from fivebar_host.config import Profile
from fivebar_host.program import Kind, Program

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


def encode_lines(job: Job, profile: Profile, relative: bool = False,
                 laser: bool = False) -> list[str]:
    """The lines of `fivebar convert`: comment headers, then the job's program
    (`compile.emit.setup` and `job_program`, the very items `fivebar plot` streams)
    written by `fivebar_host.wire` (docs/protocol.md):

        G90 | G91                      absolute or relative step coordinates
        G1 A<steps> B<steps> P<µs> S<0-255>   one per segment, in job order
        G1 P<µs> S<0-255>              a dwell (G4; `compile.dwell`): no motion
        M5                             at the end

    Laser power is opt-in (issue 6): only with `laser=True` (the CLI's `--laser`) do the
    drawing segments carry the profile's power — `M3 S0` (or `M4 S0`, the profile's
    on_command) once at the start, `S<power>` on drawing segments and S0 on travel. Without
    it every line says S0 and the laser output never turns on; the job is a pen plot, and
    pen down / pen up are the servo's `M280` or `M3 S0` before and `M5` after each run of
    drawing segments (`compile.emit.pen_item`). The header lines are comments the
    firmware ignores.

    The job starts at the homed pose (absolute steps 0, 0); the sender must make sure the
    firmware's position is that before streaming (e.g. after `fivebar home`)."""
    from fivebar_host import wire

    prog = Program.join([setup(profile, laser, stream=False),
                         job_program(job, profile, laser)])
    h = job.home_rad
    top = int(prog.s[prog.kind == Kind.MOVE].max(initial=0)) if laser else 0
    switch = " / ".join(wire.bodies(Program.join([pen_item(profile, True),
                                                  pen_item(profile, False)])))
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
        _comment(f"laser: power from the profile, S up to {top}" if laser
                 else f"pen: S0 on every line; pen down/up = {switch}"),
    ]
    return head + wire.file_lines(prog, relative)


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
