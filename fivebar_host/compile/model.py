"""The data model of a compiled job: what the command line can change (`CompileOptions`) and
what compiling produces (`Job`, with its `PathStats` and `ModeChange` records).

`Job` holds everything streaming, resuming and the reports need, indexed per target (row 0 =
the homed pose, absolute steps (0, 0)) and per segment k (target k → k+1). It lives apart
from the pipeline (`fivebar_host.compile.job`) so the sender, the server, the previews and
the reports can use it without the compiler's stages.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, cast

import numpy as np
from numpy.typing import NDArray

from fivebar_host.compile import steps
from fivebar_host.toolpath import layout
from fivebar_host.toolpath.geometry import Drawing
from kinematics.arrays import BoolArray, FloatArray, IntArray
from kinematics.fivebar import FiveBar

#: Order in which `--mode auto` tries the working modes (ties keep this order).
AUTO_ORDER = ("+-", "-+", "++", "--")
#: Joint-space step cap per segment (rad): keeps the planner's rate staircase fine.
MAX_STEP_RAD = 0.05


def compact_ints(a: IntArray) -> IntArray:
    """`a` as int32 when every value fits (the same values in half the memory on large
    drawings), else unchanged."""
    i32 = np.iinfo(np.int32)
    if a.size and (a.min() < i32.min or a.max() > i32.max):
        return a
    return a.astype(np.int32, copy=False)


@functools.cache
def _libc_trim() -> Callable[[int], int] | None:
    """glibc's `malloc_trim`, or None where the C library has none."""
    try:
        return cast(Callable[[int], int],
                    ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim)
    except (OSError, AttributeError):
        return None


def release_free_memory() -> None:
    """Give the heap's free pages back to the system (glibc `malloc_trim`; nothing
    elsewhere). Called between the stages of a large job: the arrays a stage frees leave
    holes in the heap that the next stage's arrays, of other sizes, do not fill, and
    without this they stay resident and add to the peak (a few ms a call)."""
    trim = _libc_trim()
    if trim is not None:
        trim(0)


#: Rows converted at a time by `compact_steps` (bounds the float temporaries).
STEPS_BLOCK = 1 << 16


def compact_steps(angles_rad: FloatArray, home_rad: tuple[float, float],
                  steps_per_rev: float) -> IntArray:
    """`steps.absolute_steps` of the angles (N, 2), computed in blocks straight into int32
    (int64 when a value reaches 2^30, so that differences of steps fit too): the same steps
    without the whole float and int64 temporaries."""
    out = np.empty((angles_rad.shape[0], 2), dtype=np.int32)
    for i in range(0, angles_rad.shape[0], STEPS_BLOCK):
        st = steps.absolute_steps(angles_rad[i:i + STEPS_BLOCK], home_rad, steps_per_rev)
        if st.size and np.abs(st).max() >= 1 << 30:
            return steps.absolute_steps(angles_rad, home_rad, steps_per_rev)
        out[i:i + STEPS_BLOCK] = st
    return cast(IntArray, out)  # int32: the same values (IntArray names any int width here)

if TYPE_CHECKING:
    from fivebar_host.raster.runs import RasterRuns


@dataclass(frozen=True)
class CompileOptions:
    """What the command line can change (None: the profile's value)."""

    mode: str | None = None  # "++", "+-", "-+", "--", "auto"
    tolerance_mm: float | None = None
    origin_mm: tuple[float, float] | None = None
    scale: float | None = None
    rotate_deg: float = 0.0
    fit: bool = False
    layers: tuple[str, ...] = ()
    keep_order: bool = False
    draw_feed_mm_s: float | None = None  # None: the profile's [motion] values
    travel_feed_mm_s: float | None = None
    accel_fraction: float | None = None  # share (0, 1] of [motion] max_joint_rad_s2
    validate: bool = True
    validation_samples: int = 4
    no_simplify: bool = False  # keep every vertex of dense straight-line input
    max_segments: float | None = None  # None: `toolpath.svg.reader.DEFAULT_MAX_SEGMENTS`
    layer_pause: bool = False  # stop for a pen change between Inkscape layers
    no_pause: bool = False  # never stop for a pen change (not even before "!" layers)
    gcode_strict: bool = False  # G-code: every word outside the honoured ones refused
    # fills (`compile.fill`, docs/fill.md)
    hatch_mm: float | None = None  # hatch spacing on the paper; 0: the profile's pen width
    hatch_angle_deg: float = 45.0  # on the drawing, counter-clockwise from its x axis
    crosshatch: bool = False  # a second pass at +90°
    hatch_inset_mm: float = 0.0  # the hatch keeps this far inside each region's edge
    hiding: bool = False  # hidden-line removal in paint order (AxiDraw's --hiding)
    hatch_along: str = "lines"  # "arm1"/"arm2": joint-iso arcs, that motor still


