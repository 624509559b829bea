"""When a spindle-speed record says the spindle runs: a measured standstill reads a few rpm, not 0.

The regime blocks of :mod:`models.selection_cv`, the grey-box model's test
for two distinct running speeds (and its refusal of a record where the
spindle never runs) and the twin's check that a record starts at rest all
read a speed record through :func:`running`.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: a speed below this fraction of the record's top speed is standstill
STANDSTILL_FRACTION = 0.05
#: a speed at or below this is standstill whatever the record's top speed, rpm: a tachometer at rest reads a few
#: rpm (0-4 rpm on a logged standstill), and no machine-tool spindle runs steadily this slowly, so a record
#: that never gets above it has no running speed of its own to take 5 % of. It only decides where the top
#: speed is under 400 rpm (20 / 0.05): a record of real running speeds (FL_THERMAL: 1250 rpm and up) is judged
#: as before
STANDSTILL_RPM = 20.0


def running(speed: ArrayLike) -> NDArray[np.bool_]:
    """Rows where the spindle runs: |speed| above :data:`STANDSTILL_RPM` and above :data:`STANDSTILL_FRACTION`
    of the record's top |speed|.

    Parameters
    ----------
    speed : array-like, shape (n_samples,)
        Spindle speed per row, rpm (set points or measured); a NaN row does not run.

    Returns
    -------
    ndarray of bool, shape (n_samples,)
        All False for a record that never runs.
    """
    speed = np.abs(np.asarray(speed, float))
    top = speed.max(initial=0.0, where=np.isfinite(speed))
    return speed > max(STANDSTILL_RPM, STANDSTILL_FRACTION * top)
