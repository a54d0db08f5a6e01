"""Path order: reordering and reversing never change the geometry, never make travel worse
than the file's order nor the nearest-neighbour order, the greedy stage equals a brute-force
nearest neighbour, a convex case reaches its known optimum, and sections stay apart."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fivebar_host.compile.chords import _order
from fivebar_host.toolpath import tour
from fivebar_host.toolpath.order import _greedy, order_paths, travel_length


@settings(max_examples=30, deadline=None)
@given(st.integers(min_value=1, max_value=120), st.integers(min_value=0, max_value=2**31))
def test_order_is_a_permutation_and_never_worse(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    s = rng.uniform(0, 100, (n, 2))
    e = s + rng.normal(0, 5, (n, 2))
    home = np.array([50.0, -20.0])
    o = order_paths(s, e, home, home)
    assert sorted(o.order.tolist()) == list(range(n))
    assert o.travel_after_mm <= o.travel_before_mm + 1e-9
    assert abs(travel_length(s, e, o.order, o.reverse, home, home) - o.travel_after_mm) < 1e-9
    # geometry: each path, as drawn (possibly reversed), is the original one
    drawn = {(int(p), bool(r)) for p, r in zip(o.order, o.reverse, strict=True)}
    for p, r in drawn:
        a, b = (e[p], s[p]) if r else (s[p], e[p])
        assert {tuple(a), tuple(b)} == {tuple(s[p]), tuple(e[p])}


def test_greedy_equals_brute_force() -> None:
    rng = np.random.default_rng(3)
    n = 150
    s = rng.uniform(0, 100, (n, 2))
    e = s + rng.normal(0, 3, (n, 2))
    order, rev = _greedy(s, e, np.zeros(2))
    pos = np.zeros(2)
    alive = set(range(n))
    for k in range(n):
        best = min(((float(np.hypot(*(pt - pos))), p, r) for p in sorted(alive)
                    for r, pt in ((False, s[p]), (True, e[p]))))
        assert (order[k], rev[k]) == (best[1], best[2])
        alive.remove(best[1])
        pos = s[best[1]] if best[2] else e[best[1]]


def test_keep_order() -> None:
    s = np.array([[0.0, 0.0], [50.0, 0.0], [1.0, 0.0]])
    e = s + 0.5
    o = order_paths(s, e, np.zeros(2), keep_order=True)
    assert o.order.tolist() == [0, 1, 2] and not o.reverse.any()


def _convex_case(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Short chords of a circle at irregular angles, shuffled and randomly reversed, and a
    home point on the circle between the last and the first: every endpoint is on the
    convex hull, so the shortest closed tour is the polygon in angular order (each chord
    drawn along it), and its travel is the perimeter less the chords."""
    rng = np.random.default_rng(seed)
    gaps = rng.uniform(0.2, 1.0, 2 * n + 1)
    ang = np.cumsum(gaps) / gaps.sum() * 2 * np.pi  # the last one is the home point
    pts = 50.0 * np.stack((np.cos(ang), np.sin(ang)), axis=1)
    s, e = pts[0:2 * n:2], pts[1:2 * n:2]
    home = pts[-1]
    ring = np.concatenate((pts, pts[:1]))
    perimeter = float(np.hypot(*np.diff(ring, axis=0).T).sum())
    optimum = perimeter - float(np.hypot(*(e - s).T).sum())
    perm = rng.permutation(n)
    flip = rng.random(n) < 0.5
    s2 = np.where(flip[:, None], e[perm], s[perm])
    e2 = np.where(flip[:, None], s[perm], e[perm])
    return s2, e2, home, optimum


@pytest.mark.parametrize("seed", range(12))
def test_convex_case_reaches_the_known_optimum(seed: int) -> None:
    n = 10 + 7 * seed
    s, e, home, optimum = _convex_case(n, seed)
    o = order_paths(s, e, home, home)
    assert o.travel_after_mm == pytest.approx(optimum, rel=1e-9, abs=1e-9)
    assert sorted(o.order.tolist()) == list(range(n))


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=2, max_value=300), st.integers(min_value=0, max_value=2**31),
       st.booleans(), st.booleans())
def test_never_worse_than_nearest_neighbour(n: int, seed: int, park: bool,
                                            home_start: bool) -> None:
    rng = np.random.default_rng(seed)
    s = rng.uniform(0, 100, (n, 2))
    # clusters and coincident endpoints, as drawings have
    s = np.round(s / 10) * 10 if seed % 3 == 0 else s
    e = s + rng.normal(0, 4, (n, 2))
    home = np.array([0.0, 0.0])
    start = home if home_start else None  # None: the tour may begin anywhere
    end = home if park else None
    g_order, g_rev = _greedy(s, e, home if home_start else s[0])
    greedy = travel_length(s, e, g_order, g_rev, start, end)
    o = order_paths(s, e, start, end)
    assert sorted(o.order.tolist()) == list(range(n))
    assert o.travel_after_mm <= greedy + 1e-9
    assert travel_length(s, e, o.order, o.reverse, start, end) == pytest.approx(
        o.travel_after_mm, abs=1e-9)


def test_sections_are_ordered_on_their_own() -> None:
    """With pen-change stops each section is ordered alone, in section order: every path of
    a section comes before any of the next, each path exactly once."""
    rng = np.random.default_rng(5)
    n = 400
    s = rng.uniform(0, 100, (n, 2))
    e = s + rng.normal(0, 3, (n, 2))
    sec = rng.integers(0, 4, n)
    od = _order(s, e, np.zeros(2), False, sec)
    assert sorted(od.order.tolist()) == list(range(n))
    assert (np.diff(sec[od.order]) >= 0).all()


def test_tour_moves_keep_the_strokes_and_count_their_gain() -> None:
    """Every 2-opt and Or-opt move changes the travel by exactly its computed gain and the
    tour stays a permutation with consistent positions and directions."""
    rng = np.random.default_rng(11)
    for trial in range(150):
        n = int(rng.integers(2, 14))
        s = rng.uniform(0, 10, (n, 2))
        e = s + rng.normal(0, 2, (n, 2))
        start = None if trial % 3 == 0 else rng.uniform(0, 10, 2)
        end = None if trial % 2 else rng.uniform(0, 10, 2)
        t = tour.Tour(s, e, rng.permutation(n), rng.random(n) < 0.5, start, end)
        for _ in range(15):
            x, y, z = (int(v) for v in rng.integers(0, 2 * n + 1 + (end is not None), 3))
            mv = tour._move_2opt(t, x, y)
            if mv is not None:
                before = t.length()
                t.reverse(mv[0], mv[1])
                assert before - t.length() == pytest.approx(mv[2], abs=1e-9)
            for mo in (tour._oropt_now(t, x, y, int(rng.integers(1, 4)), -1),
                       tour._oropt_now(t, x, y, 0, z)):  # a short block, a long one
                if mo is not None:
                    g = tour._gain_oropt1(t, *mo)
                    before = t.length()
                    t.move(*mo)
                    assert before - t.length() == pytest.approx(g, abs=1e-9)
            p = t.path[1:n + 1]
            assert sorted(p.tolist()) == list(range(n))
            assert (t.pos[p] == np.arange(1, n + 1)).all()
            r = t.rev[1:n + 1, None]
            assert np.array_equal(np.stack((t.ax, t.ay), 1)[1:n + 1],
                                  np.where(r, e[p], s[p]))
