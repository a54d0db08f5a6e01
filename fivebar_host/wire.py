"""The wire: the one writer of the motion lines the host sends, and the one model of their bytes.

A compiled job travels as a typed `Program` (`fivebar_host.program`: records, not text) until it
is written; this module turns items into text, and nothing else in the host writes a `G1`,
`G6` or `M280`:

* **fivebar's protocol** (docs/protocol.md 6): `G1 A<steps> B<steps> P<µs> S<power>`, a dwell
  `G1 P<µs> S<power>`, the pen servo's `M280 S<µs> R<ms> D<ms>`, `M3 S0`/`M4 S0`, `M5`,
  `G90`, `$14=<µs>` (`body`, `bodies`); a file for `fivebar convert` (`file_lines`, absolute
  or relative); hand-written lines read back into items (`read_lines`: tests, scripts).
* **G6 packing** (6.3, protocol 3): consecutive moves in one wire line, a `G1` head and
  relative items `[P<µs>]±da±db`, one line number per segment (`pack_line`), and the byte
  model the planner's link floor uses (`item_bytes`, `segment_bytes`) — the same arithmetic
  as the packer's text, checked against it in tests/test_linkrate.py.
* **GRBL's dialect** (docs/grbl.md): the joint-space `G1 X<deg> Y<deg> F<deg/min>` lines,
  tool and dwell lines of `--controller grbl` (`grbl_*`).

Ranges are checked here as the firmware checks them (`ProtocolError`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fivebar_host import protocol
from fivebar_host.program import ABSENT, Kind, Program
from fivebar_host.protocol import (
    P_MAX_US,
    P_MIN_US,
    PEN_MS_MAX,
    POS_LIMIT,
    POWER_MAX,
    SERVO_MAX_US,
    SERVO_MIN_US,
    ProtocolError,
)
from kinematics.arrays import BoolArray, IntArray


# ------------------------------------------------------------------ fivebar: one line
def g1(a: int | None, b: int | None, p_us: int, s: int | None = None) -> str:
    """The body of a G1 segment (A/B/S left out when None); ProtocolError out of range."""
    if not P_MIN_US <= p_us <= P_MAX_US:
        raise ProtocolError(f"segment duration P{p_us} outside {P_MIN_US}..{P_MAX_US} us")
    words = ["G1"]
    for letter, value in (("A", a), ("B", b)):
        if value is not None:
            if not -POS_LIMIT <= value <= POS_LIMIT:
                raise ProtocolError(f"{letter}{value} outside +-{POS_LIMIT} steps")
            words.append(f"{letter}{value}")
    words.append(f"P{p_us}")
    if s is not None:
        if not 0 <= s <= POWER_MAX:
            raise ProtocolError(f"laser power S{s} outside 0..{POWER_MAX}")
        words.append(f"S{s}")
    return " ".join(words)


def m280(pulse_us: int, move_ms: int = 0, settle_ms: int = 0) -> str:
    """The body of a pen servo command (docs/protocol.md 6.2): a queued block that moves the
    servo pulse to `pulse_us` over `move_ms`, then keeps the next segment waiting `settle_ms`
    more. Raises ProtocolError for values the firmware refuses."""
    if not SERVO_MIN_US <= pulse_us <= SERVO_MAX_US:
        raise ProtocolError(f"pen pulse S{pulse_us} outside {SERVO_MIN_US}..{SERVO_MAX_US} us")
    for letter, ms in (("R", move_ms), ("D", settle_ms)):
        if not 0 <= ms <= PEN_MS_MAX:
            raise ProtocolError(f"pen {letter}{ms} outside 0..{PEN_MS_MAX} ms")
    words = [f"M280 S{pulse_us}"]
    if move_ms:
        words.append(f"R{move_ms}")
    if settle_ms:
        words.append(f"D{settle_ms}")
    return " ".join(words)


def _word(v: int) -> int | None:
    return None if v == ABSENT else v


def body(prog: Program, i: int, p_us: int | None = None, s: int | None = None) -> str:
    """Item `i` as a line body; `p_us`/`s` replace the record's values (overrides)."""
    k = int(prog.kind[i])
    p = int(prog.p_us[i]) if p_us is None else p_us
    sv = int(prog.s[i]) if s is None else s
    if k == Kind.MOVE:
        return g1(_word(int(prog.a[i])), _word(int(prog.b[i])), p, _word(sv))
    if k == Kind.DWELL:
        return g1(None, None, p, _word(sv))
    if k == Kind.PEN:
        return m280(sv, int(prog.a[i]), int(prog.b[i]))
    if k == Kind.TOOL_ON:
        return f"M{sv} S0"
    if k == Kind.TOOL_OFF:
        return "M5"
    if k == Kind.ABSOLUTE:
        return "G90"
    if k == Kind.PEN_PARK:
        return f"$14={sv}"
    if k == Kind.TEXT:
        return prog.texts[sv]
    if k == Kind.SET_POSITION:
        words = [f"{n}{v}" for n, v in (("A", int(prog.a[i])), ("B", int(prog.b[i])))
                 if v != ABSENT]
        return " ".join(["G92", *words])
    if k == Kind.RASTER:  # for messages: a G7 line's data is bytes (g7_line writes it)
        run = f" run {sv}" if sv >= 0 else ""
        return f"G7 segment A{int(prog.a[i])} B{int(prog.b[i])} P{p}{run}"
    raise ProtocolError(f"item {i}: unknown kind {k}")


