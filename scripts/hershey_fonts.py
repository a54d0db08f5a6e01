"""Generate fivebar's bundled Hershey fonts (SVG fonts) from the original `.jhf` files.

Source: the Hershey font data as James Hurt's `.jhf` files, e.g. a checkout of
https://github.com/kamalmostafa/hershey-fonts (directory `hershey-fonts/`). The data is
public domain with an acknowledgement requirement (`LICENSE-Hershey.txt` next to the output);
no code of that repository is used here.

    python scripts/hershey_fonts.py PATH/TO/hershey-fonts/hershey-fonts

writes `fivebar_host/toolpath/fonts/data/hershey/<name>.svg` for every Latin text font
(`FONTS`), plus `HersheySansMono.svg`, a fixed-pitch arrangement of `futural`.

`.jhf` format (hershey-fonts.notes): per glyph a number (cols 0–4), a vertex count (5–7),
then pairs of characters, each coordinate offset from 'R': first the left and right
bearings, then x, y vertices (y down), " R" lifting the pen. Line breaks may fall inside a
glyph; the vertex count says where it ends.

Coordinates of the SVG fonts: 1 Hershey unit = 31.5 font units (1000 to the em, the scale of
the EMS Hershey SVG fonts, so a font-size draws the same size as there), x from the glyph's
left bearing (the origin vpype's `text` uses), y up from the baseline at Hershey y = 9. The
values are exact (multiples of 0.5). The 96th glyph (DEL, a control character) is left out.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from xml.sax.saxutils import quoteattr

OUT = Path(__file__).resolve().parent.parent / "fivebar_host" / "toolpath" / "fonts" / "data" \
    / "hershey"
SCALE = 31.5  # font units per Hershey unit (1000-unit em, as the EMS fonts)
BASELINE = 9  # Hershey y of the baseline
#: The bundled fonts: .jhf name → (description). Latin text fonts only; the symbol, Greek,
#: Cyrillic and Japanese sets key their glyphs by ASCII letters, which is not Unicode text.
FONTS = {
    "futural": "Hershey Simplex Sans (EMS HersheySans1)",
    "futuram": "Hershey Duplex Sans (EMS HersheySansMed)",
    "rowmans": "Hershey Roman Simplex",
    "rowmand": "Hershey Roman Duplex",
    "rowmant": "Hershey Roman Triplex",
    "timesr": "Hershey Times Roman (EMS HersheySerifMed)",
    "timesrb": "Hershey Times Roman Bold (EMS HersheySerifBold)",
    "timesi": "Hershey Times Italic (EMS HersheySerifMedItalic)",
    "timesib": "Hershey Times Italic Bold (EMS HersheySerifBoldItalic)",
    "scripts": "Hershey Script Simplex (EMS HersheyScript1)",
    "scriptc": "Hershey Script Complex (EMS HersheyScriptMed)",
    "cursive": "Hershey Cursive",
    "gothiceng": "Hershey Gothic English (EMS HersheyGothEnglish)",
    "gothicger": "Hershey Gothic German",
    "gothicita": "Hershey Gothic Italian",
    "gothgbt": "Hershey Gothic English Triplex",
    "gothgrt": "Hershey Gothic German Triplex",
    "gothitt": "Hershey Gothic Italian Triplex",
}
MONO_FROM = "futural"
MONO_ADVANCE = 24  # Hershey units: every futural glyph lies within ±11 of its centre
#: Adobe glyph names of ASCII 32–126.
NAMES = (
    "space", "exclam", "quotedbl", "numbersign", "dollar", "percent", "ampersand",
    "quotesingle", "parenleft", "parenright", "asterisk", "plus", "comma", "hyphen", "period",
    "slash", "zero", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine",
    "colon", "semicolon", "less", "equal", "greater", "question", "at", "A", "B", "C", "D",
    "E", "F", "G", "H", "I", "J", "K", "L", "M", "N", "O", "P", "Q", "R", "S", "T", "U", "V",
    "W", "X", "Y", "Z", "bracketleft", "backslash", "bracketright", "asciicircum",
    "underscore", "grave", "a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k", "l", "m",
    "n", "o", "p", "q", "r", "s", "t", "u", "v", "w", "x", "y", "z", "braceleft", "bar",
    "braceright", "asciitilde",
)

Glyph = tuple[int, int, list[list[tuple[int, int]]]]


def read_jhf(path: Path) -> list[Glyph]:
    """The glyphs of a .jhf file: (left, right, strokes of (x, y) vertices)."""
    records: list[str] = []
    for raw in path.read_text(encoding="latin-1").split("\n"):
        line = raw.rstrip("\r")
        if not line.strip():
            continue
        if records and len(records[-1]) - 8 < 2 * int(records[-1][5:8]):
            records[-1] += line  # a glyph continued on the next line
        else:
            records.append(line)
    glyphs = []
    for rec in records:
        body = rec[8:8 + 2 * int(rec[5:8])]
        left, right = ord(body[0]) - 82, ord(body[1]) - 82
        strokes: list[list[tuple[int, int]]] = [[]]
        for i in range(2, len(body), 2):
            if body[i:i + 2] == " R":
                strokes.append([])
            else:
                strokes[-1].append((ord(body[i]) - 82, ord(body[i + 1]) - 82))
        glyphs.append((left, right, [s for s in strokes if s]))
    return glyphs


def num(v: float) -> str:
    return f"{v:.1f}".rstrip("0").rstrip(".")


def path_data(strokes: list[list[tuple[int, int]]], x0: float) -> str:
    """SVG path data in font units (y up) for strokes in Hershey units, x offset by −x0."""
    parts = []
    for s in strokes:
        pts = [(num((x - x0) * SCALE), num((BASELINE - y) * SCALE)) for x, y in s]
        parts.append("M" + " L".join(f"{x} {y}" for x, y in pts))
    return " ".join(parts)


def top(glyph: Glyph) -> float:
    return max((BASELINE - y) * SCALE for s in glyph[2] for _, y in s)


def font_svg(name: str, description: str, glyphs: list[Glyph], mono: int | None = None) -> str:
    """One SVG font document."""
    ascii_glyphs = glyphs[:95]
    space = (mono or ascii_glyphs[0][1] - ascii_glyphs[0][0]) * SCALE
    cap, xh = top(ascii_glyphs[ord("H") - 32]), top(ascii_glyphs[ord("x") - 32])
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        '<svg xmlns="http://www.w3.org/2000/svg" version="1.1">',
        "<metadata>",
        f"{description}: a Hershey font for fivebar, generated by scripts/hershey_fonts.py",
        f"from {MONO_FROM if mono else name}.jhf (James Hurt's format of Dr. A. V. Hershey's "
        "fonts;",
        "see LICENSE-Hershey.txt for the acknowledgements that must go with this data).",
        "1 Hershey unit = 31.5 font units; x from the glyph's left bearing, baseline at "
        "Hershey y = 9." + (f" Fixed pitch: every glyph centred in {mono} units." if mono
                           else ""),
        "</metadata>",
        "<defs>",
        f'<font id="{name}" horiz-adv-x="{num(space)}">',
        f'<font-face font-family="{name}" units-per-em="1000" ascent="800" descent="-200" '
        f'cap-height="{num(cap)}" x-height="{num(xh)}"/>',
        f'<missing-glyph horiz-adv-x="{num(space)}"/>',
    ]
    for i, glyph in enumerate(ascii_glyphs):
        left, right, strokes = glyph
        adv = mono if mono else right - left
        x0 = (left + right) / 2 - mono / 2 if mono else left
        d = path_data(strokes, x0)
        attrs = (f"unicode={quoteattr(chr(32 + i))} glyph-name=\"{NAMES[i]}\" "
                 f'horiz-adv-x="{num(adv * SCALE)}"')
        lines.append(f"<glyph {attrs}" + (f' d="{d}"/>' if d else "/>"))
    lines += ["</font>", "</defs>", "</svg>", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("jhf_dir", type=Path, help="directory with the .jhf files")
    ap.add_argument("-o", "--out", type=Path, default=OUT)
    a = ap.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    for name, desc in FONTS.items():
        glyphs = read_jhf(a.jhf_dir / f"{name}.jhf")
        (a.out / f"{name}.svg").write_text(font_svg(name, desc, glyphs), encoding="utf-8")
    mono = read_jhf(a.jhf_dir / f"{MONO_FROM}.jhf")
    (a.out / "HersheySansMono.svg").write_text(
        font_svg("HersheySansMono", "Hershey Simplex Sans, fixed pitch (fivebar's)", mono,
                 MONO_ADVANCE), encoding="utf-8")
    print(f"wrote {len(FONTS) + 1} fonts to {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
