"""G6 packing: consecutive job segments in one wire line (docs/protocol.md 6.3, protocol 3).

A job is built as one `G1` body per segment (`run.program`), and everything that maps the
firmware's line numbers back to segments (resume files, `Ln` done, the executed-path report)
counts one line number per segment. A `G6` line keeps that: it stands for the run of `G1`
lines it replaces, with their consecutive numbers, and the firmware gives each of its blocks
its own number. Packing is the link's business only: `Streamer` asks `pack_line` for the wire
line that starts at a body, and the bytes on the wire shrink from about 36 to about 8 per
segment of a drawing (`python benchmarks/link.py`).

A body joins the line when it is a `G1` whose target is known in absolute steps (`G90` in
force, A and B both given; a dwell `G1 P… S…` moves nothing), with the head's `S`, and the
line still fits `limit_bytes`. Everything else goes out as the classic numbered line, byte
for byte what protocol 2 sent.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

from fivebar_host import protocol

#: A G1 body as `protocol.g1` writes it: (A, B, P, S), A/B/S optional.
_G1 = re.compile(r"G1(?: A(-?\d+))?(?: B(-?\d+))? P(\d+)(?: S(\d+))?")

#: The longest checksum field: `*65535/99`.
_FIELD_MAX = 9


@dataclass(frozen=True)
class Segment:
    """A G1 body's values; `a`/`b`/`s` None when the word is absent."""

    a: int | None
    b: int | None
    p_us: int
    s: int | None


def parse_g1(body: str) -> Segment | None:
    """The values of a `G1` body in `protocol.g1`'s form, else None."""
    m = _G1.fullmatch(body)
    if m is None:
        return None
    a, b, p, s = m.groups()
    return Segment(None if a is None else int(a), None if b is None else int(b), int(p),
                   None if s is None else int(s))


def modes(bodies: list[str]) -> list[bool]:
    """Per body, whether `G90` (absolute targets) is known to be in force there: only after
    a `G90` body of the same stream and before any `G91` (the stream's start state is the
    device's, unknown to the packer)."""
    out: list[bool] = []
    absolute = False
    for body in bodies:
        out.append(absolute)
        if body == "G90":
            absolute = True
        elif body == "G91":
            absolute = False
    return out


def pack_line(body_at: Callable[[int], str], start: int, total: int, number: int,
              absolute: bool, limit_bytes: int) -> tuple[bytes, int]:
    """The wire line for the bodies from `start` (numbered `number`) and how many it covers.

    `body_at(j)` gives body j as it is to be sent (overrides applied), called in order.
    A `G6` line covers the head and every following body that `_item` accepts while the
    whole line, newline included, stays within `limit_bytes`; a line of one segment is the
    classic `N<n> <body>*<crc>/<len>`.
    """
    body = body_at(start)
    head = parse_g1(body) if absolute else None
    if head is None or head.a is None or head.b is None or start + 1 >= total:
        return protocol.encode_line(body, number), 1
    words = f"G6A{head.a}B{head.b}P{head.p_us}" + ("" if head.s is None else f"S{head.s}")
    text = f"N{number}{words} "
    room = limit_bytes - _FIELD_MAX - 1
    pos, p_us = (head.a, head.b), head.p_us
    count = 1
    while start + count < total:
        seg = parse_g1(body_at(start + count))
        if seg is None:
            break
        item = _item(seg, pos, p_us, head.s)
        if item is None or len(text) + len(item) > room:
            break
        text += item
        p_us = seg.p_us
        if seg.a is not None and seg.b is not None:
            pos = (seg.a, seg.b)
        count += 1
    if count == 1:
        return protocol.encode_line(body, number), 1
    raw = text.encode("ascii")
    return raw + protocol.checksum_field(raw) + b"\n", count


def _item(seg: Segment, pos: tuple[int, int], p_us: int, s: int | None) -> str | None:
    """The G6 item for `seg` after target `pos` at duration `p_us`, or None when it cannot
    be one (one axis only, another power)."""
    if seg.s != s:
        return None
    if seg.a is None and seg.b is None:
        da = db = 0
    elif seg.a is None or seg.b is None:
        return None
    else:
        da, db = seg.a - pos[0], seg.b - pos[1]
    text = f"{da:+d}{db:+d}"
    return text if seg.p_us == p_us else f"P{seg.p_us}{text}"
