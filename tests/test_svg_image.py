"""SVG `<image>` burned as a raster (`raster/svgimage.py`, issue 32 "Inputs"): a relative
file and a data URI place the same pixels (`href` and `xlink:href`); URLs, absolute paths,
paths leaving the SVG's folder, missing files, broken data and an upload's relative file
are refused by name; the user's placement options apply as to any drawing; the dry run
prints the raster report.  Placement against the browser: tests/test_svg_image_browser.py.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from svgimage_support import MM_PER_PX, PAGE, data_uri, lit_mask, pattern, svg

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, compile_drawing
from fivebar_host.config import load_profile
from fivebar_host.errors import InputError
from fivebar_host.raster.svgimage import compile_svg_images
from fivebar_host.toolpath.svg import read_svg

BODY = '<image {attr}="{href}" x="20" y="10" width="160" height="120"/>'


def test_a_relative_file_and_a_data_uri_place_the_same_pixels(tmp_path: Path) -> None:
    (tmp_path / "img").mkdir()
    (tmp_path / "img" / "f.png").write_bytes(pattern())
    by_file = lit_mask(svg(BODY.format(attr="href", href="img/f.png")), tmp_path)
    by_xlink = lit_mask(svg(BODY.format(attr="xlink:href", href="img/f.png")), tmp_path)
    by_uri = lit_mask(svg(BODY.format(attr="href", href=data_uri(pattern()))))
    assert by_uri.sum() == 4900  # the pattern's 49 black pixels, 10 × 10 CSS px each
    assert (by_file == by_uri).all() and (by_xlink == by_uri).all()


@pytest.mark.parametrize(("href", "why"), [
    ("http://example.com/a.png", "is a URL or an absolute path.*nothing is ever fetched"),
    ("https://example.com/a.png", "is a URL or an absolute path"),
    ("file:///etc/a.png", "is a URL or an absolute path"),
    ("/etc/a.png", "is a URL or an absolute path"),
    ("../outside.png", "leaves the SVG's folder"),
    ("sub/../../outside.png", "leaves the SVG's folder"),
    ("missing.png", "cannot read 'missing.png'"),
    ("data:image/png;base64,iVBORw0KGgo!!", "broken data URI"),
    ("data:image/png;base64", "broken data URI"),
    ("data:image/png;base64,aGVsbG8gd29ybGQ=", "not an image Pillow can read"),
    ("data:image/png;base64," + data_uri(pattern()).split(",")[1][:80],
     "truncated or damaged"),
    ("", "has no href"),
])
def test_refusals_are_named(tmp_path: Path, href: str, why: str) -> None:
    (tmp_path / "outside.png").write_bytes(pattern())
    folder = tmp_path / "svgs"
    (folder / "sub").mkdir(parents=True)
    text = svg(f'<image id="pic" href="{href}" width="50" height="40"/>')
    with pytest.raises(InputError, match=why) as ei:
        lit_mask(text, folder)
    assert "<image id='pic'> at line 1" in str(ei.value) or "t.svg" in str(ei.value)


def test_a_symlink_out_of_the_folder_is_refused(tmp_path: Path) -> None:
    (tmp_path / "outside.png").write_bytes(pattern())
    folder = tmp_path / "svgs"
    folder.mkdir()
    (folder / "link.png").symlink_to(tmp_path / "outside.png")
    with pytest.raises(InputError, match="leaves the SVG's folder"):
        lit_mask(svg('<image href="link.png" width="50" height="40"/>'), folder)


def _job(values: dict[str, Any], body: str | None = None, base: Path | None = None) -> Any:
    text = svg(body or BODY.format(attr="href", href=data_uri(pattern())))
    d = read_svg(text.encode(), file="t.svg")
    return compile_svg_images(d, load_profile(None), {"laser": True, **values}, base)


def test_an_uploaded_svg_cannot_refer_to_a_file() -> None:
    with pytest.raises(InputError, match="uploaded SVG has no folder"):
        _job({}, BODY.format(attr="href", href="f.png"))


def test_origin_and_scale_apply_as_to_a_drawing() -> None:
    """`--origin X,Y` puts the page's bottom-left corner at (X, Y) and `--scale` scales
    about it: the grid's corner is the image's top-left, its pitch one pattern pixel."""
    centred = _job({}).raster
    ox = centred.origin[0] - 20 * MM_PER_PX
    oy = centred.origin[1] - (PAGE[1] - 10) * MM_PER_PX
    for scale in (1.0, 0.7):
        ras = _job({"origin_mm": (ox, oy), "scale": scale}).raster
        px = 10 * MM_PER_PX * scale  # one pattern pixel: 10 CSS px
        assert math.isclose(ras.pitch_mm, px) and math.isclose(ras.interval_mm, px)
        top_left = (ox + 20 * MM_PER_PX * scale, oy + (PAGE[1] - 10) * MM_PER_PX * scale)
        assert np.allclose(ras.origin, top_left)
        assert ras.target.shape == (12, 16)
        assert np.array_equal(ras.target > 0, _pattern_dark())


def _pattern_dark() -> np.ndarray:
    import io

    from PIL import Image

    out: np.ndarray = np.asarray(Image.open(io.BytesIO(pattern()))) < 128
    return out


def test_rotate_resamples_and_says_so() -> None:
    job = _job({"rotate_deg": 90.0})
    ras = job.raster
    assert ras.target.shape == (16, 12)  # the pattern turned a quarter
    assert np.array_equal(ras.target > 0, np.rot90(_pattern_dark()))
    assert any("rotated or skewed" in n for n in ras.notes)


def test_centred_by_default_and_fit_fills_the_safe_area() -> None:
    centred = _job({}).raster
    fitted = _job({"fit": True}).raster
    assert fitted.pitch_mm > 1.2 * centred.pitch_mm  # grown to fill the safe area


def test_a_drawing_compile_refuses_images() -> None:
    text = svg(BODY.format(attr="href", href=data_uri(pattern())))
    d = read_svg(text.encode(), file="t.svg")
    with pytest.raises(InputError, match=r"1 <image> element\(s\): a raster"):
        compile_drawing(d, load_profile(None), CompileOptions())


def test_the_dry_run_prints_the_raster_report(tmp_path: Path) -> None:
    (tmp_path / "f.png").write_bytes(pattern())
    f = tmp_path / "photo.svg"
    f.write_text(svg(BODY.format(attr="href", href="f.png")))
    for laser in (["--laser"], []):
        r = CliRunner().invoke(main, ["plot", str(f), "--dry-run", "--preview",
                                      str(tmp_path / "p.png"), *laser])
        assert r.exit_code == 0, r.output
        assert "burn          16 × 12 px" in r.output
        assert "1 <image> element burned as one scan grid of 12 × 16 cells" in r.output
        assert "scanlines     10 (1 pass)" in r.output
        assert ("rehearsed" in r.output) == (not laser)


def test_a_mixed_file_is_refused_on_the_command_line(tmp_path: Path) -> None:
    f = tmp_path / "mixed.svg"
    f.write_text(svg(BODY.format(attr="href", href=data_uri(pattern()))
                     + '<path id="frame" d="M0 0 H100" stroke="black"/>'))
    r = CliRunner().invoke(main, ["plot", str(f), "--dry-run", "--laser"])
    assert r.exit_code != 0
    assert "mixes raster images (<image> at line 1) with drawn vector elements (<path " \
           "id='frame'> at line 1)" in r.output


def test_the_daemon_burns_an_uploaded_svg_of_images() -> None:
    """An upload (`server.jobs.compile_upload`) takes the raster route too; its relative
    file hrefs are refused (an upload has no folder)."""
    from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload

    prof = load_profile(None)
    data = svg(BODY.format(attr="href", href=data_uri(pattern()))).encode()
    job = compile_upload(data, "poster.svg", JobOptions.from_values({"laser": True}), prof).job
    assert job.raster is not None and job.raster.target.shape == (12, 16)
    data = svg(BODY.format(attr="href", href="f.png")).encode()
    with pytest.raises(SubmitError, match="uploaded SVG has no folder"):
        compile_upload(data, "poster.svg", JobOptions.from_values({"laser": True}), prof)


def test_empty_or_collapsed_images_burn_nothing() -> None:
    uri = data_uri(pattern())
    body = (f'<image href="{uri}" width="0" height="40"/>'
            f'<image href="{uri}" width="-5" height="40"/>'
            f'<image href="{uri}" width="50" height="40" transform="scale(0 1)"/>')
    with pytest.raises(InputError, match="nothing to burn: every <image> has an empty"):
        _job({}, body)


def test_a_grid_too_fine_is_refused_naming_the_option() -> None:
    from fivebar_host.errors import JobError

    with pytest.raises(JobError, match="more than 50,000,000: give a coarser --line-interval"):
        _job({"line_interval_mm": 0.001})


def test_layers_separate_images_from_paths() -> None:
    """`--layer` picks one side of a mixed file: the images' layer burns, the paths' draws."""
    ink = 'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"'
    text = svg(f'<g {ink} inkscape:groupmode="layer" inkscape:label="photo">'
               + BODY.format(attr="href", href=data_uri(pattern())) + '</g>'
               f'<g {ink} inkscape:groupmode="layer" inkscape:label="frame">'
               '<path d="M0 0 H100" stroke="black"/></g>')
    with pytest.raises(InputError, match="mixes raster images"):
        read_svg(text.encode(), file="t.svg")
    photo = read_svg(text.encode(), ["photo"], file="t.svg")
    frame = read_svg(text.encode(), ["frame"], file="t.svg")
    assert len(photo.images) == 1 and photo.n_strokes == 0
    assert not frame.images and frame.n_strokes == 1
