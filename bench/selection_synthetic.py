"""Does the model-selection rule predict generalisation?  Checked on full-FE records with a known continuation.

FL_THERMAL part 1 has one later block (block 4, 5000 rpm), and it has been
looked at, so a rule cannot be judged on it again.  This study makes new
records by another route: the full FE of ``vmc_ram`` (not a data-driven
model) under physics changes that none of the candidates knows
(:data:`DEVELOPMENT`, :data:`TEST`), on ``scenarios/regime_blocks_56h.toml``,
a record shaped like FL_THERMAL part 1 (four regime blocks: a 4 h run at
2000/4000/6000/8000 rpm and the 4 h stop after it) followed by a 24 h
continuation with speeds and a duty pattern part 1 does not have (5000 rpm,
10 min cycles at 10000 rpm, 3000 rpm, 10000 rpm).  The sixteen
"temperatures" are laid out like FL_THERMAL's (:data:`LAYOUTS`, two
layouts); the targets are the Y and Z drifts at the tool and the column-top
probe, zero-referenced at the first row.  The candidates are those of
``bench/fl_thermal_study.py``.

For every record and channel, two questions:

* **later block** (FL_THERMAL's protocol): the rule on blocks 1-3, judged on
  block 4 by candidates trained on blocks 1-3;
* **continuation** (the issue's protocol): the rule on all of part 1, judged
  on the continuation by candidates trained on all of part 1.

Four rules (:data:`RULES`): leave-one-block-out folds with or without the
rolling-origin ones, each candidate's fold RMSEs pooled by the arithmetic
mean or by the mean of their logs (the geometric mean).  The rule with the
highest median Spearman ρ on the development cases is chosen
(:func:`chosen_rule`) and judged on the test cases (:data:`SPLITS`; the
history of what ran when is above :data:`DEVELOPMENT` and :data:`TEST_2`).
Reported: the rank agreement, how often the rule's choice beats MLR on the
16 temperatures, and its RMSE over the best candidate's in hindsight, each
with the best-scored candidate and with the parsimony among nested grey-box
orders (:func:`~models.selection_cv.parsimonious_choice`, the one-standard-
error rule).  The parsimony was added once every case up to :data:`TEST_2`
had been seen, and shipped by a criterion fixed before its first run (a
lower geometric mean of choice RMSE over best in hindsight on those seen
cases, both questions); :data:`TEST_3` judges it.  The folds were made distinct once every case up to
:data:`TEST_3` had been seen (the last block's fold had been counted twice, as leave-one-block-out and as
rolling origin); :data:`TEST_4` judges the rules with distinct folds.  Then a series model's fold that
leaves out the first block was found offset by another block's start level; :data:`TEST_5` judges the rules
with it mended.

Run from the repository root (about 14 min on 2 cores, FE truths included;
they are cached under ``THERMAL_TWIN_CACHE``)::

    python bench/selection_synthetic.py [--workers 2]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from sklearn.base import clone

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fl_thermal_study import candidate_rmse, candidates, fmt

from models.selection_cv import (
    SCHEMES,
    Fold,
    geometric_mean_rmse,
    margin,
    parsimonious_choice,
    rank_agreement,
    regime_blocks,
    select_by_blocked_cv,
)
from twin.gap.truth import PhysicsChange, physics_truth
from twin.live.protocol import (
    BASE_FLOOR,
    BELT,
    CARRIER_SIDE,
    COLUMN_BACK,
    COLUMN_SIDE,
    RAM_FLANK,
    SPINDLE_SOURCES,
    TABLE_COOLANT,
)

SCENARIO = ROOT / "scenarios" / "regime_blocks_56h.toml"
PART1_END_S = 32.5 * 3600.0
#: Sixteen temperatures in FL_THERMAL's layout: t4 and t16 room air (t4 with the HVAC cycle), t5 a thermometer
#: that follows every run.  "near" holds the spindle nose (t5), the carrier strips and the spindle motor;
#: "remote" nothing at the spindle nose or the carrier's front: the column, the base, the Z drive, the carrier
#: strips' back end and the spindle motor (t5), as on a machine instrumented where sensors were easy to fit.
LAYOUTS = {
    "near": ("T01", "T03", "T05", "T15", "T18", "T08", "T10", "T12",
             "T14", "T16", "T17", "T19", "T20", "T23", "T26", "A_top"),
    "remote": ("T01", "T02", "T08", "T15", "T20", "T09", "T16", "T17",
               "T21", "T22", "T23", "T24", "T25", "T26", "A_spindle", "A_top"),
}
#: µm; X is left out: the machine is symmetric about x = 0 and its X drift is noise (|X| < 0.3 µm)
CHANNELS = ("Y", "Z", "Y_top")
BASELINE = "MLR (baseline)"
QUESTIONS = ("later block", "continuation")


#: The rules compared: which folds, and how a candidate's fold RMSEs are pooled (lower is better).  The mean of
#: log RMSE (the geometric mean) weighs every regime alike; the plain mean is ruled by the regime with the largest
#: drift.
_GEOMETRIC_MEAN = partial(geometric_mean_rmse, floor=0.0)
RULES = {
    "LOBO + rolling origin, mean": (SCHEMES, np.mean),
    "LOBO, mean": (("leave-one-block-out",), np.mean),
    "LOBO + rolling origin, mean log": (SCHEMES, _GEOMETRIC_MEAN),
    "LOBO, mean log": (("leave-one-block-out",), _GEOMETRIC_MEAN),
}
#: Ties in the choice of rule go to the first round's rule (the first of :data:`RULES`).
INCUMBENT = next(iter(RULES))


@dataclass(frozen=True)
class Case:
    """A physics change of the truth and its noise seed."""

    label: str
    change: PhysicsChange = field(default_factory=PhysicsChange)
    seed: int = 0


#: The rule is chosen on DEVELOPMENT and judged once on TEST.  History, so that nothing is hidden: an earlier
#: version of this script ran the "near" layout of the six DEVELOPMENT cases once, with the first two rules only,
#: and that run was read (cases 705 and 706 were then meant as test cases; they moved to DEVELOPMENT for it).
#: The "remote" layout, the mean-log rules and the TEST cases 707-710 were added after that run, and none of
#: them had run when the rule choice (:func:`chosen_rule`) was fixed.
DEVELOPMENT = (
    Case("nominal", PhysicsChange(), 701),
    Case("spindle speed exponents + 0.4", PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, 0.4)), 702),
    Case("enclosure convection × 0.6, enclosure air lag 3 h",
         PhysicsChange(convection={"enclosure": 0.6}, zone_lags_h={"enclosure": 3.0}), 703),
    Case("ram α × 1.1, carrier–ram joint × 0.3", PhysicsChange(expansion={"ram": 1.1}, joints={"carrier-ram": 0.3}), 704),
    Case("spindle sources × 1.4", PhysicsChange(source_scale=dict.fromkeys(SPINDLE_SOURCES, 1.4)), 705),
    Case("outer convection × 1.5, column–carrier joint × 0.5",
         PhysicsChange(convection={"outside": 1.5}, joints={"column-carrier": 0.5}), 706),
)
TEST = (
    Case("spindle speed exponents − 0.3, base–column joint × 0.3",
         PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, -0.3), joints={"base-column": 0.3}), 707),
    Case("60 W belt drive on the carrier", PhysicsChange(sources=(BELT,)), 708),
    Case("spindle sources × 0.7, enclosure air lag 6 h",
         PhysicsChange(source_scale=dict.fromkeys(SPINDLE_SOURCES, 0.7), zone_lags_h={"enclosure": 6.0}), 709),
    Case("50 W coolant tank in the base floor", PhysicsChange(sources=(BASE_FLOOR,)), 710),
)
#: Held out a second time, fixed before it first ran: TEST was judged once with the first grey-box fit, which
#: let the exponent b run to a bound on a single training speed; the fit now keeps b at its start value there
#: (:class:`~models.greybox.GreyBoxRegressor`), and these cases judge the rule with it.
TEST_2 = (
    Case("spindle speed exponents + 0.2, front convection × 0.5",
         PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, 0.2), convection={"front": 0.5}), 711),
    Case("40 W hydraulic clamp on the carrier's left side", PhysicsChange(sources=(CARRIER_SIDE,)), 712),
    Case("enclosure convection × 1.5, spindle sources × 1.2",
         PhysicsChange(convection={"enclosure": 1.5}, source_scale=dict.fromkeys(SPINDLE_SOURCES, 1.2)), 713),
    Case("column–carrier joint × 0.3, outer convection × 0.6, enclosure air lag 3 h",
         PhysicsChange(joints={"column-carrier": 0.3}, convection={"outside": 0.6}, zone_lags_h={"enclosure": 3.0}),
         714),
)
#: Held out a third time, fixed before it first ran: every case above had been seen when the parsimony among
#: nested grey-box orders (:func:`~models.selection_cv.select_by_blocked_cv`) was written; these judge it.
TEST_3 = (
    Case("spindle speed exponents − 0.2, 40 W on the column's back wall",
         PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, -0.2), sources=(COLUMN_BACK,)), 715),
    Case("30 W on the ram's left flank, ram α × 0.9",
         PhysicsChange(sources=(RAM_FLANK,), expansion={"ram": 0.9}), 716),
    Case("outer convection × 0.8, enclosure air lag 4 h, carrier–ram joint × 0.5",
         PhysicsChange(convection={"outside": 0.8}, zone_lags_h={"enclosure": 4.0}, joints={"carrier-ram": 0.5}),
         717),
    Case("45 W hydraulic unit on the column's left side, spindle sources × 1.1",
         PhysicsChange(sources=(COLUMN_SIDE,), source_scale=dict.fromkeys(SPINDLE_SOURCES, 1.1)), 718),
)
#: Held out a fourth time, fixed before it first ran: every case above had been seen when the folds were made
#: distinct (rolling origin into the last block is leaving it out, and it had been counted twice, see
#: :func:`~models.selection_cv.blocked_folds`); these judge the rules with distinct folds.
TEST_4 = (
    Case("spindle speed exponents + 0.3, column α × 1.1",
         PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, 0.3), expansion={"column": 1.1}), 719),
    Case("40 W of warm coolant on the table top, front convection × 1.5",
         PhysicsChange(sources=(TABLE_COOLANT,), convection={"front": 1.5}), 720),
    Case("spindle sources × 0.8, base–column joint × 0.5, enclosure air lag 2 h",
         PhysicsChange(source_scale=dict.fromkeys(SPINDLE_SOURCES, 0.8), joints={"base-column": 0.5},
                       zone_lags_h={"enclosure": 2.0}), 721),
    Case("60 W belt drive on the carrier, carrier–ram joint × 0.7, outer convection × 1.2",
         PhysicsChange(sources=(BELT,), joints={"carrier-ram": 0.7}, convection={"outside": 1.2}), 722),
)
#: Held out a fifth time, fixed before it first ran: every case above had been seen when a series model's fold
#: that leaves out the first block was found scored against another block's start level (its first training
#: target; see :func:`~models.selection_cv.fold_prediction`); these judge the rules with that fold mended.
TEST_5 = (
    Case("spindle speed exponents − 0.1, carrier α × 1.1",
         PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, -0.1), expansion={"carrier": 1.1}), 723),
    Case("30 W on the ram's left flank, front convection × 0.7",
         PhysicsChange(sources=(RAM_FLANK,), convection={"front": 0.7}), 724),
    Case("spindle sources × 1.3, column–carrier joint × 0.7, enclosure air lag 5 h",
         PhysicsChange(source_scale=dict.fromkeys(SPINDLE_SOURCES, 1.3), joints={"column-carrier": 0.7},
                       zone_lags_h={"enclosure": 5.0}), 725),
    Case("50 W coolant tank in the base floor, outer convection × 0.7, base–column joint × 0.7",
         PhysicsChange(sources=(BASE_FLOOR,), convection={"outside": 0.7}, joints={"base-column": 0.7}), 726),
)
#: Held out a sixth time, fixed before it first ran: every case above had been seen when `twin train --select
#: auto` began to pass over a choice whose fit on all the training rows leaves its slowest pole undetermined
#: (:meth:`~models.greybox.GreyBoxRegressor.determined_by`); these judge that.
TEST_6 = (
    Case("spindle speed exponents + 0.1, enclosure convection × 0.8",
         PhysicsChange(source_exponent=dict.fromkeys(SPINDLE_SOURCES, 0.1), convection={"enclosure": 0.8}), 727),
    Case("40 W on the column's back wall, base–column joint × 0.6",
         PhysicsChange(sources=(COLUMN_BACK,), joints={"base-column": 0.6}), 728),
    Case("spindle sources × 1.2, carrier α × 0.9, enclosure air lag 4 h",
         PhysicsChange(source_scale=dict.fromkeys(SPINDLE_SOURCES, 1.2), expansion={"carrier": 0.9},
                       zone_lags_h={"enclosure": 4.0}), 729),
    Case("50 W coolant tank in the base floor, front convection × 1.3",
         PhysicsChange(sources=(BASE_FLOOR,), convection={"front": 1.3}), 730),
)
SPLITS = {"development": DEVELOPMENT, "test": TEST, "test 2": TEST_2, "test 3": TEST_3, "test 4": TEST_4,
          "test 5": TEST_5, "test 6": TEST_6}


def study_arrays(case: Case, layout: str):
    """``X`` = [time_s, spindle_rpm, 16 temperatures], zero-referenced targets (µm), speed, part-1 row count."""
    data = physics_truth(SCENARIO, case.change, seed=case.seed)
    time_s, speed = data.time_s, data["spindle"]
    X = np.column_stack([time_s, speed, data.matrix(list(LAYOUTS[layout]))])
    targets = {ch: data[ch] - data[ch][0] for ch in CHANNELS}
    return X, targets, speed, int(np.searchsorted(time_s, PART1_END_S))


def rule_choices(selection, rule: str, zoo) -> tuple[dict[str, float], str, str, bool, list[str]]:
    """Each candidate's score under ``rule`` (from the fold RMSEs of one all-schemes selection), the best-scored
    candidate, the choice with the parsimony among nested grey-box orders, whether the folds cannot tell
    that choice from the next-best candidate (:func:`~models.selection_cv.margin`), and the ranking."""
    schemes, pool = RULES[rule]
    keep = [i for i, name in enumerate(selection.folds) if name.rsplit(" block ", 1)[0] in schemes]
    folds = {k: [v[i] for i in keep] for k, v in selection.fold_rmse.items()}
    score = {k: float(pool(v)) for k, v in folds.items()}
    ranking = sorted(score, key=lambda k: (score[k], k))
    chosen = parsimonious_choice(zoo, folds, ranking[0], floor=np.finfo(float).tiny)
    found = margin(ranking, chosen, folds, floor=np.finfo(float).tiny)
    return score, ranking[0], chosen, found is not None and found[2], ranking


def determined(zoo, X, y, n_fit, name, seen) -> bool:
    """Whether `twin train --select auto` keeps candidate ``name`` fitted on rows ``[0, n_fit)``: it passes over a
    grey-box fit whose slowest pole those rows do not determine (:meth:`~models.greybox.GreyBoxRegressor.
    determined_by`; its stability checks are not repeated here). ``seen`` caches the answers of one record."""
    if name not in seen:
        estimator, cols = zoo[name]
        seen[name] = not hasattr(estimator, "determined_by") or clone(estimator).fit(
            X[:n_fit, list(cols)], y[:n_fit]).determined_by(X[n_fit - 1, 0] - X[0, 0])
    return seen[name]


def judge(X, y, speed, n_fit, test, zoo):
    """Every rule's scores and choices on rows ``[0, n_fit)``, and the candidates' RMSE on ``test`` trained on
    those rows."""
    selection = select_by_blocked_cv(zoo, X[:n_fit], y[:n_fit], speed[:n_fit], schemes=SCHEMES)
    judged_fold = Fold("judged", 0, test, np.arange(test[1]) < n_fit)
    judged = candidate_rmse(zoo, X[: test[1]], y[: test[1]], judged_fold)
    return {rule: rule_choices(selection, rule, zoo) for rule in RULES}, judged


def run_case(task) -> list[dict]:
    """Both questions, every rule, every channel of one case and layout."""
    split, case, layout = task
    warnings.simplefilter("ignore")
    X, targets, speed, n1 = study_arrays(case, layout)
    blocks = regime_blocks(speed[:n1])
    if len(blocks) != 4:
        raise RuntimeError(f"{SCENARIO.name}: expected 4 regime blocks in part 1, found {len(blocks)}")
    zoo = candidates()
    rows = []
    for ch, y in targets.items():
        for question, n_fit, test in zip(QUESTIONS, (blocks[-1][0], n1), (blocks[-1], (n1, len(X)))):
            choices, judged = judge(X, y, speed, n_fit, test, zoo)
            best = min(judged, key=judged.get)
            seen = {}
            for rule, (score, choice, parsimonious, indistinct, ranking) in choices.items():
                trained = next((name for name in (parsimonious, *ranking) if np.isfinite(score[name])
                                and determined(zoo, X, y, n_fit, name, seen)), parsimonious)
                rows.append({"split": split, "case": case.label, "layout": layout, "channel": ch,
                             "question": question, "rule": rule, "rho": rank_agreement(score, judged),
                             "choice": choice, "choice_rmse": judged[choice],
                             "parsimonious": parsimonious, "parsimonious_rmse": judged[parsimonious],
                             "indistinct": indistinct, "trained": trained, "trained_rmse": judged[trained],
                             "baseline_rmse": judged[BASELINE], "best": best, "best_rmse": judged[best]})
    return rows


def chosen_rule(rows) -> str:
    """The rule with the highest median ρ on the development cases (both questions, both layouts)."""
    median = {rule: np.median([r["rho"] for r in rows if r["split"] == "development" and r["rule"] == rule])
              for rule in RULES}
    return max(RULES, key=lambda rule: (median[rule], rule == INCUMBENT))


def summary(rows, split, chosen) -> None:
    print(f"\n#### {split} cases ({'the rule was chosen here' if split == 'development' else 'judged'})\n")
    print("| question | layout | rule | median ρ | ρ ≥ 0.8 | choice beats MLR16 | "
          "median choice RMSE / best in hindsight | with parsimony: beats MLR16 | median RMSE / best |")
    print("|---|---|---|---|---|---|---|---|---|")
    for question in QUESTIONS:
        for layout in ("both", *LAYOUTS):
            for rule in RULES:
                sel = [r for r in rows if r["split"] == split and r["question"] == question and r["rule"] == rule
                       and layout in ("both", r["layout"])]
                rho = np.array([r["rho"] for r in sel])
                mark = " (chosen)" if rule == chosen else ""
                print(f"| {question} | {layout} | {rule}{mark} | {np.median(rho):.2f} | {np.sum(rho >= 0.8)}/{len(sel)} "
                      + "".join(f"| {sum(r[key + '_rmse'] < r['baseline_rmse'] for r in sel)}/{len(sel)} "
                                f"| {np.median([r[key + '_rmse'] / r['best_rmse'] for r in sel]):.2f} "
                                for key in ("choice", "parsimonious")) + "|")


def details(rows, chosen) -> None:
    print(f"\n#### Per case, the chosen rule ({chosen}); RMSE in µm\n")
    print("| split | case | layout | channel | question | ρ | choice | its RMSE | with parsimony | trained | MLR16 | "
          "best in hindsight |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if r["rule"] == chosen:
            nested = "same" if r["parsimonious"] == r["choice"] else \
                f"{r['parsimonious']} {fmt(r['parsimonious_rmse'])}"
            trained = "same" if r["trained"] == r["parsimonious"] else f"{r['trained']} {fmt(r['trained_rmse'])}"
            print(f"| {r['split']} | {r['case']} | {r['layout']} | {r['channel']} | {r['question']} | {r['rho']:.2f} | "
                  f"{r['choice']} | {fmt(r['choice_rmse'])} | {nested} | {trained} | {fmt(r['baseline_rmse'])} | "
                  f"{r['best']} {fmt(r['best_rmse'])} |")


def chosen_rule_rows(rows, split, question, chosen) -> list[dict]:
    """The rows of one split and question under the chosen rule."""
    return [r for r in rows if r["split"] == split and r["question"] == question and r["rule"] == chosen]


def geometric_regret(rows, key) -> float:
    """Geometric mean over ``rows`` of ``row[key + "_rmse"]`` over the best in hindsight (nan without rows)."""
    return float(np.exp(np.mean([np.log(r[key + "_rmse"] / r["best_rmse"]) for r in rows]))) if rows else np.nan


def parsimony_summary(rows, chosen) -> None:
    """The chosen rule with and without the parsimony among nested grey-box orders: geometric-mean RMSE over the
    best in hindsight, and how often the choice changes and gets better or worse."""
    print(f"\n#### Parsimony among nested grey-box orders, with the chosen rule ({chosen})\n")
    print("| split | question | choices changed | better / worse | geometric-mean RMSE / best: without | with |")
    print("|---|---|---|---|---|---|")
    for split in dict.fromkeys(r["split"] for r in rows):
        for question in QUESTIONS:
            sel = chosen_rule_rows(rows, split, question, chosen)
            changed = [r for r in sel if r["parsimonious"] != r["choice"]]
            better = sum(r["parsimonious_rmse"] < r["choice_rmse"] for r in changed)
            worse = sum(r["parsimonious_rmse"] > r["choice_rmse"] for r in changed)
            print(f"| {split} | {question} | {len(changed)}/{len(sel)} | {better} / {worse} | "
                  f"{geometric_regret(sel, 'choice'):.3f} | {geometric_regret(sel, 'parsimonious'):.3f} |")


def identification_summary(rows, chosen) -> None:
    """The chosen rule's choice (with parsimony) against what `twin train --select auto` trains: the next in rank
    where the choice's fit on all the training rows leaves its slowest pole undetermined."""
    print(f"\n#### Passing over an undetermined fit, with the chosen rule ({chosen}) and parsimony\n")
    print("| split | question | choices passed over | better / worse | geometric-mean RMSE / best: choice | "
          "trained |")
    print("|---|---|---|---|---|---|")
    for split in dict.fromkeys(r["split"] for r in rows):
        for question in QUESTIONS:
            sel = chosen_rule_rows(rows, split, question, chosen)
            changed = [r for r in sel if r["trained"] != r["parsimonious"]]
            better = sum(r["trained_rmse"] < r["parsimonious_rmse"] for r in changed)
            worse = sum(r["trained_rmse"] > r["parsimonious_rmse"] for r in changed)
            print(f"| {split} | {question} | {len(changed)}/{len(sel)} | {better} / {worse} | "
                  f"{geometric_regret(sel, 'parsimonious'):.3f} | {geometric_regret(sel, 'trained'):.3f} |")


