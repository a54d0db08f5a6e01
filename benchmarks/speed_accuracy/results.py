"""`Results`: everything one run measured, the only input of the report and the charts."""

from __future__ import annotations

from dataclasses import dataclass, field

from benchmarks import approx
from benchmarks.speed_accuracy.approaches import ApproachResult
from benchmarks.speed_accuracy.config import Config
from benchmarks.speed_accuracy.examples import ExampleRow
from benchmarks.speed_accuracy.jobs import JobRow, ValidationCost
from benchmarks.speed_accuracy.methods import MethodRow
from benchmarks.speed_accuracy.nbar_forward import NbarKinRow
from benchmarks.speed_accuracy.scene import PointSet, Scene
from benchmarks.speed_accuracy.stability import StabilityMap
from benchmarks.speed_accuracy.steps import StepRow


@dataclass
class Results:
    """Everything one run measured (the report and the charts read only this)."""

    info: dict[str, str]
    cfg: Config
    scene: Scene
    sets: dict[str, PointSet]
    linear: approx.LinearApprox
    kin: list[MethodRow]
    nbar: list[NbarKinRow]
    examples: list[ExampleRow]
    examples_note: str
    jobs: list[JobRow]
    validation: ValidationCost | None
    steps: list[StepRow]
    smap: StabilityMap
    appr: list[ApproachResult]
    timings: dict[str, float] = field(default_factory=dict)
