"""Image files: every format Pillow reads for us, the documented conversions, and the named
errors (never a traceback, a non-zero exit, nothing compiled)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from fivebar_host.cli import main
from fivebar_host.errors import FivebarError, InputError
from fivebar_host.raster import image


def _grey(w: int = 32, h: int = 16) -> Image.Image:
    a = np.tile(np.linspace(0, 255, w), (h, 1)).astype(np.uint8)
    return Image.fromarray(a)


@pytest.mark.parametrize("suffix", [".png", ".jpg", ".bmp", ".gif", ".tif", ".webp"])
def test_formats_read_to_darkness(tmp_path: Path, suffix: str) -> None:
    p = tmp_path / f"g{suffix}"
    _grey().save(p)
    g = image.load(p)
    assert g.dark.shape == (16, 32)
    # left black (darkness 1), right white (0); lossy formats within a few levels
    assert g.dark[:, 0].mean() == pytest.approx(1.0, abs=0.03)
    assert g.dark[:, -1].mean() == pytest.approx(0.0, abs=0.03)


def test_conversions_are_noted(tmp_path: Path) -> None:
    a = np.tile(np.linspace(0, 65535, 16), (4, 1)).astype(np.uint16)
    Image.fromarray(a).save(tmp_path / "g16.png")
    g = image.load(tmp_path / "g16.png")
    assert g.dark[0, 0] == pytest.approx(1.0) and g.dark[0, -1] == pytest.approx(0.0)
    assert any("I;16" in n for n in g.notes)
    rgba = _grey().convert("RGBA")
    rgba.putalpha(0)  # fully transparent: white paper, nothing burns
    rgba.save(tmp_path / "a.png")
    g = image.load(tmp_path / "a.png")
    assert float(g.dark.max()) == pytest.approx(0.0)
    assert any("transparency" in n for n in g.notes)
    _grey().convert("CMYK").save(tmp_path / "c.jpg")
    assert any("CMYK" in n for n in image.load(tmp_path / "c.jpg").notes)


def test_dpi_is_read(tmp_path: Path) -> None:
    _grey().save(tmp_path / "d.png", dpi=(254, 254))
    assert image.load(tmp_path / "d.png").dpi == pytest.approx((254, 254), abs=0.1)


def _bad_files(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    ok = tmp_path / "ok.jpg"
    _grey(200, 100).save(ok, quality=95)
    data = ok.read_bytes()
    trunc = tmp_path / "trunc.jpg"
    trunc.write_bytes(data[: len(data) // 3])
    junk = tmp_path / "junk.png"
    junk.write_bytes(b"this is not an image\n" * 20)
    bomb = tmp_path / "bomb.png"
    Image.new("1", (20000, 20000)).save(bomb)  # 400 Mpx of zeros: a few kB on disk
    drawing = tmp_path / "drawing.png"
    drawing.write_bytes(b'\xef\xbb\xbf<?xml version="1.0"?>\n<svg xmlns="http://www.w3.org/'
                        b'2000/svg"><path d="M0 0 L1 1"/></svg>\n')
    return {"truncated": (trunc, "truncated"), "unknown": (junk, "not an image"),
            "svg": (drawing, "the file is an SVG drawing: give it the extension .svg"),
            "bomb": (bomb, "decompression bomb"),
            "missing": (tmp_path / "nope.png", "cannot read")}


def test_bad_images_are_named_input_errors(tmp_path: Path) -> None:
    for what, (p, reason) in _bad_files(tmp_path).items():
        with pytest.raises(InputError) as ei:
            image.load(p)
        assert isinstance(ei.value, FivebarError), what
        assert str(p) in str(ei.value) and reason in str(ei.value), what
        assert what == "svg" or "SVG drawing" not in str(ei.value), what


def test_bad_images_on_the_cli_exit_non_zero_without_traceback(tmp_path: Path) -> None:
    for what, (p, reason) in _bad_files(tmp_path).items():
        r = CliRunner().invoke(main, ["plot", str(p), "--laser", "--dry-run", "--width", "20",
                                      "--preview", str(tmp_path / "pv.png")])
        assert r.exit_code != 0, what
        assert "Traceback" not in r.output and reason in r.output, what
        assert not isinstance(r.exception, AssertionError), what
        assert not (tmp_path / "pv.png").exists(), what


def test_the_dry_run_counts_copies_of_an_image(tmp_path: Path) -> None:
    """`--copies 2` engraves the image twice with the page delay between (run.job), so the
    dry run's time says so, as it does for a drawing (before: one copy's time only)."""
    img = tmp_path / "g.png"
    _grey().save(img)
    args = ["plot", str(img), "--laser", "--dry-run", "--width", "10",
            "--preview", str(tmp_path / "pv.png")]
    one = CliRunner().invoke(main, args)
    two = CliRunner().invoke(main, [*args, "--copies", "2", "--page-delay", "7s"])
    assert one.exit_code == 0 and two.exit_code == 0, two.output
    assert not any(ln.startswith("copies") for ln in one.output.splitlines())
    t = float(re.search(r"^time +([\d.]+) s", one.output, re.MULTILINE)[1])  # type: ignore[index]
    line = next(ln for ln in two.output.splitlines() if ln.startswith("copies"))
    assert "2 copies of" in line and "1 page delay of 7 s" in line, line
    total = re.search(r"≈ (?:(\d+) min )?([\d.]+) s \(", line)
    assert total is not None, line
    assert float(total[1] or 0) * 60 + float(total[2]) == pytest.approx(2 * t + 7, abs=0.15)


def test_pixels_finer_than_the_spot_are_named_with_the_option_that_resamples(
        tmp_path: Path) -> None:
    """An image burned at its own pixels where they are finer than the laser's spot (the
    default profile's 0.1 mm) burns each as a spot-wide dot and takes (spot/pixel)² more
    pixels than it can show: the dry run says so and names --line-interval."""
    img = tmp_path / "g.png"
    _grey(400, 100).save(img)

    def notes(*extra: str) -> list[str]:
        r = CliRunner().invoke(main, ["plot", str(img), "--laser", "--dry-run", *extra,
                                      "--preview", str(tmp_path / "pv.png")])
        assert r.exit_code == 0, r.output
        return [ln for ln in r.output.splitlines() if "finer than the laser" in ln]

    said = notes("--width", "10mm")  # 0.025 mm pixels
    assert len(said) == 1 and "0.025 × 0.025 mm" in said[0], said
    assert "--line-interval 0.1mm" in said[0] and "16× fewer pixels" in said[0], said
    assert notes("--width", "10mm", "--line-interval", "0.1mm") == []
    assert notes("--width", "40mm") == []  # 0.1 mm pixels: the spot's own size
