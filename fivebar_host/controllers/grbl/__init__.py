"""A stock GRBL 1.1 board driven in joint space (`--controller grbl`): its link, its lines,
resume, and the `Controller` that drives a run over them."""

from fivebar_host.controllers.grbl.controller import GrblController as Controller

__all__ = ["Controller"]
