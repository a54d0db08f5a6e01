"""The API behind the web page, without a browser: the option definitions, the dry run, the
queue order (store and route, and the schema 1 → 2 migration), the event stream, the page's
files served without the token, and the machine panel's jog and motors off on the mock."""

from __future__ import annotations

import base64
import http.client
import json
import sqlite3
import time
from pathlib import Path
from typing import Any

from fivebar_host.compile import nbar_opinion
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.options import JOB_OPTIONS
from fivebar_host.report.text.dryrun import report_lines
from fivebar_host.server import store as st_
from fivebar_host.server.client import ServerClient, ServerError, plot_options
from fivebar_host.server.jobs import JobOptions, compile_upload
from fivebar_host.server.store import JobStore
from tests.serve_support import running_daemon, send

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SVG = {"Content-Type": "image/svg+xml"}
GCODE = {"Content-Type": "text/x-gcode"}


def _json(raw: Any) -> Any:
    return json.loads(raw.body)


def test_options_are_the_single_definitions(tmp_path: Path) -> None:
    with running_daemon(tmp_path / "s", "w-opt") as d:
        r = send(d.url, "GET", "/api/options")
        assert r.status == 200
        body = _json(r)
    assert [o["query"] for o in body["options"]] == [o.query for o in JOB_OPTIONS]
    tol = next(o for o in body["options"] if o["name"] == "tolerance_mm")
    assert (tol["min"], tol["max"], tol["unit"], tol["kind"]) == (1e-4, 10.0, "mm", "float")
    assert body["features"] == {"endstops": False, "pen": False, "motors_off": True,
                                "jog": True}


def test_dry_run_is_the_cli_report_and_queues_nothing(tmp_path: Path) -> None:
    data = (EXAMPLES / "simple.svg").read_bytes()
    with running_daemon(tmp_path / "s", "w-dry") as d:
        r = send(d.url, "POST", "/api/dryrun?name=simple.svg&tolerance=0.1", data, SVG)
        assert r.status == 200, r.body
        out = _json(r)
        far = b"G21\nG90\nG0 X0 Y100\nG1 X0 Y100 F600\nG1 X300 Y100\n"
        bad = send(d.url, "POST", "/api/dryrun?name=far.gcode&origin=0,0", far, GCODE)
        assert ServerClient(d.url).jobs() == []
        assert not mock.machine("w-dry").ledger
    prof = load_profile(None)
    job = compile_upload(data, "simple.svg", JobOptions(tolerance_mm=0.1), prof).job
    assert out["report"] == report_lines(job, nbar_opinion(job, prof), profile=prof)
    assert out["segments"] == job.n_segments and out["tolerance_mm"] == 0.1
    assert base64.b64decode(out["preview_png"]).startswith(b"\x89PNG\r\n\x1a\n")
    assert bad.status == 422
    err = _json(bad)
    assert err["error"] == "job_error" and err["reason"] == "reach"
    assert err["message"].startswith("far.gcode:5, path #0")


def test_move_reorders_waiting_jobs(tmp_path: Path) -> None:
    data = (EXAMPLES / "square.gcode").read_bytes()
    with running_daemon(tmp_path / "s", "w-move") as d:
        c = ServerClient(d.url)
        first = c.submit(data, "held.gcode", plot_options())["id"]  # held: the pose question
        deadline = time.monotonic() + 10
        while c.job(first)["state"] != "held" and time.monotonic() < deadline:
            time.sleep(0.02)
        ids = [c.submit(data, f"{k}.gcode", plot_options())["id"] for k in range(3)]
        r = send(d.url, "POST", f"/api/jobs/{ids[2]}/move?index=0")
        assert r.status == 200 and _json(r) == {"queue": [ids[2], ids[0], ids[1]]}
        r = send(d.url, "POST", f"/api/jobs/{ids[0]}/move?index=99")
        assert _json(r) == {"queue": [ids[2], ids[1], ids[0]]}
        r = send(d.url, "POST", f"/api/jobs/{first}/move?index=0")
        assert r.status == 409 and "only a waiting job can be moved" in _json(r)["message"]
        assert send(d.url, "POST", f"/api/jobs/{ids[0]}/move?index=-1").status == 422
        c.home(at_home=True)  # between jobs: the held one is not running
        c.cancel(first)
        deadline = time.monotonic() + 20
        while c.job(ids[2])["state"] == "queued" and time.monotonic() < deadline:
            time.sleep(0.02)
        assert c.job(ids[2])["state"] in ("running", "done")
        assert c.job(ids[1])["state"] == "queued" or c.job(ids[1])["started_at"] >= \
            c.job(ids[2])["started_at"]


