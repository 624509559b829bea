"""The gap diagnosis on densely sampled records of a finer mesh's truth: the discretisation floor (prints).

Run from the repository root (each case: a 35 mm full-FE truth of ``gap_quick_8h`` at 10 s, 2–3 min, then a
diagnosis of 1 min)::

    python bench/gap_dense.py none convection_enclosure

For each case (``none``: no effect; else a library effect at its benchmark truth value and hidden constants):
the verdict, the named effect, the sensors that are within their discretisation floor only
(:func:`twin.gap.verdict.mesh_limited`), the four largest floors against σ_j (sensor, floor and σ_j in its
unit) and the time the floor took.  At 10 s the
timing floor of ± half a sample is too small to hide the 45 mm twin's difference from the 35 mm truth
beside the Z feed's heat (T24).
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from twin.core.machine import build_machine
from twin.core.scenario import load_scenario
from twin.gap.benchmark import TRUTH_HIDDEN, TRUTH_VALUES
from twin.gap.diagnose import _machine, diagnose
from twin.gap.effects import default_library
from twin.gap.truth import truth_dataset
from twin.gap.verdict import mesh_limited, sentence

#: Sampling interval and truth time step of the dense records, s.
DENSE_S = 10.0
#: Truth mesh size, m (the twin's is 45 mm).
TRUTH_MESH_M = 0.035


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="+", help="'none' or library effect names")
    parser.add_argument("--seed", type=int, default=5, help="noise seed of the truths")
    args = parser.parse_args()
    library = {e.name: e for e in default_library()}
    scenario = dataclasses.replace(load_scenario("gap_quick_8h"), sample_interval_s=DENSE_S, time_step_s=DENSE_S)
    fine, twin = build_machine("vmc_ram", TRUTH_MESH_M), _machine("vmc_ram")
    for case in args.cases:
        active = [] if case == "none" else [(library[case].variant(**TRUTH_HIDDEN.get(case, {})),
                                            np.array(TRUTH_VALUES[case], float))]
        d = diagnose(truth_dataset(scenario, fine, active, seed=args.seed), twin, n_pairs=0, discovery=False)
        floors = d.scales.discretisation_sensor
        largest = sorted(floors, key=lambda n: floors[n] / d.scales.sensor[n], reverse=True)[:4]
        print(f"== {case} (true {TRUTH_VALUES.get(case, '-')}): {d.decision.outcome}, named "
              f"{d.winner.name if d.winner is not None else None}; within the floor only: "
              f"{mesh_limited(d.nominal, d.scales)}; largest floors against σ_j "
              f"{[(n, round(floors[n], 3), round(d.scales.sensor[n], 3)) for n in largest]}; "
              f"floor {d.timings.get('discretisation_s', 0):.1f} s")
        print("   " + sentence(d)[:400])


if __name__ == "__main__":
    main()
