"""Bursts of simultaneous submissions to a daemon on loopback: up to the documented limits
they queue (they wait for a compilation slot), past them the refusal is the documented JSON
`busy` with Retry-After — never uvicorn's plain-text 503 — and the store holds exactly the
accepted jobs plus the ones queued before (nothing lost).

Before the fix, uvicorn's `limit_concurrency=128` counted open connections: 200 connections
opened at once got 21 accepted and 179 plain-text "Service Unavailable"."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import pytest
from serve_support import running_daemon, send

from benchmarks.serve_burst import SMALL_GCODE, burst
from fivebar_host.devices import mock
from fivebar_host.server import security
from fivebar_host.server.client import ServerClient, ServerError, plot_options
from fivebar_host.server.daemon import Daemon
from fivebar_host.server.routes import submit as submit_module

GCODE = {"Content-Type": "text/x-gcode"}


def stored(d: Daemon) -> dict[str, int]:
    """Jobs per state in the daemon's store."""
    assert d.store is not None
    return d.store.counts()


def queue_held_job(d: Daemon) -> int:
    """Queue a job that is held (it asks for the home pose): it blocks the queue, so nothing
    moves, and it must still be there after the burst."""
    ans = send(d.url, "POST", "/api/jobs?name=first.gcode", SMALL_GCODE, GCODE)
    assert ans.status == 201, ans
    return int(json.loads(ans.body)["id"])


def test_200_simultaneous_submissions_are_all_queued(tmp_path: Path) -> None:
    with running_daemon(tmp_path, "burst200") as d:
        first = queue_held_job(d)
        r = burst(d.url, 200, SMALL_GCODE)
        print(f"200 simultaneous submissions: {len(r.accepted)} accepted, "
              f"{len(r.refused)} refused, {len(r.other)} other, {r.seconds:.1f} s")
        assert r.other == []  # no plain text, no error, no lost connection
        assert len(r.accepted) == 200 and r.refused == []  # 200 < the documented 256
        ids = {json.loads(a.body)["id"] for a in r.accepted}
        assert len(ids) == 200 and first not in ids
        counts = stored(d)
        assert sum(counts.values()) == 201 and counts["held"] == 1, counts
        assert d.store is not None and d.store.get(first) is not None
        assert mock.machine("burst200").ledger == []


def test_past_the_upload_limit_the_refusal_is_json_busy_with_retry_after(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """With room for 20 uploads and compilations held until every other submission has
    been answered, exactly 20 are queued and 180 refused, each with the JSON answer."""
    gate = threading.Event()
    refusals = [0]
    real_compile, real_busy = submit_module.compile_upload, security._busy

    def slow_compile(*args: Any) -> Any:
        gate.wait(60)
        return real_compile(*args)

    async def counting_busy(send_: Any, message: str) -> None:
        refusals[0] += 1
        if refusals[0] == 180:
            gate.set()
        await real_busy(send_, message)

    with running_daemon(tmp_path, "burst20", max_uploads=20, compile_processes=False) as d:
        first = queue_held_job(d)
        monkeypatch.setattr(submit_module, "compile_upload", slow_compile)
        monkeypatch.setattr(security, "_busy", counting_busy)
        r = burst(d.url, 200, SMALL_GCODE)
        gate.set()
        assert r.other == []
        assert (len(r.accepted), len(r.refused)) == (20, 180)
        for a in r.refused:
            doc = json.loads(a.body)
            assert doc["error"] == "busy" and "nothing was queued" in doc["message"]
            assert int(a.headers["retry-after"]) >= 1
        counts = stored(d)
        assert sum(counts.values()) == 21 and counts["held"] == 1, counts
        assert d.store is not None and d.store.get(first) is not None
        assert mock.machine("burst20").ledger == []


def hold_compilation(monkeypatch: pytest.MonkeyPatch) -> tuple[threading.Event,
                                                                threading.Event]:
    """Make every compilation wait for `gate` (set `entered` when one starts); the daemon
    must compile in threads (`compile_processes=False`) for the replacement to apply."""
    gate, entered = threading.Event(), threading.Event()
    real_compile = submit_module.compile_upload

    def slow_compile(*args: Any) -> Any:
        entered.set()
        gate.wait(60)
        return real_compile(*args)

    monkeypatch.setattr(submit_module, "compile_upload", slow_compile)
    return gate, entered


def test_a_submission_that_waits_too_long_for_a_slot_is_refused_busy(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    gate, entered = hold_compilation(monkeypatch)
    monkeypatch.setattr(submit_module, "SUBMIT_WAIT_S", 0.3)
    with running_daemon(tmp_path, "wait", compile_slots=1, compile_processes=False) as d:
        answers: list[Any] = []
        holder = threading.Thread(target=lambda: answers.append(
            send(d.url, "POST", "/api/jobs?name=a.gcode", SMALL_GCODE, GCODE)))
        holder.start()
        assert entered.wait(30)  # the first one holds the only slot
        # the second one waits behind the held compilation, then gives up
        late = send(d.url, "POST", "/api/jobs?name=b.gcode", SMALL_GCODE, GCODE)
        gate.set()
        holder.join(30)
        assert late.status == 503 and json.loads(late.body)["error"] == "busy", late
        assert late.headers["retry-after"].isdigit()
        assert answers and answers[0].status == 201, answers
        assert sum(stored(d).values()) == 1


def test_the_client_submits_again_after_a_busy_refusal(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`ServerClient.submit` (and so `plot --server`) waits Retry-After and tries again: the
    refusal queued nothing, so the drawing is queued exactly once."""
    gate, entered = hold_compilation(monkeypatch)
    with running_daemon(tmp_path, "retry", max_uploads=1, compile_processes=False) as d:
        answers: list[Any] = []
        holder = threading.Thread(target=lambda: answers.append(
            send(d.url, "POST", "/api/jobs?name=a.gcode", SMALL_GCODE, GCODE)))
        holder.start()
        assert entered.wait(30)  # the one upload allowed is in progress
        refused = send(d.url, "POST", "/api/jobs?name=b.gcode", SMALL_GCODE, GCODE)
        assert refused.status == 503 and json.loads(refused.body)["error"] == "busy"
        c = ServerClient(d.url)
        with pytest.raises(ServerError) as e:
            c.submit(SMALL_GCODE, "c.gcode", plot_options(), busy_retries=0)
        assert e.value.error == "busy" and e.value.retry_after_s == security.RETRY_AFTER_S
        threading.Timer(0.5, gate.set).start()
        job = c.submit(SMALL_GCODE, "d.gcode", plot_options())  # refused, waits, retried
        holder.join(30)
        assert answers[0].status == 201 and job["name"] == "d.gcode"
        assert [j["name"] for j in c.jobs()] == ["a.gcode", "d.gcode"]
