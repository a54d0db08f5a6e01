"""Mechanism model: joints as points, lines and planes; links as rigid sets of joints; inputs.

The data a simulation runs on: `Joint`, `Link`, `Input`, `Settings` and the `Mechanism` (its
coordinates in the stored form, the compiled constraint rows and input motions, and the
coordinate / residual helpers used on results). Built from a mechanism file by
`kinematics.nbar.build` (parsing in `kinematics.nbar.spec`, link reduction in
`kinematics.nbar.links`). No file I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray
from kinematics.errors import FivebarError
from kinematics.nbar import constraints as cst
from kinematics.nbar.constraints import Constraint
from kinematics.nbar.perturb import InputBasis
from kinematics.nbar.system import QuadraticSystem

Kind = Literal["planar", "spherical", "spatial"]
JointType = Literal["revolute", "prismatic", "point", "spherical"]
InputKind = Literal["revolute", "prismatic", "actuator"]


class MechanismError(FivebarError, ValueError):
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
