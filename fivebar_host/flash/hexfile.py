"""Intel HEX files (what avr-objcopy writes and bootloaders are shipped as) into a flash
image: the bytes from address 0, erased (0xFF) where the file has no data.

Record types 00 (data), 01 (end), 02 and 04 (extended segment and linear address) are read;
03 and 05 (start addresses) mean nothing to a bootloader and are skipped. A bad checksum, a
malformed line, a missing end record or data past `limit` is a HexError naming the line."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from fivebar_host.errors import InputError

#: The value of erased flash.
ERASED = 0xFF


class HexError(InputError):
    """The file is not a valid Intel HEX image (or does not fit the flash)."""


@dataclass(frozen=True)
class FlashImage:
    """Bytes from address 0 to the last byte the file sets; unset bytes are 0xFF."""

    data: bytes
    source: str = ""

    def pages(self, page_size: int) -> list[tuple[int, bytes]]:
        """(byte address, one full page) for each page holding any byte of the image,
        padded with 0xFF: a bootloader writes whole pages."""
        out = []
        for start in range(0, len(self.data), page_size):
            page = self.data[start:start + page_size]
            out.append((start, page + bytes([ERASED]) * (page_size - len(page))))
        return out


def parse_hex(text: str, source: str = "<hex>", limit: int = 1 << 20) -> FlashImage:
    """The image of Intel HEX `text`; HexError (with `source` and the line) when invalid or
    when it sets a byte at or above `limit` (the flash's size)."""
    mem: dict[int, int] = {}
    base = 0
    ended = False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if ended:
            raise HexError(f"{source}:{number}: data after the end record")
        rec = _record(line, source, number)
        kind, addr, payload = rec[3], rec[1] << 8 | rec[2], rec[4:-1]
        if kind == 0:
            for i, byte in enumerate(payload):
                at = base + addr + i
                if at >= limit:
                    raise HexError(f"{source}:{number}: data at 0x{at:X}, past the end of the "
                                   f"flash (0x{limit:X} bytes): the image does not fit")
                mem[at] = byte
        elif kind == 1:
            ended = True
        elif kind in (2, 4) and len(payload) == 2:
            base = (payload[0] << 8 | payload[1]) << (4 if kind == 2 else 16)
        elif kind not in (3, 5):
            raise HexError(f"{source}:{number}: unknown record type {kind:02X}")
    if not ended:
        raise HexError(f"{source}: no end record (a truncated file?)")
    if not mem:
        raise HexError(f"{source}: no data")
    data = bytearray([ERASED]) * (max(mem) + 1)
    for at, byte in mem.items():
        data[at] = byte
    return FlashImage(bytes(data), source)


def _record(line: str, source: str, number: int) -> bytes:
    """One record's bytes, its length and checksum checked."""
    try:
        if not line.startswith(":") or len(line) % 2 == 0:
            raise ValueError
        rec = bytes.fromhex(line[1:])
    except ValueError:
        raise HexError(f"{source}:{number}: not an Intel HEX record: {line[:40]!r}") from None
    if len(rec) < 5 or rec[0] + 5 != len(rec):
        raise HexError(f"{source}:{number}: the record's length byte does not match the line")
    if sum(rec) & 0xFF:
        raise HexError(f"{source}:{number}: checksum mismatch (a damaged file?)")
    return rec


def read_hex(path: Path, limit: int = 1 << 20) -> FlashImage:
    """The image of the Intel HEX file at `path` (HexError when invalid, OSError when
    unreadable)."""
    return parse_hex(path.read_text(encoding="ascii", errors="replace"), str(path), limit)
