"""AGO-ANFIS: ANFIS trained on accumulated (AGO) series, restored by IAGO (thesis §6.2.2).

The zero-referenced inputs and output are accumulated, ``X¹ = AGO(X⁰)``,
``y¹ = AGO(y⁰)``; an ANFIS (default ANFIS-FCM, 3 rules, thesis) maps
``X¹(k) → y¹(k)``; the prediction is ``ŷ⁰ = IAGO(ANFIS(X¹))``. AGO smooths
noise, but the accumulated inputs keep growing, so a long test series leaves
the training range: there the ANFIS fallback (nearest rule's linear
consequent, see :mod:`models.anfis`) makes the de-accumulated output a
linear model of the current input changes.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import clone

from .anfis import ANFISRegressor
from .grey import GreySeriesRegressor, ago, iago
from .registry import register_model


@register_model({"ago-anfis": {"random_state": 0}}, time_series=True)
class AGOANFISRegressor(GreySeriesRegressor):
    """ANFIS on AGO series (grey time-series convention, see :mod:`models.grey`).

    Parameters
    ----------
    anfis : ANFISRegressor or None
        Unfitted template; None means ``ANFISRegressor(init="fcm", n_rules=3, random_state=random_state)``.
        Tune it through nested parameters, e.g. ``anfis__epochs``.
    random_state : int, RandomState or None
        Seeds the default template's FCM initialisation (ignored when ``anfis`` is given: seed that one).

    Attributes
    ----------
    anfis_ : the fitted ANFISRegressor (on AGO series)
    y_reference_ : first training target
    """

    def __init__(self, anfis: ANFISRegressor | None = None, random_state: int | np.random.RandomState | None = None):
        self.anfis = anfis
        self.random_state = random_state

    def _template(self) -> ANFISRegressor:
        if self.anfis is not None:
            return self.anfis
        return ANFISRegressor(init="fcm", n_rules=3, random_state=self.random_state)

    def _n_parameters(self, n_features):
        return self._template().n_parameters(n_features)

    def _samples_without_equation(self):
        return 0, ""  # ANFIS maps every accumulated sample X¹(k) → y¹(k)

    def _fit_changes(self, X0, y0):
        self.anfis_ = clone(self._template()).fit(ago(X0), ago(y0))

    def _predict_changes(self, X0):
        return iago(self.anfis_.predict(ago(X0)))
