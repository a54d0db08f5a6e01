"""A scanline's pieces grouped into G7 lines, with each line's size on the wire reckoned by
arithmetic (docs/protocol.md 6.4; `wire.g7_line` is the writer, and the tests hold the two
byte for byte).

Consecutive pieces join one line greedily while the line stays within `LINE_LIMIT` bytes
(6-digit line numbers), 32 segments and the firmware's pixel ring, and its changes within
`FIT_CYCLES` of one progression U + i·T from the line's first piece (module `pixels`).  The
greedy extension counts U and T at their largest (`varint` of the line's cycles, no escape);
the line it stops at is then fitted and sized exactly, and given up a piece at a time while
it breaks a rule.  A piece's item (P where the duration differs from the piece before — the
firmware's modal P; ΔA, ΔB zigzag) and its pixels cost the same in whatever line they land,
so their escaped sizes are counted once for the whole scanline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fivebar_host import protocol
from fivebar_host.raster.motion import ScanMotion
from fivebar_host.raster.pixels import CYCLES_PER_US, FIT_CYCLES, Changes
from kinematics.arrays import IntArray

#: The longest G7 line the host writes, newline included: half the firmware's 255-byte
#: receive ring, so that one is on its way while the firmware parses the other.
LINE_LIMIT = 127
#: The firmware's pixel ring (fb_raster.h).
PX_RING = 128
#: Above this pixel rate a line's record takes at most half the ring (`ring_share`) ...
HALF_RING_PX_S = 6000.0
#: ... where the link carries this many bytes a pixel at that rate.
HALF_RING_BYTES = 2.0
#: Segments one G7 line carries at most (its head's 5-bit count).
MAX_SEGMENTS = 32
#: Digits of the line numbers a line is sized with (`wire.G7_NUMBER_DIGITS`).
NUMBER_DIGITS = 6
#: Bytes the escape adds, per byte value.
_ESC = np.zeros(256, dtype=np.int64)
_ESC[list(protocol.PX_ESCAPED)] = 1
#: 0, 1, 2 … as floats: a line's change indices (sliced: a line holds few changes).
_INDEX = np.arange(1024, dtype=np.float64)


@dataclass(frozen=True)
class Group:
    """One G7 line: its pieces [first, first + count) of the scanline and its run (the
    first change U cycles after the line's first piece starts, then every T), its size on
    the wire, and how far its changes are from U + i·T."""

    first: int
    count: int
    u: int
    t: int
    powers: bytes
    residual: float  # largest |change − (U + i·T)|, cycles
    nbytes: int = 0


def varint_bytes(x: int) -> bytes:
    """The LEB128 varint of x ≥ 0 (`protocol.write_g7`)."""
    out = bytearray()
    while True:
        b, x = x & 0x7F, x >> 7
        out.append(b | (0x80 if x else 0))
        if not x:
            return bytes(out)


def _esc_len(data: bytes) -> int:
    return len(data) + sum(1 for c in data if c in protocol.PX_ESCAPED)


def escaped_varint_len(x: IntArray) -> IntArray:
    """Escaped bytes of the varints of x ≥ 0 (elementwise)."""
    x = np.asarray(x, dtype=np.int64)
    out = np.zeros(x.shape, dtype=np.int64)
    rest = x.copy()
    for _ in range(5):
        more = rest >= 0x80
        live = (rest > 0) | (out == 0)
        b = (rest & 0x7F) | np.where(more, 0x80, 0)
        out += np.where(live, 1 + _ESC[b], 0)
        if not more.any():  # every varint ended here: later rounds would add nothing
            break
        rest = rest >> 7
    return out


def line_size(data_len: int) -> int:
    """Bytes on the wire of a G7 line whose escaped data takes `data_len` bytes
    (`wire.g7_line_bytes`: `N<n> G7:`, the data, `*<crc>/<len>` at most, the newline)."""
    head = 1 + NUMBER_DIGITS + 1
    body = 3 + data_len
    return head + body + 1 + 5 + 1 + len(str(head + body)) + 1


@dataclass(frozen=True)
class _Costs:
    """A scanline's per-piece costs and changes (module docstring)."""

    item: list[int]  # escaped item bytes
    px: list[int]  # pixels (changes)
    px_b: list[int]  # escaped pixel bytes
    has_p: list[bool]
    cyc: list[int]  # cycles
    start: list[int]  # cycles at each piece's start (K + 1)
    cuts: list[int]  # changes of piece j: cuts[j] … cuts[j + 1] − 1
    ch: Changes
    acc: list[int]  # item + pixel bytes of the pieces before piece j (K + 1)


def _costs(sm: ScanMotion, ch: Changes) -> _Costs:
    dur = sm.duration_us.astype(np.int64)
    cyc = dur * CYCLES_PER_US
    start = np.concatenate(([0], np.cumsum(cyc)))
    d = (sm.steps[1:] - sm.steps[:-1]).astype(np.int64)
    zz = np.where(d >= 0, 2 * d, -2 * d - 1)
    has_p = np.concatenate(([True], dur[1:] != dur[:-1]))
    esc_p, esc_a, esc_b = escaped_varint_len(np.stack((dur, zz[:, 0], zz[:, 1])))
    item = np.where(has_p, esc_p, 0) + esc_a + esc_b
    piece = np.clip(np.searchsorted(start, ch.t, side="right") - 1, 0, len(cyc) - 1)
    cuts = np.searchsorted(piece, np.arange(len(cyc) + 1))
    esc = np.concatenate(([0], np.cumsum(_ESC[ch.power])))
    px = cuts[1:] - cuts[:-1]
    px_b = px + esc[cuts[1:]] - esc[cuts[:-1]]
    acc = np.concatenate(([0], np.cumsum(item + px_b)))
    return _Costs(item.tolist(), px.tolist(), px_b.tolist(), has_p.tolist(), cyc.tolist(),
                  start.tolist(), cuts.tolist(), ch, acc.tolist())


def _fit_line(c: _Costs, j: int, end: int, t_prev: int | None
              ) -> tuple[int, int, float]:
    """U, T and the residual of the changes of pieces j … end − 1: T the secant's floor or
    ceil (or the modal `t_prev` when it fits within `FIT_CYCLES`, or the longest that keeps
    every change inside at U = 0), U the minimax offset, lowered where the last change
    would fall past the line's segments and never below 0."""
    a, b = c.cuts[j], c.cuts[end]
    off = c.ch.t[a:b] - float(c.start[j])
    n = b - a
    if n == 0:
        return 0, 0, 0.0
    cands: list[int] = []
    if n > 1:
        if t_prev is not None:
            cands.append(t_prev)
        t0 = (float(off[-1]) - float(off[0])) / (n - 1)
        cands += [math.floor(t0), math.ceil(t0)]
    else:
        cands.append(0)
    total = c.start[end] - c.start[j]
    if n > 1:  # the longest T with every change inside at U = 0: always a valid line
        cands.append((total - 1) // (n - 1))
    i = _INDEX[:n] if n <= _INDEX.shape[0] else np.arange(n, dtype=np.float64)
    best: tuple[int, int, float] | None = None
    for k, t in enumerate(cands):
        r = off - i * t
        mx, mn = float(r.max()), float(r.min())
        u = round((mx + mn) / 2)
        # every change inside the line's segments (the firmware's rule), U ≥ 0 (a varint)
        u = max(min(u, total - 1 - (n - 1) * t), 0)
        if u + (n - 1) * t > total - 1:
            continue
        res = max(mx - u, u - mn)  # = max |r − u| (rounding is monotone)
        if k == 0 and t_prev is not None and n > 1 and res <= FIT_CYCLES:
            return u, t, res  # the modal T: a shorter line
        if best is None or res < best[2]:
            best = (u, t, res)
    assert best is not None
    return best


def _exact(c: _Costs, j: int, end: int, u: int, t: int, t_prev: int | None) -> int:
    """Bytes on the wire of pieces j … end − 1 as one line with this U and T."""
    count = end - j
    n_px = c.cuts[end] - c.cuts[j]
    write_t = n_px > 1 and t != t_prev
    head = (count - 1) | (0x20 if u else 0) | (0x40 if write_t else 0)
    mask = 0
    for i, p in enumerate(c.has_p[j:end]):
        if p:
            mask |= 1 << i
    data = bytes([head]) + mask.to_bytes((count + 7) // 8, "little")
    if u:
        data += varint_bytes(u)
    if write_t:
        data += varint_bytes(t)
    return line_size(_esc_len(data) + c.acc[end] - c.acc[j])


def ring_share(px_per_s: float, link_bytes_s: float) -> int:
    """The ring bytes one G7 line's record may take for a scan the joints allow at
    `px_per_s`, on a link carrying `link_bytes_s`: half the ring when that rate is above
    `HALF_RING_PX_S` and the link carries it at `HALF_RING_BYTES` a pixel, else the whole
    ring.  The firmware stores a line's record only once the ring has room for all of it,
    and queues the line's segments only then; with records of more than half the ring the
    next line waits until the current one is half burned, and at 8,000 px/s the ~4 ms left
    were not always enough to parse and queue it (benchmarks/raster.py: 1–4 underruns a
    run at 250000–1000000 baud, none with half-ring lines).  Where the link sets the speed
    (115200 baud) the whole ring is used: fewer, longer lines cost fewer bytes a pixel.
    Decided once for the image, before its speed is searched."""
    fast = px_per_s > HALF_RING_PX_S and link_bytes_s >= HALF_RING_BYTES * px_per_s
    return PX_RING // 2 if fast else PX_RING


def groups(sm: ScanMotion, ch: Changes, ring_bytes: int = PX_RING) -> list[Group]:
    """The scanline's G7 lines (module docstring), each record within `ring_bytes` of the
    ring (`ring_share`).  A scanline's first line writes its P and T (a stream may start
    there: a resume restarts a scanline); later lines leave out what the line before set
    (the firmware's modal P and T), as the wire writes them."""
    c = _costs(sm, ch)
    k = len(c.cyc)
    out: list[Group] = []
    j = 0
    t_prev: int | None = None
    ring = ring_bytes - protocol.PX_HEAD
    while j < k:
        end = j + 1
        est = 1 + c.item[j] + c.px_b[j]
        cycles, px = c.cyc[j], c.px[j]
        while end < k and end - j < MAX_SEGMENTS:
            nxt_cycles = cycles + c.cyc[end]
            big = max(1, (nxt_cycles.bit_length() + 6) // 7)  # its varint's bytes
            size = est + c.item[end] + c.px_b[end] + 2 * big + (end - j + 8) // 8
            if line_size(size) > LINE_LIMIT or px + c.px[end] > ring:
                break
            est += c.item[end] + c.px_b[end]
            cycles, px = nxt_cycles, px + c.px[end]
            end += 1
        while True:
            u, t, res = _fit_line(c, j, end, t_prev)
            size = _exact(c, j, end, max(u, 0), t, t_prev)
            n_px = c.cuts[end] - c.cuts[j]
            ok = (size <= LINE_LIMIT and res <= FIT_CYCLES and u >= 0
                  and (n_px < 2 or t >= protocol.PX_T_MIN))
            if ok or end == j + 1:
                break
            end -= 1
        a, b = c.cuts[j], c.cuts[end]
        out.append(Group(j, end - j, u, t, ch.power[a:b].tobytes(), res, size))
        if b - a > 1:
            t_prev = t
        j = end
    return out
