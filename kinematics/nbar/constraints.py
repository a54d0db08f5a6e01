"""Rigidity constraints of the point-line-plane representation, with analytic derivatives.

Sharma & Purwar (2020). A point is homogeneous: (x, y, w) in the plane, (x, y, z, w) on the
sphere and in space. A planar line is (L1, L2, L4) with L1·x + L2·y + L4·w = 0; a spherical
prismatic joint is a plane through the centre, (L1, L2, L3, 0). Each function below is one of the
paper's equations written exactly as C = left side − right side, vectorised over leading axes,
and returns C with its partial derivatives with respect to *every* coordinate, homogenising
factors included. The paper's Eqs. 26–41 set those factors to 1, print ∂C/∂a = 2(a − b) for
Eq. 1 (the derivative of −C), and divide by ‖L‖² in Eq. 37 where ‖L‖ is meant; the formulas
here were derived again and are checked against central finite differences in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray, IndexArray

ConstraintKind = Literal["RR", "RP", "PP", "PPsin", "NORM", "SPHERE", "ACT"]

#: Which of the paper's equations each constraint kind implements (planar / spherical-spatial).
EQUATIONS: dict[str, str] = {
    "RR": "Eq. 2 (plane) / Eq. 1 (sphere, space)",
    "RP": "Eq. 5 (plane) / Eq. 4 (sphere)",
    "PP": "Eq. 7 (plane) / Eq. 6 (sphere)",
    "PPsin": "Eq. 7 with the sine of the angle (near-parallel lines)",
    "NORM": "Eq. 8",
    "SPHERE": "Eq. 9",
    "ACT": "Eq. 1 with a driven length (linear actuator)",
}


def _dot(u: FloatArray, v: FloatArray) -> FloatArray:
    """Row-wise dot product over the last axis (2 or 3 wide here: summed component by
    component, several times faster than einsum or a reduction on such short rows)."""
    out = u[..., 0] * v[..., 0]
    for i in range(1, u.shape[-1]):
        out = out + u[..., i] * v[..., i]
    return np.asarray(out, dtype=np.float64)


def rr_value(a: FloatArray, b: FloatArray, r: FloatArray | float) -> FloatArray:
    """Value of Eq. 1 / 2 alone (see `rr`)."""
    av, aw = a[..., :-1], a[..., -1]
    bv, bw = b[..., :-1], b[..., -1]
    r2 = np.asarray(r, dtype=np.float64) ** 2
    return np.asarray(2.0 * _dot(av, bv) + (aw * r2 - _dot(av, av) / aw) * bw
                      - aw * _dot(bv, bv) / bw, dtype=np.float64)


def rp_value(a: FloatArray, line: FloatArray, d: FloatArray | float) -> FloatArray:
    """Value of Eqs. 3–5 alone (see `rp`)."""
    av, aw = a[..., :-1], a[..., -1]
    lv, l4 = line[..., :-1], line[..., -1]
    return np.asarray(_dot(av, lv) + aw * l4 - np.asarray(d) * aw * np.sqrt(_dot(lv, lv)),
                      dtype=np.float64)


def rr(a: FloatArray, b: FloatArray, r: FloatArray | float
       ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """RR link, Eqs. 1–2: the points a, b (weights last) stay a distance r apart.

    C = 2 a·b + a0·b_w − a_w·|b|²/b_w with a0 = a_w r² − |a|²/a_w, which equals
    a_w b_w (r² − |a/a_w − b/b_w|²). Returns (C, ∂C/∂a, ∂C/∂b).
    """
    av, aw = a[..., :-1], a[..., -1]
    bv, bw = b[..., :-1], b[..., -1]
    aa, bb = _dot(av, av), _dot(bv, bv)
    r2 = np.asarray(r, dtype=np.float64) ** 2
    a0 = aw * r2 - aa / aw
    c = rr_value(a, b, r)
    da = np.empty_like(a)
    db = np.empty_like(b)
    da[..., :-1] = 2.0 * bv - 2.0 * av * (bw / aw)[..., None]
    da[..., -1] = r2 * bw + aa * bw / aw**2 - bb / bw
    db[..., :-1] = 2.0 * av - 2.0 * bv * (aw / bw)[..., None]
    db[..., -1] = a0 + aw * bb / bw**2
    return c, da, db


def rp(a: FloatArray, line: FloatArray, d: FloatArray | float
       ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """RP / PR link, Eqs. 3–5: point a keeps the signed distance d from a line or plane.

    C = a_v·L_v + a_w·L_4 − d·a_w·‖L_v‖, L_v the normal part of the line (L1, L2) or plane
    (L1, L2, L3), L_4 its offset (0 for a spherical plane, Eq. 4). Returns (C, ∂C/∂a, ∂C/∂L).
    """
    av, aw = a[..., :-1], a[..., -1]
    lv, l4 = line[..., :-1], line[..., -1]
    dd = np.asarray(d, dtype=np.float64)
    nl = np.sqrt(_dot(lv, lv))
    c = rp_value(a, line, d)
    da = np.empty_like(a)
    dl = np.empty_like(line)
    da[..., :-1] = lv
    da[..., -1] = l4 - dd * nl
    dl[..., :-1] = av - (dd * aw / nl)[..., None] * lv
    dl[..., -1] = aw
    return c, da, dl


def pp(line: FloatArray, other: FloatArray, k: FloatArray | float
       ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """PP link, Eqs. 6–7: two lines (planes) keep the angle arccos k between their normals.

    C = L_v·M_v − k‖L_v‖‖M_v‖. Returns (C, ∂C/∂L, ∂C/∂M); offsets L_4, M_4 do not appear.
    """
    lv, mv = line[..., :-1], other[..., :-1]
    kk = np.asarray(k, dtype=np.float64)
    nl, nm = np.sqrt(_dot(lv, lv)), np.sqrt(_dot(mv, mv))
    c = _dot(lv, mv) - kk * nl * nm
    dl = np.zeros_like(line)
    dm = np.zeros_like(other)
    dl[..., :-1] = mv - (kk * nm / nl)[..., None] * lv
    dm[..., :-1] = lv - (kk * nl / nm)[..., None] * mv
    return c, dl, dm


def pp_sin(line: FloatArray, other: FloatArray, s: FloatArray | float
           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Planar PP link through the sine of the angle: L1·M2 − L2·M1 = s‖L_v‖‖M_v‖.

    Eq. 7 fixes the cosine k, whose gradient vanishes as the lines become parallel (k → ±1);
    the sine form is well conditioned there and also keeps the sense of the angle. Used for
    planar PP pairs with |k| > |s|. Returns (C, ∂C/∂L, ∂C/∂M).
    """
    l1, l2 = line[..., 0], line[..., 1]
    m1, m2 = other[..., 0], other[..., 1]
    ss = np.asarray(s, dtype=np.float64)
    nl = np.sqrt(l1 * l1 + l2 * l2)
    nm = np.sqrt(m1 * m1 + m2 * m2)
    c = l1 * m2 - l2 * m1 - ss * nl * nm
    dl = np.zeros_like(line)
    dm = np.zeros_like(other)
    dl[..., 0] = m2 - ss * nm * l1 / nl
    dl[..., 1] = -m1 - ss * nm * l2 / nl
    dm[..., 0] = -l2 - ss * nl * m1 / nm
    dm[..., 1] = l1 - ss * nl * m2 / nm
    return c, dl, dm


