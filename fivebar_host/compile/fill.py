"""The fill stage: hatching (`--hatch`) and hidden-line removal (`--hiding`) on the placed
drawing, in machine millimetres, before it is flattened (`compile.place`).

It runs after placement so that the hatch spacing, the inset and every tolerance are
millimetres on the paper whatever `--scale`/`--fit` did; the hatch angle is measured on the
drawing (counter-clockwise from its x axis), so it turns with `--rotate`. Regions are built
within a tenth of the job's tolerance (`fill.regions`), hidden parts are found on chords of
that fineness and cut out of the exact primitives (`fill.hiding`, `fill.cuts`).

Per layer (an Inkscape layer's name, AxiDraw style) `+hatch=0.3mm`, `+angle=30`, `+cross`,
`+inset=0.1mm`, `+nohatch` change the hatch and `+nohide` leaves the layer out of hidden-line
removal (drawn whole, hiding nothing); docs/fill.md.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from fivebar_host.compile.model import CompileOptions
from fivebar_host.config import Profile
from fivebar_host.errors import InputError
from fivebar_host.options import parse_length
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.fill.arcs import ArcFrame, arc_hatch
from fivebar_host.toolpath.fill.assemble import FillResult, HatchStrokes, rebuild
from fivebar_host.toolpath.fill.chains import join_segments
from fivebar_host.toolpath.fill.cuts import Visible, visible_pieces
from fivebar_host.toolpath.fill.hatch import hatch_lines, rings_of, rotation
from fivebar_host.toolpath.fill.hiding import Hidden, convex_pieces, hidden_chords
from fivebar_host.toolpath.fill.paint import NO_FILL, PaintTable
from fivebar_host.toolpath.fill.regions import fill_regions
from fivebar_host.toolpath.geometry import ARC, Drawing, Polylines, flatten
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Regions and hidden parts are found within this share of the job's tolerance.
FINE = 0.1


@dataclass(frozen=True)
class Hatch:
    """One layer's hatch: spacing (mm on the paper; 0 = none), angle on the drawing
    (degrees), a second pass at +90° (`cross`), inset from the region's edge (mm)."""

    spacing_mm: float
    angle_deg: float
    cross: bool
    inset_mm: float
    along: str = "lines"  # or "arm1", "arm2": joint-iso arcs (`fill.arcs`)


def describe(h: Hatch) -> str:
    """A hatch in words for the dry run."""
    if h.along != "lines":
        other = "arm2" if h.along == "arm1" else "arm1"
        how = (f"at most {h.spacing_mm:g} mm apart along {h.along}'s joint-iso arcs (motor "
               f"{h.along[-1]} still)" + (f" and {other}'s" if h.cross else ""))
    else:
        how = f"{h.spacing_mm:g} mm apart at {h.angle_deg:g}°" + (" and +90°" if h.cross
                                                                   else "")
    return how + (f", {h.inset_mm:g} mm inside the edges" if h.inset_mm else "")


def wanted(opts: CompileOptions) -> bool:
    """Whether the stage has anything to do."""
    return opts.hatch_mm is not None or opts.hiding


def outline_notes(d: Drawing, opts: CompileOptions) -> list[str]:
    """Without `--hatch` and `--hiding` every element is drawn as its outline: a filled
    shape as its edge alone, a fill-only one (no stroke painted: a shadow, a white mask)
    outlined all the same — not what the file shows, so the job says so, with the options
    that draw it as a browser shows it."""
    paint = d.paint
    if wanted(opts) or paint is None:
        return []
    filled = paint.rule != NO_FILL
    n = int(np.count_nonzero(filled))
    if not n:
        return []
    bare = int(np.count_nonzero(filled & ~paint.stroked))
    what = (f"{n} filled shapes drawn as outlines only" if n > 1
            else "1 filled shape drawn as an outline only")
    if bare:
        what += (f" ({bare} of them with no stroke in the file)" if n > 1
                 else " (with no stroke in the file)")
    return [what + ": --hatch fills them, --hiding leaves out what later fills cover and "
            "the outlines the file does not stroke (docs/fill.md)"]


def default_width(profile: Profile) -> float:
    """The line a tool draws, mm: the pen's `width_mm`, else the laser's `spot_mm`."""
    return profile.pen.width_mm if profile.pen is not None else profile.laser.spot_mm


