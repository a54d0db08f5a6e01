"""Line simplification of densely sampled input, within a share of the one tolerance budget.

A drawing exported as many short straight lines (a polyline sampled every 0.05 mm by
`vpype read -q`, the G1 moves of a CAM tool, an SVG `<polyline>`) would otherwise become one
or more firmware segments per input line: thousands of tiny segments whose junctions the
planner must slow down for, so it plots far slower than the curve it was sampled from.
`simplify_polylines` removes vertices from every run of consecutive straight input lines
with the Ramer–Douglas–Peucker algorithm (vectorised over all runs at once, one level of
the recursion per round), keeping every vertex of a curve's flattening, every end of a run
and every stroke end.

**Bound.** Let O be a run of original lines from vertex i to vertex j and C the chord
[P_i, P_j] that replaces it. RDP keeps C only when every original vertex between i and j is
within ε of the *segment* C (distance to the segment, not to its line), i.e. inside the
capsule K = {x : d(x, C) ≤ ε}. K is convex, so every original edge (between two vertices
in K) lies in K too: every point of O is within ε of C. Conversely, let c ∈ C at axial
position s ∈ [0, |C|] along C. The axial projection of O is continuous and runs from 0
(P_i) to |C| (P_j), so some q ∈ O has the same axial position s (intermediate value
theorem); q ∈ K at axial position within [0, |C|] means its distance from C's line is
≤ ε, and that is |q − c|. So every point of C is within ε of O: the Hausdorff distance
between C and O is at most ε. The job compiler then refines each such chord so the
joint-interpolated pen path stays within tol − ε of it (`fivebar_host.compile.chords`), and
by the triangle inequality every pen point is within tol of the original lines.

The ε comes from the flattening share of the budget (tol_f = tol/2): straight input lines are
never flattened, so a run of them treated like the flattening of a curve gets the budget a
curve gets. A chord that replaces a single line keeps the whole budget (it is exact).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from fivebar_host.toolpath.geometry import LINE, Polylines
from kinematics.arrays import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class Simplified:
    """Simplified polylines and, per vertex, the first primitive of the chord that ends there
    (`prim_first`; `Polylines.prim` holds the last): a chord that replaced several input
    lines covers primitives prim_first … prim (contiguous in the stroke)."""

    poly: Polylines
    prim_first: IntArray
    removed: int  # vertices removed


def segment_distance(p: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance of points p (n, 2) from the segments [a, b] (n, 2 each); a point segment
    (a = b) gives the distance to that point."""
    ab = b - a
    ap = p - a
    ll = np.einsum("ij,ij->i", ab, ab)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(ll > 0, np.einsum("ij,ij->i", ap, ab) / np.where(ll > 0, ll, 1.0), 0.0)
    u = np.clip(u, 0.0, 1.0)
    return np.asarray(np.hypot(*(ap - u[:, None] * ab).T), dtype=np.float64)


def rdp_keep(points: FloatArray, lo: IntArray, hi: IntArray, eps: float) -> BoolArray:
    """Ramer–Douglas–Peucker on the vertex ranges [lo[k], hi[k]] of `points`: which vertices
    to keep so every removed vertex is within `eps` of the segment between the kept vertices
    around it. Both ends of every range are kept. All ranges advance one recursion level per
    round (vectorised)."""
    keep = np.zeros(points.shape[0], dtype=bool)
    keep[lo] = True
    keep[hi] = True
    lo = np.asarray(lo, dtype=np.int64)
    hi = np.asarray(hi, dtype=np.int64)
    while True:
        wide = hi - lo >= 2
        lo, hi = lo[wide], hi[wide]
        if not lo.size:
            return keep
        cnt = hi - lo - 1
        grp = np.repeat(np.arange(lo.shape[0]), cnt)
        first = np.cumsum(cnt) - cnt
        idx = lo[grp] + 1 + (np.arange(grp.shape[0]) - first[grp])
        d = segment_distance(points[idx], points[lo[grp]], points[hi[grp]])
        dmax = np.maximum.reduceat(d, first)
        split = dmax > eps
        # first vertex of each range at its maximum distance
        at_max = np.flatnonzero(d == dmax[grp])
        g_of, pos = np.unique(grp[at_max], return_index=True)
        mid = np.empty(lo.shape[0], dtype=np.int64)
        mid[g_of] = idx[at_max[pos]]
        mid, lo_s, hi_s = mid[split], lo[split], hi[split]
        keep[mid] = True
        lo = np.concatenate((lo_s, mid))
        hi = np.concatenate((mid, hi_s))


def simplify_polylines(poly: Polylines, kind: NDArray[np.int8], eps: float) -> Simplified:
    """Remove vertices inside runs of straight input lines (module doc) so that every chord
    of the result is within `eps` of the lines it replaces, and they of it."""
    m = poly.points.shape[0]
    prim_first = poly.prim.copy()
    if m == 0 or eps <= 0:
        return Simplified(poly, prim_first, 0)
    start = np.zeros(m, dtype=bool)
    start[poly.offsets[:-1]] = True
    end = np.zeros(m, dtype=bool)
    end[poly.offsets[1:] - 1] = True
    line_in = (kind[poly.prim] == LINE) & ~start  # chord v−1 → v is a whole input line
    line_out = np.zeros(m, dtype=bool)
    line_out[:-1] = line_in[1:]
    fixed = start | end | ~line_in | ~line_out
    fv = np.flatnonzero(fixed)
    run = np.diff(fv) >= 2  # interior vertices between two fixed ones: a run of lines
    keep = fixed | rdp_keep(poly.points, fv[:-1][run], fv[1:][run], eps)
    kept = np.flatnonzero(keep)
    # The chord into kept vertex w starts at the kept vertex before it: its first primitive
    # is that of the input line after that vertex.
    prev = np.concatenate(([0], kept[:-1]))
    pf = np.where(start[kept], poly.prim[kept], poly.prim[np.minimum(prev + 1, m - 1)])
    new_off = np.concatenate(([0], np.cumsum(keep)))[poly.offsets].astype(np.int64)
    out = replace(poly, points=poly.points[kept], offsets=new_off, prim=poly.prim[kept],
                  t=poly.t[kept], t0=poly.t0[kept])
    return Simplified(out, pf.astype(np.int64), int(m - kept.shape[0]))
