"""Safe region and page rectangle (kinematics.workspace), against analytic cases and dense
independent sampling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from kinematics.fivebar import FiveBar
from kinematics.workspace import (
    NoSafeRegionError,
    Rect,
    angles_within_limits,
    find_page_rectangle,
    largest_page_rectangle,
    point_safety,
    safe_mask,
)
from kinematics.workspace.rectangles import _max_rectangle

DEG = math.pi / 180.0
FB = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
LIMITS = ((10 * DEG, 170 * DEG), (10 * DEG, 170 * DEG))


def _dense_inside(fb: FiveBar, mode: str, rect: Rect, min1: float, min2: float,
                  limits: object, assembly: str | None, seed: int = 0) -> np.ndarray:
    """Independent check: 0.05 mm walk of the boundary plus 20 000 random interior points."""
    rng = np.random.default_rng(seed)
    n = max(8, math.ceil(2 * (rect.width + rect.height) / 0.05))
    t = np.linspace(0.0, 1.0, n)
    w, h = rect.width, rect.height
    edge = np.concatenate([
        np.stack((rect.x0 + t * w, np.full(n, rect.y0)), 1),
        np.stack((rect.x0 + t * w, np.full(n, rect.y1)), 1),
        np.stack((np.full(n, rect.x0), rect.y0 + t * h), 1),
        np.stack((np.full(n, rect.x1), rect.y0 + t * h), 1)])
    inner = np.stack((rect.x0 + rng.random(20000) * w, rect.y0 + rng.random(20000) * h), 1)
    pts = np.concatenate([edge, inner])
    return point_safety(fb, mode, pts, min1, min2, limits, assembly=assembly)  # type: ignore[arg-type]


def test_mask_layout_matches_meshgrid() -> None:
    xs = np.linspace(-50, 100, 31)
    ys = np.linspace(20, 150, 27)
    m = safe_mask(FB, "+-", xs, ys, 5 * DEG, 15 * DEG, LIMITS)
    assert m.shape == (27, 31)
    gx, gy = np.meshgrid(xs, ys)
    ref = point_safety(FB, "+-", np.stack((gx.ravel(), gy.ravel()), 1), 5 * DEG, 15 * DEG,
                       LIMITS).reshape(gx.shape)
    assert np.array_equal(m, ref)
    assert m.any() and not m.all()


@pytest.mark.parametrize("mode", ["++", "+-", "-+", "--"])
def test_reach_without_margins_is_the_intersection_of_annuli(mode: str) -> None:
    """With zero margins and no limits, the region (either assembly) is the set where both
    arms reach: lo_i ≤ |P − M_i| ≤ hi_i, circles about the motors — in every working mode —
    minus only the type-2 curve (measure zero). Points within 0.05 mm of a circle are skipped."""
    fb = FiveBar(70.0, 110.0, 70.0, 110.0, 60.0)
    xs = np.arange(-200.0, 260.0, 1.7)
    ys = np.arange(-200.0, 200.0, 1.7)
    m = safe_mask(fb, mode, xs, ys, 0.0, 0.0)
    gx, gy = np.meshgrid(xs, ys)
    d1 = np.hypot(gx, gy)
    d2 = np.hypot(gx - fb.w, gy)
    inside = (d1 <= 180) & (d1 >= 40) & (d2 <= 180) & (d2 >= 40)
    clear = ((np.abs(d1 - 180) > 0.05) & (np.abs(d1 - 40) > 0.05)
             & (np.abs(d2 - 180) > 0.05) & (np.abs(d2 - 40) > 0.05))
    assert np.array_equal(m[clear], inside[clear])


def test_type1_margin_shrinks_reach_to_law_of_cosines_circle() -> None:
    """A type-1 margin δ on a stretched arm is the angle between a and b lines; with P on the
    ray through M1 at distance c, arm 1's margin is the exterior angle at R1, so the outer
    boundary moves to c = √(a² + b² + 2ab·cos δ) (law of cosines, Eq. 23)."""
    fb = FiveBar(60.0, 90.0, 60.0, 90.0, 40.0)
    delta = 10 * DEG
    c_edge = math.sqrt(60**2 + 90**2 + 2 * 60 * 90 * math.cos(delta))
    # A ray from M1 at 70°: there |P − M2| ≈ 141 mm, arm 2 is ~41° from its own singularity.
    ang = 70 * DEG
    cs = np.array([c_edge - 0.02, c_edge + 0.02])
    pts = np.stack((cs * math.cos(ang), cs * math.sin(ang)), 1)
    ok = point_safety(fb, "+-", pts, delta, 0.0)
    assert list(ok) == [True, False]


def test_angles_within_limits_wraps() -> None:
    lim = ((-200 * DEG, -10 * DEG), (10 * DEG, 170 * DEG))
    th = np.array([[170 * DEG, 90 * DEG],     # 170° ≡ −190°: inside [−200, −10]
                   [-5 * DEG, 90 * DEG],      # outside
                   [90 * DEG, 90 * DEG],      # 90° ≡ −270°: outside
                   [-100 * DEG, 175 * DEG]])  # arm 2 outside
    assert list(angles_within_limits(th, lim)) == [True, False, False, False]


@pytest.mark.parametrize("mode", ["+-", "++", "-+"])
def test_free_rectangle_inside_and_locally_maximal(mode: str) -> None:
    min1, min2 = 5 * DEG, 15 * DEG
    fit = find_page_rectangle(FB, mode, min1, min2, LIMITS, resolution_mm=0.75)
    r = fit.rect
    assert r.width > 10 and r.height > 10
    assert _dense_inside(FB, mode, r, min1, min2, LIMITS, fit.assembly).all()
    # Undo the one-cell shrink and grow any one side by two more cells: that leaves the
    # safe region, so the search did not settle for a needlessly small rectangle.
    c = 0.75
    g = 3 * c
    for grown in (Rect(r.x0 - g, r.y0 - c, r.width + g + c, r.height + 2 * c),
                  Rect(r.x0 - c, r.y0 - g, r.width + 2 * c, r.height + g + c),
                  Rect(r.x0 - c, r.y0 - c, r.width + g + c, r.height + 2 * c),
                  Rect(r.x0 - c, r.y0 - c, r.width + 2 * c, r.height + g + c)):
        assert not point_safety(FB, mode, grown.sample(0.2), min1, min2, LIMITS,
                                assembly=fit.assembly).all()


def test_rectangle_avoids_mode_1a_hole() -> None:
    """In "++" with no limits the type-2 trace cuts a hole; the rectangle must not cover it
    even though the hole lies between safe points (a corner-only check would pass)."""
    min1, min2 = 3 * DEG, 10 * DEG
    fit = find_page_rectangle(FB, "++", min1, min2, None, resolution_mm=1.0,
                              bounds=(-150.0, 190.0, 0.0, 150.0))
    assert _dense_inside(FB, "++", fit.rect, min1, min2, None, fit.assembly).all()
    assert fit.rect.y0 >= 0.0


def test_max_rectangle_matches_brute_force() -> None:
    """The histogram search against exhaustive enumeration on random small grids, with the
    same objective: area after the one-cell shrink, (kx − 3)(ky − 3)."""
    rng = np.random.default_rng(3)
    for _ in range(40):
        ny, nx = rng.integers(5, 13, size=2)
        mask = rng.random((ny, nx)) < 0.85
        best = 0
        for j0 in range(ny):
            for j1 in range(j0, ny):
                for i0 in range(nx):
                    for i1 in range(i0, nx):
                        kx, ky = i1 - i0 + 1, j1 - j0 + 1
                        if kx > 3 and ky > 3 and mask[j0:j1 + 1, i0:i1 + 1].all():
                            best = max(best, (kx - 3) * (ky - 3))
        got = _max_rectangle(mask)
        if best == 0:
            assert got is None
        else:
            assert got is not None
            i0, i1, j0, j1 = got
            assert mask[j0:j1 + 1, i0:i1 + 1].all()
            assert (i1 - i0 - 2) * (j1 - j0 - 2) == best


@pytest.mark.parametrize("aspect", [297 / 210, 0.5, 2.5])
def test_aspect_rectangle(aspect: float) -> None:
    min1, min2 = 5 * DEG, 15 * DEG
    fit = find_page_rectangle(FB, "+-", min1, min2, LIMITS, aspect=aspect, resolution_mm=0.75)
    r = fit.rect
    assert r.width / r.height == pytest.approx(aspect, rel=1e-9)
    assert _dense_inside(FB, "+-", r, min1, min2, LIMITS, fit.assembly, seed=1).all()
    free = largest_page_rectangle(FB, "+-", min1, min2, LIMITS, resolution_mm=0.75)
    assert r.area <= free.area * 1.05


def test_assembly_sign_is_respected() -> None:
    min1, min2 = 5 * DEG, 15 * DEG
    plus = find_page_rectangle(FB, "+-", min1, min2, LIMITS, assembly="+")
    assert plus.assembly == "+"
    pts = plus.rect.sample(2.0)
    th = FB.inverse_batch(pts, "+-").require(pts)
    assert (FB.singularity_margins(th, pts)[:, 2] >= min2).all()


def test_no_safe_region_raises() -> None:
    with pytest.raises(NoSafeRegionError, match="no rectangle"):
        largest_page_rectangle(FB, "+-", 5 * DEG, 15 * DEG, LIMITS,
                               bounds=(200.0, 300.0, 0.0, 100.0))  # beyond reach
    with pytest.raises(ValueError, match="aspect"):
        largest_page_rectangle(FB, "+-", 0.0, 0.0, aspect=-1.0)
