"""The resume point of an interrupted job: where it stopped, as a file and as a record.

A fault writes a `ResumePoint` (`run.store`: next to the drawing, `resume_path`, or in the
daemon's database): the job's `fingerprint`, the first segment not known to be finished, the
position when it is known, and otherwise the stream that ran, so that a later `--resume` can
read the record a controller keeps across a reset (position, `H`, `Ln` done:
docs/protocol.md 7) and map it back to the exact segment (`controllers.fivebar.kept`). The
file is JSON; its field names and values are a format other sessions read (and the daemon
copies the reason into its store).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from fivebar_host.compile import Job
from fivebar_host.run.errors import SendError

RESUME_SUFFIX = ".fivebar-resume.json"


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
    these fields existed read with them None: no stream information. `stream_end` is the
    segment the stream ended before (None: the job's end; a pen-change stop ends a stream
    early, `run.stops`); `copy` the copy (1-based, `--copies`) that was running (None: 1).
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
    stream_end: int | None = None  # segment the stream ended before (None: the job's end)
    copy: int | None = None  # the copy that was running (None: the first)

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
                               opt_int("sent_segment"), opt_int("stream_end"),
                               opt_int("copy"))
        except FileNotFoundError:
            raise SendError(f"{path}: no resume file (nothing was interrupted?)") from None
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
            raise SendError(f"{path}: unreadable resume file: {e}") from e


def resume_path(drawing: str | Path) -> Path:
    """The resume file of a drawing: `<drawing>.fivebar-resume.json` beside it."""
    p = Path(drawing)
    return p.with_name(p.name + RESUME_SUFFIX)


#: Rows hashed at a time by `fingerprint` (the same bytes as one pass, in order).
FINGERPRINT_BLOCK = 1 << 16


def fingerprint(job: Job) -> str:
    """Hash of what the machine would do (steps, durations, laser), to match resume files."""
    h = hashlib.sha256()
    for arr in (job.steps, job.duration_us, job.power, job.draw):
        # integers hashed as int64 whatever the job stores them in (`compact_ints`), so a
        # resume file matches the job by value; in blocks, without a whole int64 copy
        wide = np.int64 if arr.dtype.kind == "i" else arr.dtype
        for i in range(0, arr.shape[0], FINGERPRINT_BLOCK):
            h.update(np.ascontiguousarray(arr[i:i + FINGERPRINT_BLOCK], dtype=wide).tobytes())
    if job.pauses:  # where the pen-change stops are (jobs without any hash as before)
        h.update(repr([(p.segment, p.name) for p in job.pauses]).encode())
    return h.hexdigest()[:16]


def redraw_text(next_segment: int, sent_segment: int | None) -> str:
    """How many segments a resume from `next_segment` may draw a second time."""
    if sent_segment is None:
        return "segments that ran after it before the fault will be drawn again"
    n = max(0, sent_segment - next_segment)
    return f"up to {n} segment{'' if n == 1 else 's'} after it may be drawn twice"
