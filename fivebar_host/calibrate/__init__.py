"""Calibration pipeline steps (pattern, measure, fit, check) over kinematics.calibration."""
