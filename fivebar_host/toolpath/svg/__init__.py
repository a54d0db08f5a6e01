"""SVG reader: every visible outline of an SVG document as exact primitives in millimetres.

The SVG specification and mature renderers (resvg, browsers) are the reference; where a pen
cannot show something as a screen does, the reader says so once per kind (a warning naming
the element, in `Drawing.warnings`) or refuses with the reason (`InputError`); it never draws
something other than what the file shows. Modules:

- `xmltree`: expat parse with line numbers (no external entities, billion-laughs safe).
- `units`: lengths (absolute units, %, em, ex), number lists, viewBox/preserveAspectRatio.
- `pathdata`: path data by the SVG grammar; invalid data is drawn up to the first error
  (what browsers show) with a warning naming the element and the column.
- `shapes`: the basic shapes.
- `css`: `<style>` sheets, `class`, `style` and presentation attributes, cascaded.
- `paint`: inherited properties, what makes an element invisible, colour luminance.
- `walk`: the tree walk: transforms, nested viewports, `<use>`/`<symbol>`, `<switch>`,
  Inkscape layers.
- `clip`, `masking`: `clip-path`, `mask` and viewport overflow as regions (shapely); pen
  lines are cut exactly where they leave a region.
- `markers`: `marker-start`/`-mid`/`-end` drawn at the shapes' vertices, as browsers do.
- `undrawn`: what is not drawn (images, foreign objects, filters), counted for one note.
- `text` with `textcontent`, `textlayout`, `textpath`, `textdeco`: `<text>` laid out as
  browsers do and drawn with single-stroke fonts (`toolpath.fonts`); `lettering`: lines of
  text as an SVG document (`fivebar text`).
- `reader`: `read_svg`, the page, warnings and the final checks.
"""

from fivebar_host.toolpath.svg.reader import read_svg
from fivebar_host.toolpath.svg.units import parse_length, viewport_transform

__all__ = ["parse_length", "read_svg", "viewport_transform"]
