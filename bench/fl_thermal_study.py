"""Measured-data study on FL_THERMAL part 1: every model, then sensor selection.

Run from the repository root:

    python bench/fl_thermal_study.py

Protocol: chronological split, first 60 % of the rows for training (0–19.3 h:
the 1250 and 2500 rpm runs, their stops and the start of the 3750 rpm run),
last 40 % for testing (19.3–32.1 h: the rest of 3750 rpm and the unseen
5000 rpm run). Nothing is shuffled, nothing is tuned on the test part: every
model uses its documented defaults. Static models (MLR, PCR, ANN, ANFIS)
map the temperatures at time t to the displacement at t; grey models are
time-series models, calibrated on the training part and run over the whole
series from its first sample (the thesis's "calibrate on the first stage,
predict the rest"), scored on the test part.

The data are read from ``../shared/data/fl_thermal/`` (or the folder in
``THERMAL_TWIN_FL_THERMAL``) and never copied.
"""

from __future__ import annotations

import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from models import (  # noqa: E402
    AGOANFISRegressor,
    ANFISRegressor,
    ANNRegressor,
    GM0NRegressor,
    GM1NRegressor,
    GMCRegressor,
    GNNMCIRegressor,
    MLRRegressor,
    PCRRegressor,
    chronological_prediction,
    max_abs_residual,
    rmse,
    select_sensors,
)
from models.selection import METHODS  # noqa: E402

CHANNELS = [f"ch{i}_um" for i in range(1, 6)]
TEMPERATURES = [f"t{i}_degC" for i in range(1, 17)]
TRAIN_FRACTION = 0.6
N_SELECT = 5
SEED = 0


def data_dir() -> Path:
    """The FL_THERMAL folder: $THERMAL_TWIN_FL_THERMAL or ../shared/data/fl_thermal."""
    env = os.environ.get("THERMAL_TWIN_FL_THERMAL")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data" / "fl_thermal"


def model_zoo():
    """Every model with its documented defaults (name → unfitted estimator)."""
    return {
        "MLR (baseline)": MLRRegressor(),
        "PCR (85 %)": PCRRegressor(),
        "ANN 16-10-1": ANNRegressor(random_state=SEED),
        "ANFIS-FCM, 3 rules": ANFISRegressor(n_rules=3, epochs=50, validation_fraction=0.2, random_state=SEED),
        "GM(0,N)": GM0NRegressor(),
        "GM(1,N)": GM1NRegressor(),
        "GMC(1,N) LS": GMCRegressor(),
        "GMC(1,N) PSO": GMCRegressor(calibration="pso", random_state=SEED),
        "GNNMCI(1,N) PSO": GNNMCIRegressor(random_state=SEED),
        "AGO-ANFIS, 3 rules": AGOANFISRegressor(ANFISRegressor(n_rules=3, epochs=50, random_state=SEED)),
    }


def cell(y_test, pred, model) -> str:
    """``RMSE / max|res|`` in µm; unstable grey fits (development coefficient < 0) marked †."""
    unstable = getattr(model, "development_coefficient_", 0.0) < 0.0
    mark = " †" if unstable else ""
    err = rmse(y_test, pred)
    if not np.isfinite(err) or err > 1e3:
        return f"diverges{mark}"
    return f"{err:.2f} / {max_abs_residual(y_test, pred):.1f}{mark}"


def table(title, header, rows):
    print(f"\n### {title}\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for row in rows:
        print("| " + " | ".join(row) + " |")


def main() -> None:
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    frame = pd.read_csv(data_dir() / "fl_thermal_part1.csv")
    n_train = int(TRAIN_FRACTION * len(frame))
    T = frame[TEMPERATURES].to_numpy()
    T_rpm = np.column_stack([T, frame["spindle_rpm"].to_numpy() / 1000.0])  # rpm in thousands
    Y = {ch: frame[ch].to_numpy() for ch in CHANNELS}
    print(
        f"FL_THERMAL part 1: {len(frame)} rows, train rows 0..{n_train - 1} "
        f"(0-{frame.time_s[n_train - 1] / 3600:.1f} h), test rows {n_train}..{len(frame) - 1} "
        f"({frame.time_s[n_train] / 3600:.1f}-{frame.time_s.iloc[-1] / 3600:.1f} h)."
    )
    header = ["model"] + [f"{ch} RMSE / max" for ch in CHANNELS]
    uncompensated = ["uncompensated"] + [
        f"{rmse(Y[ch][n_train:], np.zeros(len(frame) - n_train)):.2f} / {np.max(np.abs(Y[ch][n_train:])):.1f}"
        for ch in CHANNELS
    ]

    rows = [uncompensated]
    for name, template in model_zoo().items():
        row = [name]
        for ch in CHANNELS:
            model = template.__class__(**template.get_params(deep=False))
            row.append(cell(Y[ch][n_train:], chronological_prediction(model, T, Y[ch], n_train), model))
        rows.append(row)
    table("Test part, 16 temperatures as inputs (µm)", header, rows)

    rows = [uncompensated]
    for name in ("MLR (baseline)", "PCR (85 %)", "ANN 16-10-1", "ANFIS-FCM, 3 rules"):
        template = model_zoo()[name]
        row = [name.replace("16-10-1", "17-10-1") + " + rpm"]
        for ch in CHANNELS:
            model = template.__class__(**template.get_params(deep=False))
            row.append(cell(Y[ch][n_train:], chronological_prediction(model, T_rpm, Y[ch], n_train), model))
        rows.append(row)
    table("Test part, 16 temperatures + spindle_rpm (static models, µm)", header, rows)

    baseline = {ch: rmse(Y[ch][n_train:], chronological_prediction(MLRRegressor(), T, Y[ch], n_train)) for ch in CHANNELS}
    rows = []
    for method in METHODS:
        picks, mlr, anfis = [], [], []
        for ch in CHANNELS:
            sel = select_sensors(T[:n_train], Y[ch][:n_train], method=method, n_select=N_SELECT, random_state=SEED)
            cols = np.sort(sel.indices)
            picks.append(cols)
            mlr.append(rmse(Y[ch][n_train:], chronological_prediction(MLRRegressor(), T[:, cols], Y[ch], n_train)))
            model = ANFISRegressor(n_rules=3, epochs=50, validation_fraction=0.2, random_state=SEED)
            anfis.append(rmse(Y[ch][n_train:], chronological_prediction(model, T[:, cols], Y[ch], n_train)))
        wins = sum(m < baseline[ch] for m, ch in zip(mlr, CHANNELS))
        rows.append(
            [method, " ".join(f"T{c + 1}" for c in picks[2])]
            + [f"{m:.2f} / {a:.2f}" for m, a in zip(mlr, anfis)]
            + [f"{wins}/5"]
        )
    table(
        f"Sensor selection on the training part, {N_SELECT} of 16 sensors per channel "
        "(test RMSE µm: MLR / ANFIS-FCM 3 rules on the chosen sensors)",
        ["method", "chosen for ch3"] + CHANNELS + ["MLR beats 16-sensor MLR"],
        [["MLR on all 16 (baseline)", "T1-T16"] + [f"{baseline[ch]:.2f}" for ch in CHANNELS] + ["-"]] + rows,
    )
    print(f"\n† development coefficient < 0: an unstable grey model. Total time {time.perf_counter() - start:.0f} s.")


if __name__ == "__main__":
    main()
