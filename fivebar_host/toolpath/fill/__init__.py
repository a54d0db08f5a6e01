"""Filled shapes: what the SVG reader records about each element's paint (`paint`), the fill
regions built from it with the exact fill rule (`regions`), pen hatching of those regions
(`hatch`, `chains`), hidden-line removal in paint order (`hiding`), and the drawing rebuilt
with both (`assemble`). The compile stage that drives them is `fivebar_host.compile.fill`;
docs/fill.md tells the user's side.

Everything here works on a `Drawing` in one frame (the compile stage runs it in machine
millimetres, after placement, so spacings and tolerances are paper millimetres) and on
shapely geometries in that frame.
"""
