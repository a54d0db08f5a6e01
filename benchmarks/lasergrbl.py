"""LaserGRBL-style raster files and their burn measured from the emulator's pin trace.

`raster_file` writes a file in the form LaserGRBL's "line to line" raster export gives
(its GrblFile.cs, read for the form only): `G90`, `G21`, the feed, the laser on at S0
(`M4 S0` or `M3 S0`), then per image row its runs of equal pixels, a burning run `X<x>
S<s>` (the first after a rapid with `G1` in front, modal after), white pixels and the step
to the next row gathered into one `G0 X<x> Y<y> S0` before the next burning run, alternate
rows reversed, numbers with at most three decimals; `M5` and `G0 X0 Y0` at the end.  The
image is a random one of runs 1 … `MAX_RUN` px long at `LEVELS` (S values whose powers
255·S/1000 the laser pin shows as distinct PWM widths: 0 or 8 … 247), so that every run
boundary is a power change the pin can show.

`burn_figures` measures a run from the trace (`fbsim -t`) against the file's own runs
(`Reference`, from the generator, not from anything the bridge computed), with the raster
verification's primitives (`raster.dose`: step edges → motor positions → forward kinematics;
laser high intervals):

* a *change* on the pin (`pin_changes`): a PWM rise after a laser-off stretch, one that
  moves the high time to a new level (medians of `LEVEL_N` pulses `WIDTH_TOL` apart: the
  trace's edges jitter by ±3 cycles; `RESTART_TOL` at a rise that restarts the PWM period,
  as the firmware's write of a new power does), or a laser-off fall (`changes.off_writes`); changes
  within `MERGE_PERIODS` PWM periods are one;
* each run boundary of the file (a power change between neighbouring runs, the row's first
  and last burned pixel included) is *covered* when a change happens with the pen within
  `NEAR_MM` of the boundary's point; its distance is the pen's distance from the point at
  the nearest change;
* a change with the pen on a row's burned stretch farther than `NEAR_MM` from every
  boundary is a change *inside a constant run*;
* a step taken with the laser on (`raster.dose.laser_on`) with the pen off every burning run (by
  more than `NEAR_MM` along the row, or off the row's band) is a laser-on step *outside*;
* px/s: the rows' burned stretches in pixels ÷ the time from the first laser rise to the
  last fall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile.incremental import Batch, OnlineCompiler, Solved
from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.raster import changes, dose
from fivebar_host.raster import trace as rtrace
from kinematics.arrays import FloatArray

#: S values of the random image's runs (0 = white), with `$30` = 1000.
LEVELS = (0, 150, 300, 450, 600, 750, 900)
MAX_RUN = 20
#: A PWM level change: the median high time of `LEVEL_N` pulses moves by this, cycles.
WIDTH_TOL = 10
LEVEL_N = 5
#: ... or by this at a rise that restarts the PWM period, cycles.
RESTART_TOL = 2
#: Changes this many PWM periods apart or closer are one.
MERGE_PERIODS = 4
#: A change is at a boundary within this, mm.
NEAR_MM = 0.05


@dataclass(frozen=True)
class Reference:
    """The file's image on the machine: row centre lines at y (machine mm), pixel edges at
    x0 + c·pitch, each pixel's S (R, C), and which rows run towards −x."""

    s: NDArray[np.int64]
    x0: float
    y: FloatArray
    pitch: float
    reversed_rows: NDArray[np.bool_]

    def boundaries(self, row: int) -> FloatArray:
        """x (mm) of the row's run boundaries, where the power changes (0 outside)."""
        p = np.concatenate(([0], self.s[row], [0]))
        cut = np.flatnonzero(np.diff(p) != 0)
        out: FloatArray = self.x0 + cut * self.pitch
        return out

    def burned(self, row: int) -> tuple[float, float] | None:
        """The row's burned stretch [x_a, x_b] (first to last burned pixel), None if white."""
        lit = np.flatnonzero(self.s[row] > 0)
        if not lit.size:
            return None
        return (self.x0 + lit[0] * self.pitch, self.x0 + (lit[-1] + 1) * self.pitch)

    @property
    def pixels(self) -> int:
        """Pixels of the rows' burned stretches."""
        out = 0
        for r in range(self.s.shape[0]):
            b = self.burned(r)
            if b is not None:
                out += round((b[1] - b[0]) / self.pitch)
        return out

    @property
    def n_boundaries(self) -> int:
        return int(sum(self.boundaries(r).shape[0] for r in range(self.s.shape[0])))


