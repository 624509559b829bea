"""The error type raised for bad input to the solver."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:   # numpy is imported inside the checks: importing this module stays light
    import numpy as np
    from numpy.typing import ArrayLike


class FEAInputError(ValueError):
    """Bad input to the FE solver: the message names the item and the value.

    It derives from ``ValueError`` so callers that already guard against bad
    values catch it, while the message, not a traceback from inside numpy or
    scipy, tells the user what to fix.
    """


def require_finite(name: str, values: ArrayLike) -> np.ndarray:
    """Refuse values holding a NaN or an infinity.

    Parameters
    ----------
    name : str
        What the values are, named in the error.
    values : array_like
        Numbers.

    Returns
    -------
    ndarray
        ``values`` as floats.

    Raises
    ------
    FEAInputError
        Naming the first bad value and its index.
    """
    import numpy as np

    arr = np.asarray(values, dtype=float)
    bad = ~np.isfinite(arr)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        where = f" at index {index}" if arr.ndim else ""
        raise FEAInputError(f"{name} must be finite, got {float(arr[bad][0])!r}{where}")
    return arr


def require_positive(name: str, value: float) -> float:
    """Refuse anything but a finite number > 0.

    Parameters
    ----------
    name : str
        What the value is, named in the error.
    value : float
        The value.

    Returns
    -------
    float
        ``value``.
    """
    import math

    try:
        number = float(value)
    except (TypeError, ValueError):
        raise FEAInputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number) or number <= 0.0:
        shown = value.tolist() if type(value).__module__ == "numpy" else value    # 3600, not np.int64(3600)
        raise FEAInputError(f"{name} must be positive, got {shown!r}")
    return number
