"""Raster scanlines in a sender's G-code (LaserGRBL, LightBurn "line to line"): recognised in
the bridge's look-ahead and burned by the raster machinery (`fivebar_host.raster`) instead of
one planned move per run.

A raster file burns an image row by row as run-length moves, `G1 X.. S..` per run of equal
pixels, white runs as `G0`/`S0` moves, alternate rows reversed.  Planned as ordinary moves,
the five-bar's joint-space segments make the pen speed vary inside a run (every segment its
own staircase), and with M4 the power follows that speed: it changes inside constant runs.
Here such a row is a *scanline* (`find`): consecutive straight moves on one Cartesian line in
one direction, the burning ones (laser mode, M3/M4 with S above `$31`) at one feed, with at
least two power levels among them (white gaps count as power 0), every boundary on a grid of
one pixel pitch (`pitch`: the shortest run divided by 1 … `MAX_SPLIT`, every boundary within
`PITCH_TOL` of a pixel of it).  It is compiled as `raster.motion` compiles an image row
(`compile_scan`): one straight line at one constant pen speed (the feed, lowered only where
the joints' speed limit asks, `raster.speed.speed_cap`, or their acceleration along the line,
by `SLOWER`), cut into joint-space pieces within the tolerance, every run boundary placed by
inverse kinematics at its own time inside its piece, the powers carried by G7 lines
(docs/protocol.md 6.4) — so the power changes at the boundaries and nowhere else.

**Overscan, laser off.** The file has none (LaserGRBL adds none); the raster machinery ramps
from rest to the scan speed before the first pixel and back to rest after the last, on the
line's extension, with the laser off (the G7 runs start at the first pixel's boundary and
end with power 0 at the last one).  Chosen over GRBL's own answer (M4 scaling the power
with the speed on the ramps) because it gives every pixel the same dose at one speed and
keeps the laser off where the file has no pixels; the ramps are a fraction of a millimetre
(v²/2a: 0.2–0.4 mm at F3000 on the default profile).  Where the overscan leaves the
machine's reach (or any other check fails) the scanline is not taken: its moves run as
ordinary moves, as before, and the bridge's log says why.

**M3 and M4.** M4 scales the power with the speed over F (GRBL's laser mode); at the
scanline's constant speed v that is one factor v/F (1 at the programmed feed) for the whole
line, so it is constant inside a run, M3 or M4.

**Travel.** The laser-off moves (G0, S0) next to a scanline are travel: the ones before it
are replaced by one checked joint move to its overscan start (`raster.travel`), the first
one after it starts from its overscan end.  Their own path is not followed (nothing burns on
it); every target the sender gave is still reached where the file goes on.

Progress: each RASTER and travel item carries the index of the accepted move it belongs to
(`Program.segment`), so `compile.incremental.moves_finished` counts a scanline's runs as the
firmware finishes them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile import linkrate
from fivebar_host.compile.incremental import Batch, OnlineCompiler, Solved
from fivebar_host.compile.steps import absolute_steps, step_angles
from fivebar_host.errors import FivebarError, JobError
from fivebar_host.program import Kind, PixelRun, Program
from fivebar_host.protocol import P_MIN_US
from fivebar_host.raster import lines as linesmod
from fivebar_host.raster import motion, speed, travel
from fivebar_host.raster.grid import ScanGrid, Scanline
from fivebar_host.raster.job import CHORD_SHARE, K_MAX
from kinematics.arrays import FloatArray, IntArray

#: A move continues the scanline when its end is this close to the line, mm.
ALIGN_MM = 1e-3
#: Every boundary within this share of a pixel of the pitch grid.
PITCH_TOL = 0.02
#: The pitch is the shortest run divided by at most this.
MAX_SPLIT = 10
#: Pixels one scanline holds at most (a longer row runs as ordinary moves).
MAX_PIXELS = 20000
#: Where the joints' acceleration along the line is too much at the feed, the scan speed
#: is lowered by this factor, at most this often.
SLOWER = 0.8
SLOWER_TRIES = 8
#: Moves the look-ahead may hold while a scanline is still arriving (`open_tail`).
SCAN_LOOKAHEAD = 2000


@dataclass(frozen=True)
class Scan:
    """A recognised scanline: the chunk's moves [first, end), its start P₀ and direction d
    (machine mm), the pixel pitch, each pixel's power at the programmed feed and whether it
    is M4 (dynamic), the feed (mm/s) and each pixel's move (its index in the chunk)."""

    first: int
    end: int
    p0: FloatArray
    d: FloatArray
    pitch: float
    power: NDArray[np.uint8]
    dynamic: NDArray[np.bool_]
    feed: float
    move: IntArray

    @property
    def n_px(self) -> int:
        return int(self.power.shape[0])


