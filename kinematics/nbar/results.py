"""A simulation's result: per-row status, the limits met, and the assembled `Simulation`.

Kept apart from the tracker and the sweep loops so that both the public entry points
(`kinematics.nbar.solver`) and the tracker (which reports a `Status` per step) use one
definition. `finish` verifies every solved row with the paper's exact equations
(`Mechanism.residuals`): that is the residual reported per row.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray
from kinematics.nbar.model import Mechanism


class Status(IntEnum):
    """Per-step outcome. OK and SUBDIVIDED rows hold a solved state."""

    OK = 0  # solved with the full step
    SUBDIVIDED = 1  # solved after splitting the step (continuity or convergence)
    LIMIT = 2  # motion limit: this row holds the last configuration reached, at its input value
    INCONSISTENT = 3  # redundant equations admit no motion (see LimitReport.reason)
    UNREACHED = 4  # after a limit: not attempted


@dataclass(frozen=True)
class LimitReport:
    """Where and why the motion stopped."""

    kind: Literal["limit", "inconsistent"]
    row: int
    reached: FloatArray
    failed: FloatArray
    requested: FloatArray
    reason: str
    residual: float

    def __str__(self) -> str:
        fmt = ", ".join
        if self.kind == "inconsistent":
            return (f"inconsistent constraints at input ({fmt(f'{v:.10g}' for v in self.reached)}"
                    f"): {self.reason}")
        return (f"motion limit between input ({fmt(f'{v:.10g}' for v in self.reached)}) and "
                f"({fmt(f'{v:.10g}' for v in self.failed)}) on the way to "
                f"({fmt(f'{v:.10g}' for v in self.requested)}): {self.reason}")


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated motion: per row the input values, every joint's coordinates (NaN where
    not solved), the exact scaled residual, Newton iterations, accepted sub-steps and status."""

    mechanism: Mechanism
    inputs: FloatArray
    coords: FloatArray
    residual: FloatArray
    iterations: NDArray[np.int64]
    substeps: NDArray[np.int64]
    status: NDArray[np.int8]
    limits: tuple[LimitReport, ...]
    reversed_at: int | None

    @property
    def completed(self) -> bool:
        """True when every requested row was solved."""
        return bool(np.all(self.status <= Status.SUBDIVIDED))

    @property
    def solved(self) -> NDArray[np.bool_]:
        """(N,) mask of rows that hold a configuration (OK, SUBDIVIDED or LIMIT)."""
        return np.asarray(self.status <= Status.LIMIT, dtype=bool)

    def path(self, name: str) -> FloatArray:
        """Trajectory (N, 2|3) of a point joint, or (N, 3) coordinates of a line / plane."""
        return self.mechanism.positions(self.coords, name)

    @property
    def status_names(self) -> list[str]:
        """Status per row as lower-case names."""
        return [Status(int(s)).name.lower() for s in self.status]


def finish(mech: Mechanism, inputs: FloatArray, q: FloatArray, iters: NDArray[np.int64],
           subs: NDArray[np.int64], status: NDArray[np.int8], limits: list[LimitReport],
           reversed_at: int | None) -> Simulation:
    """Assemble the result and verify every solved row with the exact equations."""
    ok = status <= int(Status.LIMIT)
    every = bool(ok.all())
    coords = np.full((status.size, *mech.coords0.shape), np.nan)
    resid = np.full(status.size, np.nan)
    if every or ok.any():
        q_ok, u_ok = (q, inputs) if every else (q[ok], inputs[ok])
        c = mech.coords_batch(q_ok, u_ok)
        coords[ok] = c
        if mech.constraints:
            resid[ok] = np.max(np.abs(mech.residuals(c, u_ok)), axis=1)
        else:
            resid[ok] = 0.0
    return Simulation(mech, inputs, coords, resid, iters, subs, status, tuple(limits),
                      reversed_at)
