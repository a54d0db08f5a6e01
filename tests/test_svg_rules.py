"""SVG reader by rule class (issue 21), each against geometry worked out by hand from the SVG
specification (analytic coordinates), never against the reader's own earlier output:
path grammar and its errors, CSS cascade, <switch>, <symbol> viewports, relative lengths,
clip-path, mask, text. A second reader (svgelements) checks the path grammar on generated data.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import Drawing, flatten
from fivebar_host.toolpath.svg import read_svg

NS = 'xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink"'
HEAD = 'width="200mm" height="200mm" viewBox="0 0 200 200"'


def svg(body: str, head: str = HEAD) -> bytes:
    return f"<svg {NS} {head}>\n{body}\n</svg>\n".encode()


def runs(d: Drawing, tol: float = 0.001) -> list[np.ndarray]:
    """Pen-down runs as points in page coordinates (y down, as written in the file)."""
    p = flatten(d, tol)
    pts = d.to_file_frame(p.points)
    return [pts[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]


def ends(d: Drawing) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    return [(tuple(np.round(r[0], 6)), tuple(np.round(r[-1], 6))) for r in runs(d)]


# --------------------------------------------------------------------------- path grammar
@pytest.mark.parametrize(("d", "pts"), [
    ("M1.0e-1-1e2L1-2", [(0.1, -100), (1, -2)]),           # exponent then sign
    ("M.5.5L1.5.5", [(0.5, 0.5), (1.5, 0.5)]),              # second '.' starts a number
    ("M1-2-3-4", [(1, -2), (-3, -4)]),                      # implicit lineto after moveto
    ("m1 1 2 2", [(1, 1), (3, 3)]),                         # implicit relative lineto
    ("M0,0L10,0,10,10", [(0, 0), (10, 0), (10, 10)]),       # comma separated pairs
    ("M0 0h10v10H0z", [(0, 0), (10, 0), (10, 10), (0, 10), (0, 0)]),
    ("M 1e1 1E1 L 2e+1 2e-0", [(10, 10), (20, 2)]),
])
def test_compact_number_lists_parse_by_the_grammar(d: str, pts: list[tuple[float, float]]) -> None:
    (r,) = runs(read_svg(svg(f'<path d="{d}" stroke="black" fill="none"/>')))
    assert np.allclose(r, pts, atol=1e-9)


def test_arc_flags_need_no_separator() -> None:
    # a rx ry rot large sweep x y with flags and the next number run together: "a5 5 0 0110 0"
    (r,) = runs(read_svg(svg('<path d="M0 50a5 5 0 0110 0" stroke="black"/>')))
    # semicircle of radius 5 from (0,50) to (10,50), sweep=1 goes through page y = 45
    assert np.allclose(np.hypot(r[:, 0] - 5, r[:, 1] - 50), 5, atol=1e-9)
    assert r[:, 1].min() == pytest.approx(45, abs=1e-3)  # within the flattening tolerance


@pytest.mark.parametrize(("d", "column", "kept"), [
    ("L 10 10 L 20 20", 1, None),                   # no leading moveto: nothing drawn
    ("M 10 10 L 150#80", 14, None),                 # '#' is not a separator
    ("M 0 0 L 10 0 L 10 10 X 5 5", 22, [(0, 0), (10, 0), (10, 10)]),
    ("M 0 0 L 10 0 L 20,", 19, [(0, 0), (10, 0)]),  # incomplete pair, trailing comma
    ("M 0 0 L 10 0 Z 5", 16, [(0, 0), (10, 0), (0, 0)]),  # closepath takes no numbers
    ("M 0 0 A 5 5 0 2 1 10 0", 15, None),           # flag must be 0 or 1
])
def test_invalid_path_data_is_drawn_up_to_the_error(d: str, column: int,
                                                    kept: list[tuple[float, float]] | None
                                                    ) -> None:
    body = f'<path id="bad" d="{d}" stroke="black"/>'
    if kept is None:
        body += '<path d="M 100 100 L 110 100" stroke="black"/>'
    dr = read_svg(svg(body), file="f.svg")
    (w,) = [w for w in dr.warnings if "invalid d data" in w]
    assert f"column {column}:" in w and '<path id="bad"> at line 2' in w
    r = runs(dr)
    if kept is None:
        assert [s.ident for s in dr.sources] == [None]  # only the valid path
    else:
        assert np.allclose(r[0], kept)


def test_odd_points_drop_the_last_number_with_a_warning() -> None:
    d = read_svg(svg('<polyline points="0 0 10 0 10 10 5" stroke="black" fill="none"/>'))
    assert np.allclose(runs(d)[0], [(0, 0), (10, 0), (10, 10)])
    assert any("odd number of coordinates" in w for w in d.warnings)


_coord = st.integers(-50, 50).map(lambda v: v / 4)


@st.composite
def path_data(draw: st.DrawFn) -> str:
    """Valid path data in the compact form minifiers write (no separators where the grammar
    allows none)."""
    out = [f"M{draw(_coord)} {draw(_coord)}"]
    prev = "M"
    for _ in range(draw(st.integers(1, 6))):
        cmd = draw(st.sampled_from("LlHhVvCcSsQqTtAa"))
        # S reflects only after C/S and T only after Q/T (SVG 2 §9.5.2); svgelements also
        # reflects across kinds, so the comparison keeps to what both read alike.
        if (cmd in "Ss" and prev not in "CcSs") or (cmd in "Tt" and prev not in "QqTt"):
            cmd = "L"
        prev = cmd
        n = {"l": 2, "h": 1, "v": 1, "c": 6, "s": 4, "q": 4, "t": 2, "a": 7}[cmd.lower()]
        if cmd.lower() == "a":
            args = [str(draw(st.integers(1, 20))), str(draw(st.integers(1, 20))),
                    str(draw(st.integers(0, 90))), draw(st.sampled_from("01")),
                    draw(st.sampled_from("01")), str(draw(_coord)), str(draw(_coord))]
        else:
            args = [f"{draw(_coord):g}" for _ in range(n)]
        text = cmd
        for a in args:
            text += a if (a[0] == "-" or text[-1].isalpha()) else " " + a
        out.append(text)
    return "".join(out)


@settings(max_examples=60, deadline=None)
@given(path_data())
def test_path_geometry_matches_svgelements(d: str) -> None:
    svgelements = pytest.importorskip("svgelements")
    ref = svgelements.Path(d)
    try:
        dr = read_svg(svg(f'<path d="{d}" stroke="black" fill="none"/>'))
    except InputError as e:
        assert "no strokes" in str(e)
        assert ref.length(error=1e-6) < 1e-9
        return
    mine = sum(float(np.hypot(*np.diff(r, axis=0).T).sum()) for r in runs(dr, 1e-4))
    assert mine == pytest.approx(ref.length(error=1e-7), rel=1e-3, abs=1e-3)
    bb = ref.bbox()
    pts = np.concatenate(runs(dr, 1e-4))
    assert np.allclose([*pts.min(axis=0), *pts.max(axis=0)], bb, atol=1e-2)


# --------------------------------------------------------------------------- CSS
def test_css_class_display_none_hides_the_guide() -> None:
    body = ('<style>.guide { display: none }</style>'
            '<rect class="guide" x="0" y="0" width="200" height="200" stroke="black"/>'
            '<line x1="0" y1="5" x2="10" y2="5" stroke="black"/>')
    assert ends(read_svg(svg(body))) == [((0, 5), (10, 5))]


def test_css_specificity_important_and_origin_order() -> None:
    body = ('<style><![CDATA[ g > .a { stroke: none } #x { stroke: black } '
            'line { visibility: hidden } .s { stroke: none !important } '
            'g line.v { visibility: visible } ]]></style><g>'
            '<line id="x" class="a v" x1="0" y1="1" x2="9" y2="1" fill="none"/>'  # id wins
            '<line class="a v" x1="0" y1="2" x2="9" y2="2" stroke="black" fill="none"/>'
            '<line class="v s" x1="0" y1="3" x2="9" y2="3" style="stroke:black" fill="none"/>'
            '<line class="v" x1="0" y1="4" x2="9" y2="4" style="stroke:black" fill="none"/>'
            '</g><line x1="0" y1="5" x2="9" y2="5" stroke="black"/>')   # hidden by type rule
    ys = sorted(r[0, 1] for r in runs(read_svg(svg(body))))
    # y=2: CSS beats the presentation attribute; y=3: !important beats style=""; y=5 hidden
    assert ys == pytest.approx([1, 4])


def test_css_descendant_vs_child_and_groups() -> None:
    body = ('<style>#top > line, .deep line { display: none }</style>'
            '<g id="top"><line x1="0" y1="1" x2="9" y2="1" stroke="black"/>'
            '<g><line x1="0" y1="2" x2="9" y2="2" stroke="black"/></g></g>'
            '<g class="deep"><g><line x1="0" y1="3" x2="9" y2="3" stroke="black"/></g></g>')
    assert [r[0, 1] for r in runs(read_svg(svg(body)))] == pytest.approx([2])


def test_css_unsupported_selector_and_import_are_said() -> None:
    body = ('<style>@import url(x.css); a + line { display: none } line:hover{display:none}'
            '</style><line x1="0" y1="1" x2="9" y2="1" stroke="black"/>')
    d = read_svg(svg(body))
    assert len(runs(d)) == 1  # :hover never applies to a still picture
    assert any("@import" in w for w in d.warnings)
    assert any("sibling combinator '+'" in w for w in d.warnings)


# --------------------------------------------------------------------------- switch
def test_switch_draws_only_the_first_child_that_applies() -> None:
    body = ('<switch><line systemLanguage="fr,de" x1="0" y1="1" x2="9" y2="1" stroke="black"/>'
            '<line requiredExtensions="http://example.org/x" x1="0" y1="2" x2="9" y2="2" '
            'stroke="black"/><line systemLanguage="en-GB" x1="0" y1="3" x2="9" y2="3" '
            'stroke="black"/><line x1="0" y1="4" x2="9" y2="4" stroke="black"/></switch>')
    assert [r[0, 1] for r in runs(read_svg(svg(body)))] == pytest.approx([3])
    assert [r[0, 1] for r in runs(read_svg(svg(body), language="de"))] == pytest.approx([1])
    assert [r[0, 1] for r in runs(read_svg(svg(body), language="ja"))] == pytest.approx([4])


# --------------------------------------------------------------------------- symbol, viewports
@pytest.mark.parametrize(("use", "par", "corners"), [
    # viewBox 0 0 10 10 into 50×50 at (20,20): scale 5
    ('x="20" y="20" width="50" height="50"', "", [(20, 20), (70, 70)]),
    # 100×50 viewport, meet: scale 5, centred horizontally (x offset 25)
    ('width="100" height="50"', "", [(25, 0), (75, 50)]),
    ('width="100" height="50"', 'preserveAspectRatio="xMinYMin meet"', [(0, 0), (50, 50)]),
    ('width="100" height="50"', 'preserveAspectRatio="none"', [(0, 0), (100, 50)]),
    # no width/height: 100% of the viewport (200 × 200) → scale 20 → clipped to 200
    ("", "", [(0, 0), (200, 200)]),
])
def test_symbol_viewbox_maps_into_the_use_viewport(use: str, par: str,
                                                    corners: list[tuple[int, int]]) -> None:
    body = (f'<defs><symbol id="s" viewBox="0 0 10 10" {par}>'
            '<rect x="0" y="0" width="10" height="10" fill="none" stroke="black"/></symbol>'
            f'</defs><use href="#s" {use}/>')
    pts = np.concatenate(runs(read_svg(svg(body))))
    assert np.allclose([pts.min(axis=0), pts.max(axis=0)], corners, atol=1e-9)


def test_symbol_and_nested_svg_clip_their_overflow() -> None:
    body = ('<symbol id="s" viewBox="0 0 10 10"><line x1="-10" y1="5" x2="20" y2="5" '
            'stroke="black"/></symbol><use xlink:href="#s" x="100" width="20" height="20"/>'
            '<svg x="10" y="100" width="50" height="50" viewBox="0 0 10 10">'
            '<line x1="-10" y1="5" x2="20" y2="5" stroke="black"/></svg>'
            '<svg x="10" y="160" width="50" height="20" overflow="visible">'
            '<line x1="-10" y1="5" x2="20" y2="5" stroke="black"/></svg>')
    got = ends(read_svg(svg(body)))
    assert got == [((100, 10), (120, 10)), ((10, 125), (60, 125)), ((0, 165), (30, 165))]


# --------------------------------------------------------------------------- lengths
def test_percent_em_ex_lengths_on_shapes() -> None:
    body = ('<circle cx="50%" cy="25%" r="10%" fill="none" stroke="black"/>'
            '<g style="font-size:10px"><rect x="1em" y="2em" width="3ex" height="1em" '
            'stroke="black" fill="none"/></g>'
            '<line x1="0" y1="1em" x2="5em" y2="1em" stroke="black"/>')
    circle, rect, line = runs(read_svg(svg(body)))
    # r = 10 % of √((200² + 200²)/2) = 20
    assert np.allclose(np.hypot(circle[:, 0] - 100, circle[:, 1] - 50), 20, atol=1e-9)
    assert np.allclose([rect.min(axis=0), rect.max(axis=0)], [(10, 20), (25, 30)])
    assert np.allclose(line, [(0, 16), (80, 16)])  # default font-size 16 px


def test_root_percent_size_without_viewbox_is_read() -> None:
    d = read_svg(f'<svg {NS} width="100%" height="100%"><rect x="10" y="20" width="96" '
                 'height="48" stroke="black" fill="none"/></svg>'.encode())
    pts = np.concatenate(runs(d))
    px = 25.4 / 96
    assert np.allclose([pts.min(axis=0), pts.max(axis=0)],
                       [(10 * px, 20 * px), (106 * px, 68 * px)])
    assert any("content's extent" in w for w in d.warnings)
    d2 = read_svg(svg('<rect x="0" y="0" width="10" height="10"/>',
                      'width="50%" height="100%" viewBox="0 0 100 100"'))
    px_mm = 25.4 / 96
    assert d2.page_size_mm == pytest.approx((50 * px_mm, 100 * px_mm))


# --------------------------------------------------------------------------- clip-path
STAR = "M100 10 L127 190 L10 70 L190 70 L73 190 Z"  # a pentagram


def _star_x_at(y: float) -> list[float]:
    """Where the pentagram's five edges cross the horizontal y (analytic)."""
    v = [(100, 10), (127, 190), (10, 70), (190, 70), (73, 190), (100, 10)]
    xs = []
    for (x0, y0), (x1, y1) in itertools.pairwise(v):
        if (y0 - y) * (y1 - y) < 0:
            xs.append(x0 + (y - y0) * (x1 - x0) / (y1 - y0))
    return sorted(xs)


