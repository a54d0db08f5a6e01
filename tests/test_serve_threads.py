"""The daemon's machine state has one owner (issue 31): whatever other threads ask — pause,
overrides, resume, cancel, home, jog, motors off from HTTP handlers, the stop from the
daemon's own thread — only the machine thread writes the worker, its record, the running
job's live progress and overrides, and the link. Every attribute write on those objects is
recorded with the thread that made it while a daemon on the mock machine is driven through
all of its requests."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import pytest
from serve_support import running_daemon, wait_for

from fivebar_host.run.overrides import Overrides
from fivebar_host.server.client import ServerClient, ServerError, plot_options
from fivebar_host.server.control import JobControl
from fivebar_host.server.jobrun import JobRunner
from fivebar_host.server.journal import JournalLink
from fivebar_host.server.manual import Manual
from fivebar_host.server.pose import PoseKeeper
from fivebar_host.server.recovery import Recovery
from fivebar_host.server.state import Live, MachineRecord
from fivebar_host.server.worker import Worker

SQUARE = Path(__file__).resolve().parent.parent / "examples" / "square.gcode"
#: The classes whose instances hold the machine thread's state.
OWNED = (Worker, MachineRecord, Live, Overrides, JournalLink, JobRunner, JobControl, Manual,
         Recovery, PoseKeeper)
#: What `threading.Thread` itself writes (`join` marks a thread stopped from the joiner).
THREAD_INTERNALS = frozenset(vars(threading.Thread()))

Write = tuple[str, str, str]  # class, attribute, writing thread


def spy_on_writes(monkeypatch: pytest.MonkeyPatch, recording: threading.Event
                  ) -> list[Write]:
    """Record every attribute write on instances of `OWNED` while `recording` is set."""
    writes: list[Write] = []
    for cls in OWNED:
        def spy(self: Any, name: str, value: Any, _orig: Any = cls.__setattr__,
                _cls: str = cls.__name__) -> None:
            if recording.is_set() and name not in THREAD_INTERNALS:
                writes.append((_cls, name, threading.current_thread().name))
            _orig(self, name, value)

        monkeypatch.setattr(cls, "__setattr__", spy)
    return writes


def drive(c: ServerClient) -> None:
    """Every request the daemon takes from other threads, on one job and between jobs."""
    held = c.submit(SQUARE.read_bytes(), "held.gcode", plot_options())  # asks: held
    wait_for(lambda: c.job(held["id"])["state"] == "held", what="held with a question")
    c.resume(held["id"], confirm=True)
    wait_for(lambda: c.job(held["id"])["segments_done"] >= 10, what="progress")
    c.pause(held["id"])
    wait_for(lambda: c.job(held["id"])["state"] == "paused", what="paused")
    c.request("POST", f"/api/jobs/{held['id']}/overrides", query={"feed": "50"})
    with pytest.raises(ServerError) as e:
        c.home(at_home=True)
    assert e.value.status == 409  # a job is current: refused by the machine thread
    waiting = c.submit(SQUARE.read_bytes(), "waiting.gcode", plot_options(confirm=True))
    assert c.cancel(waiting["id"])["state"] == "cancelled"
    c.resume(held["id"])
    wait_for(lambda: c.job(held["id"])["state"] == "running", what="running again")
    c.cancel(held["id"])
    wait_for(lambda: c.job(held["id"])["state"] == "cancelled", what="cancelled")
    c.home(at_home=True)
    c.request("POST", "/api/machine/jog", query={"motor": "A", "steps": "10"})
    c.request("POST", "/api/machine/motors_off")


def test_only_the_machine_thread_writes_the_machine_state(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    recording = threading.Event()
    writes = spy_on_writes(monkeypatch, recording)
    with running_daemon(tmp_path, "owner", speed=2) as d:
        recording.set()
        drive(ServerClient(d.url))
    # leaving the block stopped the daemon from this thread (the stop request)
    others = sorted({w for w in writes if w[2] != "fivebar-machine"})
    assert others == [], others
    written = {(cls, name) for cls, name, _ in writes}
    assert {("MachineRecord", "request"), ("MachineRecord", "terminate"),
            ("MachineRecord", "motors_off"), ("MachineRecord", "pose_known"),
            ("MachineRecord", "current"), ("Live", "paused"),
            ("Overrides", "feed_pct")} <= written, written
