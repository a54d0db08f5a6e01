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

from fivebar_host import protocol
from fivebar_host.compile.steps import step_angles
from fivebar_host.raster.motion import RasterCtx, ScanMotion
from kinematics.arrays import FloatArray, IntArray

CYCLES_PER_US = 16
#: The longest G7 line the host writes, newline included: half the firmware's 255-byte
#: receive ring, so that one is on its way while the firmware parses the other.
LINE_LIMIT = 127
#: The most a change may differ from its line's progression U + i·T, cycles (2.5 µs).
FIT_CYCLES = 40
#: The firmware's pixel ring and a record's header (fb_raster.h).
PX_RING = 128


@dataclass(frozen=True)
class Changes:
    """A scanline's laser changes: cycles from its start (float) and powers."""

    t: FloatArray
    power: NDArray[np.uint8]


@dataclass(frozen=True)
class Group:
    """One G7 line: its pieces [first, first + count) of the scanline and its run (the
    first change U cycles after the line's first piece starts, then every T)."""

    first: int
    count: int
    u: int
    t: int
    powers: bytes
    residual: float  # largest |change − (U + i·T)|, cycles


def crossings(ctx: RasterCtx, sm: ScanMotion, powers: NDArray[np.uint8]) -> Changes:
    """The scanline's laser changes on its executed motion (module docstring); `powers`
    are its pixels in scan order."""
    th = step_angles(sm.steps, ctx.home, ctx.spr)
    fk = ctx.checker.forward
    pts, _ = fk(th)
    s_end = (pts - sm.p0) @ sm.d  # executed along-track σ of every piece end
    cyc = sm.duration_us.astype(np.float64) * CYCLES_PER_US
    start = np.concatenate(([0.0], np.cumsum(cyc)))
    bound = np.arange(sm.n_px + 1, dtype=np.float64) * ctx.grid.pitch
    j = np.clip(np.searchsorted(s_end, bound, side="right") - 1, 0, len(cyc) - 1)
    dth = th[j + 1] - th[j]

    def along(lam: FloatArray) -> FloatArray:
        p, _ = fk(th[j] + lam[:, None] * dth)
        out: FloatArray = (p - sm.p0) @ sm.d - bound
        return out

    lo, hi = np.zeros_like(bound), np.ones_like(bound)
    f_lo, f_hi = s_end[j] - bound, s_end[j + 1] - bound
    lam = np.clip(-f_lo / np.where(f_hi != f_lo, f_hi - f_lo, 1.0), 0.0, 1.0)
    for _ in range(3):  # secant steps from the linear guess
        f = along(lam)
        lo, f_lo = np.where(f < 0, lam, lo), np.where(f < 0, f, f_lo)
        hi, f_hi = np.where(f >= 0, lam, hi), np.where(f >= 0, f, f_hi)
        lam = np.clip(lo - f_lo * (hi - lo) / np.where(f_hi != f_lo, f_hi - f_lo, 1.0),
                      0.0, 1.0)
    t = start[j] + lam * cyc[j]
    return Changes(t, np.concatenate((np.asarray(powers, dtype=np.uint8), [0])).astype(np.uint8))


def fit(offsets: FloatArray) -> tuple[int, int, float]:
    """U, T (integer cycles) and the largest residual of offsets ≈ U + i·T."""
    n = offsets.shape[0]
    if n == 0:
        return 0, 0, 0.0
    if n == 1:
        u = int(round(float(offsets[0])))
        return u, 0, abs(offsets[0] - u)
    i = np.arange(n)
    best: tuple[int, int, float] | None = None
    t0 = (float(offsets[-1]) - float(offsets[0])) / (n - 1)
    for t in {int(np.floor(t0)), int(np.ceil(t0))}:
        r = offsets - i * t
        u = int(round((float(r.max()) + float(r.min())) / 2))
        res = float(np.abs(r - u).max())
        if best is None or res < best[2]:
            best = (u, t, res)
    assert best is not None
    return best


