"""Design search and working-mode transitions (kinematics.design, kinematics.modes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinematics.design import _screen, design_search
from kinematics.fivebar import FiveBar
from kinematics.modes import plan_joint_move, plan_working_modes
from kinematics.workspace import (
    NoSafeRegionError,
    Rect,
    find_page_rectangle,
    measures,
    page_stats,
    point_safety,
)

DEG = math.pi / 180.0
LIMITS = ((10 * DEG, 170 * DEG), (10 * DEG, 170 * DEG))
STEP = 2 * math.pi / 12800


@pytest.mark.parametrize("mode", ["+-", "++"])
def test_vectorised_screen_agrees_with_point_test(mode: str) -> None:
    """The broadcasting kernel of the design search against `point_safety` and `measures`
    (the FiveBar code path) on random geometries and points."""
    rng = np.random.default_rng(5)
    geo = np.column_stack([rng.uniform(40, 120, 30), rng.uniform(60, 180, 30),
                           rng.uniform(40, 120, 30), rng.uniform(60, 180, 30),
                           rng.uniform(10, 80, 30)])
    x = rng.uniform(-150, 250, (30, 1, 60))
    y = rng.uniform(-50, 250, (30, 1, 60))
    feas_pt = []
    for c in range(30):
        fb = FiveBar(*geo[c])
        pts = np.stack((x[c, 0], y[c, 0]), 1)
        ok = point_safety(fb, mode, pts, 5 * DEG, 10 * DEG, LIMITS)
        feas_pt.append(ok)
        # One point per "placement", so the screen's feasibility is per point.
        f, mud, sens = _screen(geo[c:c + 1], x[c:c + 1].reshape(1, 60, 1),
                               y[c:c + 1].reshape(1, 60, 1), mode, 5 * DEG, 10 * DEG, LIMITS)
        np.testing.assert_array_equal(f[0], ok)
        pm = measures(fb, mode, pts)
        v = ok
        np.testing.assert_allclose(mud[0][v], np.abs(pm.mu[v] - math.pi / 2).max(axis=1),
                                   atol=1e-9)
        np.testing.assert_allclose(sens[0][v], pm.sens[v].max(axis=1), rtol=1e-9)
    assert np.concatenate(feas_pt).any() and not np.concatenate(feas_pt).all()


def test_design_search_returns_pages_that_fit() -> None:
    """Every returned design carries its page inside the safe region (dense independent
    sampling) and the `workspace` page check (fixed-aspect grid search) finds room for it."""
    res = design_search(60.0, 40.0, "+-", 5 * DEG, 15 * DEG, LIMITS, STEP, n_candidates=1500,
                        seed=1, top=3)
    assert res.evaluated == 1500 and res.feasible > 0 and res.candidates
    scores = [c.score for c in res.candidates]
    assert scores == sorted(scores)
    for c in res.candidates:
        fb, page = c.geometry, c.page
        assert (page.width, page.height) == (60.0, 40.0)
        pts = page.sample(0.4, 0.1)
        assert point_safety(fb, "+-", pts, 5 * DEG, 15 * DEG, LIMITS,
                            assembly=c.stats.assembly).all()
        fit = find_page_rectangle(fb, "+-", 5 * DEG, 15 * DEG, LIMITS, aspect=1.5)
        assert fit.rect.height >= 40.0
        st = page_stats(fb, "+-", page, STEP)
        assert c.score == pytest.approx(st.worst_mu_dev_rad / (50 * DEG)
                                        + st.worst_sens_mm_per_rad / math.hypot(60, 40))


def test_design_search_fixed_spacing_and_impossible_page() -> None:
    res = design_search(50.0, 30.0, "+-", 5 * DEG, 15 * DEG, LIMITS, STEP, n_candidates=600,
                        motor_spacing=25.0, seed=2, top=2)
    assert res.candidates and all(c.geometry.w == 25.0 for c in res.candidates)
    # Margins of 60° for both types leave (almost) nothing: no candidate may be returned
    # unless it truly passes.
    hard = design_search(50.0, 30.0, "+-", 60 * DEG, 60 * DEG, LIMITS, STEP, n_candidates=300,
                         seed=3)
    for c in hard.candidates:
        assert c.stats.min_type1_rad >= 60 * DEG - 1e-9
    with pytest.raises(ValueError, match="page size"):
        design_search(0.0, 30.0, "+-", 0.0, 0.0, None, STEP)


def test_page_stats_refuses_page_across_singularity() -> None:
    fb = FiveBar(100.0, 60.0, 100.0, 60.0, 50.0)
    with pytest.raises(NoSafeRegionError):
        page_stats(fb, "+-", Rect(-20.0, 50.0, 80.0, 60.0), STEP)  # straddles the 1a loop


# ----------------------------------------------------------------------------- transitions
FB = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)


def _line(p: tuple[float, float], q: tuple[float, float], n: int) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray(p) + t * (np.asarray(q) - np.asarray(p))


def test_plan_switches_mode_through_a_type1_singularity() -> None:
    """With joint limits of 10–170°, the lower right (x ≈ 75, y 40–65) is out of reach in
    mode "+-" (θ2 would go below 10°) but safe in "++": the plan draws the centre in "+-",
    lifts the pen, drives arm 2 through its stretched singularity into "++", and back."""
    strokes = [_line((0, 120), (40, 120), 41), _line((75, 40), (75, 65), 26),
               _line((75, 100), (10, 100), 66)]
    min1, min2 = 5 * DEG, 15 * DEG
    home = np.radians([120.0, 60.0])
    plan = plan_working_modes(FB, strokes, "+-", min1, min2, LIMITS, assembly="+",
                              start_angles=home)
    assert [(p.stroke, p.mode) for p in plan.pieces] == [(0, "+-"), (1, "++"), (2, "+-")]
    assert len(plan.transitions) == 2 and len(plan.describe()) == 2
    for k, piece in enumerate(plan.pieces):
        pts = strokes[piece.stroke][piece.start:piece.stop]
        assert point_safety(FB, piece.mode, pts, min1, min2, LIMITS, assembly="+").all()
        t = piece.transition
        if t is None:
            continue
        prev = plan.pieces[k - 1]
        last = strokes[prev.stroke][prev.stop - 1]
        first = strokes[piece.stroke][piece.start]
        np.testing.assert_allclose(t.pen_path[0], last, atol=1e-9)
        np.testing.assert_allclose(t.pen_path[-1], first, atol=1e-9)
        # Continuity, assembly kept, type-2 margin kept, joint limits kept.
        assert np.abs(np.diff(t.joint_path, axis=0)).max() <= 0.5 * DEG + 1e-12
        fw = FB.forward_batch(t.joint_path, "+")
        assert fw.valid.all()
        np.testing.assert_allclose(fw.points, t.pen_path, atol=1e-12)
        assert (FB.singularity_margins(t.joint_path, t.pen_path)[:, 2] >= min2).all()
        lo, hi = 10 * DEG - 1e-12, 170 * DEG + 1e-12
        assert ((t.joint_path >= lo) & (t.joint_path <= hi)).all()
        # The mode at both ends, and exactly arm 2 crossing its type-1 singularity.
        ends = FB.mode_of(t.pen_path[[0, -1]], t.joint_path[[0, -1]])
        name = ["".join("+" if v > 0 else "-" for v in row) for row in ends]
        assert name == [t.from_mode, t.to_mode]
        # Each arm whose sign changes crosses its type-1 singularity an odd number of times,
        # the other an even number; the crossings lie on the reach circles.
        for arm in (1, 2):
            n = sum(1 for c in t.crossings if c[0] == arm)
            assert n % 2 == (t.from_mode[arm - 1] != t.to_mode[arm - 1])
        assert any(c[0] == 2 for c in t.crossings)
        for arm, kind, x, y in t.crossings:
            d = math.hypot(x - (0.0 if arm == 1 else FB.w), y)
            assert abs(d - (150.0 if kind == "stretched" else 30.0)) < 1.0


def test_plan_splits_a_stroke_and_keeps_the_joining_segment() -> None:
    """(15, 70) is safe only in "+-", (60, 90) only in "++": one stroke between them is
    split, the pen lifts, the mode changes, and drawing resumes at the last point drawn."""
    stroke = _line((15, 70), (60, 90), 80)
    for mode, end in (("+-", 0), ("++", -1)):
        other = "++" if mode == "+-" else "+-"
        assert point_safety(FB, mode, stroke[[end]], 5 * DEG, 15 * DEG, LIMITS, assembly="+")[0]
        assert not point_safety(FB, other, stroke[[end]], 5 * DEG, 15 * DEG, LIMITS,
                                assembly="+")[0]
    plan = plan_working_modes(FB, [stroke], "+-", 5 * DEG, 15 * DEG, LIMITS, assembly="+",
                              start_angles=np.radians([120.0, 60.0]))
    assert [p.mode for p in plan.pieces] == ["+-", "++"]
    a, b = plan.pieces[0], plan.pieces[1]
    assert b.start == a.stop - 1  # the segment between the pieces is drawn after the switch
    assert b.transition is not None and a.mode != b.mode
    assert plan.pieces[-1].stop == stroke.shape[0]


def test_plan_refuses_unsafe_points_with_a_clear_error() -> None:
    with pytest.raises(NoSafeRegionError, match="stroke 0 point 1"):
        plan_working_modes(FB, [np.array([[20.0, 120.0], [0.0, 10.0]])], "+-", 5 * DEG,
                           15 * DEG, LIMITS, assembly="+")
    with pytest.raises(ValueError, match="assembly"):
        plan_working_modes(FB, [], "+-", 0.0, 0.0, assembly=None)  # type: ignore[arg-type]


def test_joint_move_detours_around_the_mode_1a_hole() -> None:
    """Short floating links: the safe region of mode "+-", assembly "+", is a ring around the
    Mode 1a hole. From below the base to above it the straight joint-space line runs into the
    type-2 singularity; the planner must go round, keeping the margin all the way."""
    fb = FiveBar(100.0, 60.0, 100.0, 60.0, 50.0)
    p, q = (25.0, -125.0), (25.0, 125.0)
    a = np.asarray(fb.inverse(p, "+-"))
    b = np.asarray(fb.inverse(q, "+-"))
    b = a + np.mod(b - a + math.pi, 2 * math.pi) - math.pi
    direct = a + np.linspace(0, 1, 400)[:, None] * (b - a)
    fw = fb.forward_batch(direct, "+")
    assert not (fw.valid.all()
                and (fb.singularity_margins(direct, fw.points)[:, 2] >= 15 * DEG).all())
    got = plan_joint_move(fb, a, b, "+", 15 * DEG, None)
    assert got is not None
    path, pen, m2 = got
    np.testing.assert_allclose(pen[[0, -1]], [p, q], atol=1e-9)
    assert m2 >= 15 * DEG
    assert np.abs(np.diff(path, axis=0)).max() <= 0.5 * DEG + 1e-12
    check = fb.forward_batch(path, "+")
    assert check.valid.all()
    assert (fb.singularity_margins(path, check.points)[:, 2] >= 15 * DEG).all()
