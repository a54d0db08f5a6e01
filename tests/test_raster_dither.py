"""Image modes and dithering against independent checks: the kernels' published weight
matrices (written out here as printed in the literature, not taken from the module), a
plain textbook loop over those matrices, hand-computed small cases, and the published 4 × 4
Bayer matrix."""

from __future__ import annotations

import numpy as np
import pytest

from fivebar_host.errors import OptionError
from fivebar_host.raster import dither
from fivebar_host.raster.modes import ImageMode, to_powers

# The published matrices: rows from the current pixel's row down; the column of "*" (the
# current pixel) is the centre column; entries left of and at "*" on its row are 0.
PUBLISHED: dict[str, tuple[int, list[list[int]]]] = {
    "floyd": (16, [[0, 0, 0, 7, 0],
                   [0, 3, 5, 1, 0]]),
    "jarvis": (48, [[0, 0, 0, 7, 5],
                    [3, 5, 7, 5, 3],
                    [1, 3, 5, 3, 1]]),
    "stucki": (42, [[0, 0, 0, 8, 4],
                    [2, 4, 8, 4, 2],
                    [1, 2, 4, 2, 1]]),
    "atkinson": (8, [[0, 0, 0, 1, 1],
                     [0, 1, 1, 1, 0],
                     [0, 0, 1, 0, 0]]),
}


def textbook(dark: np.ndarray, name: str) -> np.ndarray:
    """Error diffusion straight from the published matrix: raster order, threshold ½."""
    div, mat = PUBLISHED[name]
    x = np.asarray(dark, dtype=np.float64).copy()
    h, w = x.shape
    out = np.zeros((h, w), dtype=bool)
    for r in range(h):
        for c in range(w):
            q = x[r, c] >= 0.5
            out[r, c] = q
            e = x[r, c] - q
            for dr, row in enumerate(mat):
                for j, wt in enumerate(row):
                    rr, cc = r + dr, c + j - 2
                    if wt and rr < h and 0 <= cc < w:
                        x[rr, cc] += e * wt / div
    return out


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_kernel_taps_are_the_published_weights(name: str) -> None:
    div, mat = PUBLISHED[name]
    k = dither.KERNELS[name]
    assert k.divisor == div
    got = np.zeros((len(mat), 5), dtype=np.int64)
    for dr, dc, wt in k.taps:
        got[dr, dc + 2] += wt
    assert got.tolist() == mat


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_diffusion_matches_the_textbook_loop(name: str) -> None:
    rng = np.random.default_rng(7)
    # widths at and just above each kernel's wavefront slope too (the strided views'
    # smallest strides; narrower images take the index-array path)
    for shape in ((1, 9), (7, 1), (13, 17), (5, 40), (6, 3), (9, 5), (4, 4), (8, 2)):
        dark = rng.random(shape)
        assert np.array_equal(dither.diffuse(dark, dither.KERNELS[name]), textbook(dark, name))


def test_floyd_steinberg_by_hand() -> None:
    # 0.4 → 0 (e 0.4); 0.4 + 0.4·7/16 = 0.575 → 1 (e −0.425); 0.4 − 0.425·7/16 ≈ 0.214 → 0
    got = dither.diffuse(np.full((1, 3), 0.4), dither.FLOYD_STEINBERG)
    assert got.tolist() == [[False, True, False]]
    # second row: (1,0) receives 0.4·5/16 + (−0.425)·1/16 from its upper neighbours' errors
    two = dither.diffuse(np.array([[0.4, 0.4], [0.3, 0.0]]), dither.FLOYD_STEINBERG)
    v10 = 0.3 + 0.4 * 5 / 16 + (-0.425) * 3 / 16
    assert two[1, 0] == (v10 >= 0.5)


def test_atkinson_drops_a_quarter_of_the_error() -> None:
    div, mat = PUBLISHED["atkinson"]
    assert sum(map(sum, mat)) / div == pytest.approx(0.75)
    for name in ("floyd", "jarvis", "stucki"):
        div, mat = PUBLISHED[name]
        assert sum(map(sum, mat)) == div


@pytest.mark.parametrize("name", ["floyd", "jarvis", "stucki", "bayer"])
def test_dithered_grey_keeps_its_mean(name: str) -> None:
    for level in (0.25, 0.5, 0.8):
        dark = np.full((64, 64), level)
        on = (dither.ordered(dark) if name == "bayer"
              else dither.diffuse(dark, dither.KERNELS[name]))
        assert abs(on.mean() - level) < 0.02


def test_bayer_matrix_is_the_published_one() -> None:
    published4 = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]]
    assert dither.bayer_matrix(2).astype(int).tolist() == published4
    m8 = dither.bayer_matrix(3)
    assert sorted(m8.ravel().astype(int).tolist()) == list(range(64))


def test_grayscale_power_curve() -> None:
    d = np.array([[0.0, 0.25, 0.5, 1.0]])
    p = to_powers(d, ImageMode("grayscale", power_min=20, power_max=220, gamma=2.0))
    assert p.tolist() == [[0, round(20 + 200 * 0.0625), round(20 + 200 * 0.25), 220]]


def test_threshold_and_negative() -> None:
    d = np.array([[0.2, 0.5, 0.9]])
    assert to_powers(d, ImageMode("threshold", power_max=200)).tolist() == [[0, 200, 200]]
    neg = to_powers(d, ImageMode("threshold", power_max=200, negative=True))
    assert neg.tolist() == [[200, 200, 0]]


def test_bad_mode_values_are_option_errors() -> None:
    with pytest.raises(OptionError):
        ImageMode("halftone")
    with pytest.raises(OptionError):
        ImageMode(power_min=200, power_max=100)