def burns(m: Solved) -> bool:
    """The move burns: a laser G1 with power."""
    return m.draw and m.power > 0


def _continues(m: Solved, p0: tuple[float, float], d: tuple[float, float], feed: float,
               at: float) -> float | None:
    """Where `m` ends (σ) when it goes on along the line P₀ + σ·d from σ = `at` in direction
    d (a burning move at `feed`), else None."""
    line = m.line
    if line is None or m.jog or (burns(m) and abs(m.feed_mm_s - feed) > 1e-9):
        return None
    sx, sy, ex, ey = line[0] - p0[0], line[1] - p0[1], line[2] - p0[0], line[3] - p0[1]
    across = max(abs(sx * d[1] - sy * d[0]), abs(ex * d[1] - ey * d[0]))
    s_at, e_at = sx * d[0] + sy * d[1], ex * d[0] + ey * d[1]
    if across <= ALIGN_MM and abs(s_at - at) <= ALIGN_MM and e_at > at:
        return e_at
    return None


def _candidate(chunk: Sequence[Solved], i: int) -> tuple[int, int]:
    """(end of the candidate scanline starting at move i, one past its last burning move);
    (i, i) when move i cannot start one."""
    m = chunk[i]
    if not burns(m) or m.line is None or m.jog:
        return i, i
    x0, y0, x1, y1 = m.line
    n = math.hypot(x1 - x0, y1 - y0)
    if n <= 1e-9:
        return i, i
    p0, d = (x0, y0), ((x1 - x0) / n, (y1 - y0) / n)
    j, last, at = i + 1, i + 1, n
    while j < len(chunk):
        e = _continues(chunk[j], p0, d, m.feed_mm_s, at)
        if e is None:
            break
        at = e
        if burns(chunk[j]):
            last = j + 1
        j += 1
    return j, last


def pitch(sigma: FloatArray) -> float | None:
    """The pixel pitch of boundaries σ (mm from the scanline's start, the last its length):
    the shortest run divided by 1 … `MAX_SPLIT` such that every σ is within `PITCH_TOL` of a
    pixel of it (None when none is)."""
    runs = np.diff(np.concatenate(([0.0], sigma)))
    shortest = float(runs.min())
    for k in range(1, MAX_SPLIT + 1):
        h = shortest / k
        q = sigma / h
        if float(np.abs(q - np.rint(q)).max()) <= PITCH_TOL and q[-1] <= MAX_PIXELS + 0.5:
            return h
    return None


def _scan(chunk: Sequence[Solved], i: int, end: int) -> Scan | None:
    """The scanline of moves [i, end) (module doc), None when they do not make one."""
    first = chunk[i].line
    assert first is not None
    p0 = np.array(first[:2])
    v = np.array(first[2:]) - p0
    d = v / float(np.hypot(*v))
    ends = np.array([m.line[2:] for m in chunk[i:end] if m.line is not None])
    sigma = (ends - p0) @ d
    levels = {(m.power if burns(m) else 0) for m in chunk[i:end]}
    if len(levels) < 2 or sigma.shape[0] != end - i:
        return None
    h = pitch(sigma)
    if h is None:
        return None
    cuts = np.concatenate(([0], np.rint(sigma / h).astype(np.int64)))
    if (np.diff(cuts) <= 0).any():
        return None
    counts = np.diff(cuts)
    moves = chunk[i:end]
    power = np.repeat([m.power if burns(m) else 0 for m in moves], counts).astype(np.uint8)
    dyn = np.repeat([m.dynamic and burns(m) for m in moves], counts).astype(bool)
    return Scan(i, end, p0, d, h, power, dyn, chunk[i].feed_mm_s,
                np.repeat(np.arange(i, end), counts))


def find(chunk: Sequence[Solved]) -> list[Scan]:
    """The scanlines among a chunk's moves, in order (module doc)."""
    out: list[Scan] = []
    i = 0
    while i < len(chunk):
        _, last = _candidate(chunk, i)
        sc = _scan(chunk, i, last) if last > i + 1 else None
        if sc is None:
            i += 1
            continue
        out.append(sc)
        i = sc.end
    return out


def open_tail(items: Sequence[object]) -> int:
    """How many of the look-ahead's last moves belong to a scanline that the next line may
    still continue (0: none): the bridge lets them in beyond its `ok` window, since a
    scanline is burned once it is complete (`controller.Bridge._wait_window`)."""
    moves: list[Solved] = []
    for it in reversed(items):
        if not isinstance(it, Solved):
            break
        moves.append(it)
        if len(moves) >= SCAN_LOOKAHEAD:
            break
    moves.reverse()
    i = 0
    while i < len(moves):
        j, last = _candidate(moves, i)
        if j == len(moves) and last > i:
            return len(moves) - i
        i = max(i + 1, last)
    return 0


