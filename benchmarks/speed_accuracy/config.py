"""Constants and sizes of one `python -m benchmarks.speed_accuracy` run.

`Config` holds the sizes (`full()` the documented run, `quick()` a smoke test of the same code
paths); the module constants fix what "interior", "near a singularity" and "exact" mean for
every section, so the report can quote them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

Box = tuple[float, float, float, float]

#: The repository root (docs/, configs/, examples/ and firmware/ are read from here).
ROOT = Path(__file__).resolve().parent.parent.parent
#: "Well-conditioned interior": every singularity margin (kinematics.fivebar) at least this.
WELL_DEG = 15.0
#: "Near a singularity": the margin to that singularity type below this (the others ≥ it).
NEAR_DEG = 2.0
#: Candidates for the near sets are drawn this close to the singular curves (mm).
NEAR_TYPE1_MM = 0.5
NEAR_TYPE2_MM = 10.0
#: An exact method's error must stay at or below this (mm); above it counts as error growth.
EXACT_MM = 1e-6
#: The drawings of item 3 (name → what it is).
SCENE_NOTES = {
    "text": "examples/fivebar_text.svg, the word in single-stroke curves",
    "shapes": "examples/simple.svg: frame with rounded corners, circle, triangle, zigzag",
    "random strokes": "benchmarks/pipeline.py `make_svg`: short random lines and quadratic "
                      "curves, as in the pipeline benchmark",
}
#: Extended precision for the reference evaluation.
LD = np.longdouble
FIRMWARE_CONFIG = ROOT / "firmware" / "fivebar" / "config.h"


@dataclass(frozen=True)
class Config:
    """Sizes of one run. `full()` is the documented run (< 3 min on 2 cores); `quick()` is a
    smoke test of the same code paths in seconds."""

    n_time: int = 100_000  # points per timed call (item 1)
    repeats: int = 5  # timed repeats; the median is reported
    n_near: int = 20_000  # points per error set
    lut_sizes: tuple[int, ...] = (64, 128, 256, 512)
    cubic_sizes: tuple[int, ...] = (64, 128, 256, 512)
    guarded_sizes: tuple[int, ...] = (128, 256, 512)  # bilinear with max_error = tolerance
    tile_counts: tuple[int, ...] = (8, 16, 32, 64)
    nbar_tols: tuple[float, ...] = (1e-6, 1e-8, 1e-10, 1e-12)
    nbar_points: int = 150  # continuation checks per error set (n-bar)
    raster_lines: int = 30  # raster path over the page for the n-bar timing
    ex_tols: tuple[float, ...] = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
    ex_factors: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0)
    ex_runs: int = 5
    ex_base_runs: int = 3
    job_tols: tuple[float, ...] = (0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002)
    job_repeats: int = 3
    random_paths: int = 50
    microsteps: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
    gears: tuple[float, ...] = (1.0, 2.0, 4.0)
    map_pitch_mm: float = 2.0
    nbar_map_stride: int = 2
    map_lut: int = 256
    map_tiles: int = 32
    approach_exponents: tuple[float, ...] = tuple(-0.5 * k for k in range(-2, 25))
    job_scenes: tuple[str, ...] = ("text", "shapes", "random strokes")
    max_examples: int = 0  # n-bar example files to run (0: all)
    quick_run: bool = False

    @staticmethod
    def full() -> Config:
        return Config()

    @staticmethod
    def quick() -> Config:
        return Config(n_time=2_000, repeats=2, n_near=400, lut_sizes=(32, 64),
                      cubic_sizes=(32,), guarded_sizes=(32,), tile_counts=(8,),
                      nbar_tols=(1e-8, 1e-12),
                      nbar_points=6, raster_lines=4, ex_tols=(1e-6, 1e-12),
                      ex_factors=(1.0, 2.0), ex_runs=1, ex_base_runs=1, job_tols=(0.2, 0.05),
                      job_repeats=1, random_paths=10, microsteps=(1, 16), gears=(1.0,),
                      map_pitch_mm=12.0, nbar_map_stride=2, map_lut=64, map_tiles=8,
                      approach_exponents=(0.0, -3.0, -6.0, -9.0, -12.0),
                      job_scenes=("shapes",), max_examples=1, quick_run=True)
