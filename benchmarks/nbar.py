"""Speed and accuracy of the n-bar solver on the paper's examples, against scipy.optimize.

For every mechanism file in configs/mechanisms: wall time of `sweep` (the file's 180 steps;
median of interleaved runs; setup, solving and the exact-equation check of every state included),
steps per second, Newton iterations per step and the largest residual, side by side with a
baseline that solves the same equations (the same Φ and analytic Jacobian callables) along the
same input values with scipy: `fsolve` (MINPACK hybrj) for square systems, `least_squares`
(Levenberg–Marquardt) when equations outnumber unknowns. fsolve runs with xtol = 1e-9, about
the loosest setting at which its states still meet the solver's 1e-10 residual on every
example (the "max res" column shows it; 1e-8 does not on Watt-I); tighter settings only make
it slower. The baseline starts each step from the previous state (Algorithm 1); a second
column starts it from the same cubic extrapolation the solver uses. When a sweep meets motion
limits, its time includes locating them (fold solve, bracket < 2^-24 of a step), which the
baseline does not do; the baseline is given the same inputs, up to the limits reached.
Targets (issue 3): ≤ 5 ms per 180 steps, ≥ 5× the baseline. The machine's load average is
printed first: on a shared machine the wall times scale with it.

Run: python benchmarks/nbar.py [--runs N]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import warnings
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import scipy
from scipy.optimize import fsolve, least_squares

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from fivebar_host.report.text.linkage import load_mechanism  # noqa: E402
from kinematics.nbar import Mechanism, sweep  # noqa: E402

#: The paper's MATLAB run times for 180 steps (Sec. 4), seconds.
PAPER_S = {"fourbar_crank_rocker": 1.4, "stephenson2": 3.79, "theo_jansen": 3.81,
           "spherical_rrpr": 1.49, "spherical_watt1": 3.33, "five_ss": 0.28}
TARGET_MS = 5.0
TARGET_SPEEDUP = 5.0

FloatArray = np.ndarray


def _callables(mech: Mechanism, u: FloatArray
               ) -> tuple[Callable[[FloatArray], FloatArray], Callable[[FloatArray], FloatArray]]:
    """Φ(q) and J(q) at input u: the solver's own equations (scaled, Eqs. 1–9)."""
    sys_ = mech.system
    n, nd = sys_.n_u, sys_.n_d
    x = sys_.new_x()
    x[n: n + nd] = mech.basis.driven(u)
    x[n + nd: -1] = mech.basis.actuators(u)

    def fun(q: FloatArray) -> FloatArray:
        x[:n] = q
        return sys_.evaluate(x)[1]

    def jac(q: FloatArray) -> FloatArray:
        x[:n] = q
        return np.ascontiguousarray(sys_.evaluate(x)[0][:, :n])

    return fun, jac


def baseline(mech: Mechanism, inputs: FloatArray, extrapolate: bool
             ) -> tuple[FloatArray, int, int]:
    """Solve every row of `inputs` with scipy from the previous state (or a cubic
    extrapolation). Returns (states, function evaluations, failures)."""
    q = mech.q0.copy()
    hist: list[FloatArray] = [q]
    out = np.empty((inputs.shape[0], q.size))
    out[0] = q
    nfev = 0
    fails = 0
    lsq = mech.overdetermined
    for k in range(1, inputs.shape[0]):
        start = q
        if extrapolate and len(hist) >= 4:
            start = 4 * hist[-1] - 6 * hist[-2] + 4 * hist[-3] - hist[-4]
        fun, jac = _callables(mech, inputs[k])
        if lsq:
            res = least_squares(fun, start, jac=jac, method="lm", xtol=1e-12, ftol=1e-12,
                                gtol=1e-12)
            q, ok, nf = res.x, res.success, res.nfev
        else:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                q, info, ier, _ = fsolve(fun, start, fprime=jac, full_output=True, xtol=1e-9)
            ok, nf = ier == 1, int(info["nfev"])
        nfev += nf
        fails += 0 if ok else 1
        out[k] = q
        hist = [*hist[-3:], q]
    return out, nfev, fails


