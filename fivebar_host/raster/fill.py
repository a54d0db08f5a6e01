"""Laser scan fill (`fivebar plot drawing.svg --laser --fill scan`, docs/fill.md): a
drawing's filled regions burned by scanlines through the raster machinery.

The drawing is placed exactly as its vector job would be (`toolpath.layout.place` with the
job's `--fit`, `--scale`, `--rotate`, `--origin`, centring), and its exact fill-rule regions
(`toolpath.fill.regions`, shapely) are taken in machine millimetres.  The *burned area* is
what a browser paints: the non-white fills in paint order, a later white fill (`PaintTable.
paper`) erasing what lies beneath it (`painted_region`).

That area becomes a scan grid (`fill_grid`): rows `--line-interval` mm apart (default the
profile's [laser] spot_mm) across the scan direction (`--scan-angle`), square cells along
it; a cell burns, at `--power-max` (default the profile's [laser] power), when its centre is
inside the painted area (`shapely.contains_xy`, vectorised).  So the burned edges are exact
to half a cell along the scan and half an interval across it.  From the grid on, the job is
the image route's own (`raster.job.burn_grid`: scanlines, one pen speed, overscan,
bidirectional or `--one-way`, `--passes`, G7 pieces, the job's segments).

Strokes (outlines) are not engraved by a scan fill; the job's notes say how many stroked
elements were left out.  Refused (`OptionError`/`JobError`, nothing sent): `--fill scan`
without `--laser`, with `--hatch`, on a G-code file, on a drawing with no filled shape, and
on a servo-joint profile (as every raster job).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.compile.fill import FINE
from fivebar_host.compile.model import CompileOptions, Job
from fivebar_host.compile.place import setup
from fivebar_host.config import Profile
from fivebar_host.errors import JobError, OptionError, Where
from fivebar_host.options import compile_values
from fivebar_host.raster.grid import ScanGrid
from fivebar_host.raster.job import burn_grid, raster_mode, raster_options, refuse_servo
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.fill.paint import NO_FILL, PaintTable
from fivebar_host.toolpath.fill.regions import fill_regions
from fivebar_host.toolpath.geometry import Drawing

#: Scan-grid rows tested against the region at once (bounds the memory of a large grid).
ROWS_PER_CHUNK = 256
#: G-code files: no fills (`compile.job.GCODE_SUFFIXES`, repeated to keep imports light).
_GCODE = {".gcode", ".nc", ".ngc", ".gc", ".g", ".tap", ".cnc"}


def wanted(values: Mapping[str, Any]) -> bool:
    """Whether the option values ask for a scan fill (`--fill scan`)."""
    return values.get("fill") == "scan"


def refuse(file: str, values: Mapping[str, Any], profile: Profile) -> None:
    """The refusals that need no reading (module docstring)."""
    if not values.get("laser"):
        raise OptionError("--fill", "scan burns the filled shapes with the laser: give "
                          "--laser too (a pen fills with --hatch)")
    if values.get("hatch_mm") is not None:
        raise OptionError("--fill", "--fill scan and --hatch are two ways of filling: give "
                          "one of them")
    if Path(file).suffix.lower() in _GCODE:
        raise OptionError("--fill", "a G-code file has no filled shapes; --fill scan needs an "
                          "SVG drawing")
    refuse_servo(profile, file)


def painted_region(d: Drawing, tol: float) -> BaseGeometry:
    """What a browser paints of `d`'s fills (module docstring), built within `tol`."""
    paint = d.paint or PaintTable.empty(len(d.sources))
    regions = fill_regions(d, tol)
    painted: BaseGeometry = shapely.Polygon()
    pending: list[BaseGeometry] = []
    for s in sorted(regions):
        if paint.paper.shape[0] > s and paint.paper[s]:
            if pending:
                painted = shapely.union_all([painted, *pending])
                pending = []
            if not painted.is_empty:
                painted = painted.difference(regions[s])
        else:
            pending.append(regions[s])
    if pending:
        painted = shapely.union_all([painted, *pending])
    return painted


