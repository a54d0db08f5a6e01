"""The daemon's live overrides (`POST /api/jobs/{id}/overrides`) on the mock machine: a power
change reaches the later lines only, the job shows its overrides while it runs, refusals
(range, unknown job, finished job) answer in the API's error format, and the page has the
controls."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from serve_support import running_daemon, send, wait_for

from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.server.client import ServerClient, plot_options

SIMPLE = Path(__file__).resolve().parent.parent / "examples" / "simple.svg"


def post(url: str, target: str) -> tuple[int, dict[str, Any]]:
    r = send(url, "POST", target)
    return r.status, json.loads(r.body)


def test_power_override_reaches_later_lines_only(tmp_path: Path) -> None:
    full = load_profile(None).laser.power
    with running_daemon(tmp_path, "ov-api", speed=2.0) as d:
        c = ServerClient(d.url)
        j = c.submit(SIMPLE.read_bytes(), "simple.svg", plot_options(laser=True, confirm=True))
        jid = j["id"]
        assert j["overrides"] is None  # queued
        wait_for(lambda: c.job(jid)["state"] == "running" and c.job(jid)["segments_done"] >= 30,
                 timeout_s=30.0, what="job running")
        assert c.job(jid)["overrides"] == {"feed_pct": 100, "power_pct": 100}
        status, body = post(d.url, f"/api/jobs/{jid}/overrides?power=50")
        assert status == 200, body
        assert body["id"] == jid and body["overrides"] == {"feed_pct": 100, "power_pct": 50}
        status, body = post(d.url, f"/api/jobs/{jid}/overrides?feed=80")
        assert status == 200 and body["overrides"] == {"feed_pct": 80, "power_pct": 50}
        assert c.job(jid)["overrides"] == {"feed_pct": 80, "power_pct": 50}

        # refusals, in the API's error format
        for q in ("power=101", "power=-1", "feed=5", "feed=101", "feed=half"):
            status, body = post(d.url, f"/api/jobs/{jid}/overrides?{q}")
            assert status == 422 and body["error"] == "bad_option", (q, body)
        # neither: nothing changes (what the OpenAPI description can say: both optional)
        status, body = post(d.url, f"/api/jobs/{jid}/overrides")
        assert status == 200 and body["overrides"] == {"feed_pct": 80, "power_pct": 50}
        status, body = post(d.url, "/api/jobs/9999/overrides?power=50")
        assert status == 404 and body["error"] == "not_found"

        wait_for(lambda: c.job(jid)["state"] == "done", timeout_s=30.0, what="job done")
        done = c.job(jid)
        assert done["overrides"] is None
        status, body = post(d.url, f"/api/jobs/{jid}/overrides?power=50")
        assert status == 409 and body["error"] == "conflict", body

        lit = [e.power for e in sorted(mock.machine("ov-api").ledger, key=lambda e: e.line)
               if e.kind == "G1" and e.power > 0]
    half = full * 50 // 100
    assert set(lit) == {full, half}
    first_half = lit.index(half)
    # lines written before the request keep the full power, every later one has half
    assert first_half > 10 and all(p == full for p in lit[:first_half])
    assert all(p == half for p in lit[first_half:])


def test_page_has_the_override_controls(tmp_path: Path) -> None:
    with running_daemon(tmp_path, "ov-page", speed=2.0) as d:
        page = send(d.url, "GET", "/").body.decode()
        js = send(d.url, "GET", "/static/app.js").body.decode()
    assert 'id="overrides"' in page and 'data-ov="feed"' in page and 'data-ov="power"' in page
    assert "'overrides'" in js and "renderOverrides" in js
