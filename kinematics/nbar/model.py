"""Mechanism model: joints as points, lines and planes; links as rigid sets of joints; inputs.

`build_mechanism(spec)` turns the parsed mechanism file (a dict; format in docs/mechanisms.md)
into a `Mechanism`: coordinates cleaned up (lines and planes normalised, Eq. 8; spherical joints
projected onto the unit sphere, Eq. 9), every link reduced to independent binary rigidity
constraints whose metrics come from the initial configuration (Algorithm 1, line 1), explicit
link lengths assembled, and the constraint rows compiled for the Newton loop. No file I/O.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from kinematics.nbar import constraints as cst
from kinematics.nbar.constraints import Constraint, ConstraintKind, FloatArray
from kinematics.nbar.perturb import InputBasis, Motion, MotionKind, build_basis
from kinematics.nbar.system import QuadraticSystem, build_system, newton

Kind = Literal["planar", "spherical", "spatial"]
JointType = Literal["revolute", "prismatic", "point", "spherical"]
InputKind = Literal["revolute", "prismatic", "actuator"]

#: Largest radial correction accepted when projecting a spherical joint onto the unit sphere.
MAX_SPHERE_CORRECTION = 0.05
#: Smallest acceptable independence (σ_min of the unit constraint gradients on the joint's own
#: degrees of freedom) of the binary constraints chosen to hold a joint in its link.
MIN_INDEPENDENCE = 1e-3


class MechanismError(ValueError):
    """A mechanism description that cannot be simulated; the message names the culprit."""


@dataclass(frozen=True)
class Joint:
    """A joint: a point (revolute, tracer point, spherical joint) or a line / plane (prismatic)."""

    name: str
    type: JointType

    @property
    def is_line(self) -> bool:
        """True for prismatic joints (a line in the plane, a plane through the centre)."""
        return self.type == "prismatic"


@dataclass(frozen=True)
class Link:
    """A rigid link: the joints it carries, and optionally an explicit length (binary RR)."""

    name: str
    joints: tuple[str, ...]
    length: float | None = None


@dataclass(frozen=True)
class Input:
    """An actuated input: a link driven at one of its fixed joints, or a linear actuator.

    `value0` is the input value of the initial configuration: for a planar revolute input the
    absolute angle (rad, from +x, counter-clockwise) of the link's first moving point about the
    pivot; 0 for spherical rotations and prismatic inputs (displacement from the start); the
    initial distance for an actuator. `step` is the default increment per simulation step.
    """

    name: str
    kind: InputKind
    link: str | None
    joint: str | None
    between: tuple[str, str] | None
    value0: float
    step: float
    unit: str


@dataclass(frozen=True)
class Settings:
    """Simulation defaults from the file's [simulation] table."""

    steps: int = 180
    tolerance: float = 1e-10
    max_iterations: int = 6
    max_halvings: int = 24
    reverse_at_limit: bool = False


