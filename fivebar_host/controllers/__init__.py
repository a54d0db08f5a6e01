"""The controllers fivebar drives, one sub-package each, found by name.

`fivebar` is fivebar's own firmware (numbered, checked lines; exact resume), `grbl` a stock
GRBL 1.1 board driven in joint space. Each sub-package's `Controller` is a
`run.controller.Controller` class with `open(url, profile)`. `controller_for(name)` is the one
place a controller's name is read: it imports `fivebar_host.controllers.<name>` and takes its
`Controller`, the way Klipper loads `kinematics/<name>.py` and pyserial a URL scheme's
`protocol_<name>` module, so a new controller is a new sub-package and nothing else changes.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import TYPE_CHECKING, cast

from fivebar_host.errors import UsageError

if TYPE_CHECKING:
    from fivebar_host.config import Profile
    from fivebar_host.run.controller import Controller

#: The controller `--controller` picks when none is named.
DEFAULT = "fivebar"


def names() -> tuple[str, ...]:
    """The controllers there are (the sub-packages of this package), the default first."""
    found = sorted(m.name for m in pkgutil.iter_modules(__path__) if m.ispkg)
    return tuple(sorted(found, key=lambda n: n != DEFAULT))


def controller_for(name: str) -> type[Controller]:
    """The controller class called `name` (`UsageError` naming the ones there are)."""
    if name not in names():
        raise UsageError(f"no controller {name!r}: there are {', '.join(names())}")
    module = importlib.import_module(f"{__name__}.{name}")
    return cast("type[Controller]", module.Controller)


def open_controller(name: str, url: str, profile: Profile) -> Controller:
    """Open the machine at `url` (a device path, COM port or pyserial URL) with the
    controller called `name`. Servo joints need fivebar's servo build (docs/protocol.md
    6.4): another controller refuses them."""
    from fivebar_host.joints import require_stepper_joints

    if name != DEFAULT:
        require_stepper_joints(profile.joints, profile.source)
    return controller_for(name).open(url, profile)
