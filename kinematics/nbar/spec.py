"""Parsing of a mechanism file's tables (TOML, format in docs/mechanisms.md) into model parts.

Each table is checked on its own, with messages that name the culprit: [mechanism]'s kind,
[joints] (coordinates; spherical joints projected onto the unit sphere, Eq. 9; line and plane
normals normalised, Eq. 8), [links], [[inputs]] (the rigid motion each applies, Eqs. 10–22, and
the joints it drives), [simulation] and the tracers. Building the `Mechanism` from the parts is
`kinematics.nbar.build`'s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple, cast

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray
from kinematics.nbar.model import (
    Input,
    InputKind,
    Joint,
    JointType,
    Kind,
    Link,
    MechanismError,
    Settings,
)
from kinematics.nbar.perturb import Motion, MotionKind

#: Largest radial correction accepted when projecting a spherical joint onto the unit sphere.
MAX_SPHERE_CORRECTION = 0.05


def table(spec: Mapping[str, Any], key: str, where: str) -> Mapping[str, Any]:
    v = spec.get(key)
    if not isinstance(v, Mapping):
        raise MechanismError(f"{where}: missing table [{key}]")
    return v


def check_keys(tbl: Mapping[str, Any], allowed: set[str], where: str) -> None:
    extra = sorted(set(tbl) - allowed)
    if extra:
        raise MechanismError(f"{where}: unknown key(s) {', '.join(extra)}; "
                             f"allowed: {', '.join(sorted(allowed))}")


def numbers(v: Any, n: int, where: str) -> list[float]:
    if (not isinstance(v, Sequence) or isinstance(v, str) or len(v) != n
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)):
        raise MechanismError(f"{where}: expected a list of {n} numbers, got {v!r}")
    out = [float(x) for x in v]
    if not all(math.isfinite(x) for x in out):
        raise MechanismError(f"{where}: coordinates must be finite, got {v!r}")
    return out


def number(v: Any, where: str, positive: bool = False) -> float:
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        raise MechanismError(f"{where}: expected a finite number, got {v!r}")
    if positive and v <= 0:
        raise MechanismError(f"{where}: must be positive, got {v!r}")
    return float(v)


def parse_head(spec: Mapping[str, Any]) -> tuple[Mapping[str, Any], Kind]:
    """The [mechanism] table and its kind (planar, spherical or spatial)."""
    head = table(spec, "mechanism", "file")
    check_keys(head, {"name", "kind", "source", "units", "ground", "tracers"}, "[mechanism]")
    kind = head.get("kind")
    if kind not in ("planar", "spherical", "spatial"):
        raise MechanismError(f"[mechanism].kind must be planar, spherical or spatial, "
                             f"got {kind!r}")
    return head, cast(Kind, kind)


def parse_joints(spec: Mapping[str, Any], kind: Kind
                  ) -> tuple[list[Joint], list[list[float]], list[str]]:
    joints_tbl = table(spec, "joints", "mechanism")
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
            check_keys(tbl, {"type", key}, where)
            if key not in tbl:
                raise MechanismError(f"{where}: a prismatic joint needs {key} = [a, b, c]")
            v = numbers(tbl[key], 3, f"{where}.{key}")
            nv = math.hypot(v[0], v[1]) if kind == "planar" else math.hypot(*v)
            if nv < 1e-12:
                raise MechanismError(f"{where}.{key}: the normal (a, b{'' if dim == 2 else ', c'})"
                                     " must not be zero")
            raw.append([x / nv for x in v])
        else:
            check_keys(tbl, {"type", "at"}, where)
            if "at" not in tbl:
                raise MechanismError(f"{where}: needs at = [{'x, y' if dim == 2 else 'x, y, z'}]")
            v = numbers(tbl["at"], dim, f"{where}.at")
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


def parse_links(spec: Mapping[str, Any], names: Sequence[str]) -> list[Link]:
    links: list[Link] = []
    for name, v in table(spec, "links", "mechanism").items():
        where = f"[links] {name}"
        length: float | None = None
        if isinstance(v, Mapping):
            check_keys(v, {"joints", "length"}, where)
            members = v.get("joints")
            if "length" in v:
                length = number(v["length"], f"{where}.length", positive=True)
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


def parse_tracers(head: Mapping[str, Any], joints: Sequence[Joint], names: Sequence[str]
                   ) -> tuple[str, ...]:
    tr = head.get("tracers")
    if tr is None:
        pts = [j.name for j in joints if j.type == "point"]
        return tuple(pts) if pts else (names[-1],)
    if (not isinstance(tr, Sequence) or isinstance(tr, str)
            or not all(isinstance(t, str) and t in names for t in tr)):
        raise MechanismError(f"[mechanism].tracers must list joint names, got {tr!r}")
    return tuple(tr)


def parse_settings(spec: Mapping[str, Any]) -> Settings:
    tbl = spec.get("simulation", {})
    if not isinstance(tbl, Mapping):
        raise MechanismError("[simulation] must be a table")
    check_keys(tbl, {"steps", "tolerance", "max_iterations", "max_halvings",
                      "reverse_at_limit"}, "[simulation]")
    s = Settings()
    steps = tbl.get("steps", s.steps)
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 1:
        raise MechanismError(f"[simulation].steps must be a positive integer, got {steps!r}")
    tol = number(tbl.get("tolerance", s.tolerance), "[simulation].tolerance", positive=True)
    mi = tbl.get("max_iterations", s.max_iterations)
    mh = tbl.get("max_halvings", s.max_halvings)
    for key, v in (("max_iterations", mi), ("max_halvings", mh)):
        if not isinstance(v, int) or isinstance(v, bool) or v < 1:
            raise MechanismError(f"[simulation].{key} must be a positive integer, got {v!r}")
    rev = tbl.get("reverse_at_limit", s.reverse_at_limit)
    if not isinstance(rev, bool):
        raise MechanismError(f"[simulation].reverse_at_limit must be true or false, got {rev!r}")
    return Settings(steps, tol, mi, mh, rev)


class Frame(NamedTuple):
    """What the inputs are parsed against: the mechanism's kind, joints (names, coordinates,
    which are lines / planes, which are fixed), links by name and the ground link."""

    kind: Kind
    names: Sequence[str]
    links: Mapping[str, Link]
    fixed: NDArray[np.bool_]
    coords: FloatArray
    is_line: NDArray[np.bool_]
    ground: str


@dataclass
class Inputs:
    """The parsed [[inputs]]: each input, the rigid motion it applies (Eqs. 10–22) with its
    axis, the input driving each joint (−1: none), and the counts of free motion parameters
    (`n_f`) and actuators."""

    owner: NDArray[np.intp]
    inputs: list[Input] = field(default_factory=list)
    motions: list[Motion] = field(default_factory=list)
    axes: list[FloatArray] = field(default_factory=list)
    n_f: int = 0
    n_act: int = 0


def parse_inputs(spec: Mapping[str, Any], fr: Frame) -> Inputs:
    """Inputs and the rigid motion each applies (Eqs. 10–22), with the joints it drives."""
    tbls = spec.get("inputs")
    if not isinstance(tbls, Sequence) or isinstance(tbls, str) or not tbls:
        raise MechanismError("[[inputs]]: at least one input is required")
    out = Inputs(np.full(len(fr.names), -1, dtype=np.intp))
    for k, tbl in enumerate(tbls):
        where = f"[[inputs]] #{k + 1}"
        if not isinstance(tbl, Mapping):
            raise MechanismError(f"{where}: expected a table")
        if "actuator" in tbl:
            _add_actuator(out, tbl, where, fr)
        else:
            _add_driven_link(out, tbl, where, fr)
    return out


def _add_actuator(out: Inputs, tbl: Mapping[str, Any], where: str, fr: Frame) -> None:
    """A linear actuator between two points: its input is their distance (ACT row)."""
    check_keys(tbl, {"actuator", "step", "name"}, where)
    pair = tbl["actuator"]
    if (not isinstance(pair, Sequence) or isinstance(pair, str) or len(pair) != 2
            or not all(p in fr.names for p in pair) or pair[0] == pair[1]):
        raise MechanismError(f"{where}: actuator must name two different joints")
    a, b = (fr.names.index(p) for p in pair)
    if fr.is_line[a] or fr.is_line[b]:
        raise MechanismError(f"{where}: an actuator joins two points")
    if "step" not in tbl:
        raise MechanismError(f"{where}: an actuator needs an explicit step (a length)")
    step = number(tbl["step"], f"{where}.step")
    dim = 2 if fr.kind == "planar" else 3
    length = float(np.linalg.norm(fr.coords[a, :dim] - fr.coords[b, :dim]))
    name = str(tbl.get("name", f"{pair[0]}–{pair[1]}"))
    out.inputs.append(Input(name, "actuator", None, None, (str(pair[0]), str(pair[1])),
                            length, step, "length"))
    out.motions.append(Motion("actuator", length, out.n_act))
    out.axes.append(np.zeros(3))
    out.n_act += 1


def _add_driven_link(out: Inputs, tbl: Mapping[str, Any], where: str, fr: Frame) -> None:
    """A link driven at one of its fixed joints: a rotation (revolute) or translation
    (prismatic) of its moving joints."""
    check_keys(tbl, {"link", "joint", "step", "name", "initial"}, where)
    lname, jname, j, moving = _driven_joint(tbl, where, fr)
    for i in moving:
        if out.owner[i] >= 0:
            raise MechanismError(f"{where}: joint {fr.names[i]} is already driven by input "
                                 f"{out.inputs[int(out.owner[i])].name}")
        out.owner[i] = len(out.inputs)
    step = number(tbl.get("step", 2.0 * math.pi / 180.0), f"{where}.step")
    mkind, axis, value0 = _link_motion(fr, j, moving)
    if "initial" in tbl:
        value0 = _initial_value(tbl["initial"], where, mkind, value0)
    ikind: InputKind = "prismatic" if fr.is_line[j] else "revolute"
    name = str(tbl.get("name", f"{lname}@{jname}"))
    out.inputs.append(Input(name, ikind, lname, jname, None, value0, step,
                            "length" if mkind == "translate-plane" else "rad"))
    out.motions.append(Motion(mkind, value0, out.n_f))
    out.axes.append(axis)
    out.n_f += 1 if mkind == "translate-plane" else 2


def _driven_joint(tbl: Mapping[str, Any], where: str, fr: Frame
                  ) -> tuple[str, str, int, list[int]]:
    """(link, joint, joint index, moving joints of the link) of a driven-link input, checked:
    a moving link, driven at a fixed joint on it, in a planar or spherical mechanism."""
    lname, jname = tbl.get("link"), tbl.get("joint")
    if not isinstance(lname, str) or lname not in fr.links or lname == fr.ground:
        raise MechanismError(f"{where}: link must name a moving link, got {lname!r}")
    lk = fr.links[lname]
    if jname not in lk.joints:
        raise MechanismError(f"{where}: joint {jname!r} is not on link {lname}")
    j = fr.names.index(jname)
    if not fr.fixed[j]:
        raise MechanismError(f"{where}: the actuated joint {jname} must be fixed (on the "
                             f"ground link {fr.ground}); the paper actuates at fixed joints")
    if fr.kind == "spatial":
        raise MechanismError(f"{where}: spatial mechanisms are driven by an actuator "
                             "between two joints (actuator = [\"A\", \"B\"])")
    moving = [fr.names.index(x) for x in lk.joints if not fr.fixed[fr.names.index(x)]]
    if not moving:
        raise MechanismError(f"{where}: link {lname} has no moving joint to drive")
    return lname, str(jname), j, moving


def _link_motion(fr: Frame, j: int, moving: Sequence[int]
                 ) -> tuple[MotionKind, FloatArray, float]:
    """(motion kind, axis, initial value) of a link driven at joint j: a rotation in the
    plane about the pivot (value: the absolute angle of the link's first moving point), a
    translation along a planar line, or a rotation about the sphere's axis through j."""
    coords = fr.coords
    if fr.kind == "planar" and not fr.is_line[j]:
        axis = coords[j, :2].copy()
        pts = [i for i in moving if not fr.is_line[i]]
        value0 = 0.0
        if pts:
            d = coords[pts[0], :2] - axis
            value0 = math.atan2(d[1], d[0])
        return "rotate-plane", axis, value0
    if fr.kind == "planar":
        a, b = coords[j, 0], coords[j, 1]
        return "translate-plane", np.array([b, -a]) / math.hypot(a, b), 0.0
    return "rotate-sphere", coords[j] / np.linalg.norm(coords[j]), 0.0


def _initial_value(v: Any, where: str, mkind: MotionKind, value0: float) -> float:
    """The input's stated initial value; a planar rotation's must agree (mod 2π) with the
    angle of the joint coordinates."""
    v0 = number(v, f"{where}.initial")
    if mkind == "rotate-plane" and value0 != 0.0:
        turns = (v0 - value0) / (2.0 * math.pi)
        if abs(turns - round(turns)) > 1e-9:
            raise MechanismError(
                f"{where}.initial = {v0!r} rad disagrees with the link's angle "
                f"{value0!r} rad in the joint coordinates")
    return v0