def base_hatch(opts: CompileOptions, profile: Profile) -> Hatch:
    """The job's hatch from its options (spacing 0: the profile's pen width)."""
    sp = opts.hatch_mm
    if sp is not None and sp == 0.0:
        sp = default_width(profile)
    return Hatch(sp or 0.0, opts.hatch_angle_deg, opts.crosshatch, opts.hatch_inset_mm,
                 opts.hatch_along)


_TOKEN = re.compile(r"\+(hatch|angle|inset)=(\S+)|\+(cross|nohatch|nohide)\b", re.I)


def layer_settings(name: str | None, base: Hatch) -> tuple[Hatch, bool]:
    """A layer's hatch and whether it takes part in hidden-line removal, from the tokens
    in its name (module doc)."""
    h, hide = base, True
    for m in _TOKEN.finditer(name or ""):
        key = (m.group(1) or m.group(3)).lower()
        try:
            if key == "hatch":
                h = replace(h, spacing_mm=parse_length(m.group(2)))
            elif key == "inset":
                h = replace(h, inset_mm=parse_length(m.group(2)))
            elif key == "angle":
                h = replace(h, angle_deg=float(m.group(2).lower().removesuffix("deg")))
        except ValueError as e:
            raise InputError(f"layer {name!r}: +{key}={m.group(2)}: {e}") from None
        if key == "cross":
            h = replace(h, cross=True)
        elif key == "nohatch":
            h = replace(h, spacing_mm=0.0)
        elif key == "nohide":
            hide = False
    if not (math.isfinite(h.spacing_mm) and 0 <= h.spacing_mm <= 100):
        raise InputError(f"layer {name!r}: hatch spacing must be within 0..100 mm")
    return h, hide


def apply(mdraw: Drawing, pl: layout.Placement, tol: float, opts: CompileOptions,
          profile: Profile, mode: str) -> Drawing:
    """The placed drawing with its hatches and without its hidden parts (module doc);
    `mode`: the working mode the job is placed for (joint-iso arcs keep its signs)."""
    mo = profile.motors
    frames = tuple(ArcFrame(profile.geometry, mode, arm, mo.home_rad[arm - 1],
                            mo.rad_per_step) for arm in (1, 2))
    return fill_drawing(mdraw, base_hatch(opts, profile), opts.hiding, tol, pl.matrix,
                        opts.hatch_mm is not None, frames)


def fill_drawing(d: Drawing, base: Hatch, hiding: bool, tol: float,
                 matrix: FloatArray | None = None, hatching: bool = True,
                 frames: tuple[ArcFrame, ...] = ()) -> Drawing:
    """`d` hatched (`base` per layer, unless `hatching` is off) and with its hidden parts
    removed (`hiding`), everything found within `FINE`·`tol`; `matrix` maps the drawing's
    directions to `d`'s frame (the placement's, for the hatch angle; None: the same);
    `frames`: the machine of each arm, for hatching along joint-iso arcs."""
    paint = d.paint or PaintTable.empty(len(d.sources))
    fine = tol * FINE
    poly = flatten(d, fine)
    regions = fill_regions(d, fine, poly)
    by_layer: dict[str | None, tuple[Hatch, bool]] = {}
    for s in d.sources:
        if s.layer not in by_layer:
            h, hide = layer_settings(s.layer, base)
            by_layer[s.layer] = (h if hatching else replace(h, spacing_mm=0.0), hide)
    hides = np.array([by_layer[s.layer][1] for s in d.sources], dtype=bool)
    occluding = np.zeros(len(d.sources), bool)
    if hiding:
        occluding[[s for s in regions if hides[s]]] = True
        vis, hidden_mm, unstroked_mm, hidden_segs = _hide(d, poly, paint, regions,
                                                          occluding, hides, fine)
    else:
        vis, hidden_mm, unstroked_mm = _all_visible(d), 0.0, 0.0
        hidden_segs = np.zeros((0, 2, 2))
    m = np.identity(2) if matrix is None else np.asarray(matrix, dtype=np.float64)
    hatches, stats, gaps = _hatch_all(d, m, regions, by_layer, occluding, fine, paint.paper,
                                      frames)
    notes: tuple[str, ...] = () if regions else (
        "nothing in the drawing is filled: --hatch and --hiding change nothing",)
    notes += tuple(f"hatch along {arm}'s joint-iso arcs: {k} motor steps apart, so the gap "
                   f"between neighbouring arcs on the paper is {lo:.3f}–{hi:.3f} mm here "
                   "(the still motor on a whole step; the gap varies with the angle between "
                   "the arm's two links)" for arm, (k, lo, hi) in sorted(gaps.items()))
    result = FillResult(hatch_mm=stats[0], link_mm=stats[1], regions=int(stats[2]),
                        simple_regions=int(stats[3]), hatch_runs=int(stats[4]),
                        hatch_runs_simple=int(stats[5]), hidden_mm=hidden_mm,
                        unstroked_mm=unstroked_mm, hiding=hiding, hidden=hidden_segs,
                        notes=notes, hatch=describe(base) if hatching else "")
    out = rebuild(d, vis, hatches, result)
    if out.kind.shape[0] == 0:
        raise InputError("nothing is left to draw: every line is hidden under later fills "
                         "(--hiding) and nothing is hatched", d.file)
    return out


