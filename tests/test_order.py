"""Path order: reordering and reversing never change the geometry, never make travel worse
than the file's order, and the greedy stage equals a brute-force nearest neighbour."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

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
