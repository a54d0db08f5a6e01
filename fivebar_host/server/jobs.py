"""Submitted drawings → compiled, checked jobs: options, names, parsing in memory.

A submission is the drawing's bytes plus the plot options of `fivebar plot` (mode, tolerance,
origin, scale, rotation, fit, layers, keep-order, laser). It is parsed in memory (the SVG and
G-code readers take bytes) and compiled with the daemon's profile exactly as the CLI would,
so a job that cannot run is refused with the CLI's message and never queued. The client's
file name is only a label (and, by its suffix, the format): it must be a bare file name —
no directory parts — and never touches the file system.
"""

from __future__ import annotations

import hashlib
import re
import sys
import threading
import unicodedata
from collections import OrderedDict
from dataclasses import asdict, dataclass, fields
from typing import Any

from fivebar_host.compile import GCODE_SUFFIXES, CompileOptions, Job, compile_drawing, gcode_tool
from fivebar_host.config import Profile, require_tool
from fivebar_host.errors import FivebarError, InputError, JobError, OptionError, shorten
from fivebar_host.options import PEN_NAMES, check_values, compile_values
from fivebar_host.raster.fill import compile_fill_scan
from fivebar_host.raster.fill import refuse as refuse_fill
from fivebar_host.raster.image import decode as decode_image
from fivebar_host.raster.image import is_image_file
from fivebar_host.raster.job import compile_raster, raster_options
from fivebar_host.raster.svgimage import compile_svg_images
from fivebar_host.run.resume import fingerprint
from fivebar_host.run.stops import Copies
from fivebar_host.toolpath.gcode import read_gcode
from fivebar_host.toolpath.svg import read_svg


def _invisible_ranges() -> str:
    """The characters a shown name must not hold, as a regular-expression class body:
    controls (C0, DEL, C1), format characters (bidi marks, embeddings, overrides and
    isolates, zero-width characters, the BOM: a right-to-left override in a name makes
    "gpj.svg" show as "gvs.jpg") and the line and paragraph separators."""
    bad = [c for c in range(sys.maxunicode + 1)
           if unicodedata.category(chr(c)) in ("Cc", "Cf", "Zl", "Zp")]
    runs: list[tuple[int, int]] = []
    for c in bad:
        if runs and runs[-1][1] == c - 1:
            runs[-1] = (runs[-1][0], c)
        else:
            runs.append((c, c))

    def one(c: int) -> str:
        return f"\\x{c:02x}" if c < 0x80 else chr(c)
    return "".join(one(a) if a == b else f"{one(a)}-{one(b)}" for a, b in runs)


#: What a file name may look like (also its OpenAPI pattern, so the two agree): 1 to 128
#: characters, no directory separators, no control or format character, and no leading
#: dot (no ".", "..", nor a hidden file's name).
_INVISIBLE = _invisible_ranges()
NAME_PATTERN = f"^[^./\\\\{_INVISIBLE}][^/\\\\{_INVISIBLE}]{{0,127}}$"
_NAME = re.compile(NAME_PATTERN)
SVG_SUFFIXES = frozenset({".svg"})


class SubmitError(FivebarError, ValueError):
    """A submission refused before it was queued: `code` (stable key) and the message."""

    def __init__(self, code: str, message: str, status: int = 422,
                 detail: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.code = code
        self.status = status
        self.detail = detail or {}

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled with all its fields (it crosses from a compiling process,
        `server.compiler`)."""
        return (type(self), (self.code, str(self), self.status, self.detail))


#: CompileOptions fields a submission cannot set: the daemon always validates its jobs.
_FIXED = frozenset({"validate", "validation_samples"})


@dataclass(frozen=True)
class JobOptions(CompileOptions):
    """The plot options of a submission: the compiler's (None: the daemon profile's value),
    plus the laser opt-in and the answer to the daemon's pose question."""

    laser: bool = False
    #: Answer yes to the daemon's question "are the arms at the home pose?" (or "still where
    #: the job stopped?") when the daemon cannot know it itself (first job after power-up).
    confirm: bool = False
    #: Pen servo overrides (fivebar_host.options PEN_NAMES): declared so that the API knows
    #: them, but the daemon runs its own profile's pen and refuses them (compile_upload).
    pen_up_position: float | None = None
    pen_down_position: float | None = None
    pen_up_rate: float | None = None
    pen_down_rate: float | None = None
    pen_up_delay_ms: float | None = None
    pen_down_delay_ms: float | None = None
    #: The run's copies and the wait between them, s (`run.stops`; not compiled).
    copies: int = 1
    page_delay_s: float = 15.0
    #: Raster engraving of an uploaded image (fivebar_host.options RASTER_NAMES;
    #: `raster.job.raster_options` reads them; ignored for drawings).
    width_mm: float | None = None
    height_mm: float | None = None
    dpi: float | None = None
    line_interval_mm: float | None = None
    image_mode: str = "grayscale"
    power_min: int = 0
    power_max: int | None = None
    gamma: float = 1.0
    threshold: float = 0.5
    negative: bool = False
    scan_angle_deg: float = 0.0
    one_way: bool = False
    passes: int = 1
    #: `--fill scan`: a drawing's filled shapes burned by scanlines (`raster.fill`).
    fill: str = "outline"

    def copies_plan(self) -> Copies:
        """The copies and page delay as the sender takes them."""
        return Copies(self.copies, self.page_delay_s)

    def compile_options(self) -> CompileOptions:
        """The compiler's options (everything but laser and confirm)."""
        values = {f.name: getattr(self, f.name) for f in fields(CompileOptions)}
        compile_values(values)  # options that contradict each other (OptionError)
        return CompileOptions(**values)

    def to_json(self) -> dict[str, Any]:
        """A JSON-friendly dict (stored with the job)."""
        d = {k: v for k, v in asdict(self).items() if k not in _FIXED}
        d["layers"] = list(self.layers)
        d["origin_mm"] = list(self.origin_mm) if self.origin_mm is not None else None
        return d

    @staticmethod
    def from_values(values: dict[str, Any]) -> JobOptions:
        """From option values keyed by field name (`fivebar_host.options`), checked against
        their definitions; unknown names are an OptionError."""
        return JobOptions(**check_values(values))

    @staticmethod
    def from_json(d: dict[str, Any]) -> JobOptions:
        """Inverse of `to_json` (a stored job)."""
        return JobOptions.from_values(
            {**d, "layers": tuple(d.get("layers", ())),
             "origin_mm": None if d.get("origin_mm") is None else tuple(d["origin_mm"])})


