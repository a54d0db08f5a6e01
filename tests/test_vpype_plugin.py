"""The vpype plugin (`fivebar_host.vpype_plugin`): vpype itself is run, in a subprocess, with
the plugin found through the `vpype.plugins` entry point that pyproject.toml declares (a
dist-info made from that declaration is put on the path, so the test does not depend on how
the project was installed); plus the document → drawing conversion against hand-computed
millimetres.

vpype is in the `test` extra; the test is skipped only where vpype cannot be imported.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

vp = pytest.importorskip("vpype")
pytest.importorskip("vpype_cli")

from fivebar_host.compile import CompileOptions, compile_drawing  # noqa: E402
from fivebar_host.config import load_profile  # noqa: E402
from fivebar_host.errors import FivebarError  # noqa: E402
from fivebar_host.vpype_plugin import PX_PER_MM, document_to_drawing  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SIMPLE = ROOT / "examples" / "simple.svg"
PROF = load_profile()


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A directory holding a dist-info whose entry points are pyproject.toml's
    `vpype.plugins` table, for the subprocess's path."""
    table = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    plugins = table["vpype.plugins"]
    assert plugins == {"fivebar": "fivebar_host.vpype_plugin:fivebar"}
    d = tmp_path_factory.mktemp("ep") / "fivebar_vpype_plugin-0.dist-info"
    d.mkdir()
    (d / "METADATA").write_text("Metadata-Version: 2.1\nName: fivebar-vpype-plugin\n"
                                "Version: 0\n")
    (d / "entry_points.txt").write_text(
        "[vpype.plugins]\n" + "".join(f"{k} = {v}\n" for k, v in plugins.items()))
    return d.parent


def vpype(plugin_path: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(plugin_path), str(ROOT),
                                         env.get("PYTHONPATH", "")])
    env["MPLBACKEND"] = "Agg"
    return subprocess.run([sys.executable, "-m", "vpype_cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def test_vpype_preview_reports_and_draws(plugin_path: Path, tmp_path: Path) -> None:
    png = tmp_path / "p.png"
    r = vpype(plugin_path, tmp_path, "read", str(SIMPLE), "linemerge", "linesort",
              "fivebar", "preview", "--preview", str(png))
    assert r.returncode == 0, r.stderr
    assert "placement     centred" in r.stdout and "deviation     max" in r.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # placed as the SVG itself is (`fivebar plot examples/simple.svg`: 58.0 × 28.0 mm)
    size = next(ln for ln in r.stdout.splitlines() if ln.startswith("placement"))
    assert "58.0 × 28.0 mm" in size


def test_vpype_plot_on_the_mock_streams_every_segment(plugin_path: Path,
                                                      tmp_path: Path) -> None:
    r = vpype(plugin_path, tmp_path, "read", str(SIMPLE), "linemerge", "linesort", "fivebar",
              "plot", "--port", "fivebar-mock://?speed=0", "--yes", "--tolerance", "0.1")
    assert r.returncode == 0, r.stderr
    job = next(ln for ln in r.stdout.splitlines() if ln.startswith("job: "))
    done = next(ln for ln in r.stdout.splitlines() if ln.startswith("done: "))
    n = int(job.split()[1])
    assert done.startswith(f"done: {n} segments") and "machine at A = 0 steps, B = 0 steps" in done


def test_vpype_plot_refusal_names_the_reason(plugin_path: Path, tmp_path: Path) -> None:
    r = vpype(plugin_path, tmp_path, "read", str(SIMPLE), "fivebar", "plot", "--port",
              "fivebar-mock://?speed=0", "--origin", "0,0")
    assert r.returncode != 0
    assert "vpype-document" in r.stderr and "dead zone" in r.stderr, r.stderr
    r = vpype(plugin_path, tmp_path, "read", str(SIMPLE), "fivebar", "plot")
    assert r.returncode != 0 and "needs --port" in r.stderr


def test_document_to_drawing_in_mm_y_up() -> None:
    """A line from (0, 0) to (96, 48) px on a 192 × 96 px page is (0, 25.4) → (25.4, 12.7)
    mm from the page's bottom-left corner."""
    doc = vp.Document(page_size=(192.0, 96.0))
    doc.add(vp.LineCollection([np.array([0 + 0j, 96 + 48j, 192 + 96j])]), 1)
    doc.add(vp.LineCollection([np.array([10 + 10j])]), 2)  # a single point: nothing drawn
    d = document_to_drawing(doc)
    assert d.kind.shape[0] == 2 and d.n_strokes == 1
    assert np.allclose(d.params[0, :4], [0.0, 25.4, 25.4, 12.7])
    assert np.allclose(d.params[1, :4], [25.4, 12.7, 50.8, 0.0])
    assert d.page_size_mm == pytest.approx((50.8, 25.4))
    assert math.isclose(PX_PER_MM, 96 / 25.4)
    with pytest.raises(FivebarError, match="no layer 7"):
        document_to_drawing(doc, ("7",))
    with pytest.raises(FivebarError, match="no lines"):
        document_to_drawing(vp.Document())


def test_dense_vpype_circle_compiles_within_tolerance() -> None:
    """vpype's linearised circle (dense polyline) compiles, and the validated deviation
    from those lines stays within the tolerance + one step quantum."""
    doc = vp.Document(page_size=(200.0, 200.0))
    doc.add(vp.LineCollection([vp.circle(100, 100, 60, quantization=0.05 * PX_PER_MM)]), 1)
    job = compile_drawing(document_to_drawing(doc), PROF, CompileOptions())
    assert job.max_dev_mm <= job.tolerance_mm + job.step_quantum_mm
    assert job.placement.how == "centred"
