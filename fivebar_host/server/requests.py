"""The one door into the machine thread: requests, their queue, and the handle other threads hold.

HTTP handlers and the daemon's signal handling never touch the machine thread's record
(server.state). They hold a `WorkerHandle`, which puts a request in the thread-safe
`RequestQueue` and, where the caller needs an answer, waits for it on a future the machine
thread completes; and they read the last `Snapshot` the machine thread published.

The requests: for a job, `Pause`, `Resume` (a paused job, or a held one back to the queue),
`Cancel` and `SetOverrides`; for the machine between jobs, `Home`, `Jog`, `Pen`, `MotorsOff`
and `ClearAlarm`; and `Terminate` (stop the daemon) and `Wake` (the queue of jobs changed),
which need no answer. The machine thread takes them whenever it looks: between jobs at once
(it waits on the queue while idle), during a job every time the stream asks whether to
stop, and while a job is paused. Once the machine thread has ended the queue is closed:
what is asked then is refused at once.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any

from fivebar_host.server.state import ActionError, JobStateError, Snapshot

#: Longest a job request waits for the machine thread's answer, s (it answers within a
#: status poll, unless it is homing or moving the arms between jobs).
JOB_REQUEST_TIMEOUT_S = 180.0
#: Longest a manual action may wait for its turn and run, s.
ACTION_TIMEOUT_S = 120.0
#: ... and homing, s.
HOME_TIMEOUT_S = 180.0


@dataclass(frozen=True)
class Pause:
    """Hold the running job `job_id` (laser off at once)."""

    job_id: int


@dataclass(frozen=True)
class Resume:
    """Continue a paused job, or requeue a held one; `confirm` answers its question."""

    job_id: int
    confirm: bool = False


@dataclass(frozen=True)
class Cancel:
    """Cancel a job: the running one stops at once (laser off); others leave the queue."""

    job_id: int


@dataclass(frozen=True)
class SetOverrides:
    """Set the running job's live feed and/or laser power, %; answered (feed %, power %)."""

    job_id: int
    feed_pct: int | None = None
    power_pct: int | None = None


@dataclass(frozen=True)
class Home:
    """Home: `$H` with endstops, else set the count once the person confirms `at_home`."""

    at_home: bool


@dataclass(frozen=True)
class Jog:
    """Move one motor by `steps`, or the pen by `dxy_mm` (laser off), as `fivebar jog`."""

    motor: str | None = None
    steps: int = 0
    dxy_mm: tuple[float, float] | None = None


@dataclass(frozen=True)
class Pen:
    """Lower (`down`) or raise the servo pen."""

    down: bool


@dataclass(frozen=True)
class MotorsOff:
    """Switch the motors off (`M18`): the arms move freely, the pose is forgotten."""


@dataclass(frozen=True)
class ClearAlarm:
    """Clear an alarm (`$X`; the position is kept)."""


@dataclass(frozen=True)
class Terminate:
    """Stop the daemon: the running job at a segment's end, or at once with `hurry`."""

    hurry: bool = False


@dataclass(frozen=True)
class Wake:
    """The queue of jobs changed (a submission, a new order): look at it now."""


JobRequest = Pause | Resume | Cancel | SetOverrides
MachineAction = Home | Jog | Pen | MotorsOff | ClearAlarm
Request = JobRequest | MachineAction | Terminate | Wake


@dataclass(frozen=True)
class Ask:
    """A request in the queue, with the future its answer goes to (None: no answer)."""

    request: Request
    answer: Future[Any] | None


def refusal(request: Request) -> Exception:
    """The error of a request the machine thread will never take (it has ended)."""
    if isinstance(request, MachineAction):
        return ActionError("the daemon stopped")
    return JobStateError("the daemon stopped")