def complete(items: Sequence[object]) -> int:
    """How many of the look-ahead's first items end with a complete scanline (0: none): the
    items up to the end of the last scanline that the line after it does not continue."""
    last = 0
    start = 0
    while start < len(items):
        stop = start
        while stop < len(items) and isinstance(items[stop], Solved):
            stop += 1
        moves = [it for it in items[start:stop] if isinstance(it, Solved)]
        for sc in find(moves):
            j, _ = _candidate(moves, sc.first)
            if j < len(moves) or stop < len(items):
                last = start + sc.end
        start = stop + 1
    return last


class ScanRefusedError(FivebarError):
    """A recognised scanline the raster machinery does not take (out of reach with its
    overscan, too fast for the firmware's step rate …): it runs as ordinary moves."""


def _steps(oc: OnlineCompiler, th: FloatArray) -> IntArray:
    mot = oc.profile.motors
    out: IntArray = absolute_steps(np.asarray(th).reshape(1, 2), mot.home_rad,
                                   mot.steps_per_rev)[0]
    return out


def compile_scan(oc: OnlineCompiler, sc: Scan, start: IntArray) -> tuple[Program, IntArray]:
    """A scanline's items from absolute steps `start`: the checked joint move to its overscan
    start, then its pieces as RASTER items with their G7 runs (module doc); where it ends
    (steps).  `ScanRefusedError` when the raster machinery refuses
    it (the message says why)."""
    prof = oc.profile
    h = sc.pitch
    n = np.array([sc.d[1], -sc.d[0]])
    grid = ScanGrid(sc.p0 - 0.5 * h * n, sc.d, n, h, h, sc.power[None, :])
    ctx = motion.RasterCtx(prof, oc.checker, grid, sc.feed,
                           CHORD_SHARE * oc.tolerance_mm, K_MAX)
    sl = Scanline(0, 0, sc.n_px, 1)
    try:
        v = min(sc.feed, speed.speed_cap(ctx, [sl]), linkrate.bytes_per_s(prof) * h)
        for _ in range(SLOWER_TRIES):
            # M4: the power times the speed over F (GRBL's laser mode), one factor a line
            scale = np.where(sc.dynamic, min(1.0, v / sc.feed), 1.0)
            power = np.rint(sc.power * scale).astype(np.uint8)
            ctx = replace(ctx, v=v, grid=replace(grid, powers=power[None, :]))
            try:
                sm, ch = speed.plan_line(ctx, sl)
                break
            except JobError as e:
                if e.reason != "too_fast":
                    raise
                v *= SLOWER
        else:
            raise ScanRefusedError(f"no speed up to {sc.feed:.0f} mm/s keeps the joints' "
                                   "acceleration within max_joint_rad_s2")
        travel.check_move(prof, oc.checker, start, sm.steps[0], "move to the scanline")
    except FivebarError as e:
        raise ScanRefusedError(str(e)) from None
    rate = np.abs(np.diff(sm.steps, axis=0)).max(axis=1) / (sm.duration_us * 1e-6)
    if float(rate.max()) > oc.max_rate_steps_s:
        raise ScanRefusedError(f"{rate.max():.0f} steps/s exceeds the firmware's step rate "
                               f"({oc.max_rate_steps_s})")
    groups = linesmod.groups(sm, ch)
    tg, du = travel.joint_move(prof, start, sm.steps[0])
    if not du.shape[0]:  # already there: a G7 line's deltas need a target before it
        tg, du = np.asarray(start, dtype=np.int64).reshape(1, 2), np.array([P_MIN_US])
    first = int(sc.move[0])
    move_in = Program.moves(tg[:, 0], tg[:, 1], du, 0, first)
    run = np.full(sm.duration_us.shape[0], -1, dtype=np.int64)
    for k, g in enumerate(groups):
        run[g.first] = k
    # each piece belongs to the move of the pixel it starts in (ramp in: the first move,
    # ramp out: the last), so a move is done once the pieces after it have begun
    px = np.floor(sm.sigma[:-1] / h + 1e-9).astype(np.int64)
    seg = sc.move[np.clip(px, 0, sc.n_px - 1)]
    pieces = Program(np.full(run.shape[0], Kind.RASTER, dtype=np.int64),
                     sm.steps[1:, 0].astype(np.int64), sm.steps[1:, 1].astype(np.int64),
                     sm.duration_us.astype(np.int64), run, seg.astype(np.int64),
                     runs=tuple(PixelRun(g.u, g.t, g.powers) for g in groups))
    prog = Program.join([Program.command(Kind.TOOL_ON, s=3), move_in, pieces,
                         Program.command(Kind.TOOL_OFF)])
    return prog, np.asarray(sm.steps[-1], dtype=np.int64)


