"""SVG `<image>` burned as a raster (issue 32, "Inputs"): an SVG whose drawn content is
`<image>` elements (`svg.walk.ImageRef`) becomes one scan grid through the image route's
own machinery (`raster.job.burn_grid`).

Where the pixels come from (`image_bytes`): a `data:` URI (base64 or percent-encoded), or
a relative file href (`href` or `xlink:href`) inside the SVG's own folder tree.  Refused,
never fetched, each an `InputError` naming the element's line: a URL with any other
scheme (http:, https:, file: …), an absolute path, a path leaving the SVG's folder, a
missing file, a broken data URI, a relative file in an uploaded SVG (it has no folder).
Decoding is `raster.image.decode` (Pillow; its named errors: bomb, truncated, unknown).

Where the pixels go, as a browser places them (`image_map`): the image's pixel box
(W × H px) is fitted into the element's viewport x, y, width × height (a missing width or
height: the image's own size in CSS px, or the other side's scale when only one is given)
by `preserveAspectRatio` (`svg.units.viewport_transform`: xMidYMid meet by default, the
nine alignments, slice, none), then through the element's and its ancestors' transforms and
the root's viewBox and units to the drawing frame (mm), then the user's placement
(`--scale`, `--fit`, `--origin`, `--rotate`, centring: `toolpath.layout.place`, the vector
job's own, on the images' visible boxes).  The viewport clips what shows (slice), and so
does an ancestor's `clip-path`.

The scan grid (`images_grid`): one grid for all the images, at `--scan-angle`, its pitch
and interval `1/--resolution` (`--line-interval`) or else the smallest image pixel on the
machine; each cell takes the power (the image mode's, on the image's own pixels) of the
image pixel under its centre, nearest neighbour, a later image painting over an earlier one
across its whole visible box (transparency is white, as `decode` composites it).  An image
whose final map is a scale + translation (no rotation or skew) with its pixel size as the
pitch is burned pixel for pixel; a rotated or skewed one is resampled this way, said in the
job's notes.  `--width`, `--height` and `--dpi` (an image file's size) do not apply: the
SVG sizes its images.
"""

from __future__ import annotations

import base64
import binascii
import math
import re
import urllib.parse
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.affinity import affine_transform

from fivebar_host.compile.model import CompileOptions, Job
from fivebar_host.compile.place import setup
from fivebar_host.config import Profile
from fivebar_host.errors import InputError, JobError, Where
from fivebar_host.options import compile_values
from fivebar_host.raster import image
from fivebar_host.raster.grid import ScanGrid
from fivebar_host.raster.job import burn_grid, located, raster_mode, raster_options, refuse_servo
from fivebar_host.raster.modes import to_powers
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.geometry import LINE, Drawing, DrawingBuilder
from fivebar_host.toolpath.svg.units import viewport_transform
from fivebar_host.toolpath.svg.walk import ImageRef
from kinematics.arrays import FloatArray

#: Scan-grid rows sampled at once (bounds the memory of a large grid).
ROWS_PER_CHUNK = 256
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


@dataclass(frozen=True)
class Placed:
    """One decoded image: its darkness, its map pixel (x right, y down) → drawing frame
    (3×3, mm, y up), its viewport in the image's user units and its element."""

    ref: ImageRef
    gray: image.Gray
    to_drawing: FloatArray  # pixel → drawing mm
    viewport: tuple[float, float, float, float]  # x, y, w, h (user units)


def _where(ref: ImageRef) -> str:
    return f"<image{f' id={ref.ident!r}' if ref.ident else ''}> at line {ref.line}"


