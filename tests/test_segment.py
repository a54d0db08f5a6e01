"""Joint-space segmentation: the bound holds on the *interpolated* path (dense forward
kinematics of the joint chords, far denser than the refinement's samples) for random lines near
singularities; refused poses name the point and the reason."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from fivebar_host.config import load_profile
from fivebar_host.toolpath.segment import CheckFailedError, PoseChecker, refine

PROF = load_profile()
FB = PROF.geometry
LIM = PROF.motors.limits_rad
# Small margins so the lines come close to both singularity types.
NEAR = PoseChecker(FB, "+-", 1, math.radians(1.0), math.radians(3.0), LIM)
DEFAULT = PoseChecker(FB, "+-", 1, PROF.kinematics.min_type1_margin_rad,
                      PROF.kinematics.min_type2_margin_rad, LIM)


def dense_deviation(ch: PoseChecker, pa: np.ndarray, pb: np.ndarray, iv: object,
                    n: int = 64) -> np.ndarray:
    """Max distance of FK(θa + s·Δθ), s on a dense grid, from each piece's chord."""
    c, sa, sb = iv.chord, iv.sa, iv.sb  # type: ignore[attr-defined]
    tha, thb = iv.tha, iv.thb  # type: ignore[attr-defined]
    s = np.linspace(0, 1, n)
    th = (tha[:, None, :] + s[None, :, None] * (thb - tha)[:, None, :]).reshape(-1, 2)
    g = FB.forward_batch(th, "+" if ch.assembly > 0 else "-").points.reshape(-1, n, 2)
    qa = pa[c] + sa[:, None] * (pb[c] - pa[c])
    qb = pa[c] + sb[:, None] * (pb[c] - pa[c])
    seg = qb - qa
    u = np.clip(np.einsum("nsj,nj->ns", g - qa[:, None], seg)
                / np.einsum("nj,nj->n", seg, seg)[:, None], 0, 1)
    d = g - qa[:, None] - u[..., None] * seg[:, None]
    return np.sqrt((d**2).sum(-1)).max(axis=1)


def _near_singular_pool(n: int = 40_000) -> np.ndarray:
    """Points of the +- / assembly + workspace that pass NEAR's checks but lie close to a
    singularity (type-1 margin < 12° or type-2 margin < 12°), from random joint angles."""
    rng = np.random.default_rng(11)
    th = rng.uniform(math.radians(10), math.radians(170), (n, 2))
    fk = FB.forward_batch(th, "+")
    p = fk.points[fk.valid]
    inv = FB.inverse_batch(p, "+-")
    p, ang = p[inv.valid], inv.angles[inv.valid]
    code, m = NEAR.codes(ang, p)
    near = (code == 0) & ((m[:, :2].min(axis=1) < math.radians(12))
                          | (m[:, 2] < math.radians(12)))
    return p[near]


POOL = _near_singular_pool()


@st.composite
def near_singular_line(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    p = POOL[draw(st.integers(min_value=0, max_value=POOL.shape[0] - 1))]
    ang = draw(st.floats(min_value=0.0, max_value=2 * math.pi))
    length = draw(st.floats(min_value=0.5, max_value=20.0))
    return p, p + length * np.array([math.cos(ang), math.sin(ang)])


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow])
@given(near_singular_line(), st.sampled_from([0.2, 0.05, 0.01]))
def test_bound_holds_on_interpolated_path_near_singularities(
        line: tuple[np.ndarray, np.ndarray], tol: float) -> None:
    pa, pb = (x.reshape(1, 2) for x in line)
    ends = np.concatenate((pa, pb))
    inv = FB.inverse_batch(ends, "+-")
    assume(inv.valid.all())
    asm = FB.assembly_of(inv.angles, ends)
    assume(asm[0] == asm[1] == 1)
    try:
        th = NEAR.inverse(ends)
        iv = refine(NEAR, pa, pb, th[:1], th[1:], np.array([tol]), 0.05)
    except CheckFailedError:
        assume(False)
        return
    m = FB.singularity_margins(iv.tha, FB.forward_batch(iv.tha, "+").points)
    dev = dense_deviation(NEAR, pa, pb, iv)
    assert dev.max() <= tol, (dev.max(), tol, np.degrees(np.abs(m).min()))
    # pieces tile the chord
    assert iv.sa[0] == 0.0 and iv.sb[-1] == 1.0
    assert np.allclose(iv.sa[1:], iv.sb[:-1])


