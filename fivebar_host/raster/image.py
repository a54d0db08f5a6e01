"""Reading an image file into the one form the raster pipeline works on: darkness per pixel.

Pillow decodes (PNG, JPEG, BMP, GIF, TIFF, WebP): it is the decoder matplotlib already
depends on, so it adds nothing to an install, it reads every format a laser owner brings,
and it guards against decompression bombs.  Everything after this module is numpy.

The result is `Gray`: darkness in [0, 1] per pixel (1 = black: burn), rows top to bottom,
and the file's own resolution when it states one.  Conversions, each said in
`Gray.notes` when it happened:

* the EXIF orientation is applied (as a browser shows the photo);
* transparency is composited on white (transparent = nothing to burn);
* colour becomes luminance by ITU-R BT.601 (Y = 0.299 R + 0.587 G + 0.114 B), from CMYK
  through Pillow's conversion to RGB (no ICC profile is applied);
* 16-bit and 32-bit integer greys are scaled from their full range, float greys clipped
  to [0, 1]; palette, 1-bit and grey-with-alpha images go through RGBA.

Every failure is an `InputError` naming the file and why: not an image Pillow knows, a
format outside the six, a truncated or damaged file, more pixels than `MAX_PIXELS` (a
decompression bomb, or a photo far larger than any burn needs).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fivebar_host.errors import InputError
from kinematics.arrays import FloatArray

#: Formats read (Pillow's names); anything else Pillow identifies is refused, named.
FORMATS = ("PNG", "JPEG", "BMP", "GIF", "TIFF", "WEBP")
#: Suffixes of the files `fivebar plot` takes as images.
SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tif", ".tiff", ".webp")
#: The most pixels an image may have: 50 megapixels is 7000 × 7000 — at 10 px/mm a
#: 700 mm burn, far past any five-bar's reach — while a decompression bomb claims billions.
MAX_PIXELS = 50_000_000


@dataclass(frozen=True)
class Gray:
    """An image as darkness (H, W) in [0, 1] (1 = black), its resolution in dots per inch
    (x, y) when the file states one, and what was converted on the way."""

    dark: FloatArray
    dpi: tuple[float, float] | None
    file: str
    notes: tuple[str, ...] = ()

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.dark.shape[0]), int(self.dark.shape[1])


def is_image_file(path: str | Path) -> bool:
    """Whether `fivebar plot` takes the file as an image (by its suffix)."""
    return Path(path).suffix.lower() in SUFFIXES


def load(path: str | Path) -> Gray:
    """Read an image file (see the module docstring for the conversions and the errors)."""
    name = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise InputError(f"cannot read the image: {e.strerror or e}", name) from e
    return decode(data, name)


def _drawing_hint(data: bytes) -> str:
    """What to do when an image file holds a drawing: SVG (XML) text, for the error."""
    head = data[:512].lstrip(b"\xef\xbb\xbf \t\r\n").lower()
    if head.startswith((b"<?xml", b"<svg", b"<!doctype svg", b"<!--")) and b"<svg" in data:
        return "; the file is an SVG drawing: give it the extension .svg to draw it"
    return ""


def decode(data: bytes, name: str) -> Gray:
    """The image in `data` (a file's bytes or a data URI's), `name` for messages."""
    import io

    from PIL import Image, ImageOps, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            old = Image.MAX_IMAGE_PIXELS
            Image.MAX_IMAGE_PIXELS = MAX_PIXELS
            try:
                img = Image.open(io.BytesIO(data))
                fmt = img.format or "?"
                if fmt not in FORMATS:
                    raise InputError(f"{fmt} images are not read (only "
                                     f"{', '.join(FORMATS)})", name)
                w, h = img.size
                if w * h > MAX_PIXELS:
                    raise InputError(f"{w} × {h} pixels is more than {MAX_PIXELS:,}: a "
                                     "decompression bomb, or far more than a burn needs; "
                                     "scale it down first", name)
                img.load()
            finally:
                Image.MAX_IMAGE_PIXELS = old
    except UnidentifiedImageError as e:
        raise InputError("not an image Pillow can read (PNG, JPEG, BMP, GIF, TIFF, WebP)"
                         + _drawing_hint(data), name) from e
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as e:
        raise InputError(f"refused as a decompression bomb: {e}", name) from e
    except (OSError, SyntaxError, ValueError) as e:  # truncated or damaged data
        if isinstance(e, InputError):
            raise
        raise InputError(f"the image is truncated or damaged: {e}", name) from e
    notes: list[str] = []
    oriented = ImageOps.exif_transpose(img)
    if oriented is not None and oriented.size != img.size:
        notes.append("EXIF orientation applied")
    shown: Image.Image = oriented if oriented is not None else img
    dpi = _dpi(shown.info.get("dpi"))
    return Gray(_darkness(shown, notes), dpi, name, tuple(notes))


def _dpi(value: object) -> tuple[float, float] | None:
    """The file's resolution, when it states a sensible one."""
    if isinstance(value, tuple) and len(value) == 2:
        try:
            x, y = float(value[0]), float(value[1])
        except (TypeError, ValueError):
            return None
        if 1.0 <= x <= 100_000.0 and 1.0 <= y <= 100_000.0:
            return x, y
    return None


def _darkness(img: object, notes: list[str]) -> FloatArray:
    """Darkness in [0, 1] from any Pillow mode (module docstring)."""
    from PIL import Image

    assert isinstance(img, Image.Image)
    mode = img.mode
    if mode in ("I;16", "I;16B", "I;16L", "I"):
        a = np.asarray(img, dtype=np.float64)
        top = 65535.0 if mode.startswith("I;16") else max(float(a.max()), 1.0)
        notes.append(f"{mode} grey scaled from 0…{top:g}")
        return 1.0 - np.clip(a / top, 0.0, 1.0)
    if mode == "F":
        notes.append("float grey clipped to 0…1")
        return 1.0 - np.clip(np.asarray(img, dtype=np.float64), 0.0, 1.0)
    if mode == "L":
        return 1.0 - np.asarray(img, dtype=np.float64) / 255.0
    if mode == "CMYK":
        notes.append("CMYK converted to RGB without a colour profile")
        img = img.convert("RGB")
    if mode not in ("RGB", "RGBA"):
        img = img.convert("RGBA")
    a = np.asarray(img, dtype=np.float64) / 255.0
    rgb = a[..., :3]
    if a.shape[-1] == 4:
        alpha = a[..., 3:4]
        if float(alpha.min()) < 1.0:
            notes.append("transparency composited on white")
        rgb = rgb * alpha + (1.0 - alpha)
    y = rgb @ np.array([0.299, 0.587, 0.114])
    out: FloatArray = 1.0 - np.clip(y, 0.0, 1.0)
    return out
