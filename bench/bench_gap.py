"""Wall time of one gap diagnosis of a 24 h record against the whole effect library (prints; not a test).

Run from the repository root:

    python bench/bench_gap.py                   # truth on the 35 mm mesh if cached/shipped, else the nominal one
    python bench/bench_gap.py --effect belt_drive --truth-mesh-size 0
    python bench/bench_gap.py --repeat 2        # a second diagnosis in the same process (engine cached)
    python bench/bench_gap.py --independent column_source --out runs/gap_independent
                                                # cases of the independent benchmark (comma list or
                                                # library/outside/pairs/controls/checks/all), report printed
    python bench/bench_gap.py --merge runs/gap_independent/*/
                                                # the goal table of cases run apart (each folder written
                                                # by `twin gap benchmark --independent CASE --out DIR`)

The record is ``gap_blind_24h`` (24 h, 1 min sampling, 1441 rows, 36 sensor
channels) with one effect of the library switched on in the truth (default
``speed_exponent``, a nonlinear one).  Reported: the truth run, then for each
diagnosis the engine build (structure of the 14 effects + parametric reduced
model; once per process), the nominal run, the fits (14 singles + 3 pairs), the
where/attribution part, the report with renders, and the total.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def merged_independent(folders):
    """The independent benchmark's report over result folders of cases run apart (wall time: the sum)."""
    import json

    from twin.gap.benchmark import format_independent, independent_metrics

    results, wall, settings = [], 0.0, None
    for folder in folders:
        document = json.loads((Path(folder) / "independent.json").read_text(encoding="utf-8"))
        results += document["results"]
        wall += document["wall_seconds"]
        settings = settings or dict(document["settings"], scheduler="cases run apart (wall time summed)")
    return format_independent(results, independent_metrics(results), wall, settings)


def main(argv=None):
    from twin.gap.benchmark import SCENARIO, TRUTH_HIDDEN, TRUTH_MESH_SIZE_M, TRUTH_VALUES, _machine
    from twin.gap.diagnose import diagnose
    from twin.gap.effects import default_library
    from twin.gap.report import write_report
    from twin.gap.truth import truth_dataset

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--effect", default="speed_exponent", choices=sorted(TRUTH_VALUES))
    p.add_argument("--truth-mesh-size", type=float, default=TRUTH_MESH_SIZE_M)
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--no-render", action="store_true")
    p.add_argument("--independent", metavar="CASES", help="run cases of the independent benchmark instead")
    p.add_argument("--out", help="with --independent: output folder (independent.md, independent.json)")
    p.add_argument("--merge", nargs="+", metavar="DIR", help="print the independent goal table of result folders")
    args = p.parse_args(argv)
    if args.merge:
        print(merged_independent(args.merge))
        return
    if args.independent:
        from twin.gap.benchmark import independent_benchmark

        result = independent_benchmark(args.independent, out_dir=args.out)
        print(result.markdown)
        return

    t0 = time.perf_counter()
    truth_machine = _machine("vmc_ram", args.truth_mesh_size or None)
    nominal = _machine("vmc_ram", None)
    effect = {e.name: e for e in default_library()}[args.effect].variant(**TRUTH_HIDDEN.get(args.effect, {}))
    data = truth_dataset(SCENARIO, truth_machine, [(effect, np.array(TRUTH_VALUES[args.effect]))])
    print(f"truth: {args.effect} on {truth_machine.thermal.n_nodes} thermal nodes, {len(data)} rows: "
          f"{time.perf_counter() - t0:.1f} s (machines loaded from caches)")
    for k in range(args.repeat):
        t1 = time.perf_counter()
        d = diagnose(data, nominal)
        t2 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            write_report(d, Path(tmp) / "report", render=not args.no_render)
        t3 = time.perf_counter()
        t = d.timings
        print(f"diagnosis {k + 1}: engine {t['engine_s']:.1f} s, nominal {t['nominal_s']:.2f} s, "
              f"fits {t['fits_s']:.1f} s ({len(d.singles)} effects + {len(d.pairs)} pairs), "
              f"where/attribution {t['where_s']:.1f} s, report {t3 - t2:.1f} s; total {t3 - t1:.1f} s")
        print(f"  {d.verdict}")
    print(f"reduced model: {d.model.backend.order} states")


if __name__ == "__main__":
    main()