def image_bytes(ref: ImageRef, svg_file: str, base: Path | None) -> tuple[bytes, str]:
    """The encoded image of `ref` and the name its errors carry (module docstring)."""
    href, where = ref.href, _where(ref)
    if not href:
        raise InputError(f"{where} has no href", svg_file, ref.line)
    if href[:5].lower() == "data:":
        head, comma, body = href[5:].partition(",")
        if not comma:
            raise InputError(f"{where}: broken data URI (no comma before the data)",
                             svg_file, ref.line)
        try:
            if head.lower().endswith(";base64"):
                data = base64.b64decode(re.sub(r"\s+", "", urllib.parse.unquote(body)),
                                        validate=True)
            else:
                data = urllib.parse.unquote_to_bytes(body)
        except (binascii.Error, ValueError) as e:
            raise InputError(f"{where}: broken data URI ({e})", svg_file, ref.line) from e
        return data, f"{svg_file}: {where} (data URI)"
    if _SCHEME.match(href) or href.startswith(("/", "\\")):
        raise InputError(f"{where}: href {href[:80]!r} is a URL or an absolute path: only "
                         "data: URIs and files in the SVG's own folder are read (nothing is "
                         "ever fetched); save the image next to the SVG and refer to it by "
                         "a relative path", svg_file, ref.line)
    if base is None:
        raise InputError(f"{where}: href {href[:80]!r} is a file, and an uploaded SVG has no "
                         "folder: embed the image as a data: URI", svg_file, ref.line)
    rel = urllib.parse.unquote(href.split("#", 1)[0].split("?", 1)[0])
    root = base.resolve()
    target = (root / rel).resolve()
    if not target.is_relative_to(root):
        raise InputError(f"{where}: href {href[:80]!r} leaves the SVG's folder ({root}): "
                         "only files inside it are read", svg_file, ref.line)
    try:
        return target.read_bytes(), str(target)
    except OSError as e:
        raise InputError(f"{where}: cannot read {href[:80]!r}: {e.strerror or e}", svg_file,
                         ref.line) from e


def image_map(ref: ImageRef, shape: tuple[int, int]) -> tuple[FloatArray,
                                                              tuple[float, float, float, float]]:
    """The map pixel → drawing frame (3×3) of an image of `shape` (H, W) and its viewport
    (x, y, w, h in user units) (module docstring)."""
    h_px, w_px = shape
    w, h = ref.width, ref.height
    if w is None and h is None:
        w, h = float(w_px), float(h_px)
    elif w is None:
        assert h is not None
        w = h * w_px / h_px
    elif h is None:
        h = w * h_px / w_px
    vp = viewport_transform((0.0, 0.0, float(w_px), float(h_px)), w, h, ref.par)
    at = np.array([[1.0, 0.0, ref.x], [0.0, 1.0, ref.y], [0.0, 0.0, 1.0]])
    out: FloatArray = np.asarray(ref.matrix, dtype=np.float64) @ at @ vp
    return out, (ref.x, ref.y, w, h)


def _visible_box(p: Placed) -> FloatArray:
    """The drawing-frame corners (4, 2) of the image's box cut by its viewport."""
    h_px, w_px = p.gray.shape
    x, y, w, h = p.viewport
    inv = np.linalg.inv(np.asarray(p.ref.matrix, dtype=np.float64))
    # the image box in user units: pixel corners through to_drawing, back through the matrix
    corners = np.array([[0, 0, 1], [w_px, 0, 1], [w_px, h_px, 1], [0, h_px, 1]], float)
    user = (inv @ p.to_drawing @ corners.T).T[:, :2]
    x0, x1 = max(x, user[:, 0].min()), min(x + w, user[:, 0].max())
    y0, y1 = max(y, user[:, 1].min()), min(y + h, user[:, 1].max())
    box = np.array([[x0, y0, 1], [x1, y0, 1], [x1, y1, 1], [x0, y1, 1]], float)
    out: FloatArray = (np.asarray(p.ref.matrix, dtype=np.float64) @ box.T).T[:, :2]
    return out


