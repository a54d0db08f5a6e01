"""SVG text drawn with single-stroke fonts: the reader's rules, each against what the SVG/CSS
specifications (and the fonts' own data) say, worked out by hand. The layout against a
browser is `test_text_browser.py`, the glyphs against vpype `test_text_vpype.py`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fivebar_host.errors import InputError
from fivebar_host.toolpath.fonts.library import FontLibrary, TextConfig, norm
from fivebar_host.toolpath.fonts.svgfont import load_svg_font
from fivebar_host.toolpath.geometry import Drawing
from fivebar_host.toolpath.svg import read_svg
from fivebar_host.toolpath.svg.text import CharLayout, family_list

NS = ('xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
      'width="200mm" height="100mm" viewBox="0 0 200 100"')
LIB = FontLibrary()
FUT = LIB.load("futural")
U = 31.5 / 1000  # em per Hershey unit
#: A user font with a ligature, kerning and a glyph with a curve (font units: 100 to the em).
TOY = b"""<svg xmlns="http://www.w3.org/2000/svg"><defs><font id="toy" horiz-adv-x="50">
<font-face font-family="Toy Font" units-per-em="100" ascent="80" descent="-20"/>
<glyph unicode="a" glyph-name="a" horiz-adv-x="40" d="M0 0 L40 0"/>
<glyph unicode="b" glyph-name="b" horiz-adv-x="60" d="M0 0 C0 50 60 50 60 0"/>
<glyph unicode="ab" glyph-name="a_b" horiz-adv-x="90" d="M0 0 L90 90"/>
<glyph unicode=" " glyph-name="space" horiz-adv-x="30"/>
<hkern u1="a" g2="b" k="10"/>
</font></defs></svg>"""


def svg(body: str) -> bytes:
    return f"<svg {NS}>\n{body}\n</svg>\n".encode()


def read(body: str, **kw: object) -> tuple[Drawing, list[CharLayout]]:
    layouts: list[CharLayout] = []
    d = read_svg(svg(body), file="t.svg", layouts=layouts, **kw)  # type: ignore[arg-type]
    return d, layouts


def advance(font: object, text: str, size: float) -> float:
    return sum(font.glyph(c).advance for c in text) * size / 1000  # type: ignore[attr-defined]


# --------------------------------------------------------------------------- drawing
def test_text_draws_each_glyph_stroke_once_filled_or_stroked() -> None:
    """Text is the documented exception to fill-only outlines: fill, stroke or both draw the
    glyph strokes once; neither draws nothing."""
    want = sum(FUT.glyph(c).n_strokes for c in "Hi!")
    for paint in ('', 'fill="none" stroke="red"', 'fill="blue" stroke="red"'):
        d, _ = read(f'<text x="10" y="50" font-family="futural" font-size="10" {paint}>Hi!'
                    "</text>")
        assert d.n_strokes == want and d.texts[0].strokes == want, paint
    with pytest.raises(InputError, match="no strokes to draw"):
        read('<text x="10" y="50" fill="none">Hi</text>')


def test_glyph_geometry_is_the_fonts_placed_by_size_and_position() -> None:
    d, lay = read('<text x="20" y="50" font-family="HersheySans1" font-size="10">I</text>')
    # futural "I": one stroke at x = 4 Hershey units right of the origin, cap height 21 units
    x = 20 + 4 * U * 10
    pts = d.to_file_frame(d.params[:, :4].reshape(-1, 2))
    assert np.allclose(pts, [[x, 50 - 21 * U * 10], [x, 50]])
    assert np.allclose(lay[0].user[0], [20, 50])


def test_missing_glyph_is_named_by_code_point_position_and_element() -> None:
    body = '<text id="t" x="0" y="20" font-family="futural">ok <tspan id="s">\u2603</tspan></text>'
    with pytest.raises(InputError, match=r"t\.svg:2: character '\u2603' \(U\+2603\) at "
                                         r"position 4 of the text of <text id=\"t\"> \(in "
                                         r"<tspan id=\"s\">\) has no glyph in HersheySans1 "
                                         r"\(futural\) nor the fallback Relief SingleLine"):
        read(body)


def test_fallback_draws_what_the_font_lacks_and_says_so() -> None:
    d, _ = read('<text x="0" y="20" font-family="futural">Café</text>')
    assert d.texts[0].fonts == ("HersheySans1 (futural)", "Relief SingleLine (fallback)")
    assert any("'é' (first U+00E9 at position 4)" in w and "fallback Relief" in w
               for w in d.warnings)
    with pytest.raises(InputError, match=r"U\+00E9.*\(no \[text\] fallback\)"):
        read('<text x="0" y="20" font-family="futural">Café</text>',
             text=TextConfig(fallback=""))


def test_font_family_list_falls_back_per_character_and_notes_unknown_names() -> None:
    d, _ = read('<text x="0" y="20" font-family="NoSuchFont, futural, Relief SingleLine">'
                "aé</text>")
    assert d.texts[0].fonts == ("HersheySans1 (futural)", "Relief SingleLine")
    assert any("font-family 'NoSuchFont' is not a single-stroke font" in w for w in d.warnings)
    d, _ = read('<text x="0" y="20" font-family="NoSuchFont">a</text>')
    assert d.texts[0].fonts == ("HersheySerifMed (timesr)",)  # the default: serif


@pytest.mark.parametrize(("family", "label"), [
    ("sans-serif", "HersheySans1 (futural)"), ("serif", "HersheySerifMed (timesr)"),
    ("cursive", "HersheyScript1 (scripts)"), ("'cursive'", "Hershey Cursive (cursive)"),
    ("monospace", "HersheySansMono"), ("fantasy", "HersheyGothEnglish (gothiceng)"),
    ("Arial", "HersheySans1 (futural)"), ("'Times New Roman'", "HersheySerifMed (timesr)"),
    ("Courier New", "HersheySansMono"), ("HersheyScriptMed", "HersheyScriptMed (scriptc)"),
    ("timesib", "HersheySerifBoldItalic (timesib)"), ("hershey-sans", "HersheySans1 (futural)"),
    ('"Relief SingleLine Outline"', "Relief SingleLine"), ("system-ui", "HersheySans1 (futural)"),
])
def test_names_resolve_as_the_issue_lists_them(family: str, label: str) -> None:
    d, _ = read(f"<text x=\"0\" y=\"20\" font-family=\"{family.replace(chr(34), '&quot;')}\">"
                "a</text>")
    assert d.texts[0].fonts == (label,)


def test_weight_and_style_pick_faces_and_synthesize_oblique() -> None:
    d, _ = read('<text x="0" y="20" font-family="serif" font-weight="700" font-style="italic">'
                'a</text><text x="0" y="40" style="font: bold 10px sans-serif">a</text>')
    assert [t.fonts for t in d.texts] == [("HersheySerifBoldItalic (timesib)",),
                                          ("HersheySansMed (futuram)",)]
    up, _ = read('<text x="0" y="20" font-family="futural" font-size="10">l</text>')
    sl, _ = read('<text x="0" y="20" font-family="futural" font-size="10" font-style="italic">'
                 "l</text>")
    (a, b), (c, e) = (up.to_file_frame(x.params[0, :4].reshape(2, 2)) for x in (up, sl))
    # the top of the stem moves right by tan 14° × its height; the baseline point stays
    assert math.isclose(c[0] - a[0], math.tan(math.radians(14)) * (b[1] - a[1]), rel_tol=1e-9)
    assert np.allclose(e, b)


def test_user_font_ligature_kerning_and_curves(tmp_path: Path) -> None:
    f = tmp_path / "toy.svg"
    f.write_bytes(TOY)
    cfg = TextConfig(aliases={"Toy": str(f)})
    d, lay = read('<text x="0" y="50" font-family="Toy" font-size="100">ab a b</text>',
                  text=cfg)
    # "ab" is the ligature (one glyph, its second character takes no room); no kerning
    # across a space
    assert lay[0].chars == "ab a b"
    assert np.allclose(lay[0].user[:, 0], [0, 90, 90, 120, 160, 190])
    assert lay[0].drawn.tolist() == [True, False, False, True, False, True]
    assert d.kind.tolist() == [0, 0, 1]  # the ligature's line, a's line, b's curve
    d, lay = read('<text x="0" y="50" font-family="Toy" font-size="100" letter-spacing="1">'
                  "ab</text>", text=cfg)
    assert lay[0].drawn.tolist() == [True, True]  # letter-spacing: no ligature (CSS Text 3)
    assert np.allclose(lay[0].user[:, 0], [0, 31])  # a (40) − kern (10) + spacing (1)
    d, lay = read('<text x="0" y="50" font-family="Toy" font-size="100" '
                  'font-kerning="none">a b</text>', text=cfg)
    assert np.allclose(lay[0].user[:, 0], [0, 40, 70])


def test_font_dirs_find_fonts_by_file_and_family_name(tmp_path: Path) -> None:
    (tmp_path / "toyfile.svg").write_bytes(TOY)
    (tmp_path / "notafont.svg").write_bytes(b"<svg xmlns='http://www.w3.org/2000/svg'/>")
    cfg = TextConfig(font_dirs=(str(tmp_path),))
    for name in ("toyfile", "Toy Font"):
        d, _ = read(f'<text x="0" y="20" font-family="{name}">a</text>', text=cfg)
        assert d.texts[0].fonts == ("Toy Font (toyfile.svg)",)
    d, _ = read(f'<text x="0" y="20" font-family="{tmp_path / "toyfile.svg"}">a</text>')
    assert d.texts[0].fonts == ("HersheySerifMed (timesr)",)  # a drawing never names a file


def test_svg_font_errors_name_the_font_file() -> None:
    with pytest.raises(InputError, match=r"bad\.svg: not an SVG font"):
        load_svg_font(b"<svg xmlns='http://www.w3.org/2000/svg'/>", file="bad.svg")
    broken = TOY.replace(b'd="M0 0 L40 0"', b'd="M0 0 L40"')
    font = load_svg_font(broken, file="broken.svg")
    with pytest.raises(InputError, match=r"broken\.svg:3: font glyph 'a' has invalid path "
                                         r"data at column"):
        font.glyph("a")


def test_names_compare_without_case_spaces_and_regular() -> None:
    assert norm("Hershey Sans") == norm("hershey-sans") == norm("HersheySans_Regular")
    assert family_list("'Hershey Sans', serif ,  Times  New Roman") == [
        ("Hershey Sans", True), ("serif", False), ("Times New Roman", False)]


# --------------------------------------------------------------------------- layout rules
def test_white_space_collapses_or_is_preserved() -> None:
    _, lay = read('<text x="0" y="20">  a \n\t b <tspan> c </tspan> </text>'
                  '<text x="0" y="40" xml:space="preserve"> a\n b </text>')
    assert [x.chars for x in lay] == ["a b c", " a  b "]


def test_position_lists_apply_to_characters_and_descendants_override() -> None:
    _, lay = read('<text font-family="futural" font-size="10" x="10 20 30" y="50" '
                  'dy="0 1 1 1">abc<tspan x="100">de</tspan></text>')
    x, y = lay[0].user.T
    assert np.allclose(x[:4], [10, 20, 30, 100])
    assert np.allclose(x[4], 100 + FUT.glyph("d").advance * 10 / 1000)
    assert np.allclose(y, [50, 51, 52, 53, 53])


def test_rotate_repeats_its_last_value_and_glyphs_turn_about_their_origin() -> None:
    _, lay = read('<text x="10" y="50" font-family="futural" rotate="10 20">abcd</text>')
    assert lay[0].rotate.tolist() == [10, 20, 20, 20]


def test_anchor_spacing_and_display_visibility() -> None:
    size = 10.0
    _, lay = read(f'<text x="100" y="50" font-family="futural" font-size="{size}" '
                  'text-anchor="end" letter-spacing="1" word-spacing="2">a b<tspan '
                  'visibility="hidden">c</tspan><tspan display="none">zzz</tspan></text>')
    total = advance(FUT, "a bc", size) + 4 * 1 + 2
    assert lay[0].chars == "a bc"
    assert math.isclose(lay[0].user[0, 0], 100 - total, abs_tol=1e-9)
    assert lay[0].drawn.tolist() == [True, False, True, False]  # hidden: space kept


def test_text_on_a_path_follows_the_path_and_hides_what_runs_off() -> None:
    _, lay = read('<path id="p" d="M 10 50 L 60 50" transform="rotate(90 10 50)"/>'
                  '<text font-family="futural" font-size="10"><textPath href="#p" '
                  'startOffset="40">iiiii</textPath></text>')
    (c,) = lay
    # the path runs down from (10, 50): glyph origins go down it, turned by 90°
    assert np.allclose(c.user[0], [10, 90]) and np.allclose(c.rotate[0], 90)
    adv = FUT.glyph("i").advance * 10 / 1000
    shown = [40 + k * adv + adv / 2 <= 50 for k in range(5)]
    assert c.placed.tolist() == shown and not all(shown)


def test_text_path_to_nothing_draws_nothing_and_says_so() -> None:
    d, _ = read('<text x="0" y="9"><textPath href="#none">gone</textPath>x</text>')
    assert any("<textPath> refers to no path" in w for w in d.warnings)
    assert d.texts[0].glyphs == 1


def test_vertical_and_right_to_left_text_are_refused() -> None:
    with pytest.raises(InputError, match=r"t\.svg:2: <text> has writing-mode 'tb': vertical"):
        read('<text x="0" y="9" writing-mode="tb">a</text>')
    with pytest.raises(InputError, match="right-to-left text is not supported"):
        read('<text x="0" y="9" style="direction: rtl">a</text>')


def test_transforms_css_layers_use_and_clip_apply_to_text() -> None:
    body = ('<style>.big { font-size: 20px } #t { font-family: futural }</style>'
            '<g id="layer" inkscape:groupmode="layer" inkscape:label="words" '
            'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape">'
            '<text id="t" class="big" x="0" y="0" transform="translate(50 50) scale(2)">I'
            "</text></g>"
            '<clipPath id="c"><rect x="0" y="0" width="200" height="38"/></clipPath>'
            '<symbol id="s"><text x="0" y="40" font-family="futural">I</text></symbol>'
            '<use href="#s" x="100" clip-path="url(#c)"/>')
    d, lay = read(body)
    assert [s.layer for s in d.sources] == ["words", None]
    assert np.allclose(d.to_file_frame(lay[0].drawing[0]), [50, 50])  # (0, 0) translated
    assert math.isclose(d.texts[0].size_mm, 40.0)  # 20 user units (mm) scaled by 2
    # the <use>d "I" (16 user units: stem from y = 40 − 21 units to 40) is cut at y = 38
    pts = d.to_file_frame(d.params[d.stroke_source[d.stroke] == 1][:, :4].reshape(-1, 2))
    assert math.isclose(pts[:, 1].max(), 38.0, abs_tol=1e-6)
    assert math.isclose(pts[:, 1].min(), 40 - 21 * U * 16, abs_tol=1e-6)


def test_streamed_and_whole_tree_reads_agree() -> None:
    body = ('<g><text x="5" y="20" font-family="futural">ab<tspan dy="3">c</tspan>d</text>'
            '</g><g><path d="M0 0L9 9" stroke="black"/></g>')
    a = read_svg(svg(body))
    b = read_svg(svg(body + '<use href="#late"/><g id="late"/>'))  # a forward reference
    assert np.array_equal(a.params, b.params) and a.texts == b.texts


def test_decorations_are_one_pen_line_each_at_the_fonts_positions() -> None:
    size = 10.0
    d, _ = read(f'<text x="10" y="50" font-family="futural" font-size="{size}" '
                'text-decoration="underline">ab<tspan baseline-shift="super">c</tspan>'
                '<tspan style="text-decoration: line-through">d</tspan></text>')
    glyph_strokes = sum(FUT.glyph(ch).n_strokes for ch in "abcd")
    assert d.texts[0].strokes == glyph_strokes + 2 == d.n_strokes
    lines = d.to_file_frame(d.params[-2:, :4].reshape(-1, 2)).reshape(-1, 2, 2)
    total = advance(FUT, "abcd", size)
    # underline: the futural file gives no underline-position, so 0.1 em below the
    # baseline, across all four letters (the superscript does not move it)
    assert np.allclose(lines[0], [[10, 51], [10 + total, 51]])
    # line-through of "d": half its x-height above the baseline
    xd = 10 + advance(FUT, "abc", size)
    y = 50 - FUT.x_height / 2 * size / 1000
    assert np.allclose(lines[1], [[xd, y], [10 + total, y]])


def test_what_is_not_applied_is_said_once_per_kind() -> None:
    d, _ = read('<text x="0" y="9" textLength="50" font-variant="small-caps">a</text>'
                '<text x="0" y="19" textLength="50">b</text>'
                '<text x="0" y="29"><tref href="#x"/>c<textPath href="#p" side="right">'
                "d</textPath></text><path id='p' d='M0 50 L90 50'/>")
    notes = [w for w in d.warnings if "textLength" in w]
    assert len(notes) == 1 and "2 elements" in notes[0]
    assert any("small-caps" in w for w in d.warnings)
    assert any("<tref> inside <text> is not text content" in w for w in d.warnings)
    assert any("<textPath> side is not used" in w for w in d.warnings)


def test_font_size_zero_draws_nothing_and_huge_text_is_refused() -> None:
    d, lay = read('<text x="0" y="9" font-size="0">gone</text><text x="0" y="19">a</text>')
    assert [t.glyphs for t in d.texts] == [0, 1] and lay[0].chars == "gone"
    with pytest.raises(InputError, match="not finite or larger than"):
        read('<text x="0" y="9" font-size="1e200">a</text>')
