"""Compiling an image into a raster `Job`: image → powers → scan grid → scanlines planned at
one pen speed → G7 lines → the job's segments, with `Job.raster` (`raster.runs`).

`RasterOptions` holds what a burn is asked with (`fivebar plot photo.jpg --laser`, the
options of `fivebar_host.options`).  The image's size is `width_mm`/`height_mm` (one keeps
its shape), else its resolution `dpi` (else the file's own, else 96, a browser's CSS pixel);
the burn resolution `resolution` (pixels per mm on the scan grid; default: the image's own
pixels) resamples it (area-weighted when smaller, bilinear when larger) before the image
mode turns darkness into powers.

The pen speed is `speed_mm_s` (default the profile's draw feed), lowered where the joints
or the link need it (`raster.speed`): one speed for the whole image, so the dose per pixel
is the same on every scanline.

Segments: from the homed pose a checked move to the first scanline's overscan start, then
per scanline its pieces (G7: ramp in, image, ramp out) and the move to the next one, then
the move back home.  The job's `draw` marks the image pieces; its power is 0 everywhere
(the G7 runs carry the pixels).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.compile.model import CompileOptions, Job
from fivebar_host.compile.place import find_home, setup
from fivebar_host.compile.steps import absolute_steps
from fivebar_host.config import Profile
from fivebar_host.errors import InputError, JobError, OptionError, Where
from fivebar_host.raster import assemble, image, motion, speed
from fivebar_host.raster import grid as gridmod
from fivebar_host.raster.modes import ImageMode, to_powers
from fivebar_host.raster.runs import RasterRuns
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.segment import PoseChecker
from kinematics.arrays import FloatArray

#: The chord of a scan piece may bow this share of the tolerance off the line (the rest is
#: the step quantisation's).
CHORD_SHARE = 0.5
#: Pixels of one scan piece at most (about what a 127-byte G7 line carries).
K_MAX = 40
#: A browser's CSS pixel when the file states no resolution.
DEFAULT_DPI = 96.0


@dataclass(frozen=True)
class RasterOptions:
    """How an image is burned (module docstring)."""

    mode: ImageMode = ImageMode()  # noqa: RUF009 (frozen: one shared default is fine)
    width_mm: float | None = None
    height_mm: float | None = None
    dpi: float | None = None
    resolution: float | None = None  # burn pixels per mm
    angle_deg: float = 0.0
    bidirectional: bool = True
    passes: int = 1
    speed_mm_s: float | None = None
    origin_mm: tuple[float, float] | None = None


def pixel_size(gray: image.Gray, ro: RasterOptions) -> tuple[float, float]:
    """(w, h) mm of one image pixel (module docstring)."""
    h_px, w_px = gray.shape
    if ro.width_mm is not None or ro.height_mm is not None:
        for name, v in (("--width", ro.width_mm), ("--height", ro.height_mm)):
            if v is not None and not (math.isfinite(v) and v > 0):
                raise OptionError(name, f"must be a positive size; got {v!r}")
        sx = ro.width_mm / w_px if ro.width_mm is not None else None
        sy = ro.height_mm / h_px if ro.height_mm is not None else None
        return (sx or sy or 1.0), (sy or sx or 1.0)
    dpi = (ro.dpi, ro.dpi) if ro.dpi is not None else gray.dpi or (DEFAULT_DPI, DEFAULT_DPI)
    if not all(math.isfinite(d) and d > 0 for d in dpi):
        raise OptionError("--dpi", f"must be positive; got {dpi[0]!r}")
    return 25.4 / dpi[0], 25.4 / dpi[1]


def resample(dark: FloatArray, size_mm: tuple[float, float], pitch: float) -> FloatArray:
    """Darkness resampled to square pixels of `pitch` mm over an image `size_mm` (w, h)."""
    from PIL import Image

    w = max(1, round(size_mm[0] / pitch))
    h = max(1, round(size_mm[1] / pitch))
    if (h, w) == dark.shape:
        return dark
    img = Image.fromarray(np.asarray(dark, dtype=np.float32), mode="F")
    smaller = w < dark.shape[1] or h < dark.shape[0]
    out = img.resize((w, h), Image.Resampling.BOX if smaller else Image.Resampling.BILINEAR)
    return np.clip(np.asarray(out, dtype=np.float64), 0.0, 1.0)


def _checker(profile: Profile, mode: str) -> PoseChecker:
    kin = profile.kinematics
    return PoseChecker(profile.geometry, mode, 1 if kin.assembly == "+" else -1,
                       kin.min_type1_margin_rad, kin.min_type2_margin_rad,
                       profile.motors.limits_rad)


def _top_left(profile: Profile, mode: str, size: tuple[float, float],
              origin: tuple[float, float] | None, file: str) -> FloatArray:
    """The image's top-left corner on the machine: `origin`, or centred in the largest safe
    rectangle of its shape (as an SVG is centred)."""
    if origin is not None:
        return np.asarray(origin, dtype=np.float64)
    kin = profile.kinematics
    pf = layout.safe_area(profile.geometry, mode, kin.min_type1_margin_rad,
                          kin.min_type2_margin_rad, profile.motors.limits_rad,
                          size[0] / size[1], kin.assembly)
    if pf is None:
        raise JobError(f"working mode {mode} has no singularity-safe area", Where(file=file),
                       "does_not_fit")
    cx, cy = pf.rect.center
    return np.array([cx - size[0] / 2, cy + size[1] / 2])


def _placement(grid: gridmod.ScanGrid, how: str) -> layout.Placement:
    box = assemble.machine_bbox(grid.corners_mm())
    return layout.Placement(np.eye(2), np.zeros(2), 1.0, 0.0, box, box, None, how)


def compile_raster(path: str | Path, profile: Profile, ro: RasterOptions,
                   gray: image.Gray | None = None) -> Job:
    """Read and compile an image (module docstring); `gray` when it is already read (an
    SVG `<image>`). Raises `InputError`, `JobError` or `OptionError`."""
    file = str(path)
    refuse_servo(profile, file)
    with located(file):
        return _compile(file, profile, ro, gray)


@contextmanager
def located(file: str) -> Iterator[None]:
    """A `JobError` raised inside that names no place is raised again naming `file`."""
    try:
        yield
    except JobError as e:
        if e.where is None:
            raise JobError(e.detail, Where(file=file), e.reason) from None
        raise


def refuse_servo(profile: Profile, file: str) -> None:
    """`JobError` on servo joints: the servo build has no pixel timer."""
    if profile.joints is not None:
        raise JobError("raster engraving needs stepper joints: the servo build of the firmware "
                       "has no pixel interrupt and refuses G7 (docs/protocol.md 6.5)",
                       Where(file=file), "servo_joints")


def _grid(file: str, g: image.Gray, ro: RasterOptions, profile: Profile, mode: str
          ) -> gridmod.ScanGrid:
    """The image's powers on its scan grid, placed on the machine (module docstring)."""
    pw, ph = pixel_size(g, ro)
    size = (g.shape[1] * pw, g.shape[0] * ph)
    if ro.resolution is not None:
        if not (math.isfinite(ro.resolution) and ro.resolution > 0):
            raise OptionError("--resolution", f"must be positive; got {ro.resolution!r}")
        pitch = 1.0 / ro.resolution
        dark, px = resample(g.dark, size, pitch), (pitch, pitch)
    else:
        dark, px = g.dark, (pw, ph)
    powers = to_powers(dark, ro.mode)
    return gridmod.scan_grid(powers, px, _top_left(profile, mode, size, ro.origin_mm, file),
                             ro.angle_deg)