def check_name(name: str) -> str:
    """A client's file name, refused when it is a path or not printable."""
    if not _NAME.match(name):
        raise SubmitError("bad_name", f"name must be a plain file name (no directories, "
                          "no leading dot, at most 128 characters, no control, bidi or "
                          f"other invisible characters); got {shorten(name)!a}",
                          status=400)
    return name


def _suffix(name: str) -> str:
    dot = name.rfind(".")
    return name[dot:].lower() if dot > 0 else ""


def read_upload(data: bytes, name: str, layers: tuple[str, ...],
                profile: Profile | None = None) -> Any:
    """Parse an uploaded drawing in memory, by suffix or else by content (like the CLI);
    `profile` gives G-code Z words their meaning (`compile.gcode_tool`)."""
    if not data.strip():
        raise SubmitError("empty_upload", f"{name}: the upload is empty", status=400)
    suffix = _suffix(name)
    text = profile.text if profile is not None else None  # the fonts of SVG <text>
    if suffix in SVG_SUFFIXES:
        return read_svg(data, layers or None, file=name, text=text)
    if suffix in GCODE_SUFFIXES or not data.lstrip()[:512].startswith(
            (b"<?xml", b"<svg", b"<!--", b"<!DOCTYPE")):
        if layers:
            raise InputError("--layer applies to SVG files only", name)
        return read_gcode(data, file=name, **gcode_tool(profile))
    return read_svg(data, layers or None, file=name, text=text)


@dataclass(frozen=True)
class Compiled:
    """A checked job and what identifies it."""

    job: Job
    fingerprint: str
    upload_sha256: str


def compile_upload(data: bytes, name: str, opts: JobOptions, profile: Profile) -> Compiled:
    """Parse and compile a submission; `SubmitError` with the CLI's message if it cannot run."""
    check_name(name)
    given = [n for n in PEN_NAMES if getattr(opts, n) is not None]
    if given:
        raise SubmitError("bad_option", f"{', '.join(given)}: pen overrides are not applied by "
                          "the daemon; set them in its profile's [pen] table")
    try:
        require_tool(profile, opts.laser)
        if is_image_file(name):  # raster engraving (docs/raster.md), like the CLI
            job = compile_raster(name, profile, raster_options(asdict(opts), profile),
                                 gray=decode_image(data, name))
        else:
            drawing = read_upload(data, name, opts.layers, profile)
            if drawing.images:  # an SVG's <image> elements burned (docs/raster.md)
                job = compile_svg_images(drawing, profile, asdict(opts), None)
            elif opts.fill == "scan":  # a drawing's fills by scanlines (docs/fill.md)
                refuse_fill(name, asdict(opts), profile)
                job = compile_fill_scan(name, profile, asdict(opts), drawing)
            else:
                job = compile_drawing(drawing, profile, opts.compile_options())
    except SubmitError:
        raise
    except InputError as e:
        raise SubmitError("input_error", str(e)) from e
    except JobError as e:
        detail: dict[str, Any] = {"reason": e.reason}
        if e.where is not None:
            w = e.where
            detail["where"] = {"path_index": w.path_index, "path_id": w.path_id,
                               "source_line": w.source_line,
                               "drawing_xy": list(w.drawing_xy) if w.drawing_xy else None,
                               "machine_xy": list(w.machine_xy) if w.machine_xy else None}
        raise SubmitError("job_error", str(e), detail=detail) from e
    except OptionError as e:
        raise SubmitError("bad_option", str(e)) from e
    except FivebarError as e:
        raise SubmitError("invalid", str(e)) from e
    return Compiled(job, fingerprint(job), hashlib.sha256(data).hexdigest())


class CompiledCache:
    """The last few compiled jobs by id, so a job is not compiled twice in one daemon run."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._items: OrderedDict[int, Job] = OrderedDict()
        self._lock = threading.Lock()

    def put(self, job_id: int, job: Job) -> None:
        """Remember a compiled job (the oldest is forgotten beyond `size`)."""
        with self._lock:
            self._items[job_id] = job
            self._items.move_to_end(job_id)
            while len(self._items) > self.size:
                self._items.popitem(last=False)

    def get(self, job_id: int) -> Job | None:
        """A remembered job, or None."""
        with self._lock:
            return self._items.get(job_id)

    def drop(self, job_id: int) -> None:
        """Forget a job (it is over)."""
        with self._lock:
            self._items.pop(job_id, None)
