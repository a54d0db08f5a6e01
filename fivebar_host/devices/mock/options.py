"""The options of a ``fivebar-mock://`` URL: what the mock device is and which faults it has.

``fivebar-mock://?speed=10&drop=0.01&seed=1``; unknown options raise ``MockURLError``, a
``ValueError`` and ``serial.SerialException``, naming the option.  They are parsed here, once,
when the port opens, so a typo in a test's URL fails at once instead of silently running a
fault-free device.

- ``speed=F`` (10): motion time factor (see "Time" in ``fivebar_host.devices.mock``);
  0 = instant.
- ``drop=P`` / ``corrupt=P`` (0): per-byte probability that a host→device byte is lost /
  replaced by another printable byte.  Only line bytes (newlines included) are affected;
  real-time bytes are never dropped and corruption never produces one, so the faults are
  what the checksum, line numbers and resend requests must absorb.
- ``seed=N`` (0): seed of the drop/corrupt random generator (reproducible faults).
- ``disconnect_after=N``: once the N-th line has been handled the link breaks: every read,
  write and ``in_waiting`` raises ``serial.SerialException``.  The device keeps running.
- ``reset_after=N``: once the N-th line has been handled the device resets with its RAM
  powered (a watchdog or brown-out reset, docs/protocol.md section 7 "kept across a reset"):
  motion stops where it is, laser off, queue, line counter, modal state and settings restart
  as at power-on, the banner is sent; the position, ``H`` and ``Ln`` done are kept.  The rest
  of that ``write`` is lost.
- ``power_cut_after=N``: once the N-th line has been handled the controller loses power
  and boots again: as ``reset_after``, but nothing is kept (position 0, ``H:0``, ``Ln:0,0``);
  the motors stay where they physically are.
- ``error_on=K`` / ``error_code=C`` (11): the K-th line, if it would be accepted, is
  answered ``error:C`` instead of being executed, exactly as the firmware answers a refused
  line with that code (the counter advances, a running job holds with ``Hold:2``; codes
  8/9/10 refuse the line with a resend request instead).
- ``stall_after=N``: once the N-th line has been handled the device hangs: no reply, no
  status, no motion; bytes are swallowed; output pins (laser) keep their state.  Its
  watchdog (docs/protocol.md section 9) resets it ``watchdog`` ms (wall time) later, as
  the firmware's does: laser off, banner, the position, ``H`` and ``Ln`` done it had when
  it hung kept.  A DTR reset (reopening with the same ``machine``) revives it sooner, the
  same way.
- ``watchdog=MS`` (256): the watchdog timeout after a ``stall_after`` hang, the firmware's
  (2^15 cycles of the AVR's 128 kHz watchdog oscillator); 0 = no watchdog: the hang lasts
  until a DTR reset (a board without it, or a hung USB-serial bridge), so the host's
  reply timeout is what notices it.
- ``endstops=A,B``: switch A (B) is pressed while motor A's (B's) physical position is at
  most A (B) steps — the simavr harness's ``-a``/``-b`` semantics; either may be empty.
- ``rx=N`` (255), ``queue=N`` (16), ``line=N`` (128): buffer sizes, reported in the banner.
- ``version=S`` (1.1.0), ``proto=N`` (4): what the banner claims (for "unknown firmware"
  tests).
- ``machine=NAME``: ports opened with the same name drive one physical machine: its
  physical position, ledger and laser log survive a close/reopen, and opening the port is
  a DTR reset of the firmware still running on it (its motion stops where it is; position,
  ``H`` and ``Ln`` done are kept).  The first open powers the controller up;
  ``machine(NAME).power_cut()`` cuts its power, so the next boot is a power-on again.  A
  second open while the first port is open fails as a busy port.

Lines are counted for the fault options as the device takes them from its receive buffer
(every ``\\n``, refused and empty lines included), from 1 after the port was opened; each
fault fires once per port.
"""

from __future__ import annotations

import math
import re
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import serial

from fivebar_host import protocol
from fivebar_host.devices.mock.codes import E_SOFT_LIMIT, SCHEME
from fivebar_host.errors import FivebarError
from fivebar_host.protocol import POS_LIMIT


class MockURLError(FivebarError, serial.SerialException, ValueError):  # type: ignore[misc]
    """A ``fivebar-mock://`` URL with an unknown option or a malformed value."""


@dataclass(frozen=True)
class MockOptions:
    """The options of one ``fivebar-mock://`` URL (see the module docstring)."""

    speed: float = 10.0
    drop: float = 0.0
    corrupt: float = 0.0
    seed: int = 0
    disconnect_after: int | None = None
    reset_after: int | None = None
    error_on: int | None = None
    error_code: int = E_SOFT_LIMIT
    stall_after: int | None = None
    watchdog: int = 256
    power_cut_after: int | None = None
    endstops: tuple[int | None, int | None] = (None, None)
    rx: int = 255
    queue: int = 16
    line: int = 128
    version: str = "1.1.0"
    proto: int = protocol.PROTOCOL_VERSION
    machine: str | None = None
    true: tuple[float, ...] | None = None
    backlash: tuple[int, int] | None = None  # the real slack of each motor, steps


def _int_option(key: str, value: str, lo: int, hi: int) -> int:
    try:
        v = int(value)
    except ValueError:
        raise MockURLError(f"{SCHEME}: option {key}={value!r} is not an integer") from None
    if not lo <= v <= hi:
        raise MockURLError(f"{SCHEME}: option {key}={v} outside {lo}..{hi}")
    return v


