"""Simulation (Algorithm 1): the public entry points `simulate` and `sweep`.

Both follow one branch with a `Tracker` (`kinematics.nbar.tracker`: predictor, Newton, the
branch-flip guard of `kinematics.nbar.guard`, subdivision, motion limits located at folds by
`kinematics.nbar.fold`) and assemble a `Simulation` (`kinematics.nbar.results`), every solved
state checked again with the paper's exact equations (`Mechanism.residuals`): that is the
residual reported per row.

`simulate` steps through given input values one by one. `sweep` drives the inputs along a
line in equal steps; by default (`fast=True`) it takes them on the fast path
(`kinematics.nbar.fast`: blocks of steps predicted and corrected together, a Taylor start, a
fold look-ahead) and hands every step that needs more to the tracker; `fast=False` runs every
step through the tracker (the reference path), with the same rows within the tolerance.
`sweep(..., reverse_at_limit=True)` runs the inputs back at a motion limit to trace a
rocker's whole range.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from kinematics.arrays import FloatArray
from kinematics.nbar.fast import FastPath, rows
from kinematics.nbar.history import HISTORY
from kinematics.nbar.model import Mechanism, Settings
from kinematics.nbar.results import LimitReport, Simulation, Status, finish
from kinematics.nbar.tracker import Snapshot, Tracker

__all__ = ["simulate", "sweep"]


def _settings(mech: Mechanism, tolerance: float | None, max_halvings: int | None) -> Settings:
    s = mech.settings
    return Settings(s.steps, s.tolerance if tolerance is None else tolerance, s.max_iterations,
                    s.max_halvings if max_halvings is None else max_halvings,
                    s.reverse_at_limit)


def simulate(mech: Mechanism, inputs: ArrayLike, *, tolerance: float | None = None,
             max_halvings: int | None = None) -> Simulation:
    """Follow the mechanism through the given input values (N,) or (N, n_inputs).

    Starts from the initial configuration (moving first to inputs[0] if that differs, without
    recording the way there). Rows after a motion limit are UNREACHED; the limit row holds the
    last configuration reached and its input value. Every step is a tracker step (the
    reference path; there is no fast path for arbitrary input values).
    """
    u_all = np.asarray(inputs, dtype=np.float64)
    n_in = len(mech.inputs)
    if u_all.ndim == 1 and n_in == 1:
        u_all = u_all[:, None]
    if u_all.ndim != 2 or u_all.shape[1] != n_in:
        raise ValueError(f"inputs must have shape (N, {n_in}); got {np.shape(inputs)}")
    if not np.all(np.isfinite(u_all)):
        raise ValueError("inputs must be finite")
    tr = Tracker(mech, _settings(mech, tolerance, max_halvings))
    n_rows = u_all.shape[0]
    xtab = mech.basis.entries_batch(u_all)
    q = np.full((n_rows, mech.system.n_u), np.nan)
    out_u = u_all.copy()
    iters = [0] * n_rows
    subs = [0] * n_rows
    status = [Status.UNREACHED] * n_rows
    limits: list[LimitReport] = []
    locked = tr.locked()
    same = np.all(u_all == np.vstack((tr.u, u_all[:-1])), axis=1)  # input unchanged
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        _follow(tr, u_all, xtab, same, locked, q, out_u, iters, subs, status, limits)
    return finish(mech, out_u, q, np.array(iters, dtype=np.int64),
                  np.array(subs, dtype=np.int64),
                  np.fromiter(status, dtype=np.int8, count=len(status)), limits, None)


def _follow(tr: Tracker, u_all: FloatArray, xtab: FloatArray,
            same: NDArray[np.bool_], locked: str | None, q: FloatArray, out_u: FloatArray,
            iters: list[int], subs: list[int], status: list[Status],
            limits: list[LimitReport]) -> None:
    """`simulate`'s loop: advance through every row, filling the output lists in place."""
    for k in range(u_all.shape[0]):
        if same[k] and (k == 0 or status[k - 1] <= Status.SUBDIVIDED):
            st, it, sb, why, failed, res = Status.OK, 0, 0, "", tr.u, 0.0
        elif locked is not None:
            status[k] = Status.INCONSISTENT
            limits.append(LimitReport("inconsistent", k, tr.u.copy(), u_all[k].copy(),
                                      u_all[k].copy(), locked, math.nan))
            break
        else:
            st, it, sb, why, failed, res = tr.advance(u_all[k], xtab[k])
        iters[k], subs[k] = it, sb
        if st == Status.LIMIT:
            kind, reason = tr.explain(why, res)
            limits.append(LimitReport(kind, k, tr.u.copy(), failed.copy(), u_all[k].copy(),
                                      reason, res))
            if kind == "inconsistent":
                status[k] = Status.INCONSISTENT
                break
            status[k] = Status.LIMIT
            out_u[k] = tr.u
            q[k] = tr.q
            break
        status[k] = st
        q[k] = tr.q