def piece_residual(sm: ScanMotion, ch: Changes) -> float:
    """The largest residual of one piece's changes against their own progression (what a
    line of that piece alone leaves), cycles."""
    start = np.concatenate(([0], np.cumsum(sm.duration_us.astype(np.int64) * CYCLES_PER_US)))
    piece = np.searchsorted(start, ch.t, side="right") - 1
    worst = 0.0
    for j in np.unique(piece).tolist():
        sel = piece == j
        if int(sel.sum()) > 2:
            worst = max(worst, fit(ch.t[sel] - start[j])[2])
    return worst


def groups(sm: ScanMotion, ch: Changes) -> list[Group]:
    """The scanline's G7 lines (module docstring).  A scanline's first line writes its P and
    T (a stream may start there: a resume restarts a scanline); later lines leave out what
    the line before set (the firmware's modal P and T), as the wire writes them."""
    cyc = sm.duration_us.astype(np.int64) * CYCLES_PER_US
    start = np.concatenate(([0], np.cumsum(cyc)))
    d = np.diff(sm.steps, axis=0)
    items = [(int(p), int(a), int(b)) for p, (a, b) in zip(sm.duration_us.tolist(),
                                                         d.tolist(), strict=True)]
    piece = np.clip(np.searchsorted(start, ch.t, side="right") - 1, 0, len(cyc) - 1)
    cuts = np.searchsorted(piece, np.arange(len(cyc) + 1))  # changes of piece j: cuts[j]…
    out: list[Group] = []
    j, k = 0, len(cyc)
    p_prev: int | None = None
    t_prev: int | None = None
    while j < k:
        ctx = _Line(items, start, cuts, ch, p_prev, t_prev)
        best = ctx.line(j, j + 1, force=True)
        end = j + 1
        while end < k and (trial := ctx.line(j, end + 1)) is not None:
            best, end = trial, end + 1
        assert best is not None
        out.append(best)
        p_prev = items[end - 1][0]
        if len(best.powers) > 1:
            t_prev = best.t
        j = end
    return out


class _Line:
    """Candidate lines from one scanline's pieces, after a line that left P and T modal."""

    def __init__(self, items: list[tuple[int, int, int]], start: IntArray, cuts: IntArray,
                 ch: Changes, p_prev: int | None, t_prev: int | None) -> None:
        self.items, self.start, self.cuts, self.ch = items, start, cuts, ch
        self.p_prev, self.t_prev = p_prev, t_prev

    def line(self, j: int, end: int, force: bool = False) -> Group | None:
        """Pieces j … end − 1 as one line, or None when it breaks a rule (not with `force`)."""
        from fivebar_host.wire import g7_body, g7_line_bytes

        a, b = int(self.cuts[j]), int(self.cuts[end])
        pw = self.ch.power[a:b].tobytes()
        u, t, res = fit(self.ch.t[a:b] - self.start[j])
        if len(pw) > 1 and self.t_prev is not None and t != self.t_prev:
            # the modal T when it fits as well: a shorter line
            r = self.ch.t[a:b] - self.start[j] - np.arange(b - a) * self.t_prev
            u2 = int(round((float(r.max()) + float(r.min())) / 2))
            res2 = float(np.abs(r - u2).max())
            if res2 <= FIT_CYCLES:
                u, t, res = u2, self.t_prev, res2
        size = g7_line_bytes(g7_body(self.items[j:end], max(u, 0), t, pw, self.p_prev,
                                     self.t_prev))
        over = u + max(len(pw) - 1, 0) * t - int(self.start[end] - self.start[j] - 1)
        if over > 0:  # every change inside the line's segments (the firmware's rule)
            u -= over
            res = float(np.abs(self.ch.t[a:b] - self.start[j] - u
                               - np.arange(b - a) * t).max())
        inside = u >= 0
        ok = (size <= LINE_LIMIT and len(pw) <= PX_RING - protocol.PX_HEAD and inside
              and res <= FIT_CYCLES and u >= 0 and (len(pw) < 2 or t >= protocol.PX_T_MIN))
        if not ok and not force:
            return None
        return Group(j, end - j, max(u, 0), t, pw, res)
