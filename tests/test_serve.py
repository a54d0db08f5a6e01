"""`fivebar serve` in-process on 127.0.0.1 (port 0) with the mock device, driven through real
HTTP requests: concurrent submissions, cancel, pause/resume, refused uploads, the token on a
non-loopback listener, browser protections, the OpenAPI description and `plot --server`."""

from __future__ import annotations

import http.client
import json
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from serve_support import wait_for

from fivebar_host.cli import main
from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.server.client import ServerClient, ServerError, follow, plot_options
from fivebar_host.server.daemon import Daemon, ServeConfig
from fivebar_host.server.security import SecurityError

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SQUARE = EXAMPLES / "square.gcode"
SIMPLE = EXAMPLES / "simple.svg"


@pytest.fixture
def start_daemon(tmp_path: Path) -> Iterator[Callable[..., Daemon]]:
    """Factory of in-process daemons (stopped at the end, mock machines forgotten)."""
    started: list[Daemon] = []

    def start(port_url: str, **kw: Any) -> Daemon:
        kw.setdefault("listen", "127.0.0.1:0")
        kw.setdefault("state_dir", tmp_path / f"state{len(started)}")
        kw.setdefault("banner_timeout_s", 1.0)
        d = Daemon(ServeConfig(port_url=port_url, **kw))
        d.start()
        started.append(d)
        return d

    yield start
    for d in started:
        d.stop(hurry=True, timeout_s=15.0)
    mock.forget_machines()


def plan_steps(path: Path) -> np.ndarray:
    """Steps per motor (absolute, summed over segments) the job plans."""
    job = compile_job(path, load_profile(None), CompileOptions())
    return np.abs(np.diff(job.steps, axis=0)).sum(axis=0)


def executed_steps(machine: str) -> np.ndarray:
    """Steps per motor the mock machine issued (absolute, summed over blocks)."""
    led = mock.machine(machine).ledger
    return np.array([sum(abs(e.steps[0]) for e in led if e.kind == "G1"),
                     sum(abs(e.steps[1]) for e in led if e.kind == "G1")])


def raw(url: str, method: str, path: str, body: bytes | None = None,
        headers: dict[str, str] | None = None) -> tuple[int, dict[str, Any]]:
    """One request with http.client (full control over headers)."""
    host, port = url.removeprefix("http://").rsplit(":", 1)
    conn = http.client.HTTPConnection(host.strip("[]"), int(port), timeout=30)
    try:
        conn.request(method, path, body=body, headers=headers or {})
        resp = conn.getresponse()
        data = resp.read()
        return resp.status, json.loads(data) if data else {}
    finally:
        conn.close()


def test_two_clients_submit_at_once(start_daemon: Callable[..., Daemon]) -> None:
    # the mock in real time, as a machine runs: the daemon must keep its queue fed (no
    # underrun) while it compiles the second submission in the same process; faster than
    # real time, the compilation's hold on the interpreter sometimes outlasted the queue
    d = start_daemon("fivebar-mock://?speed=1&machine=two")
    barrier = threading.Barrier(2)
    results: list[dict[str, Any]] = []
    errors: list[BaseException] = []

    def client(path: Path) -> None:
        try:
            c = ServerClient(d.url)
            data = path.read_bytes()
            barrier.wait()
            results.append(c.submit(data, path.name, plot_options(confirm=True)))
        except BaseException as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=client, args=(p,)) for p in (SQUARE, SIMPLE)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors, errors
    assert sorted(r["state"] for r in results) == ["queued", "queued"]
    ids = sorted(r["id"] for r in results)
    assert ids[0] != ids[1]
    c = ServerClient(d.url)
    done = [follow(c, i, lambda j: None, max_s=60) for i in ids]
    assert [j["state"] for j in done] == ["done", "done"], done
    assert all(j["segments_done"] == j["segments_total"] for j in done)
    assert all(j["underruns"] == 0 for j in done), done
    # one after the other, never interleaved
    first, second = sorted(done, key=lambda j: j["started_at"])
    assert second["started_at"] >= first["finished_at"]
    # the machine executed exactly both plans
    assert executed_steps("two").tolist() == (plan_steps(SQUARE) + plan_steps(SIMPLE)).tolist()
    listed = c.jobs()
    assert [j["id"] for j in listed] == ids