@pytest.mark.parametrize("rule", ["nonzero", "evenodd"])
def test_clip_path_star_with_clip_rule(rule: str) -> None:
    body = (f'<clipPath id="c"><path d="{STAR}" clip-rule="{rule}"/></clipPath>'
            '<g clip-path="url(#c)"><rect x="0" y="0" width="200" height="200" stroke="black" '
            'fill="none"/><line x1="0" y1="100" x2="200" y2="100" stroke="black"/></g>')
    got = ends(read_svg(svg(body)))
    xs = _star_x_at(100)  # four crossings; the middle part is the inner pentagon
    if rule == "nonzero":
        want = [((xs[0], 100), (xs[3], 100))]
    else:
        want = [((xs[0], 100), (xs[1], 100)), ((xs[2], 100), (xs[3], 100))]
    assert len(got) == len(want)  # the 200×200 rectangle lies outside the star
    assert np.allclose(np.array(got), np.array(want), atol=1e-6)


def test_clip_path_units_and_transforms() -> None:
    # objectBoundingBox: the circle is the bbox's inscribed ellipse; the clipPath's own
    # transform and a child's transform compose with it.
    body = ('<clipPath id="o" clipPathUnits="objectBoundingBox"><circle cx=".5" cy=".5" '
            'r=".5"/></clipPath><line x1="0" y1="50" x2="200" y2="50" stroke="black" '
            'clip-path="url(#o)" transform="translate(0 0)"/>'
            '<path d="M0 0 H200 V20 H0 Z" fill="none" stroke="none"/>'
            '<clipPath id="t" transform="translate(100 0)"><rect x="0" y="0" width="20" '
            'height="200" transform="scale(2 1)"/></clipPath>'
            '<line x1="0" y1="150" x2="200" y2="150" stroke="black" clip-path="url(#t)"/>')
    got = ends(read_svg(svg(body)))
    # a horizontal line has a zero-height bbox: objectBoundingBox gives an empty clip
    # (nothing drawn, as in browsers); the second clips to x ∈ [100, 140]
    assert got == [((100, 150), (140, 150))]


