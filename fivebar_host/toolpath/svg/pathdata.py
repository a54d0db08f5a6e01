"""SVG path data (`d`) by the grammar of SVG 2 §9.3.9, into exact primitives in user units.

Written here rather than taken from svgpathtools because a plotter must know *where* path
data goes wrong: svgpathtools reads `L 150#80` as `L 150 80` and a path without a leading
moveto as an arc from (0, 0). The grammar is followed to the letter, including compact number
lists (`1-2`, `.5.5`, `1e-1-1e2`) and arc flags without separators (`a1 1 0 00.5.5`).

Errors (SVG 2 §9.5.4 "Error handling in path data"): the path is rendered up to the last
complete segment before the first error — what browsers and resvg show — and `parse_path`
returns the error (column in `d` and reason) so the reader warns naming the element: nothing
after the error is drawn, nothing is invented. A path whose data does not start with a moveto
therefore draws nothing.

Primitives: LINE (x0 y0 x1 y1), CUBIC (4 control points; quadratics are degree-elevated exactly),
ARC (centre, 2×2 M, θ0, Δθ with E(θ) = c + M·(cos θ, sin θ)); zero-length segments are left out.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from fivebar_host.toolpath.geometry import ARC, CUBIC, LINE
from fivebar_host.toolpath.svg.units import NUMBER

Prim = tuple[int, tuple[float, ...]]
_NUM = re.compile(NUMBER)
_WSP = re.compile(r"[ \t\r\n\f]*")
_COMMA_WSP = re.compile(r"[ \t\r\n\f]*,?[ \t\r\n\f]*")
#: Number of arguments per command.
ARGS = {"m": 2, "l": 2, "h": 1, "v": 1, "c": 6, "s": 4, "q": 4, "t": 2, "a": 7, "z": 0}


def _valid_pattern() -> re.Pattern[str]:
    """Path data without arcs that `parse_path`'s scanner reads to the end without an
    error, in ASCII (where the grammar's digits are 0-9 alone): every number and separator
    an atomic group and every repeat possessive (Python 3.11), so each takes what the
    scanner's own match takes and nothing is given back, in linear time. A separator with
    a comma must be followed by a number; an argument set may repeat without its letter
    (after M/m: as L/l) but not after Z/z; the data must start with a moveto."""
    wsp = r"[ \t\r\n\f]*"
    sep = rf"(?>{wsp},?{wsp})"
    after = rf"(?>{wsp}(?:,{wsp}(?=[+\-.0-9]))?)"  # after a set: a comma needs a number
    number = rf"(?>{NUMBER})"

    def sets(n: int) -> str:
        return rf"(?:{sep.join([number] * n)}{after})++"

    block = (rf"(?:[MmLlTt]{wsp}{sets(2)}|[HhVv]{wsp}{sets(1)}|[Cc]{wsp}{sets(6)}"
             rf"|[SsQq]{wsp}{sets(4)}|[Zz]{wsp})")
    return re.compile(rf"{wsp}(?:[Mm]{wsp}{sets(2)}{block}*+)?")


#: Argument sets after the first of a moveto are linetos.
_IMPLICIT = {"M": "L", "m": "l"}
#: `_valid_pattern`, and the tokens (command letters and numbers) of such data.
_VALID = _valid_pattern()
_TOKEN = re.compile(rf"[MmLlHhVvCcSsQqTtZz]|{NUMBER}")


class PathDataError(Exception):
    """Where (0-based index into `d`) and why the path data stops being valid."""

    def __init__(self, pos: int, reason: str) -> None:
        super().__init__(reason)
        self.pos = pos
        self.reason = reason


@dataclass
class PathResult:
    """Subpaths (pen-down runs) of one path, and the first error if the data has one."""

    subpaths: list[list[Prim]]
    error: PathDataError | None = None


class _State:
    """Current point, subpath start and the last control point (for S and T)."""

    def __init__(self) -> None:
        self.x = self.y = 0.0
        self.sx = self.sy = 0.0
        self.ctrl: tuple[float, float] | None = None  # reflected by S (after C/S)
        self.qctrl: tuple[float, float] | None = None  # reflected by T (after Q/T)
        self.subpaths: list[list[Prim]] = []
        self.cur: list[Prim] = []

    def new_subpath(self) -> None:
        if self.cur:
            self.subpaths.append(self.cur)
        self.cur = []

    def emit(self, prim: Prim) -> None:
        self.cur.append(prim)


class _Scanner:
    def __init__(self, d: str) -> None:
        self.d = d
        self.i = 0

    def wsp(self) -> None:
        m = _WSP.match(self.d, self.i)
        assert m is not None
        self.i = m.end()

    def comma_wsp(self) -> None:
        m = _COMMA_WSP.match(self.d, self.i)
        assert m is not None
        self.i = m.end()

    def number(self) -> float:
        m = _NUM.match(self.d, self.i)
        if not m:
            raise PathDataError(self.i, self._expected("a number"))
        self.i = m.end()
        return float(m.group())  # an overflow (inf) is refused by the coordinate check

    def flag(self) -> float:
        if self.i < len(self.d) and self.d[self.i] in "01":
            self.i += 1
            return float(self.d[self.i - 1])
        raise PathDataError(self.i, self._expected("an arc flag 0 or 1"))

    def starts_number(self) -> bool:
        return self.i < len(self.d) and self.d[self.i] in "+-.0123456789"

    def _expected(self, what: str) -> str:
        if self.i >= len(self.d):
            return f"expected {what}, found the end of the data"
        return f"expected {what}, found {self.d[self.i]!r}"


def parse_path(d: str) -> PathResult:
    """Parse path data; see the module docstring for the error rule. Valid data without
    arcs is read token by token (`_parse_valid`: about twice as fast on large drawings),
    the rest by the scanner, which finds the errors."""
    if d.isascii() and _VALID.fullmatch(d):
        return _parse_valid(d)
    return _scan_path(d)


def _parse_valid(d: str) -> PathResult:
    """`parse_path` on data `_VALID` matches: its tokens are where the scanner reads them
    (numbers by the same pattern, separators between them), each letter followed by whole
    argument sets (none after Z/z), so the sets are applied as the scanner applies them."""
    tokens = _TOKEN.findall(d)
    st = _State()
    cmd, k, i, n = "", 0, 0, len(tokens)
    while i < n:
        t = tokens[i]
        if t.isalpha():
            cmd, k, i = t, ARGS[t.lower()], i + 1
            if not k:  # Z/z
                _close(st)
                continue
        _apply(st, cmd, [float(x) for x in tokens[i:i + k]])
        i += k
        cmd = _IMPLICIT.get(cmd, cmd)
    st.new_subpath()
    return PathResult(st.subpaths)


def _scan_path(d: str) -> PathResult:
    """`parse_path` by the scanner, character by character up to the first error."""
    sc = _Scanner(d)
    st = _State()
    cmd = ""
    try:
        sc.wsp()
        if sc.i < len(d) and d[sc.i] not in "Mm":
            raise PathDataError(sc.i, f"path data must start with a moveto (M or m), "
                                      f"found {d[sc.i]!r}")
        while True:
            sc.wsp()
            if sc.i >= len(d):
                break
            c = d[sc.i]
            if c.lower() in ARGS:
                cmd = c
                sc.i += 1
                sc.wsp()
            elif not (cmd and cmd.lower() != "z" and sc.starts_number()):
                raise PathDataError(sc.i, f"unexpected {c!r}")
            _command(sc, st, cmd)
            cmd = {"M": "L", "m": "l"}.get(cmd, cmd)  # later pairs are implicit linetos
    except PathDataError as e:
        st.new_subpath()
        return PathResult(st.subpaths, e)
    st.new_subpath()
    return PathResult(st.subpaths)


def _command(sc: _Scanner, st: _State, cmd: str) -> None:
    """One argument set of a command, and the separator after it."""
    low = cmd.lower()
    if low == "z":
        _close(st)
        return
    args: list[float] = []
    for k in range(ARGS[low]):
        if k:
            sc.comma_wsp()
        args.append(sc.flag() if low == "a" and k in (3, 4) else sc.number())
    m0 = sc.i
    sc.comma_wsp()
    if "," in sc.d[m0:sc.i] and not sc.starts_number():
        raise PathDataError(sc.i, "a comma must be followed by a number")
    _apply(st, cmd, args)


def _close(st: _State) -> None:
    """Z/z: a line back to the subpath's start, which becomes the current point."""
    _line(st, st.sx, st.sy)
    st.x, st.y = st.sx, st.sy
    st.ctrl = st.qctrl = None


def _apply(st: _State, cmd: str, a: list[float]) -> None:
    rel = cmd.islower()
    ox, oy = (st.x, st.y) if rel else (0.0, 0.0)
    low = cmd.lower()
    prev_c, prev_q = st.ctrl, st.qctrl
    st.ctrl = st.qctrl = None
    if low == "m":
        st.new_subpath()
        st.x, st.y = ox + a[0], oy + a[1]
        st.sx, st.sy = st.x, st.y
    elif low == "l":
        _line(st, ox + a[0], oy + a[1])
    elif low == "h":
        _line(st, (st.x if rel else 0.0) + a[0], st.y)
    elif low == "v":
        _line(st, st.x, (st.y if rel else 0.0) + a[0])
    elif low in ("c", "s"):
        if low == "c":
            c1 = (ox + a[0], oy + a[1])
            a = a[2:]
        else:
            c1 = (2 * st.x - prev_c[0], 2 * st.y - prev_c[1]) if prev_c else (st.x, st.y)
        _cubic(st, c1, (ox + a[0], oy + a[1]), (ox + a[2], oy + a[3]))
    elif low in ("q", "t"):
        if low == "q":
            q = (ox + a[0], oy + a[1])
            a = a[2:]
        else:
            q = (2 * st.x - prev_q[0], 2 * st.y - prev_q[1]) if prev_q else (st.x, st.y)
        _quad(st, q, (ox + a[0], oy + a[1]))
    else:
        _arc(st, a[0], a[1], a[2], a[3] != 0, a[4] != 0, ox + a[5], oy + a[6])


def _line(st: _State, x: float, y: float) -> None:
    if (x, y) != (st.x, st.y):
        st.emit((LINE, (st.x, st.y, x, y)))
    st.x, st.y = x, y


def _cubic(st: _State, c1: tuple[float, float], c2: tuple[float, float],
           p: tuple[float, float]) -> None:
    s = (st.x, st.y)
    if not (s == c1 == c2 == p):
        st.emit((CUBIC, (*s, *c1, *c2, *p)))
    st.ctrl = c2
    st.x, st.y = p


def _quad(st: _State, q: tuple[float, float], p: tuple[float, float]) -> None:
    s = (st.x, st.y)
    if not (s == q == p):
        # Exact degree elevation: c1 = s + 2/3 (q − s), c2 = p + 2/3 (q − p).
        c1 = (s[0] + (q[0] - s[0]) * 2 / 3, s[1] + (q[1] - s[1]) * 2 / 3)
        c2 = (p[0] + (q[0] - p[0]) * 2 / 3, p[1] + (q[1] - p[1]) * 2 / 3)
        st.emit((CUBIC, (*s, *c1, *c2, *p)))
    st.qctrl = q
    st.x, st.y = p


def _arc(st: _State, rx: float, ry: float, phi_deg: float, large: bool, sweep: bool,
         x: float, y: float) -> None:
    """Endpoint → centre parameterisation, SVG 2 Appendix B.2.4 (radii scaled up when too
    small, B.2.5); rx or ry zero → a line; equal end points → omitted."""
    x1, y1 = st.x, st.y
    if (x1, y1) == (x, y):
        return
    rx, ry = abs(rx), abs(ry)
    if rx == 0 or ry == 0:
        _line(st, x, y)
        return
    phi = math.radians(phi_deg % 360.0)
    cp, sp = math.cos(phi), math.sin(phi)
    dx, dy = (x1 - x) / 2, (y1 - y) / 2
    x1p, y1p = cp * dx + sp * dy, -sp * dx + cp * dy
    ux, uy = x1p / rx, y1p / ry
    lam = ux * ux + uy * uy
    if lam > 1:
        rx, ry = rx * math.sqrt(lam), ry * math.sqrt(lam)
    a2, b2 = (rx * y1p) * (rx * y1p), (ry * x1p) * (ry * x1p)
    num, den = (rx * ry) * (rx * ry) - a2 - b2, a2 + b2
    k = math.sqrt(max(num, 0.0) / den) if den > 0 else 0.0
    if large == sweep:
        k = -k
    cxp, cyp = k * rx * y1p / ry, -k * ry * x1p / rx
    cx = cp * cxp - sp * cyp + (x1 + x) / 2
    cy = sp * cxp + cp * cyp + (y1 + y) / 2
    th0 = math.atan2((y1p - cyp) / ry, (x1p - cxp) / rx)
    th1 = math.atan2((-y1p - cyp) / ry, (-x1p - cxp) / rx)
    dth = th1 - th0
    if sweep and dth < 0:
        dth += 2 * math.pi
    elif not sweep and dth > 0:
        dth -= 2 * math.pi
    if not all(map(math.isfinite, (cx, cy, rx, ry, th0, dth))):
        _line(st, x, y)  # overflowing radii: the arc is a line for any finite view
        return
    # point(θ) = c + R(φ)·diag(rx, ry)·(cos θ, sin θ)
    st.emit((ARC, (cx, cy, rx * cp, -ry * sp, rx * sp, ry * cp, th0, dth)))
    st.x, st.y = x, y
