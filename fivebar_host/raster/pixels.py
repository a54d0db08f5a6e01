"""Every pixel boundary placed in time on the motion the machine really runs, and the G7
lines that carry the powers (docs/protocol.md 6.4).

The firmware runs a piece of C cycles with n steps on a motor with step k at
floor((2k−1)C/2n): the motor passes position k − ½ at step k, so its continuous position
is n·t/C — the joints move on the straight line between the piece's quantised ends at a
constant rate.  The pen, by forward kinematics of that line, crosses each pixel boundary
σᵢ = i·h of the scanline at one time tᵢ inside one piece; it is found on the quantised
angles (not the ideal ones) by solving (FK(θⱼ + λΔθⱼ) − P₀)·d = σᵢ for λ with the secant
method (the along-track position is monotone and nearly linear in λ; three steps reach
1e-9 mm).  Change i puts pixel i's power on the laser at tᵢ; one more at the last pixel's
exit puts 0.

Consecutive pieces are grouped into G7 lines greedily: a piece joins the line before it
while the line stays within the link's line (`LINE_LIMIT` bytes, counted by the wire's own
writer with 6-digit line numbers, `wire.g7_body`), its run
within the firmware's pixel ring, and the run's changes within `FIT_CYCLES` of one
arithmetic progression U + i·T (integer cycles from the line's first piece) — the form a
G7 line gives them.  The residual left by the fit is kept per line (`Group.residual`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile.steps import step_angles
from fivebar_host.raster.motion import RasterCtx, ScanMotion
from kinematics.arrays import FloatArray

CYCLES_PER_US = 16
#: The most a change may differ from its line's progression U + i·T, cycles (2.5 µs).
FIT_CYCLES = 40


@dataclass(frozen=True)
class Changes:
    """A scanline's laser changes: cycles from its start (float) and powers."""

    t: FloatArray
    power: NDArray[np.uint8]


#: The piece parameters λ the along-track position is sampled at (`crossings`).
_LAMBDA = np.linspace(0.0, 1.0, 5)
#: Their Vandermonde matrix's inverse: samples → coefficients of s(λ) = Σ cₘλᵐ.
_VINV = np.linalg.inv(np.vander(_LAMBDA, increasing=True))


def crossings(ctx: RasterCtx, sm: ScanMotion, powers: NDArray[np.uint8]) -> Changes:
    """The scanline's laser changes on its executed motion (module docstring); `powers`
    are its pixels in scan order."""
    th = step_angles(sm.steps, ctx.home, ctx.spr)
    fk = ctx.checker.forward
    cyc = sm.duration_us.astype(np.float64) * CYCLES_PER_US
    start = np.concatenate(([0.0], np.cumsum(cyc)))
    bound = np.arange(sm.n_px + 1, dtype=np.float64) * ctx.grid.pitch
    # one forward kinematics for the piece ends and every piece's λ samples (each point
    # on its own: only the pieces holding a boundary are used below)
    k = th.shape[0] - 1
    q = th[:-1, None, :] + _LAMBDA[None, :, None] * (th[1:] - th[:-1])[:, None, :]
    pts, _ = fk(np.concatenate((th, q.reshape(-1, 2))))
    s_end = (pts[:k + 1] - sm.p0) @ sm.d  # executed along-track σ of every piece end
    s_all = ((pts[k + 1:] - sm.p0) @ sm.d).reshape(-1, _LAMBDA.shape[0])
    j = np.clip(np.searchsorted(s_end, bound, side="right") - 1, 0, len(cyc) - 1)
    # the pieces holding a boundary: `np.unique(j)`, without its sort where j is sorted
    # (the executed piece ends advance along the line)
    new = np.empty(j.shape[0], dtype=bool)
    new[0] = True
    np.not_equal(j[1:], j[:-1], out=new[1:])
    if (j[1:] >= j[:-1]).all():
        used, which = j[new], np.cumsum(new) - 1
    else:
        used, which = np.unique(j, return_inverse=True)
    s = s_all[used]
    # s(λ) of each boundary's piece, exact at both ends: cₘ per boundary, m = 0 … 4, each
    # row contiguous (the Newton steps below run on whole rows)
    c = np.ascontiguousarray((s @ _VINV.T).T)[:, which]
    s0, s1 = s_end[j], s_end[j + 1]
    lam = np.minimum(np.maximum((bound - s0) / np.where(s1 != s0, s1 - s0, 1.0), 0.0), 1.0)
    c4x4, c3x3, c2x2 = 4 * c[4], 3 * c[3], 2 * c[2]  # the derivative's coefficients
    f, df = np.empty_like(lam), np.empty_like(lam)
    for _ in range(4):  # Newton on the quartic (Horner) from the linear guess
        # f = (((c₄λ + c₃)λ + c₂)λ + c₁)λ + c₀ − σᵢ,  f' = ((4c₄λ + 3c₃)λ + 2c₂)λ + c₁
        np.multiply(c[4], lam, out=f)
        for m in (3, 2, 1):
            f += c[m]
            f *= lam
        f += c[0]
        f -= bound
        np.multiply(c4x4, lam, out=df)
        df += c3x3
        df *= lam
        df += c2x2
        df *= lam
        df += c[1]
        if not df.all():
            df[df == 0] = 1.0
        f /= df
        np.subtract(lam, f, out=lam)
        np.maximum(lam, 0.0, out=lam)
        np.minimum(lam, 1.0, out=lam)
    t = start[j] + lam * cyc[j]
    return Changes(t, np.concatenate((np.asarray(powers, dtype=np.uint8), [0])).astype(np.uint8))


