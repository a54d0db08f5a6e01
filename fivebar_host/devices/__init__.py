"""Devices the host can talk to instead of real hardware, as pyserial URL schemes: the
emulated firmware (`fivebar-sim://`: sim.py, simport.py, simtrace.py), a mock that obeys
docs/protocol.md (`fivebar-mock://`: mock/) and a stock GRBL 1.1 model (`fivebar-grbl://`:
grblmock.py).

The schemes are registered with pyserial at the entry points — the `fivebar` command, the
daemon's device, the vpype plugin, the tests and benchmarks — by `register()`, so the links
(`controllers.*.link`) open whatever pyserial opens and know nothing of these devices. A
program that uses the library with these URLs calls `fivebar_host.devices.register()` once.
"""


def register() -> None:
    """Make `fivebar-mock://`, `fivebar-sim://` and `fivebar-grbl://` known to
    `serial.serial_for_url` (idempotent)."""
    from fivebar_host.devices import urls

    urls.register()