def margin_summary(rows, chosen) -> None:
    """Whether the reason's last sentence means something: the chosen rule's choices (with parsimony) that the
    folds cannot tell from the next-best candidate, against the clear ones, by their RMSE over the best in
    hindsight (geometric mean) and how often they beat MLR16."""
    print(f"\n#### Choices the folds cannot tell from the next-best, with the chosen rule ({chosen}) and parsimony\n")
    print("| split | question | flagged | flagged: geometric-mean RMSE / best | beats MLR16 | "
          "clear: geometric-mean RMSE / best | beats MLR16 |")
    print("|---|---|---|---|---|---|---|")
    for split in dict.fromkeys(r["split"] for r in rows):
        for question in QUESTIONS:
            sel = chosen_rule_rows(rows, split, question, chosen)
            cells = []
            for flagged in (True, False):
                part = [r for r in sel if r["indistinct"] == flagged]
                beats = sum(r["parsimonious_rmse"] < r["baseline_rmse"] for r in part)
                cells.append(f"{geometric_regret(part, 'parsimonious'):.3f} | {beats}/{len(part)}")
            print(f"| {split} | {question} | {sum(r['indistinct'] for r in sel)}/{len(sel)} | "
                  f"{cells[0]} | {cells[1]} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    parser.add_argument("--splits", default=",".join(SPLITS),
                        help=f"comma-separated splits to run (default all: {', '.join(SPLITS)})")
    args = parser.parse_args()
    splits = args.splits.split(",")
    unknown = sorted(set(splits) - set(SPLITS))
    if unknown or "development" not in splits:
        parser.error(f"--splits: need 'development' and known splits ({', '.join(SPLITS)}), got {args.splits!r}")
    start = time.perf_counter()
    tasks = [(split, case, layout) for split in splits for case in SPLITS[split] for layout in LAYOUTS]
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = [row for case_rows in pool.map(run_case, tasks) for row in case_rows]
    chosen = chosen_rule(rows)
    details(rows, chosen)
    for split in splits:
        summary(rows, split, chosen)
    parsimony_summary(rows, chosen)
    identification_summary(rows, chosen)
    margin_summary(rows, chosen)
    print(f"\nRule chosen on the development cases (highest median ρ): {chosen}.")
    print(f"{len(tasks)} records ({len(LAYOUTS)} sensor layouts) × {len(CHANNELS)} channels × 2 questions, "
          f"{len(candidates())} candidates; {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
