"""The web page of `fivebar serve` in a real headless Chromium, against the daemon on 127.0.0.1
in front of the mock machine and of the emulated firmware: upload (drag and drop and the file
picker), the dry run (preview, estimate, the CLI's report), queueing, progress to done, pause
and resume, cancel, reorder, delete, a refusal with its file:line reason, bad input (not a
drawing, too large, an option out of range, a second tab) shown in words with nothing reaching
the machine, the machine panel (home, jog, motors off, alarm), a fault and its resume, the
token prompt on a phone-sized screen. Screenshots of each state go to build/screenshots/ (or
$FIVEBAR_SCREENSHOTS) with measurements.json: page weight, time to first render, and the
latency from a status change on the machine to the page."""

from __future__ import annotations

import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from fivebar_host.compile import nbar_opinion
from fivebar_host.config import load_profile
from fivebar_host.devices import mock
from fivebar_host.options import JOB_OPTIONS
from fivebar_host.report.text.dryrun import format_duration, report_lines
from fivebar_host.server.client import ServerClient, plot_options
from fivebar_host.server.jobs import JobOptions, SubmitError, compile_upload
from tests.web_support import (
    EXAMPLES,
    PHONE,
    browser_missing,
    chromium,
    click_job_button,
    daemon,
    drop_file,
    errors_shown,
    job_row,
    job_state,
    latency_summary,
    record,
    shot,
    wait,
)

pytestmark = pytest.mark.browser
SIMPLE = EXAMPLES / "simple.svg"
TEXT = EXAMPLES / "fivebar_text.svg"
SQUARE = EXAMPLES / "square.gcode"
#: A drawing whose line 5 lies beyond the arms' reach (with its origin at the machine's).
FAR = b"G21\nG90\nG0 X0 Y100\nG1 X0 Y100 F600\nG1 X300 Y100\n"


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    why = browser_missing()
    if why is not None:
        pytest.skip(why)
    with chromium(tmp_path_factory.mktemp("chromium-profile")) as driver:
        yield driver


def css(driver: Any, sel: str) -> Any:
    return driver.find_element("css selector", sel)


def press(driver: Any, sel: str) -> None:
    """Click `sel` as a person would: scrolled to the middle of the window first (the page's
    sticky header covers the top rows when the browser scrolls a control to the edge)."""
    el = css(driver, sel)
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'})", el)
    el.click()


def text(driver: Any, sel: str) -> str:
    return str(css(driver, sel).text)


#: The job options a laser machine's page offers: all but the pen overrides, which the
#: daemon refuses (its jobs use its own profile's pen settings).
PAGE_OPTIONS = [o for o in JOB_OPTIONS if not o.name.startswith("pen_")]


def open_page(driver: Any, url: str) -> None:
    driver.get(url + "/")
    wait(driver, lambda d: text(d, "#link") == "live", what="the event stream")
    wait(driver, lambda d: len(d.find_elements("css selector", "#options [name]"))
         == len(PAGE_OPTIONS), what="the option form")


def check_and_queue(driver: Any) -> int:
    """Dry run the chosen file, then queue it; the new job's id."""
    css(driver, "#check").click()
    wait(driver, lambda d: css(d, "#dryrun").is_displayed()
         and d.execute_script("return document.querySelector('#preview').naturalWidth") > 0,
         what="the dry run")
    css(driver, "#queue-it").click()
    note = wait(driver, lambda d: [n.text for n in d.find_elements("css selector",
                                                                   "#errors .note")],
                what="the queued note")
    return int(note[0].split()[1])


def set_option(driver: Any, query: str, value: str) -> None:
    field = css(driver, f"#opt-{query}")
    field.clear()
    field.send_keys(value)


