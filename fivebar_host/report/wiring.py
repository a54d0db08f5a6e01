"""The wiring picture (docs/wiring.png, `fivebar wiring --picture`): the Arduino's digital
header with each of the firmware's pins labelled, for the CNC shield and a bare board."""

from __future__ import annotations

from pathlib import Path

from fivebar_host.wiring import WIRES


def draw_wiring(path: Path) -> Path:
    """Write the picture to `path` (PNG) and return it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyBboxPatch

    by_pin = {w.pin: w for w in WIRES}
    fig, ax = plt.subplots(figsize=(11, 6.2))
    ax.set_xlim(0, 110)
    ax.set_ylim(0, 62)
    ax.axis("off")
    ax.add_patch(FancyBboxPatch((2, 40), 40, 18, boxstyle="round,pad=0.6", fc="#1d5f8f",
                                ec="#0d3b5c"))
    ax.text(22, 52, "Arduino Uno / Nano\n(ATmega328P)", color="white", ha="center",
            va="center", fontsize=12, weight="bold")
    pins = [f"D{n}" for n in range(2, 13)]
    for i, pin in enumerate(pins):
        y = 57 - i * 5.2
        used = pin in by_pin
        ax.add_patch(FancyBboxPatch((44, y - 1.6), 6, 3.2, boxstyle="round,pad=0.2",
                                    fc="#f0b429" if used else "#d0d4da", ec="#555"))
        ax.text(47, y, pin, ha="center", va="center", fontsize=9, weight="bold")
        if used:
            w = by_pin[pin]
            ax.plot([50.5, 56], [y, y], color="#444", lw=1.2)
            ax.text(57, y + 0.9, w.what, fontsize=9, va="center", weight="bold")
            ax.text(57, y - 1.1, f"shield: {w.shield}   ·   bare: {w.bare}", fontsize=7.5,
                    va="center", color="#333")
    ax.text(2, 34, "Pins from firmware/fivebar/config.h.\nD4, D7 unused; D0/D1 are the "
            "USB serial link.\nEndstops and the pen share\nthe shield's 5 V and GND.",
            fontsize=9, va="top", color="#333")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
