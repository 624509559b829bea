"""Benchmark of the reduced-order model and its FMUs on the 160 h ETVE (scenarios/etve_160h.toml).

Prints: the ROM build time (no cache), and simulated seconds per wall second
for the full FE twin, the ROM in process (ZOH), the Python FMU and the native
FMU (both through ``fmpy.simulate_fmu`` with the scenario's input table, and
the native one also in a bare ``doStep`` loop), plus the ROM's error against
the FE on the run.

    python bench/bench_rom_fmu.py                  # default order
    python bench/bench_rom_fmu.py --order 80 --skip-fe
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    from twin.core.machine import build_machine
    from twin.core.scenario import load_scenario
    from twin.core.simulate import simulate as simulate_fe
    from twin.fmu.export import export_fmu, input_table, scenario_start, simulate, table_inputs
    from twin.fmu.session import FMUSession
    from twin.rom.reduction import DEFAULT_ORDER, build_rom, simulate_rom
    from twin.rom.report import max_errors

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="etve_160h")
    p.add_argument("--order", type=int, default=DEFAULT_ORDER)
    p.add_argument("--skip-fe", action="store_true", help="do not run the full FE model (takes ~1 min)")
    args = p.parse_args(argv)
    try:                                   # one BLAS thread: stable timings on a shared 2-core machine
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass

    machine = build_machine(load_scenario(args.scenario).machine)
    scenario = load_scenario(args.scenario)
    span = scenario.duration_s
    print(f"machine {machine.name}: {machine.thermal.n_nodes} thermal unknowns, {machine.thermal.n_inputs} inputs; "
          f"scenario {scenario.name}: {span / 3600:g} h, step {scenario.time_step_s:g} s")

    start = time.perf_counter()
    rom = build_rom(machine, args.order)
    build = time.perf_counter() - start
    print(f"ROM build (Krylov, order {rom.order}, no cache): {build:.2f} s "
          f"(basis {rom.info['basis_seconds']:.2f} s)")

    rows = []
    fe_ds = None
    if not args.skip_fe:
        start = time.perf_counter()
        fe_ds = simulate_fe(scenario, machine, noise=False).dataset
        rows.append(("full FE (θ-method)", time.perf_counter() - start))

    simulate_rom(rom, scenario)                                   # warm-up
    best = np.inf
    for _ in range(20):
        start = time.perf_counter()
        ds = simulate_rom(rom, scenario)
        best = min(best, time.perf_counter() - start)
    rows.append(("ROM in process (ZOH, scenario → dataset)", best))
    table = input_table(rom, scenario)
    U = table_inputs(rom, table)[2:]
    z0 = rom.steady_state(table_inputs(rom, table)[1])
    t = table["time"][2:]
    best = np.inf
    for _ in range(20):
        start = time.perf_counter()
        rom.simulate(t, U, z0, "zoh")
        best = min(best, time.perf_counter() - start)
    rows.append((f"ROM integration alone (ZOH, inputs given, {rom.n_outputs} outputs)", best))

    T0, steady = scenario_start(rom, scenario)
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("python", "native"):
            path = export_fmu(rom, Path(tmp) / f"{kind}.fmu", kind=kind)
            start = time.perf_counter()
            simulate(path, table, T_initial=T0, steady_start=steady)
            rows.append((f"{kind} FMU (fmpy.simulate_fmu, {rom.n_outputs} outputs)", time.perf_counter() - start))
        path = Path(tmp) / "native.fmu"
        h = float(table["time"][3] - table["time"][2])
        names = [n for n in table.dtype.names if n != "time"]
        first = {n: float(table[n][1]) for n in names}
        with FMUSession(path, T_initial=T0, steady_start=steady, inputs=first) as s:
            start = time.perf_counter()
            for k in range(2, len(table) - 1):
                s.set(**{n: float(table[n][k]) for n in names})
                s.step(h)
                s.get("X", "Y", "Z")
            rows.append(("native FMU (bare doStep loop, set inputs, get X/Y/Z)", time.perf_counter() - start))

    fe_seconds = rows[0][1] if fe_ds is not None else None
    print()
    print("| model | wall s | simulated s per wall s | speed-up vs FE |")
    print("|---|---:|---:|---:|")
    for name, seconds in rows:
        speed = f"{fe_seconds / seconds:,.0f}×" if fe_seconds else "–"
        print(f"| {name} | {seconds:.3f} | {span / seconds:,.3g} | {speed} |")
    if fe_ds is not None:
        e = max_errors(ds, fe_ds)
        print(f"\nROM (ZOH) vs FE on {scenario.name}: T {e.get('temperature', 0):.2e} K, "
              f"TCP {e.get('displacement', 0):.2e} µm (includes the FE's backward-Euler step error)")
        e = max_errors(simulate_rom(rom, scenario, scheme="theta"), fe_ds)
        print(f"ROM (θ-scheme, like for like) vs FE: T {e.get('temperature', 0):.2e} K, "
              f"TCP {e.get('displacement', 0):.2e} µm")


if __name__ == "__main__":
    main()