@dataclass(frozen=True)
class PathStats:
    """Per job path (in drawing order): where it came from and how well it is drawn."""

    source: IntArray  # (P,) index of the first source element of the path
    reversed: BoolArray  # (P,)
    first_seg: IntArray  # (P,) first draw segment
    end_seg: IntArray  # (P,) one past the last draw segment
    max_dev_mm: FloatArray  # (P,) from the quantised steps (validation), NaN if not validated
    mean_dev_mm: FloatArray


@dataclass(frozen=True)
class LayerPause:
    """A stop for a pen change before segment `segment` (the first segment of the travel
    into the layer, or of its drawing; 0: before anything moves): the layer's `name` and
    its place `number` (1-based) among the job's `of` layers in document order
    (`compile.layers`)."""

    segment: int
    name: str
    number: int
    of: int

    def describe(self) -> str:
        """"layer 2/3 'red'" for prompts, reports and the daemon's pause reason."""
        return f"layer {self.number}/{self.of} {self.name!r}"


@dataclass(frozen=True)
class ModeChange:
    """A pen-up change of working mode compiled into the job (thesis Sec. 7.2), planned by
    `kinematics.modes.plan_working_modes` (or `plan_joint_move` for a move home): travel
    segments `first_seg` … `end_seg` − 1, laser off, drive the arm(s) whose working-mode sign
    changes through their type-1 singularity (stretched or folded) on the way into job path
    `path` (= `Job.n_paths`: the park move back to the homed pose). Measured on the executed
    move (quantised steps, sampled ≤ 0.5° apart): where each arm crosses (arm, "stretched" /
    "folded", x, y mm) and the smallest type-2 margin."""

    from_mode: str
    to_mode: str
    path: int
    first_seg: int
    end_seg: int
    lift_mm: tuple[float, float]
    land_mm: tuple[float, float]
    crossings: tuple[tuple[int, str, float, float], ...]
    min_type2_rad: float
    duration_s: float

    def describe(self, n_paths: int) -> str:
        """One line for the dry-run report."""
        into = "back to the homed pose" if self.path >= n_paths else f"into path #{self.path}"
        how = "; ".join(f"arm {a} {k} at ({x:.1f}, {y:.1f}) mm"
                        for a, k, x, y in self.crossings) or "no arm crossing"
        return (f"{self.from_mode} → {self.to_mode} {into}: pen up at ({self.lift_mm[0]:.1f}, "
                f"{self.lift_mm[1]:.1f}) mm, {how}, pen down at ({self.land_mm[0]:.1f}, "
                f"{self.land_mm[1]:.1f}) mm; segments {self.first_seg}–{self.end_seg - 1} "
                f"(laser off), {self.duration_s:.2f} s, type-2 margin ≥ "
                f"{math.degrees(self.min_type2_rad):.1f}°")


