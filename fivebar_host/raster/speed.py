"""Every scanline planned at one pen speed, that speed chosen so the joints and the link
keep up (`plan_image`).

The pen speed starts at the asked one, lowered so that (1) no joint exceeds `SPEED_SHARE` of
`max_joint_rad_s` over the image (`speed_cap`), and (2) the link keeps up: the wire lines,
in order, at `compile.linkrate.LINK_SHARE` of the link's byte rate, each arriving before its
first segment runs, the firmware holding at most `BUFFER_BYTES` of them ahead
(`link_lateness`).  One speed for the whole image: the dose per pixel is the same on every
scanline.

The link's speed is found on a probe first — `PROBE_LINES` scanlines spread over the
image, as if consecutive, with a wider margin — then the whole image is planned once at it
and checked; where a line would still be late, the speed that makes none late is found on
the planned lines' times scaled by the speed ratio (`_scaled_speed`, a bisection on the
link model alone) and the image planned again.  The move to the first scanline lasts at
least `lead_us`, the time to fill the firmware's buffer, so the first scanline starts as
every later one does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import linkrate
from fivebar_host.raster import assemble, linegeo, motion, pixels
from fivebar_host.raster import grid as gridmod
from fivebar_host.raster import lines as linesmod
from kinematics.arrays import FloatArray, IntArray

#: Share of max_joint_rad_s the scan speed may ask of a joint.
SPEED_SHARE = 0.9
#: The firmware's buffering a stream can get ahead by: its receive ring (255), its line
#: buffer and pixel ring (128 each), less a line of margin.
BUFFER_BYTES = 380
#: Consecutive scanlines the link's speed is found on before the whole image is planned.
PROBE_LINES = 24
#: Margin on a speed the link model finds on the whole image, and on the probe (where the
#: denser stretches of the image may not be).
LINK_MARGIN = 0.98
PROBE_MARGIN = 0.95
#: The firmware's work a G7 segment takes at least, µs: the plain segments' floor the raster
#: planner was measured with (`compile.linkrate.FIRMWARE_SEGMENT_US` was 1100 then); a G7
#: segment also carries the scan's pixel records, so it keeps this value.
G7_SEGMENT_US = 1100


@dataclass(frozen=True)
class Planned:
    """The scanlines planned at one speed: their motion, changes and G7 lines, and the
    job's segments as collected (`assemble.collect`)."""

    ctx: motion.RasterCtx
    scans: list[motion.ScanMotion]
    changes: list[pixels.Changes]
    groups: list[list[linesmod.Group]]
    collected: assemble.Collected

    @property
    def late_s(self) -> float:
        """How late the latest wire line arrives (`link_lateness`), s."""
        w = self.collected.wire
        return link_lateness(w.nbytes, w.start_s, linkrate.bytes_per_s(self.ctx.profile),
                             w.nseg)


def plan_line(ctx: motion.RasterCtx, sl: gridmod.Scanline, k_hint: int | None = None,
              pad_mm: tuple[float, float] | None = None, bounds: FloatArray | None = None
              ) -> tuple[motion.ScanMotion, pixels.Changes]:
    """One scanline planned, with its changes: scan pieces short enough that each piece's
    changes fit one progression U + i·T within `pixels.FIT_CYCLES` (the pen's speed drifts
    slightly along a joint-space chord; in cycles the drift grows as the speed falls, and
    quadratically with the piece's length).  `k_hint`: the pixels a piece held on the
    scanline before (a neighbour fits about as many; one more is tried); `pad_mm`: how far
    its overscan reached (the line's samples are solved that far ahead at once); `bounds`:
    its pixel boundaries' angles when solved already (`motion.solve_bounds`)."""
    row = ctx.grid.powers[sl.row, sl.c0:sl.c1]
    row = row if sl.sign > 0 else row[::-1]
    geo = motion.LineGeo(ctx, sl, pad_mm, bounds)
    k = motion.scan_k(geo)
    if k_hint is not None:
        k = min(k, k_hint + 1)
    while True:
        sm = motion.plan(geo, k)
        ch = pixels.crossings(ctx, sm, row)
        worst = pixels.piece_residual(sm, ch)
        if worst <= pixels.FIT_CYCLES or k == 1:
            return sm, ch
        k = max(1, min(k - 1, math.floor(k * math.sqrt(pixels.FIT_CYCLES / worst) * 0.9)))


def plan_all(ctx: motion.RasterCtx, lines: list[gridmod.Scanline], home: IntArray,
             ring: int = linesmod.PX_RING) -> Planned:
    """Every scanline planned at ctx.v, its changes, its G7 lines (records within `ring`
    bytes of the pixel ring), and the job's segments."""
    scans, changes, groups = [], [], []
    k: int | None = None
    pad: tuple[float, float] | None = None
    for sl, bounds in zip(lines, motion.solve_bounds(ctx, lines), strict=True):
        sm, ch = plan_line(ctx, sl, k, pad, bounds)
        k = _piece_px(sm, ctx.grid.pitch)
        pad = _overscan_pad(sm)
        scans.append(sm)
        changes.append(ch)
        groups.append(linesmod.groups(sm, ch, ring))
    col = assemble.collect(ctx.profile, ctx.checker, scans, groups, home,
                           lead_us(linkrate.bytes_per_s(ctx.profile)))
    return Planned(ctx, scans, changes, groups, col)


