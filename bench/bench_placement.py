"""Wall time of the sensor-placement study on the default machine (≥ 5 scenarios, ≥ 2,000 candidates).

    python bench/bench_placement.py                 # default study, records from the cache if present
    python bench/bench_placement.py --no-cache      # simulate every scenario again
    python bench/bench_placement.py --scheduler serial

Prints the wall time of each phase (simulations through the Dask sweep: the scenarios and the
step responses of ``greedy-physics``; selection by every method for K = 1…8 and both axes;
scoring) and the total, and the load averages before and after.
"""
from __future__ import annotations

import argparse
import json
import os
import time


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-cache", action="store_true", help="simulate again even if records are cached")
    parser.add_argument("--scheduler", default="local", help="local (default), serial or tcp://HOST:8786")
    parser.add_argument("--candidates", type=int, default=2000)
    parser.add_argument("--out", default="runs/bench_placement")
    parser.add_argument("--json", help="write the timings as JSON here")
    args = parser.parse_args(argv)

    from twin.placement.study import placement_study

    load_before = os.getloadavg()
    start = time.perf_counter()
    res = placement_study(n_candidates=args.candidates, scheduler=args.scheduler, use_cache=not args.no_cache,
                          out_dir=args.out, log=None)
    wall = time.perf_counter() - start
    t = res.timings
    cfg = res.config
    n_scenarios = len(cfg["train"]) + len(cfg["validation"]) + len(cfg["test"])
    print(f"placement study: {n_scenarios} scenarios + {t.get('responses', 0)} step "
          f"responses, {cfg['n_candidates']} candidates, "
          f"{len(cfg['methods'])} methods × K = 1…{cfg['k_max']} × {len(cfg['axes'])} axes, scheduler {args.scheduler}")
    print(f"  simulations  {t['simulation_s']:7.1f} s  ({t['simulated']} run, {t['from_cache']} from cache; "
          f"{t['simulation_cpu_s']:.1f} s summed over the runs)")
    print(f"  selection    {t['selection_s']:7.1f} s")
    print(f"  scoring      {t['scoring_s']:7.1f} s  (+ ANFIS check {t.get('anfis_s', 0.0):.1f} s)")
    print(f"  total        {wall:7.1f} s  (report written to {args.out}/)")
    load_after = os.getloadavg()
    print(f"  load average (1, 5, 15 min) before {', '.join(f'{v:.2f}' for v in load_before)}; after "
          f"{', '.join(f'{v:.2f}' for v in load_after)} on {os.cpu_count()} cores")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"wall_s": wall, **t, "load_before": load_before, "load_after": load_after, "config": cfg}, fh,
                      indent=1, default=str)


if __name__ == "__main__":
    main()