class _Rows:
    """A sweep's output rows, preallocated: inputs, unknowns (NaN where none), Newton
    iterations, accepted sub-steps, status, the limits met, and `pos`, the next row."""

    def __init__(self, cap: int, n_in: int, n: int) -> None:
        self.u = np.empty((cap, n_in))
        self.q = np.full((cap, n), np.nan)
        self.iterations = np.zeros(cap, dtype=np.int64)
        self.substeps = np.zeros(cap, dtype=np.int64)
        self.status = np.full(cap, Status.UNREACHED, dtype=np.int8)
        self.limits: list[LimitReport] = []
        self.pos = 0

    def put(self, u: FloatArray, q: FloatArray) -> None:
        """Append one OK row (no Newton iterations: a known state)."""
        self.u[self.pos] = u
        self.q[self.pos] = q
        self.status[self.pos] = Status.OK
        self.pos += 1

    def taken(self, us: FloatArray, k: int) -> None:
        """Account for k rows whose states and iterations the fast path already wrote."""
        pos = self.pos
        self.u[pos: pos + k] = us
        self.substeps[pos: pos + k] = 1
        self.status[pos: pos + k] = Status.OK
        self.pos += k

    def replayed(self, first: int, k: int) -> None:
        """Append rows first − 1, …, first − k again, in that order (way back)."""
        pos = self.pos
        self.u[pos: pos + k] = self.u[first - k: first][::-1]
        self.q[pos: pos + k] = self.q[first - k: first][::-1]
        self.status[pos: pos + k] = Status.OK
        self.pos += k

    def record(self, tr: Tracker, st: Status, it: int, sb: int, why: str,
               failed: FloatArray, res: float, target: FloatArray) -> bool:
        """Append a tracker step's row; at a failure classify it. True when the sweep must
        stop (inconsistent equations)."""
        pos = self.pos
        self.pos += 1
        self.iterations[pos] = it
        self.substeps[pos] = sb
        if st != Status.LIMIT:
            self.u[pos] = target
            self.q[pos] = tr.q
            self.status[pos] = st
            return False
        kind, reason = tr.explain(why, res)
        self.limits.append(LimitReport(kind, pos, tr.u.copy(), failed.copy(), target.copy(),
                                       reason, res))
        self.u[pos] = tr.u
        if kind == "inconsistent":
            self.status[pos] = Status.INCONSISTENT
            return True
        self.q[pos] = tr.q
        self.status[pos] = Status.LIMIT
        return False

    def result(self, mech: Mechanism, reversed_at: int | None) -> Simulation:
        """The rows written so far as a verified `Simulation`."""
        p = self.pos
        return finish(mech, self.u[:p], self.q[:p], self.iterations[:p], self.substeps[:p],
                      self.status[:p], self.limits, reversed_at)


