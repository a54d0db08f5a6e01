"""Every job option declared once: name, type, unit, range, default and help.

A job option (tolerance, placement, working mode, laser …) is one `Option` in `JOB_OPTIONS`.
From that one definition come:

- the click options of `fivebar plot` / `convert` / `frame` (`fivebar_host.cli.common`),
- the daemon's query parameters: their OpenAPI description, their parsing and validation,
  and the refusal of an unknown parameter (`fivebar_host.server.app`),
- the HTTP client's query string (`fivebar_host.server.client.plot_options`).

Values are parsed from text once, here, at the edge (the CLI and the query string both hand
over text) into the units the pipeline uses: millimetres, degrees for the user-facing
rotation, plain numbers. The parsed values are keyed by the field names of
`CompileOptions` / `JobOptions` (`tolerance_mm`, `origin_mm`, …), so building the compiler's
options is `CompileOptions(**values)` with no renaming on the way.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, NoReturn

from fivebar_host.errors import OptionError
from fivebar_host.option_words import WORDS as _WORDS

#: Text forms of a boolean in a query string (as FastAPI/pydantic read them).
_TRUE = frozenset({"true", "1", "yes", "on"})
_FALSE = frozenset({"false", "0", "no", "off"})
#: Most layers a job may select, and the longest layer name.
MAX_LAYERS = 64
MAX_LAYER_CHARS = 200


#: Millimetres per unit of a length written in an option value (CSS/SVG units: 96 px and
#: 72 pt to the inch, as vpype and Inkscape read them).
LENGTH_UNITS: dict[str, float] = {"mm": 1.0, "cm": 10.0, "in": 25.4, "pt": 25.4 / 72.0,
                                  "px": 25.4 / 96.0}
#: Paper sizes by name, portrait (width, height) in mm: ISO 216 and the US sizes.
PAGE_SIZES: dict[str, tuple[float, float]] = {
    "a6": (105.0, 148.0), "a5": (148.0, 210.0), "a4": (210.0, 297.0), "a3": (297.0, 420.0),
    "letter": (215.9, 279.4), "legal": (215.9, 355.6), "tabloid": (279.4, 431.8)}
_LENGTH = re.compile(r"^\s*([-+]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|nan|inf))\s*"
                     r"([a-zA-Z]*)\s*$", re.IGNORECASE)


def parse_length(text: str) -> float:
    """A length in mm from text: a number with an optional unit (mm, cm, in, pt, px; none
    means mm), e.g. "0.1mm", "1in", "72pt". ValueError says what it must look like."""
    m = _LENGTH.match(text)
    unit = m.group(2).lower() if m else ""
    if m is None or unit not in ("", *LENGTH_UNITS):
        raise ValueError(f"must be a length such as 12.5, 0.1mm, 1in, 2cm, 72pt or 96px; "
                         f"got {text!r}")
    return float(m.group(1)) * LENGTH_UNITS.get(unit, 1.0)


_SPEED = re.compile(r"^(.*?)\s*/\s*(s|sec|min)\s*$", re.IGNORECASE)
#: Time units in seconds, as a duration may be written ("15", "15s", "500ms", "1.5min").
TIME_UNITS: dict[str, float] = {"ms": 1e-3, "s": 1.0, "sec": 1.0, "min": 60.0}


def parse_duration(text: str, unit: str = "s") -> float:
    """A duration in `unit` (s or ms) from text: a number with an optional unit (ms, s,
    min; none means `unit`), e.g. "15", "15s", "500ms", "1.5min". ValueError says what it
    must look like."""
    m = _LENGTH.match(text)
    given = m.group(2).lower() if m else ""
    if m is None or given not in ("", *TIME_UNITS):
        raise ValueError(f"must be a duration such as 15 ({unit}), 15s, 500ms or 1.5min; "
                         f"got {text!r}")
    return float(m.group(1)) * (TIME_UNITS[given] / TIME_UNITS[unit] if given else 1.0)


def parse_speed(text: str) -> float:
    """A speed in mm/s from text: a length per second or minute ("40", "40mm/s", "1in/s",
    "2400mm/min"; a bare number is mm/s). ValueError says what it must look like."""
    m = _SPEED.match(text.strip())
    try:
        if m is None:
            return parse_length(text)
        per_s = 60.0 if m.group(2).lower() == "min" else 1.0
        return parse_length(m.group(1)) / per_s
    except ValueError:
        raise ValueError(f"must be a speed such as 40, 40mm/s, 1.5in/s or 2400mm/min; "
                         f"got {text!r}") from None


def parse_fraction(text: str) -> float:
    """A plain number or a percentage ("0.5", "50%")."""
    t = text.strip()
    return float(t[:-1]) / 100.0 if t.endswith("%") else float(t)


def parse_page(text: str, landscape: bool = False) -> tuple[float, float]:
    """A page size (width, height) in mm: a name (A3, A4, A5, A6, letter, legal, tabloid;
    portrait unless `landscape`) or "WxH" with optional units on each side ("200x150",
    "8.5inx11in", "21cmx29.7cm"). `landscape` puts the longer side across. ValueError says
    what it must look like."""
    key = text.strip().lower()
    if key in PAGE_SIZES:
        w, h = PAGE_SIZES[key]
    else:
        try:
            w, h = (parse_length(v) for v in _split_page(key))
        except ValueError:
            raise ValueError("page size must be a name (A3, A4, A5, A6, letter, legal, "
                             "tabloid) or WxH with optional units (200x150, 8.5inx11in); "
                             f"got {text!r}") from None
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        raise ValueError(f"page size must be positive; got {text!r}")
    return (max(w, h), min(w, h)) if landscape else (w, h)


def _split_page(text: str) -> tuple[str, str]:
    """"WxH" into its two sides ("x" or "×" between two lengths)."""
    m = re.match(r"^\s*(.+?[0-9.a-wyz])\s*[x×]\s*([-+0-9.].*)$", text)
    if m is None:
        raise ValueError(text)
    return m.group(1), m.group(2)


@dataclass(frozen=True)
class Option:
    """One job option.

    `name` is the field of `CompileOptions`/`JobOptions` it sets; `flag` the command line's
    spelling; `query` the daemon's query parameter. `kind` is one of "float", "bool",
    "choice", "xy" (two numbers "X,Y"), "int" and "text". `repeat` options take several values (a
    tuple). `cli=False` options exist only on the API (the CLI asks on the terminal
    instead). "int" is a whole number within [lo, hi] (`--copies`)."""

    name: str
    flag: str
    query: str
    kind: str
    help: str
    unit: str = ""
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    choices: tuple[str, ...] = ()
    repeat: bool = False
    metavar: str = ""
    cli: bool = True
    percent: bool = False  # a float that may be written as a percentage ("50%")
    #: a word that stands for the value 0 (`--hatch pen`: the profile's pen width); the
    #: CLI flag may then be given without a value, meaning that word
    word: str = ""
    #: The web page's words: its label, its help where `help` speaks in flags or G-code
    #: (empty: `help`), and an example value for the empty field.
    label: str = ""
    web_help: str = ""
    example: str = ""

    # ------------------------------------------------------------------ parsing
    def parse(self, text: str) -> Any:
        """One value from its text form (command line or query string); OptionError names
        the option and says what it must look like."""
        text = text.strip()
        if self.kind == "bool":
            low = text.lower()
            if low in _TRUE or low in _FALSE:
                return low in _TRUE
            return self._fail(f"must be true or false; got {text!r}")
        if self.kind == "choice":
            if text not in self.choices:
                return self._fail(f"must be one of {', '.join(self.choices)}; got {text!r}")
            return text
        if self.kind == "int":
            try:
                n = int(text)
            except ValueError:
                return self._fail(f"must be a whole number; got {text!r}")
            return self.check(n)
        if self.kind == "float":
            try:
                v = self._number(text)
            except ValueError as e:
                why = str(e) if self.unit in ("mm", "mm/s", "s", "ms") else (
                    f"must be a number{self._unit_text()}"
                    + (" or a percentage (50%)" if self.percent else "") + f"; got {text!r}")
                return self._fail(why)
            return self.check(v)
        if self.kind == "xy":
            parts = text.split(",")
            try:
                x, y = (parse_length(p) for p in parts)
            except ValueError:
                return self._fail(f"must look like X,Y in mm or with units (e.g. 10,95 or "
                                  f"1in,4in); got {text!r}")
            return self.check((x, y))
        return self.check(text)

    def _number(self, text: str) -> float:
        """The number of a float option's text, in its unit (ValueError when malformed)."""
        if self.word and text.lower() == self.word:
            return 0.0
        if self.unit == "mm":
            return parse_length(text)
        if self.unit == "mm/s":
            return parse_speed(text)
        if self.unit in ("s", "ms"):
            return parse_duration(text, self.unit)
        return parse_fraction(text) if self.percent else float(text)

    def check(self, value: Any) -> Any:
        """Validate an already typed value (range, finiteness, length); returns it."""
        if value is None:
            return None
        if self.kind == "float":
            v = float(value)
            if not math.isfinite(v):
                self._fail(f"must be finite; got {value!r}")
            self._check_range(v)
            return v
        if self.kind == "int":
            try:
                n = int(value)
                whole = not isinstance(value, bool) and float(value) == n
            except (TypeError, ValueError, OverflowError):
                whole = False
            if not whole:
                self._fail(f"must be a whole number; got {value!r}")
            self._check_range(n)
            return n
        if self.kind == "xy":
            x, y = (float(c) for c in value)
            if not (math.isfinite(x) and math.isfinite(y)):
                self._fail(f"must be finite; got {value!r}")
            return (x, y)
        if self.kind == "text" and len(str(value)) > MAX_LAYER_CHARS:
            self._fail(f"must be at most {MAX_LAYER_CHARS} characters")
        if self.kind == "choice" and value not in self.choices:
            self._fail(f"must be one of {', '.join(self.choices)}; got {value!r}")
        if self.kind == "bool":
            return bool(value)
        return value

    def _check_range(self, v: float) -> None:
        low_bad = self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo)
        if low_bad or (self.hi is not None and v > self.hi):
            self._fail(f"must be within {self.range_text()}; got {v!r}")

    def _fail(self, why: str) -> NoReturn:
        raise OptionError(self.query, why)

    # ------------------------------------------------------------------ text forms
    def _unit_text(self) -> str:
        return f" ({self.unit})" if self.unit else ""

    def range_text(self) -> str:
        """The allowed range, e.g. "0.0001..10 mm" or "> 0"."""
        if self.lo is None and self.hi is None:
            return ""
        if self.hi is None:
            return f"{'>' if self.lo_open else '>='} {self.lo:g}"
        unit = f" {self.unit}" if self.unit else ""
        if self.lo_open:
            return f"> {self.lo:g} and <= {self.hi:g}{unit}"
        return f"{self.lo:g}..{self.hi:g}{unit}"

    def describe(self) -> str:
        """The help text with unit and range (click's help, the OpenAPI description)."""
        rng = self.range_text()
        return self.help + (f" Range: {rng}." if rng else "")

    def to_text(self, value: Any) -> str | list[str] | None:
        """The query-string form of a value (None: leave the parameter out)."""
        if value is None or (self.repeat and not value):
            return None
        if self.repeat:
            return [str(v) for v in value]
        if self.kind == "bool":
            return "true" if value else "false"
        if self.kind == "xy":
            return f"{float(value[0])!r},{float(value[1])!r}"
        return str(value)

    def openapi(self) -> dict[str, Any]:
        """The OpenAPI 3 parameter object of this option (query, optional)."""
        schemas: dict[str, dict[str, Any]] = {
            "bool": {"type": "boolean"}, "float": {"type": "number"},
            "int": {"type": "integer"},
            "choice": {"type": "string", "enum": list(self.choices)},
            "xy": {"type": "string", "pattern": r"^[^,]+,[^,]+$"}, "text": {"type": "string"}}
        schema = schemas[self.kind]
        if self.kind in ("float", "int"):
            if self.lo is not None:
                schema["exclusiveMinimum" if self.lo_open else "minimum"] = self.lo
            if self.hi is not None:
                schema["maximum"] = self.hi
            if self.unit in ("mm", "mm/s") or self.percent:  # also "0.1mm", "1in/s", "50%"
                # (minimum/maximum apply to the number; the text is checked by `parse`)
                del schema["type"]
                schema["anyOf"] = [{"type": "number"}, {"type": "string"}]
        if self.repeat:
            schema = {"type": "array", "items": schema, "maxItems": MAX_LAYERS}
        elif self.default is not None:
            schema["default"] = self.default
        return {"name": self.query, "in": "query", "required": False,
                "description": self.describe(), "schema": schema}


