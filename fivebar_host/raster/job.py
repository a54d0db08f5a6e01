"""Compiling an image into a raster `Job`: image → powers → scan grid → scanlines planned at
one pen speed → G7 lines → the job's segments, with `Job.raster` (`raster.runs`).

`RasterOptions` holds what a burn is asked with (`fivebar plot photo.jpg --laser`, the
options of `fivebar_host.options`).  The image's size is `width_mm`/`height_mm` (one keeps
its shape), else its resolution `dpi` (else the file's own, else 96, a browser's CSS pixel);
the burn resolution `resolution` (pixels per mm on the scan grid; default: the image's own
pixels) resamples it (area-weighted when smaller, bilinear when larger) before the image
mode turns darkness into powers.

The pen speed is `speed_mm_s` (default the profile's draw feed), lowered where needed so
that (1) no joint exceeds `SPEED_SHARE` of `max_joint_rad_s` over the image, and (2) the
link keeps up: the wire lines, in order, at `compile.linkrate.LINK_SHARE` of the link's
byte rate, each arriving before its first segment runs, the firmware holding at most
`BUFFER_BYTES` of them ahead (`link_lateness`).  One speed for the whole image: the dose
per pixel is the same on every scanline.

Segments: from the homed pose a checked move to the first scanline's overscan start, then
per scanline its pieces (G7: ramp in, image, ramp out) and the move to the next one, then
the move back home.  The job's `draw` marks the image pieces; its power is 0 everywhere
(the G7 runs carry the pixels).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import linkrate
from fivebar_host.compile.model import CompileOptions, Job, PathStats
from fivebar_host.compile.place import find_home, setup
from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.config import Profile
from fivebar_host.errors import InputError, JobError, OptionError, Where
from fivebar_host.program import PixelRun
from fivebar_host.raster import grid as gridmod
from fivebar_host.raster import image, motion, pixels, travel
from fivebar_host.raster.modes import ImageMode, to_powers
from fivebar_host.raster.runs import RasterRuns, ScanInfo
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.geometry import Drawing
from fivebar_host.toolpath.segment import PoseChecker
from kinematics.arrays import FloatArray, IntArray

#: Share of max_joint_rad_s the scan speed may ask of a joint.
SPEED_SHARE = 0.9
#: The firmware's buffering a stream can get ahead by: its receive ring (255), its line
#: buffer and pixel ring (128 each), less a line of margin.
BUFFER_BYTES = 380
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

    mode: ImageMode = ImageMode()
    width_mm: float | None = None
    height_mm: float | None = None
    dpi: float | None = None
    resolution: float | None = None  # burn pixels per mm
    angle_deg: float = 0.0
    bidirectional: bool = True
    passes: int = 1
    speed_mm_s: float | None = None
    origin_mm: tuple[float, float] | None = None


@dataclass(frozen=True)
class Planned:
    """The scanlines planned at one speed: their motion, changes and G7 lines."""

    ctx: motion.RasterCtx
    scans: list[motion.ScanMotion]
    changes: list[pixels.Changes]
    groups: list[list[pixels.Group]]


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


def plan_line(ctx: motion.RasterCtx, sl: gridmod.Scanline
              ) -> tuple[motion.ScanMotion, pixels.Changes]:
    """One scanline planned, with its changes: scan pieces short enough that each piece's
    changes fit one progression U + i·T within `pixels.FIT_CYCLES` (the pen's speed drifts
    slightly along a joint-space chord; in cycles the drift grows as the speed falls, and
    quadratically with the piece's length)."""
    row = ctx.grid.powers[sl.row, sl.c0:sl.c1]
    row = row if sl.sign > 0 else row[::-1]
    k = motion.scan_k(ctx, sl)
    while True:
        sm = motion.plan(ctx, sl, k)
        ch = pixels.crossings(ctx, sm, row)
        worst = pixels.piece_residual(sm, ch)
        if worst <= pixels.FIT_CYCLES or k == 1:
            return sm, ch
        k = max(1, min(k - 1, math.floor(k * math.sqrt(pixels.FIT_CYCLES / worst) * 0.9)))


def plan_all(ctx: motion.RasterCtx, lines: list[gridmod.Scanline]) -> Planned:
    """Every scanline planned at ctx.v, its changes and its G7 lines."""
    scans, changes, groups = [], [], []
    for sl in lines:
        sm, ch = plan_line(ctx, sl)
        scans.append(sm)
        changes.append(ch)
        groups.append(pixels.groups(sm, ch))
    return Planned(ctx, scans, changes, groups)


def speed_cap(ctx: motion.RasterCtx, lines: list[gridmod.Scanline]) -> float:
    """The fastest pen speed no joint exceeds `SPEED_SHARE` of its limit at (module doc)."""
    mot = ctx.profile.motion
    wmax = SPEED_SHARE * min(mot.max_joint_rad_s,
                             protocol.SETTINGS[0][2] * 2 * math.pi / ctx.spr)
    g = max(motion.gains(ctx, sl, 0.0, (sl.c1 - sl.c0) * ctx.grid.pitch)[0] for sl in lines)
    return wmax / g


def link_lateness(line_bytes: list[int], line_start_s: list[float], rate: float) -> float:
    """How late the latest wire line arrives, s (≤ 0: none is late): the lines streamed in
    order at `rate` bytes/s, never more than `BUFFER_BYTES` of them sent and not yet begun,
    the job's clock starting when its first line has arrived (its line l begins at
    `line_start_s[l]` on that clock)."""
    if not line_bytes:
        return 0.0
    t0 = line_bytes[0] / rate
    t, ahead, started, worst = 0.0, 0, 0, -math.inf
    for i, b in enumerate(line_bytes):
        while started < i and t0 + line_start_s[started] <= t:
            ahead -= line_bytes[started]
            started += 1
        while ahead + b > BUFFER_BYTES and started < i:
            t = max(t, t0 + line_start_s[started])
            ahead -= line_bytes[started]
            started += 1
        t += b / rate
        ahead += b
        worst = max(worst, t - (t0 + line_start_s[i]))
    return worst


def _placement(grid: gridmod.ScanGrid, how: str) -> layout.Placement:
    from fivebar_host.raster.assemble import machine_bbox

    box = machine_bbox(grid.corners_mm())
    return layout.Placement(np.eye(2), np.zeros(2), 1.0, 0.0, box, box, None, how)


def _wire_lateness(ctx: motion.RasterCtx, pl: Planned, home: IntArray) -> float:
    from fivebar_host.raster.assemble import collect

    _, _, _, wire = collect(ctx.profile, ctx.checker, pl.scans, pl.groups, home)
    return link_lateness(wire.nbytes, wire.start_s, linkrate.bytes_per_s(ctx.profile))


def compile_raster(path: str | Path, profile: Profile, ro: RasterOptions,
                   gray: image.Gray | None = None) -> Job:
    """Read and compile an image (module docstring); `gray` when it is already read (an
    SVG `<image>`). Raises `InputError`, `JobError` or `OptionError`."""
    from fivebar_host.raster.assemble import build_job, collect, scan_infos

    file = str(path)
    try:
        return _compile(file, profile, ro, gray, (build_job, collect, scan_infos))
    except JobError as e:
        if e.where is None:
            raise JobError(e.detail, Where(file=file), e.reason) from None
        raise


def _compile(file: str, profile: Profile, ro: RasterOptions, gray: image.Gray | None,
             fns: tuple) -> Job:  # type: ignore[type-arg]
    build_job, collect, scan_infos = fns
    g = gray if gray is not None else image.load(file)
    notes = list(g.notes)
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
    su = setup(profile, CompileOptions(), profile.kinematics.working_mode)
    home = find_home(su, file)
    mode = su.mode if su.mode != "auto" else home.mode
    checker = _checker(profile, mode)
    grid = gridmod.scan_grid(powers, px, _top_left(profile, mode, size, ro.origin_mm, file),
                             ro.angle_deg)
    lines = gridmod.scanlines(grid, ro.bidirectional, ro.passes)
    if not lines:
        raise InputError("nothing to burn: every pixel is white at these settings", file)
    v0 = ro.speed_mm_s if ro.speed_mm_s is not None else profile.motion.draw_feed_mm_s
    ctx = motion.RasterCtx(profile, checker, grid, v0, CHORD_SHARE * profile.motion.tolerance_mm,
                           K_MAX)
    cap = speed_cap(ctx, lines)
    if cap < v0:
        notes.append(f"speed {v0:g} → {cap:.1f} mm/s: the joints' speed limit along the image")
        ctx = replace(ctx, v=cap)
    home_steps = absolute_steps(np.asarray(profile.motors.home_rad).reshape(1, 2),
                                profile.motors.home_rad, profile.motors.steps_per_rev)[0]
    pl = plan_all(ctx, lines)
    for _ in range(6):  # the link's floor: one speed for the whole image
        late = _wire_lateness(ctx, pl, home_steps)
        if late <= 0:
            break
        total = sum(sm.time_us for sm in pl.scans) * 1e-6
        v_new = ctx.v * total / (total + late) * 0.97
        notes.append(f"speed {ctx.v:.1f} → {v_new:.1f} mm/s: what the link carries")
        ctx = replace(ctx, v=v_new)
        pl = plan_all(ctx, lines)
    seg, runs, spans, _ = collect(profile, checker, pl.scans, pl.groups, home_steps)
    residual = max((gr.residual for gs in pl.groups for gr in gs), default=0.0)
    info = RasterRuns(np.concatenate(seg.g7), np.concatenate(seg.run), np.concatenate(seg.scan),
                      tuple(runs), scan_infos(pl.scans, pl.changes, spans),
                      (float(grid.origin[0]), float(grid.origin[1])),
                      (float(grid.u[0]), float(grid.u[1])), (float(grid.n[0]), float(grid.n[1])),
                      grid.pitch, grid.interval, grid.powers, ctx.v,
                      min(sm.accel for sm in pl.scans), residual, file, tuple(notes))
    how = "origin" if ro.origin_mm is not None else "centred"
    return build_job(profile, checker, file, mode, home_steps, seg, info,
                     _placement(grid, how), notes)


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
