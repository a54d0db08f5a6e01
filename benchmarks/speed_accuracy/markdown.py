"""Number formatting for the markdown report: a few significant digits, bytes, shares.

`fmt_g` prints "—" for NaN and "∞" for infinity, so a table cell never shows "nan"."""

from __future__ import annotations

import math


def fmt_g(x: float, digits: int = 2) -> str:
    """`digits` significant digits, exponent form outside [1e-3, 1e5)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    if math.isinf(x):
        return "∞"
    if x == 0:
        return "0"
    return f"{x:.{digits}g}" if 1e-3 <= abs(x) < 1e5 else f"{x:.{digits - 1}e}"


def fmt_bytes(n: int) -> str:
    """B, KiB or MiB ("—" for none)."""
    if n == 0:
        return "—"
    if n < 1024:
        return f"{n} B"
    return f"{n / 1024:.0f} KiB" if n < 2**20 else f"{n / 2**20:.1f} MiB"


def fmt_pct(x: float) -> str:
    """A share as a whole percentage ("—" for NaN)."""
    return "—" if math.isnan(x) else f"{100 * x:.0f} %"
