"""Link reduction: each rigid link as independent binary rigidity constraints.

A link of k joints is rigid through 2k − 3 binary constraints in the plane and on the sphere
(3k − 6 in space), whose metrics are measured in the initial configuration (Algorithm 1,
line 1): point–point distances (RR, Eq. 1), point–line distances (RP, Eqs. 2–3) and
line–line angles (PP, Eqs. 4–7). `reduce_link` chooses them so that every joint is held by
the most independent ones.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray
from kinematics.nbar import constraints as cst
from kinematics.nbar.constraints import ConstraintKind
from kinematics.nbar.model import Kind, Link, MechanismError

#: Smallest acceptable independence (σ_min of the unit constraint gradients on the joint's own
#: degrees of freedom) of the binary constraints chosen to hold a joint in its link.
MIN_INDEPENDENCE = 1e-3


@dataclass(frozen=True)
class Row:
    kind: ConstraintKind
    prims: tuple[int, int]
    value: float
    grad_first: FloatArray
    grad_second: FloatArray


def _pair_row(i: int, j: int, h: FloatArray, is_line: NDArray[np.bool_], planar: bool) -> Row:
    """The binary rigidity constraint between primitives i and j, with its metric measured in
    the initial configuration (Algorithm 1, line 1) and the gradients there."""
    li, lj = bool(is_line[i]), bool(is_line[j])
    if not li and not lj:
        r = float(np.linalg.norm(h[i, :-1] / h[i, -1] - h[j, :-1] / h[j, -1]))
        _, ga, gb = cst.rr(h[i], h[j], r)
        return Row("RR", (i, j), r, ga, gb)
    if li and lj:
        lv, mv = h[i, :-1], h[j, :-1]
        den = float(np.linalg.norm(lv) * np.linalg.norm(mv))
        k = float(lv @ mv) / den
        if planar:
            s = float(lv[0] * mv[1] - lv[1] * mv[0]) / den
            if abs(k) > abs(s):
                _, ga, gb = cst.pp_sin(h[i], h[j], s)
                return Row("PPsin", (i, j), s, ga, gb)
        _, ga, gb = cst.pp(h[i], h[j], k)
        return Row("PP", (i, j), k, ga, gb)
    p, ln = (j, i) if li else (i, j)
    a, line = h[p], h[ln]
    d = float(a[:-1] @ line[:-1] + a[-1] * line[-1]) / (a[-1] * float(np.linalg.norm(line[:-1])))
    _, ga, gl = cst.rp(a, line, d)
    return Row("RP", (p, ln), d, ga, gl)


def _tangent_basis(v: FloatArray, line: bool, kind: Kind) -> FloatArray:
    """Columns spanning the directions a primitive can move in (homogeneous coordinates):
    the plane for a planar point, (rotate, shift) for a planar line, the tangent plane of the
    sphere (or of the unit normal) on the sphere, all of space for a spatial point."""
    if kind == "planar":
        if line:
            return np.array([[-v[1], v[0], 0.0], [0.0, 0.0, 1.0]]).T
        return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]).T
    if kind == "spatial":
        return np.vstack((np.eye(3), np.zeros((1, 3))))
    n = v[:3] / np.linalg.norm(v[:3])
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    return np.vstack((np.array([t1, t2]).T, np.zeros((1, 2))))


def _independence(rows: Sequence[Row], i: int, tb: FloatArray) -> float:
    """σ_min of the chosen rows' unit gradients projected on primitive i's own motions."""
    g = np.array([(r.grad_first if r.prims[0] == i else r.grad_second) @ tb for r in rows])
    nrm = np.linalg.norm(g, axis=1)
    if np.any(nrm < 1e-12):
        return 0.0
    return float(np.linalg.svd(g / nrm[:, None], compute_uv=False)[-1])


def reduce_link(link: Link, members: Sequence[int], h: FloatArray, is_line: NDArray[np.bool_],
                kind: Kind, names: Sequence[str]) -> list[Row]:
    """Independent binary rigidity constraints for one link (2k − 3 in the plane and on the
    sphere, 3k − 6 in space for k ≥ 3 points, 1 for two).

    A base pair (in space a base triangle) gets its mutual constraints; every further joint is
    then tied to joints already placed by as many binary constraints as it has degrees of
    freedom (2, or 3 in space), choosing, among all placed partners, the subset whose gradients
    are the most independent on that joint's own motions. Lines and planes are primitives like
    points: point–line pairs give RP rows, line–line pairs PP rows.
    """
    planar = kind == "planar"
    pts = [i for i in members if not is_line[i]]
    lns = [i for i in members if is_line[i]]
    if kind == "spatial" and lns:
        raise MechanismError(f"link {link.name}: prismatic joints are not supported in space")
    rows: list[Row] = []
    if len(members) < 2:
        return rows
    if kind == "spatial" and len(pts) >= 3:
        def area(t: Sequence[int]) -> float:
            a, b, c = (h[k, :3] for k in t)
            return float(np.linalg.norm(np.cross(b - a, c - a)))
        triples: list[Sequence[int]] = list(itertools.combinations(pts, 3))
        base = list(triples[int(np.argmax([area(t) for t in triples]))])
        if area(base) < 1e-6 * spread(h, pts) ** 2:
            raise MechanismError(f"link {link.name}: its joints are collinear; a rigid spatial "
                                 "link needs three joints that are not on one line")
        rows += [_pair_row(a, b, h, is_line, planar) for a, b in itertools.combinations(base, 2)]
    else:
        if len(pts) >= 2:
            def dist(t: Sequence[int]) -> float:
                return float(np.linalg.norm(h[t[0], :-1] - h[t[1], :-1]))
            pairs: list[Sequence[int]] = list(itertools.combinations(pts, 2))
            base = list(pairs[int(np.argmax([dist(t) for t in pairs]))])
        elif pts:
            base = [pts[0], lns[0]]
        else:
            base = [lns[0], lns[1]]
        rows.append(_pair_row(base[0], base[1], h, is_line, planar))
    placed = list(base)
    dof = 3 if kind == "spatial" else 2
    for i in [k for k in pts + lns if k not in base]:
        cands = [_pair_row(i, j, h, is_line, planar) for j in placed]
        tb = _tangent_basis(h[i], bool(is_line[i]), kind)
        best = max(itertools.combinations(cands, dof), key=lambda c: _independence(c, i, tb))
        if _independence(best, i, tb) < MIN_INDEPENDENCE:
            others = ", ".join(names[j] for j in placed)
            raise MechanismError(
                f"link {link.name}: joint {names[i]} cannot be held by binary constraints to "
                f"{others}: it is (nearly) {'coplanar' if kind == 'spatial' else 'collinear'} "
                "with them, so the distance gradients are dependent; move it off that "
                f"{'plane' if kind == 'spatial' else 'line'} or split the link")
        rows += list(best)
        placed.append(i)
    for r in rows:
        if r.kind == "RR" and r.value < 1e-9 * max(spread(h, pts), 1e-300):
            a, b = r.prims
            raise MechanismError(f"link {link.name}: joints {names[a]} and {names[b]} coincide")
    return rows


def spread(h: FloatArray, pts: Sequence[int]) -> float:
    """Largest distance of the given points from their centroid (1 if there are none)."""
    if not pts:
        return 1.0
    p = h[list(pts), :-1] / h[list(pts), -1:]
    return float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1))) or 1.0