def bodies(prog: Program) -> list[str]:
    """Every item as a line body, in order."""
    return [body(prog, i) for i in range(len(prog))]


def file_lines(prog: Program, relative: bool = False) -> list[str]:
    """A program as the lines of a file (`fivebar convert`): absolute (`G90`, as streamed),
    or relative (`G91`, each move's target as the difference from the one before; the
    program starts at the homed pose, steps 0, 0)."""
    if not relative:
        return bodies(prog)
    pos = prog.positions((0, 0))
    prev = np.concatenate((np.zeros((1, 2), dtype=np.int64), pos[:-1]))
    out = []
    for i in range(len(prog)):
        k = int(prog.kind[i])
        if k == Kind.ABSOLUTE:
            out.append("G91")
        elif k == Kind.MOVE:
            d = pos[i] - prev[i]
            out.append(g1(int(d[0]), int(d[1]), int(prog.p_us[i]), _word(int(prog.s[i]))))
        else:
            out.append(body(prog, i))
    return out


_G1 = re.compile(r"G1(?: A(-?\d+))?(?: B(-?\d+))? P(\d+)(?: S(\d+))?")
_M280 = re.compile(r"M280 S(\d+)(?: R(\d+))?(?: D(\d+))?")
_PARK = re.compile(r"\$14=(\d+)")
_G92 = re.compile(r"G92(?: A(-?\d+))?(?: B(-?\d+))?")


def read_lines(lines: Sequence[str]) -> Program:
    """Line bodies in this module's forms as a program (hand-written programs: tests,
    scripts). A body in another form (`$H`, `M3 S255` …) is a `TEXT` item,
    sent as it is and never packed."""
    rows: list[tuple[int, int, int, int, int]] = []
    texts: list[str] = []

    def opt(v: str | None) -> int:
        return ABSENT if v is None else int(v)

    for text in lines:
        if (m := _G1.fullmatch(text)) is not None:
            a, b, p, s = m.groups()
            kind = Kind.DWELL if a is None and b is None else Kind.MOVE
            rows.append((kind, opt(a), opt(b), int(p), opt(s)))
        elif (m := _M280.fullmatch(text)) is not None:
            rows.append((Kind.PEN, int(m.group(2) or 0), int(m.group(3) or 0), 0,
                         int(m.group(1))))
        elif text in ("M3 S0", "M4 S0"):
            rows.append((Kind.TOOL_ON, 0, 0, 0, int(text[1])))
        elif text == "M5":
            rows.append((Kind.TOOL_OFF, 0, 0, 0, 0))
        elif text == "G90":
            rows.append((Kind.ABSOLUTE, 0, 0, 0, 0))
        elif (m := _PARK.fullmatch(text)) is not None:
            rows.append((Kind.PEN_PARK, 0, 0, 0, int(m.group(1))))
        elif (m := _G92.fullmatch(text)) is not None:
            rows.append((Kind.SET_POSITION, opt(m.group(1)), opt(m.group(2)), 0, 0))
        else:
            rows.append((Kind.TEXT, 0, 0, 0, len(texts)))
            texts.append(text)
    if not rows:
        return Program.empty()
    cols = np.asarray(rows, dtype=np.int64).T
    return Program(cols[0], cols[1], cols[2], cols[3], cols[4],
                   np.full(len(rows), -1, dtype=np.int64), tuple(texts))


