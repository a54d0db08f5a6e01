"""Raster engraving (issue 32): images burned pixel by pixel along straight Cartesian scanlines.

The stages, each a module with one concern:

* `image` — an image file (Pillow) → darkness per pixel; `modes` + `dither` — darkness →
  laser power per pixel (grayscale, threshold, error diffusion, Bayer);
* `grid` — the pixels placed on the machine: size, resolution, scan angle, the scanlines
  (rows of the scan grid, blank ends trimmed), bidirectional or one-way, passes;
* `motion` — each scanline as joint-space segments at one constant pen speed, with the
  overscan that lets the joints reach it, and the checked moves between scanlines;
* `pixels` — every pixel boundary's crossing time on the executed (step-quantised) motion,
  grouped into G7 lines (docs/protocol.md 6.4) with one first-change offset and period each;
* `job` — all of it as a compiled `Job` whose segments carry the G7 runs (`RasterRuns`);
* `dose` — the burned image reconstructed from step pulses and the laser pin, and its
  figures against the target.
"""
