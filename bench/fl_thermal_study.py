"""Measured-data study on FL_THERMAL part 1: every model, sensor selection, regime-blocked selection.

Run from the repository root (every section, or one with ``--section``):

    python bench/fl_thermal_study.py [--section split|loro|selection|timing]

``split`` (the first study): chronological split, first 60 % of the rows for training (0–19.3 h:
the 1250 and 2500 rpm runs, their stops and the start of the 3750 rpm run),
last 40 % for testing (19.3–32.1 h: the rest of 3750 rpm and the unseen
5000 rpm run). Nothing is shuffled, nothing is tuned on the test part: every
model uses its documented defaults. Static models (MLR, PCR, ANN, ANFIS)
map the temperatures at time t to the displacement at t; grey models are
time-series models, calibrated on the training part and run over the whole
series from its first sample (the thesis's "calibrate on the first stage,
predict the rest"), scored on the test part.

``loro``: leave-one-regime-out, every model family including the grey-box
RC model: each of the four regime blocks (a run at one speed and the stop
after it) is held out in turn (:mod:`models.selection_cv`).

``selection``: the selection rule (blocked CV, :func:`models.selection_cv.select_by_blocked_cv`)
on the first three blocks only, then every candidate trained on those three
blocks and scored once on the fourth (5000 rpm, a speed the rule never saw);
the Spearman rank agreement of the rule with that later block, of the first
round's arithmetic-mean score and of the old rule (one 60/40 chronological
split of the same three blocks); then the rule's choice on all of part 1.

``timing``: fit time of the grey-box model on the whole of part 1.

The data are read from ``../shared/data/fl_thermal/`` (or the folder in
``THERMAL_TWIN_FL_THERMAL``) and never copied.
"""

from __future__ import annotations

import argparse
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
from models.greybox import GreyBoxRegressor  # noqa: E402
from models.selection import METHODS  # noqa: E402
from models.selection_cv import (  # noqa: E402
    Fold,
    blocked_folds,
    held_out_rmse,
    rank_agreement,
    regime_blocks,
    select_by_blocked_cv,
)

CHANNELS = [f"ch{i}_um" for i in range(1, 6)]
TEMPERATURES = [f"t{i}_degC" for i in range(1, 17)]
TRAIN_FRACTION = 0.6
N_SELECT = 5
SEED = 0
#: X columns of the blocked studies: time_s, spindle_rpm, t1..t16 (t4 = the air, with the HVAC cycling)
TIME, SPEED, FIRST_T = 0, 1, 2
T_COLUMNS = tuple(range(FIRST_T, FIRST_T + 16))
AMBIENT = FIRST_T + 3   # t4
AIR_2 = FIRST_T + 15    # t16, the noisy air sensor
SPINDLE = FIRST_T + 4   # t5, the thermometer that follows every run


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


def candidates():
    """Every model family for the blocked studies: name → (unfitted estimator, columns of the study X)."""
    # the PSO calibrations (GMC PSO, GNNMCI) take 11-12 s per fit on 5,800 rows, about half of all the
    # fitting here, and in the split study return the LS point wherever LS is stable: left out of the
    # blocked studies so they run in minutes on a shared 2-core machine
    slow = {"GMC(1,N) PSO", "GNNMCI(1,N) PSO"}
    zoo = {name: (model, T_COLUMNS) for name, model in model_zoo().items() if name not in slow}
    heat_ambient = (TIME, SPEED, AMBIENT)
    zoo.update({
        "grey-box 1 pole, rpm + t4": (GreyBoxRegressor(n_poles=1, temperature_inputs=(2,)), heat_ambient),
        "grey-box 2 poles, rpm + t4": (GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)), heat_ambient),
        "grey-box 3 poles, rpm + t4": (GreyBoxRegressor(n_poles=3, temperature_inputs=(2,)), heat_ambient),
        "grey-box 2 poles, rpm + t4 + t16": (
            GreyBoxRegressor(n_poles=2, temperature_inputs=(2, 3)), (TIME, SPEED, AMBIENT, AIR_2)),
        "grey-box 2 poles, rpm + t4, observer on t5": (
            GreyBoxRegressor(n_poles=2, temperature_inputs=(2,), observed=(3,)), (TIME, SPEED, AMBIENT, SPINDLE)),
    })
    return zoo


def study_arrays(frame):
    """``X`` = [time_s, spindle_rpm, t1..t16], the targets per channel and the speed."""
    X = np.column_stack([frame["time_s"], frame["spindle_rpm"], frame[TEMPERATURES]]).astype(float)
    return X, {ch: frame[ch].to_numpy(float) for ch in CHANNELS}, frame["spindle_rpm"].to_numpy(float)


def candidate_rmse(zoo, X, y, fold):
    """Every candidate of ``zoo`` trained on ``fold``'s training rows and scored on its test rows: name → RMSE."""
    return {name: held_out_rmse(est, X[:, list(cols)], y, fold) for name, (est, cols) in zoo.items()}


def fmt(value):
    return f"{value:.2f}" if np.isfinite(value) and value < 1e3 else "diverges"


