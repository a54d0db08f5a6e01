"""A plan never gets longer when a limit is raised, and the feed really sets the drawing time
(issue 20: 5 × 1000 chords of 0.1 mm planned 6.2 s at 100 mm/s, 15 rad/s, 600 rad/s² and
29.6 s at 200 / 30 / 1200 — the old staircase repair's cascade, planner module doc).

Three levels:
- the staircase durations on given segments (`staircase.enforce_staircase`) are the least that
  meet every limit, so they are *exactly* monotone: raising α, the junction jump or lowering
  the floor never lengthens any segment, to the µs;
- whole compiled jobs (seeded random drawings and limit pairs, `tests/plan_jobs.py`): the
  raised set's plan is no longer than the base's, up to `REL_TOL` — the cut into pieces may
  move when the feed, the joint speed or a small α change (`compile.timing.cut_accel`), and
  with it the whole steps each piece gets;
- issue 20's circle job: the four limit sets of the issue, and doubling the feed halves the
  drawing part.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from benchmarks.plan_jobs import (
    circle_job,
    compiled,
    draw_s,
    plan_s,
    random_job,
    random_limits,
    with_limits,
)
from fivebar_host.compile import staircase
from fivebar_host.config import load_profile

PROF = load_profile()
#: Allowance on "never longer" for whole jobs. On given pieces the plan is exactly monotone
#: (first test); a raised feed or joint speed (or α below `compile.timing.cut_accel`'s cap)
#: may re-cut a ramp — pieces end at new fractions of their segment, each rounded to whole
#: steps, and a piece of 2 steps whose rounding moves by one step changes its rate by a
#: half, which the staircase then ramps around. Measured on 440 seeded random jobs and limit
#: pairs: 2 plans longer, by at most 0.05 % (with pieces of 3 steps none; with the cut cap
#: at 0.35 instead of 0.25 of J²/D_min: one, by 0.19 %). 0.5 % leaves that room while any
#: cascade like issue 20's (×1.6 to ×8 on these jobs before the fix) fails by far.
REL_TOL = 0.005


@pytest.mark.parametrize("seed", range(30))
def test_staircase_durations_exactly_monotone_in_the_limits(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 120))
    d = rng.normal(0, 0.01, (n, 2))
    d[rng.random(n) < 0.2] *= 0.1  # some short segments
    d[rng.random(n) < 0.1, int(rng.integers(2))] = 0.0  # a joint standing still
    stop = rng.random(n) < 0.1
    floor = rng.integers(100, 20_000, n)
    alpha, jump = float(rng.uniform(10, 2000)), float(rng.uniform(0.1, 2.0))
    base = staircase.enforce_staircase(d, floor, stop, alpha, jump)
    jr, ar = staircase.staircase_ratios(d, base, stop, alpha, jump)
    assert jr.max() <= 1 + 1e-9 and ar.max() <= 1 + 1e-9 and (base >= floor).all()
    lower_floor = np.maximum(floor - rng.integers(0, 5000, n), 1)
    for raised in (staircase.enforce_staircase(d, floor, stop, alpha * rng.uniform(1, 4), jump),
                   staircase.enforce_staircase(d, floor, stop, alpha, jump * rng.uniform(1, 4)),
                   staircase.enforce_staircase(d, lower_floor, stop, alpha, jump)):
        assert (raised <= base).all()


@pytest.mark.parametrize("seed", range(40))
def test_raising_any_limit_never_lengthens_the_plan(seed: int) -> None:
    svg = random_job(seed)
    base, raised = random_limits(seed)
    t_base = plan_s(compiled(svg, with_limits(PROF, base)))
    t_raised = plan_s(compiled(svg, with_limits(PROF, raised)))
    assert t_raised <= t_base * (1 + REL_TOL), (base, raised, t_base, t_raised)


# ------------------------------------------------------- issue 20's job: 5 × 1000 chords
#: (draw feed, joint speed, joint acceleration) of the issue, ordered so that each set raises
#: a limit of the one before.
ISSUE_SETS = [(100.0, 15.0, 600.0), (150.0, 15.0, 600.0), (200.0, 15.0, 600.0),
              (200.0, 30.0, 1200.0)]


def _circle_plan(feed: float, w: float, a: float) -> tuple[float, float]:
    job = compiled(circle_job(), with_limits(PROF, (feed, PROF.motion.travel_feed_mm_s, w, a)))
    return plan_s(job), draw_s(job)


def test_issue_job_higher_limits_never_plan_longer() -> None:
    """main before the fix: 6.19, 26.22, 19.97, 29.62 s."""
    times = [_circle_plan(*s)[0] for s in ISSUE_SETS]
    for t0, t1 in itertools.pairwise(times):
        assert t1 <= t0 * (1 + REL_TOL), times


def test_issue_job_doubling_the_feed_halves_the_drawing() -> None:
    """At 15 rad/s and 600 rad/s² the feed binds: 500 mm at 100 and 200 mm/s is 5.0 and
    2.5 s plus the run-up out of and into rest, which the feed hardly shortens (main before
    the fix: 5.13 → 18.80 s, ×3.7)."""
    ratio = _circle_plan(200.0, 15.0, 600.0)[1] / _circle_plan(100.0, 15.0, 600.0)[1]
    assert ratio == pytest.approx(0.5, abs=0.03)