def fine_note(g: image.Gray, ro: RasterOptions, profile: Profile) -> list[str]:
    """The image burned at its own pixels where they are finer than the laser's spot: each
    burns as a spot-wide dot over its neighbours, the scan takes (spot/pixel)² more pixels
    (and lines) than it can show, so the job says so, with the option that resamples."""
    if ro.resolution is not None:
        return []
    pw, ph = pixel_size(g, ro)
    spot = profile.laser.spot_mm
    if max(pw, ph) >= 0.5 * spot:
        return []
    gain = spot * spot / (pw * ph)
    return [f"the image's pixels are {pw:.4g} × {ph:.4g} mm, finer than the laser's "
            f"{spot:g} mm spot ([laser] spot_mm): --line-interval {spot:g}mm burns the same "
            f"picture in {gain:.0f}× fewer pixels"]


def _compile(file: str, profile: Profile, ro: RasterOptions, gray: image.Gray | None) -> Job:
    g = gray if gray is not None else image.load(file)
    notes = list(g.notes) + fine_note(g, ro, profile)
    mode = raster_mode(profile, file)
    grid = _grid(file, g, ro, profile, mode)
    how = "origin" if ro.origin_mm is not None else "centred"
    return burn_grid(file, profile, mode, grid, ro, notes, _placement(grid, how),
                     "nothing to burn: every pixel is white at these settings")


