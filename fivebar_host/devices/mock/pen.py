"""The pen servo of the mock firmware (fb_motion.c's pen part, docs/protocol.md 6.2).

``PenServo`` is where the firmware's servo pulse is over time: a park (pen up) pulse set by
``$14`` (0 = no pen, no pulses), a target the running ``M280`` block set, and a linear move
from the pulse it had towards that target over the block's move time.  A park jumps to the
park pulse at once and, for a hold, remembers the target so that ``~`` can lower the pen
again (and wait its move and settle time first).  It belongs to the machine
(``Machine.pen``), so it outlives reboots, and every change is logged (``PenServo.log``):
tests check where the pen was when the motors stepped.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class PenServo:
    """The servo pulse over clock time (seconds), µs; see the module docstring."""

    park: int = 0
    target: int = 0
    saved: int = 0  # the target a hold's park interrupted (0: none)
    restore_ms: int = 0  # move + settle ms of the M280 that set the target
    t0: float = 0.0  # when the current move started
    start: float = 0.0  # pulse at t0
    move_s: float = 0.0  # clock seconds the move takes
    log: list[tuple[float, int, int]] = field(default_factory=list)  # (t, start, target)

    def pulse(self, t: float) -> int:
        """The pulse output at clock time ``t`` (the move's straight line), µs."""
        if self.move_s <= 0.0 or t >= self.t0 + self.move_s:
            return self.target
        f = max(0.0, (t - self.t0) / self.move_s)
        return round(self.start + f * (self.target - self.start))

    @property
    def down(self) -> bool:
        """The pen is away from its park position (lowered)."""
        return self.target != self.park

    def _set(self, t: float, target: int, move_s: float) -> None:
        self.start = self.pulse(t) if move_s > 0.0 else target
        self.t0, self.target, self.move_s = t, target, move_s
        self.log.append((t, self.start, target))

    def setup(self, t: float, park: int) -> None:
        """``$14``, a boot: the park pulse, and the pen parked there (nothing to restore)."""
        self.park = park
        self.saved = 0
        self._set(t, park, 0.0)

    def park_now(self, t: float, keep: bool) -> None:
        """Park at once; ``keep`` (a hold) remembers the target for ``unpark``."""
        if keep and self.down and not self.saved:
            self.saved = self.target
        elif not keep:
            self.saved = 0
        self._set(t, self.park, 0.0)

    def unpark(self, t: float) -> int:
        """Back to the target a hold's park interrupted: the ms to wait (0: nothing)."""
        if not self.saved:
            return 0
        target, self.saved = self.saved, 0
        self._set(t, target, 0.0)
        return self.restore_ms or 1

    def start_block(self, t: float, target: int, move_s: float, total_ms: int) -> None:
        """An ``M280`` block starts: move to ``target`` over ``move_s`` clock seconds."""
        self.saved = 0
        self.restore_ms = total_ms
        self._set(t, target, move_s)
