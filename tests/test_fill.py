"""Hatching and hidden lines (`toolpath.fill`, `compile.fill`) on cases worked out by hand,
including the failures of the tools fivebar replaces: the EggBot/AxiDraw Hatch Fill
extension's issues 32 (the even-odd test flips when an inset is set), 90 (thin objects get
no hatch), 177 (a traceback on `<polygon>`) and 36 (a pen lift per hatch line), and
vpype-occult's 7 (only polygons occlude) and 27 (fill-only shapes used as masks are drawn).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.compile.fill import Hatch, fill_drawing, layer_settings
from fivebar_host.config import load_profile
from fivebar_host.errors import InputError
from fivebar_host.toolpath.geometry import Drawing, flatten
from fivebar_host.toolpath.svg import read_svg

ROOT = Path(__file__).resolve().parent.parent


def svg(body: str, size: int = 100) -> bytes:
    return (f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/'
            f'xlink" width="{size}mm" height="{size}mm" viewBox="0 0 {size} {size}">{body}'
            '</svg>').encode()


def runs(d: Drawing, role: str | None = None) -> list[np.ndarray]:
    """Strokes as page-frame polylines (y down), only those of sources with `role`."""
    p = flatten(d, 1e-4)
    out = []
    for i, (a, b) in enumerate(zip(p.offsets[:-1], p.offsets[1:], strict=True)):
        src = d.sources[int(d.stroke_source[p.stroke[i]])]
        if role is None or src.role == role:
            out.append(d.to_file_frame(p.points[a:b]))
    return out


def length(rs: list[np.ndarray]) -> float:
    return float(sum(np.hypot(*np.diff(r, axis=0).T).sum() for r in rs))


def fill(body: str, spacing: float = 1.0, hiding: bool = False, inset: float = 0.0,
         angle: float = 0.0, hatching: bool = True) -> Drawing:
    return fill_drawing(read_svg(svg(body)), Hatch(spacing, angle, False, inset), hiding,
                        0.01, hatching=hatching)


# ------------------------------------------------------------------ the clip composes
def test_filled_shape_under_a_clip_path_draws_the_clips_edge() -> None:
    # resvg's clip-path test: a green rectangle clipped to a star shows a star; the
    # rectangle's own outline lies outside the star, so before this only nothing (or the
    # frame) was drawn, silently
    star = "M50 5 L76.5 86.5 L7.2 36.1 L92.8 36.1 L23.5 86.5 Z"
    d = read_svg(svg(f'<clipPath id="c"><path d="{star}"/></clipPath>'
                     '<rect width="100" height="100" fill="green" clip-path="url(#c)"/>'))
    drawn = shapely.union_all([shapely.LineString(r) for r in runs(d)])
    want = shapely.Polygon([(50, 5), (76.5, 86.5), (7.2, 36.1), (92.8, 36.1), (23.5, 86.5)])
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(shapely.node(want.exterior))))
    outline = shapely.union_all(faces).boundary
    assert drawn.length == pytest.approx(outline.length, rel=1e-6)
    assert drawn.hausdorff_distance(outline) < 1e-6


def test_unclipped_and_stroke_only_elements_are_drawn_as_before() -> None:
    d = read_svg(svg('<rect x="10" y="10" width="20" height="20" fill="none" '
                     'stroke="black"/><clipPath id="c"><rect width="15" height="100"/>'
                     '</clipPath><rect x="10" y="40" width="20" height="20" fill="none" '
                     'stroke="black" clip-path="url(#c)"/>'))
    assert length(runs(d)) == pytest.approx(80 + 5 + 20 + 5)


# ------------------------------------------------------------------ hatching
def test_hatch_lines_lie_on_the_grid_inside_the_region() -> None:
    d = fill('<rect x="10.3" y="20" width="40" height="30" fill="black"/>', spacing=1.0)
    hatch = runs(d, "hatch")
    assert len(hatch) == 1  # one run for a simple region
    pts = np.concatenate(hatch)
    assert pts[:, 0].min() >= 10.3 - 1e-9 and pts[:, 0].max() <= 50.3 + 1e-9
    # the hatch lines (horizontal chords) on y' = (k + ½)·1 mm in the drawing frame (y up)
    r = hatch[0]
    flat = np.abs(np.diff(r[:, 1])) < 1e-12
    ys = 100 - r[:-1][flat & (np.abs(np.diff(r[:, 0])) > 1), 1]
    assert np.allclose((ys - 0.5) % 1.0, 0.0, atol=1e-9)
    assert len(np.unique(ys.round(9))) == 30
    assert d.fill is not None and d.fill.hatch_mm == pytest.approx(30 * 40)


def test_evenodd_hole_stays_a_hole_with_an_inset() -> None:
    # EggBot/AxiDraw hatch issue 32: with an inset, rings offset one by one flip the even-odd
    # test and fill the hole. Here the region is found first, then shrunk as a whole.
    ring = ("M90 50 A40 40 0 1 1 10 50 A40 40 0 1 1 90 50 Z "
            "M70 50 A20 20 0 1 1 30 50 A20 20 0 1 1 70 50 Z")  # same direction: evenodd hole
    for inset in (0.0, 2.0):
        d = fill(f'<path d="{ring}" fill="black" fill-rule="evenodd"/>', 0.5, inset=inset)
        r = np.hypot(*(np.concatenate(runs(d, "hatch")) - 50).T)
        assert r.min() >= 20 + inset - 1e-3 and r.max() <= 40 - inset + 1e-3
        assert d.fill is not None
        area = math.pi * ((40 - inset) ** 2 - (20 + inset) ** 2)
        assert d.fill.hatch_mm * 0.5 == pytest.approx(area, rel=0.01)


def test_thin_objects_get_a_hatch_line() -> None:
    # EggBot/AxiDraw hatch issue 90: a shape thinner than the spacing, between two grid
    # lines, gets no hatch. Here it gets one line through its middle.
    d = fill('<rect x="10" y="50.2" width="60" height="0.3" fill="black"/>'
             '<circle cx="80" cy="20" r="0.2" fill="black"/>', spacing=2.0)
    hatch = runs(d, "hatch")
    assert len(hatch) == 2
    bar = next(r for r in hatch if r[:, 0].max() > 60)
    assert np.allclose(bar[:, 1], 50.35) and np.ptp(bar[:, 0]) == pytest.approx(60)


def test_polygons_and_polylines_are_hatched() -> None:
    # EggBot/AxiDraw hatch issue 177: a traceback on <polygon>
    d = fill('<polygon points="10,10 90,10 10,90 90,90" fill="black" fill-rule="evenodd"/>'
             '<polyline points="60,60 95,60 95,95" fill="black"/>', 1.0)
    assert d.fill is not None and d.fill.regions == 3  # two bow-tie lobes and the triangle
    assert d.fill.hatch_mm == pytest.approx((2 * 1600 + 612.5) / 1.0, rel=0.01)


U_SHAPES = ('<path d="M5 5 H35 V35 H27 V12 H13 V35 H5 Z" fill="black"/>'
            '<path d="M45 5 H95 V15 H55 V25 H95 V35 H55 V45 H95 V55 H45 Z" fill="black"/>'
            '<path d="M50 60 L76.5 95 L30 70 L80 70 L33.5 95 Z" fill="black" '
            'fill-rule="evenodd"/><circle cx="20" cy="70" r="15" fill="black"/>')


def test_one_pen_lift_per_simple_region() -> None:
    # EggBot/AxiDraw hatch issue 36: a pen lift per hatch line. Here a U, a comb, the
    # five points of an even-odd star and a disc: each simple region is one run
    d = fill(U_SHAPES, spacing=0.7, angle=30)
    assert d.fill is not None
    assert d.fill.simple_regions == 8  # the U, the comb, the star's five points, the disc
    assert d.fill.hatch_runs_simple == d.fill.simple_regions


def test_pen_lifts_of_the_compiled_job(tmp_path: Path) -> None:
    f = tmp_path / "u.svg"
    f.write_bytes(svg(U_SHAPES))
    prof = load_profile(ROOT / "configs" / "pen-servo.toml")
    job = compile_job(f, prof, CompileOptions(hatch_mm=0.8, hiding=True, fit=True))
    # fill-only shapes under --hiding: no outline; 8 simple regions, the pen down 8 times
    assert job.pen_downs <= 8


# ------------------------------------------------------------------ hidden lines
@pytest.mark.parametrize(("shape", "cut"), [
    ('<circle cx="50" cy="50" r="10" fill="white"/>', 20.0),
    ('<ellipse cx="50" cy="50" rx="15" ry="5" fill="white"/>', 30.0),
    ('<rect x="40" y="40" width="20" height="20" rx="5" fill="white"/>', 20.0),
    ('<path d="M35 55 A15 15 0 0 1 65 55 Z" fill="white"/>', 2 * math.sqrt(200)),
    ('<defs><circle id="c" r="10"/></defs><use href="#c" x="50" y="50" fill="white"/>', 20.0),
])
def test_every_filled_element_occludes(shape: str, cut: float) -> None:
    # vpype-occult issue 7: only polygons occlude. A line beneath each shape is cut at the
    # shape's exact edge.
    d = fill('<path d="M0 50 H100" stroke="black"/>' + shape, hiding=True, hatching=False)
    line = [r for r in runs(d) if np.allclose(r[:, 1], 50)]
    assert length(line) == pytest.approx(100 - cut, abs=2e-3)
    assert d.fill is not None and d.fill.hidden_mm == pytest.approx(cut, abs=2e-3)


def test_fill_only_shapes_hide_without_being_drawn() -> None:
    # vpype-occult issue 27: fill-only shapes used as masks are stroked. Under --hiding a
    # fill-only shape hides what is beneath it and draws nothing itself; a stroked one
    # draws its (visible) outline.
    d = fill('<path d="M0 50 H100" stroke="black"/>'
             '<rect x="20" y="40" width="20" height="20" fill="white"/>'
             '<rect x="60" y="40" width="20" height="20" fill="white" stroke="black"/>',
             hiding=True, hatching=False)
    drawn = length(runs(d))
    assert drawn == pytest.approx(60 + 80, abs=1e-3)
    assert d.fill is not None and d.fill.unstroked_mm == pytest.approx(80, abs=1e-3)


def test_paint_order_an_element_never_hides_itself_or_what_is_above() -> None:
    d = fill('<rect x="20" y="20" width="60" height="60" fill="white" stroke="black"/>'
             '<path d="M0 50 H100" stroke="black"/>', hiding=True, hatching=False)
    assert length(runs(d)) == pytest.approx(240 + 100, abs=1e-3)


def test_hatch_of_a_covered_shape_is_cut_and_the_cover_hatched() -> None:
    d = fill('<rect x="10" y="10" width="50" height="50" fill="black"/>'
             '<rect x="30" y="30" width="50" height="50" fill="black"/>', 0.5, hiding=True)
    assert d.fill is not None
    assert d.fill.hatch_mm * 0.5 == pytest.approx(2500 + 2500 - 900, rel=0.01)
    lower = runs(d, "hatch")[0]
    inside = (lower[:, 0] > 30 + 1e-6) & (lower[:, 1] > 30 + 1e-6)
    assert not inside.any()


def test_layers_choose_their_hatch_and_can_stay_out_of_hiding() -> None:
    base = Hatch(0.5, 45, False, 0.0)
    assert layer_settings("ink +hatch=1mm +angle=30 +cross", base)[0] == Hatch(1, 30, True, 0)
    assert layer_settings("+nohatch", base)[0].spacing_mm == 0
    assert layer_settings("top +nohide", base)[1] is False
    g = ('<g inkscape:groupmode="layer" inkscape:label="{}" xmlns:inkscape='
         '"http://www.inkscape.org/namespaces/inkscape">{}</g>')
    body = (g.format("lines +nohide", '<path d="M0 50 H100" stroke="black"/>')
            + g.format("cover", '<rect x="20" y="40" width="20" height="20" fill="black"/>'))
    d = fill(body, hiding=True, hatching=False)
    assert length(runs(d)) == pytest.approx(100)


def test_text_is_drawn_once_never_hatched_and_cut_where_covered() -> None:
    # text keeps its documented exception: filled text draws its glyph strokes once; it is
    # not hatched (a single-stroke font has no outline) and hides nothing, but a fill
    # painted over it hides its strokes like any other
    t = '<text x="10" y="50" font-size="20" fill="black">HI</text>'
    plain = fill(t, 0.5)
    assert runs(plain, "hatch") == []
    whole = length(runs(plain))
    cover = '<rect x="0" y="0" width="100" height="100" fill="white"/>'
    with pytest.raises(InputError, match="every line is hidden"):
        fill(t + cover, 0.5, hiding=True)  # the white cover hides it all and is not hatched
    under = fill(cover.replace("white", "black") + t, 0.5, hiding=True)
    assert length(runs(under)) - length(runs(under, "hatch")) == pytest.approx(whole)


def test_joint_iso_arcs_move_one_motor_and_keep_their_gaps(tmp_path: Path) -> None:
    # --hatch-along arm1: on every arc of the hatch motor 1 stays on one whole step, so
    # the executed arc is exactly the requested one; the gaps are at most the spacing
    f = tmp_path / "disc.svg"
    f.write_bytes(svg('<circle cx="50" cy="50" r="40" fill="black"/>'))
    prof = load_profile(ROOT / "configs" / "pen-servo.toml")
    job = compile_job(f, prof, CompileOptions(hatch_mm=0.5, hatch_along="arm1", fit=True))
    d = job.drawing
    hatch = np.array([s.role == "hatch" for s in d.sources])
    k = np.flatnonzero(job.draw)
    on_arc = (d.kind[job.seg_prim] == 2) & hatch[job.source[k]]
    assert on_arc.sum() > 100
    ks = k[on_arc]
    assert np.array_equal(job.steps[ks, 0], job.steps[ks + 1, 0])
    assert d.fill is not None
    (note,) = [n for n in d.fill.notes if "joint-iso" in n]
    lo, hi = (float(v) for v in note.split("is ")[1].split(" mm")[0].split("–"))
    assert 0 < lo <= hi <= 0.5
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm


def test_outlines_of_filled_shapes_are_named_unless_filled_or_hidden(tmp_path: Path) -> None:
    """Without --hatch or --hiding a filled shape is drawn as its edge, and a fill-only one
    (the logo's grey shadow, its white mask) is outlined where the file shows no line: the
    job says how many, and nothing once the options draw what a browser shows."""
    prof = load_profile()
    logo = ROOT / "examples" / "fill_logo.svg"
    plain = compile_job(logo, prof, CompileOptions(fit=True))
    said = [n for n in plain.notes if "filled shape" in n]
    assert said == [n for n in said if n.startswith("6 filled shapes drawn as outlines only "
                                                    "(2 of them with no stroke in the file)")]
    assert len(said) == 1 and "--hatch" in said[0] and "--hiding" in said[0]
    for opts in (CompileOptions(fit=True, hatch_mm=0.8), CompileOptions(fit=True, hiding=True)):
        assert not any("filled shape" in n for n in compile_job(logo, prof, opts).notes)
    one = tmp_path / "one.svg"
    one.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="40mm" '
                   'viewBox="0 0 40 40"><rect x="5" y="5" width="20" height="20" '
                   'fill="black"/><path d="M5 30 L35 30" stroke="black" fill="none"/></svg>')
    notes = compile_job(one, prof, CompileOptions()).notes
    assert next(n for n in notes if "filled shape" in n).startswith(
        "1 filled shape drawn as an outline only (with no stroke in the file)")
    assert not any("filled shape" in n
                   for n in compile_job(ROOT / "examples" / "simple.svg", prof,
                                        CompileOptions()).notes)