def test_clip_keeps_curves_exact_and_splits_at_the_edge() -> None:
    body = ('<clipPath id="c"><rect x="0" y="0" width="100" height="200"/></clipPath>'
            '<circle cx="100" cy="100" r="50" fill="none" stroke="black" clip-path="url(#c)"/>')
    d = read_svg(svg(body))
    (r,) = runs(d, 1e-4)
    assert np.allclose(np.hypot(r[:, 0] - 100, r[:, 1] - 100), 50, atol=1e-9)
    assert r[:, 0].max() == pytest.approx(100, abs=1e-4)  # cut within the clip tolerance
    assert {tuple(np.round(r[0], 4)), tuple(np.round(r[-1], 4))} == {(100, 150), (100, 50)}


def test_clip_path_basic_shape_is_refused() -> None:
    with pytest.raises(InputError, match=r"clip-path: 'circle\(50%\)' is not supported"):
        read_svg(svg('<rect width="10" height="10" style="clip-path: circle(50%)"/>'))


# --------------------------------------------------------------------------- mask
def test_mask_white_minus_black_is_a_region() -> None:
    body = ('<mask id="m" maskUnits="userSpaceOnUse"><rect width="200" height="200" '
            'fill="#fff"/><circle cx="100" cy="100" r="50" fill="black"/></mask>'
            '<line x1="0" y1="100" x2="200" y2="100" stroke="black" mask="url(#m)"/>')
    d = read_svg(svg(body))
    assert np.allclose(np.array(ends(d)), [((0, 100), (50, 100)), ((150, 100), (200, 100))],
                       atol=0.01)  # the circle's hole is cut within the clip tolerance
    assert not d.warnings