def _all_visible(d: Drawing) -> Visible:
    n = d.kind.shape[0]
    new = np.ones(n, bool)
    new[1:] = d.stroke[1:] != d.stroke[:-1]
    return Visible(np.arange(n), np.zeros(n), np.ones(n), new)


def _chord_sources(d: Drawing, poly: Polylines) -> IntArray:
    """Per flattened vertex: the source of the chord ending there (−1 at stroke starts)."""
    counts = np.diff(poly.offsets)
    src = np.repeat(d.stroke_source[poly.stroke], counts).astype(np.int64)
    src[poly.offsets[:-1]] = -1
    return src


def _hide(d: Drawing, poly: Polylines, paint: PaintTable, regions: dict[int, BaseGeometry],
          occluding: BoolArray, hides: BoolArray, fine: float
          ) -> tuple[Visible, float, float, FloatArray]:
    """Hidden-line removal (`fill.hiding`): the visible pieces, the hidden stroke length,
    the outline length of fill-only shapes left out, and the hidden pieces as segments."""
    pieces = convex_pieces({s: g for s, g in regions.items() if occluding[s]})
    csrc = _chord_sources(d, poly)
    hidden = hidden_chords(poly, csrc, pieces, hides, occluding)
    keep_src = paint.stroked | ~hides  # fill-only shapes: occlude, not stroked (AxiDraw)
    keep = keep_src[d.stroke_source[d.stroke]]
    vis = visible_pieces(d.kind, d.params, d.stroke, keep, poly, hidden, 10 * fine)
    a, b = poly.points[hidden.chord - 1], poly.points[hidden.chord]
    dd = b - a
    segs = np.stack((a + hidden.u0[:, None] * dd, a + hidden.u1[:, None] * dd), axis=1)
    kept = keep_src[csrc[hidden.chord]]
    hidden_mm = float(((hidden.u1 - hidden.u0) * np.hypot(*dd.T))[kept].sum())
    v = np.flatnonzero(csrc >= 0)
    gone = v[~keep_src[csrc[v]]]
    ga, gb = poly.points[gone - 1], poly.points[gone]
    unstroked_mm = float(np.hypot(*(gb - ga).T).sum())
    segs = np.concatenate((segs[kept], np.stack((ga, gb), axis=1)))
    return vis, hidden_mm, unstroked_mm, segs


def _visible_region(s: int, regions: dict[int, BaseGeometry], later: list[int],
                    tree: shapely.STRtree | None) -> BaseGeometry:
    """Source s's fill less the fills painted after it that hide (`later`, in the tree)."""
    g = regions[s]
    if tree is None:
        return g
    idx = tree.query(g)
    cover = [regions[later[i]] for i in idx.tolist() if later[i] > s]
    return g.difference(shapely.union_all(cover)) if cover else g


def _hatch_all(d: Drawing, m: FloatArray, regions: dict[int, BaseGeometry],
               by_layer: dict[str | None, tuple[Hatch, bool]], occluding: BoolArray,
               fine: float, paper: BoolArray, frames: tuple[ArcFrame, ...]
               ) -> tuple[list[HatchStrokes], tuple[float, ...],
                          dict[str, tuple[int, float, float]]]:
    """Hatch strokes of every hatched source (not white ones: `paper`), (hatch mm, link
    mm, regions, simple regions, runs, runs in simple regions), and per arm hatched along
    its arcs (steps apart, narrowest and widest gap, mm)."""
    later = [s for s in regions if occluding[s]]
    tree = shapely.STRtree([regions[s] for s in later]) if later else None
    out: list[HatchStrokes] = []
    tot = np.zeros(6)
    gaps: dict[str, tuple[int, float, float]] = {}
    for s in sorted(regions):
        src = d.sources[s]
        h = by_layer[src.layer][0]
        if h.spacing_mm <= 0 or src.role or paper[s]:
            continue
        g = _visible_region(s, regions, later, tree)
        if h.inset_mm > 0:
            g = g.buffer(-h.inset_mm, join_style="mitre")
        if g.is_empty:
            continue
        if h.along != "lines" and frames:
            hs = _arc_hatch(s, g, h, frames, fine / FINE, tot, gaps)
            if hs.prims:
                out.append(hs)
            continue
        runs: list[FloatArray] = []
        for extra in (0.0, 90.0) if h.cross else (0.0,):
            r, st = hatch_region(g, _machine_angle(m, h.angle_deg + extra), h.spacing_mm,
                                 fine)
            runs.extend(r)
            tot += st
        if runs:
            out.append(HatchStrokes(s, runs))
    return out, tuple(float(v) for v in tot), gaps