def raster_mode(profile: Profile, file: str) -> str:
    """The working mode a raster job runs in: the profile's, else the homed pose's."""
    su = setup(profile, CompileOptions(), profile.kinematics.working_mode)
    return su.mode if su.mode != "auto" else find_home(su, file).mode


def burn_grid(file: str, profile: Profile, mode: str, grid: gridmod.ScanGrid,
              ro: RasterOptions, notes: list[str], placement: layout.Placement,
              empty: str) -> Job:
    """The job that burns a scan grid's powers (the part every raster route shares: an
    image, `raster.fill`'s filled shapes): its scanlines (`ro`'s direction and passes)
    planned at one pen speed, the G7 pieces, `RasterRuns` and the job's segments, placed
    by `placement`; `empty` is the `InputError` when no cell burns."""
    checker = _checker(profile, mode)
    lines = gridmod.scanlines(grid, ro.bidirectional, ro.passes)
    if not lines:
        raise InputError(empty, file)
    v0 = ro.speed_mm_s if ro.speed_mm_s is not None else profile.motion.draw_feed_mm_s
    ctx = motion.RasterCtx(profile, checker, grid, v0, CHORD_SHARE * profile.motion.tolerance_mm,
                           K_MAX)
    home_steps = absolute_steps(np.asarray(profile.motors.home_rad).reshape(1, 2),
                                profile.motors.home_rad, profile.motors.steps_per_rev)[0]
    pl = speed.plan_image(ctx, lines, home_steps, notes)
    col = pl.collected
    residual = max((gr.residual for gs in pl.groups for gr in gs), default=0.0)
    seg = col.seg
    info = RasterRuns(np.concatenate(seg.g7), np.concatenate(seg.run), np.concatenate(seg.scan),
                      tuple(col.runs), assemble.scan_infos(pl.scans, pl.changes, col.spans),
                      (float(grid.origin[0]), float(grid.origin[1])),
                      (float(grid.u[0]), float(grid.u[1])), (float(grid.n[0]), float(grid.n[1])),
                      grid.pitch, grid.interval, grid.powers, pl.ctx.v,
                      min(sm.accel for sm in pl.scans), residual, file, tuple(notes))
    return assemble.build_job(profile, checker, file, mode, home_steps, seg, info,
                              placement, notes)


def raster_options(values: Mapping[str, Any], profile: Profile) -> RasterOptions:
    """The raster options of a job's option values (`fivebar_host.options`, keyed by field
    name): the image's size and resolution, its mode and powers (`--power-max` defaults to
    the profile's [laser] power), the scan's angle, direction, passes and speed
    (`--draw-speed`), its place (`--origin`: the image's top-left corner)."""
    pmax = values.get("power_max")
    mode = ImageMode(str(values.get("image_mode") or "grayscale"),
                     int(values.get("power_min") or 0),
                     int(profile.laser.power if pmax is None else pmax),
                     float(values.get("gamma") or 1.0), float(values.get("threshold") or 0.5),
                     bool(values.get("negative")))
    li = values.get("line_interval_mm")
    return RasterOptions(mode, values.get("width_mm"), values.get("height_mm"),
                         values.get("dpi"), None if li is None else 1.0 / float(li),
                         float(values.get("scan_angle_deg") or 0.0),
                         not bool(values.get("one_way")), int(values.get("passes") or 1),
                         values.get("draw_feed_mm_s"), values.get("origin_mm"))
