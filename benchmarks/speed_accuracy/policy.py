"""The report's opening section, "Model no more than a scene needs": the pipeline's choices
(closed form, n-bar only to validate, adaptive segmentation, no tolerance below the step
quantum) argued with this run's figures, one small function per bullet."""

from __future__ import annotations

import math
from collections.abc import Sequence

from benchmarks.speed_accuracy.markdown import fmt_bytes, fmt_g, fmt_pct
from benchmarks.speed_accuracy.methods import MethodRow
from benchmarks.speed_accuracy.results import Results
from kinematics.nbar import Settings

#: Families that are exact by construction (no approximation to pick).
EXACT_FAMILIES = ("closed form", "bare formulas")


def _best(rows: Sequence[MethodRow], direction: str, family: str) -> MethodRow:
    return next(r for r in rows if r.direction == direction and r.family == family)


def _fastest_meeting(rows: Sequence[MethodRow], direction: str, tol: float,
                     exclude: tuple[str, ...], safe: bool = False) -> MethodRow | None:
    """The fastest method that answers every interior point within `tol`; with `safe`, also
    never answers any point of any set with more than `tol` (it refuses instead)."""
    ok = [r for r in rows if r.direction == direction and r.family not in exclude
          and r.errors["interior"].max_mm <= tol and r.errors["interior"].answered >= 0.999
          and (not safe or all(math.isnan(e.max_mm) or e.max_mm <= tol
                               for e in r.errors.values()))]
    return min(ok, key=lambda r: r.ns_per_point) if ok else None


def _approx_sentence(a: MethodRow, c: MethodRow, direction: str, tol: float,
                     safe: bool) -> str:
    cmp = "slower" if a.ns_per_point > c.ns_per_point else "faster"
    ratio = (a.ns_per_point / c.ns_per_point if cmp == "slower"
             else c.ns_per_point / a.ns_per_point)
    n1, n2 = a.errors["near type 1"], a.errors["near type 2"]
    if n1.answered == 0 and n2.answered == 0:
        near = "it refuses every near-singular point of both sets"
    else:
        worst = max(x for x in (n1.max_mm, n2.max_mm) if not math.isnan(x))
        near = (f"near singularities it answers {fmt_pct(n1.answered)} of the type-1 and "
                f"{fmt_pct(n2.answered)} of the type-2 set, with errors up to {fmt_g(worst)} mm"
                + (", far beyond the tolerance and without a warning" if worst > tol
                   else ""))
    what = ("The fastest" if not safe else "The fastest *guarded*") + f" {direction} "
    what += ("approximation that answers every interior point within "
             f"{tol:g} mm" + (" and never answers worse than that anywhere" if safe else ""))
    return (f"  {what} is the {a.name} ({a.ns_per_point:.0f} ns per point, {ratio:.1f}× "
            f"{cmp} than the closed form, interior error {fmt_g(a.errors['interior'].max_mm)} mm, "
            f"{fmt_bytes(a.nbytes)}, built in {fmt_g(a.build_s)} s); {near}.")


def _validation_sentence(res: Results) -> str:
    v = res.validation
    if v is None:
        return "(The validation timing was skipped: the job did not compile.) "
    return (f"On the {v.scene} job the closed-form validation of the quantised steps takes "
            f"{1e3 * v.closed_s:.1f} ms; the n-bar second opinion over {v.poses} poses takes "
            f"{1e3 * v.nbar_s:.0f} ms and differs from it by at most "
            f"{fmt_g(v.disagreement_mm)} mm. ")


def _closed_form_lines(ci: MethodRow, cf: MethodRow) -> list[str]:
    """The section's heading and the closed form's bullet."""
    worst_ci = max(ci.errors[s].max_mm for s in ci.errors)
    worst_cf = max(cf.errors[s].max_mm for s in cf.errors)
    return [
        "## Model no more than a scene needs",
        "",
        "The job pipeline uses the cheapest model that meets the tolerance, and this run's "
        "figures say which one that is:",
        "",
        f"- **Closed form for the five-bar.** Inverse kinematics take {ci.ns_per_point:.0f} ns "
        f"per point with every check, forward {cf.ns_per_point:.0f} ns; their largest pen "
        f"error over all three sets is {fmt_g(worst_ci)} mm (inverse) and {fmt_g(worst_cf)} mm "
        "(forward) against the long-double evaluation — exact for any tolerance a plotter "
        "can have.",
    ]


def _approximation_lines(res: Results, direction: str, c: MethodRow) -> list[str]:
    """The fastest approximation of one direction within the tolerance, unguarded and
    guarded (or that there is none)."""
    tol = res.scene.tol_mm
    lines: list[str] = []
    picks = [(False, _fastest_meeting(res.kin, direction, tol, EXACT_FAMILIES)),
             (True, _fastest_meeting(res.kin, direction, tol, EXACT_FAMILIES, safe=True))]
    if all(a is None for _, a in picks):
        lines.append(f"  No approximation of the {direction} kinematics answered every "
                     f"interior point within the {tol:g} mm tolerance.")
    for safe, a in picks:
        if a is not None and not (safe and a is picks[0][1]):
            lines.append(_approx_sentence(a, c, direction, tol, safe))
    return lines


