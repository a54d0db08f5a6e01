"""Five-bar robot as an n-bar mechanism, and path validation against the closed form.

The host recomputes a job's end-effector path from its motor angles through the general solver
(continuation from the first pose) and compares it with `kinematics.fivebar.FiveBar.forward`;
the two share no code, so agreement checks both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.arrays import FloatArray
from kinematics.extension import ExtendedFiveBar
from kinematics.fivebar import FiveBar
from kinematics.nbar.build import build_mechanism
from kinematics.nbar.model import Mechanism, MechanismError
from kinematics.nbar.results import Simulation, Status
from kinematics.nbar.solver import simulate


def _sign(assembly: str | int) -> float:
    if assembly in ("+", 1):
        return 1.0
    if assembly in ("-", -1):
        return -1.0
    raise ValueError(f"assembly must be '+' or '-'; got {assembly!r}")


def fivebar_spec(geometry: FiveBar, angles0: ArrayLike, assembly: str | int = "+"
                 ) -> dict[str, Any]:
    """Mechanism-file dict of the five-bar robot at motor angles `angles0` (rad).

    Motors M1 = (0, 0), M2 = (w, 0) are fixed and both driven; the floating links carry their
    stated lengths b1, b2, so the end-effector P given here is only a first guess on the side
    of R1→R2 that `assembly` names ('+': left) and is assembled exactly when the file is built.
    """
    th = np.asarray(angles0, dtype=np.float64).reshape(2)
    s = _sign(assembly)
    g = geometry
    r1 = np.array([g.a1 * math.cos(th[0]), g.a1 * math.sin(th[0])])
    r2 = np.array([g.w + g.a2 * math.cos(th[1]), g.a2 * math.sin(th[1])])
    d = r2 - r1
    span = float(np.hypot(*d))
    if span == 0.0:
        raise MechanismError("the elbows coincide at the first pose (a type-2 singularity)")
    normal = np.array([-d[1], d[0]]) / span
    height = math.sqrt(max(0.5 * (g.b1**2 + g.b2**2) - 0.25 * span**2, (0.1 * span) ** 2))
    p = 0.5 * (r1 + r2) + s * height * normal
    return {
        "mechanism": {"name": "five-bar robot", "kind": "planar", "units": "mm",
                      "ground": "base", "tracers": ["P"]},
        "joints": {
            "M1": {"type": "revolute", "at": [0.0, 0.0]},
            "M2": {"type": "revolute", "at": [g.w, 0.0]},
            "R1": {"type": "revolute", "at": r1.tolist()},
            "R2": {"type": "revolute", "at": r2.tolist()},
            "P": {"type": "revolute", "at": p.tolist()},
        },
        "links": {
            "base": ["M1", "M2"],
            "a1": ["M1", "R1"],
            "a2": ["M2", "R2"],
            "b1": {"joints": ["R1", "P"], "length": g.b1},
            "b2": {"joints": ["R2", "P"], "length": g.b2},
        },
        "inputs": [
            {"link": "a1", "joint": "M1", "name": "theta1", "initial": float(th[0])},
            {"link": "a2", "joint": "M2", "name": "theta2", "initial": float(th[1])},
        ],
    }


def fivebar_mechanism(geometry: FiveBar, angles0: ArrayLike, assembly: str | int = "+"
                      ) -> Mechanism:
    """The five-bar robot as a `Mechanism`, assembled at motor angles `angles0` in `assembly`.

    With the pen on an extension of link 1 (`ExtendedFiveBar`, extension > 0) the assembled
    joint is renamed J and link b1 becomes the rigid link R1–J–K–P (K a construction point
    off the line R1J) whose pen point P is put
    where the extension's definition says (e beyond J, turned by γ from R1→J) — not through
    the closed form's Eq. X1 — so the solver carries the rigid triangle on its own.
    Raises MechanismError if the pose does not assemble or lands in the other assembly mode.
    """
    mech = build_mechanism(fivebar_spec(geometry, angles0, assembly))
    c = mech.coords0
    r1, r2, p = (c[mech.index(j), :2] for j in ("R1", "R2", "P"))
    cross = float((r2 - r1)[0] * (p - r1)[1] - (r2 - r1)[1] * (p - r1)[0])
    if cross * _sign(assembly) <= 0.0:
        raise MechanismError(f"the first pose did not assemble in mode {assembly!r}")
    if isinstance(geometry, ExtendedFiveBar) and geometry.extension > 0.0:
        spec = fivebar_spec(geometry, angles0, assembly)
        u = (p - r1) / geometry.b1
        g = geometry.extension_angle
        pen = p + geometry.extension * np.array([math.cos(g) * u[0] - math.sin(g) * u[1],
                                                 math.sin(g) * u[0] + math.cos(g) * u[1]])
        spec["joints"]["J"] = {"type": "revolute", "at": p.tolist()}
        spec["joints"]["P"] = {"type": "point", "at": pen.tolist()}
        # A construction point off the line R1J keeps the rigid body well posed when the
        # extension is straight (R1, J, P collinear give dependent distance gradients).
        off = r1 + 0.5 * np.array([-(p - r1)[1], (p - r1)[0]])
        spec["joints"]["K"] = {"type": "point", "at": off.tolist()}
        spec["links"]["b1"] = ["R1", "J", "K", "P"]
        spec["links"]["b2"] = {"joints": ["R2", "J"], "length": geometry.b2}
        mech = build_mechanism(spec)
    return mech


@dataclass(frozen=True, eq=False)
class FiveBarValidation:
    """Deviation between the n-bar and the closed-form end-effector paths (mm).

    `valid` marks rows where both solutions exist; `deviation` is NaN elsewhere.
    """

    nbar_points: FloatArray
    closed_points: FloatArray
    deviation: FloatArray
    valid: NDArray[np.bool_]
    simulation: Simulation

    @property
    def max_deviation(self) -> float:
        """Largest deviation over the valid rows (mm); inf if a row is not valid."""
        if not self.valid.all():
            return math.inf
        return float(np.max(self.deviation)) if self.deviation.size else 0.0

    def __str__(self) -> str:
        bad = int((~self.valid).sum())
        lim = "; ".join(str(lr) for lr in self.simulation.limits)
        tail = f"; {bad} row(s) without a solution ({lim})" if bad else ""
        ok = self.deviation[self.valid]
        worst = float(np.max(ok)) if ok.size else math.nan
        return (f"n-bar vs closed form: max deviation {worst:.3g} mm over "
                f"{int(self.valid.sum())} pose(s){tail}")


def validate_fivebar_path(geometry: FiveBar, angles: ArrayLike, assembly: str | int = "+",
                          tolerance: float = 1e-12) -> FiveBarValidation:
    """Recompute the end-effector path for motor angles (N, 2) (rad, from +x, CCW) through
    the general solver and compare it with the closed-form forward kinematics.

    `tolerance` is the solver's relative residual: 1e-12 (rather than the default 1e-10) keeps
    the n-bar path within ~1e-10 mm of the exact one on a machine of ~100 mm, so the reported
    deviation measures disagreement, not the solver's stopping rule.
    """
    th = np.asarray(angles, dtype=np.float64)
    if th.ndim != 2 or th.shape[1] != 2 or th.shape[0] == 0:
        raise ValueError(f"angles must have shape (N, 2); got {th.shape}")
    sign = "+" if _sign(assembly) > 0 else "-"
    mech = fivebar_mechanism(geometry, th[0], sign)
    sim = simulate(mech, th, tolerance=tolerance)
    nb = sim.path("P")
    closed = geometry.forward_batch(th, sign)
    valid = np.asarray(sim.solved & (sim.status != Status.LIMIT) & closed.valid, dtype=bool)
    dev = np.full(th.shape[0], np.nan)
    dev[valid] = np.hypot(*(nb[valid] - closed.points[valid]).T)
    return FiveBarValidation(nb, np.asarray(closed.points), dev, valid, sim)
