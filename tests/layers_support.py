"""The two-layer drawing and the pen profile the pen-change tests share (mock, daemon,
emulator): two Inkscape layers of two strokes each, so a stop falls between them."""

from __future__ import annotations

from pathlib import Path

PEN = Path(__file__).resolve().parent.parent / "configs" / "pen-servo.toml"

#: The red layer's second stroke: a line, or a curve (`layers_text(curve=True)`).
_LAST_LINE = '<line x1="2" y1="18" x2="12" y2="18" stroke="red"/>'
_LAST_CURVE = '<path d="M 2 18 C 5 14 9 14 12 18" stroke="red" fill="none"/>'


def layers_text(first: str = "black", second: str = "red", curve: bool = False) -> str:
    """The drawing's text, its layers labelled `first` and `second`."""
    return f"""<svg xmlns="http://www.w3.org/2000/svg"
 xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"
 width="30mm" height="20mm" viewBox="0 0 30 20">
<g inkscape:groupmode="layer" inkscape:label="{first}" id="layer1">
<line x1="2" y1="2" x2="12" y2="2" stroke="black"/>
<line x1="18" y1="18" x2="28" y2="18" stroke="black"/>
</g>
<g inkscape:groupmode="layer" inkscape:label="{second}" id="layer2">
<line x1="18" y1="2" x2="28" y2="2" stroke="red"/>
{_LAST_CURVE if curve else _LAST_LINE}
</g>
</svg>
"""