def _linear_line(res: Results, ci: MethodRow, cf: MethodRow) -> str:
    """The thesis' Eq. 25 on this machine, and whether any approximation beat the closed
    form."""
    tol = res.scene.tol_mm
    lin = res.linear
    ai = _fastest_meeting(res.kin, "inverse", tol, EXACT_FAMILIES)
    af = _fastest_meeting(res.kin, "forward", tol, EXACT_FAMILIES)
    faster = [a for a, c in ((ai, ci), (af, cf)) if a is not None
              and a.ns_per_point < c.ns_per_point]
    lin_pen = _best(res.kin, "inverse", "linear Eq. 25/26").errors["interior"].max_mm
    return (
        f"  The thesis' linear transform (Eq. 25) fitted to this machine's page region by least "
        f"squares gives γ = {math.degrees(lin.gamma):.1f}°, B = {lin.scale:.4g} rad/mm, "
        f"A = ({lin.shift[0]:.4g}, {lin.shift[1]:.4g}) mm, but misses the motor angles by up "
        f"to {lin.max_rad:.2f} rad ({math.degrees(lin.max_rad):.0f}°) on its own fit points: "
        f"{fmt_g(lin_pen)} mm of pen error in the interior. " + (
            "So in this run no approximation is both faster than the closed form and within "
            "the tolerance: in numpy a table lookup (index arithmetic, gathers, the reach "
            "test) costs about as much as the closed form's square roots and arctangents, and "
            "every approximation adds build time, memory, an error that is estimated rather "
            "than proven, and refusals near singularities that need the closed form as a "
            "fallback anyway." if not faster else
            f"The {' and the '.join(a.name for a in faster)} ran faster than the closed form "
            "in this run, but only inside its guard: refused points need the closed form as "
            "a fallback and its error is estimated at build time, not proven; the pipeline "
            "keeps the closed form, exact everywhere with nothing to fall back on.")
        + " The firmware computes no kinematics at all (the host sends steps), so there is "
        "no small-processor case to approximate for either.")


def _nbar_line(res: Results, cf: MethodRow) -> str:
    """The n-bar solver's cost as forward kinematics: only to validate."""
    default_tol = Settings().tolerance
    dflt = min(res.nbar, key=lambda r: abs(math.log10(r.tol / default_tol)))
    us = [r.us_per_pose for r in res.nbar]
    return (
        f"- **n-bar only to validate.** As forward kinematics the general solver needs "
        f"{min(us):.0f}–{max(us):.0f} µs per pose along a raster path over the page "
        f"(tolerances {max(r.tol for r in res.nbar):g} to {min(r.tol for r in res.nbar):g}); "
        f"at its default tolerance {dflt.tol:g} that is {dflt.us_per_pose:.1f} µs, "
        f"{1e3 * dflt.us_per_pose / cf.ns_per_point:.0f}× the closed form's time, and its "
        f"answers agree with the closed form to {fmt_g(dflt.raster_max_mm)} mm there. "
        + _validation_sentence(res)
        + "So the pipeline computes with the closed form and runs the n-bar solver only as an "
        "independent check (dry-run report), never in the compile loop.")


def _segmentation_line(res: Results) -> str:
    """Adaptive segmentation against a fixed spacing at the profile's tolerance."""
    tol = res.scene.tol_mm
    jr = [r for r in res.jobs if abs(r.tol - tol) < 1e-12 and not r.error]
    parts = [f"{r.scene}: {r.draw_segments} adaptive draw segments against "
             f"{r.uniform_segments} at a fixed spacing of {fmt_g(r.uniform_h_mm)} mm "
             f"({r.uniform_segments / max(r.draw_segments, 1):.1f}×)" for r in jr]
    return (
        f"- **Adaptive segmentation instead of fixed point counts.** At the profile's "
        f"tolerance of {tol:g} mm — " + "; ".join(parts) + ". A fixed spacing has to be fine "
        "enough for the worst place of the drawing (where a curve bends most, or where the "
        "forward map bends most, close to a singularity) and spends that density everywhere; "
        "the adaptive flattening and joint-space split are dense only where the error needs "
        "it. Where a drawing is made of elements shorter than the spacing anyway, one point "
        "per element is already enough and both give the same count.")


def _quantum_lines(res: Results) -> list[str]:
    """No tolerance below the step quantum (nothing if the profile's drive was not
    measured)."""
    stepr = [r for r in res.steps if r.microsteps == res.scene.profile.motors.microsteps
             and r.gear == res.scene.profile.motors.gear_ratio]
    if not stepr:
        return []
    s = stepr[0]
    below = sorted({r.tol for r in res.jobs if r.tol < s.quantum_max_mm}, reverse=True)
    return [
        f"- **No tolerance below the step quantum.** With the profile's drive "
        f"({s.microsteps} microsteps, gear {s.gear:g}) one step moves the pen by up to "
        f"{fmt_g(s.quantum_max_mm)} mm on the page region (median "
        f"{fmt_g(s.quantum_median_mm)} mm). " + (
            f"Tolerances below that ({', '.join(f'{t:g}' for t in below)} mm) "
            "multiply segments without lowering the measured deviation much: the "
            "quantised steps set the floor (chart 3, right)." if below else "")]


def policy_section(res: Results) -> list[str]:
    """"Model no more than a scene needs", with the figures of this run."""
    ci = _best(res.kin, "inverse", "closed form")
    cf = _best(res.kin, "forward", "closed form")
    return [*_closed_form_lines(ci, cf),
            *_approximation_lines(res, "inverse", ci),
            *_approximation_lines(res, "forward", cf),
            _linear_line(res, ci, cf),
            _nbar_line(res, cf),
            _segmentation_line(res),
            *_quantum_lines(res)]
