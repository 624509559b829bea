"""Benchmark: the thesis 160 h ETVE (1 min output, 1 min steps) on the default machine.

    python bench/bench_etve.py [scenario] [--fields]

Reports the wall time of the simulation (machine from cache; the one-off
mesh and output-operator build is reported separately), the wall time of the
whole `twin run` (simulation, dataset, plots), and peak memory.  Without
``--fields`` no temperature field is stored: memory stays bounded by the
outputs (samples × channels).
"""
import resource
import sys
import tempfile
import time
from pathlib import Path


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    scenario = args[0] if args else "etve_160h"
    fields = "--fields" in sys.argv
    start = time.perf_counter()
    from twin.core.machine import build_machine
    from twin.core.scenario import load_scenario
    from twin.core.simulate import simulate
    from twin.run.workflows import run_scenario

    imports = time.perf_counter() - start
    sc = load_scenario(scenario)
    start = time.perf_counter()
    machine = build_machine(sc.machine)
    build = time.perf_counter() - start
    rss_before = peak_rss_mb()
    start = time.perf_counter()
    result = simulate(sc, machine, fields=fields)
    sim = time.perf_counter() - start
    rss_sim = peak_rss_mb()
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run_scenario(scenario, out_dir=Path(tmp) / "run", fields=fields)
        whole = time.perf_counter() - start
    ds = result.dataset
    steps = int(round(sc.duration_s / sc.time_step_s))
    print(f"scenario {sc.name}: {sc.duration_s / 3600:g} h, {len(ds)} samples, {steps} steps of "
          f"{sc.time_step_s:g} s, {machine.thermal.n_nodes} thermal nodes, {len(ds.channels)} channels")
    print(f"imports                      {imports:7.2f} s")
    print(f"machine from cache           {build:7.2f} s")
    print(f"simulation                   {sim:7.2f} s  ({sim / steps * 1e3:.2f} ms per step, "
          f"{sc.duration_s / sim:,.0f} simulated s per wall s)")
    print(f"whole `twin run` (+ files)   {whole:7.2f} s")
    print(f"peak RSS: {rss_before:.0f} MB after the build, {rss_sim:.0f} MB after the simulation "
          f"(fields stored: {len(result.fields)})")
    print(f"goal: under 120 s for the simulation -> {'met' if sim < 120 else 'NOT met'}")


if __name__ == "__main__":
    main()
