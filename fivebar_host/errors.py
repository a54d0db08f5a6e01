"""Errors of the job pipeline: one message that says where (file, path, source line, point) and
why, so a refused drawing can be fixed without guessing.

`InputError` is raised while reading a drawing (unreadable file, malformed XML, unsupported
G-code word, NaN or enormous coordinates, nothing to draw). `JobError` is raised while
compiling a job (a point out of reach, beyond a joint limit, too close to a singularity, a
working-mode change, a drawing that does not fit). Both are `ValueError`s so callers that only
know "bad input" can catch them together.

Every error a user can see derives from `FivebarError` (defined on the lowest floor,
`kinematics.errors`, and exported here): the CLI catches that root and the OS errors it
names, nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass

from kinematics.errors import FivebarError, bounded, shorten

__all__ = ["FivebarError", "InputError", "JobError", "OptionError", "UsageError", "Where",
           "bounded", "shorten"]


class OptionError(FivebarError, ValueError):
    """A job option with a value outside its definition (`fivebar_host.options`), or an
    option that does not exist; `option` is its name as the user wrote it."""

    def __init__(self, option: str, why: str) -> None:
        super().__init__(f"{option}: {why}")
        self.option = option
        self.why = why


class UsageError(FivebarError, ValueError):
    """Options that contradict each other or make no sense for this input (`--fit` with
    `--scale`, `--layer` on a G-code file); the message names them."""


class InputError(FivebarError, ValueError):
    """A drawing that cannot be read; the message names the file and the line/element."""

    def __init__(self, message: str, file: str | None = None, line: int | None = None) -> None:
        where = file or "<input>"
        if line is not None and line > 0:
            where += f":{line}"
        super().__init__(f"{where}: {message}")
        self.file = file
        self.line = line
        self.detail = message


@dataclass(frozen=True)
class Where:
    """Where in the drawing a problem is: the path as the user knows it and the point.

    `path_index` is the 0-based index of the source element (SVG element in document order,
    or G-code stroke); `path_id` the SVG id if any; `source_line` the line in the input file;
    `drawing_xy` the point in the drawing's own frame (SVG page mm from the top-left, y down;
    G-code mm as written) and `machine_xy` the same point in machine mm (M1 at the origin).
    """

    file: str | None = None
    path_index: int | None = None
    path_id: str | None = None
    source_line: int | None = None
    drawing_xy: tuple[float, float] | None = None
    machine_xy: tuple[float, float] | None = None
    what: str = "path"  # "path", "travel", "move from home", "move to home"

    def describe(self) -> str:
        """One human-readable clause: 'drawing.svg:12 path #3 (id "leaf") at ...'."""
        parts: list[str] = []
        loc = self.file or ""
        if self.source_line:
            loc += f":{self.source_line}"
        if loc:
            parts.append(loc)
        if self.path_index is not None:
            label = f"{self.what} #{self.path_index}"
            if self.path_id:
                label += f' (id "{self.path_id}")'
            parts.append(label)
        elif self.what != "path":
            parts.append(self.what)
        if self.drawing_xy is not None:
            parts.append(f"drawing ({self.drawing_xy[0]:.3f}, {self.drawing_xy[1]:.3f}) mm")
        if self.machine_xy is not None:
            parts.append(f"machine ({self.machine_xy[0]:.3f}, {self.machine_xy[1]:.3f}) mm")
        return ", ".join(parts)


class JobError(FivebarError, ValueError):
    """A drawing that the machine cannot execute as asked; nothing has moved.

    Carries `where` (a `Where`) and `reason` (a short stable key such as "reach",
    "joint_limit", "type1_margin", "type2_margin", "mode_change", "does_not_fit",
    "tolerance") besides the human message.
    """

    def __init__(self, message: str, where: Where | None = None, reason: str = "") -> None:
        text = message if where is None else f"{where.describe()}: {message}"
        super().__init__(text)
        self.where = where
        self.reason = reason
        self.detail = message

