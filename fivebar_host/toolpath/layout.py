"""Layout: where the drawing goes on the machine.

The drawing frame (mm, y up; SVG page bottom-left at the origin, G-code as written) maps to
the machine frame (mm, motor M1 at the origin) by a similarity x ↦ s·R(φ)·x + b:

- `--origin X,Y`: the drawing's origin lands at machine (X, Y) (scale and rotation about the
  drawing origin). The per-point checks then decide whether it can be drawn.
- default for a G-code file: its own coordinates are machine coordinates (origin at machine
  (0, 0), how = "as written"), as a CNC or laser controller runs it. A G-code file is written
  for a machine frame, so moving it silently would draw somewhere else than the file says;
  points out of reach are refused by the per-point checks, with a hint to use --fit or
  --origin.
- default for an SVG (or any page drawing): the drawing's bounding box (after rotation and
  scale) is centred in the largest singularity-safe rectangle of the drawing's aspect in the
  working mode and the machine's assembly mode (`kinematics.workspace.find_page_rectangle`).
- `--fit`: centred, and scaled so the box fills that rectangle.

`does_not_fit_hint` words the "drawing is W × H mm, the safe area is w × h mm" message used
when a placed drawing is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fivebar_host.errors import JobError, UsageError, Where
from fivebar_host.toolpath.extent import bbox
from fivebar_host.toolpath.geometry import Drawing
from kinematics.arrays import FloatArray
from kinematics.fivebar import FiveBar
from kinematics.workspace import NoSafeRegionError, PageFit, Rect, find_page_rectangle


@dataclass(frozen=True)
class Placement:
    """machine = matrix · drawing + offset (mm); with the inputs it came from."""

    matrix: FloatArray
    offset: FloatArray
    scale: float
    rotate_deg: float
    drawing_bbox: tuple[float, float, float, float]  # drawing frame, unscaled, unrotated
    machine_bbox: tuple[float, float, float, float]
    area: Rect | None  # the safe rectangle used for centring/fitting (None with --origin)
    how: str  # "origin", "as written" (G-code default), "centred", "fit"

    def to_machine(self, pts: FloatArray) -> FloatArray:
        return np.asarray(pts, dtype=np.float64) @ self.matrix.T + self.offset

    def to_drawing(self, pts: FloatArray) -> FloatArray:
        inv = np.linalg.inv(self.matrix)
        return (np.asarray(pts, dtype=np.float64) - self.offset) @ inv.T

    @property
    def size_mm(self) -> tuple[float, float]:
        x0, y0, x1, y1 = self.machine_bbox
        return x1 - x0, y1 - y0


#: `Placement.how` of a G-code file drawn at its own coordinates (no --origin, no --fit).
AS_WRITTEN = "as written"


def is_machine_coordinates(drawing: Drawing) -> bool:
    """Whether the drawing comes from a G-code file (every source a G-code cutting run): its
    coordinates are meant as machine coordinates, so the default placement keeps them."""
    return bool(drawing.sources) and all(s.tag == "gcode" for s in drawing.sources)


def keeps_own_coordinates(drawing: Drawing, origin_mm: tuple[float, float] | None,
                          fit: bool) -> bool:
    """Whether `place` draws `drawing` at its own coordinates: a G-code file without --origin
    and --fit (the placement then does not depend on the working mode)."""
    return origin_mm is None and not fit and is_machine_coordinates(drawing)


def safe_area(fb: FiveBar, mode: str, min_type1_rad: float, min_type2_rad: float,
              limits_rad: tuple[tuple[float, float], tuple[float, float]],
              aspect: float | None, assembly: str | None = None) -> PageFit | None:
    """The largest safe rectangle (of `aspect` = width/height if given) in `mode` and
    `assembly` ("+"/"-"; None: either), or None."""
    try:
        return find_page_rectangle(fb, mode, min_type1_rad, min_type2_rad, limits_rad, aspect,
                                   assembly=assembly)
    except NoSafeRegionError:
        return None


def place(drawing: Drawing, fb: FiveBar, mode: str, min_type1_rad: float,
          min_type2_rad: float, limits_rad: tuple[tuple[float, float], tuple[float, float]],
          *, origin_mm: tuple[float, float] | None = None, scale: float | None = None,
          rotate_deg: float = 0.0, fit: bool = False,
          assembly: str | None = None) -> Placement:
    """Place `drawing` on the machine in working mode `mode` and assembly mode `assembly`
    (the machine's; None: either) (see module doc)."""
    if scale is not None and not (math.isfinite(scale) and scale > 0):
        raise UsageError(f"--scale must be a positive number; got {scale!r}")
    if not math.isfinite(rotate_deg):
        raise UsageError(f"--rotate must be a finite angle in degrees; got {rotate_deg!r}")
    if fit and scale is not None:
        raise UsageError("--fit and --scale cannot be used together (--fit chooses the scale)")
    if fit and origin_mm is not None:
        raise UsageError("--fit and --origin cannot be used together (--fit centres the "
                         "drawing in the safe area)")
    phi = math.radians(rotate_deg)
    rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    dbox = bbox(drawing)
    rbox = bbox(drawing.transformed(rot, np.zeros(2))) if rotate_deg % 360.0 else dbox
    bw, bh = rbox[2] - rbox[0], rbox[3] - rbox[1]
    s = 1.0 if scale is None else float(scale)
    if origin_mm is not None or keeps_own_coordinates(drawing, origin_mm, fit):
        a = s * rot
        b = np.asarray(origin_mm if origin_mm is not None else (0.0, 0.0), dtype=np.float64)
        return _finish(a, b, s, rotate_deg, dbox, rbox, None,
                       "origin" if origin_mm is not None else AS_WRITTEN)
    big = max(bw, bh)
    eps = max(big * 1e-3, 1e-6)
    aspect = max(bw, eps) / max(bh, eps)
    pf = safe_area(fb, mode, min_type1_rad, min_type2_rad, limits_rad, aspect, assembly)
    if pf is None:
        asm = "" if assembly is None else f" in assembly {assembly}"
        raise JobError(f"working mode {mode} has no singularity-safe area at all{asm} with "
                       "these margins and joint limits", Where(file=drawing.file),
                       "does_not_fit")
    area = pf.rect
    if fit:
        s = min(area.width / max(bw, eps), area.height / max(bh, eps))
    a = s * rot
    cx, cy = (rbox[0] + rbox[2]) / 2 * s, (rbox[1] + rbox[3]) / 2 * s
    b = np.array(area.center) - np.array([cx, cy])
    return _finish(a, b, s, rotate_deg, dbox, rbox, area, "fit" if fit else "centred")


def _finish(a: FloatArray, b: FloatArray, s: float, rot_deg: float,
            dbox: tuple[float, float, float, float], rbox: tuple[float, float, float, float],
            area: Rect | None, how: str) -> Placement:
    mbox = (rbox[0] * s + b[0], rbox[1] * s + b[1], rbox[2] * s + b[0], rbox[3] * s + b[1])
    return Placement(a, b, s, rot_deg, dbox, mbox, area, how)


def does_not_fit_hint(pl: Placement, fb: FiveBar, mode: str, min_type1_rad: float,
                      min_type2_rad: float,
                      limits_rad: tuple[tuple[float, float], tuple[float, float]],
                      assembly: str | None = None) -> str:
    """'the drawing is 120.0 × 80.0 mm; the largest safe area of that shape in mode +- is
    61.9 × 41.3 mm at (x, y) (largest of any shape: …); try --fit or --scale 0.52'."""
    w, h = pl.size_mm
    eps = max(max(w, h) * 1e-3, 1e-6)
    pf = safe_area(fb, mode, min_type1_rad, min_type2_rad, limits_rad,
                   max(w, eps) / max(h, eps), assembly)
    anyshape = safe_area(fb, mode, min_type1_rad, min_type2_rad, limits_rad, None, assembly)
    msg = f"the drawing is {w:.1f} × {h:.1f} mm"
    if pl.how == AS_WRITTEN:
        x0, y0, x1, y1 = pl.machine_bbox
        msg = (f"a G-code file is drawn at its own coordinates ({x0:.1f}…{x1:.1f}, "
               f"{y0:.1f}…{y1:.1f} mm in the machine frame, motor M1 at (0, 0)): out of reach "
               "or too close to a singularity there; use --fit or --origin X,Y to place it; "
               + msg)
    if pf is None or anyshape is None:
        return msg + f"; working mode {mode} has no safe area" + (
            "" if assembly is None else f" in assembly {assembly}")
    r, q = pf.rect, anyshape.rect
    msg += (f"; the largest safe area of that shape in mode {mode} is {r.width:.1f} × "
            f"{r.height:.1f} mm at ({r.x0:.1f}, {r.y0:.1f}) mm (largest of any shape: "
            f"{q.width:.1f} × {q.height:.1f} mm at ({q.x0:.1f}, {q.y0:.1f}) mm)")
    ratio = min(r.width / max(w, eps), r.height / max(h, eps))
    if ratio < 1.0:
        msg += f"; try --fit or --scale {math.floor(ratio * pl.scale * 100) / 100:g}"
    elif pl.how == "origin":
        msg += "; the drawing would fit: drop --origin to centre it there"
    elif pl.how == AS_WRITTEN:
        mb = pl.machine_bbox
        ox = r.center[0] - (mb[0] + mb[2]) / 2 + pl.offset[0]
        oy = r.center[1] - (mb[1] + mb[3]) / 2 + pl.offset[1]
        msg += f"; the drawing would fit: --origin {ox:.1f},{oy:.1f} centres it there"
    return msg
