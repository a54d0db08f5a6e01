"""One scanline's geometry: the line P(σ) = P₀ + σ·d and the inverse kinematics of its
points (`LineGeo`: each point solved once), and what is solved for every scanline at once
(`solve_bounds`, `max_gain`) so that a large image does not pay a numpy call per scanline
for it.  Batching never changes a value: every point is solved on its own, elementwise,
and a scanline with an unreachable point is solved again on its own, which names it (the
same `JobError` as without the batch).  Module `motion` plans on these.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.errors import JobError
from fivebar_host.raster.grid import ScanGrid, Scanline
from fivebar_host.toolpath.segment import REASON_KEY, CheckFailedError, wrap_to_limits
from kinematics.arrays import FloatArray, IntArray

if TYPE_CHECKING:
    from fivebar_host.raster.motion import RasterCtx

#: Step of the line samples the joint gains are read from, mm.
SAMPLE_MM = 0.5


def line_frame(grid: ScanGrid, sl: Scanline) -> tuple[FloatArray, FloatArray, float]:
    """P₀, d and L of a scanline (module `motion`'s docstring)."""
    h = grid.pitch
    s_entry = sl.c0 * h if sl.sign > 0 else sl.c1 * h
    p0 = grid.point(s_entry, sl.row)
    return p0, sl.sign * grid.u, (sl.c1 - sl.c0) * h


class LineGeo:
    """One scanline's frame and its inverse kinematics, each point solved once: the pixel
    boundaries' angles (or `bounds`, solved with other scanlines'), the samples' every
    `SAMPLE_MM` (grown as the overscan asks; solved `pad_mm` ahead on the first ask), the
    scan pieces' steps per piece size, the ramp acceleration once found.  Unchecked:
    `check` checks a planned scanline's points (its piece ends and the samples over its
    extent) at once."""

    def __init__(self, ctx: RasterCtx, sl: Scanline, pad_mm: tuple[float, float] | None = None,
                 bounds: FloatArray | None = None) -> None:
        self.ctx, self.sl = ctx, sl
        self.p0, self.d, self.length = line_frame(ctx.grid, sl)
        self.n_px = sl.c1 - sl.c0
        self._bounds: FloatArray | None = bounds  # (`solve_bounds`)
        self._k0, self._th = 0, np.zeros((0, 2))
        # samples solved ahead in one batch (`pad_mm`: how far before 0 and after L the
        # planning will likely ask, e.g. the scanline before's overscan): first index,
        # angles, reachable; `samples` takes them where they cover what it asks
        self._pad = pad_mm
        self._pre: tuple[int, FloatArray, NDArray[np.bool_]] = (0, np.zeros((0, 2)),
                                                               np.zeros(0, bool))
        self.accel: float | None = None
        self._scan: dict[tuple[int, int, int], tuple[IntArray, IntArray, FloatArray]] = {}

    @property
    def bounds(self) -> FloatArray:
        """Joint angles of the pixel boundaries (n_px + 1)."""
        if self._bounds is None:
            self._bounds = self.ik(np.arange(self.n_px + 1, dtype=np.float64)
                                   * self.ctx.grid.pitch)
        return self._bounds

    def ik(self, sigma: FloatArray) -> FloatArray:
        """Joint angles (wrapped into the limits) of the line's points at σ; an unreachable
        one is the checked JobError (`_inverse`)."""
        c = self.ctx.checker
        inv = c.fb.inverse_batch(self.p0 + np.multiply.outer(sigma, self.d), c.mode)
        if not inv.valid.all():
            _inverse(self.ctx, self.sl, self.p0, self.d, sigma)
        return wrap_to_limits(inv.angles, self.ctx.profile.motors.limits_rad)[0]

    def samples(self, lo: float, hi: float) -> tuple[FloatArray, FloatArray]:
        """σ and angles of the samples k·`SAMPLE_MM` covering [lo, hi]."""
        k_lo, k_hi = math.floor(lo / SAMPLE_MM), math.ceil(hi / SAMPLE_MM)
        k_hi = max(k_hi, k_lo + 2)
        have_hi = self._k0 + self._th.shape[0]
        if not self._th.shape[0]:
            self._k0, have_hi = k_lo, k_lo
            if self._pad is not None:
                self._prefetch(k_lo - math.ceil(self._pad[0] / SAMPLE_MM),
                               k_hi + 1 + math.ceil(self._pad[1] / SAMPLE_MM))
        if k_lo < self._k0:
            new = self._solved(k_lo, self._k0)
            self._th, self._k0 = np.concatenate((new, self._th)), k_lo
        if k_hi + 1 > have_hi:
            new = self._solved(have_hi, k_hi + 1)
            self._th = np.concatenate((self._th, new))
        i = k_lo - self._k0
        th = self._th[i:i + k_hi - k_lo + 1]
        return np.arange(k_lo, k_hi + 1, dtype=np.float64) * SAMPLE_MM, th

    def _prefetch(self, ka: int, kb: int) -> None:
        """Solve the samples ka … kb − 1 ahead, unchecked, in one call (`_solved` takes
        them)."""
        c = self.ctx.checker
        sigma = np.arange(ka, kb, dtype=np.float64) * SAMPLE_MM
        inv = c.fb.inverse_batch(self.p0 + np.multiply.outer(sigma, self.d), c.mode)
        self._pre = (ka, wrap_to_limits(inv.angles, self.ctx.profile.motors.limits_rad)[0],
                     inv.valid)

    def _solved(self, ka: int, kb: int) -> FloatArray:
        """Angles of the samples ka … kb − 1: the prefetched ones where they cover the range
        and are all reachable (each point is solved on its own: the same angles), else
        `ik`'s (which refuses an unreachable one, naming it)."""
        k0, th, ok = self._pre
        i, j = ka - k0, kb - k0
        if i >= 0 and j <= th.shape[0] and ok[i:j].all():
            return th[i:j]
        return self.ik(np.arange(ka, kb, dtype=np.float64) * SAMPLE_MM)

    def gains(self, lo: float, hi: float) -> tuple[float, float]:
        """Largest |g| (rad/mm) and |dg/dσ| (rad/mm²) of either motor on σ ∈ [lo, hi]."""
        sig, th = self.samples(lo, hi)
        # (differences as slices: np.diff's own overhead counts, called for every try)
        g = (th[1:] - th[:-1]) / (sig[1:] - sig[:-1])[:, None]
        dg = np.abs(g[1:] - g[:-1]) / SAMPLE_MM
        return float(np.abs(g).max()), float(dg.max()) if dg.size else 0.0

    def check(self, sigma: FloatArray, th: FloatArray) -> None:
        """A planned scanline's points and the samples over its extent checked like a
        drawing's (module docstring); JobError naming the row and column of the first
        failing one."""
        ss, ts = self.samples(float(sigma.min()), float(sigma.max()))
        sig = np.concatenate((sigma, ss))
        ang = np.concatenate((th, ts))
        pts = self.p0 + np.multiply.outer(sig, self.d)
        code, m = self.ctx.checker.codes(ang, pts)
        bad = np.flatnonzero(code)
        if bad.size:
            i = int(bad[np.argmin(sig[bad])])
            c = int(code[i])
            msg = self.ctx.checker.explain(c, ang[i], pts[i], m[i])
            raise _named(self.ctx, self.sl, CheckFailedError(
                i, (float(pts[i, 0]), float(pts[i, 1])), REASON_KEY[c], msg), float(sig[i]))

    def scan_part(self, k: int, entry: IntArray) -> tuple[IntArray, IntArray, FloatArray]:
        """The scan pieces at k pixels a piece, entered at absolute steps `entry` (the ramp
        in's last end): their pixel boundaries, the steps of their ends after the entry and
        the executed along-track σ of all their ends (forward kinematics of the quantised
        ends), solved once — the ramps, which `plan` may retry, end on the same steps."""
        key = (k, int(entry[0]), int(entry[1]))
        got = self._scan.get(key)
        if got is None:
            ctx = self.ctx
            ends = piece_ends(self.n_px, k)
            steps = absolute_steps(self.bounds[ends[1:]], ctx.home, ctx.spr)
            th = step_angles(np.concatenate((entry.reshape(1, 2), steps)), ctx.home, ctx.spr)
            pts, _ = ctx.checker.forward(th)
            got = self._scan[key] = (ends, steps, (pts - self.p0) @ self.d)
        return got


#: Pixel boundaries solved at a time by `solve_bounds`.
BOUNDS_BLOCK = 1 << 16


def solve_bounds(ctx: RasterCtx, lines: list[Scanline]) -> list[FloatArray | None]:
    """`LineGeo.bounds` of every scanline, solved in blocks of about `BOUNDS_BLOCK` points
    (each point on its own: the same angles as one scanline at a time, without a call per
    scanline); None for a scanline with an unreachable boundary (its `LineGeo` solves it
    again and names the point)."""
    out: list[FloatArray | None] = []
    c, limits = ctx.checker, ctx.profile.motors.limits_rad
    i = 0
    while i < len(lines):
        block: list[FloatArray] = []
        n = 0
        while i < len(lines) and (not block or n < BOUNDS_BLOCK):
            sl = lines[i]
            p0, d, _ = line_frame(ctx.grid, sl)
            sigma = np.arange(sl.c1 - sl.c0 + 1, dtype=np.float64) * ctx.grid.pitch
            block.append(p0 + np.multiply.outer(sigma, d))
            n += sigma.shape[0]
            i += 1
        inv = c.fb.inverse_batch(np.concatenate(block), c.mode)
        th = wrap_to_limits(inv.angles, limits)[0]
        at = 0
        for pts in block:
            k = pts.shape[0]
            out.append(th[at:at + k] if inv.valid[at:at + k].all() else None)
            at += k
    return out


def _named(ctx: RasterCtx, sl: Scanline, e: CheckFailedError, s: float) -> JobError:
    """The JobError of a failing point σ = s of the scanline: its row and pixel column."""
    col = sl.c0 + s / ctx.grid.pitch if sl.sign > 0 else sl.c1 - s / ctx.grid.pitch
    where = ("in the overscan before" if s < 0 else "in the overscan after"
             if s > (sl.c1 - sl.c0) * ctx.grid.pitch else "at")
    return JobError(f"scanline of row {sl.row}: {where} column {col:.1f} "
                    f"({e.point[0]:.2f}, {e.point[1]:.2f}) mm: {e.message}", None, e.reason)


def _inverse(ctx: RasterCtx, sl: Scanline, p0: FloatArray, d: FloatArray,
             sigma: FloatArray) -> FloatArray:
    """Checked joint angles of the line's points at σ; a failing point is a JobError naming
    the row and the pixel column."""
    pts = p0 + np.multiply.outer(sigma, d)
    try:
        return ctx.checker.inverse(pts)
    except CheckFailedError as e:
        raise _named(ctx, sl, e, float(sigma[e.index])) from None


def gains(ctx: RasterCtx, sl: Scanline, lo: float, hi: float) -> tuple[float, float]:
    """Largest |g| (rad/mm) and |dg/dσ| (rad/mm²) of either motor on σ ∈ [lo, hi]."""
    return LineGeo(ctx, sl).gains(lo, hi)


def piece_ends(n_px: int, k: int) -> IntArray:
    """Pixel boundaries that end the scan pieces (k pixels each, the last the rest)."""
    return np.asarray([*range(0, n_px, k), n_px], dtype=np.int64)


def max_gain(ctx: RasterCtx, lines: list[Scanline]) -> float:
    """The largest |g| (rad/mm) of either motor over every scanline's own extent [0, L]:
    `gains(ctx, sl, 0, L)[0]` of every line, its samples solved in blocks of about
    `BOUNDS_BLOCK` points (each difference within one scanline, as on its own)."""
    best = -math.inf
    c, limits = ctx.checker, ctx.profile.motors.limits_rad
    i = 0
    while i < len(lines):
        first, pts, sig = i, [], []
        n = 0
        while i < len(lines) and (i == first or n < BOUNDS_BLOCK):
            sl = lines[i]
            p0, d, length = line_frame(ctx.grid, sl)
            k_hi = max(math.ceil(length / SAMPLE_MM), 2)  # `LineGeo.samples(0, L)`
            s = np.arange(0, k_hi + 1, dtype=np.float64) * SAMPLE_MM
            pts.append(p0 + np.multiply.outer(s, d))
            sig.append(s)
            n += s.shape[0]
            i += 1
        inv = c.fb.inverse_batch(np.concatenate(pts), c.mode)
        if not inv.valid.all():  # the first such scanline's error, named as on its own
            for sl in lines[first:i]:
                gains(ctx, sl, 0.0, (sl.c1 - sl.c0) * ctx.grid.pitch)
        th = wrap_to_limits(inv.angles, limits)[0]
        s_all = np.concatenate(sig)
        inner = np.ones(s_all.shape[0] - 1, dtype=bool)  # differences within one line
        inner[np.cumsum([x.shape[0] for x in sig])[:-1] - 1] = False
        g = (th[1:] - th[:-1])[inner] / (s_all[1:] - s_all[:-1])[inner][:, None]
        best = max(best, float(np.abs(g).max()))
    return best