def image(rows: int, cols: int, seed: int = 1) -> NDArray[np.int64]:
    """A random image of runs (module doc): S per pixel (rows, cols)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((rows, cols), dtype=np.int64)
    for r in range(rows):
        c, prev = 0, -1
        while c < cols:
            n = int(rng.integers(1, MAX_RUN + 1))
            level = prev
            while level == prev:
                level = int(rng.choice(LEVELS))
            out[r, c:c + n] = level
            c, prev = c + n, level
    return out


def _num(v: float) -> str:
    """LaserGRBL's number form: at most three decimals, no trailing zeros."""
    text = f"{v:.3f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def raster_file(s: NDArray[np.int64], px_per_mm: float = 10.0, feed_mm_min: float = 3000.0,
                spindle: int = 4, origin: tuple[float, float] = (0.0, 0.0),
                machine_origin: tuple[float, float] = (0.0, 0.0)
                ) -> tuple[list[str], Reference]:
    """The LaserGRBL-style lines of an image of S values (module doc), its top-left pixel's
    corner at work `origin` (rows downwards, −y), and the `Reference` on the machine whose
    G54 origin is `machine_origin`."""
    rows, cols = s.shape
    h = 1.0 / px_per_mm
    lines = ["G90", "G21", f"F{_num(feed_mm_min)}", f"M{spindle} S0"]
    ys = origin[1] - (np.arange(rows) + 0.5) * h
    rev = np.arange(rows) % 2 == 1
    for r in range(rows):
        y = float(ys[r])
        order = range(cols - 1, -1, -1) if rev[r] else range(cols)
        row = [int(s[r, c]) for c in order]
        x = origin[0] + (cols * h if rev[r] else 0.0)
        step = -h if rev[r] else h
        x_cur, rapid = x, True  # a new row: the rapid there comes before its first run
        c = 0
        while c < cols:
            k = c
            while k < cols and row[k] == row[c]:
                k += 1
            x_end = x + step * k
            if row[c] == 0:  # white: gathered into the rapid before the next run
                rapid = True
            elif rapid:
                lines += [f"G0 X{_num(x_cur)} Y{_num(y)} S0", f"G1 X{_num(x_end)} S{row[c]}"]
                rapid = False
            else:
                lines.append(f"X{_num(x_end)} S{row[c]}")
            x_cur, c = x_end, k
    lines += ["M5", "G0 X0 Y0"]
    ref = Reference(s, origin[0] + machine_origin[0], ys + machine_origin[1], h, rev)
    return lines, ref


@dataclass(frozen=True)
class BurnFigures:
    """What `burn_figures` measures (module doc)."""

    pixels: int
    seconds: float
    boundaries: int
    covered: int
    max_distance_mm: float  # over the covered boundaries
    inside_changes: int
    outside_steps: int
    changes: int
    #: (row, x mm, cycle) of each change inside a constant run
    inside_at: tuple[tuple[int, float, float], ...] = ()
    motion_s: float = 0.0  # from the first step to the last

    @property
    def rate(self) -> float:
        return self.pixels / self.seconds if self.seconds > 0 else 0.0

    @property
    def coverage(self) -> float:
        return self.covered / self.boundaries if self.boundaries else 1.0

    def line(self) -> str:
        return (f"{self.pixels} px in {self.seconds:.2f} s = {self.rate:.0f} px/s; power "
                f"changes at {100 * self.coverage:.2f} % of {self.boundaries} boundaries "
                f"(max {self.max_distance_mm:.4f} mm), {self.inside_changes} inside constant "
                f"runs, laser on outside the runs {self.outside_steps} steps")


