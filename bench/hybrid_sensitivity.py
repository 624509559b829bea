"""How far the hybrid study's figures move when its records move by 1e-12 of themselves.

Run from the repository root (about 3 min on 2 cores: the study's 16
simulations once, then the data-driven and residual fits per draw):

    python bench/hybrid_sensitivity.py [--draws 8]

``twin study hybrid`` (``docs/compensation.md``) fits ANFIS-FCM twice per
axis: to the drift (data-driven) and to the physics residual (hybrid). The
default ANFIS trains by Jang's rule, whose step size follows counts of
consecutive error decreases, so a difference in the last bits of the data
can change the path the premises take and the minimum they end in. Each draw
multiplies every value of every record by ``1 + 1e-12·z`` (z standard normal,
seeded by the draw number; the inputs chosen on the unperturbed records are
kept) and refits; draw 0 is the records as simulated. The table gives each
approach's pooled held-out RMSE and max |residual| (µm) per draw and their
range, and on how many of the held-out records the hybrid is best.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from twin.compensation.studies import (
    DEFAULT_GAP,
    HYBRID_TEST,
    HYBRID_TRAIN,
    hybrid_records,
    hybrid_scores,
    select_inputs,
)
from twin.compensation.train import format_table
from twin.core.dataset import Dataset

RELATIVE_PERTURBATION = 1e-12


def perturbed(records, draw):
    """The records with every value multiplied by 1 + 1e-12·z (draw 0: unchanged)."""
    if draw == 0:
        return records
    rng = np.random.default_rng(draw)
    return [Dataset(ds.time_s, ds.values * (1.0 + RELATIVE_PERTURBATION * rng.standard_normal(ds.values.shape)),
                    ds.channels, ds.metadata) for ds in records]


def hybrid_wins(rows, axis, measure):
    """Held-out records of ``axis`` on which the hybrid has the lowest ``measure``."""
    held_out = [r for r in rows if r["axis"] == axis and r["role"] == "held-out"]
    records = dict.fromkeys(r["dataset"] for r in held_out)
    return sum(min((r for r in held_out if r["dataset"] == d), key=lambda r: r[measure])["approach"]
               .startswith("hybrid") for d in records), len(records)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=8, help="perturbed draws besides the records as simulated")
    args = parser.parse_args()
    t0 = time.perf_counter()
    axes = ("Z", "Y")
    measured, physics, train, _ = hybrid_records(HYBRID_TRAIN, HYBRID_TEST, axes, dict(DEFAULT_GAP),
                                                 scheduler="serial")
    inputs = {axis: select_inputs(measured[:len(train)], axis) for axis in axes}
    print(f"simulations: {time.perf_counter() - t0:.0f} s; inputs: "
          + "; ".join(f"{a}: {', '.join(n)}" for a, n in inputs.items()))
    rows_out, spread = [], {}
    for draw in range(args.draws + 1):
        rows, _, pooled = hybrid_scores(perturbed(measured, draw), physics, len(train), axes, "anfis", inputs)
        for p in pooled:
            approach = p["approach"].split(" ")[0]
            spread.setdefault((p["axis"], approach), []).append((p["rmse"], p["max_residual"]))
            row = {"draw": draw, "axis": p["axis"], "approach": approach, "pooled RMSE (um)": p["rmse"],
                   "pooled max |residual| (um)": p["max_residual"]}
            if approach == "hybrid":
                won, n = hybrid_wins(rows, p["axis"], "rmse")
                won_max, _ = hybrid_wins(rows, p["axis"], "max_residual")
                row["hybrid best (RMSE / max) of"] = f"{won} / {won_max} of {n}"
            rows_out.append(row)
    cols = ["draw", "axis", "approach", "pooled RMSE (um)", "pooled max |residual| (um)",
            "hybrid best (RMSE / max) of"]
    print(format_table(rows_out, cols), end="")
    print("\nrange over the draws (um):")
    for (axis, approach), values in spread.items():
        rmse, peak = np.array(values).T
        print(f"  {axis} {approach}: RMSE {rmse.min():.3g}-{rmse.max():.3g}, max |residual| "
              f"{peak.min():.3g}-{peak.max():.3g}")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