@dataclass
class Cursor:
    """Where the plan stands: the machine's angles and pen point, and — right after a
    scanline, the machine at rest at its overscan end — the point of the file where the
    scanline ended (`scan_end`, else None)."""

    th: FloatArray
    pt: tuple[float, float]
    scan_end: tuple[float, float] | None = None


def _rapid(oc: OnlineCompiler, cur: Cursor, to: tuple[float, float], like: Solved) -> Solved:
    """A laser-off move from the cursor to `to` (a `Solved` rapid, checked)."""
    s = oc.solve(cur.th, cur.pt, [to], rapid=True, draw=False, feed_mm_s=like.feed_mm_s,
                 power=0, dynamic=False, arc=False)
    if s is None:  # already there
        return Solved(cur.th[None], np.array([to]), np.zeros(1), False, like.feed_mm_s, 0,
                      False)
    return s


def _ordinary(oc: OnlineCompiler, cur: Cursor, chunk: Sequence[Solved], lo: int, hi: int,
              before_scan: bool) -> list[Program]:
    """Moves [lo, hi) planned as ordinary moves (`OnlineCompiler.plan`), the laser-off ones
    before a scanline left out (its own travel replaces them) and, after one, the first
    started from its overscan end: a laser-off move goes straight to its end, anything else
    after a laser-off move back to where the scanline ended (module doc)."""
    idx = list(range(lo, hi))
    if before_scan:
        while idx and not burns(chunk[idx[-1]]):
            idx.pop()
    if not idx:
        return []
    moves = [chunk[k] for k in idx]
    index = list(idx)
    if cur.scan_end is not None:
        m0 = moves[0]
        if not burns(m0) and m0.line is not None and not m0.jog:
            moves[0] = _rapid(oc, cur, (m0.line[2], m0.line[3]), m0)
        else:
            moves.insert(0, _rapid(oc, cur, cur.scan_end, m0))
            index.insert(0, idx[0])
    batch = oc.plan(cur.th, cur.pt, moves)
    where = np.asarray(index, dtype=np.int64)
    prog = batch.program
    seg = np.where(prog.segment >= 0, where[np.maximum(prog.segment, 0)], -1)
    cur.th = moves[-1].th[-1]
    cur.pt = (float(moves[-1].pts[-1, 0]), float(moves[-1].pts[-1, 1]))
    cur.scan_end = None
    return [replace(prog, segment=seg)]


def plan(oc: OnlineCompiler, cur: Cursor, chunk: Sequence[Solved],
         log: Callable[[str], None]) -> Batch:
    """A chunk of moves from rest to rest with its scanlines burned as rasters (module
    doc); `cur` is moved to where the batch ends."""
    scans = find(chunk) if oc.laser and not chunk[0].jog else []
    parts: list[Program] = []
    lo = 0
    for sc in scans:
        try:
            prog, end = compile_scan(oc, sc, _after(oc, cur, chunk, lo, sc.first))
        except ScanRefusedError as e:
            log(f"raster line of moves {sc.first}-{sc.end - 1} runs as ordinary moves: {e}")
            continue
        parts += _ordinary(oc, cur, chunk, lo, sc.first, True)
        parts.append(prog)
        mot = oc.profile.motors
        cur.th = step_angles(end.reshape(1, 2), mot.home_rad, mot.steps_per_rev)[0]
        p = oc.point_of(cur.th)
        assert p is not None
        last = chunk[sc.end - 1].line
        assert last is not None
        cur.pt, cur.scan_end = p, (last[2], last[3])
        lo = sc.end
    parts += _ordinary(oc, cur, chunk, lo, len(chunk), False)
    prog = Program.join(parts)
    st = _steps(oc, cur.th)
    return Batch(prog, float(prog.p_us[prog.is_motion].sum()) * 1e-6, (int(st[0]), int(st[1])),
                 chunk[0].jog, len(chunk))


def _after(oc: OnlineCompiler, cur: Cursor, chunk: Sequence[Solved], lo: int, hi: int
           ) -> IntArray:
    """Absolute steps where the ordinary moves [lo, hi) before a scanline leave the machine
    (their laser-off tail left out; the cursor's when nothing of them runs)."""
    k = hi
    while k > lo and not burns(chunk[k - 1]):
        k -= 1
    if k == lo:
        return _steps(oc, cur.th)
    return _steps(oc, chunk[k - 1].th[-1])