@dataclass(frozen=True, eq=False)
class Mechanism:
    """A mechanism ready to simulate.

    coords0 (n, 3) holds the initial coordinates per joint in the stored form: planar points
    (x, y, 1), planar lines (a, b, c) with a² + b² = 1, spherical points (x, y, z) on the unit
    sphere, spherical planes (a, b, c) unit normals, spatial points (x, y, z).
    """

    name: str
    kind: Kind
    source: str
    units: str
    joints: tuple[Joint, ...]
    coords0: FloatArray
    fixed: NDArray[np.bool_]
    driven: NDArray[np.bool_]
    links: tuple[Link, ...]
    ground: str
    inputs: tuple[Input, ...]
    tracers: tuple[str, ...]
    constraints: tuple[Constraint, ...]
    size: float
    settings: Settings
    adjustments: tuple[str, ...]
    system: QuadraticSystem
    basis: InputBasis

    @property
    def planar(self) -> bool:
        """True for planar mechanisms."""
        return self.kind == "planar"

    @property
    def dim(self) -> int:
        """Number of affine coordinates of a point: 2 or 3."""
        return 2 if self.planar else 3

    @property
    def is_line(self) -> NDArray[np.bool_]:
        """(n,) mask of prismatic joints (lines / planes)."""
        return np.array([j.is_line for j in self.joints], dtype=bool)

    @property
    def names(self) -> tuple[str, ...]:
        """Joint names in storage order."""
        return tuple(j.name for j in self.joints)

    @property
    def input0(self) -> FloatArray:
        """Input values (n_inputs,) of the initial configuration."""
        return np.array([i.value0 for i in self.inputs], dtype=np.float64)

    @property
    def step(self) -> FloatArray:
        """Default input increments (n_inputs,) per simulation step."""
        return np.array([i.step for i in self.inputs], dtype=np.float64)

    @property
    def q0(self) -> FloatArray:
        """Initial values of the unknown coordinates (the Newton state vector)."""
        return np.asarray(self.coords0.ravel()[self.system.unknown_flat], dtype=np.float64)

    @property
    def overdetermined(self) -> bool:
        """True when there are more equations than unknowns (least-squares steps)."""
        return self.system.m > self.system.n_u

    def index(self, name: str) -> int:
        """Storage index of the joint called `name`."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r} in {self.name!r}") from None

    def coords_batch(self, q: FloatArray, u: FloatArray) -> FloatArray:
        """Full coordinates (S, n, 3) from unknowns q (S, n_u) and input values u (S, n_in)."""
        qq = np.atleast_2d(q)
        uu = np.atleast_2d(u)
        out = np.broadcast_to(self.coords0.ravel(), (qq.shape[0], self.coords0.size)).copy()
        out[:, self.system.unknown_flat] = qq
        if self.system.n_d:
            out[:, self.system.driven_flat] = self.basis.driven_batch(uu)
        return out.reshape(qq.shape[0], *self.coords0.shape)

    def actuator_lengths(self, u: FloatArray) -> FloatArray:
        """Actuator lengths (S, n_act) for input values u (S, n_in), in ACT-row order."""
        uu = np.atleast_2d(u)
        return np.asarray(uu[:, self._actuator_cols], dtype=np.float64)

    @cached_property
    def _actuator_cols(self) -> NDArray[np.intp]:
        """Input columns of the actuators (found once: `residuals` runs once per sweep)."""
        return np.array([j for j, i in enumerate(self.inputs) if i.kind == "actuator"],
                        dtype=np.intp)

    @cached_property
    def _groups(self) -> cst.RowGroups:
        return cst.group_rows(self.constraints)

    @cached_property
    def _is_line(self) -> NDArray[np.bool_]:
        return self.is_line

    def residuals(self, coords: FloatArray, u: FloatArray) -> FloatArray:
        """Scaled residuals (S, m) of the paper's exact equations at full coordinates."""
        lengths = self.actuator_lengths(u) if self._actuator_cols.size else None
        return cst.exact_residuals(coords, self._is_line, self.planar, self._groups, lengths)

    def positions(self, coords: FloatArray, name: str) -> FloatArray:
        """Affine position(s) (..., dim) of point joint `name`, or the stored line/plane."""
        i = self.index(name)
        if self.joints[i].is_line:
            return np.asarray(coords[..., i, :], dtype=np.float64)
        return np.asarray(coords[..., i, : self.dim], dtype=np.float64)


# ----------------------------------------------------------------------------- parsing helpers
def _table(spec: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any]:
    v = spec.get(key)
    if not isinstance(v, Mapping):
        raise MechanismError(f"{where}: missing table [{key}]")
    return v


def _check_keys(tbl: Mapping[str, Any], allowed: set[str], where: str) -> None:
    extra = sorted(set(tbl) - allowed)
    if extra:
        raise MechanismError(f"{where}: unknown key(s) {', '.join(extra)}; "
                             f"allowed: {', '.join(sorted(allowed))}")


def _numbers(v: Any, n: int, where: str) -> list[float]:
    if (not isinstance(v, Sequence) or isinstance(v, str) or len(v) != n
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)):
        raise MechanismError(f"{where}: expected a list of {n} numbers, got {v!r}")
    out = [float(x) for x in v]
    if not all(math.isfinite(x) for x in out):
        raise MechanismError(f"{where}: coordinates must be finite, got {v!r}")
    return out


def _number(v: Any, where: str, positive: bool = False) -> float:
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        raise MechanismError(f"{where}: expected a finite number, got {v!r}")
    if positive and v <= 0:
        raise MechanismError(f"{where}: must be positive, got {v!r}")
    return float(v)


def parse_mechanism(text: str) -> Mechanism:
    """Build a mechanism from the text of a mechanism file (TOML)."""
    try:
        spec = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise MechanismError(f"not valid TOML: {e}") from None
    return build_mechanism(spec)