def test_cancel_mid_job_turns_laser_off_and_next_job_runs(
        start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=2&machine=cancel")
    c = ServerClient(d.url)
    a = c.submit(SQUARE.read_bytes(), "a.gcode", plot_options(laser=True, confirm=True))
    b = c.submit(SQUARE.read_bytes(), "b.gcode", plot_options(laser=True))
    m = mock.machine("cancel")
    wait_for(lambda: c.job(a["id"])["segments_done"] >= 40 and m.laser > 0, what="laser on")
    t_cancel = time.monotonic()
    c.cancel(a["id"])
    ja = wait_for(lambda: (j := c.job(a["id"]))["state"] == "cancelled" and j, what="cancel")
    # the laser went off at once (hold), well before the next job could switch it on again
    offs = [t for t, p in m.laser_log if t >= t_cancel and p == 0]
    assert offs and offs[0] - t_cancel < 0.3, m.laser_log[-5:]
    ons = [t for t, p in m.laser_log if t >= t_cancel and p > 0]
    assert not ons or ons[0] > offs[0]
    stopped = [e for e in m.ledger if e.stopped is not None]
    assert stopped and stopped[-1].stopped == "reset"  # held mid-segment, then reset
    assert "laser off" in ja["message"]
    assert 0 < ja["segments_done"] < ja["segments_total"]
    assert ja["resume"] is None
    jb = follow(c, b["id"], lambda j: None, max_s=60)
    assert jb["state"] == "done", jb
    assert m.laser == 0
    st = c.status()
    assert st["machine"]["laser"] == 0 and st["machine"]["position"] == {"a": 0, "b": 0}
    assert st["jobs"]["cancelled"] == 1 and st["jobs"]["done"] == 1


def test_pause_holds_with_laser_off_then_resume_finishes_exactly(
        start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=2&machine=pause")
    c = ServerClient(d.url)
    j = c.submit(SQUARE.read_bytes(), "sq.gcode", plot_options(laser=True, confirm=True))
    m = mock.machine("pause")
    wait_for(lambda: c.job(j["id"])["segments_done"] >= 30, what="progress")
    c.pause(j["id"])
    wait_for(lambda: c.job(j["id"])["state"] == "paused", what="paused")
    pos = c.status()["machine"]["position"]
    time.sleep(0.3)
    st = c.status()["machine"]
    assert st["state"] == "Hold" and st["laser"] == 0 and m.laser == 0
    assert st["position"] == pos  # frozen
    with pytest.raises(ServerError) as e:
        c.pause(12345)
    assert e.value.status == 404
    c.resume(j["id"])
    done = follow(c, j["id"], lambda x: None, max_s=60)
    assert done["state"] == "done"
    assert executed_steps("pause").tolist() == plan_steps(SQUARE).tolist()


def test_disconnect_recovered_exactly_from_the_record_kept_across_the_reset(
        start_daemon: Callable[..., Daemon]) -> None:
    """The link breaks mid-job; reconnecting resets the controller (as opening an Uno's port
    does), which keeps its position and last executed line: the daemon maps them to the exact
    segment and, with --auto-resume, finishes the job with nothing drawn twice."""
    d = start_daemon("fivebar-mock://?speed=2&machine=dc&disconnect_after=9",
                     auto_resume=True)
    c = ServerClient(d.url)
    j = c.submit(SQUARE.read_bytes(), "sq.gcode", plot_options(laser=True, confirm=True))
    # held at the fault; recovered and requeued once the worker has reconnected
    done = wait_for(lambda: (x := c.job(j["id"]))["state"] == "done" and x, timeout_s=60,
                    what="the job done after the reconnect")
    assert done["resume"] is None
    m = mock.machine("dc")
    # every reconnect (each new port breaks again after 9 wire lines) reset the controller;
    # with 20 the controller booted only once on this branch (cause not traced).  (8 left
    # too few for the stream once each new stream's first line numbers it past the kept
    # `Ln` done, `Link.number_past_kept`: a step a connection at some resume points.)
    assert m.boots >= 2 and m.laser == 0
    assert {e.stopped for e in m.ledger} <= {None, "reboot"}
    assert executed_steps("dc").tolist() == plan_steps(SQUARE).tolist()


def test_malformed_upload_refused_with_the_cli_message(
        start_daemon: Callable[..., Daemon], tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    d = start_daemon("fivebar-mock://?speed=10&machine=bad")
    c = ServerClient(d.url)
    bad = b'<?xml version="1.0"?>\n<svg xmlns="http://www.w3.org/2000/svg" width="10mm"\n' \
          b'  height="10mm"><path d="M 0 0 L 5 5"</svg>\n'
    with pytest.raises(ServerError) as e:
        c.submit(bad, "bad.svg", plot_options())
    assert e.value.status == 422 and e.value.error == "input_error"
    # the CLI says the same about the same file
    (tmp_path / "bad.svg").write_bytes(bad)
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["convert", "bad.svg", "-o", "out.gcode"])
    assert r.exit_code == 2
    assert f"error: {e.value}" in r.output
    # a drawing the machine cannot reach: the compiler's precise reason, nothing queued
    with pytest.raises(ServerError) as e2:
        c.submit(SQUARE.read_bytes(), "square.gcode", plot_options(scale=40.0))
    assert e2.value.status == 422 and e2.value.error == "job_error"
    assert e2.value.body["reason"] and "square.gcode" in str(e2.value)
    # not a drawing at all, an empty body, a path as name, a bad option, a simple type
    status, body = raw(d.url, "POST", "/api/jobs?name=x.gcode", b"\x00\xff\xfe garbage",
                       {"Content-Type": "text/x-gcode"})
    assert status == 422 and body["error"] == "input_error", body
    status, body = raw(d.url, "POST", "/api/jobs?name=x.svg", b"",
                       {"Content-Type": "image/svg+xml"})
    assert status == 400 and body["error"] == "empty_upload"
    status, body = raw(d.url, "POST", "/api/jobs?name=../../etc/x.svg", SIMPLE.read_bytes(),
                       {"Content-Type": "image/svg+xml"})
    assert status == 400 and body["error"] == "bad_name" and "no directories" in body["message"]
    status, body = raw(d.url, "POST", "/api/jobs?name=x.svg&tolerance=99",
                       SIMPLE.read_bytes(), {"Content-Type": "image/svg+xml"})
    assert status == 422 and body["error"] == "bad_option" and "tolerance" in body["message"]
    status, body = raw(d.url, "POST", "/api/jobs?name=x.svg", SIMPLE.read_bytes(),
                       {"Content-Type": "text/plain"})
    assert status == 415 and body["error"] == "bad_content_type"
    assert c.jobs() == []


def test_oversized_upload_refused(start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=10&machine=big", max_upload_bytes=64 * 1024)
    big = b"; padding\n" * 10_000  # 100 kB of G-code comments
    status, body = raw(d.url, "POST", "/api/jobs?name=big.gcode", big,
                       {"Content-Type": "text/x-gcode"})
    assert status == 413 and body["error"] == "too_large"
    assert "65536" in body["message"]
    # the same without Content-Length (chunked): counted while read, still refused
    host, port = d.url.removeprefix("http://").rsplit(":", 1)
    conn = http.client.HTTPConnection(host, int(port), timeout=30)
    conn.request("POST", "/api/jobs?name=big.gcode", body=iter([big[:40_000], big[40_000:]]),
                 headers={"Content-Type": "text/x-gcode"}, encode_chunked=True)
    resp = conn.getresponse()
    assert resp.status == 413 and json.loads(resp.read())["error"] == "too_large"
    conn.close()
    # small bodies elsewhere
    status, body = raw(d.url, "POST", "/api/jobs/1/cancel", b"x" * 100_000,
                       {"Content-Type": "application/json"})
    assert status == 413
    assert ServerClient(d.url).jobs() == []


def test_non_loopback_listener_requires_the_token(start_daemon: Callable[..., Daemon],
                                                  tmp_path: Path) -> None:
    # Listens on every interface; the requests below go to 127.0.0.1 only.
    d = start_daemon("fivebar-mock://?speed=10&machine=tok", listen="0.0.0.0:0")
    port = d.url.rsplit(":", 1)[1]
    local = f"http://127.0.0.1:{port}"
    assert d.token_path is not None and d.token is not None
    assert (d.token_path.stat().st_mode & 0o777) == 0o600
    assert ((d.state_dir / "fivebar.db").stat().st_mode & 0o777) == 0o600
    for path in ("/api/status", "/api/jobs", "/openapi.json"):
        status, body = raw(local, "GET", path)
        assert status == 401 and body["error"] == "unauthorized", path
    status, _ = raw(local, "GET", "/api/status", headers={"Authorization": "Bearer nope"})
    assert status == 401
    status, _ = raw(local, "POST", "/api/jobs?name=s.svg", SIMPLE.read_bytes(),
                    {"Content-Type": "image/svg+xml"})
    assert status == 401
    assert ServerClient(local, token=d.token).status()["jobs"]["queued"] == 0
    # the token survives a restart (same state directory) and is not regenerated
    token = d.token
    d.stop(hurry=True)
    d2 = start_daemon("fivebar-mock://?speed=10&machine=tok2", listen="127.0.0.1:0",
                      state_dir=d.state_dir, require_token=True)
    assert d2.token == token
    assert raw(d2.url, "GET", "/api/status")[0] == 401
    d2.stop(hurry=True)
    # a token file others can read protects nothing: refused, naming the fix
    d.token_path.chmod(0o644)
    with pytest.raises(SecurityError, match="chmod 600"):
        start_daemon("fivebar-mock://?speed=10&machine=tok3", state_dir=d.state_dir)


def test_loopback_listener_refuses_foreign_hosts_and_origins(
        start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=10&machine=web")
    assert d.token is None
    port = d.url.rsplit(":", 1)[1]
    status, body = raw(d.url, "GET", "/api/status", headers={"Host": f"evil.example:{port}"})
    assert status == 421 and body["error"] == "bad_host"
    status, body = raw(d.url, "POST", "/api/jobs?name=s.svg", SIMPLE.read_bytes(),
                       {"Content-Type": "image/svg+xml", "Origin": "http://evil.example"})
    assert status == 403 and body["error"] == "cross_origin"
    status, _ = raw(d.url, "GET", "/api/status", headers={"Origin": d.url})
    assert status == 200


def test_openapi_describes_the_api(start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=10&machine=oa")
    status, spec = raw(d.url, "GET", "/openapi.json")
    assert status == 200 and spec["openapi"].startswith("3.")
    paths = spec["paths"]
    for p in ("/api/status", "/api/jobs", "/api/jobs/{job_id}", "/api/jobs/{job_id}/pause",
              "/api/jobs/{job_id}/resume", "/api/jobs/{job_id}/cancel", "/api/machine/home"):
        assert p in paths, p
    post = paths["/api/jobs"]["post"]
    assert "image/svg+xml" in post["requestBody"]["content"]
    assert {"name", "laser", "mode", "tolerance", "origin", "layer"} <= {
        q["name"] for q in post["parameters"]}
    status, body = raw(d.url, "GET", "/api/jobs/99")
    assert status == 404 and body == {"error": "not_found", "message": "no job 99"}


def test_held_until_the_home_pose_is_confirmed(start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=10&machine=ask")
    c = ServerClient(d.url)
    j = c.submit(SQUARE.read_bytes(), "sq.gcode", plot_options())  # no confirm
    held = wait_for(lambda: (x := c.job(j["id"]))["state"] == "held" and x, what="held")
    assert "home pose" in held["question"] and "nothing has moved" in held["message"]
    assert executed_steps("ask").tolist() == [0, 0]
    # a second job waits behind the held one
    j2 = c.submit(SQUARE.read_bytes(), "sq2.gcode", plot_options(confirm=True))
    time.sleep(0.5)
    assert c.job(j2["id"])["state"] == "queued"
    assert c.status()["blocked_by"] == j["id"]
    c.resume(j["id"], confirm=True)
    assert follow(c, j["id"], lambda x: None, max_s=60)["state"] == "done"
    assert follow(c, j2["id"], lambda x: None, max_s=60)["state"] == "done"


def test_plot_server_follows_with_a_progress_bar(start_daemon: Callable[..., Daemon]) -> None:
    d = start_daemon("fivebar-mock://?speed=10&machine=cli")
    r = CliRunner().invoke(main, ["plot", str(SQUARE), "--server", d.url, "--yes"])
    assert r.exit_code == 0, r.output
    assert "job 1 queued" in r.output and "plotting" in r.output
    n = compile_job(SQUARE, load_profile()).n_segments
    assert f"done: {n} segments" in r.output  # (no terminal: the bar shows its label only)
    # refused drawing: the compiler's message, exit status 2, nothing queued
    r = CliRunner().invoke(main, ["plot", str(SQUARE), "--server", d.url, "--scale", "40"])
    assert r.exit_code == 2 and "error: " in r.output and "square.gcode" in r.output
    r = CliRunner().invoke(main, ["plot", str(SQUARE), "--server", d.url, "--port", "x"])
    assert r.exit_code == 2 and "drop --port" in r.output
    assert len(ServerClient(d.url).jobs()) == 1


def test_missing_port_is_reported_and_jobs_wait(start_daemon: Callable[..., Daemon],
                                                tmp_path: Path) -> None:
    d = start_daemon(str(tmp_path / "no-such-tty"))
    c = ServerClient(d.url)
    m = wait_for(lambda: (x := c.status()["machine"])["error"] != "not connected yet" and x,
                 what="connection attempt")
    assert not m["connected"] and "no-such-tty" in m["error"]
    j = c.submit(SQUARE.read_bytes(), "sq.gcode", plot_options(confirm=True))
    time.sleep(0.3)
    assert c.job(j["id"])["state"] == "queued"
    c.cancel(j["id"])
    assert c.job(j["id"])["state"] == "cancelled"
    with pytest.raises(ServerError) as e:
        c.cancel(j["id"])
    assert e.value.status == 409 and "already cancelled" in str(e.value)


def test_unknown_options_are_refused_and_options_are_declared_once(
        start_daemon: Callable[..., Daemon]) -> None:
    """An unknown query parameter is an error on every route (`scael=2` is never queued
    with the scale left out), and the OpenAPI parameters are the option definitions."""
    from fivebar_host.options import BY_NAME, JOB_OPTIONS

    d = start_daemon("fivebar-mock://?speed=10&machine=opts")
    status, body = raw(d.url, "POST", "/api/jobs?name=x.svg&scael=2", SIMPLE.read_bytes(),
                       {"Content-Type": "image/svg+xml"})
    assert status == 422 and body["error"] == "bad_option", body
    assert "scael" in body["message"] and "did you mean 'scale'" in body["message"]
    status, body = raw(d.url, "GET", "/api/jobs?limt=3")
    assert status == 422 and body["error"] == "bad_option" and "limt" in body["message"]
    status, body = raw(d.url, "GET", "/api/jobs")
    assert status == 200 and body == []
    status, spec = raw(d.url, "GET", "/openapi.json")
    params = {p["name"]: p for p in spec["paths"]["/api/jobs"]["post"]["parameters"]}
    for opt in JOB_OPTIONS:
        assert params[opt.query]["description"] == opt.describe()
    tol = params["tolerance"]["schema"]
    assert (tol["minimum"], tol["maximum"]) == (BY_NAME["tolerance_mm"].lo,
                                                BY_NAME["tolerance_mm"].hi)


def test_path_of_an_uncached_job_compiles_outside_the_streaming_daemon(
        start_daemon: Callable[..., Daemon], monkeypatch: pytest.MonkeyPatch) -> None:
    """The live view's path of a job the cache lost (a restart) is compiled again in a
    compilation slot and a compiling process, as a submission is, and then cached: never in
    the daemon's own threads, where it would starve the stream of the running job."""
    d = start_daemon("fivebar-mock://?speed=0.5&machine=pathc")
    c = ServerClient(d.url)
    running = c.submit(SQUARE.read_bytes(), "square.gcode", plot_options(confirm=True))
    waiting = c.submit(SIMPLE.read_bytes(), "simple.svg", plot_options(confirm=True))
    assert d.cache is not None
    d.cache.drop(waiting["id"])

    def in_daemon(*args: Any) -> Any:
        raise AssertionError("compiled in the daemon")

    monkeypatch.setattr("fivebar_host.server.stored.compile_upload", in_daemon)
    status, body = raw(d.url, "GET", f"/api/jobs/{waiting['id']}/path")
    assert status == 200, body
    job = compile_job(SIMPLE, load_profile(None), CompileOptions())
    step = max(1, -(-job.n_segments // 4000))
    assert len(body["points"]) == len(job.points_mm[::step])
    assert np.allclose([p[:2] for p in body["points"]], job.points_mm[::step], atol=0.006)
    assert d.cache.get(waiting["id"]) is not None  # the machine thread uses it
    for j in (running, waiting):
        c.cancel(j["id"])
