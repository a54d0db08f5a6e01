"""SVG reader: every feature against its exact geometry (units, viewBox, transforms, shapes,
path commands), visibility and layers, and bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import ARC, CUBIC, LINE, Drawing, evaluate, flatten
from fivebar_host.toolpath.svg import read_svg

NS = ('xmlns="http://www.w3.org/2000/svg" '
      'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"')


def svg(body: str, head: str = 'width="100mm" height="100mm" viewBox="0 0 100 100"') -> bytes:
    return f"<svg {NS} {head}>\n{body}\n</svg>\n".encode()


def points(d: Drawing, tol: float = 0.01) -> list[np.ndarray]:
    p = flatten(d, tol)
    return [p.points[a:b] for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True)]


def chord_deviation(d: Drawing, tol: float, dense: int = 64) -> float:
    """Largest distance of the exact curves (dense samples of every chord's parameter range)
    from their chords."""
    p = flatten(d, tol)
    worst = 0.0
    for v in range(p.points.shape[0] - 1):
        if v + 1 in p.offsets:
            continue
        i = p.prim[v + 1]
        t = np.linspace(p.t0[v + 1], p.t[v + 1], dense)
        c = evaluate(np.full(dense, d.kind[i]), np.repeat(d.params[i:i + 1], dense, 0), t)
        a, b = p.points[v], p.points[v + 1]
        ab = b - a
        u = np.clip((c - a) @ ab / max(ab @ ab, 1e-300), 0, 1)
        worst = max(worst, float(np.hypot(*(c - a - u[:, None] * ab).T).max()))
    return worst


# --------------------------------------------------------------------------- shapes
@pytest.mark.parametrize("tol", [0.5, 0.05, 0.01])
def test_circle_r10_points_on_circle_and_chords_within_tol(tol: float) -> None:
    d = read_svg(svg('<circle cx="50" cy="50" r="10" stroke="black" fill="none"/>'))
    (pts,) = points(d, tol)
    r = np.hypot(pts[:, 0] - 50, pts[:, 1] - 50)  # page 100 mm high: y flip keeps 50
    assert np.allclose(r, 10.0, atol=1e-9)  # 10 ± tol, in fact exact
    # Sagitta of every chord: r·(1 − cos(Δφ/2)) ≤ tol, with the exact angular steps.
    ang = np.unwrap(np.arctan2(pts[:, 1] - 50, pts[:, 0] - 50))
    sag = 10.0 * (1 - np.cos(np.abs(np.diff(ang)) / 2))
    assert sag.max() <= tol + 1e-12
    assert abs(abs(ang[-1] - ang[0]) - 2 * math.pi) < 1e-9  # closed full turn
    assert chord_deviation(d, tol) <= tol + 1e-12
    # Not wastefully fine either: within a factor ~2 of the fewest chords for this tol.
    n_min = math.ceil(math.pi / math.acos(1 - tol / 10.0))
    assert len(pts) - 1 <= 2 * n_min + 1


def test_ellipse_points_satisfy_equation_and_start_at_3_oclock() -> None:
    d = read_svg(svg('<ellipse cx="30" cy="40" rx="20" ry="5"/>'))
    (pts,) = points(d, 0.01)
    x, y = pts[:, 0] - 30, (100 - pts[:, 1]) - 40  # back to page coordinates
    assert np.allclose((x / 20) ** 2 + (y / 5) ** 2, 1.0, atol=1e-12)
    assert np.allclose(pts[0], [50, 60])
    # clockwise on the page (y down) = the second point is below in page coords.
    assert y[1] > 0


def test_rect_rounded_and_clamped_radii() -> None:
    d = read_svg(svg('<rect x="10" y="10" width="40" height="20" rx="5"/>'))
    assert sorted(d.kind.tolist()) == [LINE] * 4 + [ARC] * 4
    (pts,) = points(d, 1e-4)
    perim = np.hypot(*np.diff(pts, axis=0).T).sum()
    assert perim == pytest.approx(2 * (40 + 20) - 8 * 5 + 2 * math.pi * 5, abs=1e-3)
    # rx larger than half the width is clamped to w/2 (SVG 1.1 §9.2); ry defaults to rx and
    # is clamped to h/2: the rectangle becomes the inscribed ellipse.
    d2 = read_svg(svg('<rect x="0" y="0" width="20" height="10" rx="50"/>'))
    (p2,) = points(d2, 1e-4)
    x, y = p2[:, 0], 100 - p2[:, 1]
    assert np.allclose(((x - 10) / 10) ** 2 + ((y - 5) / 5) ** 2, 1.0, atol=1e-12)


def test_line_polyline_polygon() -> None:
    d = read_svg(svg('<line x1="1" y1="2" x2="3" y2="4" stroke="black"/>'
                     '<polyline points="0,0 10,0 10,10" stroke="black" fill="none"/>'
                     '<polygon points="20 20, 30 20, 30 30"/>'))
    a, b, c = points(d)
    assert np.allclose(a, [[1, 98], [3, 96]])
    assert np.allclose(b, [[0, 100], [10, 100], [10, 90]])
    assert np.allclose(c, [[20, 80], [30, 80], [30, 70], [20, 80]])  # polygon closes


def test_path_commands_absolute_and_relative_match_svgpathtools() -> None:
    import svgpathtools

    dstr = ("M10 10 L20 10 H30 V20 l5 5 h5 v-5 C50 30 60 30 70 20 S 80 10 90 20 "
            "Q 90 40 70 40 T 50 40 q -5 5 -10 0 t -10 0 A 10 5 30 0 1 10 50 "
            "a 5 5 0 1 0 10 10 c 1 2 3 4 5 6 s 2 2 4 0 z M 5 90 l 10 0")
    d = read_svg(svg(f'<path d="{dstr}" stroke="black" fill="none"/>'))
    ref = svgpathtools.parse_path(dstr)
    refsegs = [s for s in ref if s.start != s.end]
    assert d.kind.shape[0] == len(refsegs)
    t = np.linspace(0, 1, 7)
    for i, seg in enumerate(refsegs):
        mine = evaluate(np.full(7, d.kind[i]), np.repeat(d.params[i:i + 1], 7, 0), t)
        theirs = np.array([[seg.point(x).real, 100 - seg.point(x).imag] for x in t])
        assert np.allclose(mine, theirs, atol=1e-9), (i, type(seg).__name__)
    assert set(d.kind.tolist()) == {LINE, CUBIC, ARC}
    assert d.n_strokes == 2  # the second M starts a new pen-down run


def test_arc_exact_semicircle() -> None:
    d = read_svg(svg('<path d="M0 50 A 10 10 0 0 1 20 50"/>'))
    (pts,) = points(d, 0.001)
    assert np.allclose(np.hypot(pts[:, 0] - 10, pts[:, 1] - 50), 10, atol=1e-9)
    # sweep=1 in the y-down page goes through page y = 40 (the top), i.e. drawing y = 60
    assert pts[:, 1].max() == pytest.approx(60, abs=1e-6)


# --------------------------------------------------------------------------- units, transforms
@pytest.mark.parametrize(("w", "mm"), [("100mm", 100.0), ("10cm", 100.0), ("4in", 101.6),
                                       ("288pt", 101.6), ("384px", 101.6), ("384", 101.6)])
def test_units_of_width(w: str, mm: float) -> None:
    d = read_svg(svg('<line x1="0" y1="0" x2="10" y2="0" stroke="k"/>',
                     f'width="{w}" height="{w}" viewBox="0 0 10 10"'))
    (pts,) = points(d)
    assert pts[1, 0] - pts[0, 0] == pytest.approx(mm, rel=1e-12)
    assert d.page_size_mm == pytest.approx((mm, mm))


def test_no_viewbox_means_px_user_units() -> None:
    d = read_svg(svg('<line x1="0" y1="0" x2="96" y2="0" stroke="k"/>',
                     'width="200mm" height="100mm"'))
    (pts,) = points(d)
    assert pts[1, 0] == pytest.approx(25.4)


def test_viewbox_offset_and_aspect_meet_centres() -> None:
    # viewBox 2:1 into a square page: uniform scale 1 mm/unit, centred vertically (25 mm).
    d = read_svg(svg('<line x1="-50" y1="0" x2="50" y2="0" stroke="k"/>',
                     'width="100mm" height="100mm" viewBox="-50 0 100 50"'))
    (pts,) = points(d)
    assert np.allclose(pts, [[0, 75], [100, 75]])
    d2 = read_svg(svg('<line x1="-50" y1="50" x2="50" y2="50" stroke="k"/>',
                      'width="100mm" height="100mm" viewBox="-50 0 100 50" '
                      'preserveAspectRatio="none"'))
    (p2,) = points(d2)
    assert np.allclose(p2, [[0, 0], [100, 0]])


def test_nested_group_transforms_compose() -> None:
    body = ('<g transform="translate(50,50)"><g transform="rotate(90)">'
            '<g transform="scale(2)"><line x1="0" y1="0" x2="10" y2="0" stroke="k" '
            'transform="translate(1 0)"/></g></g></g>')
    d = read_svg(svg(body))
    (pts,) = points(d)
    # local (1,0)→scale (2,0)→rot90 (0,2)→(50,52) page → drawing (50, 48); (11,0)→(50,72)→28
    assert np.allclose(pts, [[50, 48], [50, 28]])


def test_skew_and_matrix_transform_on_circle_stays_exact() -> None:
    d = read_svg(svg('<circle cx="0" cy="0" r="10" transform="matrix(1 0 0.5 1 50 50) '
                     'skewY(10)"/>'))
    (pts,) = points(d, 0.001)
    m = np.array([[1, 0.5], [0, 1]]) @ np.array([[1, 0], [math.tan(math.radians(10)), 1]])
    page = np.stack((pts[:, 0], 100 - pts[:, 1]), axis=1) - [50, 50]
    local = page @ np.linalg.inv(m).T
    assert np.allclose(np.hypot(*local.T), 10.0, atol=1e-9)
    assert chord_deviation(d, 0.01) <= 0.01 + 1e-12


def test_use_references_with_offset() -> None:
    body = ('<defs><path id="p" d="M0 0 L10 0"/></defs>'
            '<use href="#p" x="5" y="5" stroke="k"/>')
    d = read_svg(svg(body))
    (pts,) = points(d)
    assert np.allclose(pts, [[5, 95], [15, 95]])


# --------------------------------------------------------------------------- visibility, layers
def test_hidden_elements_are_skipped() -> None:
    body = ('<line x1="0" y1="0" x2="1" y2="0" stroke="k" style="display:none"/>'
            '<g visibility="hidden"><line x1="0" y1="1" x2="1" y2="1" stroke="k"/>'
            '<line x1="0" y1="2" x2="1" y2="2" stroke="k" visibility="visible"/></g>'
            '<line x1="0" y1="3" x2="1" y2="3" stroke="none" fill="none"/>'
            '<line x1="0" y1="4" x2="1" y2="4" stroke="k"/>')
    d = read_svg(svg(body))
    ys = sorted(round(100 - p[0, 1]) for p in points(d))
    assert ys == [2, 4]
    assert any("hidden" in w for w in d.warnings)


def test_layers_by_label_or_id() -> None:
    body = ('<g inkscape:groupmode="layer" inkscape:label="cut" id="layer1">'
            '<line x1="0" y1="0" x2="1" y2="0" stroke="k" id="a"/></g>'
            '<g inkscape:groupmode="layer" inkscape:label="engrave" id="layer2">'
            '<line x1="0" y1="5" x2="1" y2="5" stroke="k" id="b"/></g>')
    assert len(points(read_svg(svg(body)))) == 2
    d = read_svg(svg(body), layers=["engrave"])
    assert [s.ident for s in d.sources] == ["b"] and d.sources[0].layer == "engrave"
    d = read_svg(svg(body), layers=["layer1"])
    assert [s.ident for s in d.sources] == ["a"]
    with pytest.raises(InputError, match=r'no layer named .*nope.*"cut" \(id layer1\)'):
        read_svg(svg(body), layers=["nope"])


# --------------------------------------------------------------------------- bad input
def test_malformed_xml_names_the_line(tmp_path: Path) -> None:
    f = tmp_path / "bad.svg"
    f.write_text(f"<svg {NS}>\n<path d='M0 0 L1 1'>\n</svg>\n")
    with pytest.raises(InputError, match=r"bad\.svg:3: malformed XML: mismatched tag"):
        read_svg(f)


def test_no_strokes() -> None:
    with pytest.raises(InputError, match="no strokes to draw"):
        read_svg(svg('<text x="0" y="0"> \n </text><text x="0" y="9" fill="none">a</text>'))


@pytest.mark.parametrize("d", ["M0 0 L1e400 0", "M0 0 L 1e9 0"])
def test_nan_or_enormous_coordinates(d: str) -> None:
    with pytest.raises(InputError, match=r":2: <path> has a coordinate that is not finite or "
                                         r"larger than"):
        read_svg(svg(f'<path d="{d}"/>'), file="x.svg")


def test_bad_path_data_is_drawn_up_to_the_error_and_named() -> None:
    # SVG 2 §9.5.4: render up to the last complete segment before the error.
    d = read_svg(svg('<path id="p" d="M 0 0 L 5 0 L 5"/>'), file="x.svg")
    (pts,) = points(d)
    assert np.allclose(pts, [[0, 100], [5, 100]])
    (w,) = [w for w in d.warnings if "invalid d data" in w]
    assert "column 16" in w  # the end of the data and '<path id="p"> at line 2' in w
    with pytest.raises(InputError, match=r"x\.svg: no strokes to draw.*invalid d data at "
                                         r"column 1: path data must start with a moveto"):
        read_svg(svg('<path d="L 0 0 L 5 5"/>'), file="x.svg")


def test_bad_transform_and_unit() -> None:
    with pytest.raises(InputError, match="transform="):
        read_svg(svg('<path d="M0 0 L1 1" transform="rotate(1 2)"/>'))
    with pytest.raises(InputError, match="unsupported unit 'vw'"):
        read_svg(svg('<path d="M0 0 L1 1"/>', 'width="10vw" height="10mm"'))


def test_unreadable_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read file"):
        read_svg(tmp_path / "missing.svg")
    with pytest.raises(InputError, match="cannot read file"):
        read_svg(tmp_path)


def test_not_svg_root() -> None:
    with pytest.raises(InputError, match="not <svg>"):
        read_svg(b"<html/>")