def _float_option(key: str, value: str, lo: float, hi: float) -> float:
    try:
        v = float(value)
    except ValueError:
        raise MockURLError(f"{SCHEME}: option {key}={value!r} is not a number") from None
    if not (math.isfinite(v) and lo <= v <= hi):
        raise MockURLError(f"{SCHEME}: option {key}={value} outside {lo:g}..{hi:g}")
    return v



def _error_code_option(key: str, value: str) -> int:
    code = _int_option(key, value, 1, 255)
    if code not in protocol.CODES or protocol.CODES[code].alarm:
        raise MockURLError(f"{SCHEME}: error_code={code} is not an error code of "
                           f"status.h")
    return code


def _endstops_option(key: str, value: str) -> tuple[int | None, ...]:
    sides = value.split(",")
    if len(sides) != 2:
        raise MockURLError(f"{SCHEME}: endstops must be 'A,B' (either may be empty), "
                           f"got {value!r}")
    return tuple(
        None if not s.strip() else _int_option(key, s.strip(), -POS_LIMIT, POS_LIMIT)
        for s in sides)


def _version_option(key: str, value: str) -> str:
    if not re.fullmatch(r"\S+", value):
        raise MockURLError(f"{SCHEME}: version must be one word, got {value!r}")
    return value


def _machine_option(key: str, value: str) -> str:
    if not value:
        raise MockURLError(f"{SCHEME}: machine needs a name")
    return value


def _true_option(key: str, value: str) -> tuple[float, ...]:
    parts = value.split(",")
    if len(parts) != 7:
        raise MockURLError(f"{SCHEME}: true must be a1,b1,a2,b2,w,home1,home2 (mm, degrees); "
                           f"got {value!r}")
    vals = tuple(_float_option(key, p.strip(), -1e5, 1e5) for p in parts)
    if any(v <= 0 for v in vals[:5]) or any(abs(v) > 360 for v in vals[5:]):
        raise MockURLError(f"{SCHEME}: true needs positive lengths and home angles within "
                           f"±360°; got {value!r}")
    return vals


def backlash_option(key: str, value: str) -> tuple[int, int]:
    """`backlash=A,B`: each motor's real slack in steps (0–10000), where it differs from
    the profile's `[motors] backlash_steps`: the executed-path report draws through it."""
    parts = value.split(",")
    if len(parts) != 2:
        raise MockURLError(f"{SCHEME}: {key} must be two step counts 'A,B'; got {value!r}")
    a, b = (_int_option(key, p.strip(), 0, 10_000) for p in parts)
    return a, b


#: Each option's parser, (key, text) → value; the order is the one error messages list.
_PARSERS: dict[str, Callable[[str, str], Any]] = {
    "speed": lambda k, v: _float_option(k, v, 0.0, 1e9),
    "drop": lambda k, v: _float_option(k, v, 0.0, 1.0),
    "corrupt": lambda k, v: _float_option(k, v, 0.0, 1.0),
    "seed": lambda k, v: _int_option(k, v, -(2**63), 2**63),
    "disconnect_after": lambda k, v: _int_option(k, v, 0, 2**32),
    "reset_after": lambda k, v: _int_option(k, v, 1, 2**32),
    "error_on": lambda k, v: _int_option(k, v, 1, 2**32),
    "error_code": _error_code_option,
    "stall_after": lambda k, v: _int_option(k, v, 0, 2**32),
    "watchdog": lambda k, v: _int_option(k, v, 0, 60000),
    "power_cut_after": lambda k, v: _int_option(k, v, 1, 2**32),
    "endstops": _endstops_option,
    "rx": lambda k, v: _int_option(k, v, 8, 65536),
    "queue": lambda k, v: _int_option(k, v, 1, 255),
    "line": lambda k, v: _int_option(k, v, 8, 255),
    "version": _version_option,
    "proto": lambda k, v: _int_option(k, v, 0, 2**16),
    "machine": _machine_option,
    "true": _true_option,
    "backlash": backlash_option,
}
_KNOWN = tuple(_PARSERS)


def _query_pairs(url: str) -> list[tuple[str, str]]:
    """The (key, value) pairs of a ``fivebar-mock://?…`` URL, in order."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme.lower() != SCHEME:
        raise MockURLError(f"expected a {SCHEME}:// URL, got {url!r}")
    if parts.netloc or parts.path.strip("/"):
        raise MockURLError(f"{url}: unexpected {parts.netloc + parts.path!r}; options go "
                           f"after '?', e.g. {SCHEME}://?speed=10")
    try:
        return urllib.parse.parse_qsl(parts.query, keep_blank_values=True, strict_parsing=True)
    except ValueError:
        if parts.query:
            raise MockURLError(f"{url}: malformed options {parts.query!r}") from None
        return []


def parse_mock_url(url: str) -> MockOptions:
    """Options of a ``fivebar-mock://`` URL; MockURLError names a bad or unknown option."""
    opts: dict[str, Any] = {}
    for key, value in _query_pairs(url):
        if key not in _KNOWN:
            raise MockURLError(f"{SCHEME}: unknown option {key!r} (known: {', '.join(_KNOWN)})")
        if key in opts:
            raise MockURLError(f"{SCHEME}: option {key!r} given twice")
        opts[key] = _PARSERS[key](key, value)
    return MockOptions(**opts)
