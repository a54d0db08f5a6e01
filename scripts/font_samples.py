"""Pictures of the bundled single-stroke fonts for docs/text.md: each face drawn by fivebar's
own SVG reader (the strokes a pen draws), one PNG per face, and the example card.

    python scripts/font_samples.py          # writes docs/img/text/*.png
"""

from __future__ import annotations

import sys
from pathlib import Path
from xml.sax.saxutils import escape

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "img" / "text"
LINES = ("Hamburgefonstiv 0123456789", "The quick brown fox jumps over the lazy dog. &?!")
EXTRA = {"relief": "Café Ærø Łódź Dvořák — ÿ œ ß"}


def draw(svg: bytes, path: Path, width_in: float, crop: bool = False) -> None:
    """The strokes of an SVG as black lines on white, `width_in` inches wide (`crop`: the
    page cut to the strokes' width plus 3 mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fivebar_host.toolpath.geometry import flatten
    from fivebar_host.toolpath.svg import read_svg

    d = read_svg(svg)
    p = flatten(d, 0.01)
    pts = d.to_file_frame(p.points)
    assert d.page_size_mm is not None
    w, h = d.page_size_mm
    if crop:
        w = float(pts[:, 0].max()) + 3.0
    fig = plt.figure(figsize=(width_in, width_in * h / w))
    ax = fig.add_axes((0, 0, 1, 1))
    for a, b in zip(p.offsets[:-1], p.offsets[1:], strict=True):
        ax.plot(pts[a:b, 0], pts[a:b, 1], "k-", lw=0.9, solid_capstyle="round")
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.axis("off")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def sample(key: str, label: str) -> bytes:
    lines = [*LINES, *([EXTRA[key]] if key in EXTRA else [])]
    body = "".join(f'<text x="3" y="{13 + 11 * i}">{escape(s)}</text>'
                   for i, s in enumerate(lines))
    h = 11 * len(lines) + 12
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="400mm" height="{h}mm" '
            f'viewBox="0 0 400 {h}" font-family="\'{key}\'" font-size="8">'
            f'<text x="3" y="5.5" font-family="Hershey Sans" font-size="3.2">{escape(label)}'
            f"</text>{body}</svg>").encode()


def main() -> int:
    sys.path.insert(0, str(ROOT))
    from fivebar_host.toolpath.fonts.library import FACES

    OUT.mkdir(parents=True, exist_ok=True)
    for key, (_, label) in FACES.items():
        draw(sample(key, label), OUT / f"{key}.png", 8.0, crop=True)
    draw((ROOT / "examples" / "birthday_card.svg").read_bytes(), OUT / "birthday_card.png",
         6.0)
    print(f"wrote {len(FACES) + 1} pictures to {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
