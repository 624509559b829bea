"""Benchmark of the reduced-order model and its FMUs on the 160 h ETVE (scenarios/etve_160h.toml).

Prints: the ROM build time (no cache), and simulated seconds per wall second
for the full FE twin, the ROM in process (ZOH), the Python FMU and the native
FMU (both through ``fmpy.simulate_fmu`` with the scenario's input table, and
the native one also in a bare ``doStep`` loop), plus the ROM's error against
the FE on the run.

    python bench/bench_rom_fmu.py                  # default order
    python bench/bench_rom_fmu.py --order 80 --skip-fe
    python bench/bench_rom_fmu.py --lag-check --step 5 --fe-theta 0.5          # room-driven FMU vs the twin

``--lag-check`` runs only the plant-input check: the native FMU driven by what a
plant measures (room and front air, speed, feeds; the enclosure's lagged air is a
state of the FMU) against the full FE twin (whose enclosure air is the scenario's
lagged room).  ``--step`` is the FMU's communication step (default: the
scenario's; the master's sampling of the inputs, held over each step, shrinks
with it), ``--fe-step`` and ``--fe-theta`` the FE's time step and θ (default:
the scenario's; θ = 0.5 makes the FE's own time error second order).  The model's
own difference is the column "FMU vs ROM with the lag outside".
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv=None):
    from twin.core.machine import build_machine
    from twin.core.scenario import load_scenario
    from twin.core.simulate import simulate as simulate_fe
    from twin.fmu.export import export_fmu, input_table, scenario_start, simulate
    from twin.fmu.session import FMUSession
    from twin.rom.reduction import DEFAULT_ORDER, build_rom, held_conditions, initial_state, simulate_rom
    from twin.rom.report import max_errors

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="etve_160h")
    p.add_argument("--order", type=int, default=DEFAULT_ORDER)
    p.add_argument("--skip-fe", action="store_true", help="do not run the full FE model (takes ~1 min)")
    p.add_argument("--lag-check", action="store_true", help="only compare the room-driven FMU with the full twin")
    p.add_argument("--step", type=float, default=None,
                   help="--lag-check: FMU communication step, s (default the scenario's)")
    p.add_argument("--fe-step", type=float, default=None, help="--lag-check: FE time step, s (default the scenario's)")
    p.add_argument("--fe-theta", type=float, default=None, help="--lag-check: FE θ (default the scenario's)")
    args = p.parse_args(argv)
    try:                                   # one BLAS thread: stable timings on a shared 2-core machine
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass

    if args.lag_check:
        return lag_check(args.order, args.step, args.fe_step, args.fe_theta,
                         [args.scenario] if "--scenario" in (argv or sys.argv) else ["etve_160h", "door_opening"])
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
    t = table["time"][2:]
    cond = held_conditions(scenario, rom.zones, t, rom.zone_lags_s)
    U = rom.inputs_from_conditions(cond.spindle_rpm, cond.feed_mm_min, cond.ambient_C, cond.gradient_K_per_m)
    z0 = initial_state(rom, scenario)
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


def lag_check(order, step_s=None, fe_step_s=None, fe_theta=None, scenarios=("etve_160h", "door_opening")):
    """Largest |FMU − full twin| (K, µm) of the room-driven native FMU, plus its parts, per scenario."""
    from twin.core.machine import build_machine
    from twin.core.scenario import load_scenario
    from twin.core.simulate import simulate as simulate_fe
    from twin.fmu.export import export_fmu, input_table, scenario_start, simulate
    from twin.infra.tables import markdown_table
    from twin.rom.reduction import cached_rom, simulate_rom

    machine = build_machine(load_scenario(scenarios[0]).machine)
    rom = cached_rom(machine, order)
    print(f"machine {machine.name}: lagged zones {rom.lagged_zones} "
          f"({', '.join(f'{rom.zone_lags_s[z] / 3600:g} h' for z in rom.lagged_zones)}); "
          f"FMU inputs: room-measured zones {rom.measured_zones}")
    kinds = {"T (K)": "degC", "TCP (µm)": "um"}

    def worst(result, reference):
        return {k: max(float(np.abs(result[:, j] - reference[:, j]).max())
                       for j in range(rom.n_outputs) if rom.output_units[j] == unit)
                for k, unit in kinds.items()}

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        fmu = export_fmu(rom, Path(tmp) / "native.fmu", kind="native")
        for name in scenarios:
            scenario = load_scenario(name)
            fe_scenario = dataclasses.replace(scenario, time_step_s=fe_step_s or scenario.time_step_s,
                                              theta=scenario.theta if fe_theta is None else fe_theta)
            step = step_s or scenario.time_step_s
            every = round(scenario.sample_interval_s / step)
            fine = np.arange(len(scenario.times()) * every - every + 1) * step
            start = time.perf_counter()
            fe = simulate_fe(fe_scenario, machine, noise=False).dataset.matrix(rom.output_names)
            fe_seconds = time.perf_counter() - start
            T0, steady = scenario_start(rom, scenario)
            run = simulate(fmu, input_table(rom, scenario, fine), T_initial=T0, steady_start=steady)
            result = np.column_stack([run[n] for n in rom.output_names])[::every]
            outside = simulate_rom(rom, scenario, inputs="held", sample_times=fine).matrix(rom.output_names)[::every]
            naive = dataclasses.replace(rom, zone_lags_s={})    # room air fed to every zone, no lag
            room_everywhere = simulate_rom(naive, scenario, inputs="held", sample_times=fine).matrix(
                rom.output_names)[::every]
            setting = f"{step:g} s / {fe_scenario.time_step_s:g} s, θ = {fe_scenario.theta:g} ({fe_seconds:.0f} s wall)"
            rows.append((name, setting, worst(result, fe),
                         worst(result, outside), worst(room_everywhere, fe)))
    print()
    print(markdown_table([[name, step] + [" / ".join(f"{d[k]:.2e}" for k in kinds) for d in diffs]
                          for name, step, *diffs in rows],
                         ["scenario", "FMU step / FE step, θ", "FMU vs full twin T (K) / TCP (µm)",
                          "FMU vs ROM with the lag outside", "room air fed to every zone vs full twin"],
                         align=["left", "left", "right", "right", "right"]))


if __name__ == "__main__":
    main()
