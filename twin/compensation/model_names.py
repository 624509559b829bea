"""The compensation models ``twin train`` knows, by name.

Data only, importing nothing, so the command line lists the names in its help
without loading numpy (start-up time).
"""

#: Model names → (class name in ``models``, default hyperparameters).
MODEL_NAMES = {
    "mlr": ("MLRRegressor", {}),
    "pcr": ("PCRRegressor", {}),
    "ann": ("ANNRegressor", {"random_state": 0}),
    "anfis": ("ANFISRegressor", {"init": "fcm", "n_rules": 3, "epochs": 50, "random_state": 0}),
    "anfis-fcm": ("ANFISRegressor", {"init": "fcm", "n_rules": 3, "epochs": 50, "random_state": 0}),
    "anfis-grid": ("ANFISRegressor", {"init": "grid", "n_mfs": 2, "epochs": 50, "random_state": 0}),
    "gm0n": ("GM0NRegressor", {}),
    "gm1n": ("GM1NRegressor", {}),
    "gmc": ("GMCRegressor", {"random_state": 0}),
    "gnnmci": ("GNNMCIRegressor", {"random_state": 0}),
    "ago-anfis": ("AGOANFISRegressor", {}),
}
