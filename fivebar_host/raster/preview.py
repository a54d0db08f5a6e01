"""A raster job's dry run: its report lines and its preview picture.

The preview shows the burn as it will look: the scan grid's planned powers as darkness
(255 = black), one picture pixel per burn pixel (scaled up to at least `MIN_SIDE` pixels on
the long side), the scan grid upright.  The time estimate is the job's own: every segment's
duration, overscan ramps, the moves between scanlines and every pass included.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fivebar_host.compile.model import Job
from fivebar_host.raster.dose import Figures
from fivebar_host.raster.runs import RasterRuns
from fivebar_host.run.stops import Copies, plan_text
from kinematics.arrays import FloatArray

#: The preview's long side at least, picture pixels.
MIN_SIDE = 400


def raster_of(job: Job) -> RasterRuns:
    """The job's raster part (a raster job's)."""
    r = job.raster
    if r is None:
        raise ValueError("not a raster job")
    return r


def report_lines(job: Job, laser: bool, copies: Copies | None = None) -> list[str]:
    """The dry run's report of a raster job (module docstring); without `laser` it says the
    scan is a rehearsal, every pixel at power 0 (`compile.emit.raster_program`); `copies`
    (`--copies`, `--page-delay`): the run's whole time beside one copy's."""
    r = raster_of(job)
    rows, cols = r.target.shape
    total_s = float(np.sum(job.duration_us)) * 1e-6
    scan_s = sum(float(np.sum(job.duration_us[s.first:s.end])) for s in r.lines) * 1e-6
    passes = 1 + max((s.pass_no for s in r.lines), default=0)
    lit = int(np.count_nonzero(r.target))
    out = [
        f"image         {r.image}",
        f"burn          {cols} × {rows} px at {r.pitch_mm:g} × {r.interval_mm:g} mm "
        f"({cols * r.pitch_mm:.1f} × {rows * r.interval_mm:.1f} mm), {lit} lit",
        f"scanlines     {len(r.lines)} ({passes} pass{'es' if passes > 1 else ''}), "
        f"{r.n_pixels} px scanned (the blank ones between lit ones too)",
        f"speed         {r.speed_mm_s:.1f} mm/s = {r.speed_mm_s / r.pitch_mm:.0f} px/s, "
        f"overscan {r.speed_mm_s ** 2 / (2 * r.accel_mm_s2):.2f} mm "
        f"(ramps at {r.accel_mm_s2:.0f} mm/s²)",
        f"time          {total_s:.1f} s (scanlines with overscan {scan_s:.1f} s, "
        f"moves {total_s - scan_s:.1f} s)",
    ]
    if copies is not None and copies.count > 1:
        from fivebar_host.report.text.dryrun import format_duration

        out.append(f"copies        {plan_text(job, copies, format_duration)}")
    if not laser:
        out.append("tool          laser off: every pixel sent at power 0, the scan only "
                   "rehearsed (burn with --laser)")
    out += [f"note          {n}" for n in job.notes]
    return out


def burn_picture(target: FloatArray | np.ndarray) -> np.ndarray:
    """Greyscale picture (uint8, 255 white) of powers (255 = full power): scaled up by a
    whole factor to at least `MIN_SIDE` on the long side."""
    a = np.asarray(target, dtype=np.float64)
    pic = np.clip(255.0 - a, 0.0, 255.0).round().astype(np.uint8)
    k = max(1, -(-MIN_SIDE // max(pic.shape)))
    return np.kron(pic, np.ones((k, k), dtype=np.uint8))


def draw_preview(job: Job, path: Path) -> None:
    """Write the preview (module docstring): the burn as planned."""
    from PIL import Image

    r = raster_of(job)
    Image.fromarray(burn_picture(r.target)).save(path)


def save_burned(fig: Figures, path: Path) -> None:
    """Write the burned image reconstructed from the trace (`dose.figures`: power per cell,
    255 = full power for a pixel's time) as a picture like the preview's, and beside it
    (`.npz`) the boundaries' placement (mm) and change − crossing times (µs) and the dose
    grid, and the underruns' cycles and whether the emulator lagged there, for a closer
    look."""
    from PIL import Image

    Image.fromarray(burn_picture(fig.dose)).save(path)
    np.savez_compressed(path.with_suffix(".npz"), placement_mm=fig.boundaries.placement_mm,
                        dt_us=fig.boundaries.dt_us, dose=fig.dose, stalls=fig.stalls,
                        stalls_lagging=fig.stalls_lagging, motion_s=fig.motion_s)
