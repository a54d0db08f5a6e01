"""Steps: absolute from the homed pose, quantised once; relative = differences, so the running
sum of relative moves reproduces every absolute target with no drift."""

from __future__ import annotations

import math

import numpy as np

from fivebar_host.compile.steps import absolute_steps, relative_steps, step_angles, step_quantum_mm

SPR = 200 * 16 * 4.0
HOME = (math.radians(120.0), math.radians(60.0))


def test_absolute_steps_exact_values() -> None:
    th = np.array([[HOME[0], HOME[1]], [HOME[0] + 2 * math.pi / SPR * 10.4, HOME[1] - 0.5]])
    st = absolute_steps(th, HOME, SPR)
    assert st[0].tolist() == [0, 0]
    assert st[1, 0] == 10
    assert st[1, 1] == round(-0.5 * SPR / (2 * math.pi))
    back = step_angles(st, HOME, SPR)
    assert np.all(np.abs(back - th) <= math.pi / SPR + 1e-15)  # within half a step


def test_relative_steps_sum_to_absolute_without_drift_over_1e5_segments() -> None:
    rng = np.random.default_rng(7)
    n = 100_000
    # a random walk of joint targets with sub-step increments: the worst case for drift
    th = np.array(HOME) + np.cumsum(rng.normal(0, 0.7 * 2 * math.pi / SPR, (n + 1, 2)), axis=0)
    th[0] = HOME
    ab = absolute_steps(th, HOME, SPR)
    rel = relative_steps(ab)
    assert rel.dtype == np.int64
    assert np.array_equal(np.cumsum(rel, axis=0), ab[1:])  # exact, every target
    # the naive alternative (round each relative angle) drifts by many steps
    naive = np.cumsum(np.rint(np.diff(th, axis=0) * SPR / (2 * math.pi)), axis=0)
    assert np.abs(naive - ab[1:]).max() > 10
    # and the final position is within half a step of the ideal angle
    assert np.all(np.abs(step_angles(ab[-1:], HOME, SPR) - th[-1]) <= math.pi / SPR + 1e-12)


def test_relative_steps_with_start() -> None:
    ab = np.array([[3, 4], [5, 1]])
    assert relative_steps(ab, np.array([1, 1])).tolist() == [[2, 3], [2, -3]]


def test_step_quantum_bound() -> None:
    rng = np.random.default_rng(1)
    jac = rng.normal(0, 50, (200, 2, 2))
    q = 2 * math.pi / SPR
    bound = step_quantum_mm(jac, q)
    # brute force over the corners of the rounding box |δθ_j| ≤ q/2
    corners = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]]) * q / 2
    worst = np.max(np.linalg.norm(np.einsum("nij,kj->nki", jac, corners), axis=2), axis=1)
    assert np.all(worst <= bound + 1e-12)
