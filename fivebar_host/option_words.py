"""The web page's words for the job options (`fivebar_host.options`): kept apart so
that the option table stays short."""

from __future__ import annotations

#: The web page's words for each option (label, help in words where the CLI's help names
#: flags, settings or G-code, an example): no option's API name reaches the page's text.
WORDS: dict[str, tuple[str, str, str]] = {
    "mode": ("Working mode", "How the elbows bend; auto tries all four (default: the "
             "machine's).", ""),
    "tolerance_mm": ("Tolerance", "", "0.05mm or 0.002in"),
    "origin_mm": ("Where the drawing goes (X,Y)", "Put the drawing's bottom-left corner "
                  "there on the machine, in mm or with units (default: centred).",
                  "10,95 or 1in,4in"),
    "scale": ("Scale", "A factor or a percentage: 0.5 or 50% is half size, 2 or 200% "
              "twice (default: as drawn).", "50% or 0.5"),
    "rotate_deg": ("Rotation", "Degrees counter-clockwise.", "90"),
    "fit": ("Fill the safe area", "Scale the drawing to fill the largest area the arms "
            "reach safely.", ""),
    "layers": ("Only these layers", "Inkscape layer names, comma separated (default: all).",
               "black, red"),
    "keep_order": ("Draw in file order", "Draw the paths in the file's order instead of "
                   "the shortest travel.", ""),
    "draw_feed_mm_s": ("Drawing speed", "Pen speed while drawing, per second or minute "
                       "(default: the machine's).", "25mm/s or 1in/s"),
    "travel_feed_mm_s": ("Travel speed", "Pen speed between strokes, pen up (default: the "
                         "machine's).", "80mm/s"),
    "accel_fraction": ("Acceleration", "A share of the machine's acceleration: 0.5 or 50% "
                       "(default: all of it).", "50%"),
    "max_segments": ("Most segments", "Refuse drawings with more segments than this "
                     "(default 2 million, about 0.6 GB of memory).", "2000000"),
    "laser": ("Laser on (burn)", "Without it the laser stays off on every line: a pen "
              "job.", ""),
    "pen_up_position": ("Pen up position", "", "60"),
    "pen_down_position": ("Pen down position", "", "30"),
    "pen_up_rate": ("Pen raising speed", "", ""),
    "pen_down_rate": ("Pen lowering speed", "", ""),
    "pen_up_delay_ms": ("Wait after raising the pen", "", "200"),
    "pen_down_delay_ms": ("Wait after lowering the pen", "", "200"),
    "layer_pause": ("Stop for a pen change between layers", "The pen goes up and the "
                    "machine waits until you continue; layers are drawn in file order.",
                    ""),
    "no_pause": ("Never stop for a pen change", "Not even before layers whose name starts "
                 "with '!'.", ""),
    "copies": ("Copies", "Draw the whole job this many times, the pen up and the arms "
               "parked between copies.", "1"),
    "page_delay_s": ("Wait between copies", "Seconds, to change the paper.", "15"),
    "confirm": ("The arms are at the home pose", "Tick if the machine may start from the "
                "home pose without asking (first job after power-up).", ""),
    "no_simplify": ("Keep every point", "Do not thin densely sampled lines (they are "
                    "thinned within half the tolerance otherwise).", ""),
    "hatch_mm": ("Fill shapes with hatch lines", "The distance between the lines on the "
                 "paper; 'pen' for the pen's width (default: outlines only).",
                 "0.4mm or pen"),
    "hatch_angle_deg": ("Hatch angle", "Degrees counter-clockwise.", "45"),
    "crosshatch": ("Cross-hatch", "Hatch a second time at right angles.", ""),
    "hatch_inset_mm": ("Hatch inset", "Keep the hatch this far inside each shape's edge.",
                       "0.2mm"),
    "hatch_along": ("Hatch along", "Straight lines, or arcs that one motor draws alone "
                    "(arm1: motor 1 still; arm2: motor 2 still).", ""),
    "hiding": ("Hide what is covered", "Shapes filled in the drawing hide the lines "
               "beneath them; shapes without an outline are not outlined.", ""),
    "fill": ("Laser fill", "Outline: engrave the lines; scan: burn the filled shapes line "
             "by line like a photo (outlines are then not engraved).", ""),
    # raster engraving of an image (docs/raster.md)
    "width_mm": ("Image width", "The picture's width on the machine; the height follows its "
                 "shape unless given too.", "40mm or 1.5in"),
    "height_mm": ("Image height", "The picture's height on the machine.", "30mm"),
    "dpi": ("Image resolution", "Pixels per inch, when no width or height is given "
            "(default: the file's own, else 96).", "254"),
    "line_interval_mm": ("Burn pixel size", "The distance between scanlines and between "
                         "pixels along them (default: the image's own pixels; for a scan "
                         "fill, the laser's spot).", "0.1mm"),
    "image_mode": ("Image mode", "Grayscale burns each pixel at its own power; threshold "
                   "and the dithering kinds burn dots at full power.", ""),
    "power_min": ("Lightest power", "The power of the lightest pixel that burns, 0 to 255 "
                  "(grayscale).", "10"),
    "power_max": ("Darkest power", "The power of black and of every dithered dot, 0 to "
                  "255 (default: the machine's laser power).", "200"),
    "gamma": ("Power curve", "Above 1 keeps light tones lighter, below 1 darkens them.",
              "1.8"),
    "threshold": ("Threshold", "How dark a pixel must be to burn (threshold mode).",
                  "50% or 0.5"),
    "negative": ("Negative", "Burn the light parts instead of the dark ones.", ""),
    "scan_angle_deg": ("Scan angle", "The scanlines' direction, degrees counter-clockwise; "
                       "the picture stays upright.", "45"),
    "one_way": ("Burn in one direction", "Every scanline the same way (slower; default: "
                "back and forth).", ""),
    "passes": ("Passes", "Burn the picture this many times over.", "2"),
}
