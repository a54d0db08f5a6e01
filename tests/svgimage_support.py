"""Shared by the SVG `<image>` tests: a test pattern, SVGs that place it, and the scan grid
`raster.svgimage` makes of an SVG in the drawing frame (no machine placement), as a boolean
mask on the page's CSS pixels."""

from __future__ import annotations

import base64
import io
from pathlib import Path

import numpy as np

from fivebar_host.raster.modes import ImageMode, to_powers
from fivebar_host.raster.svgimage import images_grid, load_images
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.svg import read_svg

MM_PER_PX = 25.4 / 96
PAGE = (240, 180)  # CSS px


def pattern() -> bytes:
    """A 16 × 12 PNG: black blocks on white, asymmetric (an "F" and a corner dot), so that a
    flip or a quarter turn shows."""
    from PIL import Image

    a = np.full((12, 16), 255, np.uint8)
    a[1:11, 2:4] = 0  # the F's stem
    a[1:3, 2:10] = 0  # its top bar
    a[5:7, 2:8] = 0  # its middle bar
    a[8:11, 12:15] = 0  # a block bottom right
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG")
    return buf.getvalue()


def data_uri(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode()


def svg(body: str, view: str | None = None) -> str:
    """An SVG page of `PAGE` CSS px holding `body` (its user unit a CSS px unless `view`)."""
    w, h = PAGE
    vb = view or f"0 0 {w} {h}"
    return (f'<svg xmlns="http://www.w3.org/2000/svg" '
            f'xmlns:xlink="http://www.w3.org/1999/xlink" width="{w}" height="{h}" '
            f'viewBox="{vb}">{body}</svg>')


def lit_mask(text: str, folder: Path | None = None, angle_deg: float = 0.0) -> np.ndarray:
    """The page's CSS pixels whose centre lies in a lit cell of the scan grid of `text`
    (one cell = one CSS px; placed as the drawing is, so drawing frame = machine frame)."""
    d = read_svg(text.encode(), file=str((folder or Path(".")) / "t.svg"))
    imgs = load_images(d, folder)
    pl = layout.Placement(np.eye(2), np.zeros(2), 1.0, 0.0, (0, 0, 1, 1), (0, 0, 1, 1), None,
                          "origin")
    mode = ImageMode("threshold", 0, 255, 1.0, 0.5, False)
    powers = [to_powers(p.gray.dark, mode) for p in imgs]
    grid = images_grid(imgs, pl, powers, MM_PER_PX / 2, angle_deg)
    w, h = PAGE
    ys, xs = np.mgrid[0:h, 0:w]
    px = np.stack(((xs + 0.5) * MM_PER_PX, (h - ys - 0.5) * MM_PER_PX), axis=-1)
    st = grid.to_grid(px.reshape(-1, 2))
    c = np.floor(st[:, 0] / grid.pitch).astype(int)
    r = np.floor(st[:, 1] / grid.interval).astype(int)
    rows, cols = grid.shape
    ok = (r >= 0) & (r < rows) & (c >= 0) & (c < cols)
    lit = np.zeros(r.shape, bool)
    lit[ok] = grid.powers[r[ok], c[ok]] > 0
    out: np.ndarray = lit.reshape(h, w)
    return out


def near(a: np.ndarray, b: np.ndarray, k: int = 1) -> int:
    """Pixels set in `a` farther than `k` px (chessboard) from any set in `b`."""
    grown = b.copy()
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            grown |= np.roll(np.roll(b, dy, axis=0), dx, axis=1)
    return int((a & ~grown).sum())
