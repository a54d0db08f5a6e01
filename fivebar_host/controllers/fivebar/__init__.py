"""fivebar's own firmware: the serial link, streaming, what follows a fault, the record kept
across a reset, and the `Controller` that drives a run over them."""

from fivebar_host.controllers.fivebar.controller import FivebarController as Controller

__all__ = ["Controller"]