def test_upload_preview_queue_progress_done(browser: Any, tmp_path: Path) -> None:
    """Drop a drawing, see the CLI's dry run, queue it, watch progress advance to done."""
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=2&machine=web1") as dm:
        open_page(d, dm.url)
        _page_weight(d)
        names = [e.get_attribute("name") for e in d.find_elements("css selector",
                                                                   "#options [name]")]
        assert names == [o.query for o in PAGE_OPTIONS]
        shot(d, "01-start")
        data = TEXT.read_bytes()
        drop_file(d, data, TEXT.name)
        wait(d, lambda d: TEXT.name in text(d, "#drop"), what="the dropped file")
        css(d, "#opt-confirm").click()
        css(d, "#check").click()
        wait(d, lambda d: css(d, "#dryrun").is_displayed(), what="the dry run")
        prof = load_profile(None)
        job = compile_upload(data, TEXT.name, JobOptions(), prof).job
        expected = report_lines(job, nbar_opinion(job, prof), profile=prof)
        assert d.execute_script("return document.querySelector('#report').textContent") \
            == "\n".join(expected)
        assert format_duration(job.total_time_s) in text(d, "#estimate")
        assert f"{job.max_dev_mm:.4f} mm" in text(d, "#estimate")
        assert d.execute_script("return document.querySelector('#preview').naturalWidth") > 300
        shot(d, "02-dry-run")
        css(d, "#queue-it").click()
        note = wait(d, lambda d: [n.text for n in d.find_elements("css selector",
                                                                  "#errors .note")],
                    what="the queued note")
        job_id = int(note[0].split()[1])
        seen: set[float] = set()
        running_shot = False
        deadline = time.monotonic() + 30
        while job_state(d, job_id) != "done" and time.monotonic() < deadline:
            state, p = d.execute_script(
                "const r = document.querySelector(`#jobs li[data-job='${arguments[0]}']`);"
                "return r ? [r.dataset.state, r.querySelector('progress').value] : [null, 0]",
                job_id)
            if state == "running":
                seen.add(float(p))
                if 0.3 < p < 0.8 and not running_shot:
                    running_shot = True
                    shot(d, "03-running")
            time.sleep(0.05)
        assert job_state(d, job_id) == "done", errors_shown(d)
        inner = sorted(p for p in seen if 0 < p < 1)
        assert len(inner) >= 5, f"progress seen: {sorted(seen)}"
        assert running_shot
        n = job.n_segments  # the text example's segments as the daemon compiles it
        assert f"{n} of {n}" in text(d, f'#jobs li[data-job="{job_id}"]')
        trail = d.execute_script("return fivebar.trail")
        assert len(trail) > 50 and any(p[2] == 1 for p in trail)
        # the trail is drawn in the machine's frame: every polled pen-down point inside the job's
        # machine bbox (± 1 mm), spanning most of it (polls on a busy machine may miss the
        # extremes, so the span, not the extreme, is what is asked)
        x0, y0, x1, y1 = job.placement.machine_bbox
        down = [p for p in trail if p[2] == 1]  # travel from home lies outside the drawing
        xs, ys = [p[0] for p in down], [p[1] for p in down]
        assert x0 - 1 <= min(xs) and max(xs) <= x1 + 1 and y0 - 1 <= min(ys) and max(ys) <= y1 + 1
        assert max(xs) - min(xs) > 0.5 * (x1 - x0)
        shot(d, "04-done")
        summary = latency_summary(d)
        record("latency_mock", summary)
        assert summary["n"] >= 20 and summary["median_ms"] < 500


def _page_weight(d: Any) -> None:
    """Bytes transferred on the first load and time to first render (fresh profile)."""
    nav = d.execute_script("return performance.getEntriesByType('navigation')[0].toJSON()")
    res = d.execute_script("return performance.getEntriesByType('resource')"
                           ".map((r) => r.toJSON())")
    paint = d.execute_async_script(
        "const done = arguments[0]; const seen = [];"
        "new PerformanceObserver((list) => { for (const p of list.getEntries()) "
        "seen.push([p.name, p.startTime]); }).observe({type: 'paint', buffered: true});"
        "setTimeout(() => done(seen), 300);")
    static = [r for r in res if "/static/" in r["name"]]
    api = [r for r in res if "/api/" in r["name"] and "/api/events" not in r["name"]]
    page_bytes = int(nav["transferSize"]) + sum(int(r["transferSize"]) for r in static)
    fcp = dict(paint).get("first-contentful-paint")
    first_frame = d.execute_script("return fivebar.firstFrameMs")
    assert page_bytes > 0 and first_frame is not None
    record("page", {"page_bytes_transferred": page_bytes,
                    "page_body_bytes": int(nav["encodedBodySize"])
                    + sum(int(r["encodedBodySize"]) for r in static),
                    "api_bytes_on_load": sum(int(r["transferSize"]) for r in api),
                    "first_contentful_paint_ms": None if fcp is None else round(float(fcp), 1),
                    "first_frame_ms": round(float(first_frame), 1),
                    "dom_content_loaded_ms": round(float(nav["domContentLoadedEventEnd"]), 1),
                    "files": sorted(r["name"].rsplit("/", 1)[1] for r in static)})


