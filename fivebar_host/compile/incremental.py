"""The incremental compiler: moves in machine mm, one at a time → checked joint-space targets
(when a move is accepted) → a timed `Program` (for a batch of moves at once, the look-ahead).

The public API the bridge (`fivebar bridge`, a GRBL front door) compiles a sender's stream
with: the same stages as `fivebar plot` (`fivebar_host.compile`), on a stream instead of a
file:

* `solve` runs when a move is accepted (the bridge: before the sender's `ok`): checked
  inverse kinematics of every vertex (`PoseChecker.inverse`: reach, joint limits, both
  singularity margins, assembly) and the chords refined in joint space within the tolerance
  (`toolpath.segment.refine`); a rapid (G0) is a checked straight joint-space move
  (`joint_moves`, sampled every 0.5°) with the checked Cartesian line as fallback, as pen-up
  travel is in `compile.travel`. A failure is a `MoveRefusedError` naming the point and the
  reason, raised before anything of that move runs.
* `plan` takes the solved moves waiting in the look-ahead, quantises them to absolute steps
  once (`compile.segments.drop_zero_moves`), times them with the joint speed and acceleration
  limits on the firmware's rate staircase (`compile.timing.time_stepped`) and emits the
  program (laser power only on drawing segments, S0 on every other move; a pen marked
  `M3 S0` / `M5`). A batch runs from rest to rest: the look-ahead is what the caller has
  accepted ahead, up to `LOOKAHEAD_MOVES` moves.

Tolerance budget as in `compile.job`: arcs are flattened within tol/2 (the interpreter's
chord tolerance) and refined within tol/2, straight lines within tol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fivebar_host import protocol
from fivebar_host.compile import steps
from fivebar_host.compile.backlash import take_up
from fivebar_host.compile.model import MAX_STEP_RAD
from fivebar_host.compile.segments import Segments, drop_zero_moves
from fivebar_host.compile.timing import time_stepped
from fivebar_host.compile.travel import TRAVEL_TOL_MM
from fivebar_host.config import Profile
from fivebar_host.errors import FivebarError
from fivebar_host.program import ABSENT, Kind, Program
from fivebar_host.toolpath.segment import (
    REASON_KEY,
    CheckFailedError,
    PoseChecker,
    joint_moves,
    refine,
)
from kinematics.arrays import BoolArray, FloatArray, IntArray

#: Moves the look-ahead buffer holds before a batch is planned without waiting for more.
LOOKAHEAD_MOVES = 200


class MoveRefusedError(FivebarError):
    """A move the machine cannot make: `point` (machine mm; NaN when it is on the way),
    `reason` (a `toolpath.segment.REASON_KEY` value, in words) and what failed."""

    def __init__(self, point: tuple[float, float], reason: str, message: str) -> None:
        super().__init__(message)
        self.point = point
        self.reason = reason


def moves_finished(program: Program, items_done: int, moves: int) -> int:
    """How many of a batch's `moves` accepted moves have run to their end once its first
    `items_done` items have (`Program.segment` of a move item is its move's index)."""
    rest = program.segment[max(items_done, 0):]
    ahead = rest[rest >= 0]
    return moves if ahead.size == 0 else int(ahead[0])


def pen_switch(down: bool) -> Program:
    """The pen marked down (`M3 S0`) before a run of drawing segments and up (`M5`) after it,
    which a pen-lift output can follow (the laser-enable state at S0)."""
    return Program.command(Kind.TOOL_ON, s=3) if down else Program.command(Kind.TOOL_OFF)


@dataclass(frozen=True)
class Solved:
    """One accepted move: its targets' joint angles (K, 2) and pen points (K, 2), the pen
    path length of each piece, and how it is run."""

    th: FloatArray
    pts: FloatArray
    length: FloatArray
    draw: bool
    feed_mm_s: float
    power: int  # 0–255 at the programmed feed
    dynamic: bool  # M4: power scaled with the real speed (GRBL laser mode)
    jog: bool = False
    #: a straight move (G0/G1, not an arc, not a jog): its start and end, machine mm, which
    #: `bridge.scanlines` reads raster scanlines from (None otherwise)
    line: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class Batch:
    """The program of a run of moves, from rest to rest, and where it ends."""

    program: Program
    duration_s: float
    end_steps: tuple[int, int]
    jog: bool = False
    moves: int = 0


@dataclass
class OnlineCompiler:
    """Solves moves as they are accepted and plans batches of them (module doc)."""

    profile: Profile
    mode: str
    tolerance_mm: float
    laser: bool
    #: the firmware's step rate (`$0`, steps/s) the session runs under (its boot value
    #: unless the bridge raised it for a fast profile)
    max_rate_steps_s: int = 20000

    def __post_init__(self) -> None:
        kin = self.profile.kinematics
        self.checker = PoseChecker(self.profile.geometry, self.mode,
                                   1 if kin.assembly == "+" else -1,
                                   kin.min_type1_margin_rad, kin.min_type2_margin_rad,
                                   self.profile.motors.limits_rad)
        self.pen_down = False

    # ------------------------------------------------------------------ positions
    def angles_of_steps(self, a: int, b: int) -> FloatArray:
        mot = self.profile.motors
        out: FloatArray = steps.step_angles(np.array([[a, b]]), mot.home_rad, mot.steps_per_rev)[0]
        return out

    def point_of(self, th: FloatArray) -> tuple[float, float] | None:
        """Pen position of joint angles in the machine's assembly (None if none)."""
        pts, valid = self.checker.forward(np.asarray(th, dtype=np.float64).reshape(1, 2))
        return (float(pts[0, 0]), float(pts[0, 1])) if valid[0] else None

    # ------------------------------------------------------------------ solve
    def _refuse(self, cf: CheckFailedError) -> MoveRefusedError:
        x, y = cf.point
        where = f"({x:.3f}, {y:.3f}) mm" if math.isfinite(x) else "on the way"
        why = REASON_KEY_TEXT.get(cf.reason, cf.reason)
        return MoveRefusedError((x, y), why, f"Refused {why} at machine {where}: "
                                f"{cf.message} (working mode {self.mode})")

    def solve(self, th_from: FloatArray, start: tuple[float, float],
              points: list[tuple[float, float]], *, rapid: bool, draw: bool,
              feed_mm_s: float, power: int, dynamic: bool, arc: bool,
              jog: bool = False) -> Solved | None:
        """Checked joint-space targets of one move (None if it has no XY motion)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if np.hypot(*(pts[-1] - np.asarray(start))) < 1e-9 and pts.shape[0] == 1:
            return None
        try:
            if rapid:
                th, p, length = self._rapid(th_from, start, pts[-1])
            else:
                th, p, length = self._chords(th_from, start, pts, arc)
        except CheckFailedError as cf:
            raise self._refuse(cf) from None
        line = None
        if pts.shape[0] == 1 and not arc and not jog:
            line = (float(start[0]), float(start[1]), float(pts[0, 0]), float(pts[0, 1]))
        return Solved(th, p, length, draw and not rapid, feed_mm_s, power if draw else 0,
                      dynamic, jog, line)

    def _chords(self, th_from: FloatArray, start: tuple[float, float], pts: FloatArray,
                arc: bool) -> tuple[FloatArray, FloatArray, FloatArray]:
        th_v = self.checker.inverse(pts)
        pa = np.concatenate((np.asarray(start, dtype=np.float64)[None], pts[:-1]))
        tha = np.concatenate((th_from[None], th_v[:-1]))
        tol_i = self.tolerance_mm / 2 if arc else self.tolerance_mm
        iv = refine(self.checker, pa, pts, tha, th_v, np.full(pts.shape[0], tol_i),
                    MAX_STEP_RAD)
        c = iv.chord
        ends = pa[c] + iv.sb[:, None] * (pts[c] - pa[c])
        length = (iv.sb - iv.sa) * np.hypot(*(pts[c] - pa[c]).T)
        return iv.thb, ends, length

    def _rapid(self, th_from: FloatArray, start: tuple[float, float],
               end: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        th_to = self.checker.inverse(end.reshape(1, 2))
        pieces, ok, _, _ = joint_moves(self.checker, th_from[None], th_to, MAX_STEP_RAD)
        if not ok[0]:  # the checked Cartesian line instead, as compile.travel does
            tol = max(TRAVEL_TOL_MM, self.tolerance_mm)
            iv = refine(self.checker, np.asarray(start, dtype=np.float64)[None],
                        end.reshape(1, 2), th_from[None], th_to, np.array([tol]),
                        MAX_STEP_RAD)
            th = iv.thb
        else:
            n = int(pieces[0])
            th = th_from + (np.arange(1, n + 1)[:, None] / n) * (th_to[0] - th_from)
        p, _ = self.checker.forward(th)
        length = np.hypot(*np.diff(np.concatenate(
            (np.asarray(start, dtype=np.float64)[None], p)), axis=0).T)
        return th, p, length

    # ------------------------------------------------------------------ plan
    def plan(self, th_start: FloatArray, pt_start: tuple[float, float],
             moves: list[Solved]) -> Batch:
        """Time a run of solved moves from rest to rest and write its firmware lines."""
        mot = self.profile.motors
        th = np.concatenate([th_start[None]] + [m.th for m in moves])
        pts = np.concatenate([np.asarray(pt_start, dtype=np.float64)[None]]
                             + [m.pts for m in moves])
        counts = np.array([m.th.shape[0] for m in moves])
        k = int(counts.sum())
        seg = Segments(th=th, pts=pts, draw=np.repeat([m.draw for m in moves], counts),
                       path=np.zeros(k, np.int64), source=np.full(k, -1, np.int64),
                       line=np.repeat(np.arange(len(moves)), counts),
                       length=np.concatenate([m.length for m in moves]),
                       perm=np.arange(k))
        # backlash: take-ups at reversals; each batch ends with the slack taken up downward,
        # so the counts equal the joints' steps between batches (compile.backlash)
        sp = take_up(drop_zero_moves(mot, seg), mot.backlash_steps)
        end = (int(sp.steps[-1, 0]), int(sp.steps[-1, 1]))
        if sp.draw.shape[0] == 0:
            return Batch(Program.empty(), 0.0, end, moves[0].jog if moves else False, len(moves))
        mv = sp.line
        power = np.array([m.power for m in moves], dtype=np.uint8)[mv]
        if sp.slack.shape[0]:  # a standing take-up burns nothing
            power[(sp.slack[1:] != sp.slack[:-1]).any(axis=1)] = 0
        feed = np.array([m.feed_mm_s for m in moves])[mv]
        stop = np.zeros(mv.shape[0], dtype=bool)
        stop[:-1] = (sp.draw[1:] != sp.draw[:-1]) | (power[1:] != power[:-1])
        planned = time_stepped(self.profile, self.checker, sp, power, feed, stop)
        base = planned.power.astype(np.float64)
        dyn = np.array([m.dynamic for m in moves])[planned.line]
        prog_feed = np.array([m.feed_mm_s for m in moves])[planned.line]
        speed = planned.length / np.maximum(planned.duration_us * 1e-6, 1e-9)
        scale = np.clip(speed / np.maximum(prog_feed, 1e-9), 0.0, 1.0)
        pw: IntArray = np.rint(np.where(dyn, base * scale, base)).astype(np.int64)
        prog = self._program(planned.steps[1:], planned.duration_us, planned.draw, pw,
                             planned.line)
        return Batch(prog, float(planned.duration_us.sum()) * 1e-6, end,
                     moves[0].jog, len(moves))

    def _program(self, st: IntArray, dur: IntArray, draw: BoolArray,
                 power: IntArray, move: IntArray) -> Program:
        """The batch's items: laser `M3 S0` … `M5` around it with power on drawing segments
        only; a pen down/up (`pen_switch`) where drawing starts/stops. Each move item's
        `segment` is the index of the accepted move it belongs to in the batch (how many
        moves have run follows from the firmware's last finished line: `moves_finished`)."""
        s = np.where(draw, power, 0) if self.laser else np.zeros(len(dur), dtype=np.int64)
        moves = Program.moves(st[:, 0], st[:, 1], dur, s, move)
        if self.laser:
            return Program.join([Program.command(Kind.TOOL_ON, s=3), moves,
                                 Program.command(Kind.TOOL_OFF)])
        parts: list[Program] = []
        flips = np.flatnonzero(np.diff(np.concatenate(([self.pen_down], draw)).astype(np.int8)))
        start = 0
        for i in flips.tolist():
            parts += [moves.take(slice(start, i)), pen_switch(bool(draw[i]))]
            start = i
        if len(draw):
            self.pen_down = bool(draw[-1])
        return Program.join([*parts, moves.take(slice(start, None))])

    def pen_program(self, down: bool) -> Program:
        """The item that brings the pen to `down` (none if it is already there, or a
        laser)."""
        if self.laser or down == self.pen_down:
            return Program.empty()
        self.pen_down = down
        return pen_switch(down)


REASON_KEY_TEXT = {v: v.replace("_", " ") for v in set(REASON_KEY.values())}


def dwell_program(seconds: float) -> Program:
    """Dwell items (no motion, no S word) for a G4 of `seconds`, split at the protocol's
    longest P."""
    us = round(seconds * 1e6)
    parts: list[int] = []
    while us >= protocol.P_MIN_US:
        p = min(us, protocol.P_MAX_US)
        parts.append(p)
        us -= p
    return Program.of(np.full(len(parts), Kind.DWELL), ABSENT, ABSENT, parts, ABSENT)