def fill_grid(region: BaseGeometry, pitch: float, interval: float, angle_deg: float,
              power: int) -> ScanGrid:
    """The scan grid over `region` (machine mm): rows `interval` apart across the scan at
    `angle_deg`, cells `pitch` long; a cell burns at `power` when its centre is inside."""
    phi = math.radians(angle_deg)
    u = np.array([math.cos(phi), math.sin(phi)])
    n = np.array([math.sin(phi), -math.cos(phi)])
    xy = shapely.get_coordinates(region)
    s, t = xy @ u, xy @ n
    s0, t0 = float(s.min()), float(t.min())
    cols = max(1, math.ceil((float(s.max()) - s0) / pitch - 1e-9))
    rows = max(1, math.ceil((float(t.max()) - t0) / interval - 1e-9))
    origin = s0 * u + t0 * n
    shapely.prepare(region)
    sc = (np.arange(cols) + 0.5) * pitch
    powers = np.zeros((rows, cols), dtype=np.uint8)
    for r0 in range(0, rows, ROWS_PER_CHUNK):
        tc = (np.arange(r0, min(rows, r0 + ROWS_PER_CHUNK)) + 0.5) * interval
        p = origin + sc[None, :, None] * u + tc[:, None, None] * n
        lit = shapely.contains_xy(region, p[..., 0], p[..., 1])
        powers[r0:r0 + tc.shape[0]][lit] = power
    return ScanGrid(origin, u, n, float(pitch), float(interval), powers)


def stroked_elements(d: Drawing) -> int:
    """Elements of `d` with a painted stroke (the outlines a scan fill leaves out)."""
    paint = d.paint or PaintTable.empty(len(d.sources))
    drawn = np.unique(d.stroke_source)
    drawn = drawn[drawn < paint.stroked.shape[0]]
    return int(paint.stroked[drawn].sum())


def place_fill(d: Drawing, profile: Profile, values: Mapping[str, Any], mode: str
               ) -> tuple[layout.Placement, BaseGeometry]:
    """The vector job's placement of `d` in `mode` and the painted area in machine mm."""
    opts = CompileOptions(**compile_values(values))
    su = setup(profile, opts, mode)
    pl = layout.place(d, su.fb, mode, su.min1, su.min2, su.limits, origin_mm=opts.origin_mm,
                      scale=opts.scale, rotate_deg=opts.rotate_deg, fit=opts.fit,
                      assembly=su.asm)
    return pl, painted_region(d.transformed(pl.matrix, pl.offset), su.tol * FINE)


def compile_fill_scan(path: str | Path, profile: Profile, values: Mapping[str, Any],
                      drawing: Drawing | None = None) -> Job:
    """The scan-fill job of a drawing file (module docstring); `drawing` when it is already
    read (an upload). Raises `OptionError`, `JobError` or the reader's `InputError`."""
    file = str(path)
    refuse(file, values, profile)
    if drawing is None:
        from fivebar_host.compile.job import read_drawing

        drawing = read_drawing(path, tuple(values.get("layers") or ()),
                               values.get("max_segments"), profile)
    paint = drawing.paint
    if paint is None or not (paint.rule != NO_FILL).any():
        raise JobError("nothing in the drawing is filled: --fill scan burns filled shapes "
                       "(draw the outlines without it, or fill them with --hatch)",
                       Where(file=file), "nothing_filled")
    given = values.get("mode")
    mode = str(given) if given not in (None, "auto") else raster_mode(profile, file)
    pl, region = place_fill(drawing, profile, values, mode)
    if region.is_empty:
        raise JobError("nothing to burn: every filled shape is covered by white fills",
                       Where(file=file), "nothing_filled")
    ro = raster_options(values, profile)
    li = values.get("line_interval_mm")
    interval = float(li) if li is not None else float(profile.laser.spot_mm)
    grid = fill_grid(region, interval, interval, ro.angle_deg, ro.mode.power_max)
    notes = [f"--fill scan: {int((grid.powers > 0).sum())} cells of "
             f"{interval:g} × {interval:g} mm burn the filled shapes "
             f"({region.area:.1f} mm² painted)"]
    k = stroked_elements(drawing)
    if k:
        notes.append(f"{k} stroked element{'s' if k != 1 else ''} not engraved: --fill scan "
                     "burns fills only (plot without --fill scan for the outlines)")
    return burn_grid(file, profile, mode, grid, ro, notes, pl,
                     "nothing to burn: no scan cell's centre is inside a filled shape "
                     f"(--line-interval {interval:g} mm is coarser than the shapes)")
