"""What the bridge reports, shaped as GRBL 1.1 reports it (doc/markdown/interface.md of
GRBL): the status report, `$$` settings, `$G` parser state, `$#` parameters, `$I` build info.

Settings (`Settings`) are GRBL's numbers. Those that mean something for a five-bar are
mapped (`MAPPED`); the rest are kept as written and shown back by `$$`, with no effect on the
machine (`STORED`): a settings file a sender pushes is accepted, and none of it reaches the
firmware's own `$` settings, whose numbers mean other things.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from fivebar_host.gcode import MM_PER_INCH, WCS_NAMES, ModalState, Vec

VERSION = "1.1h"
BANNER = f"Grbl {VERSION} ['$' for help]"
BUILD_DATE = "20190830"
PLANNER_BLOCKS = 15
RX_BUFFER = 128
HELP = "[HLP:$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x]"

#: GRBL settings and their defaults: (number, default, integer?).
DEFAULTS: dict[int, float] = {
    0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0,
    20: 1, 21: 0, 22: 0, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0, 30: 1000, 31: 0,
    32: 0, 100: 250.0, 101: 250.0, 102: 250.0, 110: 500.0, 111: 500.0, 112: 500.0,
    120: 10.0, 121: 10.0, 122: 10.0, 130: 200.0, 131: 200.0, 132: 200.0,
}
INTEGER = frozenset({0, 1, 2, 3, 4, 5, 6, 10, 13, 20, 21, 22, 23, 26, 32})
BOOLEAN = frozenset({4, 5, 6, 13, 20, 21, 22, 32})
#: Settings with a meaning on the bridge (docs/grbl.md says what each does).
MAPPED = {
    10: "status report: bit 0 MPos (1) or WPos (0); bit 1 buffer state (Bf:)",
    13: "report positions in inches",
    20: "soft limits: shown as written; reach, joint-limit and singularity checks always run",
    22: "homing: $H is allowed when on and the profile has endstops",
    30: "S value of full laser power",
    31: "S value below which the laser is off",
    32: "laser mode: M4 scales power with speed (always off on non-drawing moves)",
    110: "X max rate, mm/min: caps the pen feed",
    111: "Y max rate, mm/min: caps the pen feed",
}
STORED = frozenset(DEFAULTS) - frozenset(MAPPED)


@dataclass
class Settings:
    """GRBL's `$` settings as the bridge keeps them (not persistent, like the firmware's)."""

    values: dict[int, float] = field(default_factory=lambda: dict(DEFAULTS))
    startup: list[str] = field(default_factory=lambda: ["", ""])
    build_info: str = ""

    def listing(self) -> list[str]:
        return [f"${n}={_fmt_setting(n, v)}" for n, v in sorted(self.values.items())]

    def feed_cap_mm_min(self) -> float:
        return min(self.values[110], self.values[111])


def _fmt_setting(n: int, v: float) -> str:
    return str(int(v)) if n in INTEGER else f"{v:.3f}"


def fmt_vec(v: Vec, inches: bool = False) -> str:
    s = 1 / MM_PER_INCH if inches else 1.0
    return ",".join(f"{c * s:.4f}" if inches else f"{c * s:.3f}" for c in v)


def parser_state(st: ModalState) -> str:
    """`$G`: `[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]` (G codes are kept as tenths)."""
    cool = " ".join(f"M{c}" for c in sorted(st.coolant)) or "M9"
    feed = st.feed / (MM_PER_INCH if st.units == 200 else 1.0)
    return (f"[GC:G{st.motion // 10} {WCS_NAMES[st.wcs]} G{st.plane // 10} "
            f"G{st.units // 10} G{st.distance // 10} G{st.feed_mode // 10} M{st.spindle} "
            f"{cool} T{st.tool} F{feed:g} S{st.s:g}]")


def parameters(st: ModalState, inches: bool) -> list[str]:
    """`$#`: the coordinate systems, G28/G30, G92, tool length offset and probe."""
    out = [f"[{name}:{fmt_vec(off, inches)}]" for name, off in zip(WCS_NAMES, st.offsets,
                                                                    strict=True)]
    out += [f"[G28:{fmt_vec(st.g28, inches)}]", f"[G30:{fmt_vec(st.g30, inches)}]",
            f"[G92:{fmt_vec(st.g92, inches)}]", "[TLO:0.000]", "[PRB:0.000,0.000,0.000:0]"]
    return out


def build_info(settings: Settings) -> list[str]:
    """`$I`: version line and compile options (V: variable spindle, laser mode)."""
    return [f"[VER:{VERSION}.{BUILD_DATE}:{settings.build_info}]",
            f"[OPT:V,{PLANNER_BLOCKS},{RX_BUFFER}]"]


@dataclass
class StatusView:
    """Builds `<...>` reports; WCO and Ov appear as GRBL 1.1 shows them: in the first report,
    when they change, and every `WCO_EVERY` / `OV_EVERY` reports otherwise."""

    WCO_EVERY = 10
    OV_EVERY = 10
    wco_count: int = 0
    ov_count: int = 0
    last_wco: Vec | None = None
    last_ov: tuple[int, int, int] | None = None

    def reset(self) -> None:
        self.wco_count = self.ov_count = 0
        self.last_wco = self.last_ov = None

    def report(self, state: str, mpos: Vec, wco: Vec, settings: Settings, bf: tuple[int, int],
               fs: tuple[float, float], ov: tuple[int, int, int],
               accessories: str) -> str:
        """One status report (GRBL 1.1 field order: state, position, Bf, FS, WCO, Ov, A)."""
        mask = int(settings.values[10])
        inches = bool(settings.values[13])
        if mask & 1:
            parts = [state, f"MPos:{fmt_vec(mpos, inches)}"]
        else:
            parts = [state, "WPos:" + fmt_vec((mpos[0] - wco[0], mpos[1] - wco[1],
                                                mpos[2] - wco[2]), inches)]
        if mask & 2:
            parts.append(f"Bf:{bf[0]},{bf[1]}")
        scale = 1 / MM_PER_INCH if inches else 1.0
        parts.append(f"FS:{fs[0] * scale:.0f},{fs[1]:.0f}")
        self.wco_count -= 1
        if self.last_wco != wco or self.wco_count <= 0:
            parts.append(f"WCO:{fmt_vec(wco, inches)}")
            self.last_wco, self.wco_count = wco, self.WCO_EVERY
        else:
            self.ov_count -= 1
            if self.last_ov != ov or self.ov_count <= 0:
                parts.append(f"Ov:{ov[0]},{ov[1]},{ov[2]}")
                if accessories:
                    parts.append(f"A:{accessories}")
                self.last_ov, self.ov_count = ov, self.OV_EVERY
        return "<" + "|".join(parts) + ">"
