"""Workspace analysis of the five-bar robot: safe region, page rectangle, singularity traces,
transmission angle and error sensitivity, and the report `fivebar workspace` shows.

Modules, one concern each: `region` (which points are safe), `rectangles` (the largest page
inside the safe region), `singularities` (type-1 circles, type-2 curves), `measures`
(per-point measures and page figures), `maps` (the full report). The link-length search is
`kinematics.design`, the working-mode planning `kinematics.modes`. Pure numpy, no I/O.
Frame, angle and mode conventions are those of `kinematics.fivebar` (motor M1 at (0, 0), M2 at
(w, 0), mm, rad from +x counter-clockwise).

Vocabulary (thesis Sec. 1.3.2 vs. this project). The thesis calls a singularity that involves a
driving link "Mode 2" (a_i ∥ b_i: the arm is stretched or folded, P on a reach circle) and the
one between the floating links "Mode 1" (b1 ∥ b2). We say *type 1* and *type 2*, as
`FiveBar.singularity_margins` does:

- type 1 of arm i ⇔ thesis Mode 2: |P − M_i| = a_i + b_i or |a_i − b_i|. These circles bound
  the workspace (the same for all four working modes); the motor drives through them, and that
  is how an arm changes its working-mode sign.
- type 2 ⇔ thesis Mode 1: P on the line R1R2, det A = 0. Mode 1a is P between R1 and R2
  (|R1R2| = b1 + b2); its trace in the working mode "++"/"--" is the curve that cuts a hole in
  the workspace (thesis Fig. 10). Mode 1b is P outside the segment (|R1R2| = |b1 − b2|); with
  b1 = b2 (class I) R1 = R2 and the trace is a circle of radius b about that common elbow.

A point is *safe* in a working mode if the inverse kinematics (Eqs. 16–22) exist there, the
motor angles lie within the joint limits and both singularity margins clear the configured
minima. Across the type-2 curve the assembly mode flips, which the motors cannot control, so a
safe region is also tied to one assembly sign ("+" iff P lies left of R1→R2).
"""

from kinematics.workspace.maps import WorkspaceReport, workspace_report
from kinematics.workspace.measures import (
    PageStats,
    PointMeasures,
    condition_numbers,
    measures,
    page_stats,
    perturbation_displacements,
    step_quantum,
)
from kinematics.workspace.rectangles import (
    PageFit,
    Rect,
    find_page_rectangle,
    largest_page_rectangle,
)
from kinematics.workspace.region import (
    Limits,
    NoSafeRegionError,
    angles_within_limits,
    assembly_sign,
    connected_component,
    default_resolution,
    point_safety,
    safe_mask,
    workspace_bounds,
)
from kinematics.workspace.singularities import SingularityTrace, type1_circles, type2_traces

__all__ = [
    "Limits",
    "NoSafeRegionError",
    "PageFit",
    "PageStats",
    "PointMeasures",
    "Rect",
    "SingularityTrace",
    "WorkspaceReport",
    "angles_within_limits",
    "assembly_sign",
    "condition_numbers",
    "connected_component",
    "default_resolution",
    "find_page_rectangle",
    "largest_page_rectangle",
    "measures",
    "page_stats",
    "perturbation_displacements",
    "point_safety",
    "safe_mask",
    "step_quantum",
    "type1_circles",
    "type2_traces",
    "workspace_bounds",
    "workspace_report",
]