# ----------------------------------------------------------------------------- link reduction
@dataclass(frozen=True)
class _Row:
    kind: ConstraintKind
    prims: tuple[int, int]
    value: float
    grad_first: FloatArray
    grad_second: FloatArray


def _pair_row(i: int, j: int, h: FloatArray, is_line: NDArray[np.bool_], planar: bool) -> _Row:
    """The binary rigidity constraint between primitives i and j, with its metric measured in
    the initial configuration (Algorithm 1, line 1) and the gradients there."""
    li, lj = bool(is_line[i]), bool(is_line[j])
    if not li and not lj:
        r = float(np.linalg.norm(h[i, :-1] / h[i, -1] - h[j, :-1] / h[j, -1]))
        _, ga, gb = cst.rr(h[i], h[j], r)
        return _Row("RR", (i, j), r, ga, gb)
    if li and lj:
        lv, mv = h[i, :-1], h[j, :-1]
        den = float(np.linalg.norm(lv) * np.linalg.norm(mv))
        k = float(lv @ mv) / den
        if planar:
            s = float(lv[0] * mv[1] - lv[1] * mv[0]) / den
            if abs(k) > abs(s):
                _, ga, gb = cst.pp_sin(h[i], h[j], s)
                return _Row("PPsin", (i, j), s, ga, gb)
        _, ga, gb = cst.pp(h[i], h[j], k)
        return _Row("PP", (i, j), k, ga, gb)
    p, ln = (j, i) if li else (i, j)
    a, line = h[p], h[ln]
    d = float(a[:-1] @ line[:-1] + a[-1] * line[-1]) / (a[-1] * float(np.linalg.norm(line[:-1])))
    _, ga, gl = cst.rp(a, line, d)
    return _Row("RP", (p, ln), d, ga, gl)


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


def _independence(rows: Sequence[_Row], i: int, tb: FloatArray) -> float:
    """σ_min of the chosen rows' unit gradients projected on primitive i's own motions."""
    g = np.array([(r.grad_first if r.prims[0] == i else r.grad_second) @ tb for r in rows])
    nrm = np.linalg.norm(g, axis=1)
    if np.any(nrm < 1e-12):
        return 0.0
    return float(np.linalg.svd(g / nrm[:, None], compute_uv=False)[-1])


def reduce_link(link: Link, members: Sequence[int], h: FloatArray, is_line: NDArray[np.bool_],
                kind: Kind, names: Sequence[str]) -> list[_Row]:
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
    rows: list[_Row] = []
    if len(members) < 2:
        return rows
    if kind == "spatial" and len(pts) >= 3:
        def area(t: Sequence[int]) -> float:
            a, b, c = (h[k, :3] for k in t)
            return float(np.linalg.norm(np.cross(b - a, c - a)))
        triples: list[Sequence[int]] = list(itertools.combinations(pts, 3))
        base = list(triples[int(np.argmax([area(t) for t in triples]))])
        if area(base) < 1e-6 * _spread(h, pts) ** 2:
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
        if r.kind == "RR" and r.value < 1e-9 * max(_spread(h, pts), 1e-300):
            a, b = r.prims
            raise MechanismError(f"link {link.name}: joints {names[a]} and {names[b]} coincide")
    return rows


def _spread(h: FloatArray, pts: Sequence[int]) -> float:
    """Largest distance of the given points from their centroid (1 if there are none)."""
    if not pts:
        return 1.0
    p = h[list(pts), :-1] / h[list(pts), -1:]
    return float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1))) or 1.0


