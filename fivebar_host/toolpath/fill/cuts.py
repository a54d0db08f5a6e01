"""Cutting primitives exactly: the visible parameter intervals of every primitive, from
hidden intervals found on its flattened chords (`fill.hiding`), and the pieces of lines,
arcs and cubics over those intervals (lines and arcs by parameter, cubics by de Casteljau),
so a cut stroke keeps its exact curves and only where the cut falls depends on the
flattening tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fivebar_host.toolpath.fill.hiding import Hidden, union_per_chord
from fivebar_host.toolpath.geometry import ARC, CUBIC, LINE, Polylines, evaluate
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Parameters this close to a primitive's ends are its ends (keeps strokes chained).
T_EPS = 1e-12


@dataclass(frozen=True)
class Visible:
    """Visible pieces in drawing order: primitive `prim` over [a, b], and whether each piece
    starts a new stroke."""

    prim: IntArray
    a: FloatArray
    b: FloatArray
    new_stroke: BoolArray


def visible_pieces(kind: NDArray[np.int8], params: FloatArray, stroke: IntArray,
                   keep: BoolArray, poly: Polylines, hidden: Hidden,
                   min_len: float) -> Visible:
    """The visible parameter intervals of the primitives with `keep` (others are dropped
    whole), given the hidden chords; pieces shorter than `min_len` (a touch, not a line)
    are dropped."""
    n = kind.shape[0]
    v = hidden.chord
    span = poly.t[v] - poly.t0[v]
    hp, ha, hb = union_per_chord(poly.prim[v], poly.t0[v] + hidden.u0 * span,
                                 poly.t0[v] + hidden.u1 * span)
    ha = np.where(ha < T_EPS, 0.0, ha)
    hb = np.where(hb > 1 - T_EPS, 1.0, hb)
    # gaps between hidden intervals (each primitive's intervals are sorted and disjoint)
    first = np.ones(hp.shape[0], bool)
    first[1:] = hp[1:] != hp[:-1]
    last = np.ones(hp.shape[0], bool)
    last[:-1] = hp[1:] != hp[:-1]
    ga = np.concatenate((np.zeros(int(first.sum())), hb))
    gb = np.concatenate((ha[first], np.where(last, 1.0, np.roll(ha, -1))))
    gp = np.concatenate((hp[first], hp))
    whole = np.ones(n, bool)
    whole[hp] = False
    wp = np.flatnonzero(whole)
    prim = np.concatenate((gp, wp))
    a = np.concatenate((ga, np.zeros(wp.shape[0])))
    b = np.concatenate((gb, np.ones(wp.shape[0])))
    ok = (b - a > T_EPS) & keep[prim]
    prim, a, b = prim[ok], a[ok], b[ok]
    order = np.lexsort((a, prim))
    prim, a, b = prim[order], a[order], b[order]
    pa = evaluate(kind[prim], params[prim], a)
    pb = evaluate(kind[prim], params[prim], b)
    pm = evaluate(kind[prim], params[prim], 0.5 * (a + b))
    size = np.hypot(*(pa - pm).T) + np.hypot(*(pm - pb).T)
    whole_prim = (a == 0.0) & (b == 1.0)
    ok = whole_prim | (size >= min_len)
    prim, a, b = prim[ok], a[ok], b[ok]
    new = np.ones(prim.shape[0], bool)
    new[1:] = ~((a[1:] == 0.0) & (b[:-1] == 1.0) & (prim[1:] == prim[:-1] + 1)
                & (stroke[prim[1:]] == stroke[prim[:-1]]))
    return Visible(prim, a, b, new)


def sub_primitives(kind: NDArray[np.int8], params: FloatArray, a: FloatArray,
                   b: FloatArray) -> FloatArray:
    """The pieces of primitives over [a, b] (exact for every kind), params (N, 8)."""
    out = params.copy()
    cut = (a > 0.0) | (b < 1.0)
    li = cut & (kind == LINE)
    if li.any():
        p = params[li]
        d = p[:, 2:4] - p[:, 0:2]
        out[li, 0:2] = p[:, 0:2] + a[li, None] * d
        out[li, 2:4] = p[:, 0:2] + b[li, None] * d
    ar = cut & (kind == ARC)
    if ar.any():
        p = params[ar]
        out[ar, 6] = p[:, 6] + a[ar] * p[:, 7]
        out[ar, 7] = (b[ar] - a[ar]) * p[:, 7]
    cu = cut & (kind == CUBIC)
    if cu.any():
        c = params[cu, :8].reshape(-1, 4, 2)
        c = _split(c, b[cu])[0]  # [0, b]
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(b[cu] > 0, a[cu] / b[cu], 0.0)
        c = _split(c, r)[1]  # [a, b]
        out[cu, :8] = c.reshape(-1, 8)
    return out


def _split(c: FloatArray, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """De Casteljau: both halves of cubics c (N, 4, 2) at t (N,)."""
    tt = t[:, None]
    p01 = c[:, 0] + tt * (c[:, 1] - c[:, 0])
    p12 = c[:, 1] + tt * (c[:, 2] - c[:, 1])
    p23 = c[:, 2] + tt * (c[:, 3] - c[:, 2])
    p012 = p01 + tt * (p12 - p01)
    p123 = p12 + tt * (p23 - p12)
    m = p012 + tt * (p123 - p012)
    return (np.stack((c[:, 0], p01, p012, m), axis=1),
            np.stack((m, p123, p23, c[:, 3]), axis=1))