def interleaved(fns: list[Callable[[], object]], runs: int) -> list[tuple[float, float]]:
    """(median, best) wall time of each function over `runs` rounds (after one warm-up round);
    the functions take turns within a round, so on a shared machine they meet the same load."""
    for fn in fns:
        fn()
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(runs):
        for fn, ts in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
    return [(statistics.median(ts), min(ts)) for ts in times]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=15,
                    help="timed rounds (solver and both scipy variants take turns)")
    args = ap.parse_args()

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"python {platform.python_version()}, numpy {np.__version__}, scipy "
          f"{scipy.__version__}, {os.cpu_count()} cpu(s), load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"wall time: median (and best) of {args.runs} interleaved runs each; steps = input "
          "steps actually taken; targets are judged on medians\n")
    head = (f"{'example':22s} {'steps':>5s} {'ms':>6s} {'best':>6s} {'steps/s':>8s} "
            f"{'it/st':>5s} {'max res':>7s} | {'scipy ms':>8s} {'best':>6s} {'×':>5s} "
            f"{'×best':>5s} {'nfev/st':>7s} {'max res':>7s} | {'+pred ms':>8s} {'×':>5s} | "
            f"{'paper s':>7s} {'×paper':>7s}  target")
    print(head)
    print("-" * len(head))
    misses = []
    for path in sorted((ROOT / "configs" / "mechanisms").glob("*.toml")):
        name = path.stem
        mech = load_mechanism(path)
        sim = sweep(mech)
        steps = len(sim.status) - 1
        moving = sim.iterations[1:]
        res = float(np.nanmax(sim.residual))
        rows = sim.inputs
        qb, nfev, fails = baseline(mech, rows, False)
        cb = mech.coords_batch(qb, rows)
        res_b = float(np.max(np.abs(mech.residuals(cb, rows))))
        (t_ours, b_ours), (t_base, b_base), (t_pred, _) = interleaved(
            [partial(sweep, mech), partial(baseline, mech, rows, False),
             partial(baseline, mech, rows, True)], args.runs)
        ours_ms = 1e3 * t_ours
        speedup = t_base / t_ours
        paper = PAPER_S.get(name)
        ok = ours_ms <= TARGET_MS and speedup >= TARGET_SPEEDUP
        if not ok:
            misses.append(name)
        paper_txt = (f"{paper:7.2f} {paper / t_ours:7.0f}" if paper else f"{'—':>7s} {'—':>7s}")
        fail_txt = f" ({fails} scipy failures)" if fails else ""
        print(f"{name:22s} {steps:5d} {ours_ms:6.2f} {1e3 * b_ours:6.2f} {steps / t_ours:8.0f} "
              f"{float(np.mean(moving)):5.2f} {res:7.1e} | {1e3 * t_base:8.2f} "
              f"{1e3 * b_base:6.2f} {speedup:5.1f} {b_base / b_ours:5.1f} "
              f"{nfev / max(steps, 1):7.2f} {res_b:7.1e} | {1e3 * t_pred:8.2f} "
              f"{t_pred / t_ours:5.1f} | {paper_txt}  {'ok' if ok else 'MISSED'}{fail_txt}")
        if sim.limits:
            for lim in sim.limits:
                print(f"{'':22s} {lim.kind} at step {lim.row}: input {lim.reached[0]:.6g}")
    print()
    if misses:
        print(f"targets (≤ {TARGET_MS} ms, ≥ {TARGET_SPEEDUP}× scipy) missed by: "
              + ", ".join(misses))
    else:
        print(f"all examples within ≤ {TARGET_MS} ms per run and ≥ {TARGET_SPEEDUP}× scipy")


if __name__ == "__main__":
    main()
