"""Where a run keeps its resume point: a file beside the drawing, or the daemon's database.

A run that stops before its end (a fault, Ctrl-C and abort, a quit at a pen change) saves a
`ResumePoint` (`run.resume`); `--resume` (or the daemon's resume request) loads it. A
controller that keeps its own record across a crash (fivebar's firmware: `Ln` done and the
position, docs/protocol.md 7) also tells the store when a stream starts, so that a daemon
that dies mid-stream can map that record back to the exact segment (`StreamStart`). The run
knows only `ResumeStore`; `FileStore` is the CLI's (`<drawing>.fivebar-resume.json`), the
daemon's lives in its SQLite queue (`server.store`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from fivebar_host.run.resume import ResumePoint, resume_path


@dataclass(frozen=True)
class StreamStart:
    """A stream a controller is about to write: its first line number and how many lines,
    the segments it runs (`start` … `end` − 1, None: to the job's end), the position it
    starts from, and the copy (`--copies`) it draws — `run.moves.build_program`'s inputs,
    so the very program can be built again."""

    first_line: int
    lines: int
    start: int
    end: int | None
    start_position: tuple[int, int]
    copy: int


class ResumeStore(Protocol):
    """Keeps one job's resume point (module doc)."""

    #: Where the point is kept, for messages (the resume file's path, "job 12").
    name: str

    def load(self) -> ResumePoint:
        """The saved point; `SendError` naming the store when there is none or it cannot
        be read."""
        ...

    def save(self, point: ResumePoint) -> None:
        """Keep `point` (atomically: a crash leaves the old one or the new one)."""
        ...

    def clear(self) -> None:
        """The job ran to its end: forget the point."""
        ...

    def stream_started(self, stream: StreamStart) -> None:
        """A stream starts (before its first line is written)."""
        ...

    def hint(self) -> str:
        """How a person continues from the saved point, for the run's error messages
        ("" when the face says it itself)."""
        ...


class FileStore:
    """The resume file beside the drawing (`resume_path`). A stream's start needs no record
    here: a fault that leaves the position unknown writes the stream into the file itself
    (`ResumePoint.has_stream`)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = str(path)

    @classmethod
    def beside(cls, drawing: str | Path) -> FileStore:
        """The store of `drawing`'s resume file."""
        return cls(resume_path(drawing))

    def load(self) -> ResumePoint:
        return ResumePoint.load(self.path)

    def save(self, point: ResumePoint) -> None:
        point.save(self.path)

    def clear(self) -> None:
        self.path.unlink(missing_ok=True)

    def stream_started(self, stream: StreamStart) -> None:
        return None

    def hint(self) -> str:
        return f"resume file: {self.path} — continue with the same command and --resume"