WORKING_MODE_CHOICES = ("++", "+-", "-+", "--", "auto")

#: The job options, in the order the CLI's help lists them.
JOB_OPTIONS: tuple[Option, ...] = (
    Option("mode", "--mode", "mode", "choice", choices=WORKING_MODE_CHOICES,
           help="Working mode; auto tries all four and picks one that clears every check "
           "(default: the profile's)."),
    Option("tolerance_mm", "--tolerance", "tolerance", "float", unit="mm", lo=1e-4, hi=10.0,
           help="Largest deviation of the drawn path, mm or with a unit (0.1mm, 0.004in) "
           "(default: the profile's)."),
    Option("origin_mm", "--origin", "origin", "xy", unit="mm", metavar="X,Y",
           help="Put the drawing's origin (SVG: page bottom-left) at machine X,Y: mm, or "
           "with units (1in,4in; mm, cm, in, pt, px) (default: SVG centred in the largest safe "
           "rectangle; G-code at its own coordinates)."),
    Option("scale", "--scale", "scale", "float", lo=0.0, lo_open=True, percent=True,
           help="Scale factor or percentage: 0.5 or 50% (default 1)."),
    Option("rotate_deg", "--rotate", "rotate", "float", unit="degrees", default=0.0,
           help="Rotate the drawing, degrees counter-clockwise."),
    Option("fit", "--fit", "fit", "bool", default=False,
           help="Scale the drawing to fill the largest singularity-safe rectangle of the "
           "working mode."),
    Option("layers", "--layer", "layer", "text", repeat=True, default=(), metavar="NAME",
           help="Only this Inkscape layer (label or id); repeatable."),
    Option("keep_order", "--keep-order", "keep_order", "bool", default=False,
           help="Draw paths in file order (no reordering to cut travel)."),
    Option("draw_feed_mm_s", "--draw-speed", "draw_speed", "float", unit="mm/s", lo=0.0,
           lo_open=True, hi=10_000.0, metavar="SPEED",
           help="Pen speed while drawing: mm/s, or with units (25mm/s, 1in/s, 1500mm/min) "
           "(default: the profile's draw_feed_mm_s; G-code F words still apply)."),
    Option("travel_feed_mm_s", "--travel-speed", "travel_speed", "float", unit="mm/s",
           lo=0.0, lo_open=True, hi=10_000.0, metavar="SPEED",
           help="Pen speed between strokes (pen up, laser off), like --draw-speed (default: "
           "the profile's travel_feed_mm_s)."),
    Option("accel_fraction", "--accel", "accel", "float", lo=0.0, lo_open=True, hi=1.0,
           percent=True, metavar="FRACTION",
           help="Joint acceleration as a share of the profile's max_joint_rad_s2: 0.5 or "
           "50% (default 1)."),
    Option("max_segments", "--max-segments", "max_segments", "float", lo=1.0, hi=1e9,
           metavar="N", help="Refuse a drawing with more path segments than this, or whose "
           "flattened curves have more than 4 times as many points, before memory runs out "
           "(default 2000000: about 0.6 GB of memory)."),
    Option("laser", "--laser", "laser", "bool", default=False,
           help="Laser job: drawing segments carry the profile's power (S > 0). Without it "
           "every line says S0 (pen plotter: pen down/up = M3/M5 around drawing strokes)."),
    # pen servo (profile [pen]; AxiDraw's names): None keeps the profile's value
    Option("pen_up_position", "--pen-pos-up", "pen_pos_up", "float", unit="%", lo=0.0,
           hi=100.0, help="Pen up position, percent of the servo range (default: the "
           "profile's [pen] up_position)."),
    Option("pen_down_position", "--pen-pos-down", "pen_pos_down", "float", unit="%", lo=0.0,
           hi=100.0, help="Pen down position, percent of the servo range (default: the "
           "profile's)."),
    Option("pen_up_rate", "--pen-rate-raise", "pen_rate_raise", "float", unit="%/s", lo=0.0,
           lo_open=True, help="Pen raising speed, percent of the servo range per second."),
    Option("pen_down_rate", "--pen-rate-lower", "pen_rate_lower", "float", unit="%/s",
           lo=0.0, lo_open=True, help="Pen lowering speed, percent of the servo range per "
           "second."),
    Option("pen_up_delay_ms", "--pen-delay-up", "pen_delay_up", "float", unit="ms", lo=0.0,
           hi=10_000.0, help="Wait after raising the pen before the arms move, ms or with a "
           "unit (0.2s)."),
    Option("pen_down_delay_ms", "--pen-delay-down", "pen_delay_down", "float", unit="ms",
           lo=0.0, hi=10_000.0, help="Wait after lowering the pen before the arms move, ms or "
           "with a unit (0.2s)."),
    # layers, pen changes and copies (AxiDraw's names)
    Option("layer_pause", "--layer-pause", "layer_pause", "bool", default=False,
           help="Stop between the drawing's Inkscape layers for a pen change: the pen goes "
           "up, the machine waits until you continue (a layer whose name starts with '!' "
           "pauses before it even without this). Layers are drawn in document order, "
           "each ordered on its own."),
    Option("no_pause", "--no-pause", "no_pause", "bool", default=False,
           help="Never stop for a pen change, not even before '!' layers (needed to plot "
           "such a drawing without a terminal to answer)."),
    Option("gcode_strict", "--strict", "strict", "bool", default=False,
           help="G-code: refuse every word the reader does not draw with, as fivebar did "
           "before word classes (default: words that cannot change the drawn path, such as "
           "coolant, $ queries or G64, are skipped with one note; M0/M6 become pen-change "
           "stops; docs/gcode.md)."),
    Option("copies", "--copies", "copies", "int", lo=1, hi=9999, default=1, metavar="N",
           help="Plot the whole job N times, the pen up and the arms parked between copies."),
    Option("page_delay_s", "--page-delay", "page_delay", "float", unit="s", lo=0.0,
           hi=3600.0, default=15.0, metavar="SECONDS",
           help="Wait between copies, seconds or with a unit (500ms, 1.5min): time to "
           "change the paper (Ctrl-C holds)."),
    Option("confirm", "--yes", "confirm", "bool", default=False, cli=False,
           help="Answer yes if the daemon must ask whether the arms are at the home pose "
           "(first job after power-up)."),
    Option("no_simplify", "--no-simplify", "no_simplify", "bool", default=False,
           help="Keep every vertex of densely sampled straight-line input (default: runs of "
           "lines are simplified within half the tolerance, the drawn path still within it)."),
    # raster engraving of an image (PNG, JPEG, BMP, GIF, TIFF, WebP; docs/raster.md)
    Option("width_mm", "--width", "width", "float", unit="mm", lo=0.0, lo_open=True,
           hi=10_000.0, metavar="LENGTH", help="Image: its width on the machine, mm or with "
           "units (40, 40mm, 1.5in); the height follows the image's shape unless --height."),
    Option("height_mm", "--height", "height", "float", unit="mm", lo=0.0, lo_open=True,
           hi=10_000.0, metavar="LENGTH", help="Image: its height on the machine, like "
           "--width."),
    Option("dpi", "--dpi", "dpi", "float", lo=0.0, lo_open=True, hi=100_000.0,
           help="Image: its resolution, pixels per inch, when neither --width nor --height "
           "(default: the file's own, else 96)."),
    Option("line_interval_mm", "--line-interval", "line_interval", "float", unit="mm",
           lo=0.005, hi=10.0, metavar="LENGTH", help="Image: the burn's pixel size, mm "
           "(0.1 = 10 px/mm); the image is resampled to it (default: its own pixels; with "
           "--fill scan the rows' spacing, default the profile's [laser] spot_mm)."),
    Option("image_mode", "--image-mode", "image_mode", "choice", default="grayscale",
           choices=("grayscale", "threshold", "floyd", "jarvis", "stucki", "atkinson",
                    "bayer"), help="Image: grayscale (power per pixel between --power-min "
           "and --power-max), threshold, or dithering (Floyd-Steinberg, Jarvis, Stucki, "
           "Atkinson, ordered Bayer 8x8)."),
    Option("power_min", "--power-min", "power_min", "int", lo=0, hi=255, default=0,
           help="Image: the power of the lightest non-white pixel (grayscale), 0..255."),
    Option("power_max", "--power-max", "power_max", "int", lo=0, hi=255,
           help="Image: the power of black (and of every dithered dot), 0..255 (default: "
           "the profile's [laser] power)."),
    Option("gamma", "--gamma", "gamma", "float", lo=0.05, hi=20.0, default=1.0,
           help="Image: power curve, darkness^gamma (grayscale); above 1 keeps light tones "
           "lighter."),
    Option("threshold", "--threshold", "threshold", "float", lo=0.0, lo_open=True, hi=1.0,
           percent=True, default=0.5, help="Image: darkness from which a pixel burns "
           "(threshold mode): 0.5 or 50%."),
    Option("negative", "--negative", "negative", "bool", default=False,
           help="Image: invert it (burn the light parts)."),
    Option("scan_angle_deg", "--scan-angle", "scan_angle", "float", unit="degrees",
           lo=-360.0, hi=360.0, default=0.0, help="Image: the scanlines' direction, degrees "
           "counter-clockwise from +x (the image stays upright)."),
    Option("one_way", "--one-way", "one_way", "bool", default=False,
           help="Image: burn every scanline in the same direction (default: bidirectional)."),
    Option("passes", "--passes", "passes", "int", lo=1, hi=100, default=1, metavar="N",
           help="Image: burn it N times over."),
    # fills (docs/fill.md)
    Option("hatch_mm", "--hatch", "hatch", "float", unit="mm", lo=0.0, hi=100.0,
           word="pen", metavar="SPACING",
           help="Fill every filled shape with hatch lines this far apart on the paper: mm or "
           "with units (0.4mm); 'pen' or the bare flag: the profile's pen width "
           "([pen] width_mm, a laser's [laser] spot_mm). Exact fill-rule; text is not "
           "hatched."),
    Option("hatch_angle_deg", "--hatch-angle", "hatch_angle", "float", unit="degrees",
           default=45.0, lo=-360.0, hi=360.0, metavar="DEGREES",
           help="Hatch direction on the drawing, degrees counter-clockwise from its x axis."),
    Option("crosshatch", "--crosshatch", "crosshatch", "bool", default=False,
           help="Hatch a second time at right angles."),
    Option("hatch_inset_mm", "--hatch-inset", "hatch_inset", "float", unit="mm", lo=0.0,
           hi=100.0, default=0.0, metavar="DISTANCE",
           help="Keep the hatch this far inside each shape's edge, mm or with units."),
    Option("hatch_along", "--hatch-along", "hatch_along", "choice", default="lines",
           choices=("lines", "arm1", "arm2"),
           help="Hatch with straight lines, or along joint-iso arcs: arm1 holds motor 1 "
           "still on a whole step while motor 2 swings the pen about arm 1's elbow (the "
           "pen exactly on the arc, no step rounding across it); the gap between arcs "
           "varies with the linkage's angles, at most the spacing, and the dry run says "
           "how much. --crosshatch adds the other arm's arcs."),
    Option("hiding", "--hiding", "hiding", "bool", default=False,
           help="Hidden-line removal: a filled shape hides what lies beneath it (paint "
           "order); strokes and hatches are cut where covered, fill-only shapes hide "
           "without being outlined. A layer with '+nohide' in its name is left out."),
    Option("fill", "--fill", "fill", "choice", default="outline", choices=("outline", "scan"),
           help="Laser: outline engraves the paths (and --hatch lines); scan burns the "
           "filled shapes by scanlines like an image (--line-interval, default the "
           "profile's [laser] spot_mm; --scan-angle, --one-way, --passes; --power-max); "
           "strokes are then not engraved (docs/fill.md)."),
)
#: The options of a raster engraving (an image; `raster.job.RasterOptions`).
RASTER_NAMES: tuple[str, ...] = ("width_mm", "height_mm", "dpi", "line_interval_mm",
                                 "image_mode", "power_min", "power_max", "gamma", "threshold",
                                 "negative", "scan_angle_deg", "one_way", "passes", "fill")