def norm(line: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Prismatic normalisation, Eq. 8: ‖L_v‖² − 1 = 0 fixes the homogeneous scale of a line
    or plane (the offset L_4 is not part of it). Returns (C, ∂C/∂L) (Eq. 40)."""
    lv = line[..., :-1]
    c = _dot(lv, lv) - 1.0
    dl = np.zeros_like(line)
    dl[..., :-1] = 2.0 * lv
    return c, dl


def sphere(a: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit sphere, Eq. 9: |a_v/a_w|² − 1 = 0 for a spherical revolute joint.

    Returns (C, ∂C/∂a); with a_w = 1 the derivative is 2a_v (Eq. 41).
    """
    av, aw = a[..., :-1], a[..., -1]
    aa = _dot(av, av)
    c = aa / aw**2 - 1.0
    da = np.empty_like(a)
    da[..., :-1] = 2.0 * av / (aw**2)[..., None]
    da[..., -1] = -2.0 * aa / aw**3
    return c, da


@dataclass(frozen=True)
class Constraint:
    """One scalar equation of the mechanism.

    `prims` are primitive (joint) indices: (i, j) for RR/ACT (points), (point, line) for RP,
    (line, line) for PP/PPsin, (i,) for NORM/SPHERE. `value` is the metric kept constant: the
    distance r, the offset d, the cosine k or sine s, and for ACT the initial actuator length.
    `link` names the link (or joint) the equation comes from. `scale` turns the equation's units
    into a residual relative to the mechanism size (see `row_scale`).
    """

    kind: ConstraintKind
    prims: tuple[int, ...]
    value: float
    link: str
    scale: float

    @property
    def equation(self) -> str:
        """The paper's equation number(s) this row implements."""
        return EQUATIONS[self.kind]


def row_scale(kind: str, value: float, size: float) -> float:
    """Factor that makes a residual dimensionless and relative to the mechanism size.

    RR/ACT: C ≈ 2r·δ for a length error δ, so 1/(2 r size); RP: C is a length when ‖L_v‖ = 1,
    so 1/size; PP: already an angle-like number; NORM/SPHERE: C ≈ 2δ, so 1/2.
    """
    if kind in ("RR", "ACT"):
        return 1.0 / (2.0 * max(abs(value), 1e-300) * size)
    if kind == "RP":
        return 1.0 / size
    if kind in ("NORM", "SPHERE"):
        return 0.5
    return 1.0


def homogeneous(coords: FloatArray, is_line: NDArray[np.bool_], planar: bool) -> FloatArray:
    """Stored coordinates (..., n, 3) → homogeneous ones the equations take.

    Planar coordinates are stored homogeneous already ((x, y, 1) and (L1, L2, L4)); spherical
    and spatial points get w = 1 and planes through the centre get L4 = 0.
    """
    if planar:
        return coords
    out = np.empty((*coords.shape[:-1], 4))
    out[..., :3] = coords
    out[..., 3] = np.where(is_line, 0.0, 1.0)
    return out


#: Blocks of `exact_residuals`, in evaluation order. An actuator row is Eq. 1 with a driven
#: length, so the ACT rows join the RR block and one evaluation covers every distance row.
_BLOCK_ORDER = ("RR", "RP", "PP", "PPsin", "NORM", "SPHERE")


@dataclass(frozen=True, eq=False)
class _Block:
    """Rows of one block of `exact_residuals`: their primitives, metrics and place.

    `rows` are the block's rows of the constraint tuple, `run` the same as a slice when they
    are consecutive (the values are then written in place, without a scatter); `ends` is how
    many primitives a row reads (2, or 1 for NORM/SPHERE). The RR block holds the RR rows in
    row order followed by the `n_act` ACT rows (in row order, the order of act_lengths); `sq`
    is the squared metric r² per row (ACT rows: their initial length). Columns are (k, 1) so
    they broadcast along the state axis of the (k, S) arrays the block is evaluated on.
    """

    kind: str
    ends: int
    first: IndexArray
    second: IndexArray
    rows: IndexArray
    run: slice | None
    k: int
    value: FloatArray
    sq: FloatArray
    scale: FloatArray
    n_act: int


@dataclass(frozen=True, eq=False)
class RowGroups:
    """Rows of one constraint tuple grouped into blocks for vectorised exact evaluation:
    `blocks` and `take` are the plan of `exact_residuals`, built once per mechanism so that a
    call does no index work."""

    scale: FloatArray
    m: int
    blocks: tuple[_Block, ...] = ()
    _take: dict[tuple[bool, int], IndexArray] = field(default_factory=dict, repr=False)

    def take(self, planar: bool, n: int) -> IndexArray:
        """Rows of the (W·n, S) table of n joints (`_joint_table`) that `exact_residuals`
        gathers: block by block, primitive end by end, slot by slot, the rows of the block
        (each run of k rows becomes one contiguous (k, S) array). Cached per (planar, n)."""
        key = (planar, n)
        if key not in self._take:
            width = _table_width(planar)[1]
            parts = [slot * n + prim for b in self.blocks
                     for prim in (b.first, b.second)[: b.ends] for slot in range(width)]
            self._take[key] = (np.concatenate(parts) if parts
                               else np.zeros(0, dtype=np.intp))
        return self._take[key]


def _table_width(planar: bool) -> tuple[int, int]:
    """(D, W): vector components of a primitive and slots per joint of `_joint_table`."""
    return (2, 4) if planar else (3, 5)


def group_rows(constraints: tuple[Constraint, ...]) -> RowGroups:
    """The blocks `exact_residuals` evaluates the rows in: index arrays (rows, first
    primitive, second primitive) and metrics per kind."""
    kinds = [c.kind for c in constraints]
    scale = np.array([c.scale for c in constraints], dtype=np.float64)
    blocks: list[_Block] = []
    for name in _BLOCK_ORDER:
        rows_b = [r for r, k in enumerate(kinds) if k == name]
        act = [r for r, k in enumerate(kinds) if k == "ACT"] if name == "RR" else []
        rows_b += act
        if not rows_b:
            continue
        ix = np.array(rows_b, dtype=np.intp)
        first = np.array([constraints[r].prims[0] for r in rows_b], dtype=np.intp)
        second = np.array([constraints[r].prims[-1] for r in rows_b], dtype=np.intp)
        val = np.array([constraints[r].value for r in rows_b], dtype=np.float64)[:, None]
        ends = 1 if name in ("NORM", "SPHERE") else 2
        run = (slice(rows_b[0], rows_b[-1] + 1)
               if rows_b == list(range(rows_b[0], rows_b[-1] + 1)) else None)
        blocks.append(_Block(name, ends, first, second, ix, run, ix.size, val,
                             np.square(val), scale[ix][:, None], len(act)))
    return RowGroups(scale, len(constraints), tuple(blocks))


def _joint_table(xs: FloatArray, is_line: NDArray[np.bool_], planar: bool) -> FloatArray:
    """Per-joint table (W·n, S), component-major with the state axis last, from stored
    coordinates (S, n, 3).

    Slot by slot, n rows each: the D vector components (x, y[, z] or L1, L2[, L3]), the
    homogenising factor w (the stored third coordinate in the plane, L4 for a line; 1 for a
    point and 0 for a plane through the centre on the sphere and in space, as `homogeneous`)
    and the squared vector norm |v|² (summed component by component, as `_dot`). Row
    slot·n + j is joint j's. With the state axis last a gathered run of rows is a contiguous
    (k, S) array, on which the equations' arithmetic runs several times faster than on the
    strided (S, k, 4) views of the joint-last layout; |v|², which every kind needs, is
    computed once per joint instead of once per row end.
    """
    d, w = _table_width(planar)
    s, n = xs.shape[0], xs.shape[1]
    tab = np.empty((w, n, s))
    tab[:3] = xs.transpose(2, 1, 0)
    if not planar:
        tab[3] = (~is_line)[:, None]
    np.add.reduce(np.square(tab[:d]), axis=0, out=tab[w - 1])
    return tab.reshape(w * n, s)


def _block_values(b: _Block, blk: FloatArray, d: int, lengths: FloatArray | None
                  ) -> FloatArray:
    """Unscaled residuals (k, S) of one block from its gathered table rows (ends, W, k, S).

    lengths: the actuator lengths (S, n_act) of the ACT rows, or None for their initial ones.
    The formulas and their order of operations are those of `rr_value`, `rp_value`, `pp`,
    `pp_sin`, `norm` and `sphere` (so the values agree to the last bit); only the layout differs.
    """
    a = blk[0]
    if b.kind == "NORM":
        return np.asarray(a[d + 1] - 1.0, dtype=np.float64)
    if b.kind == "SPHERE":
        return np.asarray(a[d + 1] / np.square(a[d]) - 1.0, dtype=np.float64)
    o = blk[1]
    if b.kind == "PPsin":
        nl = np.sqrt(a[0] * a[0] + a[1] * a[1])
        nm = np.sqrt(o[0] * o[0] + o[1] * o[1])
        c: FloatArray = a[0] * o[1]
        c -= a[1] * o[0]
        nl *= b.value
        nl *= nm
        c -= nl
        return c
    c = np.add.reduce(a[:d] * o[:d], axis=0)
    if b.kind == "PP":
        t = b.value * np.sqrt(a[d + 1])
        t *= np.sqrt(o[d + 1])
        c -= t
        return c
    aw, ow = a[d], o[d]
    if b.kind == "RP":
        c += aw * ow
        t = b.value * aw
        t *= np.sqrt(o[d + 1])
        c -= t
        return c
    # RR and ACT: 2 a·b + (a_w r² − |a|²/a_w) b_w − a_w |b|²/b_w.
    sq = b.sq
    if b.n_act and lengths is not None:
        s = a.shape[-1]
        sq = np.empty((b.k, s))
        sq[:] = b.sq
        np.square(np.asarray(lengths, dtype=np.float64).reshape(s, -1).T,
                  out=sq[b.k - b.n_act:])
    c *= 2.0
    t = aw * sq
    t -= a[d + 1] / aw
    t *= ow
    c += t
    t = aw * o[d + 1]
    t /= ow
    c -= t
    return c


def exact_residuals(coords: FloatArray, is_line: NDArray[np.bool_], planar: bool,
                    constraints: tuple[Constraint, ...] | RowGroups,
                    act_lengths: FloatArray | None = None) -> FloatArray:
    """Scaled residuals of the exact equations for a batch of states.

    coords is (S, n, 3) (or (n, 3)); act_lengths is (S, n_act) (actuator lengths in the order
    the ACT rows appear). Returns (S, m) (or (m,)). Used to verify and report every solved
    state independently of the solver's own arithmetic, once per sweep on all its rows.

    Evaluated component-major: one gather from the per-joint table (`_joint_table`) gives each
    block (RR with the ACT rows, RP, PP, PPsin, NORM, SPHERE) its coordinates as contiguous
    (k, S) arrays, the block's formula runs on those, and the scaled values go to the block's
    columns of the result. The values are those of the per-row functions (`rr_value`,
    `rp_value`, `pp`, `pp_sin`, `norm`, `sphere`) on `homogeneous` coordinates, operation for
    operation; about 2–3× faster than calling them per kind on (S, k, 4) gathers.
    """
    grp = constraints if isinstance(constraints, RowGroups) else group_rows(constraints)
    single = coords.ndim == 2
    xs = coords[None] if single else coords
    s, n = xs.shape[0], xs.shape[1]
    d, w = _table_width(planar)
    rows = _joint_table(xs, is_line, planar)[grp.take(planar, n)]
    out = np.empty((s, grp.m))
    res = out.T
    off = 0
    for b in grp.blocks:
        n_rows = b.ends * w * b.k
        blk = rows[off: off + n_rows].reshape(b.ends, w, b.k, s)
        off += n_rows
        c = _block_values(b, blk, d, act_lengths)
        if b.run is not None:
            np.multiply(c, b.scale, out=res[b.run])
        else:
            res[b.rows] = c * b.scale
    return out[0] if single else out
