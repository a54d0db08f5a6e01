"""Figures of SVG text (issue 34): speed, glyph geometry against vpype, doubled strokes and
pen lifts, and (with --browser) the layout against headless Chromium.

    python benchmarks/text.py              # speed, vpype, strokes
    python benchmarks/text.py --browser    # + the layout cases against Chromium

- speed: CPU time (`time.process_time`, best of 5 after one warm-up read) to read an SVG
  of 10,000 characters — laid out, glyphs chosen and placed, strokes into the drawing — in
  three forms: 100 `<text>` elements of 100 characters in Hershey Sans, the same in Relief
  SingleLine (cubic glyphs, kerning), and one `<text>` of 10,000 characters with a
  `<tspan>` every 10 (fonts and sizes changing); and the cold first read (fonts loaded).
- vpype: the largest distance between a stroke point drawn by fivebar and by vpype's
  `text` (same font and size), and the largest difference in a string's advance, over the
  corpus in every Hershey font vpype has (`tests/test_text_vpype.py` asserts ≤ 0.1 mm).
- strokes: chords drawn twice by fivebar beyond the font data's own retraces, and pen-down
  paths of compiled lines against their glyph strokes (`tests/test_text_strokes.py`).
- browser: each layout case's largest glyph-origin distance (`tests/test_text_browser.py`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from xml.sax.saxutils import escape

_HERE = Path(__file__).resolve().parent
ROOT = _HERE.parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(ROOT))  # the tests' corpus and helpers
from fivebar_host.toolpath.fonts import library  # noqa: E402
from fivebar_host.toolpath.svg import read_svg  # noqa: E402
from fivebar_host.toolpath.svg.text import CharLayout  # noqa: E402
from tests.text_corpus import corpus  # noqa: E402

CHARS = 10_000


def documents() -> dict[str, bytes]:
    """The three 10,000-character documents (module doc)."""
    pool = "".join(s + " " for s in corpus())
    text = (pool * (CHARS // len(pool) + 1))[:CHARS]
    lines = [text[i:i + 100] for i in range(0, CHARS, 100)]

    def many(family: str) -> bytes:
        body = "".join(f'<text x="5" y="{5 + 6 * i}" xml:space="preserve">{escape(s)}</text>'
                       for i, s in enumerate(lines))
        return (f'<svg xmlns="http://www.w3.org/2000/svg" width="700mm" height="620mm" '
                f'viewBox="0 0 700 620" font-family="{family}" font-size="5">{body}'
                f"</svg>").encode()

    fams = ("Hershey Sans", "Hershey Serif", "cursive", "Relief SingleLine")
    spans = "".join(f'<tspan font-family="{fams[k % 4]}" font-size="{4 + k % 3}">'
                    f"{escape(text[i:i + 10])}</tspan>"
                    for k, i in enumerate(range(0, CHARS, 10)))
    one = (f'<svg xmlns="http://www.w3.org/2000/svg" width="70000mm" height="50mm" '
           f'viewBox="0 0 70000 50"><text x="5" y="20" xml:space="preserve">{spans}</text>'
           f"</svg>").encode()
    return {"100 × 100 chars, Hershey Sans": many("Hershey Sans"),
            "100 × 100 chars, Relief SingleLine": many("Relief SingleLine"),
            "1 × 10,000 chars, 1000 tspans, 4 fonts": one}


def cpu(fn: Callable[[], object], repeat: int = 5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def speed() -> None:
    docs = documents()
    library.forget_fonts()
    first = next(iter(docs.values()))
    t0 = time.process_time()
    read_svg(first)
    cold = time.process_time() - t0
    print(f"speed: {CHARS:,} characters read (laid out and drawn), CPU s, best of 5")
    for name, data in docs.items():
        layouts: list[CharLayout] = []
        d = read_svg(data, layouts=layouts)
        n = sum(len(c.chars) for c in layouts)
        print(f"  {name:<40} {cpu(lambda data=data: read_svg(data)):.3f} s  "
              f"({d.kind.shape[0]:,} primitives, {d.n_strokes:,} strokes, {n:,} chars)")
    print(f"  cold first read (fonts loaded)           {cold:.3f} s")


def vpype_figures() -> None:
    import numpy as np

    from fivebar_host.toolpath.geometry import flatten
    from tests import test_text_vpype as tv

    worst_s = worst_a = 0.0
    strings = strokes = 0
    for font in tv.HERSHEY:
        ss = tv.strings_for(font)
        layouts: list[CharLayout] = []
        d = read_svg(tv.document(font, ss), layouts=layouts)
        p = flatten(d, 1e-3)
        pts = d.to_file_frame(p.points)
        by: dict[int, list[np.ndarray]] = {}
        for k in range(p.offsets.shape[0] - 1):
            by.setdefault(int(d.stroke_source[p.stroke[k]]), []).append(
                pts[p.offsets[k]:p.offsets[k + 1]])
        texts = {t.element: t for t in d.texts}
        for i, s in enumerate(ss):
            got = by.get(texts[f'<text id="s{i}">'].source, [])
            want = tv.vpype_lines(s, font, 10.0, tv.LINE_MM * (i + 1))
            for g, w in zip(got, want, strict=True):
                worst_s = max(worst_s, float(np.hypot(*(g - w).T).max()))
            strokes += len(got)
            end = next(lay for lay in layouts if lay.ident == f"e{i}")
            worst_a = max(worst_a, abs(tv.X_END - float(end.user[0, 0])
                                       - tv.vpype_advance(s, font)))
        strings += len(ss)
    print(f"vpype: {len(tv.HERSHEY)} Hershey fonts, {strings} strings, {strokes:,} strokes "
          f"at {tv.SIZE_MM:g} mm: max stroke point distance {worst_s:.2e} mm, max advance "
          f"difference {worst_a:.2e} mm (goal ≤ 0.1 mm)")


def stroke_figures() -> None:
    from fivebar_host.compile import CompileOptions, compile_drawing
    from fivebar_host.config import load_profile
    from tests import test_text_strokes as ts
    from tests.text_support import doubled, segments_of

    found = own = strokes = 0
    for font in library.FACES:
        body = "".join(f'<text x="5" y="{15 * (i + 1)}">{escape(s)}</text>'
                       for i, s in enumerate(corpus()))
        h = 15 * (len(corpus()) + 1)
        d = read_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="400mm" height="{h}mm" '
                     f'viewBox="0 0 400 {h}" font-family="\'{font}\'" font-size="10">{body}'
                     f"</svg>".encode())
        from fivebar_host.toolpath.geometry import flatten

        p = flatten(d, 0.005)
        for t, s in zip(d.texts, corpus(), strict=True):
            sel = [k for k in range(p.offsets.shape[0] - 1)
                   if d.stroke_source[p.stroke[k]] == t.source]
            found += doubled(segments_of([p.points[p.offsets[k]:p.offsets[k + 1]]
                                          for k in sel]))
            own += ts.glyph_doubles(font, s)
            strokes += t.strokes
    print(f"strokes: {len(library.FACES)} fonts × {len(corpus())} strings, {strokes:,} glyph "
          f"strokes: {found - own} drawn twice by fivebar, {own} retraced by the font data "
          "itself (Hershey Gothic Italian 'B')")
    prof = load_profile()
    for font in ("futural", "timesr", "scripts", "relief"):
        d = read_svg(f'<svg xmlns="http://www.w3.org/2000/svg" width="60mm" height="20mm" '
                     f'viewBox="0 0 60 20"><text x="2" y="12" font-family="\'{font}\'" '
                     f'font-size="6">Lift 42, go!</text></svg>'.encode())
        job = compile_drawing(d, prof, CompileOptions())
        t = d.texts[0]
        print(f"  pen lifts {font:<8} {job.n_paths} pen-down paths for {t.glyphs} glyphs with "
              f"{t.strokes} strokes ({job.n_paths / t.glyphs:.2f} vs "
              f"{t.strokes / t.glyphs:.2f} a glyph)")


def browser_figures() -> None:
    import tempfile

    import numpy as np

    from fivebar_host.toolpath.svg.units import MM_PER_PX
    from tests import test_text_browser as tb
    from tests.text_support import browser_origins, metrics_ttf, page
    from tests.web_support import browser_missing, chromium

    why = browser_missing()
    if why:
        print(f"browser: skipped ({why})")
        return
    lib = library.FontLibrary()
    ttfs = {n: metrics_ttf(lib.load(f), n) for n, f in tb.FONTS.items()}
    worst: dict[str, float] = {}
    chars = 0
    with tempfile.TemporaryDirectory() as tmp, chromium(Path(tmp)) as drv:
        for case, (extra, body) in tb.CASES.items():
            svg = tb.HEAD.format(extra=extra) + body + "</svg>"
            got, h = tb.ours(svg)
            want = [t for t in browser_origins(drv, Path(tmp), page(svg, ttfs))
                    if any(g.ident == t["id"] for g in got)]
            for g, t in zip(got, want, strict=True):
                ref, _ = tb.reference(t, case in tb.CELL_BASELINES)
                mine = np.column_stack([g.drawing[:, 0], h - g.drawing[:, 1]]) / MM_PER_PX
                dev = np.hypot(*(mine - ref).T) * MM_PER_PX
                dev[~g.placed] = 0.0
                worst[case] = max(worst.get(case, 0.0), float(dev.max(initial=0.0)))
                chars += len(g.chars)
    print(f"browser: {len(worst)} layout cases, {chars} characters: max glyph-origin "
          f"distance {max(worst.values()):.3f} mm (goal ≤ 0.2 mm)")
    for case, v in worst.items():
        print(f"  {case:<16} {v:.4f} mm")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--browser", action="store_true", help="also the Chromium layout cases")
    a = ap.parse_args()
    speed()
    vpype_figures()
    stroke_figures()
    if a.browser:
        browser_figures()
    return 0


if __name__ == "__main__":
    sys.exit(main())