JOB_OPTIONS = tuple(
    dataclasses.replace(o, label=_WORDS[o.name][0], web_help=_WORDS[o.name][1],
                        example=_WORDS[o.name][2]) if o.name in _WORDS else o
    for o in JOB_OPTIONS)
BY_NAME: dict[str, Option] = {o.name: o for o in JOB_OPTIONS}
BY_QUERY: dict[str, Option] = {o.query: o for o in JOB_OPTIONS}
#: The pen servo overrides (applied to the profile: config.with_pen_overrides).
PEN_NAMES: tuple[str, ...] = tuple(o.name for o in JOB_OPTIONS if o.name.startswith("pen_"))
#: The options of the run, not of the compiled job: how often and how long between copies.
RUN_NAMES: tuple[str, ...] = ("copies", "page_delay_s")
#: The options that shape the compiled job (everything but laser, confirm, the pen's and
#: the run's).
COMPILE_NAMES: tuple[str, ...] = tuple(
    o.name for o in JOB_OPTIONS
    if o.name not in ("laser", "confirm", *PEN_NAMES, *RUN_NAMES, *RASTER_NAMES))


def defaults() -> dict[str, Any]:
    """Every option at its default, keyed by field name."""
    return {o.name: o.default for o in JOB_OPTIONS}


