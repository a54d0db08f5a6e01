"""The planned scanlines and the moves between them as one job: segment arrays, the G7 lines'
runs (`RasterRuns`), the wire lines the link model times, and the `Job` itself.

Segments in order: a checked joint move from the homed pose to the first scanline's
overscan start, then per scanline its pieces (every one a G7 segment; the image pieces are
the job's drawing segments) and a move to the next scanline's start, then the move home.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import steps as stepsmod
from fivebar_host.compile.model import Job, PathStats, compact_ints
from fivebar_host.config import Profile
from fivebar_host.program import PixelRun
from fivebar_host.raster import lines as linesmod
from fivebar_host.raster import motion, pixels, travel
from fivebar_host.raster.runs import RasterRuns, ScanInfo
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.geometry import Drawing
from fivebar_host.toolpath.segment import PoseChecker
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Bytes a travel piece takes on the wire as a G6 item, and a G6 line's own (wire.py).
TRAVEL_ITEM_B = 8
TRAVEL_LINE_B = 36
#: Travel pieces one G6 line carries at most (within `lines.LINE_LIMIT`).
TRAVEL_ITEMS = 1 + (linesmod.LINE_LIMIT - TRAVEL_LINE_B) // TRAVEL_ITEM_B


@dataclass
class Segments:
    """The job's segments as they are collected (targets, µs, flags, run indices)."""

    targets: list[IntArray]
    duration: list[IntArray]
    draw: list[BoolArray]
    scan: list[IntArray]
    run: list[IntArray]
    g7: list[IntArray]
    n: int = 0

    def add(self, targets: IntArray, duration: IntArray, draw: BoolArray, scan: int,
            run: IntArray, g7: bool) -> int:
        """Append pieces; returns the index of the first."""
        k = int(duration.shape[0])
        first = self.n
        self.targets.append(np.asarray(targets, dtype=np.int64).reshape(-1, 2))
        self.duration.append(np.asarray(duration, dtype=np.int64))
        self.draw.append(np.asarray(draw, dtype=bool))
        self.scan.append(np.full(k, scan, dtype=np.int64))
        self.run.append(np.asarray(run, dtype=np.int64))
        self.g7.append(np.full(k, g7, dtype=bool))
        self.n += k
        return first


@dataclass(frozen=True)
class WireLines:
    """The job's wire lines as the link model sees them: bytes and the plan time their first
    segment starts, s."""

    nbytes: list[int]
    start_s: list[float]
    nseg: list[int]  # segments a line carries


@dataclass(frozen=True)
class Collected:
    """The job's segments, the G7 lines' runs, each scanline's segments [first, end) and
    the wire lines."""

    seg: Segments
    runs: list[PixelRun]
    spans: list[tuple[int, int]]
    wire: WireLines