@dataclass(frozen=True)
class Job:
    """A compiled job (see module doc). Per target (T+1 rows; row 0 = homed pose):
    `points_mm`, `angles_rad`, `steps` (absolute). Per segment (T rows, target k → k+1):
    `draw`, `power` (0–255, 0 on travel), `path` (job path the segment draws or travels
    to; P for the final park move), `source` (source element index, −1 on travel),
    `source_line` (0 if unknown), `duration_us`, `length_mm` (requested pen path),
    `dwell` (a G-code dwell: no motion, not a drawing segment, `power` the laser power it
    burns with; `compile.dwell`; empty: none). The integer arrays (steps, indices,
    durations) are int32 when every value fits, else int64 (`compact_ints`: half the memory
    on large drawings; numpy sums them in int64)."""

    file: str
    mode: str
    assembly: int
    tolerance_mm: float
    flatten_tol_mm: float
    placement: layout.Placement
    drawing: Drawing
    steps_per_rev: float
    home_rad: tuple[float, float]
    points_mm: FloatArray
    angles_rad: FloatArray
    steps: IntArray
    draw: BoolArray
    power: NDArray[np.uint8]
    path: IntArray
    source: IntArray
    source_line: IntArray
    duration_us: IntArray
    length_mm: FloatArray
    paths: PathStats
    min_margin_rad: FloatArray  # (3,) smallest margins on targets and samples (draw+travel)
    step_quantum_mm: float
    travel_before_mm: float
    travel_after_mm: float
    joined: int
    notes: list[str] = field(default_factory=list)
    # validation data (requested geometry of each draw segment)
    seg_prim: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    #: first primitive each draw segment's chord covers (< seg_prim: a simplified run of
    #: input lines, measured against all of them); empty: one primitive per segment
    seg_prim_first: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    seg_tlo: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_thi: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_rev: BoolArray = field(default_factory=lambda: np.zeros(0, bool))
    seg_sa: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_sb: FloatArray = field(default_factory=lambda: np.zeros(0))
    seg_ca: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    seg_cb: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    max_dev_mm: float = math.nan
    mean_dev_mm: float = math.nan
    ideal_max_dev_mm: float = math.nan
    # working modes: per job path, at the homed pose, and the pen-up changes between them
    path_modes: tuple[str, ...] = ()
    home_mode: str = ""
    mode_changes: tuple[ModeChange, ...] = ()
    # pen servo moves and settle delays between the segments (0 without a pen), s
    tool_time_s: float = 0.0
    dwell: BoolArray = field(default_factory=lambda: np.zeros(0, bool))
    #: pen-change stops, by segment (`compile.layers`; empty: the job runs through)
    pauses: tuple[LayerPause, ...] = ()
    #: a raster job (an image, `fivebar_host.raster`): its G7 segments, lines and pixel runs;
    #: None for a drawing
    raster: RasterRuns | None = None
    #: per target, what the motor counts `steps` exceed the joint's steps by: the slack
    #: taken up at reversals (`compile.backlash`; empty: no backlash, counts = joint)
    slack: IntArray = field(default_factory=lambda: np.zeros((0, 2), np.int64))

    # ------------------------------------------------------------------ derived
    @property
    def n_segments(self) -> int:
        return int(self.draw.shape[0])

    @property
    def is_dwell(self) -> BoolArray:
        """Per segment: a dwell (`dwell`, or all False when the job has none)."""
        return self.dwell if self.dwell.size else np.zeros(self.n_segments, dtype=bool)

    @property
    def tool_on(self) -> BoolArray:
        """Per segment: the tool is on (pen down, laser at `power` with `--laser`): drawing
        segments and dwells with a power above 0."""
        return self.draw | (self.is_dwell & (self.power > 0))

    @property
    def dwell_time_s(self) -> float:
        """Planned time of the dwells, s (part of `total_time_s`)."""
        return float(self.duration_us[self.is_dwell].sum()) * 1e-6

    @property
    def joint_steps(self) -> IntArray:
        """The joints' steps at every target (T+1, 2): `steps` less the `slack` (backlash);
        what forward kinematics of the job reads."""
        return self.steps if not self.slack.shape[0] else self.steps.astype(np.int64) - self.slack

    @property
    def relative_steps(self) -> IntArray:
        """Per-segment step differences (T, 2): their running sum is `steps[1:]` exactly."""
        return steps.relative_steps(self.steps)

    @property
    def total_time_s(self) -> float:
        """Planned time: the segments' durations plus the pen's moves and delays."""
        return float(self.duration_us.sum()) * 1e-6 + self.tool_time_s

    @property
    def pen_downs(self) -> int:
        """Runs of drawing segments: each is one pen down and one pen up on a pen machine."""
        d = self.draw
        return int(d[0]) + int((d[1:] & ~d[:-1]).sum()) if d.size else 0

    def pause_at(self, segment: int) -> LayerPause | None:
        """The pen-change stop before `segment`, if there is one."""
        return next((p for p in self.pauses if p.segment == segment), None)

    @property
    def draw_length_mm(self) -> float:
        return float(self.length_mm[self.draw].sum())

    @property
    def travel_length_mm(self) -> float:
        return float(self.length_mm[~self.draw].sum())

    @property
    def n_paths(self) -> int:
        return int(self.paths.source.shape[0])

    def rel_or_abs(self, relative: bool) -> IntArray:
        """Per-segment step words: absolute targets `steps[1:]` or relative moves."""
        return self.relative_steps if relative else self.steps[1:]

    def executed_points(self, fb: FiveBar, samples: int = 4) -> FloatArray:
        """Pen positions along the whole job from the quantised steps, `samples` per segment
        plus the final target (forward kinematics of the joint-space interpolation)."""
        th = steps.step_angles(self.joint_steps, self.home_rad, self.steps_per_rev)
        s = np.arange(samples) / samples
        dth = np.diff(th, axis=0)
        q = (th[:-1, None, :] + s[None, :, None] * dth[:, None, :]).reshape(-1, 2)
        q = np.concatenate((q, th[-1:]))
        return fb.forward_batch(q, "+" if self.assembly > 0 else "-").points