def _overscan_pad(sm: motion.ScanMotion) -> tuple[float, float]:
    """How far the next scanline's samples are solved ahead before 0 and after L, mm: this
    one's overscan (the same on both sides), with room for a lowered ramp acceleration
    (`motion.RELAX`) and the samples around it — a guess: what it does not cover is solved
    when asked."""
    pad = 1.5 * max(-float(sm.sigma[0]), 0.0) + 2 * motion.SAMPLE_MM
    return pad, pad


def _piece_px(sm: motion.ScanMotion, pitch: float) -> int:
    """Pixels the scanline's first scan piece holds (all but its last hold as many)."""
    i = int(np.argmax(sm.kind == motion.SCAN))
    return max(1, round(float(sm.sigma[i + 1] - sm.sigma[i]) / pitch))


def speed_cap(ctx: motion.RasterCtx, lines: list[gridmod.Scanline]) -> float:
    """The fastest pen speed no joint exceeds `SPEED_SHARE` of its limit at (module doc)."""
    mot = ctx.profile.motion
    wmax = SPEED_SHARE * min(mot.max_joint_rad_s,
                             protocol.SETTINGS[0][2] * 2 * math.pi / ctx.spr)
    g = linegeo.max_gain(ctx, lines)  # max over the lines of gains(ctx, sl, 0, L)[0]
    return wmax / g


def link_lateness(line_bytes: list[int], line_start_s: list[float], rate: float,
                  line_segments: list[int]) -> float:
    """How late the latest wire line is taken, s (≤ 0: none is late): the lines streamed in
    order at `rate` bytes/s, each taking the firmware at least its segments' work
    (`G7_SEGMENT_US` each), never more than `BUFFER_BYTES` of them
    sent and not yet begun, the job's clock starting when its first line has arrived and
    been taken (its line l begins at `line_start_s[l]` on that clock)."""
    if not line_bytes:
        return 0.0
    seg_s = G7_SEGMENT_US * 1e-6
    t0 = max(line_bytes[0] / rate, line_segments[0] * seg_s)
    t, ahead, started, worst = 0.0, 0, 0, -math.inf
    for i, (b, n) in enumerate(zip(line_bytes, line_segments, strict=True)):
        while started < i and t0 + line_start_s[started] <= t:
            ahead -= line_bytes[started]
            started += 1
        while ahead + b > BUFFER_BYTES and started < i:
            t = max(t, t0 + line_start_s[started])
            ahead -= line_bytes[started]
            started += 1
        t += max(b / rate, n * seg_s)
        ahead += b
        worst = max(worst, t - (t0 + line_start_s[i]))
    return worst


def lead_us(rate: float) -> int:
    """How long the move to the first scanline lasts at least, µs (module docstring)."""
    return math.ceil(BUFFER_BYTES / rate * 1e6)


def _scaled_speed(pl: Planned, margin: float) -> float:
    """The speed at which no line of the planned ones would be late, their times scaled by
    the speed ratio (module docstring), times `margin`."""
    w = pl.collected.wire
    rate = linkrate.bytes_per_s(pl.ctx.profile)
    start = np.asarray(w.start_s)
    lo, hi = 0.05, 1.0  # the speed's factor: lo keeps up, hi is late
    for _ in range(12):
        mid = math.sqrt(lo * hi)
        if link_lateness(w.nbytes, (start / mid).tolist(), rate, w.nseg) <= 0:
            lo = mid
        else:
            hi = mid
    return pl.ctx.v * lo * margin


def probe(lines: list[gridmod.Scanline]) -> list[gridmod.Scanline]:
    """`PROBE_LINES` scanlines spread evenly over the image (the link's load varies along
    it: a pixel is a byte, but the pieces and their items vary with the workspace)."""
    if len(lines) <= PROBE_LINES:
        return lines
    pick = np.linspace(0, len(lines) - 1, PROBE_LINES).round().astype(np.int64)
    return [lines[i] for i in pick]


def plan_image(ctx: motion.RasterCtx, lines: list[gridmod.Scanline], home: IntArray,
               notes: list[str]) -> Planned:
    """Every scanline planned at the speed the joints and the link allow (module
    docstring); each lowering of the speed is noted."""
    cap = speed_cap(ctx, lines)
    if cap < ctx.v:
        notes.append(f"speed {ctx.v:g} → {cap:.1f} mm/s: the joints' speed limit along the "
                     "image")
        ctx = replace(ctx, v=cap)
    v0 = ctx.v
    ring = linesmod.ring_share(ctx.v / ctx.grid.pitch, linkrate.bytes_per_s(ctx.profile))
    # a pixel is a byte at least: no faster than the link's bytes a second in pixels
    ctx = replace(ctx, v=min(ctx.v, linkrate.bytes_per_s(ctx.profile) * ctx.grid.pitch))
    for subset, margin in ((probe(lines), PROBE_MARGIN), (lines, LINK_MARGIN)):
        for _ in range(6):
            pl = plan_all(ctx, subset, home, ring)
            if pl.late_s <= 0:
                break
            ctx = replace(ctx, v=_scaled_speed(pl, margin))
    if ctx.v < v0:
        notes.append(f"speed {v0:.1f} → {ctx.v:.1f} mm/s: what the link carries")
    return pl
