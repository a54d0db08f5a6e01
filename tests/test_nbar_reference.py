"""The fast path of a sweep against the reference path, on every example mechanism.

`sweep(..., fast=False)` takes every step through `Tracker.advance` (predictor, Newton, the
branch-flip guard, subdivision, fold location): the plain per-step algorithm. The default fast
path (`kinematics.nbar.fast`: blocks, Taylor start, fold look-ahead) must produce the same rows:
the same statuses and inputs, the same limits at the same inputs, and states that agree to
well within the solver's tolerance (both are Newton solutions of the same equations at the
same inputs to a residual of 1e-10, from different predictors).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from kinematics.nbar import Mechanism, Simulation, parse_mechanism, sweep
from kinematics.nbar.fast import FastPath

MECH = Path(__file__).resolve().parent.parent / "configs" / "mechanisms"
ALL = sorted(p.stem for p in MECH.glob("*.toml"))
#: The states may differ by the Newton tolerance's effect: 1e-9 of the mechanism's size.
STATE_TOL = 1e-9
#: Input values are the same grid points, or located limits (fold brackets of 2^-24 of a step).
INPUT_TOL = 1e-12


@cache
def load(name: str) -> Mechanism:
    return parse_mechanism((MECH / f"{name}.toml").read_text())


#: The file's sweep, a long one turning back at limits, and one with triple steps.
CASES: dict[str, dict[str, Any]] = {
    "file": {},
    "reverse": {"steps": 400, "reverse_at_limit": True},
    "triple": {"step_factor": 3.0},
}


def both(name: str, case: str) -> tuple[Simulation, Simulation, Mechanism]:
    mech = load(name)
    kw = dict(CASES[case])
    factor = kw.pop("step_factor", None)
    if factor is not None:
        kw["step"] = factor * mech.step
    return sweep(mech, **kw), sweep(mech, fast=False, **kw), mech


def test_examples_found() -> None:
    assert len(ALL) >= 7


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("name", ALL)
def test_fast_path_matches_reference(name: str, case: str) -> None:
    fast, ref, mech = both(name, case)
    assert fast.status_names == ref.status_names
    assert fast.reversed_at == ref.reversed_at
    np.testing.assert_allclose(fast.inputs, ref.inputs, rtol=0, atol=INPUT_TOL)
    solved = ref.solved
    np.testing.assert_array_equal(fast.solved, solved)
    np.testing.assert_allclose(fast.coords[solved], ref.coords[solved], rtol=0,
                               atol=STATE_TOL * max(mech.size, 1.0))
    assert len(fast.limits) == len(ref.limits)
    for a, b in zip(fast.limits, ref.limits, strict=True):
        assert (a.kind, a.row, a.reason) == (b.kind, b.row, b.reason)
        np.testing.assert_allclose(a.reached, b.reached, rtol=0, atol=INPUT_TOL)
        np.testing.assert_allclose(a.failed, b.failed, rtol=0, atol=INPUT_TOL)
    assert np.nanmax(ref.residual) <= 1e-9


def test_reference_path_takes_no_fast_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """fast=False never enters the fast path; the default does (so the comparison above
    compares two different algorithms)."""
    calls: list[int] = []
    real = FastPath.run

    def counted(self: FastPath, *args: Any) -> int:
        calls.append(1)
        return real(self, *args)

    monkeypatch.setattr(FastPath, "run", counted)
    sweep(load("fourbar_crank_rocker"), fast=False)
    assert not calls
    sweep(load("fourbar_crank_rocker"))
    assert calls