def test_mask_grey_warns_and_gradient_is_refused() -> None:
    grey = ('<mask id="m" maskUnits="userSpaceOnUse"><rect width="100" height="200" '
            'fill="rgb(50%,50%,50%)"/></mask>'
            '<line x1="0" y1="100" x2="200" y2="100" stroke="black" mask="url(#m)"/>')
    d = read_svg(svg(grey))
    assert np.allclose(np.array(ends(d)), [((0, 100), (100, 100))])
    assert any("partly transparent" in w and "drawn at full strength" in w for w in d.warnings)
    with pytest.raises(InputError, match="gradient or pattern"):
        read_svg(svg(grey.replace('fill="rgb(50%,50%,50%)"', 'fill="url(#g)"')))


# --------------------------------------------------------------------------- text, paint
def test_flowed_text_only_file_gets_the_convert_hint() -> None:
    flowed = '<flowRoot><flowRegion><rect width="9" height="9"/></flowRegion><flowPara>a' \
             '</flowPara></flowRoot>'
    with pytest.raises(InputError, match=r"<flowRoot> at line\(s\) 2, 3\) is not drawn: "
                                         r"Inkscape's flowed text.*Text > Convert to Text"):
        read_svg(svg(f"{flowed}\n{flowed}"))


def test_partial_opacity_and_dashes_are_said_once_per_kind() -> None:
    body = "".join(f'<line x1="0" y1="{i}" x2="9" y2="{i}" stroke="black" opacity="0.5" '
                   'stroke-dasharray="2 1"/>' for i in range(3))
    body += '<line x1="0" y1="9" x2="9" y2="9" stroke="black" stroke-opacity="0"/>'
    d = read_svg(svg(body))
    assert len(runs(d)) == 3
    assert sum("partial opacity" in w for w in d.warnings) == 1
    assert any("dashed" in w and "3 elements" in w for w in d.warnings)
    assert math.isclose(runs(d)[0][1, 0], 9)


def test_unknown_xml_encoding_is_a_named_error() -> None:
    # found by the byte-mutation fuzz: expat raised a bare LookupError
    with pytest.raises(InputError, match="cannot decode the file: unknown encoding"):
        read_svg(b'<?xml version="1.0" encoding="TTF-8"?><svg/>')
