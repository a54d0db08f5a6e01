"""An independent reading of 2-D G-code for the corpus test: written for the tests from the
RS274NGC/GRBL documentation, sharing no code with `fivebar_host.gcode`, so that fivebar's
geometry is checked against a second interpreter rather than against itself.

It follows the same *meaning* of a file as fivebar's reader documents (docs/gcode.md): a
G1/G2/G3 draws when the tool is on — in a file with M3/M4, M3/M4 with S > 0 (or with no S
word at all once a Z word was read), and the pen down by Z (work Z ≤ 0) or by `M300`
(the Unicorn plug-in's S30 down / S50 up); in a file without M3/M4, every G1/G2/G3 whose
pen is not up. Words of the skipped classes are ignored here by a plain list, stops and
home moves end the stroke. Only what the corpus needs is read: G0–G3 (I/J and R arcs),
G17, G20/G21, G90/G91, G92 (X/Y/Z), G28, M2/M30, M3/M4/M5, S, Z.

`reference(path)` → the drawn pieces as (kind, data): ("line", (x0, y0, x1, y1)) or ("arc",
(cx, cy, r, a0, sweep)), with `length` and `box` of a list of pieces.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

Piece = tuple[str, tuple[float, ...]]
_TOKEN = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+))")


def _words(line: str) -> list[tuple[str, float]]:
    """The words of a line with `;` and `( … )` comments dropped."""
    line = re.sub(r"\([^)]*\)", " ", line.split(";", 1)[0])
    if line.strip().startswith(("$", "?", "~", "%")):
        return []
    if re.match(r"\s*(N\d+\s*)?M0*11[78]\b", line, re.IGNORECASE):
        return []
    return [(m.group(1).upper(), float(m.group(2))) for m in _TOKEN.finditer(line)]


def reference(path: Path) -> list[Piece]:
    """The drawn pieces of a G-code file (module doc)."""
    text = path.read_text(encoding="utf-8-sig")
    lines = text.splitlines()
    has_m34 = any(re.search(r"(?<![A-Za-z])M0*[34](?![\d.])", re.sub(r"\([^)]*\)", "",
                                                                  s.split(";")[0]), re.I)
                  for s in lines)
    servo = any(re.search(r"M0*300\b(?!.*P\d)", s.split(";")[0].split("(")[0], re.I)
                for s in lines)
    x = y = z = 0.0
    ox = oy = oz = 0.0  # G92 offsets: machine = work + offset
    scale, absolute, motion = 1.0, True, None
    spindle_on, s_val, s_given, z_seen = False, 0.0, False, False
    pen_down: bool | None = None
    out: list[Piece] = []
    for raw in lines:
        ws = _words(raw)
        if not ws:
            continue
        g = [v for k, v in ws if k == "G"]
        m = [v for k, v in ws if k == "M"]
        val = {k: v for k, v in ws if k not in "GMN"}
        if 20 in g:
            scale = 25.4
        if 21 in g:
            scale = 1.0
        if 90 in g:
            absolute = True
        if 91 in g:
            absolute = False
        if "S" in val and 300 not in m:
            s_val, s_given = val["S"], True
        if 3 in m or 4 in m:
            spindle_on = True
        if 5 in m:
            spindle_on = False
        if 300 in m and servo:
            pen_down = val.get("S") == 30.0
            continue
        if 2 in m or 30 in m:
            break
        if 92 in g:
            if "X" in val:
                ox = x - val["X"] * scale
            if "Y" in val:
                oy = y - val["Y"] * scale
            if "Z" in val:
                oz = z - val["Z"] * scale
            continue
        if 28 in g or 30 in g:
            x, y = 0.0, 0.0
            pen_down = False if (z_seen or servo) else pen_down
            continue
        if 4 in g:
            continue
        for code in g:
            if code in (0, 1, 2, 3):
                motion = int(code)
        nx, ny, nz = x, y, z
        if "X" in val:
            nx = val["X"] * scale + (ox if absolute else x)
        if "Y" in val:
            ny = val["Y"] * scale + (oy if absolute else y)
        if "Z" in val and not servo:
            nz = val["Z"] * scale + (oz if absolute else z)
            z_seen = True
            pen_down = nz - oz <= 0.0
        arc_words = "I" in val or "J" in val or "R" in val
        if not ("X" in val or "Y" in val or (motion in (2, 3) and arc_words)):
            x, y, z = nx, ny, nz
            continue
        on = motion in (1, 2, 3) and pen_down is not False
        if has_m34:
            on = on and spindle_on and (s_val > 0 or (z_seen and not s_given))
        if on and motion == 1 and (nx, ny) != (x, y):
            out.append(("line", (x, y, nx, ny)))
        elif on and motion in (2, 3):
            out.append(("arc", _arc(x, y, nx, ny, val, scale, motion == 2)))
        x, y, z = nx, ny, nz
    return out


def _arc(x: float, y: float, nx: float, ny: float, val: dict[str, float], scale: float,
         cw: bool) -> tuple[float, ...]:
    """(cx, cy, r, a0, sweep) of a G2/G3 from (x, y) to (nx, ny)."""
    if "R" in val:
        r = val["R"] * scale
        dx, dy = nx - x, ny - y
        d = math.hypot(dx, dy)
        h = math.sqrt(max(r * r - d * d / 4, 0.0))
        mx, my = (x + nx) / 2, (y + ny) / 2
        # left of the chord for a short CCW arc, right for a short CW one; R < 0: the long way
        sign = (1 if not cw else -1) * (1 if r > 0 else -1)
        cx, cy = mx - sign * h * dy / d, my + sign * h * dx / d
        r = abs(r)
    else:
        cx, cy = x + val.get("I", 0.0) * scale, y + val.get("J", 0.0) * scale
        r = math.hypot(x - cx, y - cy)
    a0 = math.atan2(y - cy, x - cx)
    sweep = math.atan2(ny - cy, nx - cx) - a0
    if cw:
        while sweep >= 0:
            sweep -= 2 * math.pi
    else:
        while sweep <= 0:
            sweep += 2 * math.pi
    return (cx, cy, r, a0, sweep)


def length(pieces: list[Piece]) -> float:
    """The drawn length, mm: lines exact, arcs r·|sweep|."""
    total = 0.0
    for kind, d in pieces:
        total += math.hypot(d[2] - d[0], d[3] - d[1]) if kind == "line" else d[2] * abs(d[4])
    return total


def box(pieces: list[Piece]) -> tuple[float, float, float, float]:
    """The exact bounding box: end points, and each arc's points at 0°, 90°, 180°, 270°
    that its sweep passes."""
    xs: list[float] = []
    ys: list[float] = []
    for kind, d in pieces:
        if kind == "line":
            xs += [d[0], d[2]]
            ys += [d[1], d[3]]
            continue
        cx, cy, r, a0, sweep = d
        for a in (a0, a0 + sweep):
            xs.append(cx + r * math.cos(a))
            ys.append(cy + r * math.sin(a))
        for k in range(4):
            phi = k * math.pi / 2
            ahead = ((phi - a0) if sweep > 0 else (a0 - phi)) % (2 * math.pi)
            if ahead <= abs(sweep):
                xs.append(cx + r * math.cos(phi))
                ys.append(cy + r * math.sin(phi))
    return min(xs), min(ys), max(xs), max(ys)
