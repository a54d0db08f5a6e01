"""Section 5 of the report: the stability map's outcome counts, the approaches table and the
failure modes with the tests in tests/test_stability.py that hold them."""

from __future__ import annotations

import math

import numpy as np

from benchmarks.speed_accuracy.config import EXACT_MM
from benchmarks.speed_accuracy.markdown import fmt_g
from benchmarks.speed_accuracy.results import Results
from benchmarks.speed_accuracy.stability import CAT_STYLE, Cat
from fivebar_host.compile import MAX_STEP_RAD

#: Failure modes found by the stability map and approaches, with their tests. The wording is
#: qualitative on purpose; the figures are in the tables above.
FAILURE_MODES: tuple[str, ...] = (
    "- **Closed-form inverse at a reach circle (type 1).** θ has a square-root branch point "
    "there; the factored discriminant keeps the answer exact to rounding up to the circle, "
    "and past it the point is refused (`UnreachableError` with the excess in mm) "
    "[`test_closed_inverse_stays_exact_up_to_a_reach_circle_then_refuses`].",
    "- **Closed-form forward near coincident elbows (Mode 1b, b1 = b2).** The error grows "
    "like 1/δ and passes 1e-6 mm close to the coincidence — bounded by the problem's own "
    "conditioning (one ulp of the motor angles moves the exact P as much); exactly "
    "coincident elbows raise `DegenerateError` "
    "[`test_closed_forward_near_coincident_elbows_errs_only_as_the_problem_does`; "
    "`tests/test_fivebar.py::test_coincident_elbows_b1_equals_b2`].",
    "- **Closed-form forward at Mode 1a** (machine with short floating links). Error grows "
    "like 1/√δ within the conditioning bound; past it the links cannot meet: "
    "`UnreachableError` [`test_closed_forward_stays_exact_up_to_mode_1a_then_refuses`].",
    "- **n-bar solver towards a reach circle.** No singularity of the forward problem: "
    "bounded by its residual tolerance [`test_nbar_approaching_a_reach_circle_stays_bounded`].",
    "- **n-bar solver towards Mode 1a.** A residual ε moves P by ~√(ε·L) there, so its "
    "error grows towards √tolerance × size (bounded), then it reports a motion limit at the "
    "singular Jacobian and never answers past it "
    "[`test_nbar_approaching_mode_1a_has_bounded_error_then_reports_the_limit`].",
    "- **n-bar solver: false motion limit next to coincident elbows.** A joint step of the "
    "size a job segment may take that passes very close to R1 = R2 makes P swing round the "
    "elbows faster than the continuity guard accepts: the solver reports a motion limit "
    "(\"no continuous solution\") where the closed form answers — a refusal, never a wrong "
    "point (table of section 1: *limits reported*) "
    "[`test_nbar_step_passing_coincident_elbows_refuses_rather_than_answers_wrong`].",
    "- **n-bar solver exactly through coincident elbows.** P is free on a circle there; the "
    "continuation keeps it continuous, which lands on the other assembly sign past the "
    "coincidence (a branch change the continuity guard cannot see), while the closed form "
    "in the job's assembly jumps to the far side; validation against the closed form "
    "reports the disagreement "
    "[`test_nbar_through_coincident_elbows_keeps_p_continuous_and_validation_sees_it`].",
    "- **Linear approximation (Eqs. 25–26).** Bounded by its fit residual, which is far above "
    "a plotter's tolerance over a page; refuses outside its fit box and out of reach "
    "[`test_linear_approximation_refuses_outside_and_misses_the_tolerance_inside`].",
    "- **Lookup tables at a reach circle.** Cells with a node out of reach are refused; next "
    "to the circle the error grows (square-root branch point) and the build-time estimate "
    "tracks it; the margin guard refuses the band "
    "[`test_table_refuses_cells_at_a_reach_circle_and_estimates_the_error_next_to_it`].",
    "- **Lookup tables near type 2.** Any angle error moves the pen far there: an unguarded "
    "inverse table answers with pen errors far beyond its sampled cell estimate (a point "
    "singularity escapes sampling — the *error > tolerance* cells of the map); with the "
    "profile's singularity margins as guard those points are refused. Forward tables refuse "
    "cells past Mode 1a (nodes without a solution) "
    "[`test_table_near_type_2_escapes_its_estimate_and_the_margin_guard_refuses`].",
)


