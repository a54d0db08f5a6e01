"""`fivebar serve` streaming to the real firmware in simavr (`fivebar-sim://`): two clients
submit at once, both jobs run one after the other, and the recorded step pulses equal the
plans exactly, with the laser on only while drawing. Skipped only without the AVR toolchain.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fivebar_host.compile import CompileOptions, compile_job
from fivebar_host.config import load_profile
from fivebar_host.devices import sim
from fivebar_host.devices.simtrace import read_trace
from fivebar_host.server.client import ServerClient, follow, plot_options
from fivebar_host.server.daemon import Daemon, ServeConfig

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

pytestmark = pytest.mark.sim


def test_two_jobs_on_the_emulated_firmware(tmp_path: Path) -> None:
    reason = sim.toolchain_missing()
    if reason is not None:
        pytest.skip(f"emulator unavailable: {reason}")
    sim.ensure_built()
    trace = tmp_path / "pins.trace"
    d = Daemon(ServeConfig(port_url=f"fivebar-sim://?trace={trace}", listen="127.0.0.1:0",
                           state_dir=tmp_path / "state"))
    d.start()
    files = [EXAMPLES / "square.gcode", EXAMPLES / "simple.svg"]
    results: list[dict[str, Any]] = []
    barrier = threading.Barrier(len(files))
    try:
        def submit(path: Path) -> None:
            c = ServerClient(d.url)
            data = path.read_bytes()
            barrier.wait()
            results.append(c.submit(data, path.name, plot_options(laser=True, confirm=True)))

        threads = [threading.Thread(target=submit, args=(p,)) for p in files]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        assert len(results) == 2
        c = ServerClient(d.url)
        done = [follow(c, j["id"], lambda x: None, max_s=120) for j in results]
        assert [j["state"] for j in done] == ["done", "done"], done
        assert all(j["underruns"] == 0 for j in done), done
        machine = c.status()["machine"]
        assert machine["firmware"]["version"] and machine["laser"] == 0
        assert machine["position"] == {"a": 0, "b": 0}
    finally:
        d.stop(timeout_s=30)  # closes the port: the harness stops and flushes its trace
    prof = load_profile(None)
    jobs = [compile_job(p, prof, CompileOptions()) for p in files]
    plan = sum(np.abs(np.diff(j.steps, axis=0)).sum(axis=0) for j in jobs)
    tr = read_trace(trace)
    assert [len(tr.steps("A")), len(tr.steps("B"))] == plan.tolist()
    assert [tr.position_at("A", tr.last_cycle()), tr.position_at("B", tr.last_cycle())] == [0, 0]
    # the laser was on once per run of drawing segments, and is off at the end
    runs = sum(int(np.count_nonzero(np.diff(np.concatenate(([0], (j.draw & (j.power > 0))
                                                              .astype(int)))) == 1))
               for j in jobs)
    assert len(tr.laser_intervals()) == runs
    assert not tr.laser_on_at(tr.last_cycle())