# ------------------------------------------------------------------ fivebar: G6 packing
#: The longest wire line the host builds (`Streamer.limit`: half the firmware's 128-byte
#: receive buffer) and the bytes of such a line that are not items: `N<n>` with a 6-digit
#: number, the head `G6A<a>B<b>P<p>S<s>` with 7-digit targets, the space, `*<crc>/<len>`
#: and the newline.
LINE_BYTES = 64
LINE_OVERHEAD_B = 36
#: The longest checksum field of a body under 100 bytes: `*65535/99`; a longer body's
#: length has 3 digits (protocol 4), one byte more (`field_max`).
FIELD_MAX = 9


def field_max(limit_bytes: int) -> int:
    """The longest checksum field of a line of at most `limit_bytes` (newline included):
    its body is shorter than the limit, so its length has 3 digits only from a limit of
    101 bytes. Counting 9 there made 128-byte lines under the Streamer's 127 (half the
    255-byte ring): two of them no longer fitted in flight, and the firmware waited a
    round trip for every line (issue 39, `python benchmarks/segcost.py`)."""
    return FIELD_MAX + 1 if limit_bytes > 100 else FIELD_MAX

#: (P µs, S) of an item as it is to be written (overrides applied), asked for in order.
ValueAt = Callable[[int], tuple[int, int]]


def record_values(prog: Program) -> ValueAt:
    """The records' own P and S (no overrides)."""
    p, s = prog.rows[3], prog.rows[4]
    return lambda j: (p[j], s[j])


def absolute_known(prog: Program) -> BoolArray:
    """Per item, whether `G90` (absolute targets) is known to be in force there: only after
    an `ABSOLUTE` item of the same stream (the stream's start state is the device's,
    unknown to the packer; `G91` is never streamed, a `TEXT` G91 ends it)."""
    mark = np.where(prog.kind == Kind.ABSOLUTE, 1, 0)
    if prog.texts:
        rel = [i for i in np.flatnonzero(prog.kind == Kind.TEXT)
               if prog.texts[int(prog.s[i])] == "G91"]
        mark[rel] = -1
    last = np.zeros(len(prog), dtype=np.int64)
    idx = np.flatnonzero(mark)
    if idx.size:
        state = np.zeros(len(prog), dtype=np.int64)
        state[idx] = idx + 1
        state = np.maximum.accumulate(state)
        have = state > 0
        last[have] = mark[state[have] - 1]
    out = np.zeros(len(prog), dtype=bool)
    out[1:] = last[:-1] > 0  # an item sees what the items before it set
    return out


def item_text(da: int, db: int, p_us: int | None) -> str:
    """A G6 item: `[P<µs>]±da±db` (P only where the duration changes)."""
    text = f"{da:+d}{db:+d}"
    return text if p_us is None else f"P{p_us}{text}"


def pack_line(prog: Program, start: int, number: int, absolute: bool, limit_bytes: int,
              value_at: ValueAt | None = None) -> tuple[bytes, int]:
    """The wire line for the items from `start` (numbered `number`) and how many it covers.

    `value_at(j)` gives item j's (P, S) as it is to be written (overrides applied), asked
    in order (`record_values` without overrides). A `G6` line covers a head move with both
    targets (absolute targets known in force) and every following move or dwell with the
    head's S and both targets (or neither) while the whole line, newline included, stays
    within `limit_bytes`; a line of one item is the classic `N<n> <body>*<crc>/<len>`."""
    values = value_at or record_values(prog)
    kind, a_col, b_col = prog.rows[0], prog.rows[1], prog.rows[2]
    if kind[start] == Kind.RASTER:
        return g7_line(prog, start, number)
    p_head, s_head = values(start)
    total = len(kind)
    a, b = a_col[start], b_col[start]
    if (not absolute or kind[start] != Kind.MOVE or start + 1 >= total
            or a == ABSENT or b == ABSENT):
        return protocol.encode_line(body(prog, start, p_head, s_head), number), 1
    _check(a, b, p_head, s_head)
    words = f"G6A{a}B{b}P{p_head}" + ("" if s_head == ABSENT else f"S{s_head}")
    text = f"N{number}{words} "
    room = limit_bytes - field_max(limit_bytes) - 1
    p_prev = p_head
    count = 1
    while start + count < total:
        j = start + count
        k = kind[j]
        if k != Kind.MOVE and k != Kind.DWELL:
            break
        p, s = values(j)
        if s != s_head:
            break
        if k == Kind.DWELL:
            na, nb = a, b
        else:
            na, nb = a_col[j], b_col[j]
            if na == ABSENT or nb == ABSENT:
                break
        _check(na, nb, p, s)
        item = item_text(na - a, nb - b, None if p == p_prev else p)
        if len(text) + len(item) > room:
            break
        text += item
        p_prev, a, b = p, na, nb
        count += 1
    if count == 1:
        return protocol.encode_line(body(prog, start, p_head, s_head), number), 1
    raw = text.encode("ascii")
    return raw + protocol.checksum_field(raw) + b"\n", count


