"""Single-stroke fonts for SVG text: SVG fonts read as open strokes, and the names they
answer to.

- `svgfont`: `load_svg_font`, `Font`, `Glyph` (SVG 1.1 fonts: glyphs, advances, kerning).
- `library`: `FontLibrary` (CSS family names, EMS and vpype names, generic families, the
  profile's `[text]` table as `TextConfig`) and the bundled fonts' table.
- `data/`: the bundled fonts with their licences (Hershey, Relief SingleLine).
"""

from fivebar_host.toolpath.fonts.library import Face, FontLibrary, TextConfig
from fivebar_host.toolpath.fonts.svgfont import Font, Glyph, load_svg_font

__all__ = ["Face", "Font", "FontLibrary", "Glyph", "TextConfig", "load_svg_font"]