# ----------------------------------------------------------------------------- building
def _parse_joints(spec: Mapping[str, Any], kind: Kind
                  ) -> tuple[list[Joint], list[list[float]], list[str]]:
    joints_tbl = _table(spec, "joints", "mechanism")
    joints: list[Joint] = []
    raw: list[list[float]] = []
    notes: list[str] = []
    dim = 2 if kind == "planar" else 3
    allowed_types = ("spherical", "point") if kind == "spatial" else (
        "revolute", "prismatic", "point")
    for name, tbl in joints_tbl.items():
        where = f"[joints] {name}"
        if not isinstance(tbl, Mapping):
            raise MechanismError(f"{where}: expected an inline table like "
                                 "{ type = \"revolute\", at = [x, y] }")
        jtype = tbl.get("type", "point")
        if jtype not in allowed_types:
            raise MechanismError(f"{where}: type must be one of {', '.join(allowed_types)} "
                                 f"for a {kind} mechanism, got {jtype!r}")
        if jtype == "prismatic":
            key = "line" if kind == "planar" else "plane"
            _check_keys(tbl, {"type", key}, where)
            if key not in tbl:
                raise MechanismError(f"{where}: a prismatic joint needs {key} = [a, b, c]")
            v = _numbers(tbl[key], 3, f"{where}.{key}")
            nv = math.hypot(v[0], v[1]) if kind == "planar" else math.hypot(*v)
            if nv < 1e-12:
                raise MechanismError(f"{where}.{key}: the normal (a, b{'' if dim == 2 else ', c'})"
                                     " must not be zero")
            raw.append([x / nv for x in v])
        else:
            _check_keys(tbl, {"type", "at"}, where)
            if "at" not in tbl:
                raise MechanismError(f"{where}: needs at = [{'x, y' if dim == 2 else 'x, y, z'}]")
            v = _numbers(tbl["at"], dim, f"{where}.at")
            if kind == "spherical":
                r = math.hypot(*v)
                if abs(r - 1.0) > MAX_SPHERE_CORRECTION:
                    raise MechanismError(
                        f"{where}.at: |J| = {r:.6g} is not on the unit sphere (more than "
                        f"{MAX_SPHERE_CORRECTION} off; rounding cannot explain that)")
                if abs(r - 1.0) > 1e-15:
                    notes.append(f"{name}: projected onto the unit sphere (|J| was {r:.6g})")
                v = [x / r for x in v]
            raw.append([*v, 1.0] if kind == "planar" else v)
        joints.append(Joint(str(name), cast(JointType, jtype)))
    if not joints:
        raise MechanismError("[joints] is empty")
    return joints, raw, notes


def _parse_links(spec: Mapping[str, Any], names: Sequence[str]) -> list[Link]:
    links: list[Link] = []
    for name, v in _table(spec, "links", "mechanism").items():
        where = f"[links] {name}"
        length: float | None = None
        if isinstance(v, Mapping):
            _check_keys(v, {"joints", "length"}, where)
            members = v.get("joints")
            if "length" in v:
                length = _number(v["length"], f"{where}.length", positive=True)
        else:
            members = v
        if (not isinstance(members, Sequence) or isinstance(members, str)
                or not all(isinstance(x, str) for x in members)):
            raise MechanismError(f"{where}: expected a list of joint names")
        for j in members:
            if j not in names:
                raise MechanismError(f"{where}: unknown joint {j!r}")
        dup = sorted({j for j in members if members.count(j) > 1})
        if dup:
            raise MechanismError(f"{where}: joint(s) {', '.join(dup)} listed twice")
        if length is not None and len(members) != 2:
            raise MechanismError(f"{where}: length is only meaningful for a binary link")
        links.append(Link(str(name), tuple(members), length))
    return links