def _check(a: int, b: int, p_us: int, s: int) -> None:
    """The ranges `g1` checks, for an item packed into a G6 line."""
    if (not P_MIN_US <= p_us <= P_MAX_US or not -POS_LIMIT <= a <= POS_LIMIT
            or not -POS_LIMIT <= b <= POS_LIMIT or not (s == ABSENT or 0 <= s <= POWER_MAX)):
        g1(a, b, p_us, None if s == ABSENT else s)  # raises, naming the word


def digits(x: IntArray) -> IntArray:
    """Decimal digits of each nonnegative integer (1 for 0)."""
    out = np.ones(x.shape, dtype=np.int64)
    for t in (10, 100, 1_000, 10_000, 100_000, 1_000_000, 10_000_000, 100_000_000):
        out += x >= t
    return out


def item_bytes(d: IntArray, p_us: IntArray | None) -> IntArray:
    """Bytes of G6 items (`item_text`) for moves `d` (N, 2) steps and, where given, the `P`
    each carries (−1 or None: no P): a sign and the digits of each axis, `P` and its
    digits."""
    n = np.abs(np.asarray(d, dtype=np.int64))
    out = 2 + digits(n[:, 0]) + digits(n[:, 1])
    if p_us is not None:
        p = np.asarray(p_us, dtype=np.int64)
        out += np.where(p >= 0, 1 + digits(np.maximum(p, 0)), 0)
    return out


