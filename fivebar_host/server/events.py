"""Server-sent events for the web page: machine status, live progress and the queue, pushed.

`GET /api/events` (server.routes.page) answers `text/event-stream`. Nothing polls on a timer:
the machine thread calls `EventHub.poke` whenever it publishes a new snapshot of its state
(every status report, progress update and request it carries out: `WorkerHandle.listeners`),
and the store calls it after every committed write (`JobStore.listeners`). A poke wakes
every open stream on the event loop (coalesced: at most one wake-up is pending at a time),
and each stream sends what changed, at most once per `MIN_INTERVAL_S`:

- `status`: the machine as last reported (the `/api/status` machine fields), the pen's
  point and the linkage pose in mm, the running job's live progress (segment n of m,
  elapsed, remaining, paused, feed and power overrides), queue counts; with `changed_at`,
  the wall-clock time the daemon received the status report shown (so the page can measure
  status-to-page latency), and `trail`: the positions reported since the stream last sent them.
- `trail`: on connecting and when a new job starts, the whole path the machine has drawn so
  far for the running job, from its reported positions (mm, and whether the segment there
  draws).
- `jobs`: the queue and recent history (the `/api/jobs` objects) and the queue order, on
  connecting and after every change of the database.

A comment line every `KEEPALIVE_S` keeps proxies from closing an idle stream; a stream ends
when the client goes away or the daemon stops.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fivebar_host.compile.steps import step_angles
from fivebar_host.config import Profile
from fivebar_host.progress import Event
from fivebar_host.server.jobs import CompiledCache
from fivebar_host.server.manual import pose_mm
from fivebar_host.server.requests import WorkerHandle
from fivebar_host.server.state import machine_view
from fivebar_host.server.store import JobStore

#: Shortest time between two `status` events of one stream, s (at most 25 a second).
MIN_INTERVAL_S = 0.04
#: A comment line after this long without an event, s.
KEEPALIVE_S = 15.0
#: How often an idle stream looks whether the daemon stops or the client left, s.
CHECK_S = 1.0
#: Most trail points kept for the running job (halved by dropping every other one beyond).
MAX_TRAIL = 20000
#: Most jobs of the history sent in a `jobs` event.
JOBS_SENT = 100


@dataclass
class Trail:
    """The reported positions (steps) of the running job, with whether each segment draws."""

    job_id: int | None = None
    steps: list[tuple[int, int, int]] = field(default_factory=list)  # a, b, draws
    serial: int = 0  # bumped when the trail restarts (new job) or is thinned

    def add(self, job_id: int, a: int, b: int, draws: bool) -> None:
        """Record a reported position of `job_id` (a new job starts a new trail)."""
        if job_id != self.job_id:
            self.job_id, self.steps = job_id, []
            self.serial += 1
        if self.steps and self.steps[-1][:2] == (a, b):
            return
        self.steps.append((a, b, int(draws)))
        if len(self.steps) > MAX_TRAIL:
            self.steps = self.steps[::2]
            self.serial += 1


def sse(event: str, data: Any) -> bytes:
    """One server-sent event."""
    return f"event: {event}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n".encode()


@dataclass
class Compiling:
    """A compilation under way, as its progress reports say (`fivebar_host.progress`)."""

    name: str
    started: float  # monotonic s
    on_change: Callable[[], None] | None = None  # wakes the event streams
    stage: str = "waiting for a compilation slot"
    fraction: float | None = None
    note: str | None = None

    def heard(self, ev: Event) -> None:
        """Take one progress report (from a compiling process, through its pipe)."""
        if ev.note is not None:
            self.note = ev.note
        else:
            self.stage, self.fraction = ev.stage, ev.fraction
        if self.on_change is not None:
            self.on_change()


class EventHub:
    """Wakes the open event streams when something changed (module docstring)."""

    def __init__(self, worker: WorkerHandle, store: JobStore, cache: CompiledCache,
                 profile: Profile, stopping: threading.Event,
                 jobs_view: Callable[[], dict[str, Any]]) -> None:
        self.worker = worker
        self.store = store
        self.cache = cache
        self.profile = profile
        self.stopping = stopping
        self.jobs_view = jobs_view
        self.trail = Trail()
        self.compiling: dict[int, Compiling] = {}  # compilations under way, by id
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed = asyncio.Event()
        self._pending = False
        self._draws: tuple[int, Any] | None = None  # (job id, its draw mask)
        worker.listeners.append(self.poke)
        store.listeners.append(self.poke)

    # ------------------------------------------------------------------ any thread
    def poke(self) -> None:
        """Something changed: record the running job's position, wake the streams."""
        self._record_trail()
        loop = self._loop
        if loop is None:
            return
        with self._lock:
            if self._pending:
                return
            self._pending = True
        with contextlib.suppress(RuntimeError):  # the loop closed: the daemon stops
            loop.call_soon_threadsafe(self._fire)

    def _record_trail(self) -> None:
        snap = self.worker.snapshot()
        live, st = snap.live, snap.status
        if live is None or st is None:
            return
        draws = self._draw_mask(live.job_id)
        seg = min(live.segments_done, live.segments_total - 1)
        drawing = bool(draws[seg]) if draws is not None and 0 <= seg < len(draws) else True
        with self._lock:
            self.trail.add(live.job_id, st.a, st.b, drawing)

    def _draw_mask(self, job_id: int) -> Any:
        cached = self._draws
        if cached is not None and cached[0] == job_id:
            return cached[1]
        job = self.cache.get(job_id)
        mask = None if job is None else np.asarray(job.draw)
        self._draws = (job_id, mask)
        return mask

    # ------------------------------------------------------------------ event loop
    def _fire(self) -> None:
        with self._lock:
            self._pending = False
        self._changed.set()
        self._changed = asyncio.Event()

    def status_event(self) -> dict[str, Any]:
        """The `status` event's data (without the trail)."""
        snap = self.worker.snapshot()
        machine = machine_view(snap, self.profile)
        changed_at = None
        if snap.connected and snap.status is not None:
            changed_at = time.time() - (time.monotonic() - snap.status_at)
        pos = machine.get("position")
        pose = None if pos is None else pose_mm(self.profile, pos["a"], pos["b"])
        live = snap.live
        blk = self.store.blocking()
        return {
            "machine": machine, "current_job": snap.current, "stopping": self.stopping.is_set(),
            "blocked_by": blk.id if blk is not None and blk.id != snap.current else None,
            "pose": None if pose is None else {"pen": pose.pen, "points": pose.points,
                                               "mode": pose.mode},
            "live": None if live is None else {
                "job_id": live.job_id, "segments_done": live.segments_done,
                "copy_number": live.copy,
                "segments_total": live.segments_total, "elapsed_s": round(live.elapsed_s, 2),
                "remaining_s": round(live.remaining_s, 2), "paused": live.paused,
                "overrides": {"feed_pct": live.feed_pct, "power_pct": live.power_pct}},
            "compiling": [{"name": c.name, "stage": c.stage, "progress": c.fraction,
                           "elapsed_s": round(time.monotonic() - c.started, 1),
                           "note": c.note} for c in list(self.compiling.values())],
            "changed_at": changed_at}

    def trail_since(self, serial: int, start: int
                    ) -> tuple[bool, int, int | None, int, list[list[float]]]:
        """The trail a stream has not sent: (whole, serial, job id, end, [[x, y, draws]]).

        `whole` when the trail restarted (or was thinned) since `serial`: then it is sent
        from its beginning; `end` is the index the stream has sent up to afterwards."""
        with self._lock:
            whole = serial != self.trail.serial
            new_serial, job_id = self.trail.serial, self.trail.job_id
            pts = self.trail.steps[0 if whole else start:]
            end = len(self.trail.steps)
        if not pts:
            return whole, new_serial, job_id, end, []
        arr = np.asarray(pts, dtype=np.int64)
        mo = self.profile.motors
        th = step_angles(arr[:, :2], mo.home_rad, mo.steps_per_rev)
        fk = self.profile.geometry.forward_batch(th, self.profile.kinematics.assembly)
        out = [[round(float(x), 3), round(float(y), 3), int(d)]
               for (x, y), d, ok in zip(fk.points, arr[:, 2], fk.valid, strict=True) if ok]
        return whole, new_serial, job_id, end, out

    async def stream(self, gone: Callable[[], Any]) -> AsyncIterator[bytes]:
        """The events of one client until it goes (`await gone()` is true) or the daemon
        stops."""
        self._loop = asyncio.get_running_loop()
        cur = _Cursor()
        yield b"retry: 1000\n\n"
        while not self.stopping.is_set():
            changed = self._changed  # taken before reading: a later poke wakes us
            for chunk in self._changes(cur):
                yield chunk
            try:
                await asyncio.wait_for(changed.wait(), CHECK_S)
            except TimeoutError:
                if await gone():
                    return
                if time.monotonic() - cur.sent_at > KEEPALIVE_S:
                    cur.sent_at = time.monotonic()
                    yield b": keepalive\n\n"
                continue
            wait = cur.sent_at + MIN_INTERVAL_S - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)

    def _changes(self, cur: _Cursor) -> list[bytes]:
        """The events that bring one stream up to date (and its cursor with them)."""
        out: list[bytes] = []
        version = self.store.version
        if version != cur.jobs_version:
            cur.jobs_version = version
            out.append(sse("jobs", self.jobs_view()))
        whole, cur.trail_serial, job_id, cur.trail_len, added = self.trail_since(
            cur.trail_serial, cur.trail_len)
        if whole:
            out.append(sse("trail", {"job_id": job_id, "points": added}))
            added = []
        status = self.status_event()
        key = json.dumps({k: v for k, v in status.items() if k != "changed_at"}
                         | {"machine": {k: v for k, v in status["machine"].items()
                                        if k != "status_age_s"}}, sort_keys=True)
        if key != cur.status_key or added:
            cur.status_key = key
            status["trail"] = added
            status["sent_at"] = time.time()
            out.append(sse("status", status))
        if out:
            cur.sent_at = time.monotonic()
        return out


@dataclass
class _Cursor:
    """What one stream has sent so far."""

    jobs_version: int = -1
    trail_serial: int = -1
    trail_len: int = 0
    status_key: str = ""
    sent_at: float = 0.0
