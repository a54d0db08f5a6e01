"""Machine profiles: TOML (stdlib tomllib) into frozen dataclasses, validated at the edge.

Units are parsed once here: the file says degrees where a human would (`*_deg`), the
dataclasses hold radians, millimetres and seconds. Unknown keys, missing keys, wrong types and
out-of-range values raise `ConfigError` naming the file, the key and the bound.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fivebar_host.errors import FivebarError, InputError
from fivebar_host.joints import ServoJoints, parse_joints, servo_backlash_steps
from fivebar_host.protocol import BASE_BAUD, BAUD_RATES
from fivebar_host.toolpath.fonts.library import FontLibrary, TextConfig
from kinematics.extension import ExtendedFiveBar
from kinematics.fivebar import WORKING_MODES, FiveBar

#: Assembly modes: "+" iff the pen lies left of the directed line R1→R2 (elbow to elbow).
ASSEMBLY_MODES = ("+", "-")
DEFAULT_PROFILE = Path(__file__).resolve().parent.parent / "configs" / "default.toml"


class ConfigError(FivebarError, ValueError):
    """A profile that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class Motors:
    """Stepper setup; steps per revolution come from the drive train, never a constant."""

    full_steps: int
    microsteps: int
    gear_ratio: float
    home_rad: tuple[float, float]
    limits_rad: tuple[tuple[float, float], tuple[float, float]]
    endstops: bool
    #: each motor's slack in steps, taken up at its reversals (compile/backlash.py)
    backlash_steps: tuple[int, int] = (0, 0)

    @property
    def steps_per_rev(self) -> float:
        """Motor full steps × microsteps × gear ratio (steps per joint revolution)."""
        return self.full_steps * self.microsteps * self.gear_ratio

    @property
    def rad_per_step(self) -> float:
        """Joint angle of one microstep, rad."""
        return 2.0 * math.pi / self.steps_per_rev


@dataclass(frozen=True)
class KinematicsCfg:
    """Working mode, the assembly mode the machine is built in, and the minimum angular
    distances to each singularity type.

    `assembly` ("+" iff the pen lies left of the directed line R1→R2) is a fact of the
    hardware, not a choice per job: a five-bar cannot change it under control (that would
    pass a type-2 singularity), so every pose of every job must have this sign."""

    working_mode: str
    assembly: str
    min_type1_margin_rad: float
    min_type2_margin_rad: float


@dataclass(frozen=True)
class Motion:
    """Feeds and joint limits used by the planner; the one path tolerance."""

    draw_feed_mm_s: float
    travel_feed_mm_s: float
    max_joint_rad_s: float
    max_joint_rad_s2: float
    tolerance_mm: float
    #: The largest instantaneous joint-speed change at a segment boundary (the firmware runs
    #: each segment at one rate: its velocity staircase jumps there), rad/s; optional key,
    #: 0.5 when absent (`compile.planner.JUNCTION_JUMP_RAD_S`).  Raster turnarounds of a
    #: few ms need a larger one (configs/raster-fast.toml).
    junction_jump_rad_s: float = 0.5


@dataclass(frozen=True)
class Laser:
    """Laser (or pen) switching: power 0–255 and the on command."""

    power: int
    on_command: str
    off_between_paths: bool
    silence_timeout_s: float
    #: the width the beam burns, mm (optional, default 0.1): `--hatch`'s default spacing
    spot_mm: float = 0.1