def test_pause_resume_reorder_cancel_delete(browser: Any, tmp_path: Path) -> None:
    """Pause (machine held, laser off), resume, reorder waiting jobs, cancel, delete."""
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=1&machine=web2") as dm:
        open_page(d, dm.url)
        css(d, "#file").send_keys(str(SIMPLE))  # the file picker
        css(d, "#opt-confirm").click()
        d.execute_script("document.getElementById('opt-copies').value = '2'")
        job1 = check_and_queue(d)
        wait(d, lambda d: d.execute_script("return fivebar.status && fivebar.status.live "
                                           "&& fivebar.status.live.segments_done > 10"),
             what="the job under way")
        press(d, "#live-buttons button")  # Pause
        wait(d, lambda d: job_state(d, job1) == "paused", what="paused")
        assert text(d, "#seg").startswith("copy 1 of 2 · segment "), text(d, "#seg")
        c = ServerClient(dm.url)
        wait(d, lambda d: c.status()["machine"]["state"] == "Hold", what="the machine held")
        assert c.status()["machine"]["laser"] == 0
        done_then = c.job(job1)["segments_done"]
        time.sleep(0.4)
        assert c.job(job1)["segments_done"] == done_then
        wait(d, lambda d: "machine Hold" in text(d, "#mstate"), what="Hold on the page")
        job2 = c.submit(SQUARE.read_bytes(), "a.gcode", plot_options())["id"]
        job3 = c.submit(SQUARE.read_bytes(), "b.gcode", plot_options())["id"]
        wait(d, lambda d: job_state(d, job3) == "queued", what="two waiting jobs")
        shot(d, "05-paused")
        click_job_button(d, job2, "run later")
        wait(d, lambda d: d.execute_script("return fivebar.queue") == [job3, job2],
             what="the new order")
        assert [j["id"] for j in c.jobs() if j["state"] == "queued"] == [job2, job3]
        order = [int(e.get_attribute("data-job")) for e in
                 d.find_elements("css selector", '#jobs li[data-state="queued"]')]
        assert order == [job3, job2]
        shot(d, "06-reordered")
        click_job_button(d, job1, "Resume")
        wait(d, lambda d: job_state(d, job1) == "running", what="resumed")
        wait(d, lambda d: c.job(job1)["segments_done"] > done_then + 5, what="moving again")
        click_job_button(d, job1, "Cancel")
        wait(d, lambda d: job_state(d, job1) == "cancelled", what="cancelled")
        wait(d, lambda d: job_state(d, job3) in ("running", "done"), what="job 3 next")
        assert job_state(d, job2) == "queued"  # the reordered queue ran job 3 first
        for j in (job3, job2):
            c.cancel(j)
        click_job_button(d, job1, "Delete")
        wait(d, lambda d: job_row(d, job1) is None, what="the deleted job gone")
        shot(d, "07-cancelled-deleted")


