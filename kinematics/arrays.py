"""The array type aliases every module uses, defined once.

`FloatArray` holds millimetres, radians or seconds (float64); `IntArray` motor steps and
indices stored as int64; `IndexArray` numpy's native index type (intp), as returned by
`np.flatnonzero` and used for fancy indexing; `BoolArray` masks.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
IndexArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]

__all__ = ["BoolArray", "FloatArray", "IndexArray", "IntArray"]