def test_denser_near_singularity_sparser_in_the_middle() -> None:
    # the same 20 mm horizontal line in the well-conditioned middle and near the outer reach
    # (arm 2 almost stretched, a type-1 singularity): more segments where the map bends more
    def count(y: float) -> int:
        pa, pb = np.array([[10.0, y]]), np.array([[30.0, y]])
        th = NEAR.inverse(np.concatenate((pa, pb)))
        return refine(NEAR, pa, pb, th[:1], th[1:], np.array([0.01]), 10.0).chord.shape[0]

    assert count(146.0) >= 1.5 * count(110.0)


def test_unreachable_point_is_named() -> None:
    with pytest.raises(CheckFailedError) as ei:
        DEFAULT.inverse(np.array([[20.0, 110.0], [20.0, 160.0]]))
    assert ei.value.index == 1 and ei.value.reason == "reach"
    assert ei.value.point == (20.0, 160.0)
    assert "beyond arm 1's reach" in ei.value.message


def test_too_close_to_type2_is_named() -> None:
    # Grid points of the +- workspace (assembly +) with healthy type-1 margins whose type-2
    # margin is under the 15° minimum, found independently from FiveBar's margins.
    wide = PoseChecker(FB, "+-", 1, PROF.kinematics.min_type1_margin_rad,
                       PROF.kinematics.min_type2_margin_rad,
                       ((-math.pi, math.pi), (-math.pi, math.pi)))
    gx, gy = np.meshgrid(np.arange(-150.0, 190.0, 2.0), np.arange(-150.0, 151.0, 2.0))
    pts = np.stack((gx.ravel(), gy.ravel()), axis=1)
    inv = FB.inverse_batch(pts, "+-")
    m = np.degrees(FB.singularity_margins(inv.angles, pts)) * [1, -1, 1]
    sel = inv.valid & (m[:, :2].min(axis=1) >= 6.0) & (m[:, 2] > 1.0) & (m[:, 2] < 14.0)
    assert sel.sum() > 20
    for p, mm in zip(pts[sel][::10], m[sel][::10], strict=True):
        with pytest.raises(CheckFailedError) as ei:
            wide.inverse(p.reshape(1, 2))
        assert ei.value.reason == "type2_margin", ei.value.message
        assert ei.value.point == (p[0], p[1])
        assert f"{mm[2]:.2f}° from collinear (type-2 singularity)" in ei.value.message


def test_line_crossing_unsafe_zone_between_safe_ends_is_refused() -> None:
    # both ends are safe; the straight line between them leaves the (non-convex) safe region
    pa, pb = np.array([[-40.0, 103.0]]), np.array([[20.0, 66.0]])
    th = DEFAULT.inverse(np.concatenate((pa, pb)))  # the ends pass
    mid = (pa + pb) / 2
    with pytest.raises(CheckFailedError):
        DEFAULT.inverse(mid)  # the middle does not
    with pytest.raises(CheckFailedError) as ei:
        refine(DEFAULT, pa, pb, th[:1], th[1:], np.array([0.05]), 0.05)
    x, y = ei.value.point
    # the named point lies on the line, strictly between the ends
    t = (x - pa[0, 0]) / (pb[0, 0] - pa[0, 0])
    assert 0 < t < 1 and abs(pa[0, 1] + t * (pb[0, 1] - pa[0, 1]) - y) < 1e-6