def _arc_hatch(s: int, g: BaseGeometry, h: Hatch, frames: tuple[ArcFrame, ...], tol: float,
               tot: FloatArray, gaps: dict[str, tuple[int, float, float]]) -> HatchStrokes:
    """Source s's region hatched along joint-iso arcs (`fill.arcs`) for a job of
    tolerance `tol`, its figures added to `tot` and `gaps`."""
    arms = [int(h.along[-1])] + ([3 - int(h.along[-1])] if h.cross else [])
    out = HatchStrokes(s, [])
    for arm in arms:
        for part in shapely.get_parts(g).tolist():
            if part.geom_type != "Polygon" or part.is_empty:
                continue
            ah = arc_hatch(part, frames[arm - 1], h.spacing_mm, tol * FINE, tol)
            tot[2] += 1
            tot[3] += not part.interiors
            tot[4] += len(ah.runs)
            tot[5] += len(ah.runs) if not part.interiors else 0
            for kinds, params in ah.runs:
                arc = kinds == ARC
                tot[0] += float(np.abs(params[arc, 7]).sum()) * frames[arm - 1].b
                tot[1] += float(np.hypot(*(params[~arc, 2:4] - params[~arc, 0:2]).T).sum())
            out.prims.extend(ah.runs)
            if ah.runs:
                k, lo, hi = gaps.get(f"arm{arm}", (ah.steps, np.inf, 0.0))
                gaps[f"arm{arm}"] = (min(k, ah.steps), min(lo, ah.gap_min),
                                     max(hi, ah.gap_max))
    return out


def _machine_angle(m: FloatArray, deg: float) -> float:
    """The hatch direction on the machine for an angle on the drawing (`m`: the
    placement's linear part)."""
    a = math.radians(deg)
    v = m @ np.array([math.cos(a), math.sin(a)])
    return math.atan2(float(v[1]), float(v[0]))


def hatch_region(g: BaseGeometry, angle: float, spacing: float, eps: float
                 ) -> tuple[list[FloatArray], FloatArray]:
    """One pass of hatch lines through region g as pen-down runs (machine frame), and
    (hatch mm, link mm, polygons, simple polygons, runs, runs in simple polygons)."""
    rot = rotation(angle)
    st = np.zeros(6)
    runs: list[FloatArray] = []
    for part in shapely.get_parts(g).tolist():
        if part.geom_type != "Polygon" or part.is_empty:
            continue
        rg = rings_of(part, rot)
        ln = hatch_lines(rg, spacing)
        turned = shapely.transform(part, lambda xy: xy @ rot.T)
        done = join_segments(rg, ln, turned, eps)
        simple = not part.interiors
        st[2] += 1
        st[3] += simple
        st[4] += len(done)
        st[5] += len(done) if simple else 0
        for run in done:
            seg = np.hypot(*np.diff(run.xy, axis=0).T)
            st[0] += float(seg[run.hatch].sum())
            st[1] += float(seg[~run.hatch].sum())
            runs.append(run.xy @ rot)  # back from the hatch frame (rot is orthogonal)
    return runs, st


def hidden_chords_of(d: Drawing, tol: float, regions: dict[int, BaseGeometry]) -> Hidden:
    """The hidden chords of a drawing flattened within `tol` (for tests and benchmarks)."""
    poly = flatten(d, tol)
    occ = np.zeros(len(d.sources), bool)
    occ[list(regions)] = True
    return hidden_chords(poly, _chord_sources(d, poly), convex_pieces(regions),
                         np.ones(len(d.sources), bool), occ)