def load_images(d: Drawing, base: Path | None) -> list[Placed]:
    """Every `<image>` of `d` read, decoded and mapped; those with an empty box dropped."""
    out = []
    for ref in d.images:
        data, name = image_bytes(ref, d.file, base)
        gray = image.decode(data, name)
        lin = np.asarray(ref.matrix, dtype=np.float64)[:2, :2]
        if (ref.width is not None and ref.width <= 0) or (ref.height is not None
                                                           and ref.height <= 0) \
                or not abs(float(np.linalg.det(lin))) > 1e-12:
            continue  # an empty viewport or a collapsed transform shows nothing (as in SVG)
        m, vp = image_map(ref, gray.shape)
        out.append(Placed(ref, gray, m, vp))
    return out


def boxes_drawing(d: Drawing, imgs: list[Placed]) -> Drawing:
    """A drawing of the images' visible boxes (what `layout.place` centres and fits)."""
    b = DrawingBuilder(d.file)
    for p in imgs:
        src = b.add_source(p.ref.ident, p.ref.line, "image")
        q = _visible_box(p)
        b.begin_stroke(src)
        for i in range(4):
            a, c = q[i], q[(i + 1) % 4]
            b.add(LINE, (float(a[0]), float(a[1]), float(c[0]), float(c[1])), p.ref.line)
    return b.build(d.page_height_mm, d.page_size_mm)


def pixel_mm(p: Placed, pl: layout.Placement) -> float:
    """The smaller side of one of the image's pixels on the machine (mm)."""
    lin = pl.matrix @ p.to_drawing[:2, :2]
    return float(min(np.linalg.norm(lin[:, 0]), np.linalg.norm(lin[:, 1])))


def axis_aligned(p: Placed, pl: layout.Placement, angle_deg: float) -> bool:
    """Whether the image's pixel axes run along and across the scan (no rotation, skew)."""
    lin = pl.matrix @ p.to_drawing[:2, :2]
    phi = math.radians(angle_deg)
    u = np.array([math.cos(phi), math.sin(phi)])
    cx, cy = lin[:, 0], lin[:, 1]
    return (abs(float(cx[0] * u[1] - cx[1] * u[0])) <= 1e-9 * float(np.linalg.norm(cx))
            and abs(float(cy @ u)) <= 1e-9 * float(np.linalg.norm(cy)))


def images_grid(imgs: list[Placed], pl: layout.Placement, powers: list[Any],
                pitch: float, angle_deg: float) -> ScanGrid:
    """One scan grid over all the images placed by `pl` (module docstring)."""
    phi = math.radians(angle_deg)
    u = np.array([math.cos(phi), math.sin(phi)])
    n = np.array([math.sin(phi), -math.cos(phi)])
    boxes = [pl.to_machine(_visible_box(p)) for p in imgs]
    xy = np.concatenate(boxes)
    s, t = xy @ u, xy @ n
    s0, t0 = float(s.min()), float(t.min())
    cols = max(1, math.ceil((float(s.max()) - s0) / pitch - 1e-9))
    rows = max(1, math.ceil((float(t.max()) - t0) / pitch - 1e-9))
    if rows * cols > image.MAX_PIXELS:
        raise JobError(f"the images' scan grid would be {rows} × {cols} cells at "
                       f"{pitch:g} mm, more than {image.MAX_PIXELS:,}: give a coarser "
                       "--line-interval or a smaller --scale", None, "does_not_fit")
    origin = s0 * u + t0 * n
    out = np.zeros((rows, cols), dtype=np.uint8)
    sc = (np.arange(cols) + 0.5) * pitch
    for p, pw, box in zip(imgs, powers, boxes, strict=True):
        to_px = np.linalg.inv(_to_machine3(pl) @ p.to_drawing)
        region = shapely.Polygon(box)
        if p.ref.clip is not None:
            m = pl.matrix
            region = region.intersection(affine_transform(
                p.ref.clip, [m[0, 0], m[0, 1], m[1, 0], m[1, 1], pl.offset[0], pl.offset[1]]))
        shapely.prepare(region)
        h_px, w_px = p.gray.shape
        for r0 in range(0, rows, ROWS_PER_CHUNK):
            tc = (np.arange(r0, min(rows, r0 + ROWS_PER_CHUNK)) + 0.5) * pitch
            c = origin + sc[None, :, None] * u + tc[:, None, None] * n
            ix = np.floor(to_px[0, 0] * c[..., 0] + to_px[0, 1] * c[..., 1] + to_px[0, 2])
            iy = np.floor(to_px[1, 0] * c[..., 0] + to_px[1, 1] * c[..., 1] + to_px[1, 2])
            inside = ((ix >= 0) & (ix < w_px) & (iy >= 0) & (iy < h_px)
                      & shapely.contains_xy(region, c[..., 0], c[..., 1]))
            block = out[r0:r0 + tc.shape[0]]
            block[inside] = pw[iy[inside].astype(np.int64), ix[inside].astype(np.int64)]
    return ScanGrid(origin, u, n, float(pitch), float(pitch), out)


