"""The branch-flip guard: whether a Newton-corrected step is accepted.

One rule for every step the solver takes (`Tracker.attempt`, the fast path's single steps
and blocks, and the state next to a located fold): a step is accepted only if Newton's
correction from the predictor is at most CONTINUITY of the predicted motion, and the predicted
motion at most MAX_SPEEDUP times the last step's (per unit step). A jump to the other
assembly is a correction of the order of the distance between the branches that does not
shrink with the step, so a refused step is halved until the correction is small (or the step
falls below the resolution). Stated once here so that the fast path and the reference path
cannot drift apart.
"""

from __future__ import annotations

import math
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from kinematics.arrays import FloatArray

#: Newton may correct the predictor by at most this fraction of the predicted motion.
CONTINUITY = 0.5
#: The predicted motion may exceed the previous step's by at most this factor (per unit step).
MAX_SPEEDUP = 4.0
CONTINUITY2 = CONTINUITY * CONTINUITY
SPEEDUP2 = MAX_SPEEDUP * MAX_SPEEDUP
#: `step_accepted`'s `prev2` when there is no previous step to compare with.
NO_PREVIOUS = math.inf


@overload
def step_accepted(c2: float, m2: float, prev2: float, floor2: float) -> bool: ...


@overload
def step_accepted(c2: FloatArray, m2: FloatArray, prev2: FloatArray,
                  floor2: float) -> NDArray[np.bool_]: ...


def step_accepted(c2: Any, m2: Any, prev2: Any, floor2: float) -> Any:
    """True where a step is accepted (element-wise for arrays).

    c2: ‖q − q_pred‖², Newton's correction of the predictor (squared); m2: ‖q_pred − q_prev‖²,
    the predicted motion (squared); prev2: the last accepted step's predicted motion² scaled to
    this step's length, (h/h_last)²·m2_last, or NO_PREVIOUS; floor2: the absolute resolution²
    below which motions are not compared (1e-9 of the mechanism's size, squared).
    """
    return (c2 <= CONTINUITY2 * m2 + floor2) & (m2 <= SPEEDUP2 * prev2 + floor2)
