"""Benchmarks: scripts that print figures and draw the speed-against-accuracy charts.

A package so that `python -m benchmarks.speed_accuracy` can import its siblings; the older
scripts still run as `python benchmarks/<name>.py` (they drop this folder from sys.path so
`benchmarks/kinematics.py` does not shadow the `kinematics` package).
"""