def _to_machine3(pl: layout.Placement) -> FloatArray:
    m = np.eye(3)
    m[:2, :2], m[:2, 2] = pl.matrix, pl.offset
    return m


def compile_svg_images(d: Drawing, profile: Profile, values: Mapping[str, Any],
                       base: Path | None) -> Job:
    """The raster job of an SVG whose drawn content is `<image>` elements (module
    docstring); `base` the SVG's folder (None: an upload). Raises `InputError`,
    `JobError`, `OptionError`."""
    file = d.file
    refuse_servo(profile, file)
    with located(file):
        return _compile(d, profile, values, base)


def _compile(d: Drawing, profile: Profile, values: Mapping[str, Any], base: Path | None
             ) -> Job:
    file = d.file
    imgs = load_images(d, base)
    if not imgs:
        raise InputError("nothing to burn: every <image> has an empty width or height or a "
                         "collapsed transform", file)
    given = values.get("mode")
    mode = str(given) if given not in (None, "auto") else raster_mode(profile, file)
    opts = CompileOptions(**compile_values(values))
    su = setup(profile, opts, mode)
    pl = layout.place(boxes_drawing(d, imgs), su.fb, mode, su.min1, su.min2, su.limits,
                      origin_mm=opts.origin_mm, scale=opts.scale, rotate_deg=opts.rotate_deg,
                      fit=opts.fit, assembly=su.asm)
    ro = raster_options(values, profile)
    pitch = 1.0 / ro.resolution if ro.resolution is not None else min(
        pixel_mm(p, pl) for p in imgs)
    if not (math.isfinite(pitch) and pitch > 1e-4):
        raise JobError(f"the images' pixels are {pitch:g} mm on the machine: too small to "
                       "burn (give --line-interval)", Where(file=file), "does_not_fit")
    powers = [to_powers(p.gray.dark, ro.mode) for p in imgs]
    grid = images_grid(imgs, pl, powers, pitch, ro.angle_deg)
    notes = [f"{len(imgs)} <image> element{'s' if len(imgs) != 1 else ''} burned as one scan "
             f"grid of {grid.shape[0]} × {grid.shape[1]} cells of {pitch:.4g} mm"
             + (" (a later image over an earlier one)" if len(imgs) > 1 else "")]
    for p in imgs:
        notes.extend(f"{_where(p.ref)}: {n}" for n in p.gray.notes)
        if not axis_aligned(p, pl, ro.angle_deg):
            notes.append(f"{_where(p.ref)} is rotated or skewed against the scan: resampled "
                         "onto the scan grid (nearest pixel)")
    if any(values.get(k) is not None for k in ("width_mm", "height_mm", "dpi")):
        notes.append("--width/--height/--dpi size an image file; an SVG sizes its <image> "
                     "elements itself (scale it with --scale or --fit)")
    return burn_grid(file, profile, mode, grid, ro, notes, pl,
                     "nothing to burn: every pixel of the images is white at these settings")
