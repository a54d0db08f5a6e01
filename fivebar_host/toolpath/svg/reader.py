"""`read_svg`: the document's page (size, viewBox), the walk, and what the user is told.

Page: root `width`/`height` in mm, cm, in, pt, pc, px (96 px/in), em/ex (16 px) or unitless
(px); a percentage (or a missing size) refers to the viewBox size when there is one, and
otherwise — a browser would use its window — the page is taken as the content's extent from
the origin, with a warning (with `--fit` the page size does not matter). The Drawing is in mm,
y up, origin at the page's bottom-left corner (the page's y-down frame is flipped here).

Told once per kind (`Drawing.warnings`, printed by the dry-run report): ignored elements,
hidden elements, Inkscape's flowed text (with the hint to convert it to text), invalid path
data (drawn up to the error), partial opacity and dashes (drawn solid), unsupported CSS,
masks that are not opaque, and what text drawing says (`svg.text`). `<text>` is drawn with
single-stroke fonts (`fonts`), chosen through the profile's `[text]` table (`text`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fivebar_host.errors import InputError
from fivebar_host.toolpath.extent import bbox
from fivebar_host.toolpath.fonts.library import FontLibrary, TextConfig
from fivebar_host.toolpath.geometry import MAX_COORD_MM, Drawing, read_source
from fivebar_host.toolpath.svg.masking import Masking
from fivebar_host.toolpath.svg.stream import StreamTree, scan
from fivebar_host.toolpath.svg.text import CharLayout
from fivebar_host.toolpath.svg.units import MM_PER_PX, Lengths, parse_length, viewport_transform
from fivebar_host.toolpath.svg.walk import Ctx, Walker, root_props
from fivebar_host.toolpath.svg.xmltree import Node, parse_xml

FLOWED_HINT = ("Inkscape's flowed text (<flowRoot>) is not SVG and browsers do not show it: "
               "convert it to text first (Inkscape: Text > Convert to Text)")


def _page_size(r: Walker, root: Node, name: str) -> tuple[float, float, bool]:
    """Page width and height in mm, and whether they are known before reading the content."""
    vb = r.viewbox(root)
    known = True
    sizes = []
    for attr, i in (("width", 2), ("height", 3)):
        text = root.get(attr)
        is_rel = text is None or not text.strip() or text.strip().endswith("%")
        if is_rel and vb is None:
            known = False
            sizes.append(0.0)
            continue
        ref = vb[i] * MM_PER_PX if vb else None
        sizes.append(parse_length(text, name, root.line, attr, ref, ref))
    w, h = sizes
    if known and (w <= 0 or h <= 0):
        raise InputError(f"page size {w:g} × {h:g} mm must be positive", name, root.line)
    return w, h, known


#: Path segments (lines, curves, arcs) read from one file before it is refused by default.
DEFAULT_MAX_SEGMENTS = 2_000_000
LIMIT_HINT = ("; raise it with --max-segments (job option max_segments) if the machine has "
              "the memory: compiling takes about 0.3 GB per million segments")


def read_svg(source: str | Path | bytes, layers: Sequence[str] | None = None,
             file: str | None = None, language: str = "en",
             max_segments: int | None = DEFAULT_MAX_SEGMENTS,
             text: TextConfig | FontLibrary | None = None,
             layouts: list[CharLayout] | None = None) -> Drawing:
    """Read an SVG file (path or bytes) into a `Drawing` in mm, y up, page bottom-left at 0.

    `layers`: Inkscape layer labels or ids to draw (None: everything visible). `language`:
    the user language `<switch>`'s `systemLanguage` is matched against. `max_segments`: the
    most path segments drawn (None: no limit); more is an `InputError` raised while reading.
    `text`: the profile's `[text]` table (or a library built from one) that chooses the
    fonts of `<text>` (None: the built-in choices); `layouts`, when given, receives each
    drawn text element's character layout (`svg.text.CharLayout`). The document is walked
    while it is parsed where its references allow (`stream`).
    """
    data, name = read_source(source, file, "<svg>")
    sc = scan(data, name)
    fonts = text if isinstance(text, FontLibrary) else FontLibrary(text)
    r = Walker(name, layers, language, max_segments, LIMIT_HINT, fonts)
    r.layouts = layouts
    Masking(r)
    for sheet, line in sc.sheets:
        r.sheet.add_sheet(sheet, f"<style> at line {line}")
    page: list[float] = []

    def on_root(root: Node) -> Ctx | None:
        ctx, height_mm, width_mm, known = _enter_root(r, root, name)
        page.extend((height_mm, width_mm, float(known)))
        return ctx

    if sc.streamable:
        StreamTree(r, sc.referenced, on_root).parse(data, name)
    else:
        root = parse_xml(data, name)
        r.index(root)
        ctx = on_root(root)
        if ctx is not None:
            for child in root.children:
                r.walk(child, ctx)
    del data
    height_mm, width_mm, known = page
    _check_layers(r, name)
    r.b.warnings.extend(_warnings(r))
    drawing = r.b.build(page_height_mm=height_mm, page_size_mm=(width_mm, height_mm))
    drawing.paint = r.paint.table(len(drawing.sources))
    _check_coordinates(drawing, name)
    drawing.images = list(r.images)
    if r.images and drawing.kind.shape[0] > 0:
        raise InputError(_mixed_message(r, drawing), name, r.images[0].line)
    if r.images:
        return drawing
    if drawing.kind.shape[0] == 0:
        raise InputError(_nothing_message(r), name)
    if not known:
        drawing = _page_from_content(drawing, name)
    return drawing


def _enter_root(r: Walker, root: Node, name: str) -> tuple[Ctx | None, float, float, bool]:
    """The root's checks, page (height, width in mm, whether known) and the context of its
    content (None when it is fully transparent)."""
    if root.tag != "svg":
        raise InputError(f"root element is <{root.tag}>, not <svg>", name, root.line)
    vb = r.viewbox(root)
    width_mm, height_mm, known = _page_size(r, root, name)
    if vb is not None:
        page = viewport_transform(vb, width_mm, height_mm, root.get("preserveAspectRatio"))
        lengths = Lengths(vb[2], vb[3])
    else:
        page = np.diag([MM_PER_PX, MM_PER_PX, 1.0])
        lengths = Lengths(width_mm / MM_PER_PX, height_mm / MM_PER_PX)
    # page frame (mm, y down) → drawing frame (mm, y up, bottom-left origin)
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, height_mm], [0.0, 0.0, 1.0]])
    spec = r.sheet.cascade(root)
    if spec.get("display", "").strip() == "none":
        raise InputError("the root <svg> has display:none", name, root.line)
    ctx = Ctx(flip @ page, root_props(), lengths, None, not r.layers)
    ctx = r.enter(root, spec, ctx, False)
    return (ctx if ctx.opacity > 0 else None), height_mm, width_mm, known


def _check_layers(r: Walker, name: str) -> None:
    if r.layers:
        names = {n for pair in r.found_layers for n in pair if n}
        missing = [x for x in r.layers if x not in names]
        if missing:
            avail = ", ".join(sorted(f'"{lb}" (id {i})' for lb, i in r.found_layers)) or "none"
            raise InputError(f"no layer named {', '.join(map(repr, missing))}; layers in "
                             f"this file: {avail}", name)


def _where(n: Node) -> str:
    return f"{n.describe()} at line {n.line}"


def _warnings(r: Walker) -> list[str]:
    out = list(r.sheet.warnings)
    for tag, n in sorted(r.ignored_tags.items()):
        out.append(f"ignored {n} <{tag}> element(s)")
    if r.text_nodes:
        out.append(f"ignored {len(r.text_nodes)} flowed text element(s) (first: "
                   f"{_where(r.text_nodes[0])}): {FLOWED_HINT}")
    if r.skipped_hidden:
        out.append(f"skipped {r.skipped_hidden} hidden element(s)")
    undrawn = r.undrawn.note()
    return out + _notes(r) + ([undrawn] if undrawn else [])


def _notes(r: Walker) -> list[str]:
    return [f"{msg} ({_where(first)})" if n == 1 else
            f"{msg} ({n} elements, first: {_where(first)})"
            for msg, first, n in r.notes.values()]


def _nothing_message(r: Walker) -> str:
    what = f" in layer(s) {', '.join(r.layers)}" if r.layers else ""
    msg = (f"no strokes to draw{what}: the file has no visible path, line, polyline, polygon, "
           "rect, circle, ellipse or text with a non-zero extent") + r.undrawn.only()
    if r.text_nodes:
        lines = ", ".join(str(n.line) for n in r.text_nodes[:5])
        more = ", ..." if len(r.text_nodes) > 5 else ""
        msg += (f"; its flowed text (<{r.text_nodes[0].tag}> at line(s) {lines}{more}) is not "
                f"drawn: {FLOWED_HINT}")
    notes = _notes(r)
    if notes:
        msg += "; " + "; ".join(notes)
    return msg


def _mixed_message(r: Walker, drawing: Drawing) -> str:
    """The refusal of a file that holds both raster images and drawn vector elements."""
    def name(tag: str, ident: str | None, line: int | None) -> str:
        return f"<{tag}{f' id={ident!r}' if ident else ''}> at line {line}"

    imgs = [name("image", i.ident, i.line) for i in r.images[:3]]
    vecs = [name(s.tag, s.ident, s.line) for s in drawing.sources[:3]]
    more_i = f" and {len(r.images) - 3} more" if len(r.images) > 3 else ""
    more_v = f" and {len(drawing.sources) - 3} more" if len(drawing.sources) > 3 else ""
    return (f"the file mixes raster images ({', '.join(imgs)}{more_i}) with drawn vector "
            f"elements ({', '.join(vecs)}{more_v}): one job burns either a raster or "
            "vector paths; split it into two files (one with the images, one with the "
            "drawing) and run them one after the other, or pick one with --layer when they "
            "are in separate layers")


def _check_coordinates(drawing: Drawing, name: str) -> None:
    """Coordinates must be finite and of sane size once in mm (checked once, vectorised)."""
    bad = ~np.isfinite(drawing.params).all(axis=1) | (
        np.abs(np.nan_to_num(drawing.params, nan=0.0)).max(axis=1, initial=0.0) > MAX_COORD_MM)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        src = drawing.sources[int(drawing.stroke_source[drawing.stroke[i]])]
        raise InputError(f"<{src.tag}> has a coordinate that is not finite or larger than "
                         f"{MAX_COORD_MM:g} mm", name, int(drawing.line[i]))


def _page_from_content(drawing: Drawing, name: str) -> Drawing:
    """No viewBox and a relative or missing size: the page is the content's extent from the
    origin (as a browser window just big enough); the drawing is read with the page top at
    y = 0 and shifted up here."""
    x0, y0, x1, y1 = bbox(drawing)
    w, h = max(x1, 0.0), max(-y0, 0.0)
    if w <= 0 or h <= 0:
        w, h = max(w, x1 - x0), max(h, y1 - y0)
    out = drawing.transformed(np.identity(2), np.array([0.0, h]))
    out.page_height_mm, out.page_size_mm = h, (w, h)
    out.warnings.append(f"the root <svg> has no viewBox and a relative or missing width/height; "
                        f"the page is taken as the content's extent, {w:.1f} × {h:.1f} mm "
                        "(px at 96 per inch)")
    _check_coordinates(out, name)
    return out
