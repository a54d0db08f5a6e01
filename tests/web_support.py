"""Helpers of the web page's browser tests: headless Chromium (Debian's chromium and
chromium-driver, installed by scripts/setup.sh) driven through selenium, daemons on 127.0.0.1,
screenshots as test artifacts, waiting for the page, and the measurements the tests report."""

from __future__ import annotations

import base64
import json
import os
import shutil
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from fivebar_host.devices import mock
from fivebar_host.server.daemon import Daemon, ServeConfig

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
#: Chromium's flags: headless, no sandbox (root in a container), nothing from the network.
CHROME_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--no-first-run",
                "--disable-dev-shm-usage")
DESKTOP = (1280, 1000)
PHONE = (390, 844)


def browser_missing() -> str | None:
    """Why the browser tests cannot run here (None: they can)."""
    for path in (CHROMIUM, CHROMEDRIVER):
        if not os.access(path, os.X_OK):
            return f"{path} is missing: run scripts/setup.sh (apt: chromium chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is missing: pip install -e '.[test]'"
    return None


def screenshot_dir() -> Path:
    """Where screenshots and measurements go: $FIVEBAR_SCREENSHOTS, else build/screenshots."""
    d = Path(os.environ.get("FIVEBAR_SCREENSHOTS") or ROOT / "build" / "screenshots")
    d.mkdir(parents=True, exist_ok=True)
    return d