def sweep(mech: Mechanism, steps: int | None = None, step: ArrayLike | None = None, *,
          reverse_at_limit: bool | None = None, tolerance: float | None = None,
          max_halvings: int | None = None, fast: bool = True) -> Simulation:
    """Drive every input from its initial value by `step` (default: the file's) per step.

    Rows: the initial configuration, then one per step taken. At a motion limit a LIMIT row
    holds the extreme configuration reached; with `reverse_at_limit` the inputs then run back
    (and past the start) until the other limit or until `steps` steps were taken, so a
    rocker's whole range is traced. `fast=False` takes every step through the tracker (the
    reference path: no blocks, no Taylor start, no fold look-ahead).
    """
    s = mech.settings
    n_steps = s.steps if steps is None else int(steps)
    inc = mech.step if step is None else np.broadcast_to(
        np.asarray(step, dtype=np.float64), (len(mech.inputs),)).copy()
    rev = s.reverse_at_limit if reverse_at_limit is None else reverse_at_limit
    tr = Tracker(mech, _settings(mech, tolerance, max_halvings))
    base = tr.u.copy()
    tr.set_line(base, inc)
    # Driven entries of x for every grid point the sweep can visit, in one batch.
    offset = n_steps + 1
    grid = base + np.arange(-offset, offset + 1)[:, None] * inc
    xtab = mech.basis.entries_batch(grid)
    # Rows: the start, one per step, and at most one more when the sweep turns back.
    out = _Rows(n_steps + 3, inc.size, tr.n)
    out.put(tr.u, tr.q)
    locked = tr.locked()
    if locked is not None:
        out.limits.append(LimitReport("inconsistent", 1, tr.u.copy(), tr.u + inc, tr.u + inc,
                                      locked, math.nan))
        out.u[1] = tr.u + inc
        out.status[1] = Status.INCONSISTENT
        out.pos = 2
        n_steps = 0
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        reversed_at = _sweep_rows(tr, FastPath(tr) if fast else None, grid, xtab, offset,
                                  n_steps, rev, out)
    return out.result(mech, reversed_at)


def _sweep_rows(tr: Tracker, fp: FastPath | None, grid: FloatArray, xtab: FloatArray,
                offset: int, n_steps: int, rev: bool, out: _Rows) -> int | None:
    """`sweep`'s loop over grid rows offset + index (the start is index 0): the fast path
    while it can, the tracker for the step it stops at, turning back at a limit when `rev`.
    Returns the row at which the sweep turned back (None if it did not)."""
    index = 0
    direction = 1
    taken = 0
    reversed_at: int | None = None
    while taken < n_steps:
        if reversed_at is not None and 0 < index < reversed_at:
            # Back over the grid points solved on the way out: the same branch, the same
            # inputs, so the same states; replay them rather than solve them again (row r
            # of the way out holds grid point r).
            k = min(index, n_steps - taken)
            out.replayed(index, k)
            index -= k
            taken += k
            j = min(k, HISTORY)
            tr.replay(grid[offset + index + np.arange(j - 1, -1, -1)],
                      out.q[out.pos - j: out.pos])
            if fp is not None:
                fp.fresh()
            continue
        refused, fold_first = 0, False
        if fp is not None:
            k = fp.run(offset + index, direction, n_steps - taken, grid, xtab, out.q,
                       out.iterations, out.pos)
            if k:
                out.taken(grid[rows(offset + index + direction, k, direction)], k)
                index += direction * k
                taken += k
                if not (fp.stuck or fp.fold_ahead):
                    continue
            refused, fold_first = fp.stuck, fp.fold_ahead
        taken += 1
        g = offset + index + direction
        before = tr.snapshot() if rev and reversed_at is None else None
        st, it, sb, why, failed, res = tr.advance(grid[g], xtab[g], refused, fold_first)
        if out.record(tr, st, it, sb, why, failed, res, grid[g]):
            break
        if st == Status.LIMIT:
            if before is None:
                break
            reversed_at = out.pos - 1
            _turn_back(tr, before, out)
            direction = -direction
            continue
        index += direction
    return reversed_at


def _turn_back(tr: Tracker, before: Snapshot, out: _Rows) -> None:
    """At a limit, turn back: the next row is the grid point before the limit again. Its
    state is known; resume from it (not from the extreme, where the steps would have to grow
    again from the smallest) to run the inputs the other way."""
    tr.restore(before)
    out.put(tr.u, tr.q)
