"""Dithering darkness into burn / no burn: error diffusion and ordered (Bayer) dithering.

Error diffusion quantises each pixel in raster order (rows top to bottom, each left to
right) to 0 or 1 at the threshold 1/2 and spreads its error e = v − q to the pixels not yet
quantised, with the kernel's published weights (each over the kernel's divisor):

==================  =======  =============================================================
kernel              divisor  weights (row of the pixel: right of it; rows below: −2…+2)
==================  =======  =============================================================
Floyd–Steinberg     16       7 | 3 5 1 (−1…+1)                    (Floyd & Steinberg 1976)
Jarvis–Judice–Ninke 48       7 5 | 3 5 7 5 3 | 1 3 5 3 1          (Jarvis et al. 1976)
Stucki              42       8 4 | 2 4 8 4 2 | 1 2 4 2 1          (Stucki 1981)
Atkinson            8        1 1 | 1 1 1 (−1…+1) | 1 (0)         (Atkinson, Apple, 1980s;
                                                                  6/8 spread, 2/8 dropped)
==================  =======  =============================================================

That is a sequential recurrence, and a Python loop over a megapixel takes seconds.  It is
computed here on wavefronts instead: pixel (r, c) at step t = c + k·r.  Every pixel a
kernel spreads into (r, c) from is at an earlier step when k exceeds the kernel's reach to
the right on the rows below — and with k ≥ the kernel's widest column span (2 for
Floyd–Steinberg, 3 for Atkinson, 4 for Jarvis and Stucki) a pixel's contributions also
arrive in raster order (those of one step from different rows in the order the taps are
applied, farther rows first), so the floating-point sums are the sequential algorithm's,
bit for bit (`tests/test_raster_dither.py` runs a plain loop beside it).  Each step is a
few numpy operations over the pixels of one wavefront (about min(H, W/k) of them), read
and written as strided views of the flat arrays (a megapixel in about 0.03 s).

Ordered dithering compares each pixel with the recursive Bayer matrix (8 × 8, thresholds
(M + ½)/64) tiled over the image.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinematics.arrays import BoolArray, FloatArray


@dataclass(frozen=True)
class Kernel:
    """An error-diffusion kernel: taps (rows below, columns right, weight) over `divisor`,
    and the wavefront slope `k` that keeps the sequential order (module docstring)."""

    name: str
    divisor: int
    taps: tuple[tuple[int, int, int], ...]
    k: int


FLOYD_STEINBERG = Kernel("floyd", 16, ((0, 1, 7), (1, -1, 3), (1, 0, 5), (1, 1, 1)), 2)
JARVIS = Kernel("jarvis", 48, ((0, 1, 7), (0, 2, 5),
                               (1, -2, 3), (1, -1, 5), (1, 0, 7), (1, 1, 5), (1, 2, 3),
                               (2, -2, 1), (2, -1, 3), (2, 0, 5), (2, 1, 3), (2, 2, 1)), 4)
STUCKI = Kernel("stucki", 42, ((0, 1, 8), (0, 2, 4),
                               (1, -2, 2), (1, -1, 4), (1, 0, 8), (1, 1, 4), (1, 2, 2),
                               (2, -2, 1), (2, -1, 2), (2, 0, 4), (2, 1, 2), (2, 2, 1)), 4)
ATKINSON = Kernel("atkinson", 8, ((0, 1, 1), (0, 2, 1), (1, -1, 1), (1, 0, 1), (1, 1, 1),
                                  (2, 0, 1)), 3)
KERNELS = {k.name: k for k in (FLOYD_STEINBERG, JARVIS, STUCKI, ATKINSON)}


def _ordered_taps(kernel: Kernel) -> list[tuple[int, int, float]]:
    """The taps in the order a step applies them: farther rows first, then farther left in
    the row (the order their contributions reach a pixel in the sequential scan)."""
    taps = sorted(kernel.taps, key=lambda t: (-t[0], t[1]))
    return [(dr, dc, w / kernel.divisor) for dr, dc, w in taps]


def diffuse(dark: FloatArray, kernel: Kernel) -> BoolArray:
    """Error diffusion of darkness (H, W) in [0, 1]: True where the pixel burns.

    A wavefront's pixels (r, t − k·r) sit at flat indices t + r·(W − k), evenly spaced, so
    each step reads and writes strided views of the flat arrays (no index arrays); the
    sums are those of `_diffuse_indexed`, element for element."""
    x = np.ascontiguousarray(dark, dtype=np.float64)
    h, w = x.shape
    k = kernel.k
    if w <= k:  # (a view's stride W − k must be positive)
        return _diffuse_indexed(x, kernel)
    out = np.zeros((h, w), dtype=bool)
    pad = 2
    we = w + 2 * pad
    err = np.zeros((h + pad) * we)
    xf, of = x.reshape(-1), out.reshape(-1)
    taps = [(dr * we + dc, wt) for dr, dc, wt in _ordered_taps(kernel)]
    sx, se = w - k, we - k  # flat strides along a wavefront
    for t in range(w + k * (h - 1)):
        r0 = max(0, -(-(t - w + 1) // k))
        r1 = min(h - 1, t // k)
        if r0 > r1:
            continue
        n = r1 - r0
        a = t + r0 * sx  # pixel (r0, t − k·r0)
        view = slice(a, a + n * sx + 1, sx)
        b = r0 * we + t - k * r0 + pad  # its error cell
        v = xf[view] + err[b:b + n * se + 1:se]
        q = v >= 0.5
        of[view] = q
        e = v - q
        for off, wt in taps:
            err[b + off:b + off + n * se + 1:se] += e * wt
    return out


def _diffuse_indexed(dark: FloatArray, kernel: Kernel) -> BoolArray:
    """`diffuse` with index arrays (any width): the wavefronts' pixels gathered and their
    errors scattered row by row."""
    x = np.asarray(dark, dtype=np.float64)
    h, w = x.shape
    out = np.zeros((h, w), dtype=bool)
    if h == 0 or w == 0:
        return out
    pad = 2
    err = np.zeros((h + pad, w + 2 * pad))
    taps = _ordered_taps(kernel)
    k = kernel.k
    rows = np.arange(h)
    for t in range(w + k * (h - 1)):
        r0 = max(0, -(-(t - w + 1) // k))
        r1 = min(h - 1, t // k)
        if r0 > r1:
            continue
        r = rows[r0:r1 + 1]
        c = t - k * r
        v = x[r, c] + err[r, c + pad]
        q = v >= 0.5
        out[r, c] = q
        e = v - q
        for dr, dc, wt in taps:
            err[r + dr, c + pad + dc] += e * wt
    return out


def diffuse_reference(dark: FloatArray, kernel: Kernel) -> BoolArray:
    """The same in plain sequential loops (the definition; slow: tests and small images)."""
    x = np.asarray(dark, dtype=np.float64)
    h, w = x.shape
    err = np.zeros((h + 2, w + 4))
    out = np.zeros((h, w), dtype=bool)
    taps = _ordered_taps(kernel)
    for r in range(h):
        for c in range(w):
            v = x[r, c] + err[r, c + 2]
            q = v >= 0.5
            out[r, c] = q
            e = v - q
            for dr, dc, wt in taps:
                err[r + dr, c + 2 + dc] += e * wt
    return out


def bayer_matrix(order: int = 3) -> FloatArray:
    """The 2^order × 2^order Bayer index matrix M (values 0 … 4^order − 1), built by the
    recursion M_{2n} = [[4M, 4M + 2], [4M + 3, 4M + 1]]."""
    m = np.zeros((1, 1))
    for _ in range(order):
        m = np.block([[4 * m, 4 * m + 2], [4 * m + 3, 4 * m + 1]])
    return m


def ordered(dark: FloatArray, order: int = 3) -> BoolArray:
    """Ordered dithering: burn where darkness exceeds the tiled Bayer threshold (M + ½)/n²."""
    x = np.asarray(dark, dtype=np.float64)
    m = bayer_matrix(order)
    n = m.shape[0]
    thr = (m + 0.5) / (n * n)
    h, w = x.shape
    tiled = np.tile(thr, (-(-h // n), -(-w // n)))[:h, :w]
    out: BoolArray = x > tiled
    return out
