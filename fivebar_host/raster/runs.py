"""What a compiled raster job carries beside its segments (`Job.raster`): which segments are
G7 segments, where each G7 line starts and its pixel run, and per scanline what the dose
model, the preview and a resume need.

Pure data (numpy and `program.PixelRun`), so the job model can name it without importing
the raster pipeline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fivebar_host.program import PixelRun
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: The firmware's timer cycles a µs (16 MHz).
CYCLES_PER_US = 16


@dataclass(frozen=True)
class ScanInfo:
    """One scanline of the job: its segments [first, end), its cells [c0, c1) of scan-grid
    row `row` in direction `sign`, the pen speed, where it starts (P₀, direction d), and its
    laser changes (cycles from its first segment's start, powers; the last one the 0 at
    the last pixel's exit)."""

    first: int
    end: int
    row: int
    c0: int
    c1: int
    sign: int
    pass_no: int
    p0: tuple[float, float]
    d: tuple[float, float]
    change_t: FloatArray
    change_power: NDArray[np.uint8]


@dataclass(frozen=True)
class RasterRuns:
    """Per job segment (T): a G7 segment or not, the run index of the G7 line it starts
    (−1: none), its scanline (−1: travel); the runs; the scanlines; the scan grid's frame
    and target powers (R, C) in the burn's pixels; the pen speed; the largest residual of
    the lines' change times against their U + i·T (cycles)."""

    g7: BoolArray
    run: IntArray
    scan: IntArray
    runs: tuple[PixelRun, ...]
    lines: tuple[ScanInfo, ...]
    origin: tuple[float, float]
    u: tuple[float, float]
    n: tuple[float, float]
    pitch_mm: float
    interval_mm: float
    target: NDArray[np.uint8]
    speed_mm_s: float
    accel_mm_s2: float
    fit_residual_cycles: float
    image: str = ""
    notes: tuple[str, ...] = ()

    @property
    def n_pixels(self) -> int:
        """Scanned pixels: every cell of every scanline (blank cells between lit ones too)."""
        return int(sum(s.c1 - s.c0 for s in self.lines))

    def line_of(self, segment: int) -> int:
        """The scanline a segment belongs to (−1: travel or out of range)."""
        if 0 <= segment < self.scan.shape[0]:
            return int(self.scan[segment])
        return -1

    def cell_centres(self) -> FloatArray:
        """Machine mm (R, C, 2) of every cell's centre."""
        r, c = self.target.shape
        o, u, n = (np.asarray(v) for v in (self.origin, self.u, self.n))
        s = (np.arange(c) + 0.5) * self.pitch_mm
        t = (np.arange(r) + 0.5) * self.interval_mm
        out: FloatArray = o + s[None, :, None] * u + t[:, None, None] * n
        return out

    def restart_segment(self, segment: int) -> int:
        """Where a run interrupted before `segment` restarts: the first segment of the
        scanline whose G7 segment it is (its overscan's start), else (a move between
        scanlines) `segment` itself."""
        line = self.line_of(segment)
        if line < 0 or not self.g7[segment]:
            return segment
        return self.lines[line].first

    def runs_after(self, first: int, reached: int, duration_us: IntArray, into: float = 0.0
                   ) -> tuple[PixelRun, ...]:
        """The runs with every pixel of the G7 lines from segment `first` whose change comes
        before the stop at power 0 — the stop `into` (a fraction, 0 … 1) of the way through
        segment `reached`: restarted at `first` (a scanline's start) after a run got that
        far, nothing is burned twice (a pixel under way at the stop stays as far as it
        got)."""
        out = list(self.runs)
        if reached < first or (reached == first and into <= 0.0):
            return tuple(out)
        start = np.concatenate(([0], np.cumsum(duration_us[first:reached].astype(np.int64))))
        stop = (int(start[-1]) + into * float(duration_us[reached])) * CYCLES_PER_US
        for g in range(first, min(reached + 1, self.g7.shape[0])):
            k = int(self.run[g])
            if k < 0:
                continue
            run = out[k]
            at = int(start[g - first]) * CYCLES_PER_US + run.u + run.t * np.arange(
                len(run.powers))
            pw = np.frombuffer(run.powers, dtype=np.uint8).copy()
            pw[at < stop] = 0
            out[k] = PixelRun(run.u, run.t, pw.tobytes())
        return tuple(out)