def loro_study(frame):
    """Leave-one-regime-out: each of the four blocks held out in turn, every family, every channel."""
    X, Y, speed = study_arrays(frame)
    blocks = regime_blocks(speed)
    folds = blocked_folds(blocks, schemes=("leave-one-block-out",))
    labels = [f"{int(speed[a:b].max())} rpm" for a, b in blocks]
    print("\nRegime blocks (run + stop): " + ", ".join(
        f"{lab} rows {a}..{b - 1}" for lab, (a, b) in zip(labels, blocks)))
    rows, ch3 = [], []
    for name, (estimator, cols) in candidates().items():
        Xc = X[:, list(cols)]
        per = {ch: [held_out_rmse(estimator, Xc, Y[ch], f) for f in folds] for ch in CHANNELS}
        rows.append([name] + [f"{fmt(np.mean(v))} / {fmt(np.max(v))}" for v in per.values()])
        ch3.append([name] + [fmt(v) for v in per["ch3_um"]])
    table("Leave one regime block out: mean / worst held-out-block RMSE over the 4 blocks (µm)",
          ["model"] + CHANNELS, rows)
    table("Leave one regime block out, ch3_um RMSE per held-out block (µm)",
          ["model"] + [f"block {i + 1} ({lab})" for i, lab in enumerate(labels)], ch3)


def selection_study(frame):
    """The selection rule on blocks 1-3 judged on block 4 (rank agreement, Spearman); the rule's choice on part 1."""
    X, Y, speed = study_arrays(frame)
    blocks = regime_blocks(speed)
    cut = blocks[-1][0]
    held_out = Fold("later block", len(blocks) - 1, blocks[-1], np.arange(len(X)) < cut)
    n_old = int(TRAIN_FRACTION * cut)
    old_split = Fold("60/40", 0, (n_old, cut), np.arange(cut) < n_old)
    zoo = candidates()
    rows, agreement, final = [], [], []
    for ch in CHANNELS:
        chosen = select_by_blocked_cv(zoo, X[:cut], Y[ch][:cut], speed[:cut])
        later = candidate_rmse(zoo, X, Y[ch], held_out)
        old = candidate_rmse(zoo, X[:cut], Y[ch][:cut], old_split)
        mean_pick = min(chosen.mean_rmse, key=lambda k: (chosen.mean_rmse[k], chosen.worst_rmse[k], k))
        old_pick = min(old, key=old.get)
        rows.append([ch, chosen.chosen, fmt(later[chosen.chosen]), mean_pick, fmt(later[mean_pick]), old_pick,
                     fmt(later[old_pick]), fmt(later["MLR (baseline)"]), min(later, key=later.get),
                     fmt(min(later.values()))])
        agreement.append([ch] + [f"{rank_agreement(scores, later):.2f}" for scores in (
            chosen.score, chosen.mean_rmse, old)])
        print(f"{ch}, blocks 1-3: {chosen.reason}")
        whole = select_by_blocked_cv(zoo, X, Y[ch], speed)
        other = whole.ranking[1] if whole.chosen == whole.ranking[0] else whole.ranking[0]
        final.append([ch, whole.chosen, fmt(whole.score[whole.chosen]), fmt(whole.worst_rmse[whole.chosen]),
                      other, fmt(whole.score[other]), fmt(whole.score["MLR (baseline)"])])
        print(f"{ch}, all of part 1: {whole.reason}")
    table(f"Chosen on blocks 1-3 (rows 0..{cut - 1}), scored once per candidate on block 4 (rows {cut}..{len(X) - 1}, "
          "5000 rpm), RMSE µm",
          ["channel", "blocked CV, geometric mean", "block 4", "blocked CV, arithmetic mean", "block 4 ",
           "60/40 split", "block 4  ", "MLR16 block 4", "best in hindsight", "its block 4"], rows)
    table(f"Rank agreement (Spearman, {len(zoo)} candidates) with block 4",
          ["channel", "blocked CV, geometric mean (the rule)", "blocked CV, arithmetic mean (first round)",
           "60/40 split"], agreement)
    table("The rule on all of part 1 (4 blocks: 6 folds, 4 leave-one-block-out and 2 more rolling-origin), µm",
          ["channel", "choice", "geometric-mean RMSE", "worst fold",
           "runner-up (the lowest score if a simpler order was chosen)", "its geometric mean",
           "MLR16 geometric mean"], final)


def timing_study(frame, repeats=3):
    """Fit time of the default-order grey-box model (2 poles, rpm + t4) on all of part 1, on its even 15 s
    stamps and on the same rows with the stamps jittered by up to ±1 s (seed 0: the uneven-sampling path)."""
    X, Y, _ = study_arrays(frame)
    Xc = X[:, [TIME, SPEED, AMBIENT]]
    jittered = Xc.copy()
    jittered[1:, 0] += np.random.default_rng(0).uniform(-1.0, 1.0, len(Xc) - 1)
    for ch, label, data in (("ch3_um", "", Xc), ("ch3_um", ", stamps jittered ±1 s", jittered)):
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            model = GreyBoxRegressor(n_poles=2, temperature_inputs=(2,)).fit(data, Y[ch])
            times.append(time.perf_counter() - start)
        print(f"\ngrey-box 2 poles, rpm + t4, fit on all {len(X)} rows of part 1 ({ch}{label}): "
              f"{min(times):.2f} s best of {repeats} (max {max(times):.2f} s), {model.n_iterations_} residual "
              f"evaluations in the best start, {model.parameter_summary()}, training RMSE "
              f"{model.training_rmse_:.2f} µm")


def split_study(frame) -> None:
    start = time.perf_counter()
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


SECTIONS = {"split": split_study, "loro": loro_study, "selection": selection_study, "timing": timing_study}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--section", choices=sorted(SECTIONS), action="append",
                        help="run only this section (repeatable; default: all)")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    frame = pd.read_csv(data_dir() / "fl_thermal_part1.csv")
    for name in args.section or SECTIONS:
        start = time.perf_counter()
        SECTIONS[name](frame)
        print(f"\n[{name}: {time.perf_counter() - start:.0f} s]")


if __name__ == "__main__":
    main()