def test_store_schema_1_gains_the_queue_order(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    db = sqlite3.connect(path)
    schema = st_._SCHEMA.replace(",\n    queue_key REAL", "")
    db.executescript(schema)
    db.execute("PRAGMA user_version=1")
    db.commit()
    db.close()
    store = JobStore(path)
    try:
        ids = [store.add_job(name=f"{k}", options={}, upload=b"x", upload_sha256="0",
                             fingerprint="f", mode="+-", max_dev_mm=None, segments_total=1,
                             estimated_s=1.0).id for k in range(3)]
        assert store.queue_order() == ids
        assert store.move(ids[1], 0) == [ids[1], ids[0], ids[2]]
        assert store.next_queued().id == ids[1]  # type: ignore[union-attr]
        assert store.move(12345, 0) is None
    finally:
        store.close()


def test_page_files_without_token_api_with_it(tmp_path: Path) -> None:
    with running_daemon(tmp_path / "s", "w-tok", require_token=True) as d:
        page = send(d.url, "GET", "/")
        assert page.status == 200 and b"/static/app.js" in page.body
        assert "default-src 'self'" in page.headers["content-security-policy"]
        js = send(d.url, "GET", "/static/app.js")
        assert js.status == 200 and js.headers["content-type"].startswith("text/javascript")
        assert send(d.url, "GET", "/static/../token").status in (401, 404)
        assert send(d.url, "GET", "/static/nope.js").status == 404
        assert send(d.url, "GET", "/api/options").status == 401
        assert send(d.url, "GET", "/api/events").status == 401
        assert send(d.url, "POST", "/").status == 401
        auth = {"Authorization": f"Bearer {d.token}"}
        assert send(d.url, "GET", "/api/options", headers=auth).status == 200


def _events(url: str, until: Any, timeout_s: float = 10.0) -> list[tuple[str, Any]]:
    """Read the event stream until `until(events)` holds."""
    host, port = url.removeprefix("http://").rsplit(":", 1)
    conn = http.client.HTTPConnection(host, int(port), timeout=timeout_s)
    events: list[tuple[str, Any]] = []
    try:
        conn.request("GET", "/api/events")
        resp = conn.getresponse()
        assert resp.status == 200
        assert resp.headers["content-type"].startswith("text/event-stream")
        name, deadline = "", time.monotonic() + timeout_s
        while not until(events) and time.monotonic() < deadline:
            line = resp.fp.readline().decode().rstrip("\n")
            if line.startswith("event: "):
                name = line[7:]
            elif line.startswith("data: "):
                events.append((name, json.loads(line[6:])))
    finally:
        conn.close()
    return events


def test_event_stream_pushes_jobs_status_and_trail(tmp_path: Path) -> None:
    data = (EXAMPLES / "square.gcode").read_bytes()
    with running_daemon(tmp_path / "s", "w-ev") as d:
        first = _events(d.url, lambda ev: {"jobs", "trail"} <= {n for n, _ in ev} and any(
            n == "status" and v["machine"]["connected"] for n, v in ev))
        status = next(v for n, v in first if n == "status" and v["machine"]["connected"])
        assert status["pose"]["mode"] == "+-" and status["changed_at"] <= time.time()
        assert abs(status["pose"]["pen"][0] - 20.0) < 1e-6  # the home pose of the profile
        c = ServerClient(d.url)
        job = c.submit(data, "sq.gcode", plot_options(confirm=True))["id"]

        def finished(ev: list[tuple[str, Any]]) -> bool:
            return any(n == "jobs" and any(j["id"] == job and j["state"] == "done"
                                           for j in v["jobs"]) for n, v in ev)

        events = _events(d.url, finished, timeout_s=20)
    assert finished(events)
    trail = [p for n, v in events if n == "status" for p in v["trail"]]
    trail += [p for n, v in events if n == "trail" for p in v["points"]]
    assert len(trail) > 10 and all(len(p) == 3 for p in trail)
    lives = [v["live"]["segments_done"] for n, v in events if n == "status" and v["live"]]
    assert lives and lives == sorted(lives)


def test_jog_and_motors_off(tmp_path: Path) -> None:
    with running_daemon(tmp_path / "s", "w-jog") as d:
        c = ServerClient(d.url)
        time.sleep(0.3)
        try:
            c.request("POST", "/api/machine/jog", query={"dx": "5"})
            raise AssertionError("a pen jog before homing must be refused")
        except ServerError as e:
            assert e.status == 409 and "home the machine first" in str(e)
        c.home(at_home=True)
        out = c.request("POST", "/api/machine/jog", query={"dx": "5", "dy": "-3"})
        assert out["position"] != {"a": 0, "b": 0} and out["pose_known"]
        bad = send(d.url, "POST", "/api/machine/jog?dx=500")
        assert bad.status == 422 and _json(bad)["error"] == "bad_option"
        home = c.home(at_home=True)
        prof = load_profile(None)
        want = prof.geometry.forward(prof.motors.home_rad, prof.kinematics.assembly)
        assert home["position"] == {"a": 0, "b": 0}
        assert abs(home["position_mm"]["x"] - want[0]) < 1e-3
        assert abs(home["position_mm"]["y"] - want[1]) < 1e-3
        off = c.request("POST", "/api/machine/motors_off")
        assert off["motors_off"] and not off["pose_known"] and off["position_mm"] is None
        led = mock.machine("w-jog").ledger
        assert led[-1].kind == "M18"
        out = c.request("POST", "/api/machine/jog", query={"motor": "B", "steps": "-40"})
        assert not out["motors_off"]
        kinds = [e.kind for e in mock.machine("w-jog").ledger]
        assert kinds[kinds.index("M18") + 1] == "M17"
        assert out["position"]["b"] == off["position"]["b"] - 40


def _wait_connected(c: ServerClient, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not c.status()["machine"]["connected"]:
        assert time.monotonic() < deadline, "the daemon did not connect to the mock"
        time.sleep(0.05)


def test_pen_up_and_down_from_the_page_on_a_pen_machine(tmp_path: Path) -> None:
    """The machine panel's pen buttons (`POST /api/machine/pen`): the profile's pulses reach
    the mock's servo; a laser machine refuses them with the reason."""
    pen_profile = EXAMPLES.parent / "configs" / "pen-servo.toml"
    pen = load_profile(pen_profile).pen
    assert pen is not None
    with running_daemon(tmp_path / "p", "w-pen", profile_path=pen_profile) as d:
        c = ServerClient(d.url)
        _wait_connected(c)
        opts = c.request("GET", "/api/options")
        assert opts["features"]["pen"] is True
        c.request("POST", "/api/machine/pen", query={"down": "true"})
        servo = mock.machine("w-pen").pen
        assert servo.down and servo.target == pen.pulse_us(pen.down_position)
        c.request("POST", "/api/machine/pen", query={"down": "false"})
        assert not mock.machine("w-pen").pen.down
        bad = send(d.url, "POST", "/api/machine/pen")
        assert bad.status == 422 and _json(bad)["error"] == "bad_option"
    with running_daemon(tmp_path / "l", "w-laser") as d:
        _wait_connected(ServerClient(d.url))
        refused = send(d.url, "POST", "/api/machine/pen?down=true")
        assert refused.status == 409 and "no [pen] table" in _json(refused)["message"]
        assert all(e.kind != "M280" for e in mock.machine("w-laser").ledger)
