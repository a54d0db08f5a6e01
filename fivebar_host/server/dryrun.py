"""The dry run of a submission: the CLI's report and preview picture, nothing queued.

`POST /api/dryrun` (server.routes.submit) compiles a drawing exactly as a submission is
compiled, then answers `fivebar plot --dry-run`'s report lines (`dryrun.report_lines`) and
preview picture (`report.preview.draw_preview`, PNG) — all of it in one compiling process
(server.compiler), so neither the job nor the picture's drawing runs in the daemon that
streams.
"""

from __future__ import annotations

import base64
import tempfile
import threading
from pathlib import Path

from pydantic import BaseModel, Field

from fivebar_host.compile import Job, nbar_opinion
from fivebar_host.config import Profile
from fivebar_host.report.text.dryrun import format_duration, report_lines
from fivebar_host.run.stops import Copies, planned_time_s
from fivebar_host.server.jobs import JobOptions, compile_upload

#: Resolution of the dry run's preview picture (the CLI's file is 130 dpi).
PREVIEW_DPI = 80

#: matplotlib's pyplot keeps global state: one preview is drawn at a time.
_PREVIEW_LOCK = threading.Lock()


class DryRunOut(BaseModel):
    """A checked drawing, not queued."""

    name: str
    report: list[str] = Field(description="The dry-run report, line for line as "
                              "`fivebar plot --dry-run` prints it.")
    estimated_s: float
    estimate: str = Field(description="The estimate for people (\"4 min 5 s\").")
    max_dev_mm: float | None
    tolerance_mm: float
    segments: int
    paths: int
    mode: str
    warnings: list[str] = Field(description="The report's notes.")
    preview_png: str = Field(description="The preview picture, PNG, base64.")


def _dry_run(job: Job, profile: Profile, laser: bool,
             copies: Copies | None = None) -> tuple[list[str], bytes]:
    """The CLI's report lines and preview picture (PNG bytes) of a compiled job (`copies`:
    the run's copies and page delay, in the time line)."""
    from fivebar_host.report.preview import draw_preview  # matplotlib only in report/

    if job.raster is not None:  # an image: the raster report and the burn as planned
        from fivebar_host.raster import preview

        with tempfile.TemporaryDirectory(prefix="fivebar-preview-") as d, _PREVIEW_LOCK:
            path = Path(d) / "preview.png"
            preview.draw_preview(job, path)
            return preview.report_lines(job, laser, copies), path.read_bytes()
    lines = report_lines(job, nbar_opinion(job, profile), laser=laser, profile=profile,
                         copies=copies)
    with tempfile.TemporaryDirectory(prefix="fivebar-preview-") as d, _PREVIEW_LOCK:
        out = draw_preview(job, profile, Path(d) / "preview.png", dpi=PREVIEW_DPI)
        return lines, out.read_bytes()


def dry_run_upload(data: bytes, name: str, opts: JobOptions, profile: Profile) -> DryRunOut:
    """Compile a submission as `compile_upload` does and answer its dry run; all of it in
    one compiling process (`server.compiler`), so neither the job nor the preview's
    drawing runs in the daemon that streams."""
    job = compile_upload(data, name, opts, profile).job
    copies = opts.copies_plan()
    lines, png = _dry_run(job, profile, opts.laser, copies)
    dev = None if job.max_dev_mm != job.max_dev_mm else float(job.max_dev_mm)
    total_s = planned_time_s(job, copies)
    return DryRunOut(name=name, report=lines, estimated_s=round(total_s, 3),
                     estimate=format_duration(total_s), max_dev_mm=dev,
                     tolerance_mm=job.tolerance_mm, segments=job.n_segments,
                     paths=job.n_paths, mode=job.mode, warnings=list(job.notes),
                     preview_png=base64.b64encode(png).decode("ascii"))
