"""The exact extent of a drawing: its bounding box from the primitives' end points and the
interior points where a curve's x or y is extreme (not a flattening at some tolerance, so a
nearly straight arc of a 35 m radius, as gcodetools writes, adds nothing beyond its own
extent and `--fit` uses the whole safe area)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fivebar_host.toolpath.geometry import (
    ARC,
    CUBIC,
    Drawing,
    end_points,
    evaluate,
    start_points,
)
from kinematics.arrays import FloatArray


def bbox(drawing: Drawing) -> tuple[float, float, float, float]:
    """Exact bounding box (xmin, ymin, xmax, ymax) of the curves, mm: every primitive's end
    points and the interior points where its x or y is extreme (`extreme_points`), so a
    nearly straight arc of a 35 m radius adds nothing beyond its own extent."""
    if drawing.kind.shape[0] == 0:
        raise ValueError("empty drawing has no bounding box")
    kind, params = drawing.kind, drawing.params
    pts = np.concatenate((start_points(kind, params), end_points(kind, params),
                          extreme_points(kind, params)))
    # (column by column: numpy's reductions over the long axis of an (N, 2) array are
    # some 30x slower)
    x, y = pts[:, 0], pts[:, 1]
    return float(x.min()), float(y.min()), float(x.max()), float(y.max())


def extreme_points(kind: NDArray[np.int8], params: FloatArray) -> FloatArray:
    """The interior points of cubics and arcs where x or y is extreme (the derivative of one
    coordinate is zero): with the end points, a primitive's exact bounding box.

    Cubic: B'(t)/3 = (d0 − 2d1 + d2)t² + 2(d1 − d0)t + d0 per coordinate (d_i = p_{i+1} − p_i),
    its roots in (0, 1). Arc E(θ) = c + M·(cos θ, sin θ): x is extreme at θ = atan2(M01, M00)
    and θ + π, y at atan2(M11, M10) and θ + π, where those fall inside the sweep."""
    out = [np.zeros((0, 2))]
    cub = np.flatnonzero(kind == CUBIC)
    if cub.size:
        p = params[cub].reshape(-1, 4, 2)
        d0, d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 3] - p[:, 2]
        a, b, c = d0 - 2 * d1 + d2, 2 * (d1 - d0), d0
        with np.errstate(divide="ignore", invalid="ignore"):
            disc = np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))
            quad = np.abs(a) > 1e-12 * (np.abs(b) + np.abs(c) + 1e-300)
            r1 = np.where(quad, (-b + disc) / (2 * a), -c / b)
            r2 = np.where(quad, (-b - disc) / (2 * a), np.nan)
        for t in (r1, r2):
            for col in (0, 1):
                tt = t[:, col]
                ok = np.isfinite(tt) & (tt > 0) & (tt < 1)
                if ok.any():
                    out.append(evaluate(kind[cub[ok]], params[cub[ok]], tt[ok]))
    arc = np.flatnonzero(kind == ARC)
    if arc.size:
        p = params[arc]
        th0, sweep = p[:, 6], p[:, 7]
        base = np.stack((np.arctan2(p[:, 3], p[:, 2]), np.arctan2(p[:, 5], p[:, 4])), axis=1)
        for phi in (base[:, 0], base[:, 0] + np.pi, base[:, 1], base[:, 1] + np.pi):
            ahead = np.mod(np.where(sweep >= 0, phi - th0, th0 - phi), 2 * np.pi)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(np.abs(sweep) >= 2 * np.pi, 0.5, ahead / np.abs(sweep))
            ok = np.isfinite(t) & (t <= 1.0)
            if ok.any():
                out.append(_arc_at(p[ok], np.where(np.abs(sweep[ok]) >= 2 * np.pi,
                                                   phi[ok], th0[ok] + t[ok] * sweep[ok])))
    return np.concatenate(out)


def _arc_at(p: FloatArray, theta: FloatArray) -> FloatArray:
    """Points of arcs `p` (ARC parameters) at angles `theta`."""
    cs = np.stack((np.cos(theta), np.sin(theta)), axis=1)
    out: FloatArray = p[:, 0:2] + np.einsum("nij,nj->ni", p[:, 2:6].reshape(-1, 2, 2), cs)
    return out