@dataclass(frozen=True)
class Pen:
    """A servo pen lift (the `[pen]` table; docs/protocol.md 6.2 for the firmware side).

    Positions are percent of the servo's range like AxiDraw's (0 % = `servo_min_us`, 100 %
    = `servo_max_us`), rates percent of that range per second, delays the time the pen
    needs to settle after a move before the arms may move (ms). `z_threshold_mm`: G-code Z
    above it means pen up. `width_mm` (optional, default 0.5): the line the pen draws, the
    default spacing of `--hatch`."""

    servo_min_us: int
    servo_max_us: int
    up_position: float
    down_position: float
    up_rate: float
    down_rate: float
    up_delay_ms: int
    down_delay_ms: int
    z_threshold_mm: float
    width_mm: float = 0.5

    def pulse_us(self, position: float) -> int:
        """Servo pulse of a position in percent of the range, µs."""
        span = self.servo_max_us - self.servo_min_us
        return round(self.servo_min_us + position / 100.0 * span)

    def move_ms(self, down: bool) -> int:
        """Time the firmware takes to move the pulse between up and down (R of M280),
        rounded up to whole 20 ms servo frames: the pulse changes once a frame, so a move
        ends at most this long after it starts, and the settle delay follows in full."""
        rate = self.down_rate if down else self.up_rate
        ms = abs(self.up_position - self.down_position) / rate * 1000.0
        return min(10_000, 20 * math.ceil(ms / 20.0 - 1e-9))

    def time_s(self, down: bool) -> float:
        """How long one lowering (`down`) or raising keeps the arms waiting, s."""
        return (self.move_ms(down) + (self.down_delay_ms if down else self.up_delay_ms)) / 1e3


@dataclass(frozen=True)
class SerialCfg:
    """Serial link settings."""

    baud: int
    banner_timeout_s: float
    reply_timeout_s: float
    #: the rate `$B` switches the fivebar link to once connected (docs/protocol.md 1.1);
    #: the port opens at `baud`, the firmware's boot rate, 115200
    link_baud: int = 115200


@dataclass(frozen=True)
class Profile:
    """A complete machine profile."""

    geometry: FiveBar
    motors: Motors
    kinematics: KinematicsCfg
    motion: Motion
    laser: Laser
    serial: SerialCfg
    source: str
    tool: str = "laser"  # "pen" (a servo pen lift, `pen` set) or "laser"
    pen: Pen | None = None
    text: TextConfig = field(default_factory=TextConfig)  # `[text]`: the fonts of SVG text
    joints: ServoJoints | None = None  # `[joints]`: None = steppers (fivebar_host/joints.py)


