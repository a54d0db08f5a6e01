"""Devices the host can talk to instead of real hardware: the emulated firmware
(sim.py, simtrace.py) and, later, a mock device that obeys docs/protocol.md."""