def _level_steps(width: NDArray[np.int64]) -> FloatArray:
    """Per rise, how far the median high time of the `LEVEL_N` pulses from it is from the
    median of the `LEVEL_N` before, cycles (0 where either is incomplete)."""
    n = width.shape[0]
    out = np.zeros(n)
    if n >= 2 * LEVEL_N:
        med = np.median(np.lib.stride_tricks.sliding_window_view(width, LEVEL_N), axis=1)
        out[LEVEL_N:n - LEVEL_N + 1] = np.abs(med[LEVEL_N:] - med[:-LEVEL_N])
    return out


def _strongest(cand: NDArray[np.int64], score: FloatArray) -> NDArray[np.int64]:
    """Of neighbouring candidate rises (within `LEVEL_N`), the one of the largest score."""
    if not cand.size:
        return cand
    groups = np.split(cand, np.flatnonzero(np.diff(cand) > LEVEL_N) + 1)
    return np.array([int(g[np.argmax(score[g])]) for g in groups], dtype=np.int64)


def pin_changes(pt: rtrace.PinTrace) -> FloatArray:
    """Cycles of the laser's power changes on the pin (module doc): rises after the laser
    was off; rises where the high time moves to a new level (medians `WIDTH_TOL` apart), or
    that restart the PWM period (`changes.restarts`: the firmware's write of a new power) with
    the level moving by `RESTART_TOL` (a restart at the same power is none); laser-off
    falls (`changes.off_writes`); changes within `MERGE_PERIODS` PWM periods are one."""
    rise, fall = rtrace.high_intervals(pt)
    if not rise.size:
        return np.zeros(0)
    gap = np.diff(rise, prepend=-(10**12))
    step = _level_steps(fall - rise)
    _, restart = changes.restarts(pt)
    flag = gap > rtrace.PWM_PERIOD + changes.SLACK
    flag[_strongest(np.flatnonzero(step >= WIDTH_TOL), step)] = True
    flag |= (restart > 0) & (step >= RESTART_TOL)
    ev = np.sort(np.concatenate((rise[flag].astype(np.float64), changes.off_writes(pt))))
    if not ev.size:
        return ev
    keep = np.concatenate(([True], np.diff(ev) > MERGE_PERIODS * rtrace.PWM_PERIOD))
    out: FloatArray = ev[keep]
    return out


def _pen(profile: Profile, mo: rtrace.Motion, cycles: FloatArray,
         start: tuple[int, int] = (0, 0)) -> FloatArray:
    """The pen (N, 2) mm at the cycles: forward kinematics of the motors' positions, steps
    from the homed pose (the trace counts from `start`, where the machine stood)."""
    mot = profile.motors
    th = step_angles(mo.at(cycles) + np.asarray(start, dtype=np.float64), mot.home_rad,
                     mot.steps_per_rev)  # type: ignore[arg-type]
    out: FloatArray = profile.geometry.forward_batch(th, profile.kinematics.assembly).points
    return out


def _row_of(ref: Reference, pts: FloatArray) -> NDArray[np.int64]:
    """The row whose band (±pitch/2 about its centre line) holds each point (−1: none)."""
    k = np.rint((ref.y[0] - pts[:, 1]) / ref.pitch).astype(np.int64)
    ok = (k >= 0) & (k < ref.y.shape[0])
    kk = np.clip(k, 0, ref.y.shape[0] - 1)
    ok &= np.abs(pts[:, 1] - ref.y[kk]) <= 0.5 * ref.pitch
    return np.where(ok, kk, -1)