def test_refusals_and_bad_input_reach_nothing(browser: Any, tmp_path: Path) -> None:
    """A refusal with its file:line reason; not a drawing, too large, out of range, a second
    tab: the API's error in words on the page, and nothing reaches the machine."""
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=10&machine=web3",
                max_upload_bytes=64 * 1024) as dm:
        open_page(d, dm.url)
        drop_file(d, FAR, "far.gcode")
        set_option(d, "origin", "0,0")
        css(d, "#check").click()
        box = wait(d, lambda d: errors_shown(d), what="the refusal")[0]
        with pytest.raises(SubmitError) as refused:
            compile_upload(FAR, "far.gcode", JobOptions(origin_mm=(0.0, 0.0)),
                           load_profile(None))
        assert str(refused.value).startswith("far.gcode:5, path #0")
        assert str(refused.value) in box and "cannot be plotted" in box
        assert not css(d, "#dryrun").is_displayed()
        assert css(d, "#queue-it").get_attribute("disabled") is not None
        shot(d, "08-refusal")
        drop_file(d, b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, "photo.svg")
        css(d, "#check").click()
        wait(d, lambda d: "not a drawing" in errors_shown(d)[0], what="not a drawing")
        drop_file(d, b"; padding\n" * 10000 + SQUARE.read_bytes(), "huge.gcode")
        css(d, "#check").click()
        wait(d, lambda d: "too large" in errors_shown(d)[0], what="too large")
        assert "over the limit of 65536 bytes" in errors_shown(d)[0]
        drop_file(d, SIMPLE.read_bytes(), SIMPLE.name)
        set_option(d, "origin", "")
        set_option(d, "tolerance", "50")
        css(d, "#check").click()
        wait(d, lambda d: "tolerance: must be within 0.0001..10 mm" in errors_shown(d)[0],
             what="out of range")
        shot(d, "09-bad-input")
        _second_tab(d, dm.url)
        led = mock.machine("web3").ledger
        assert not [e for e in led if e.kind in ("G1", "G92", "M17", "M18")], led
        assert ServerClient(dm.url).status()["jobs"]["done"] == 0


def _second_tab(d: Any, url: str) -> None:
    """Tab B cancels a held job; tab A, its buttons stale, resumes it: 409 in words."""
    c = ServerClient(url)
    job = c.submit(SQUARE.read_bytes(), "held.gcode", plot_options())["id"]  # no confirm
    first = d.current_window_handle
    wait(d, lambda d: job_state(d, job) == "held", what="the held job")
    row = job_row(d, job)
    assert "Waiting for your answer" in row.text  # the question itself: once, at the top
    top = wait(d, lambda d: text(d, "#waiting"), what="the waiting reason")
    assert "home pose" in top and "Yes, they are" in top
    d.switch_to.new_window("tab")
    open_page(d, url)
    click_job_button(d, job, "Cancel")
    wait(d, lambda d: job_state(d, job) == "cancelled", what="cancelled in tab B")
    d.close()
    d.switch_to.window(first)
    d.execute_script("fivebar.act(arguments[0], 'resume', 'confirm=true')", job)
    msg = wait(d, lambda d: [e for e in errors_shown(d) if "Not possible now" in e],
               what="the conflict")[0]
    assert f"job {job} is cancelled: only a paused or held job can be resumed" in msg
    shot(d, "10-second-tab-conflict")


def test_machine_panel_fault_and_resume(browser: Any, tmp_path: Path) -> None:
    """Home, jog the pen and a motor, motors off, an alarm and its clearing; a job held by a
    fault and resumed from the page to done."""
    d = browser
    with daemon(tmp_path / "state", "fivebar-mock://?speed=10&machine=web4&error_on=12") as dm:
        open_page(d, dm.url)
        css(d, "#at-home").click()
        css(d, "#home").click()
        wait(d, lambda d: "position known" in text(d, "#m-state"), what="homed")
        x0 = d.execute_script("return fivebar.status.pose.pen[0]")
        css(d, '.pad [data-dx="1"]').click()  # +10 mm
        wait(d, lambda d: abs(d.execute_script("return fivebar.status.pose.pen[0]") - x0 - 10)
             < 0.05, what="the pen 10 mm to the right")
        a0 = d.execute_script("return fivebar.status.machine.position.a")
        css(d, '[data-motor="A"][data-sign="1"]').click()
        wait(d, lambda d: d.execute_script("return fivebar.status.machine.position.a")
             == a0 + 100, what="motor A +100 steps")
        shot(d, "11-machine-jogged")
        css(d, "#motors-off").click()
        wait(d, lambda d: "motors off" in text(d, "#m-state"), what="motors off")
        assert "position unknown" in text(d, "#m-state")
        assert any(e.kind == "M18" for e in mock.machine("web4").ledger)
        mock.machine("web4").firmware._raise_alarm(30)  # an endstop hit, as the switch would
        wait(d, lambda d: css(d, "#alarm").is_displayed(), what="the alarm banner")
        assert "alarm 30: endstop hit outside homing" in text(d, "#alarm")
        shot(d, "12-alarm")
        css(d, "#clear-alarm").click()
        wait(d, lambda d: not css(d, "#alarm").is_displayed(), what="the alarm cleared")
        css(d, "#home").click()  # at home confirmed: pose known again (motors on: M17)
        wait(d, lambda d: "position known" in text(d, "#m-state"), what="homed again")
        css(d, "#file").send_keys(str(SQUARE))
        job = check_and_queue(d)
        wait(d, lambda d: job_state(d, job) == "held", what="held by the fault")
        assert "error" in job_row(d, job).text
        shot(d, "13-fault-held")
        click_job_button(d, job, "Resume")
        wait(d, lambda d: job_state(d, job) == "done", what="resumed to done")