def segment_bytes(steps: IntArray, power: NDArray[np.integer[Any]], duration_us: IntArray | None,
                  start: int, stop: int) -> IntArray:
    """Wire bytes that segments start..stop-1 take as G6 items, their line's overhead shared
    among the items that fit it (a line of n items of b bytes carries n = (LINE_BYTES −
    LINE_OVERHEAD_B)/b of them besides its head, so each costs LINE_BYTES·b/(b + LINE_BYTES −
    LINE_OVERHEAD_B)); a segment whose power differs from the one before starts a line and
    costs LINE_OVERHEAD_B. `steps`: absolute targets (T+1, 2); `duration_us`: the planned
    durations (T,), or None before there are any (then no item carries `P`)."""
    d = np.diff(steps[start:stop + 1], axis=0).astype(np.int64)
    p = None
    if duration_us is not None:
        lo = max(start - 1, 0)
        dur = np.asarray(duration_us[lo:stop], dtype=np.int64)
        prev = dur[:-1] if start > 0 else np.concatenate(([-1], dur[:-1]))
        cur = dur[1:] if start > 0 else dur
        p = np.where(cur != prev, cur, -1)
    item = item_bytes(d, p)
    free = LINE_BYTES - LINE_OVERHEAD_B
    b = -(-LINE_BYTES * item // (item + free))
    pw = np.asarray(power[max(start - 1, 0):stop], dtype=np.int64)
    new_line = pw[1:] != pw[:-1] if start > 0 else np.concatenate(([True], pw[1:] != pw[:-1]))
    return np.where(new_line, LINE_OVERHEAD_B, b)


# ------------------------------------------------------------------ fivebar: G7 raster lines
#: The line numbers a G7 line's size is reckoned with at compile time (`raster.pixels`): 6
#: digits, enough for a million lines in one stream.
G7_NUMBER_DIGITS = 6


def g7_body(items: Sequence[tuple[int, int, int]], u: int, t: int, powers: bytes,
            p_prev: int | None, t_prev: int | None) -> bytes:
    """A G7 line's body after its `N<n> ` (docs/protocol.md 6.4): `G7:` and the binary data
    (`protocol.write_g7`) of the items (P µs, ΔA, ΔB) — each P only where the duration
    differs from the segment before (`p_prev` for the first; None: written) — with U when
    not 0, T when the run has two pixels or more and `t` is not the firmware's modal T
    (`t_prev`; None: unknown, written), and the powers."""
    out = []
    prev = p_prev
    for p, da, db in items:
        if not P_MIN_US <= p <= P_MAX_US:
            raise ProtocolError(f"G7 segment duration P{p} outside {P_MIN_US}..{P_MAX_US} us")
        out.append((None if p == prev else p, da, db))
        prev = p
    g = protocol.G7Data(tuple(out), u or None, t if len(powers) > 1 and t != t_prev else None,
                        powers)
    return b"G7:" + protocol.write_g7(g)


def g7_modal(prog: Program, start: int) -> tuple[int | None, int | None]:
    """The firmware's modal P and T when the G7 line of item `start` comes: unknown (None)
    at a scan's first line (the stream may start there), else the P of the segment before
    and the T of the scan's last run with two pixels or more."""
    kind, p_col, s_col = prog.rows[0], prog.rows[3], prog.rows[4]
    if start == 0 or kind[start - 1] != Kind.RASTER:
        return None, None
    t_prev: int | None = None
    i = start - 1
    while i >= 0 and kind[i] == Kind.RASTER:
        r = s_col[i]
        if r >= 0 and len(prog.runs[r].powers) > 1:
            t_prev = prog.runs[r].t
            break
        i -= 1
    return p_col[start - 1], t_prev


def _target_before(prog: Program, start: int) -> tuple[int, int]:
    """The absolute target of the last move before item `start`: where a G7 line's first
    (relative) segment starts from."""
    kind, a_col, b_col = prog.rows[0], prog.rows[1], prog.rows[2]
    for i in range(start - 1, -1, -1):
        if kind[i] in (Kind.MOVE, Kind.RASTER) and a_col[i] != ABSENT and b_col[i] != ABSENT:
            return a_col[i], b_col[i]
    raise ProtocolError(f"item {start}: a G7 line needs a move with both targets before it")


def g7_line(prog: Program, start: int, number: int, power_pct: int = 100) -> tuple[bytes, int]:
    """The G7 line of the RASTER items from `start` (which has the run) and how many it
    covers: the item and the RASTER items after it without a run (docs/protocol.md 6.4).
    `power_pct` scales the pixel powers (the live power override)."""
    kind, a_col, b_col, p_col, s_col = prog.rows
    run = prog.runs[s_col[start]]
    total = len(kind)
    end = start + 1
    while end < total and kind[end] == Kind.RASTER and s_col[end] < 0:
        end += 1
    a0, b0 = _target_before(prog, start)
    items = []
    for j in range(start, end):
        items.append((p_col[j], a_col[j] - a0, b_col[j] - b0))
        a0, b0 = a_col[j], b_col[j]
    powers = run.powers
    if power_pct < 100:
        powers = bytes(p * power_pct // 100 for p in powers)
    p_prev, t_prev = g7_modal(prog, start)
    raw = b"N%d " % number + g7_body(items, run.u, run.t, powers, p_prev, t_prev)
    return raw + protocol.checksum_field(raw) + b"\n", end - start


def g7_line_bytes(body: bytes, number_digits: int = G7_NUMBER_DIGITS) -> int:
    """Bytes on the wire of a G7 line with this body: `N<n> `, the body, `*<crc>/<len>` (at
    most), the newline."""
    head = 1 + number_digits + 1
    return head + len(body) + 1 + 5 + 1 + len(str(head + len(body))) + 1


# ------------------------------------------------------------------ GRBL's dialect
def grbl_number(v: float, digits: int = 8) -> str:
    """A number GRBL reads exactly (at most `digits` significant digits, no exponent)."""
    whole = len(str(int(abs(v))))
    return f"{v:.{max(0, digits - whole)}f}".rstrip("0").rstrip(".") or "0"


def grbl_g1(x_deg: float, y_deg: float, feed_deg_min: float, s: float | None = None) -> str:
    """A joint-space move: work X/Y = the motor angles in degrees (4 decimals), F in
    degrees a minute, S (0 … `$30`) on a laser run."""
    word = "" if s is None else f" S{grbl_number(s, 5)}"
    return f"G1 X{x_deg:.4f} Y{y_deg:.4f} F{grbl_number(feed_deg_min)}{word}"


def grbl_spindle(command: str, s: float) -> str:
    """`M3 S…`/`M4 S…`: a laser's power or a servo pen's position on GRBL's spindle PWM."""
    return f"{command} S{grbl_number(s, 5)}"


def grbl_dwell(seconds: float) -> str:
    """`G4 P<seconds>` (GRBL 1.1 reads P in seconds)."""
    return f"G4 P{seconds:.3f}"
