"""Smoke test of `python -m benchmarks.speed_accuracy`: every item runs end to end on tiny
sizes (`Config.quick()`), writes its report and charts into a temporary folder — never into
docs/ — and the report carries the sections, the machine record and the policy."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import speed_accuracy as sa  # noqa: E402

CHARTS = ("perf_kinematics.png", "perf_nbar.png", "perf_jobs.png", "perf_steps.png",
          "perf_stability.png", "perf_approach.png")


def test_benchmark_runs_on_tiny_sizes_without_touching_docs(tmp_path: Path) -> None:
    docs = ROOT / "docs"
    before = {p: p.stat().st_mtime_ns for p in docs.rglob("*") if p.is_file()}
    res = sa.run(sa.Config.quick(), tmp_path)
    after = {p: p.stat().st_mtime_ns for p in docs.rglob("*") if p.is_file()}
    assert before == after
    md = (tmp_path / "performance.md").read_text()
    for head in ("## Model no more than a scene needs", "## 1. Five-bar kinematics",
                 "## 2. n-bar solver", "## 3. Job compilation", "## 4. The physical limit",
                 "## 5. Stability", "### Failure modes and the tests that hold them"):
        assert head in md
    assert "--quick" in md and res.info["cpu"] in md and res.info["numpy"] in md
    for name in CHARTS:
        png = tmp_path / "img" / name
        assert png.exists() and 0 < png.stat().st_size < 300_000
    # every method answered the interior, and the exact ones exactly
    closed = [r for r in res.kin if r.family == "closed form"]
    assert {r.direction for r in closed} == {"inverse", "forward"}
    assert all(r.errors["interior"].max_mm < 1e-9 for r in closed)
    assert all(r.ns_per_point > 0 for r in res.kin)
    # every failure mode listed in the report names a test that exists
    tests = (ROOT / "tests" / "test_stability.py").read_text()
    for line in sa.FAILURE_MODES:
        for name in line.split("[`")[1].split("`")[0:1]:
            assert f"def {name}(" in tests, name