@contextmanager
def chromium(profile_dir: Path) -> Iterator[Any]:
    """A headless Chromium with a fresh profile; quit (browser and driver ended) afterwards."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in CHROME_FLAGS:
        opts.add_argument(flag)
    opts.add_argument(f"--user-data-dir={profile_dir}")
    opts.add_argument(f"--window-size={DESKTOP[0]},{DESKTOP[1]}")
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_script_timeout(20)
    try:
        yield driver
    finally:
        driver.quit()


@contextmanager
def daemon(state_dir: Path, port_url: str, **kw: Any) -> Iterator[Daemon]:
    """A daemon on 127.0.0.1 (OS-chosen port) in front of `port_url`; stopped afterwards."""
    kw.setdefault("banner_timeout_s", 2.0)
    d = Daemon(ServeConfig(port_url=port_url, listen="127.0.0.1:0", state_dir=state_dir, **kw))
    d.start()
    try:
        yield d
    finally:
        d.stop(hurry=True, timeout_s=20.0)
        mock.forget_machines()


def wait(driver: Any, pred: Callable[[Any], Any], timeout_s: float = 20.0,
         what: str = "") -> Any:
    """Poll `pred(driver)` until it is truthy (its value), or fail saying what was awaited."""
    deadline = time.monotonic() + timeout_s
    last: Any = None
    while time.monotonic() < deadline:
        try:
            last = pred(driver)
        except Exception as e:  # stale elements while the page re-renders
            last = e
        if last and not isinstance(last, Exception):
            return last
        time.sleep(0.03)
    shot(driver, f"timeout-{what.replace(' ', '-')[:40] or 'wait'}")
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}: {last!r}")


def shot(driver: Any, name: str) -> Path:
    """Save a screenshot of the whole page (beyond the window's height) as NAME.png."""
    driver.execute_script("window.scrollTo(0, 0)")  # the sticky header at the top
    time.sleep(0.1)  # let a pending animation frame paint the canvas
    w, h = driver.execute_script("return [document.documentElement.clientWidth, "
                                 "document.documentElement.scrollHeight]")
    shot = driver.execute_cdp_cmd("Page.captureScreenshot", {
        "format": "png", "captureBeyondViewport": True,
        "clip": {"x": 0, "y": 0, "width": w, "height": min(h, 6000), "scale": 1}})
    path = screenshot_dir() / f"{name}.png"
    path.write_bytes(base64.b64decode(shot["data"]))
    return path


def job_row(driver: Any, job_id: int) -> Any:
    """The job's row in the queue list (None while absent)."""
    rows = driver.find_elements("css selector", f'#jobs li[data-job="{job_id}"]')
    return rows[0] if rows else None


def job_state(driver: Any, job_id: int) -> str | None:
    """The state the page shows for a job (None while it is not listed)."""
    state = driver.execute_script(
        "const r = document.querySelector(`#jobs li[data-job='${arguments[0]}']`);"
        "return r ? r.dataset.state : null", job_id)
    return None if state is None else str(state)


def click_job_button(driver: Any, job_id: int, label: str) -> None:
    """Click the button `label` (its text or aria-label) in a job's row, as a person would;
    retried while the row is being rebuilt."""
    def find(d: Any) -> Any:
        row = job_row(d, job_id)
        if row is None:
            return None
        for b in row.find_elements("css selector", "button"):
            if label in (b.text, b.get_attribute("aria-label")) and b.is_enabled():
                b.click()
                return True
        return None

    wait(driver, find, what=f"button {label!r} of job {job_id}")


def errors_shown(driver: Any) -> list[str]:
    """The texts of the error boxes on the page, newest first."""
    return [e.text for e in driver.find_elements("css selector", "#errors .error")]


def drop_file(driver: Any, data: bytes, name: str) -> None:
    """Drop a file on the drop zone as a drag and drop from the desktop would."""
    driver.execute_script(
        "const bytes = Uint8Array.from(atob(arguments[0]), (c) => c.charCodeAt(0));"
        "const dt = new DataTransfer();"
        "dt.items.add(new File([bytes], arguments[1]));"
        "const zone = document.querySelector('#drop');"
        "zone.dispatchEvent(new DragEvent('dragover', {dataTransfer: dt, bubbles: true, "
        "cancelable: true}));"
        "zone.dispatchEvent(new DragEvent('drop', {dataTransfer: dt, bubbles: true, "
        "cancelable: true}));", base64.b64encode(data).decode(), name)


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0..1) by linear interpolation."""
    s = sorted(values)
    if len(s) == 1:
        return s[0]
    pos = q * (len(s) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


def clock_offset_ms(driver: Any) -> tuple[float, float]:
    """The page's clock (performance.timeOrigin + now()) minus Python's time.time(), ms,
    and the uncertainty (half the round trip of the script call); best of 5."""
    best: tuple[float, float] | None = None
    for _ in range(5):
        t0 = time.time() * 1000
        page = driver.execute_script("return performance.timeOrigin + performance.now()")
        t1 = time.time() * 1000
        est = (float(page) - (t0 + t1) / 2, (t1 - t0) / 2)
        if best is None or est[1] < best[1]:
            best = est
    assert best is not None
    return best


def record(name: str, values: dict[str, Any]) -> None:
    """Add measurements to measurements.json next to the screenshots (and print them)."""
    path = screenshot_dir() / "measurements.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    data[name] = values
    path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    print(f"\n{name}: {json.dumps(values)}")


def latency_summary(driver: Any) -> dict[str, Any]:
    """Status change on the machine → event handled by the page, ms (median, p99, n): the
    daemon stamps each status event with the wall-clock time it received the status report
    shown, the page records its own wall-clock time when the event arrives; both clocks are
    the machine's, and their offset is measured and corrected."""
    lat = [float(v) for v in driver.execute_script("return fivebar.latencies")]
    transport = [float(v) for v in driver.execute_script("return fivebar.transport")]
    offset, err = clock_offset_ms(driver)
    lat = [v - offset for v in lat]
    transport = [v - offset for v in transport]
    assert lat, "the page recorded no status change"
    return {"n": len(lat), "median_ms": round(statistics.median(lat), 2),
            "p99_ms": round(percentile(lat, 0.99), 2), "max_ms": round(max(lat), 2),
            "send_to_page_median_ms": round(statistics.median(transport), 2),
            "clock_offset_ms": round(offset, 3), "clock_offset_uncertainty_ms": round(err, 3)}
