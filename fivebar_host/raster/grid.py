"""The pixels on the machine: the scan grid and its scanlines.

The image is placed upright on the machine (image x → machine +x, image rows downward →
machine −y), its top-left corner at `origin_mm` or centred in the largest safe rectangle
of its shape (as an SVG is).  The burn runs on a *scan grid*: rows `interval` mm apart
across the scan direction u = (cos φ, sin φ) (φ the scan angle), cells `pitch` mm long
along it; row r covers t ∈ [r·g, (r+1)·g) across (n = u turned −90°, "down the image" at
φ = 0) and cell c covers s ∈ [c·h, (c+1)·h) along, from the grid's origin.  At φ = 0 with
the image's own pixel size the grid is the image; otherwise each cell takes the power of
the image pixel under its centre (nearest neighbour; outside the image: 0).

A *scanline* is one pass over a row between its first and last burned cell (blank ends
are skipped: the laser-off travel between scanlines takes their place); empty rows are
skipped.  Bidirectional scanning (the default) alternates the direction from one scanline
to the next, one-way scans all run +u; `passes` repeats the whole image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray


@dataclass(frozen=True)
class Scanline:
    """One pass over cells [c0, c1) of scan-grid row `row`, in direction `sign` (+1: +u)."""

    row: int
    c0: int
    c1: int
    sign: int
    pass_no: int = 0


@dataclass(frozen=True)
class ScanGrid:
    """The scan grid on the machine (module docstring) and its target powers (R, C)."""

    origin: FloatArray  # machine mm of the grid's corner (s = 0, t = 0)
    u: FloatArray  # unit vector along the scan
    n: FloatArray  # unit vector across (row 0 → row 1)
    pitch: float  # h, mm per cell along the scan
    interval: float  # g, mm between rows
    powers: NDArray[np.uint8]  # (R, C)

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.powers.shape[0]), int(self.powers.shape[1])

    def point(self, s: FloatArray | float, row: int | FloatArray) -> FloatArray:
        """Machine mm of the point s mm along row `row`'s centre line."""
        t = (np.asarray(row, dtype=np.float64) + 0.5) * self.interval
        s = np.asarray(s, dtype=np.float64)
        out: FloatArray = (self.origin + np.multiply.outer(s, self.u)
                           + np.multiply.outer(t, self.n))
        return out

    def to_grid(self, pts: FloatArray) -> FloatArray:
        """(s, t) mm of machine points in the grid frame (s along, t across)."""
        d = np.asarray(pts, dtype=np.float64) - self.origin
        out: FloatArray = np.stack((d @ self.u, d @ self.n), axis=-1)
        return out

    def corners_mm(self) -> FloatArray:
        """The grid's four corners in machine mm (its extent on the machine)."""
        r, c = self.shape
        s = np.array([0.0, c * self.pitch, c * self.pitch, 0.0])
        t = np.array([0.0, 0.0, r * self.interval, r * self.interval])
        out: FloatArray = self.origin + np.outer(s, self.u) + np.outer(t, self.n)
        return out


def scan_grid(powers: NDArray[np.uint8], pixel_mm: tuple[float, float], top_left: FloatArray,
              angle_deg: float = 0.0, pitch_mm: float | None = None,
              interval_mm: float | None = None) -> ScanGrid:
    """The scan grid of an image of `powers` (H, W) whose pixels are `pixel_mm` (w, h) with
    its top-left corner at `top_left` (machine mm); the scan angle and the grid's pitch and
    interval (default: the pixel's width and height at 0°, their smaller one otherwise)."""
    pw, ph = pixel_mm
    h_img, w_img = powers.shape
    phi = math.radians(angle_deg)
    u = np.array([math.cos(phi), math.sin(phi)])
    n = np.array([math.sin(phi), -math.cos(phi)])
    straight = abs(math.remainder(angle_deg, 360.0)) < 1e-9
    h = float(pitch_mm if pitch_mm is not None else (pw if straight else min(pw, ph)))
    g = float(interval_mm if interval_mm is not None else (ph if straight else min(pw, ph)))
    # the image's corners in the (s, t) frame of a grid with its origin at the top-left
    ex, ey = np.array([1.0, 0.0]), np.array([0.0, -1.0])  # image x, image rows (down)
    corners = np.array([[0.0, 0.0], [w_img * pw, 0.0], [w_img * pw, h_img * ph],
                        [0.0, h_img * ph]])
    pts = corners[:, :1] * ex + corners[:, 1:] * ey
    s, t = pts @ u, pts @ n
    s0, t0 = float(s.min()), float(t.min())
    if straight and pitch_mm is None and interval_mm is None:
        return ScanGrid(np.asarray(top_left, dtype=np.float64), u, n, h, g,
                        np.asarray(powers, dtype=np.uint8))
    cols = max(1, math.ceil((float(s.max()) - s0) / h - 1e-9))
    rows = max(1, math.ceil((float(t.max()) - t0) / g - 1e-9))
    origin = np.asarray(top_left, dtype=np.float64) + s0 * u + t0 * n
    # every cell's centre back in image pixels (nearest neighbour)
    sc = s0 + (np.arange(cols) + 0.5) * h
    tc = t0 + (np.arange(rows) + 0.5) * g
    p = sc[None, :, None] * u + tc[:, None, None] * n  # (R, C, 2) relative to top_left
    ix = np.floor(p[..., 0] / pw).astype(np.int64)
    iy = np.floor(-p[..., 1] / ph).astype(np.int64)
    inside = (ix >= 0) & (ix < w_img) & (iy >= 0) & (iy < h_img)
    out = np.zeros((rows, cols), dtype=np.uint8)
    out[inside] = powers[iy[inside], ix[inside]]
    return ScanGrid(origin, u, n, h, g, out)


def scanlines(grid: ScanGrid, bidirectional: bool = True, passes: int = 1) -> list[Scanline]:
    """The scanlines of the grid in burn order (module docstring)."""
    lit = grid.powers > 0
    any_lit = lit.any(axis=1)
    rows = np.flatnonzero(any_lit)
    first = lit.argmax(axis=1)
    last = lit.shape[1] - lit[:, ::-1].argmax(axis=1)
    out: list[Scanline] = []
    k = 0
    for pn in range(passes):
        for r in rows.tolist():
            sign = -1 if bidirectional and k % 2 else 1
            out.append(Scanline(r, int(first[r]), int(last[r]), sign, pn))
            k += 1
    return out