def burn_figures(trace: str | Path, profile: Profile, ref: Reference,
                 start: tuple[int, int] = (0, 0)) -> BurnFigures:
    """The figures of a raster file's burn from the pin trace (module doc); `start`: the
    machine's steps from the homed pose when the trace began."""
    pt = rtrace.read_pins(trace)
    mo = rtrace.motion_of(pt)
    rise, fall = rtrace.high_intervals(pt)
    seconds = float(fall.max() - rise.min()) / rtrace.F_CPU if rise.size else 0.0
    ev = pin_changes(pt)
    where = _pen(profile, mo, ev, start) if ev.size else np.zeros((0, 2))
    rows = _row_of(ref, where)
    covered, total, dist_max, inside = 0, 0, 0.0, 0
    inside_at: list[tuple[int, float, float]] = []
    for r in range(ref.s.shape[0]):
        b = ref.boundaries(r)
        total += b.shape[0]
        sel = rows == r
        bx = np.stack((b, np.full(b.shape[0], ref.y[r])), axis=1)
        if sel.any() and b.size:
            d = np.hypot(*(where[sel][:, None, :] - bx[None, :, :]).transpose(2, 0, 1))
            near_b = d.min(axis=0)  # per boundary: the nearest change
            got = near_b <= NEAR_MM
            covered += int(got.sum())
            if got.any():
                dist_max = max(dist_max, float(near_b[got].max()))
            stretch = ref.burned(r)
            if stretch is not None:
                ex = where[sel][:, 0]
                bad = (ex > stretch[0]) & (ex < stretch[1]) & (d.min(axis=1) > NEAR_MM)
                inside += int(bad.sum())
                inside_at += [(r, float(x), float(c)) for x, c in zip(ex[bad], ev[sel][bad],
                                                                       strict=True)]
    steps = mo.step_cycles()
    lit = dose.laser_on(rise, fall, steps)
    outside = 0
    if lit.any():
        p = _pen(profile, mo, steps[lit], start)
        rr = _row_of(ref, p)
        bad = rr < 0
        for r in np.unique(rr[rr >= 0]).tolist():
            sel = rr == r
            powers = ref.s[r]
            col = np.floor((p[sel, 0] - ref.x0) / ref.pitch).astype(np.int64)
            edge_lo = np.floor((p[sel, 0] - NEAR_MM - ref.x0) / ref.pitch).astype(np.int64)
            edge_hi = np.floor((p[sel, 0] + NEAR_MM - ref.x0) / ref.pitch).astype(np.int64)
            ok = np.zeros(col.shape[0], dtype=bool)
            for c in (col, edge_lo, edge_hi):
                inb = (c >= 0) & (c < powers.shape[0])
                ok |= inb & (powers[np.clip(c, 0, powers.shape[0] - 1)] > 0)
            bad[np.flatnonzero(sel)[~ok]] = True
        outside = int(bad.sum())
    motion_s = float(steps[-1] - steps[0]) / rtrace.F_CPU if steps.size else 0.0
    return BurnFigures(ref.pixels, seconds, total, covered, dist_max, inside, outside,
                       int(ev.shape[0]), tuple(inside_at), motion_s)


@dataclass(frozen=True)
class Streamed:
    """A file streamed through the bridge: the machine's steps when the trace began, the
    seconds to the last `ok` and to idle, the bridge's log."""

    start: tuple[int, int]
    ok_s: float
    idle_s: float
    log: list[str]
    error: str | None = None  # the sender's first error reply, if any
    planned_s: float = 0.0  # the batches' planned time, summed