def stability_section(res: Results, img_rel: str) -> list[str]:
    """Section 5, the map: how the grid was asked and the count of each outcome per method."""
    sc = res.scene
    L: list[str] = []
    L += ["## 5. Stability: where each method fails", "",
          f"![stability map]({img_rel}/perf_stability.png)", "",
          f"Grid of {res.cfg.map_pitch_mm:g} mm over the workspace box in working mode "
          f"{sc.mode}. Inverse maps are asked at every node; forward maps at the closed-form "
          "angles of the nodes in the page's assembly (the other assembly is grey: given "
          "angles and one assembly, its points are not asked). Pen error against the "
          f"long-double closed form: ≤ {EXACT_MM:g} mm, ≤ tolerance, or more. The n-bar "
          f"solver runs one continuation step of {MAX_STEP_RAD:g} rad into each node (every "
          f"{res.cfg.nbar_map_stride}nd node) at its default tolerance {res.smap.nbar_tol:g}. "
          "Counts per outcome:", ""]
    counts = res.smap.counts()
    used = [c for c in Cat if any(cc[c] for cc in counts.values())]
    L.append("| method | " + " | ".join(CAT_STYLE[c][1] for c in used) + " |")
    L.append("|---|" + "---:|" * len(used))
    for m, cc in counts.items():
        L.append(f"| {m} | " + " | ".join(str(cc[c]) for c in used) + " |")
    return L


def approaches_section(res: Results, img_rel: str) -> list[str]:
    """Section 5, the approaches: per singularity and method, error growth and the outcome at
    the singular pose and past it."""
    L: list[str] = []
    d0 = res.appr[0].approach.deltas if res.appr else np.array([math.nan])
    L += ["", f"![approaches]({img_rel}/perf_approach.png)", "",
          f"Approaching each singularity, δ from {d0[0]:g} mm down to {d0[-1]:g} mm (type 1: "
          "distance of P inside the reach circle; Mode 1a: how much shorter |R1R2| is than "
          "b1 + b2; Mode 1b: the scale of the elbows' distance). Per method: the largest pen "
          "error on the way (∞: the answer's angles put the pen nowhere — the floating links "
          "cannot meet), the smallest δ still within 1e-6 mm, how many poses were answered, "
          "and what it does exactly at the singularity (δ = 0) and just past it (δ = −1e-9 "
          "mm: past a reach circle the point is out of reach, past Mode 1a the links cannot "
          "meet, past Mode 1b the elbows have crossed). The n-bar solver follows each "
          "approach by continuation; at and past the singularity it is judged by continuity "
          "(distance from the closed-form point of the last approach pose, and the assembly "
          "sign it ends in)." + (
              " Mode 1a needs b1 + b2 < a1 + a2 + w, which the profile's machine does not "
              "have; it is shown on the same machine with shorter floating links."
              if any(ar.machine != "profile" for ar in res.appr) else "")
          if res.appr else "No approach found.", ""]
    L.append("| approach | method | max error mm | error ≤ 1e-6 mm down to δ mm | answered | "
             "at δ = 0 | past it |")
    L.append("|---|---|---:|---:|---:|---|---|")
    for ar in res.appr:
        d = ar.approach.deltas
        where = "" if ar.machine == "profile" else f" ({ar.machine})"
        for meth, ev in ar.errors.items():
            ok = ~np.isnan(ev)
            good = ok & (ev <= EXACT_MM)
            down = fmt_g(float(d[good].min())) if good.any() else "never"
            L.append(f"| {ar.approach.name}{where} | {meth} | "
                     f"{fmt_g(float(np.nanmax(ev))) if ok.any() else '—'} | {down} | "
                     f"{int(ok.sum())}/{ev.size} | {ar.at.get(meth, '—')} | "
                     f"{ar.past.get(meth, '—')} |")
    return L


def failure_modes_section() -> list[str]:
    """The failure modes found, each with the test that holds it."""
    return ["", "### Failure modes and the tests that hold them", "",
            "`tests/test_stability.py` asserts the documented behaviour at each place this "
            "run found a failure mode (the test names are in brackets):", "",
            *FAILURE_MODES]
