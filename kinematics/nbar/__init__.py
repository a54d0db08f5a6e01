"""General n-bar solver: the point-line-plane method (Sharma & Purwar 2020).

Planar, spherical and spatial linkages with revolute and prismatic joints, n-ary links and
linear actuators; numpy only, no I/O. Typical use::

    mech = parse_mechanism(text)          # or build_mechanism(tomllib.load(f))
    sim = sweep(mech)                     # the file's steps, or simulate(mech, inputs)
    sim.path("J8"), sim.residual, sim.status, sim.limits
"""

from kinematics.nbar.build import build_mechanism, parse_mechanism
from kinematics.nbar.constraints import Constraint
from kinematics.nbar.model import Input, Joint, Link, Mechanism, MechanismError, Settings
from kinematics.nbar.results import LimitReport, Simulation, Status
from kinematics.nbar.solver import simulate, sweep
from kinematics.nbar.validate import (
    FiveBarValidation,
    fivebar_mechanism,
    fivebar_spec,
    validate_fivebar_path,
)

__all__ = [
    "Constraint",
    "FiveBarValidation",
    "Input",
    "Joint",
    "LimitReport",
    "Link",
    "Mechanism",
    "MechanismError",
    "Settings",
    "Simulation",
    "Status",
    "build_mechanism",
    "fivebar_mechanism",
    "fivebar_spec",
    "parse_mechanism",
    "simulate",
    "sweep",
    "validate_fivebar_path",
]
