"""Building a `Mechanism` from a parsed mechanism file.

`build_mechanism(spec)` turns the parsed file (a dict; format in docs/mechanisms.md, tables
parsed by `kinematics.nbar.spec`) into a `Mechanism`: every link reduced to independent binary
rigidity constraints whose metrics come from the initial configuration (Algorithm 1, line 1;
`kinematics.nbar.links`), explicit link lengths assembled, and the constraint rows compiled for
the Newton loop. Mechanisms that cannot be simulated (too few equations, a singular start,
links the inputs would tear, lengths that do not assemble) raise `MechanismError`. No file I/O.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray
from kinematics.nbar import constraints as cst
from kinematics.nbar.constraints import Constraint, ConstraintKind
from kinematics.nbar.links import Row, reduce_link, spread
from kinematics.nbar.model import Input, Kind, Link, Mechanism, MechanismError
from kinematics.nbar.perturb import build_basis
from kinematics.nbar.spec import (
    Frame,
    check_keys,
    parse_head,
    parse_inputs,
    parse_joints,
    parse_links,
    parse_settings,
    parse_tracers,
)
from kinematics.nbar.system import build_system, newton


def parse_mechanism(text: str) -> Mechanism:
    """Build a mechanism from the text of a mechanism file (TOML)."""
    try:
        spec = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise MechanismError(f"not valid TOML: {e}") from None
    return build_mechanism(spec)


def build_mechanism(spec: Mapping[str, Any]) -> Mechanism:
    """Build a `Mechanism` from a parsed mechanism file (see docs/mechanisms.md)."""
    check_keys(spec, {"mechanism", "joints", "links", "inputs", "simulation"}, "file")
    head, kind = parse_head(spec)
    planar = kind == "planar"
    joints, raw, notes = parse_joints(spec, kind)
    names = [j.name for j in joints]
    n = len(joints)
    is_line = np.array([j.is_line for j in joints], dtype=bool)
    coords = np.array(raw, dtype=np.float64)
    h = cst.homogeneous(coords, is_line, planar)
    size = 1.0 if kind == "spherical" else spread(h, [i for i in range(n) if not is_line[i]])

    links = parse_links(spec, names)
    by_name = {lk.name: lk for lk in links}
    ground, fixed = _ground(head, links, by_name, names)
    ins = parse_inputs(spec, Frame(kind, names, by_name, fixed, coords, is_line, ground))
    driven = ins.owner >= 0
    known = fixed | driven
    cons, passive = _constraints(links, ground, ins.inputs, h, is_line, kind, names, known,
                                 size)
    comp_mask = np.ones((n, 3), dtype=bool)
    if planar:
        comp_mask[~is_line, 2] = False
    unknown = comp_mask & ~known[:, None]
    drv = comp_mask & driven[:, None]
    if not cons and unknown.any():
        raise MechanismError("no link constrains the moving joints")
    basis = build_basis(coords, is_line, drv, ins.owner, tuple(ins.motions), tuple(ins.axes),
                        ins.n_f)
    system = build_system(coords, is_line, planar, cons, unknown, drv)
    mech = Mechanism(str(head.get("name", "mechanism")), kind, str(head.get("source", "")),
                     str(head.get("units", "")), tuple(joints), coords, fixed, driven,
                     tuple(links), ground, tuple(ins.inputs),
                     parse_tracers(head, joints, names), cons, size, parse_settings(spec),
                     tuple(notes), system, basis)
    _check_counts(mech, names)
    _check_passive(mech, passive, names)
    return _assemble(mech)


def _ground(head: Mapping[str, Any], links: Sequence[Link], by_name: Mapping[str, Link],
            names: Sequence[str]) -> tuple[str, NDArray[np.bool_]]:
    """(ground link, mask of its joints, which are fixed); every joint must be on a link."""
    ground = head.get("ground")
    if ground not in by_name:
        raise MechanismError(f"[mechanism].ground must name a link, got {ground!r}")
    fixed = np.zeros(len(names), dtype=bool)
    fixed[[names.index(j) for j in by_name[str(ground)].joints]] = True
    in_link = {j for lk in links for j in lk.joints}
    loose = [j for j in names if j not in in_link]
    if loose:
        raise MechanismError(f"joint(s) {', '.join(loose)} belong to no link")
    return str(ground), fixed


def _constraints(links: Sequence[Link], ground: str, inputs: Sequence[Input], h: FloatArray,
                 is_line: NDArray[np.bool_], kind: Kind, names: Sequence[str],
                 known: NDArray[np.bool_], size: float
                 ) -> tuple[tuple[Constraint, ...], list[tuple[Row, str]]]:
    """The constraint rows: every moving link's rigidity rows (explicit lengths replacing
    measured distances), the unit norm of moving lines / planes (Eq. 8) and spherical points
    (Eq. 9), and one ACT row per actuator; plus the rigidity rows whose joints are all fixed
    or driven (`passive`, checked by `_check_passive`, not solved for)."""
    rows: list[tuple[ConstraintKind, tuple[int, ...], float, str]] = []
    passive: list[tuple[Row, str]] = []
    input_links = {i.link for i in inputs if i.link is not None}
    for lk in links:
        if lk.name == ground or lk.name in input_links:
            continue
        members = [names.index(j) for j in lk.joints]
        for r in reduce_link(lk, members, h, is_line, kind, names):
            value = r.value
            if lk.length is not None and r.kind == "RR":
                value = lk.length
            if known[list(r.prims)].all():
                passive.append((r, lk.name))
            else:
                rows.append((r.kind, r.prims, value, lk.name))
    for i in range(len(names)):
        if known[i]:
            continue
        if is_line[i]:
            rows.append(("NORM", (i,), 1.0, names[i]))
        elif kind == "spherical":
            rows.append(("SPHERE", (i,), 1.0, names[i]))
    for inp in inputs:
        if inp.kind == "actuator" and inp.between is not None:
            a, b = (names.index(j) for j in inp.between)
            rows.append(("ACT", (a, b), inp.value0, inp.name))
    return (tuple(Constraint(k, p, v, where, cst.row_scale(k, v, size))
                  for k, p, v, where in rows), passive)


def _jacobian_at_start(mech: Mechanism) -> tuple[FloatArray, FloatArray]:
    """(G, Φ) of the compiled system at the initial configuration."""
    sys = mech.system
    x = sys.new_x()
    x[: sys.n_u] = mech.q0
    x[sys.n_u: sys.n_u + sys.n_d] = mech.basis.driven(mech.input0)
    x[sys.n_u + sys.n_d: -1] = mech.basis.actuators(mech.input0)
    return sys.evaluate(x)


def _check_counts(mech: Mechanism, names: Sequence[str]) -> None:
    """Fewer equations than unknowns, or a rank-deficient Jacobian, means the mechanism can
    move with its inputs held (or starts exactly at a singular pose): refuse it."""
    sys = mech.system
    if sys.n_u == 0:
        return
    if sys.m < sys.n_u:
        raise MechanismError(
            f"{sys.n_u} unknown coordinates but only {sys.m} equations: the mechanism keeps "
            f"{sys.n_u - sys.m} degree(s) of freedom with its inputs held; add an input or a "
            "link")
    g, _ = _jacobian_at_start(mech)
    sv = np.linalg.svd(g[:, : sys.n_u], compute_uv=False)
    if sv[-1] <= 1e-10 * sv[0]:
        col = np.abs(np.linalg.svd(g[:, : sys.n_u])[2][-1])
        flat = int(sys.unknown_flat[int(np.argmax(col))])
        raise MechanismError(
            f"the constraint Jacobian is singular at the initial configuration "
            f"(σmin/σmax = {sv[-1] / sv[0]:.2g}): joint {names[flat // 3]} can move with the "
            "inputs held, or the mechanism starts at a singular pose")


def _check_passive(mech: Mechanism, passive: Sequence[tuple[Row, str]],
                   names: Sequence[str]) -> None:
    """Rigidity rows whose joints are all fixed or driven are not solved for; make sure the
    inputs cannot violate them (a link joining joints that different inputs move)."""
    if not passive:
        return
    cons = tuple(Constraint(r.kind, r.prims, r.value, w, cst.row_scale(r.kind, r.value,
                                                                        mech.size))
                 for r, w in passive)
    for j in range(len(mech.inputs)):
        u = mech.input0.copy()
        u[j] += mech.inputs[j].step
        coords = mech.coords_batch(mech.q0[None], u[None])
        res = cst.exact_residuals(coords, mech.is_line, mech.planar, cons)
        bad = np.flatnonzero(np.abs(res[0]) > mech.settings.tolerance)
        if bad.size:
            r, w = passive[int(bad[0])]
            raise MechanismError(
                f"link {w}: joints {', '.join(names[p] for p in r.prims)} are all fixed or "
                f"driven, and input {mech.inputs[j].name} moves them apart: the mechanism "
                "cannot move")


def _assemble(mech: Mechanism) -> Mechanism:
    """Make the initial configuration satisfy every row exactly.

    Rows measured from the initial coordinates hold there by construction; explicit lengths in
    the file need not. Their configuration is then solved (Newton, inputs at their initial
    values) from the given coordinates and the largest joint move is recorded; a file whose
    lengths cannot be met raises MechanismError.
    """
    sys = mech.system
    coords = mech.coords_batch(mech.q0[None], mech.input0[None])
    res = mech.residuals(coords, mech.input0[None])
    if sys.n_u == 0 or float(np.max(np.abs(res))) <= mech.settings.tolerance:
        return mech
    x = sys.new_x()
    x[sys.n_u: sys.n_u + sys.n_d] = mech.basis.driven(mech.input0)
    x[sys.n_u + sys.n_d: -1] = mech.basis.actuators(mech.input0)
    out = newton(sys, x, mech.q0, mech.settings.tolerance, 100, monotone=False)
    if not out.converged:
        worst = int(np.argmax(np.abs(res[0])))
        raise MechanismError(
            f"the stated dimensions do not assemble: residual {out.residual:.3g} "
            f"after 100 Newton steps (worst initial row: {mech.constraints[worst].link}, "
            f"{mech.constraints[worst].kind})")
    new = mech.coords0.copy().ravel()
    new[sys.unknown_flat] = out.q
    new3 = new.reshape(mech.coords0.shape)
    move = float(np.max(np.abs(out.q - mech.q0)))
    rel = move / mech.size
    i = int(sys.unknown_flat[int(np.argmax(np.abs(out.q - mech.q0)))]) // 3
    note = (f"assembled to the stated lengths: joints moved by up to {move:.3g} "
            f"({rel:.2g} of the size; most: {mech.joints[i].name})")
    return replace(mech, coords0=new3, adjustments=(*mech.adjustments, note))
