"""Dwells (G-code `G4`) as segments without motion, which the firmware runs as a wait.

docs/protocol.md section 6: "a segment with no motion is a dwell" — the firmware queues a
block of zero steps that lasts exactly its P µs, with the laser at the segment's power. So a
dwell needs no firmware change: it is one or more `G1 P<µs> [S<power>]` lines without A/B,
each at most the protocol's largest P (100 s), at least its smallest (100 µs).

The compiler places each dwell at the start or end of its job path (`geometry.Dwell`,
`compile.chords`): before the path's first drawing segment, or after its last segment (before
the travel to the next path). The planner must arrive there at rest, so the segment before a
dwell ends a run (`dwell_stops`, a stop in `compile.timing`); the dwell segments are inserted
into the planned job afterwards (`insert_dwells`), so the planner never times them and
`drop_zero_moves` never sees them. In the job a dwell segment is not a drawing segment
(`Job.draw` False, so validation and the executed-path report skip it), is marked in
`Job.dwell`, and carries in `Job.power` the laser power it burns with (0: tool off); on a pen
machine a power above 0 means the pen stays down (`Job.tool_on`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile.segments import Stepped
from fivebar_host.config import Profile
from fivebar_host.toolpath.geometry import Dwell
from kinematics.arrays import BoolArray, IntArray

if TYPE_CHECKING:  # timing imports this module
    from fivebar_host.compile.timing import Planned


def insertion_points(dwells: tuple[Dwell, ...], path: IntArray, draw: BoolArray) -> IntArray:
    """Index of the segment each dwell goes before (its `stroke` is its job path): after
    the last segment of its path, or before the path's first drawing segment (else after the
    travel into it). `path` is nondecreasing (travel into path j, then its drawing)."""
    out = np.empty(len(dwells), dtype=np.int64)
    for i, d in enumerate(dwells):
        after_path = int(np.searchsorted(path, d.stroke, side="right"))
        first = np.flatnonzero(draw & (path == d.stroke))
        out[i] = after_path if d.after or not first.size else int(first[0])
    return out


def dwell_stops(dwells: tuple[Dwell, ...], sp: Stepped) -> BoolArray:
    """Per stepped segment: whether a dwell follows it (the machine must stop there)."""
    stop = np.zeros(sp.draw.shape[0], dtype=bool)
    at = insertion_points(dwells, sp.path, sp.draw)
    stop[at[at > 0] - 1] = True
    return stop


def dwell_pieces(seconds: float) -> list[int]:
    """A dwell's segment durations, µs: as equal as whole µs allow, each within the
    protocol's P range (a dwell shorter than the smallest P lasts that long)."""
    us = max(protocol.P_MIN_US, round(seconds * 1e6))
    n = math.ceil(us / protocol.P_MAX_US)
    base, extra = divmod(us, n)
    return [base + (1 if i < extra else 0) for i in range(n)]


def dwell_power(d: Dwell, profile: Profile) -> int:
    """The laser power (0–255) of a dwell: the profile's power scaled by the dwell's
    fraction, at least 1 when the tool is on (so a pen stays down), 0 when it is off."""
    if not d.tool_on:
        return 0
    return int(np.clip(np.rint(d.power * profile.laser.power), 1, protocol.POWER_MAX))


def insert_dwells(dwells: tuple[Dwell, ...], profile: Profile, pd: Planned) -> Planned:
    """The planned job `pd` with every dwell's segments
    inserted (module doc); each keeps its place among dwells at the same point (file
    order)."""
    if not dwells:
        return pd
    at = insertion_points(dwells, pd.path, pd.draw)
    order = np.argsort(at, kind="stable")
    idx: list[int] = []
    dur: list[int] = []
    power: list[int] = []
    path: list[int] = []
    line: list[int] = []
    for i in order.tolist():
        d = dwells[i]
        pieces = dwell_pieces(d.seconds)
        idx += [int(at[i])] * len(pieces)
        dur += pieces
        power += [dwell_power(d, profile)] * len(pieces)
        path += [d.stroke] * len(pieces)
        line += [d.line] * len(pieces)
    ix = np.asarray(idx, dtype=np.int64)
    return replace(
        pd, th=np.insert(pd.th, ix, pd.th[ix], axis=0),
        pts=np.insert(pd.pts, ix, pd.pts[ix], axis=0),
        steps=np.insert(pd.steps, ix, pd.steps[ix], axis=0),
        draw=np.insert(pd.draw, ix, False), path=np.insert(pd.path, ix, path),
        source=np.insert(pd.source, ix, -1), line=np.insert(pd.line, ix, line),
        length=np.insert(pd.length, ix, 0.0), perm=np.insert(pd.perm, ix, -1),
        power=np.insert(pd.power, ix, power), f0=np.insert(pd.f0, ix, 0.0),
        f1=np.insert(pd.f1, ix, 1.0), duration_us=np.insert(pd.duration_us, ix, dur),
        dwell=np.insert(pd.dwell, ix, True),
        slack=np.insert(pd.slack, ix, pd.slack[ix], axis=0) if pd.slack.shape[0] else pd.slack)
