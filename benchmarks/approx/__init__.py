"""Approximate five-bar kinematics, kept to measure them against the closed form (issue 7).

Not part of the shipped packages: only the benchmarks and the tests use it.

Three families, all pure numpy and vectorised, each with inverse (point → motor angles) and
forward (motor angles → point) maps:

- `LinearApprox` — the thesis' linear transform (Gamble 2020, Sec. 5.2): Eq. 25

      [θ1, θ2']ᵀ ≈ B·(R(γ)·[x, y]ᵀ + [A1, A2]ᵀ),     R(γ) the rotation by γ,

  and its algebraic inverse, Eq. 26, [x, y]ᵀ ≈ R(γ)ᵀ·([θ1, θ2']ᵀ/B − A), as forward
  kinematics. The thesis measures θ2 as the interior angle at M2 from the direction M2→M1, so
  θ2' = π − θ2 in this project's convention (ARCHITECTURE.md); with that, the least-squares fit
  over the default machine's page region lands on γ = 135°, the rotation the thesis read off its
  Fig. 25. γ, A1, A2, B are fitted by linear least squares on c = B·cos γ, s = B·sin γ, B·A
  (`form="similarity"`, 4 parameters as in Eq. 25); `form="affine"` frees the 2×2 matrix (6
  parameters), the best any linear map can do.
- `TiledLinear` — the same fit per region: the domain box is cut into tiles and each tile gets
  its own Eq. 25 (similarity) or affine map, fitted to the closed form on a sub-grid of the tile.
  Inverse tiles live in the (x, y) box, forward tiles in the (θ1, θ2) box.
- `LookupTable` — the closed form sampled on a regular grid, read back by bilinear or bicubic
  (Keys/Catmull–Rom, a = −½) interpolation.

Documented behaviour where they fail (tests/test_stability.py holds each case):

- every map returns an `Approximation` (values + `valid` mask); invalid rows hold 0.0, never NaN;
- outside the domain box a point is refused; so is any point the closed form would refuse:
  inverse maps check both reach annuli (|a_i − b_i| ≤ |P − M_i| ≤ a_i + b_i), forward maps the
  elbow distance (|b1 − b2| ≤ |R1 − R2| ≤ b1 + b2) — two cheap distance tests, so an
  approximation never answers where no answer exists;
- tiles refuse the whole tile, tables the whole cell (the interpolation stencil: 2×2 nodes
  bilinear, 4×4 bicubic), when a sample or node of it has no closed-form answer (out of reach;
  with `assembly` given, the other assembly), or when its angles jump by more than π (the ±π
  seam: inverse tables keep one continuous branch, unwrapped about the angles at a `centre`);
- inside, the error is not checked per point (that would cost the closed form itself): each
  tile and cell stores the largest *pen* error (mm) measured against the closed form at build
  time on sub-samples (`error` / `cell_error`; for inverse maps: where the approximate angles put
  the pen), and `max_error` refuses tiles/cells above it. This is an estimate from samples, not
  a proof: a point singularity inside a cell escapes it. `min_margins` (type 1, type 2) refuses
  tiles/cells with a sample or node that close to a singularity, as the job's pose checks
  do; margins are continuous, so a fine enough grid then keeps singular points out of every
  usable cell. The error grows near type-1 singularities for inverse maps (θ has a square-root
  branch point at the reach circles) and near type-2 singularities for both (P has one where
  the floating links align, and there any angle error moves the pen far): where the closed
  form's derivative blows up, any interpolant's error does.

The benchmark (`python -m benchmarks.speed_accuracy`) charts time per point against error for
all of them; the job pipeline uses none, see docs/performance.md for why.

Modules: `common` (the result type, reach tests, grid and closed-form references shared by
both families), `linear` (`LinearApprox`, `TiledLinear`) and `table` (`LookupTable`).
"""

from benchmarks.approx.common import (
    Approximation,
    Box,
    Form,
    Kind,
    Order,
    assemblable,
    reachable,
    to_thesis,
)
from benchmarks.approx.linear import (
    LinearApprox,
    TiledLinear,
    fit_linear,
    forward_tiles,
    inverse_tiles,
)
from benchmarks.approx.table import LookupTable, forward_table, inverse_table

__all__ = [
    "Approximation",
    "Box",
    "Form",
    "Kind",
    "LinearApprox",
    "LookupTable",
    "Order",
    "TiledLinear",
    "assemblable",
    "fit_linear",
    "forward_table",
    "forward_tiles",
    "inverse_table",
    "inverse_tiles",
    "reachable",
    "to_thesis",
]