def fit(offsets: FloatArray) -> tuple[int, int, float]:
    """U, T (integer cycles) and the largest residual of offsets ≈ U + i·T."""
    n = offsets.shape[0]
    if n == 0:
        return 0, 0, 0.0
    if n == 1:
        u = round(float(offsets[0]))
        return u, 0, abs(offsets[0] - u)
    i = np.arange(n)
    best: tuple[int, int, float] | None = None
    t0 = (float(offsets[-1]) - float(offsets[0])) / (n - 1)
    for t in {int(np.floor(t0)), int(np.ceil(t0))}:
        r = offsets - i * t
        u = round((float(r.max()) + float(r.min())) / 2)
        res = float(np.abs(r - u).max())
        if best is None or res < best[2]:
            best = (u, t, res)
    assert best is not None
    return best


def piece_residual(sm: ScanMotion, ch: Changes) -> float:
    """The largest residual of one piece's changes against their own progression (what a
    line of that piece alone leaves), cycles: `fit` on every piece with three changes or
    more, at once."""
    start = np.concatenate(([0], np.cumsum(sm.duration_us.astype(np.int64) * CYCLES_PER_US)))
    piece = np.searchsorted(start, ch.t, side="right") - 1
    step = piece[1:] != piece[:-1]
    if (piece[1:] >= piece[:-1]).all():  # (the changes in time order: each piece's first)
        cuts = np.concatenate(([0], np.flatnonzero(step) + 1))
    else:
        cuts = np.searchsorted(piece, np.unique(piece))
    n = np.diff(np.concatenate((cuts, [piece.shape[0]]))).astype(np.int64)
    big = n > 2
    if not big.any():
        return 0.0
    first = cuts
    last = cuts + n - 1
    t0 = (ch.t[last] - ch.t[first]) / np.maximum(n - 1, 1)
    who = np.repeat(np.arange(cuts.shape[0]), n)
    i = np.arange(piece.shape[0]) - first[who]
    off = ch.t - start[piece]
    best = np.full(cuts.shape[0], np.inf)
    for t in (np.floor(t0), np.ceil(t0)):
        r = off - i * t[who]
        mx, mn = np.maximum.reduceat(r, cuts), np.minimum.reduceat(r, cuts)
        u = np.maximum(np.rint((mx + mn) / 2), 0.0)  # U ≥ 0 on the wire
        best = np.minimum(best, np.maximum(mx - u, u - mn))
    return float(best[big].max())
