"""Make the fivebar pyserial URL schemes known to ``serial.serial_for_url``.

pyserial finds a scheme's handler by importing ``<package>.protocol_<scheme>`` for each
package in ``serial.protocol_handler_packages`` and taking its ``Serial`` class.  Our
schemes contain a hyphen (``fivebar-mock``), which no importable file name can carry, so
``register()`` puts the handler modules into ``sys.modules`` under the dotted names pyserial
will ask for (``importlib.import_module`` returns a module found there without looking at
the file system) and adds this package to the search list.
"""

from __future__ import annotations

import sys
from types import ModuleType

import serial

PACKAGE = "fivebar_host.devices"


def _install(scheme: str, module: ModuleType) -> None:
    """Serve ``<scheme>://`` URLs with ``module.Serial``."""
    sys.modules[f"{PACKAGE}.protocol_{scheme}"] = module


def register() -> None:
    """Register ``fivebar-mock://``, ``fivebar-sim://``, ``fivebar-grbl://``,
    ``fivebar-grblhal://`` and ``fivebar-fluidnc://``; idempotent."""
    from fivebar_host.devices import grblfamily, grblmock, mock, simport

    _install(grblmock.SCHEME, grblmock)
    for scheme, port in grblfamily.PORTS.items():
        handler = ModuleType(f"{PACKAGE}.protocol_{scheme}")
        handler.Serial = port  # type: ignore[attr-defined]
        _install(scheme, handler)
    _install(mock.SCHEME, mock)
    _install(simport.SCHEME, simport)
    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)
