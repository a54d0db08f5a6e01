"""Speed against accuracy, charted; stability where methods fail (issue 7).

One run regenerates every chart in docs/img/ and docs/performance.md, all figures from that run:

1. Five-bar kinematics — time per point against the largest pen error, for the closed form
   (kinematics.fivebar), the n-bar solver as forward kinematics (kinematics.nbar), the thesis'
   linear approximation (Sec. 5.2, Eqs. 25–26, fitted by least squares; whole page region and
   per tile) and lookup tables (bilinear, bicubic) from benchmarks.approx. Errors are measured
   in the well-conditioned interior and near each singularity type separately, against the
   same closed-form formulas evaluated in extended precision (np.longdouble, 64-bit mantissa).
2. n-bar solver — convergence tolerance and input step against run time and constraint
   residual (drift) per paper example, beside the scipy baseline of benchmarks/nbar.py.
3. Job compilation — tolerance against segment count, compile time, plot time and the
   deviation measured from the quantised steps; adaptive segmentation against a fixed spacing.
4. The physical limit — microstepping and gear ratio against the step quantum on the page.
5. Stability — a map over the workspace of where each method fails, and approaches towards
   each singularity type.

Run from the repository root: python -m benchmarks.speed_accuracy [--out-dir docs] [--quick]
(--quick: tiny sizes, seconds, for a smoke test; it still writes its report into --out-dir).

One module per section, each measuring its rows and drawing its chart: `methods`,
`nbar_forward` and `kinematics_chart` (1), `examples` (2), `jobs` (3), `steps` (4),
`stability` and `approaches` (5); shared pieces in `config`, `timing`, `scene` and `plot`; the
report in `policy`, `report` and `report_stability` (from the `Results` of `run`).
"""

import matplotlib

matplotlib.use("Agg")  # before any submodule imports pyplot: charts are drawn off-screen

from benchmarks.speed_accuracy.config import Config
from benchmarks.speed_accuracy.report import write_report
from benchmarks.speed_accuracy.report_stability import FAILURE_MODES
from benchmarks.speed_accuracy.results import Results
from benchmarks.speed_accuracy.run import main, run

__all__ = ["FAILURE_MODES", "Config", "Results", "main", "run", "write_report"]