class _Table:
    """Reads one TOML table, remembering which keys were used so leftovers are errors."""

    def __init__(self, doc: dict[str, Any], name: str, source: str) -> None:
        self.source = source
        self.name = name
        if name not in doc:
            raise ConfigError(f"{source}: missing table [{name}]")
        raw = doc[name]
        if not isinstance(raw, dict):
            raise ConfigError(f"{source}: [{name}] must be a table")
        self.raw: dict[str, Any] = raw
        self.used: set[str] = set()

    def where(self, key: str) -> str:
        return f"{self.source}: [{self.name}] {key}"

    def get(self, key: str) -> Any:
        if key not in self.raw:
            raise ConfigError(f"{self.where(key)}: missing key")
        self.used.add(key)
        return self.raw[key]

    def number(self, key: str, lo: float | None = None, hi: float | None = None, *,
               lo_open: bool = False) -> float:
        """A finite real in [lo, hi] (or (lo, hi] with lo_open)."""
        v = self.get(key)
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(f"{self.where(key)}: must be a number; got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise ConfigError(f"{self.where(key)}: must be finite; got {v!r}")
        if lo is not None and (v <= lo if lo_open else v < lo):
            op = ">" if lo_open else "≥"
            raise ConfigError(f"{self.where(key)}: must be {op} {lo:g}; got {v:g}")
        if hi is not None and v > hi:
            raise ConfigError(f"{self.where(key)}: must be ≤ {hi:g}; got {v:g}")
        return v

    def integer(self, key: str, lo: int, hi: int) -> int:
        v = self.get(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{self.where(key)}: must be an integer; got {v!r}")
        if not lo <= v <= hi:
            raise ConfigError(f"{self.where(key)}: must be in [{lo}, {hi}]; got {v}")
        return v

    def optional_rate(self, key: str, rates: tuple[int, ...], default: int) -> int:
        """An optional integer that must be one of `rates` (`default` when absent)."""
        if key not in self.raw:
            return default
        v = self.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or v not in rates:
            raise ConfigError(f"{self.where(key)}: must be one of "
                              f"{', '.join(map(str, rates))} (baud); got {v!r}")
        return v

    def boolean(self, key: str) -> bool:
        v = self.get(key)
        if not isinstance(v, bool):
            raise ConfigError(f"{self.where(key)}: must be true or false; got {v!r}")
        return v

    def choice(self, key: str, options: tuple[str, ...]) -> str:
        v = self.get(key)
        if v not in options:
            raise ConfigError(f"{self.where(key)}: must be one of {', '.join(options)}; "
                              f"got {v!r}")
        return str(v)

    def pair(self, key: str, lo: float, hi: float) -> tuple[float, float]:
        v = self.get(key)
        if (not isinstance(v, list) or len(v) != 2
                or any(isinstance(x, bool) or not isinstance(x, int | float) for x in v)):
            raise ConfigError(f"{self.where(key)}: must be a list of two numbers; got {v!r}")
        for x in v:
            if not lo <= x <= hi:
                raise ConfigError(f"{self.where(key)}: values must be in [{lo:g}, {hi:g}]; "
                                  f"got {v!r}")
        return float(v[0]), float(v[1])

    def done(self) -> None:
        extra = sorted(set(self.raw) - self.used)
        if extra:
            raise ConfigError(f"{self.source}: [{self.name}] unknown key(s): {', '.join(extra)}"
                              + did_you_mean(extra, self.used))


KNOWN_TABLES = ("geometry", "motors", "kinematics", "motion", "laser", "serial", "tool", "pen",
                "text", "joints")
#: `[text]` keys naming the font of each CSS generic family (TOML keys cannot hold "-").
GENERIC_KEYS = {"serif": "serif", "sans_serif": "sans-serif", "cursive": "cursive",
                "fantasy": "fantasy", "monospace": "monospace"}
TOOLS = ("pen", "laser")
#: Pulse range a hobby servo takes (the firmware refuses others).
SERVO_RANGE_US = (500, 2500)


def _parse_pen(doc: dict[str, Any], source: str) -> tuple[str, Pen | None]:
    """The `[tool] kind` ("pen" when a `[pen]` table is given, else "laser") and the pen."""
    kind = "pen" if "pen" in doc else "laser"
    if "tool" in doc:
        t = _Table(doc, "tool", source)
        kind = t.choice("kind", TOOLS)
        t.done()
    if kind == "laser":
        if "pen" in doc:
            raise ConfigError(f"{source}: [pen]: a pen table on a laser profile ([tool] kind "
                              "= \"laser\"); remove it or set kind = \"pen\"")
        return kind, None
    p = _Table(doc, "pen", source)
    lo, hi = SERVO_RANGE_US
    smin = p.integer("servo_min_us", lo, hi)
    smax = p.integer("servo_max_us", lo, hi)
    if smax <= smin:
        raise ConfigError(f"{p.where('servo_max_us')}: must be > servo_min_us ({smin}); "
                          f"got {smax}")
    pos = {k: p.number(k, 0.0, 100.0) for k in ("up_position", "down_position")}
    rates = {k: p.number(k, 0.0, 1e6, lo_open=True) for k in ("up_rate", "down_rate")}
    delays = {k: p.integer(k, 0, 10_000) for k in ("up_delay_ms", "down_delay_ms")}
    z = p.number("z_threshold_mm", -1e4, 1e4)
    width = p.number("width_mm", 0.0, 100.0, lo_open=True) if "width_mm" in p.raw else 0.5
    p.done()
    if pos["up_position"] == pos["down_position"]:
        raise ConfigError(f"{p.where('down_position')}: must differ from up_position")
    return kind, Pen(smin, smax, pos["up_position"], pos["down_position"], rates["up_rate"],
                     rates["down_rate"], delays["up_delay_ms"], delays["down_delay_ms"], z,
                     width)


def _parse_text(doc: dict[str, Any], source: str) -> TextConfig:
    """The `[text]` table (optional; docs/text.md): the font of each generic family, the
    default family, the fallback face, more names (`aliases`) and `font_dirs`. Every name
    must resolve to a bundled font or an existing SVG font file."""
    if "text" not in doc:
        return TextConfig(source=source)
    t = _Table(doc, "text", source)
    base = TextConfig()

    def text_key(key: str, default: str) -> str:
        if key not in t.raw:
            return default
        v = t.get(key)
        if not isinstance(v, str):
            raise ConfigError(f"{t.where(key)}: must be a string; got {v!r}")
        return v

    generic = {g: text_key(k, base.generic[g]) for k, g in GENERIC_KEYS.items()}
    aliases = t.get("aliases") if "aliases" in t.raw else {}
    dirs = t.get("font_dirs") if "font_dirs" in t.raw else []
    if not isinstance(aliases, dict) or not all(isinstance(v, str) for v in aliases.values()):
        raise ConfigError(f"{t.where('aliases')}: must be a table of names to fonts; got "
                          f"{aliases!r}")
    if not isinstance(dirs, list) or not all(isinstance(v, str) for v in dirs):
        raise ConfigError(f"{t.where('font_dirs')}: must be a list of directories; got {dirs!r}")
    cfg = TextConfig(generic, text_key("fallback", base.fallback),
                     text_key("default", base.default), dict(aliases), tuple(dirs), source)
    t.done()
    lib = FontLibrary(cfg)
    names = [(k, generic[g]) for k, g in GENERIC_KEYS.items()] + [
        ("default", cfg.default), ("fallback", cfg.fallback)] + [
        (f"aliases.{k}", v) for k, v in cfg.aliases.items()]
    for key, name in names:
        try:
            ok = not name or lib.known(name)
        except InputError as e:
            raise ConfigError(f"{t.where(key)}: {e.detail}") from e
        if not ok:
            raise ConfigError(f"{t.where(key)} = {name!r} names no bundled font, [text] alias or "
                              "SVG font file (docs/text.md lists the names)")
    return cfg


def require_tool(profile: Profile, laser: bool) -> None:
    """Refuse a laser job on a pen machine (its laser output drives no laser)."""
    if laser and profile.tool == "pen":
        raise ConfigError(f"{profile.source}: --laser refused: this profile's tool is a pen "
                          "([tool] kind = \"pen\"), the machine has no laser to burn with")


def with_pen_overrides(profile: Profile, values: dict[str, Any]) -> Profile:
    """The profile with the job's pen options (`pen_*` values that are not None) applied,
    checked as the profile's own values would be."""
    given: dict[str, Any] = {k[4:]: v for k, v in values.items()
                             if k.startswith("pen_") and v is not None}
    for key in ("up_delay_ms", "down_delay_ms"):
        if key in given:
            given[key] = round(given[key])
    if not given:
        return profile
    if profile.pen is None:
        raise ConfigError(f"{profile.source}: pen options given, but the profile has no [pen] "
                          "table (its tool is a laser)")
    import dataclasses

    pen = dataclasses.replace(profile.pen, **given)
    if pen.up_position == pen.down_position:
        raise ConfigError("pen up and down positions must differ")
    return dataclasses.replace(profile, pen=pen)


def did_you_mean(names: list[str], known: Iterable[str]) -> str:
    """" (did you mean 'x'?)" for the first misspelt name close to a known one, else ""."""
    pool = {k.lower(): k for k in sorted(known)}
    for name in names:
        close = difflib.get_close_matches(name.lower(), list(pool), n=1, cutoff=0.6)
        if close:
            return f" (did you mean {pool[close[0]]!r} for {name!r}?)"
    return ""


def _parse_geometry(doc: dict[str, Any], source: str) -> FiveBar:
    """`[geometry]`: five lengths and the pen's `extension` on b1 beyond the joint, turned by
    `extension_angle_deg` from R1→joint (then a `kinematics.extension.ExtendedFiveBar`)."""
    g = _Table(doc, "geometry", source)
    lengths = {k: g.number(k, 0.0, 1e5, lo_open=True) for k in ("a1", "b1", "a2", "b2", "w")}
    ext, ang = (g.number(k, lo, hi) if k in g.raw else 0.0 for k, lo, hi in
                (("extension", 0.0, 1e5), ("extension_angle_deg", -180.0, 180.0)))
    g.done()
    try:
        if ext > 0.0:
            return ExtendedFiveBar(**lengths, extension=ext, extension_angle=math.radians(ang))
        return FiveBar(**lengths)
    except ValueError as e:
        raise ConfigError(f"{source}: [geometry]: {e}") from e


def parse_profile(doc: dict[str, Any], source: str = "<profile>") -> Profile:
    """Validate a parsed TOML document into a `Profile`."""
    unknown = sorted(set(doc) - set(KNOWN_TABLES))
    if unknown:
        raise ConfigError(f"{source}: unknown table(s): {', '.join(unknown)} "
                          f"(known: {', '.join(KNOWN_TABLES)})"
                          + did_you_mean(unknown, KNOWN_TABLES))

    geometry = _parse_geometry(doc, source)

    m = _Table(doc, "motors", source)
    full_steps = m.integer("full_steps", 1, 100_000)
    microsteps = m.integer("microsteps", 1, 256)
    gear_ratio = m.number("gear_ratio", 0.0, 1000.0, lo_open=True)
    home = m.pair("home_deg", -360.0, 360.0)
    lims_raw = m.get("limits_deg")
    if not (isinstance(lims_raw, list) and len(lims_raw) == 2):
        raise ConfigError(f"{m.where('limits_deg')}: must be [[lo1, hi1], [lo2, hi2]] in "
                          f"degrees; got {lims_raw!r}")
    lims: list[tuple[float, float]] = []
    for i, lim in enumerate(lims_raw):
        if (not isinstance(lim, list) or len(lim) != 2
                or any(isinstance(x, bool) or not isinstance(x, int | float) for x in lim)):
            raise ConfigError(f"{m.where('limits_deg')}[{i}]: must be [lo, hi]; got {lim!r}")
        lo, hi = float(lim[0]), float(lim[1])
        if not (-360.0 <= lo < hi <= 360.0 and hi - lo <= 360.0):
            raise ConfigError(f"{m.where('limits_deg')}[{i}]: need -360 ≤ lo < hi ≤ 360 and "
                              f"hi − lo ≤ 360; got {lim!r}")
        if not lo <= home[i] <= hi:
            raise ConfigError(f"{m.where('home_deg')}[{i}] = {home[i]:g} lies outside "
                              f"limits_deg[{i}] = [{lo:g}, {hi:g}]")
        lims.append((math.radians(lo), math.radians(hi)))
    endstops = m.boolean("endstops")
    lash = m.pair("backlash_steps", 0, 10_000) if "backlash_steps" in m.raw else (0.0, 0.0)
    if any(v != int(v) for v in lash):
        raise ConfigError(f"{m.where('backlash_steps')}: must be whole steps; got {lash!r}")
    m.done()
    motors = Motors(full_steps, microsteps, gear_ratio,
                    (math.radians(home[0]), math.radians(home[1])),
                    (lims[0], lims[1]), endstops, (int(lash[0]), int(lash[1])))

    k = _Table(doc, "kinematics", source)
    kin = KinematicsCfg(
        k.choice("working_mode", (*WORKING_MODES, "auto")),
        k.choice("assembly", ASSEMBLY_MODES),
        math.radians(k.number("min_type1_margin_deg", 0.0, 89.0)),
        math.radians(k.number("min_type2_margin_deg", 0.0, 89.0)),
    )
    k.done()
    home_fk = geometry.forward_batch(np.array([motors.home_rad]), kin.assembly)
    if not home_fk.valid[0]:
        raise ConfigError(f"{m.where('home_deg')} = [{home[0]:g}, {home[1]:g}]: the floating "
                          "links cannot close the loop at the homed pose (elbows too far "
                          "apart or too close for b1 and b2)")
    if geometry.assembly_of(np.array([motors.home_rad]), home_fk.points)[0] == 0:
        raise ConfigError(f"{m.where('home_deg')} = [{home[0]:g}, {home[1]:g}]: the homed pose "
                          "is a type-2 singularity (floating links collinear); its assembly "
                          "mode is undefined")

    mo = _Table(doc, "motion", source)
    motion = Motion(
        mo.number("draw_feed_mm_s", 0.0, 10_000.0, lo_open=True),
        mo.number("travel_feed_mm_s", 0.0, 10_000.0, lo_open=True),
        mo.number("max_joint_rad_s", 0.0, 1_000.0, lo_open=True),
        mo.number("max_joint_rad_s2", 0.0, 1e6, lo_open=True),
        mo.number("tolerance_mm", 1e-4, 10.0),
        mo.number("junction_jump_rad_s", 0.0, 1_000.0, lo_open=True)
        if "junction_jump_rad_s" in mo.raw else 0.5,
    )
    mo.done()

    la = _Table(doc, "laser", source)
    laser = Laser(
        la.integer("power", 0, 255),
        la.choice("on_command", ("M3", "M4")),
        la.boolean("off_between_paths"),
        la.number("silence_timeout_s", 0.0, 3600.0, lo_open=True),
        la.number("spot_mm", 0.0, 100.0, lo_open=True) if "spot_mm" in la.raw else 0.1,
    )
    la.done()

    se = _Table(doc, "serial", source)
    serial = SerialCfg(
        se.integer("baud", 300, 4_000_000),
        se.number("banner_timeout_s", 0.0, 600.0, lo_open=True),
        se.number("reply_timeout_s", 0.0, 600.0, lo_open=True),
        # the rates the Uno's 16 MHz makes: 115200 (-0.8 %), 250000, 500000, 1000000 (exact)
        se.optional_rate("link_baud", BAUD_RATES, BASE_BAUD),
    )
    se.done()
    tool, pen = _parse_pen(doc, source)
    try:
        joints = parse_joints(_Table(doc, "joints", source) if "joints" in doc else None)
        if joints is not None:  # a servo's dead band is its slack (fivebar_host/joints.py)
            motors = replace(motors, backlash_steps=servo_backlash_steps(joints, motors, source))
    except FivebarError as e:
        raise ConfigError(str(e)) from e
    return Profile(geometry, motors, kin, motion, laser, serial, source, tool, pen,
                   _parse_text(doc, source), joints)



def _read_toml(p: Path) -> dict[str, Any]:
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as e:
        raise ConfigError(f"{p}: cannot read profile: {e.strerror or e}") from e
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: not valid TOML: {e}") from e


def merged_document(path: str | Path | None = None
                    ) -> tuple[dict[str, Any], dict[tuple[str, str], str]]:
    """A profile file over the bundled default: (the merged TOML document, and for each
    (table, key) the file its value came from).

    A partial profile needs only the keys that differ from configs/default.toml; the rest
    are inherited, and `fivebar config show` says which. A key or table the default does
    not have is not inherited: `parse_profile` refuses it (with "did you mean")."""
    base = _read_toml(DEFAULT_PROFILE)
    default_name = str(DEFAULT_PROFILE)
    p = Path(path) if path is not None else DEFAULT_PROFILE
    user = base if p.resolve() == DEFAULT_PROFILE else _read_toml(p)
    merged: dict[str, Any] = {}
    sources: dict[tuple[str, str], str] = {}
    for table in {**base, **user}:
        mine, theirs = user.get(table, {}), base.get(table, {})
        if not isinstance(mine, dict) or not isinstance(theirs, dict):
            merged[table] = mine if table in user else theirs
            continue
        merged[table] = {**theirs, **mine}
        for key in merged[table]:
            sources[(table, key)] = str(p) if key in mine else default_name
    return merged, sources


def load_profile(path: str | Path | None = None) -> Profile:
    """Read and validate a profile file (the bundled default when `path` is None); keys it
    leaves out come from the bundled default (`merged_document`)."""
    p = Path(path) if path is not None else DEFAULT_PROFILE
    doc, _ = merged_document(p)
    return parse_profile(doc, str(p))