def build_mechanism(spec: Mapping[str, Any]) -> Mechanism:
    """Build a `Mechanism` from a parsed mechanism file (see docs/mechanisms.md)."""
    _check_keys(spec, {"mechanism", "joints", "links", "inputs", "simulation"}, "file")
    head = _table(spec, "mechanism", "file")
    _check_keys(head, {"name", "kind", "source", "units", "ground", "tracers"}, "[mechanism]")
    kind = head.get("kind")
    if kind not in ("planar", "spherical", "spatial"):
        raise MechanismError(f"[mechanism].kind must be planar, spherical or spatial, "
                             f"got {kind!r}")
    kind = cast(Kind, kind)
    planar = kind == "planar"
    joints, raw, notes = _parse_joints(spec, kind)
    names = [j.name for j in joints]
    n = len(joints)
    is_line = np.array([j.is_line for j in joints], dtype=bool)
    coords = np.array(raw, dtype=np.float64)
    h = cst.homogeneous(coords, is_line, planar)
    pts = [i for i in range(n) if not is_line[i]]
    size = 1.0 if kind == "spherical" else _spread(h, pts)

    links = _parse_links(spec, names)
    by_name = {lk.name: lk for lk in links}
    ground = head.get("ground")
    if ground not in by_name:
        raise MechanismError(f"[mechanism].ground must name a link, got {ground!r}")
    fixed = np.zeros(n, dtype=bool)
    fixed[[names.index(j) for j in by_name[ground].joints]] = True
    in_link = {j for lk in links for j in lk.joints}
    loose = [j for j in names if j not in in_link]
    if loose:
        raise MechanismError(f"joint(s) {', '.join(loose)} belong to no link")

    inputs, motions, axes, owner, n_f = _parse_inputs(spec, kind, names, by_name, fixed,
                                                      coords, is_line, ground)
    driven = owner >= 0
    input_links = {i.link for i in inputs if i.link is not None}
    known = fixed | driven

    rows: list[tuple[ConstraintKind, tuple[int, ...], float, str]] = []
    passive: list[tuple[_Row, str]] = []
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
    for i in range(n):
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
    cons = tuple(Constraint(k, p, v, where, cst.row_scale(k, v, size))
                 for k, p, v, where in rows)

    unknown_prim = ~known
    comp_mask = np.ones((n, 3), dtype=bool)
    if planar:
        comp_mask[~is_line, 2] = False
    unknown = comp_mask & unknown_prim[:, None]
    drv = comp_mask & driven[:, None]
    n_u = int(unknown.sum())
    if not cons and n_u:
        raise MechanismError("no link constrains the moving joints")
    tracers = _parse_tracers(head, joints, names)
    settings = _parse_settings(spec)
    basis = build_basis(coords, is_line, drv, owner, tuple(motions), tuple(axes), n_f)
    system = build_system(coords, is_line, planar, cons, unknown, drv)
    mech = Mechanism(str(head.get("name", "mechanism")), kind, str(head.get("source", "")),
                     str(head.get("units", "")), tuple(joints), coords, fixed, driven,
                     tuple(links), str(ground), tuple(inputs), tracers, cons, size, settings,
                     tuple(notes), system, basis)
    _check_counts(mech, names)
    _check_passive(mech, passive, names)
    return _assemble(mech)


def _parse_tracers(head: Mapping[str, Any], joints: Sequence[Joint], names: Sequence[str]
                   ) -> tuple[str, ...]:
    tr = head.get("tracers")
    if tr is None:
        pts = [j.name for j in joints if j.type == "point"]
        return tuple(pts) if pts else (names[-1],)
    if (not isinstance(tr, Sequence) or isinstance(tr, str)
            or not all(isinstance(t, str) and t in names for t in tr)):
        raise MechanismError(f"[mechanism].tracers must list joint names, got {tr!r}")
    return tuple(tr)


def _parse_settings(spec: Mapping[str, Any]) -> Settings:
    tbl = spec.get("simulation", {})
    if not isinstance(tbl, Mapping):
        raise MechanismError("[simulation] must be a table")
    _check_keys(tbl, {"steps", "tolerance", "max_iterations", "max_halvings",
                      "reverse_at_limit"}, "[simulation]")
    s = Settings()
    steps = tbl.get("steps", s.steps)
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
        raise MechanismError(f"[simulation].steps must be a positive integer, got {steps!r}")
    tol = _number(tbl.get("tolerance", s.tolerance), "[simulation].tolerance", positive=True)
    mi = tbl.get("max_iterations", s.max_iterations)
    mh = tbl.get("max_halvings", s.max_halvings)
    for key, v in (("max_iterations", mi), ("max_halvings", mh)):
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            raise MechanismError(f"[simulation].{key} must be a positive integer, got {v!r}")
    rev = tbl.get("reverse_at_limit", s.reverse_at_limit)
    if not isinstance(rev, bool):
        raise MechanismError(f"[simulation].reverse_at_limit must be true or false, got {rev!r}")
    return Settings(steps, tol, mi, mh, rev)