def unknown_option(key: str, known: Iterable[str]) -> OptionError:
    """The error for an option nobody declared, with the closest known name."""
    names = sorted(known)
    close = difflib.get_close_matches(key, names, n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return OptionError(key, f"unknown option{hint}; known: {', '.join(names)}")


def parse_query(pairs: Iterable[tuple[str, str]],
                extra: Iterable[str] = ()) -> dict[str, Any]:
    """Job option values from query-string pairs, keyed by field name, defaults filled in.

    Keys in `extra` (the endpoint's own parameters, such as the file name) are skipped; any
    other unknown key is an OptionError (a misspelt option is never silently ignored), and
    so is a second value for an option that takes one."""
    skip = frozenset(extra)
    values = defaults()
    seen: set[str] = set()
    for key, text in pairs:
        if key in skip:
            continue
        opt = BY_QUERY.get(key)
        if opt is None:
            raise unknown_option(key, [*BY_QUERY, *skip])
        if opt.repeat:
            items = (*values[opt.name], opt.parse(text))
            if len(items) > MAX_LAYERS:
                opt._fail(f"at most {MAX_LAYERS} values")
            values[opt.name] = items
            continue
        if key in seen:
            opt._fail("given more than once")
        seen.add(key)
        values[opt.name] = opt.parse(text)
    return values


def check_values(values: Mapping[str, Any]) -> dict[str, Any]:
    """Typed option values (e.g. from Python callers) checked against their definitions;
    unknown names are an OptionError. Missing ones take their defaults."""
    out = defaults()
    for name, value in values.items():
        opt = BY_NAME.get(name)
        if opt is None:
            raise unknown_option(name, BY_NAME)
        if opt.repeat:
            items = tuple(opt.check(v) for v in (value or ()))
            if len(items) > MAX_LAYERS:
                opt._fail(f"at most {MAX_LAYERS} values")
            out[name] = items
        else:
            out[name] = opt.check(value)
    return out


def to_query(values: Mapping[str, Any]) -> dict[str, str | list[str]]:
    """The query parameters for option values keyed by field name (the HTTP client's side
    of `parse_query`)."""
    checked = check_values(values)
    out: dict[str, str | list[str]] = {}
    for name, value in checked.items():
        text = BY_NAME[name].to_text(value)
        if text is not None:
            out[BY_NAME[name].query] = text
    return out


def compile_values(values: Mapping[str, Any]) -> dict[str, Any]:
    """The subset of option values that shapes the compiled job (`CompileOptions(**…)`);
    OptionError when they contradict each other (--layer-pause with --no-pause)."""
    if values.get("layer_pause") and values.get("no_pause"):
        raise OptionError("no_pause", "--layer-pause and --no-pause contradict each other; "
                          "give one of them")
    return {k: values[k] for k in COMPILE_NAMES if k in values}
