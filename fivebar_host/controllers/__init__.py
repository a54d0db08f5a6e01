"""Controllers: the machines fivebar drives, one sub-package each.

`fivebar` is fivebar's own firmware (numbered, checked lines; exact resume), `grbl` a stock
GRBL 1.1 board driven in joint space. Import from the sub-packages' modules.
"""