def stream_file(lines: list[str], trace: Path, profile: Profile,
                origin: tuple[float, float], realtime: bool) -> Streamed:
    """Stream `lines` through `fivebar bridge` (`--laser`, `origin` as its G54 origin) to the
    emulated firmware writing its pin trace to `trace`, with the character-counting GRBL
    sender of `benchmarks/grbl.py` over TCP; then wait until the machine is idle."""
    import time

    from benchmarks.grbl import Sender
    from fivebar_host.bridge.controller import Bridge
    from fivebar_host.bridge.serve import Server
    from fivebar_host.controllers.fivebar.link import Link

    # a fresh machine at the home pose (state=off: no arms left elsewhere by an earlier run)
    link = Link.open(f"fivebar-sim://?state=off&trace={trace}"
                     + ("&realtime=1" if realtime else ""))
    log: list[str] = []
    core = Bridge(link, profile, laser=True, tolerance_mm=profile.motion.tolerance_mm,
                  origin_mm=origin, log=log.append)
    st = link.status()
    planned = [0.0]
    submit = core.machine.submit

    def count(batch: Batch) -> None:
        planned[0] += batch.duration_s
        submit(batch)

    core.machine.submit = count  # type: ignore[method-assign]
    server = Server(core, None, ("127.0.0.1", 0))
    core.start()
    server.start()
    try:
        assert server.address is not None
        snd = Sender(server.address)
        snd.sock.sendall(b"$X\n")
        snd.wait(lambda x: x == "ok")
        t0 = time.monotonic()
        try:
            snd.stream(lines)
        except RuntimeError as e:
            return Streamed((st.a, st.b), time.monotonic() - t0, math.nan, log, str(e),
                            planned[0])
        t_ok = time.monotonic() - t0
        snd.wait_idle()
        t_idle = time.monotonic() - t0
        snd.sock.close()
    finally:
        server.stop()
        core.close()
        link.close()
    return Streamed((st.a, st.b), t_ok, t_idle, log, None, planned[0])


def row_moves(oc: OnlineCompiler, s_row: NDArray[np.int64], y: float, *, dynamic: bool,
              feed_mm_s: float = 50.0, pitch_mm: float = 0.1, start_x: float = 0.0,
              sign: int = 1, th: FloatArray | None = None) -> list[Solved]:
    """The moves of one row of runs (S per pixel in scan order, from `start_x` towards
    `sign`·x) as the bridge solves them: a burning G1 per run, a laser-off move per white
    run ($30 = 1000)."""
    if th is None:
        th = oc.checker.inverse(np.array([[start_x, y]]))[0]
    pt = (start_x, y)
    out: list[Solved] = []
    c = 0
    while c < s_row.shape[0]:
        k = c
        while k < s_row.shape[0] and s_row[k] == s_row[c]:
            k += 1
        p = round(255 * int(s_row[c]) / 1000)
        end = (start_x + sign * k * pitch_mm, y)
        m = oc.solve(th, pt, [end], rapid=p == 0, draw=p > 0, feed_mm_s=feed_mm_s, power=p,
                     dynamic=dynamic, arc=False)
        assert m is not None
        out.append(m)
        th, pt, c = m.th[-1], end, k
    return out


def turnaround_ms(profile: Profile, y: float = 100.0, cols: int = 400,
                  feed_mm_s: float = 50.0) -> tuple[float, float, float]:
    """What one row of a bidirectional raster costs beyond its burn, as the bridge plans it
    (`bridge.scanlines`): (both ramps, the step to the next row, the burn itself), ms — row
    1 of a uniform two-level pattern, planned from row 0's overscan end."""
    from fivebar_host.bridge import scanlines
    from fivebar_host.program import Kind

    oc = OnlineCompiler(profile, profile.kinematics.working_mode, profile.motion.tolerance_mm,
                        True)
    row = np.where((np.arange(cols) // 10) % 2 == 0, 450, 900)
    first = row_moves(oc, row, y, dynamic=False, feed_mm_s=feed_mm_s)
    sc0 = scanlines.find(first)[0]
    _, end0 = scanlines.compile_scan(oc, sc0, scanlines._steps(oc, first[0].th[0]))
    back = row_moves(oc, row, y - 0.1, dynamic=False, feed_mm_s=feed_mm_s,
                     start_x=cols * 0.1, sign=-1)
    sc1 = scanlines.find(back)[0]
    prog, _ = scanlines.compile_scan(oc, sc1, end0)
    move = float(prog.p_us[prog.kind == Kind.MOVE].sum()) / 1e3
    raster = float(prog.p_us[prog.kind == Kind.RASTER].sum()) / 1e3
    burn = sc1.n_px * sc1.pitch / feed_mm_s * 1e3
    return raster - burn, move, burn
