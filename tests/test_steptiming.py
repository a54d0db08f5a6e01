"""benchmarks/steptiming.py against hand-made edge lists with known answers."""

from __future__ import annotations

import math

import pytest

from benchmarks import steptiming as st


def test_segment_schedule_is_the_dda_midpoints() -> None:
    # 4 steps over 100 cycles: the middles of 25-cycle intervals, floored
    assert st.segment_schedule(1000, 100, 4) == [1012, 1037, 1062, 1087]
    # 3 steps over 10 cycles: floor(10/6), floor(30/6), floor(50/6)
    assert st.segment_schedule(0, 10, 3) == [1, 5, 8]
    assert st.segment_schedule(5, 10, 0) == []
    with pytest.raises(ValueError):
        st.segment_schedule(0, 0, 1)


def test_perfect_edges_give_zero_for_both_definitions() -> None:
    ideal = st.segment_schedule(0, 160_000, 437)
    # a constant latency is no jitter: the median removes it
    edges = [t + 37 for t in ideal]
    assert st.summarize(st.strict_deviations(edges, ideal)) == st.Jitter(0.0, 0.0, 437)
    assert st.summarize(st.interval_deviations(edges, ideal)) == st.Jitter(0.0, 0.0, 436)


@pytest.mark.parametrize("d", [1, -5, 40])
@pytest.mark.parametrize("k", [0, 17, 99])
def test_one_edge_moved_by_d(d: int, k: int) -> None:
    n = 100
    ideal = [400 * i for i in range(n)]
    edges = list(ideal)
    edges[k] += d
    strict = st.summarize(st.strict_deviations(edges, ideal))
    assert strict.max_abs == abs(d)
    assert strict.rms == pytest.approx(abs(d) / math.sqrt(n))
    inter = st.summarize(st.interval_deviations(edges, ideal))
    assert inter.max_abs == abs(d)
    # an end edge changes one interval, an inner edge two (by +d and -d)
    changed = 1 if k in (0, n - 1) else 2
    assert inter.rms == pytest.approx(abs(d) * math.sqrt(changed / (n - 1)))


def test_alternating_edges() -> None:
    # edges alternately 3 cycles late and on time: deviations {0, 3}, median 1.5
    ideal = [100 * i for i in range(10)]
    edges = [t + 3 * (i % 2) for i, t in enumerate(ideal)]
    strict = st.summarize(st.strict_deviations(edges, ideal))
    assert strict == st.Jitter(1.5, 1.5, 10)
    # whole cycles: the median 1.5 truncates to 1, deviations -1 and +2
    whole = st.strict_deviations(edges, ideal, whole_cycles=True)
    assert sorted(set(whole)) == [-1, 2]
    inter = st.summarize(st.interval_deviations(edges, ideal))
    assert inter == st.Jitter(3.0, 3.0, 9)


def test_interval_jitter_shows_a_rate_error_as_a_bias() -> None:
    ideal = [364 * i for i in range(50)]
    edges = [365 * i for i in range(50)]
    inter = st.summarize(st.interval_deviations(edges, ideal))
    assert inter == st.Jitter(1.0, 1.0, 49)
    # the strict figure accumulates it: edge i is i-24.5 cycles off the median
    strict = st.summarize(st.strict_deviations(edges, ideal))
    assert strict.max_abs == 24.5


def test_fit_interval_and_even_jitter() -> None:
    # 1000 edges at 363.6 cycles, rounded to whole cycles: fitted back, jitter < 1 cycle
    edges = [round(50 + 363.6 * k) for k in range(1000)]
    assert st.fit_interval(edges) == pytest.approx(363.6, abs=1e-4)
    strict, inter, interval = st.even_jitter(edges)
    assert interval == pytest.approx(363.6, abs=1e-4)
    assert strict.max_abs <= 0.5 + 1e-6
    assert inter.max_abs <= 1.0 + 1e-6
    # rounding errors are uniform on [-0.5, 0.5]: RMS about 1/sqrt(12)
    assert strict.rms == pytest.approx(1 / math.sqrt(12), rel=0.1)
    # one edge 100 cycles late among 1000: it dominates both maxima
    edges[500] += 100
    strict, inter, _ = st.even_jitter(edges)
    assert strict.max_abs == pytest.approx(100, abs=1.0)
    assert inter.max_abs == pytest.approx(100, abs=1.0)
    with pytest.raises(ValueError):
        st.fit_interval([5])


def test_mismatched_lengths_are_refused() -> None:
    with pytest.raises(ValueError):
        st.strict_deviations([1, 2], [1])
    with pytest.raises(ValueError):
        st.interval_deviations([1], [1, 2])
    assert st.summarize([]) == st.Jitter(0.0, 0.0, 0)
