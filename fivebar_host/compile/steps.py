"""Motor steps: absolute from the homed pose, quantised once; relative = differences.

ARCHITECTURE.md: absolute step = round(θ_rel · steps_per_rev / 2π) with θ_rel = θ − θ_home,
steps_per_rev = full steps × microsteps × gear ratio. Rounding happens once per target, on the
absolute position, so quantisation error never accumulates: relative moves are differences of
absolute steps and their running sum reproduces every absolute target exactly (integers).
"""

from __future__ import annotations

import math

import numpy as np

from kinematics.arrays import FloatArray, IntArray
from kinematics.fivebar import FiveBar


def absolute_steps(angles_rad: FloatArray, home_rad: tuple[float, float],
                   steps_per_rev: float) -> IntArray:
    """Absolute steps (N, 2) int64 of motor angles (N, 2) rad relative to the homed pose.

    Rounds half to even (numpy `rint`, like Python's `round`)."""
    th = np.asarray(angles_rad, dtype=np.float64).reshape(-1, 2)
    rel = th - np.asarray(home_rad, dtype=np.float64)
    return np.rint(rel * (steps_per_rev / (2.0 * math.pi))).astype(np.int64)


def step_angles(steps: IntArray, home_rad: tuple[float, float],
                steps_per_rev: float) -> FloatArray:
    """Motor angles (N, 2) rad of absolute step positions: what the machine really reaches."""
    return (np.asarray(home_rad, dtype=np.float64)
            + np.asarray(steps, dtype=np.float64) * (2.0 * math.pi / steps_per_rev))


def relative_steps(absolute: IntArray, start: IntArray | None = None) -> IntArray:
    """Per-segment step differences (N, 2) from `start` (default: the first row is the start
    and N−1 moves are returned)."""
    a = np.asarray(absolute, dtype=np.int64).reshape(-1, 2)
    if start is None:
        return np.asarray(np.diff(a, axis=0), dtype=np.int64)
    first = np.asarray(start, dtype=np.int64).reshape(1, 2)
    return np.asarray(np.diff(np.concatenate((first, a)), axis=0), dtype=np.int64)


def step_quantum_mm(jacobian: FloatArray, rad_per_step: float) -> FloatArray:
    """Largest pen displacement (N,) mm from rounding each motor to its nearest step: with
    |δθ_j| ≤ q/2, ‖J·δθ‖ ≤ (‖J[:, 0]‖ + ‖J[:, 1]‖)·q/2 (triangle inequality)."""
    j = np.asarray(jacobian, dtype=np.float64)
    return (np.hypot(j[:, 0, 0], j[:, 1, 0]) + np.hypot(j[:, 0, 1], j[:, 1, 1])) * (
        rad_per_step / 2.0)


def pen_position_mm(geometry: FiveBar, assembly: str, home_rad: tuple[float, float],
                    steps_per_rev: float, a_steps: int, b_steps: int
                    ) -> tuple[float, float] | None:
    """Where the pen is at motor steps (A, B) from the homed pose: forward kinematics of the
    machine's assembly (None where the links cannot close). Positions are shown in mm
    beside the steps everywhere (CLI, daemon, page)."""
    th = step_angles(np.array([[a_steps, b_steps]]), home_rad, steps_per_rev)
    fwd = geometry.forward_batch(th, assembly)
    if not fwd.valid[0]:
        return None
    return float(fwd.points[0, 0]), float(fwd.points[0, 1])
