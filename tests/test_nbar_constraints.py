"""Constraint equations of the n-bar solver against central finite differences.

Every exact equation (Eqs. 1–9 and the sine form of the planar PP link) is checked with all its
partial derivatives, homogenising factors included, at random points and non-unit lines; the
compiled quadratic-form system used by the Newton loop is checked against finite differences
of itself everywhere and against the exact equations on the normalisation manifold (Eq. 8).
The batched exact residuals (`exact_residuals`, `Mechanism.residuals`) are checked against the
per-constraint functions applied row by row.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from kinematics.nbar import Mechanism, parse_mechanism
from kinematics.nbar import constraints as cst

CONFIGS = sorted((Path(__file__).resolve().parent.parent / "configs" / "mechanisms").glob(
    "*.toml"))
RNG = np.random.default_rng(20200526)


def central_diff(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, h: float = 1e-6
                 ) -> np.ndarray:
    """Jacobian of f at x by central differences: (…, len(x))."""
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def _pair_check(fn: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray]], a: np.ndarray,
                b: np.ndarray, *args: float) -> None:
    c, da, db = fn(a, b, *args)
    na = a.size
    x = np.concatenate((a, b))

    def value(v: np.ndarray) -> np.ndarray:
        return np.asarray(fn(v[:na], v[na:], *args)[0])

    fd = central_diff(value, x)
    assert np.isfinite(c)
    np.testing.assert_allclose(np.concatenate((da, db)), fd, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("dim", [2, 3])
def test_rr_derivatives_with_homogenising_factors(dim: int) -> None:
    """Eq. 1 / Eq. 2 with free weights a_w, b_w: every partial matches central differences."""
    for _ in range(20):
        a = np.append(RNG.normal(size=dim), RNG.uniform(0.5, 2.0))
        b = np.append(RNG.normal(size=dim), RNG.uniform(0.5, 2.0))
        _pair_check(cst.rr, a, b, float(RNG.uniform(0.2, 3.0)))


def test_rr_value_is_the_distance_condition() -> None:
    """C = a_w b_w (r² − |a/a_w − b/b_w|²): zero exactly at the prescribed distance."""
    a = np.array([2.0, 4.0, 2.0])  # (1, 2) with w = 2
    b = np.array([4.0, 2.0, 1.0])  # (4, 2)
    r = np.hypot(3.0, 0.0)
    assert cst.rr(a, b, r)[0] == pytest.approx(0.0, abs=1e-12)
    assert cst.rr(a, b, 2.0)[0] == pytest.approx(2.0 * 1.0 * (4.0 - 9.0))


@pytest.mark.parametrize("dim", [2, 3])
def test_rp_derivatives(dim: int) -> None:
    """Eqs. 3–5 (point, line/plane with offset) with free a_w and a non-unit line."""
    for _ in range(20):
        a = np.append(RNG.normal(size=dim), RNG.uniform(0.5, 2.0))
        line = np.append(RNG.normal(size=dim) * RNG.uniform(0.3, 3.0), RNG.normal())
        _pair_check(cst.rp, a, line, float(RNG.normal()))


def test_rp_value_is_signed_distance() -> None:
    """Line y = 1 scaled by 3: the point (2, 4) is at signed distance 3 from it."""
    line = np.array([0.0, 3.0, -3.0])
    a = np.array([2.0, 4.0, 1.0])
    assert cst.rp(a, line, 3.0)[0] == pytest.approx(0.0, abs=1e-12)
    assert cst.rp(a, line, -3.0)[0] != pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_pp_derivatives(dim: int) -> None:
    """Eqs. 6–7 with non-unit normals; the offsets L4, M4 have zero derivative."""
    for _ in range(20):
        line = np.append(RNG.normal(size=dim) * 2.0, RNG.normal())
        other = np.append(RNG.normal(size=dim) * 0.5, RNG.normal())
        _pair_check(cst.pp, line, other, float(RNG.uniform(-1, 1)))


def test_pp_derivative_differs_from_printed_eq37_off_the_unit_norm() -> None:
    """The paper's Eq. 37 divides by ‖L‖² where the derivative of ‖L‖ gives ‖L‖: the two only
    agree when ‖L‖ = 1. Our derivative matches finite differences; the printed one does not."""
    line = np.array([2.0, 1.0, 0.5, 0.0])
    other = np.array([0.3, -1.0, 0.7, 0.0])
    k = 0.4
    _, dl, _ = cst.pp(line, other, k)
    nl, nm = np.linalg.norm(line[:3]), np.linalg.norm(other[:3])
    printed = other[:3] - k * line[:3] * nm / nl**2
    assert not np.allclose(dl[:3], printed)
    np.testing.assert_allclose(dl[:3], other[:3] - k * line[:3] * nm / nl, rtol=1e-12)


def test_pp_sin_derivatives_and_value() -> None:
    """The planar sine form: FD-exact partials, and zero for lines at the stated sine."""
    for _ in range(20):
        line = np.append(RNG.normal(size=2) * 2.0, RNG.normal())
        other = np.append(RNG.normal(size=2), RNG.normal())
        _pair_check(cst.pp_sin, line, other, float(RNG.uniform(-1, 1)))
    phi = 0.3
    line = np.array([1.0, 0.0, 5.0])
    other = np.array([np.cos(phi), np.sin(phi), -2.0]) * 4.0
    assert cst.pp_sin(line, other, np.sin(phi))[0] == pytest.approx(0.0, abs=1e-12)


def test_pp_sin_is_well_conditioned_where_cosine_form_is_not() -> None:
    """Near-parallel lines: the cosine form's gradient vanishes, the sine form's does not."""
    line = np.array([1.0, 0.0, 0.0])
    other = np.array([np.cos(1e-4), np.sin(1e-4), 0.0])
    k = float(line[:2] @ other[:2])
    s = float(line[0] * other[1] - line[1] * other[0])
    g_cos = np.linalg.norm(cst.pp(line, other, k)[1])
    g_sin = np.linalg.norm(cst.pp_sin(line, other, s)[1])
    assert g_cos < 1e-3 < 0.9 < g_sin


def test_norm_and_sphere_derivatives() -> None:
    """Eq. 8 on a line/plane and Eq. 9 on a homogeneous point (weight free)."""
    for dim in (2, 3):
        line = np.append(RNG.normal(size=dim), RNG.normal())
        np.testing.assert_allclose(cst.norm(line)[1],
                                   central_diff(lambda v: np.asarray(cst.norm(v)[0]), line),
                                   rtol=1e-6, atol=1e-8)
    a = np.append(RNG.normal(size=3), 1.3)
    np.testing.assert_allclose(cst.sphere(a)[1],
                               central_diff(lambda v: np.asarray(cst.sphere(v)[0]), a),
                               rtol=1e-6, atol=1e-8)


def test_vectorised_over_leading_axes() -> None:
    """A batch evaluates row by row exactly like single calls."""
    a = np.concatenate((RNG.normal(size=(5, 4, 2)), np.ones((5, 4, 1))), axis=-1)
    b = np.concatenate((RNG.normal(size=(5, 4, 2)), np.ones((5, 4, 1))), axis=-1)
    r = RNG.uniform(0.5, 2, size=(5, 4))
    c, da, _ = cst.rr(a, b, r)
    assert c.shape == (5, 4) and da.shape == (5, 4, 3)
    c1, da1, _ = cst.rr(a[3, 2], b[3, 2], r[3, 2])
    assert c[3, 2] == pytest.approx(float(c1))
    np.testing.assert_allclose(da[3, 2], da1)


# ------------------------------------------------------------------ the compiled system
def _load(path: Path) -> Mechanism:
    return parse_mechanism(path.read_text())


def _x_at(mech: Mechanism, q: np.ndarray) -> np.ndarray:
    sys = mech.system
    x = sys.new_x()
    x[: sys.n_u] = q
    x[sys.n_u: sys.n_u + sys.n_d] = mech.basis.driven(mech.input0 + 0.3 * mech.step)
    x[sys.n_u + sys.n_d: -1] = mech.basis.actuators(mech.input0 + 0.3 * mech.step)
    return x


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_system_jacobian_matches_finite_differences(path: Path) -> None:
    """G's unknown columns are the Jacobian of Φ: checked off the constraint manifold."""
    mech = _load(path)
    sys = mech.system
    q = mech.q0 + RNG.normal(scale=0.05, size=mech.q0.size)
    x = _x_at(mech, q)
    g, _ = sys.evaluate(x)

    def phi(v: np.ndarray) -> np.ndarray:
        return sys.evaluate(_x_at(mech, v))[1]

    np.testing.assert_allclose(g[:, : sys.n_u], central_diff(phi, q), rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_system_equals_exact_equations_on_normalised_states(path: Path) -> None:
    """Where every line/plane is unit (Eq. 8), the quadratic forms have the exact equations'
    values and first derivatives (finite differences of the exact Eqs. 1–9)."""
    mech = _load(path)
    sys = mech.system
    u = mech.input0 + 0.3 * mech.step
    coords = mech.coords_batch(mech.q0[None], u[None])[0]
    coords = coords + RNG.normal(scale=0.03, size=coords.shape) * ~mech.fixed[:, None]
    if mech.planar:
        coords[~mech.is_line, 2] = 1.0
        coords[mech.is_line] /= np.linalg.norm(coords[mech.is_line, :2], axis=1)[:, None]
    else:
        coords[mech.is_line] /= np.linalg.norm(coords[mech.is_line], axis=1)[:, None]
    q = coords.ravel()[sys.unknown_flat]
    g, phi = sys.evaluate(_x_at(mech, q))

    def exact(v: np.ndarray) -> np.ndarray:
        c = mech.coords_batch(v[None], u[None])
        return mech.residuals(c, u[None])[0]

    np.testing.assert_allclose(phi, exact(q), rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(g[:, : sys.n_u], central_diff(exact, q), rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_curvature_bounds_the_newton_remainder(path: Path) -> None:
    """Φ(q − Δ) with JΔ = Φ(q) is ½ΔᵀHΔ, bounded by ½·curvature·‖Δ‖² (square systems)."""
    mech = _load(path)
    sys = mech.system
    if sys.m != sys.n_u:
        pytest.skip("least-squares system")
    q = mech.q0 + RNG.normal(scale=0.01, size=mech.q0.size)
    g, phi = sys.evaluate(_x_at(mech, q))
    step = np.linalg.solve(g[:, : sys.n_u], phi)
    _, phi1 = sys.evaluate(_x_at(mech, q - step))
    assert np.linalg.norm(phi1) <= 0.5 * sys.curvature * float(step @ step) * (1 + 1e-9)


def test_newton_linear_solve_matches_numpy_and_flags_singular_matrices() -> None:
    """The Newton step's solver (LAPACK gesv, called without np.linalg.solve's wrapper when
    available) agrees with np.linalg.solve; a singular matrix gives a non-finite step (or
    LinAlgError), which the Newton loop treats as a failed attempt."""
    from kinematics.nbar.system import solve

    for n in (2, 5, 18):
        a = RNG.normal(size=(n, n)) + n * np.eye(n)
        b = RNG.normal(size=n)
        np.testing.assert_allclose(solve(a[:, :], b), np.linalg.solve(a, b), rtol=1e-12)
    sing = np.array([[1.0, 2.0], [2.0, 4.0]])
    with np.errstate(all="ignore"):
        try:
            out = solve(sing, np.ones(2))
        except np.linalg.LinAlgError:
            return
    assert not np.all(np.isfinite(out))


# ------------------------------------------------- batched exact residuals, row by row
def _homogeneous_row(x: np.ndarray, line: bool, planar: bool) -> np.ndarray:
    """One stored primitive as the equations take it, written out independently of
    `cst.homogeneous`: planar ones are homogeneous already; on the sphere and in space a point
    gets w = 1 and a plane through the centre L4 = 0."""
    return x.copy() if planar else np.append(x, 0.0 if line else 1.0)


def _per_row(coords: np.ndarray, is_line: np.ndarray, planar: bool,
             cons: tuple[cst.Constraint, ...], lengths: np.ndarray | None) -> np.ndarray:
    """Scaled residuals (m,) of one state, one `cst` call per row (rr, rp, pp, ...)."""
    h = [_homogeneous_row(coords[j], bool(is_line[j]), planar) for j in range(len(coords))]
    out = []
    n_act = 0
    for c in cons:
        a, b = h[c.prims[0]], h[c.prims[-1]]
        if c.kind == "RR":
            v = cst.rr(a, b, c.value)[0]
        elif c.kind == "ACT":
            v = cst.rr(a, b, c.value if lengths is None else lengths[n_act])[0]
            n_act += 1
        elif c.kind == "RP":
            v = cst.rp(a, b, c.value)[0]
        elif c.kind == "PP":
            v = cst.pp(a, b, c.value)[0]
        elif c.kind == "PPsin":
            v = cst.pp_sin(a, b, c.value)[0]
        elif c.kind == "NORM":
            v = cst.norm(a)[0]
        else:
            v = cst.sphere(a)[0]
        out.append(float(v) * c.scale)
    return np.array(out)


def _check_batched(coords: np.ndarray, is_line: np.ndarray, planar: bool,
                   cons: tuple[cst.Constraint, ...], lengths: np.ndarray | None,
                   batched: np.ndarray) -> None:
    expect = np.array([_per_row(x, is_line, planar, cons, None if lengths is None else ln)
                       for x, ln in zip(coords, lengths if lengths is not None
                                        else [None] * len(coords), strict=True)])
    assert batched.shape == expect.shape
    np.testing.assert_allclose(batched, expect, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.stem)
def test_batched_exact_residuals_match_the_per_row_equations(path: Path) -> None:
    """`Mechanism.residuals` (component-major, all rows of a kind at once, ACT rows with the
    RR rows) equals the per-constraint functions applied row by row, at states on the
    constraint manifold and perturbed off it (residuals far from 0), and in the plane with
    points and lines rescaled by non-unit homogenising factors."""
    rng = np.random.default_rng(31415)
    mech = _load(path)
    cons = mech.constraints
    s = 6
    u = mech.input0 + np.linspace(0.0, 2.0, s)[:, None] * mech.step
    on = mech.coords_batch(np.broadcast_to(mech.q0, (s, mech.q0.size)), u)
    off = on + rng.normal(scale=0.05 * mech.size, size=on.shape)
    if not mech.planar:
        off[:, mech.is_line] /= np.linalg.norm(off[:, mech.is_line], axis=-1)[..., None]
    states = [on, off]
    if mech.planar:
        w = rng.uniform(0.4, 2.5, size=on.shape[:2])[..., None]
        states += [on * w, off * w]   # same points / lines, other homogeneous factors
    lengths = mech.actuator_lengths(u)
    for coords in states:
        batched = mech.residuals(coords, u)
        _check_batched(coords, mech.is_line, mech.planar, cons, lengths, batched)
        single = mech.residuals(coords[2], u[2])
        np.testing.assert_array_equal(single, batched[2])
        # the constraint tuple (not the cached row groups) and the ACT rows' initial lengths
        plain = cst.exact_residuals(coords, mech.is_line, mech.planar, cons)
        _check_batched(coords, mech.is_line, mech.planar, cons, None, plain)
    assert np.max(np.abs(mech.residuals(off, u))) > 1e-4


@pytest.mark.parametrize("planar", [True, False])
def test_batched_exact_residuals_every_kind_interleaved(planar: bool) -> None:
    """Every kind (PP and PPsin included, which no mechanism file has) in shuffled row order,
    at random points with free weights and non-unit lines, batched and single."""
    rng = np.random.default_rng(27)
    n, s = 9, 7
    is_line = np.array([False] * 5 + [True] * 4)
    coords = rng.normal(size=(s, n, 3))
    if planar:
        coords[:, ~is_line, 2] = rng.uniform(0.4, 2.5, size=(s, 5))
    else:
        coords[:, ~is_line] *= 0.7
    pts, lines = range(5), range(5, 9)
    rows: list[tuple[cst.ConstraintKind, tuple[int, ...]]] = [
        ("RR", (0, 1)), ("RR", (2, 3)), ("ACT", (1, 4)), ("RP", (0, 5)), ("RP", (3, 6)),
        ("PP", (5, 6)), ("PP", (7, 8)), ("NORM", (5,)), ("NORM", (8,)), ("RR", (4, 0)),
        ("ACT", (2, 0)), ("RP", (4, 8))]
    if planar:
        rows += [("PPsin", (5, 7)), ("PPsin", (6, 8))]
    else:
        rows += [("SPHERE", (1,)), ("SPHERE", (3,))]
    order = rng.permutation(len(rows))
    cons = tuple(cst.Constraint(rows[i][0], rows[i][1], float(rng.uniform(-0.9, 0.9))
                                if rows[i][0] in ("PP", "PPsin", "RP")
                                else float(rng.uniform(0.3, 2.0)), f"r{i}",
                                float(rng.uniform(0.2, 3.0)))
                 for i in order)
    assert {c.prims[0] for c in cons if c.kind in ("RR", "ACT")} <= set(pts)
    assert {c.prims[-1] for c in cons if c.kind in ("RP", "NORM")} <= set(lines)
    lengths = rng.uniform(0.5, 2.0, size=(s, 2))
    batched = cst.exact_residuals(coords, is_line, planar, cons, lengths)
    _check_batched(coords, is_line, planar, cons, lengths, batched)
    grp = cst.group_rows(cons)
    np.testing.assert_array_equal(
        cst.exact_residuals(coords[4], is_line, planar, grp, lengths[4]), batched[4])
    _check_batched(coords, is_line, planar, cons, None,
                   cst.exact_residuals(coords, is_line, planar, grp))
