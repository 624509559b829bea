"""When a spindle-speed record says the spindle runs: a measured standstill reads a few rpm, not 0.

The regime blocks of :mod:`models.selection_cv`, the grey-box model's test
for two distinct running speeds and the twin's check that a record starts
at rest all read a speed record through :func:`running`.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: a speed below this fraction of the record's top speed is standstill
STANDSTILL_FRACTION = 0.05


def running(speed: ArrayLike) -> NDArray[np.bool_]:
    """Rows where the spindle runs: |speed| above :data:`STANDSTILL_FRACTION` of the record's top |speed|.

    Parameters
    ----------
    speed : array-like, shape (n_samples,)
        Spindle speed per row, rpm (set points or measured).

    Returns
    -------
    ndarray of bool, shape (n_samples,)
        All False for a record that never runs.
    """
    speed = np.abs(np.asarray(speed, float))
    return speed > STANDSTILL_FRACTION * speed.max(initial=0.0)
