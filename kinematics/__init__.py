"""Pure kinematics for fivebar: closed-form five-bar robot and the general n-bar solver.

numpy only, no I/O: every function takes and returns arrays in mm and radians.
"""