def test_phone_token_prompt(browser: Any, tmp_path: Path) -> None:
    """With a token: the page asks for it, sends it in a header only, works on a phone."""
    d = browser
    size = d.get_window_size()
    d.set_window_size(*PHONE)
    try:
        with daemon(tmp_path / "state", "fivebar-mock://?speed=10&machine=web5",
                    require_token=True) as dm:
            assert dm.token
            with pytest.raises(urllib.error.HTTPError) as e:
                urllib.request.urlopen(dm.url + "/api/status")
            assert e.value.code == 401
            d.get(dm.url + "/")
            wait(d, lambda d: css(d, "#token-dialog").is_displayed(), what="the token prompt")
            shot(d, "14-phone-token")
            css(d, "#token-input").send_keys(dm.token)
            css(d, "#token-ok").click()
            wait(d, lambda d: text(d, "#link") == "live", what="the stream with the token")
            wait(d, lambda d: len(d.find_elements("css selector", "#options [name]"))
                 == len(PAGE_OPTIONS), what="the option form")
            wait(d, lambda d: "connected to" in text(d, "#m-conn"), what="machine state")
            urls = d.execute_script("return [location.href, ...performance.getEntries()"
                                    ".map((e) => e.name)]")
            assert not [u for u in urls if dm.token in u]
            assert d.execute_script("return document.documentElement.scrollWidth") <= PHONE[0]
            shot(d, "15-phone")
            d.execute_script("sessionStorage.clear(); localStorage.clear()")
    finally:
        d.set_window_size(size["width"], size["height"])


@pytest.mark.sim
def test_emulated_firmware_progress_pause_resume(browser: Any, tmp_path: Path) -> None:
    """The same page in front of the firmware in simavr (real time): queue, pause, resume,
    watch progress to done."""
    from fivebar_host.devices import sim

    reason = sim.toolchain_missing()
    if reason is not None:
        pytest.skip(f"emulator unavailable: {reason}")
    sim.ensure_built()
    d = browser
    with daemon(tmp_path / "state", "fivebar-sim://?realtime=1", banner_timeout_s=5.0) as dm:
        open_page(d, dm.url)
        css(d, "#file").send_keys(str(SQUARE))
        css(d, "#opt-confirm").click()
        job = check_and_queue(d)
        wait(d, lambda d: d.execute_script("return fivebar.status && fivebar.status.live "
                                           "&& fivebar.status.live.segments_done > 15"),
             what="the job under way")
        press(d, "#live-buttons button")
        wait(d, lambda d: job_state(d, job) == "paused", what="paused")
        wait(d, lambda d: "machine Hold" in text(d, "#mstate"), what="held")
        shot(d, "16-sim-paused")
        press(d, "#live-buttons button")
        progress = []
        # a 7.4 s job in real time; the deadline allows a busy machine's emulator to run
        # several times slower than real time
        deadline = time.monotonic() + 120.0
        while job_state(d, job) not in ("done", "failed", "held"):
            lv = d.execute_script("return fivebar.status.live")
            if lv:
                progress.append(lv["segments_done"])
            time.sleep(0.05)
            assert time.monotonic() < deadline, f"the job did not end: {progress[-5:]}"
        assert job_state(d, job) == "done", errors_shown(d)
        assert len(set(progress)) >= 5
        shot(d, "17-sim-done")
        summary = latency_summary(d)
        record("latency_sim", summary)
        assert summary["median_ms"] < 1000