def _parse_inputs(spec: Mapping[str, Any], kind: Kind, names: Sequence[str],
                  links: Mapping[str, Link], fixed: NDArray[np.bool_], coords: FloatArray,
                  is_line: NDArray[np.bool_], ground: str
                  ) -> tuple[list[Input], list[Motion], list[FloatArray], NDArray[np.intp], int]:
    """Inputs and the rigid motion each applies (Eqs. 10–22), with the joints it drives."""
    tbls = spec.get("inputs")
    if not isinstance(tbls, Sequence) or isinstance(tbls, str) or not tbls:
        raise MechanismError("[[inputs]]: at least one input is required")
    owner = np.full(len(names), -1, dtype=np.intp)
    inputs: list[Input] = []
    motions: list[Motion] = []
    axes: list[FloatArray] = []
    n_f = 0
    n_act = 0
    for k, tbl in enumerate(tbls):
        where = f"[[inputs]] #{k + 1}"
        if not isinstance(tbl, Mapping):
            raise MechanismError(f"{where}: expected a table")
        if "actuator" in tbl:
            _check_keys(tbl, {"actuator", "step", "name"}, where)
            pair = tbl["actuator"]
            if (not isinstance(pair, Sequence) or isinstance(pair, str) or len(pair) != 2
                    or not all(p in names for p in pair) or pair[0] == pair[1]):
                raise MechanismError(f"{where}: actuator must name two different joints")
            a, b = (names.index(p) for p in pair)
            if is_line[a] or is_line[b]:
                raise MechanismError(f"{where}: an actuator joins two points")
            if "step" not in tbl:
                raise MechanismError(f"{where}: an actuator needs an explicit step (a length)")
            step = _number(tbl["step"], f"{where}.step")
            length = float(np.linalg.norm(coords[a, :2 if kind == "planar" else 3]
                                          - coords[b, :2 if kind == "planar" else 3]))
            name = str(tbl.get("name", f"{pair[0]}–{pair[1]}"))
            inputs.append(Input(name, "actuator", None, None, (str(pair[0]), str(pair[1])),
                                length, step, "length"))
            motions.append(Motion("actuator", length, n_act))
            axes.append(np.zeros(3))
            n_act += 1
            continue
        _check_keys(tbl, {"link", "joint", "step", "name", "initial"}, where)
        lname, jname = tbl.get("link"), tbl.get("joint")
        if not isinstance(lname, str) or lname not in links or lname == ground:
            raise MechanismError(f"{where}: link must name a moving link, got {lname!r}")
        lk = links[lname]
        if jname not in lk.joints:
            raise MechanismError(f"{where}: joint {jname!r} is not on link {lname}")
        j = names.index(jname)
        if not fixed[j]:
            raise MechanismError(f"{where}: the actuated joint {jname} must be fixed (on the "
                                 f"ground link {ground}); the paper actuates at fixed joints")
        if kind == "spatial":
            raise MechanismError(f"{where}: spatial mechanisms are driven by an actuator "
                                 "between two joints (actuator = [\"A\", \"B\"])")
        moving = [names.index(x) for x in lk.joints if not fixed[names.index(x)]]
        if not moving:
            raise MechanismError(f"{where}: link {lname} has no moving joint to drive")
        for i in moving:
            if owner[i] >= 0:
                raise MechanismError(f"{where}: joint {names[i]} is already driven by input "
                                     f"{inputs[int(owner[i])].name}")
            owner[i] = len(inputs)
        step_default = 2.0 * math.pi / 180.0
        step = _number(tbl.get("step", step_default), f"{where}.step")
        mkind: MotionKind
        ikind: InputKind = "prismatic" if is_line[j] else "revolute"
        value0 = 0.0
        if kind == "planar" and not is_line[j]:
            mkind, axis = "rotate-plane", coords[j, :2].copy()
            pts = [i for i in moving if not is_line[i]]
            if pts:
                d = coords[pts[0], :2] - axis
                value0 = math.atan2(d[1], d[0])
        elif kind == "planar":
            a, b = coords[j, 0], coords[j, 1]
            mkind, axis = "translate-plane", np.array([b, -a]) / math.hypot(a, b)
        else:
            mkind, axis = "rotate-sphere", coords[j] / np.linalg.norm(coords[j])
        if "initial" in tbl:
            v0 = _number(tbl["initial"], f"{where}.initial")
            if mkind == "rotate-plane" and value0 != 0.0:
                turns = (v0 - value0) / (2.0 * math.pi)
                if abs(turns - round(turns)) > 1e-9:
                    raise MechanismError(
                        f"{where}.initial = {v0!r} rad disagrees with the link's angle "
                        f"{value0!r} rad in the joint coordinates")
            value0 = v0
        name = str(tbl.get("name", f"{lname}@{jname}"))
        inputs.append(Input(name, ikind, str(lname), str(jname), None, value0, step,
                            "length" if mkind == "translate-plane" else "rad"))
        motions.append(Motion(mkind, value0, n_f))
        axes.append(axis)
        n_f += 1 if mkind == "translate-plane" else 2
    return inputs, motions, axes, owner, n_f


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


def _check_passive(mech: Mechanism, passive: Sequence[tuple[_Row, str]],
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
