"""Helpers of the end-to-end tests on the emulated firmware (test_plot_sim*.py): compiled
private copies of the bundled drawings, the planned step counts, and the step pulses a pin
trace shows with the laser on."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from fivebar_host.compile import CompileOptions, Job, compile_job
from fivebar_host.config import Profile, load_profile
from fivebar_host.devices.simtrace import Trace

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def compiled_copy(tmp_path: Path, example: str) -> tuple[Path, Profile, Job]:
    """A private copy of a bundled drawing (its resume file lands beside it), compiled with
    the default profile."""
    drawing = tmp_path / example
    shutil.copy(EXAMPLES / example, drawing)
    prof = load_profile()
    return drawing, prof, compile_job(drawing, prof, CompileOptions())


def planned_draw_steps(job: Job) -> np.ndarray:
    """|steps| per motor over the job's drawing segments."""
    return np.asarray(np.abs(np.diff(job.steps, axis=0))[job.draw].sum(axis=0))


def planned_steps(job: Job) -> np.ndarray:
    """|steps| per motor over all the job's segments, travel included."""
    return np.asarray(np.abs(np.diff(job.steps, axis=0)).sum(axis=0))


def laser_steps(tr: Trace) -> np.ndarray:
    """|steps| per motor taken while the laser pin was on."""
    iv = tr.laser_intervals()
    out = np.zeros(2, dtype=np.int64)
    for i, axis in enumerate("AB"):
        for st in tr.steps(axis):
            if any(s <= st.cycle < e for s, e in iv):
                out[i] += 1
    return out


def all_steps(tr: Trace) -> np.ndarray:
    """|steps| per motor in the trace, laser on or off."""
    return np.array([len(tr.steps(axis)) for axis in "AB"], dtype=np.int64)