def collect(profile: Profile, checker: PoseChecker, planned_scans: list[motion.ScanMotion],
            groups: list[list[linesmod.Group]], home_steps: IntArray, lead_us: int = 0
            ) -> Collected:
    """Segments, runs, each scanline's [first, end) and the wire lines (module docstring);
    the move to the first scanline lasts at least `lead_us`."""
    seg = Segments([], [], [], [], [], [])
    runs: list[PixelRun] = []
    spans: list[tuple[int, int]] = []
    wire = WireLines([], [], [])
    t_us = 0
    home = np.asarray(home_steps, dtype=np.int64).reshape(1, 2)
    # the moves between: home → first scanline → … → last scanline → home, checked and
    # planned all at once (each on its own, `travel.check_moves`, `travel.joint_moves`)
    starts = np.concatenate([home] + [sm.steps[-1:] for sm in planned_scans])
    ends = np.concatenate([sm.steps[:1] for sm in planned_scans] + [home])
    n = len(planned_scans)
    travel.check_moves(profile, checker, starts, ends,
                       lambda i: (f"move to scanline {i + 1} (row {planned_scans[i].line.row})"
                                  if i < n else "move back to the homed pose"))
    moves = travel.joint_moves(profile, starts, ends)

    def move(i: int, lead: int = 0) -> None:
        nonlocal t_us
        tg, du = moves[i]
        if 0 < du.sum() < lead:  # slower, so that the stream gets ahead
            du = np.minimum(-(-du * lead // int(du.sum())), protocol.P_MAX_US)
        if du.shape[0]:
            seg.add(tg, du, np.zeros(du.shape[0], bool), i, np.full(du.shape[0], -1), False)
            at = np.concatenate(([0], np.cumsum(du)))
            for a in range(0, du.shape[0], TRAVEL_ITEMS):  # G6 lines of TRAVEL_ITEMS
                k = min(TRAVEL_ITEMS, du.shape[0] - a)
                wire.nbytes.append(TRAVEL_LINE_B + TRAVEL_ITEM_B * (k - 1))
                wire.start_s.append((t_us + int(at[a])) * 1e-6)
                wire.nseg.append(k)
            t_us += int(du.sum())

    for i, sm in enumerate(planned_scans):
        move(i, 0 if i else lead_us)
        run = np.full(sm.duration_us.shape[0], -1, dtype=np.int64)
        start_us = np.concatenate(([0], np.cumsum(sm.duration_us)))
        for g in groups[i]:
            run[g.first] = len(runs)
            runs.append(PixelRun(g.u, g.t, g.powers))
            wire.nbytes.append(g.nbytes)
            wire.start_s.append((t_us + int(start_us[g.first])) * 1e-6)
            wire.nseg.append(g.count)
        first = seg.add(sm.steps[1:], sm.duration_us, sm.kind == motion.SCAN, i, run, True)
        spans.append((first, seg.n))
        t_us += sm.time_us
    move(n)
    return Collected(seg, runs, spans, wire)


def build_job(profile: Profile, checker: PoseChecker, file: str, mode: str,
              home_steps: IntArray, seg: Segments, info: RasterRuns,
              placement: layout.Placement, notes: list[str]) -> Job:
    """The `Job` of the collected segments (module docstring)."""
    mo = profile.motors
    steps = np.concatenate([np.asarray(home_steps, dtype=np.int64).reshape(1, 2), *seg.targets])
    th = stepsmod.step_angles(steps, mo.home_rad, mo.steps_per_rev)
    pts, _ = checker.forward(th)
    draw = np.concatenate(seg.draw)
    scan = np.concatenate(seg.scan)
    n_lines = len(info.lines)
    path = np.where(scan >= 0, scan, n_lines)
    length = np.hypot(*np.diff(pts, axis=0).T)
    _code, m = checker.codes(th, pts, check_type1=False)
    jac = profile.geometry.jacobian(th, pts)
    quantum = stepsmod.step_quantum_mm(jac, mo.rad_per_step)
    firsts = np.array([s.first for s in info.lines], dtype=np.int64)
    ends = np.array([s.end for s in info.lines], dtype=np.int64)
    stats = PathStats(np.arange(n_lines), np.array([s.sign < 0 for s in info.lines]), firsts,
                      ends, np.full(n_lines, np.nan), np.full(n_lines, np.nan))
    drawing = Drawing(file, np.zeros(0, np.int8), np.zeros((0, 8)), np.zeros(0, np.int64),
                      np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0),
                      np.zeros(0), [])
    return Job(file=file, mode=mode, assembly=checker.assembly,
               tolerance_mm=profile.motion.tolerance_mm,
               flatten_tol_mm=profile.motion.tolerance_mm / 2, placement=placement,
               drawing=drawing, steps_per_rev=mo.steps_per_rev, home_rad=mo.home_rad,
               points_mm=pts, angles_rad=th, steps=compact_ints(steps),
               draw=draw, power=np.zeros(draw.shape[0], np.uint8), path=compact_ints(path),
               source=compact_ints(np.where(draw, scan, -1)),
               source_line=np.zeros(draw.shape[0], np.int64),
               duration_us=compact_ints(np.concatenate(seg.duration)), length_mm=length,
               paths=stats, min_margin_rad=m.min(axis=0), step_quantum_mm=float(quantum.max()),
               travel_before_mm=0.0, travel_after_mm=0.0, joined=0, notes=list(notes),
               raster=info)


def scan_infos(planned_scans: list[motion.ScanMotion], changes: list[pixels.Changes],
               spans: list[tuple[int, int]]) -> tuple[ScanInfo, ...]:
    """Per scanline what the dose model, the preview and a resume need (`ScanInfo`)."""
    out = []
    for sm, ch, (a, b) in zip(planned_scans, changes, spans, strict=True):
        sl = sm.line
        out.append(ScanInfo(a, b, sl.row, sl.c0, sl.c1, sl.sign, sl.pass_no,
                            (float(sm.p0[0]), float(sm.p0[1])), (float(sm.d[0]), float(sm.d[1])),
                            ch.t, ch.power))
    return tuple(out)


def machine_bbox(corners: FloatArray) -> tuple[float, float, float, float]:
    return (float(corners[:, 0].min()), float(corners[:, 1].min()),
            float(corners[:, 0].max()), float(corners[:, 1].max()))