class RequestQueue:
    """The requests waiting for the machine thread, first in first out (any thread puts; the
    machine thread takes)."""

    def __init__(self) -> None:
        self._items: deque[Ask] = deque()
        self._cv = threading.Condition()
        self._closed = False

    def put(self, request: Request, answer: bool) -> Future[Any] | None:
        """Queue `request`; the future of its answer when `answer`. Once closed, a request
        that wants an answer is refused (its error raised here); others are dropped."""
        fut: Future[Any] | None = Future() if answer else None
        with self._cv:
            if not self._closed:
                self._items.append(Ask(request, fut))
                self._cv.notify_all()
                return fut
        if fut is not None:
            raise refusal(request)
        return None

    def take(self, timeout_s: float) -> list[Ask]:
        """Every waiting request, after waiting up to `timeout_s` for one (machine thread)."""
        if not self._items and timeout_s <= 0.0:
            return []  # the stream asks often: no lock when nothing waits
        with self._cv:
            if not self._items and timeout_s > 0.0:
                self._cv.wait(timeout_s)
            items = list(self._items)
            self._items.clear()
        return items

    def close(self) -> list[Ask]:
        """Take no more requests; those still waiting (machine thread, when it ends)."""
        with self._cv:
            self._closed = True
            items = list(self._items)
            self._items.clear()
        return items


class WorkerHandle:
    """How other threads reach the machine thread (module docstring): requests, answered
    through futures where the caller needs an answer, and the published snapshot."""

    def __init__(self, port_url: str) -> None:
        self.queue = RequestQueue()
        self._snapshot = Snapshot(port_url)
        #: Told of every change the machine thread publishes (status report, progress …):
        #: quick callables, registered before the machine thread starts.
        self.listeners: list[Callable[[], None]] = []

    # ------------------------------------------------------------------ machine thread
    def publish(self, snapshot: Snapshot) -> None:
        """Make `snapshot` the one readers see, and tell the listeners (machine thread)."""
        self._snapshot = snapshot
        for fn in self.listeners:
            fn()

    # ------------------------------------------------------------------ any thread
    def snapshot(self) -> Snapshot:
        """The machine thread's state as last published (no waiting, no serial traffic)."""
        return self._snapshot

    def _ask(self, request: Request, timeout_s: float) -> Any:
        fut = self.queue.put(request, answer=True)
        assert fut is not None
        return fut.result(timeout=timeout_s)

    def notify(self) -> None:
        """The queue of jobs changed: the machine thread looks at it now."""
        self.queue.put(Wake(), answer=False)

    def terminate(self, hurry: bool = False) -> None:
        """Stop: the running job stops at a segment boundary (or at once with `hurry`)."""
        self.queue.put(Terminate(hurry), answer=False)

    def pause(self, job_id: int) -> None:
        """Hold the running job (laser off at once); `JobStateError` if it does not run."""
        self._ask(Pause(job_id), JOB_REQUEST_TIMEOUT_S)

    def resume(self, job_id: int, confirm: bool = False) -> None:
        """Continue a paused job, or requeue a held one (at the head of the queue)."""
        self._ask(Resume(job_id, confirm), JOB_REQUEST_TIMEOUT_S)

    def cancel(self, job_id: int) -> None:
        """Cancel a job: the running one stops at once (laser off); others leave the queue."""
        self._ask(Cancel(job_id), JOB_REQUEST_TIMEOUT_S)

    def set_overrides(self, job_id: int, feed_pct: int | None = None,
                      power_pct: int | None = None) -> tuple[int, int]:
        """Set the running job's live overrides; the factors now in force (feed %, power %)."""
        values: tuple[int, int] = self._ask(SetOverrides(job_id, feed_pct, power_pct),
                                            JOB_REQUEST_TIMEOUT_S)
        return values

    def home(self, at_home: bool) -> None:
        """Home the machine (`ActionError` when it cannot be done now)."""
        self._ask(Home(at_home), HOME_TIMEOUT_S)

    def jog(self, *, motor: str | None = None, steps: int = 0,
            dxy_mm: tuple[float, float] | None = None) -> None:
        """Jog a motor by steps or the pen by mm, between jobs."""
        self._ask(Jog(motor, steps, dxy_mm), ACTION_TIMEOUT_S)

    def pen(self, down: bool) -> None:
        """Lower or raise the servo pen, between jobs."""
        self._ask(Pen(down), ACTION_TIMEOUT_S)

    def motors_off(self) -> None:
        """Switch the motors off, between jobs."""
        self._ask(MotorsOff(), ACTION_TIMEOUT_S)

    def clear_alarm(self) -> None:
        """Clear the machine's alarm, between jobs."""
        self._ask(ClearAlarm(), ACTION_TIMEOUT_S)
