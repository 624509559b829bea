"""Co-simulation example: thermal-drift compensation driven by the twin's FMU, step by step in fmpy.

Two instances of the same FMU run side by side in a ``doStep`` loop:

- the *machine* (plant): driven by the true operating conditions of a
  scenario; its TCP drift is the error a workpiece would see;
- the *compensator's model*: driven by what the controller knows — the
  spindle speed and feeds from the NC, and the ambient from an air
  thermometer with a first-order lag (``--sensor-lag``).  Its predicted
  drift is sent to the axis drives as an offset, updated every
  ``--update`` seconds and applied after a transport delay (``--delay``).

The commanded position is the nominal one minus the applied prediction, so
the residual TCP error is ``drift_true − correction_applied``.  The plot shows
the X, Y and Z drift with and without compensation (µm over hours).

    python examples/cosim_compensation.py                  # heat_cool_9000 with a door event, native FMU
    python examples/cosim_compensation.py --kind python --scenario etve_160h
    python examples/cosim_compensation.py --fast           # 2 h, coarse step (used by the tests)
"""
from __future__ import annotations

import argparse
import collections
import time
from pathlib import Path

import numpy as np


def build_fmu(kind, out_dir, machine_name="vmc_ram", order=None):
    from twin.core.machine import build_machine
    from twin.fmu.export import export_fmu
    from twin.rom.reduction import DEFAULT_ORDER, cached_rom

    rom = cached_rom(build_machine(machine_name), order or DEFAULT_ORDER)
    return rom, export_fmu(rom, Path(out_dir) / f"twin_{kind}.fmu", kind=kind,
                           outputs=[n for n in rom.output_names if n in ("X", "Y", "Z", "T18", "T01")])


def measured_zones(path):
    """The zones whose air the FMU takes as an input (``ambient_<zone>``), from its model description."""
    from fmpy import read_model_description

    names = [v.name for v in read_model_description(str(path)).modelVariables if v.causality == "input"]
    return [n[len("ambient_"):] for n in names if n.startswith("ambient_") and n != "ambient_gradient"]


def run(scenario_name="heat_cool_9000", kind="native", out_dir="runs/cosim", step_s=30.0, delay_s=60.0,
        update_s=60.0, sensor_lag_s=300.0, duration_h=None, fmu=None, door_drop_K=6.0):
    """Run the compensation loop; return a dict of time series (µm, h) and the PNG path."""
    from twin.core.machine_definition import room_zone
    from twin.core.scenario import DoorOpening, load_scenario
    from twin.fmu.session import FMUSession
    from twin.rom.reduction import scenario_conditions

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rom, path = build_fmu(kind, out_dir) if fmu is None else (None, Path(fmu))
    scenario = load_scenario(scenario_name)
    if door_drop_K:
        # A door opening 30 min into the run makes the ambient, and so the sensor lag, matter.
        scenario.events = list(scenario.events) + [DoorOpening(1800.0, 900.0, door_drop_K, 2400.0, None)]
    duration = scenario.duration_s if duration_h is None else min(scenario.duration_s, duration_h * 3600.0)
    times = np.arange(0.0, duration + 0.5 * step_s, step_s)
    zones = measured_zones(path)          # the FMU lags the other zones' air (e.g. the enclosure) itself
    cond = scenario_conditions(scenario, zones, np.r_[times[1:], times[-1]])   # held over each step

    def inputs(k, ambient):
        return dict(spindle_speed=float(cond.spindle_rpm[k]), feed_x=float(cond.feed_mm_min["x"][k]),
                    feed_y=float(cond.feed_mm_min["y"][k]), feed_z=float(cond.feed_mm_min["z"][k]),
                    ambient_gradient=float(cond.gradient_K_per_m[k]),
                    **{f"ambient_{z}": float(ambient[z]) for z in zones})

    true_amb = {z: cond.ambient_C[z][0] for z in zones}
    sensed = dict(true_amb)
    T0 = float(scenario.initial.get("temperature_C") or true_amb[room_zone(zones)])
    steady = scenario.initial["kind"] == "steady"
    plant = FMUSession(path, T_initial=T0, steady_start=steady, inputs=inputs(0, true_amb))
    model = FMUSession(path, T_initial=T0, steady_start=steady, inputs=inputs(0, sensed))
    axes = ("X", "Y", "Z")
    delay_steps = int(round(delay_s / step_s))
    pipeline = collections.deque([np.zeros(3)] * max(delay_steps, 0), maxlen=max(delay_steps, 0) or None)
    applied = np.zeros(3)
    latest = np.zeros(3)
    true_drift = np.zeros((len(times), 3))
    residual = np.zeros((len(times), 3))
    true_drift[0] = plant.get(*axes)
    residual[0] = true_drift[0]
    wall = time.perf_counter()
    alpha = 1.0 - np.exp(-step_s / sensor_lag_s) if sensor_lag_s > 0 else 1.0
    try:
        for k in range(len(times) - 1):
            true_amb = {z: cond.ambient_C[z][k] for z in zones}
            sensed = {z: sensed[z] + alpha * (true_amb[z] - sensed[z]) for z in zones}
            plant.set(**inputs(k, true_amb))
            model.set(**inputs(k, sensed))
            plant.step(step_s)
            model.step(step_s)
            if (k + 1) % max(1, int(round(update_s / step_s))) == 0:
                latest = np.array(model.get(*axes))           # a new prediction leaves the controller
            if delay_steps:
                applied = pipeline[0]                         # sent `delay` ago, reaching the drives now
                pipeline.append(latest)
            else:
                applied = latest
            true_drift[k + 1] = plant.get(*axes)
            residual[k + 1] = true_drift[k + 1] - applied
    finally:
        plant.close()
        model.close()
    wall = time.perf_counter() - wall
    png = plot(times / 3600.0, true_drift, residual, out_dir / f"cosim_compensation_{scenario.name}.png",
               f"{scenario.name} ({kind} FMU; delay {delay_s:g} s, update {update_s:g} s, "
               f"sensor lag {sensor_lag_s:g} s)")
    return dict(time_h=times / 3600.0, drift_um=true_drift, residual_um=residual, png=png, wall_s=wall,
                fmu=path)


def plot(t_h, drift, residual, path, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, ("X", "Y", "Z"))):
        ax.plot(t_h, drift[:, i], label="without compensation", color="tab:red")
        ax.plot(t_h, residual[:, i], label="with compensation (residual)", color="tab:blue")
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_ylabel(f"TCP drift {name} (µm)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best")
    axes[0].set_title(title, fontsize=10)
    axes[-1].set_xlabel("time (h)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="heat_cool_9000")
    p.add_argument("--kind", choices=("native", "python"), default="native")
    p.add_argument("--fmu", help="use this FMU instead of exporting one")
    p.add_argument("--out", default="runs/cosim", help="output folder for the FMU and the PNG")
    p.add_argument("--step", type=float, default=30.0, help="communication step, s")
    p.add_argument("--delay", type=float, default=60.0, help="transport delay of the correction, s")
    p.add_argument("--update", type=float, default=60.0, help="correction update period, s")
    p.add_argument("--sensor-lag", type=float, default=300.0, help="air thermometer time constant, s")
    p.add_argument("--fast", action="store_true", help="first 2 h only, 60 s steps")
    args = p.parse_args(argv)
    step = 60.0 if args.fast else args.step
    res = run(args.scenario, args.kind, args.out, step, args.delay, args.update, args.sensor_lag,
              duration_h=2.0 if args.fast else None, fmu=args.fmu)
    d, r = res["drift_um"], res["residual_um"]
    for i, name in enumerate("XYZ"):
        print(f"{name}: max |drift| {np.abs(d[:, i]).max():7.2f} µm without, {np.abs(r[:, i]).max():6.2f} µm "
              f"with compensation (RMS {np.sqrt(np.mean(d[:, i] ** 2)):.2f} → {np.sqrt(np.mean(r[:, i] ** 2)):.2f})")
    print(f"{len(res['time_h']) - 1} steps of two FMU instances in {res['wall_s']:.2f} s; plot: {res['png']}")
    return res


if __name__ == "__main__":
    main()
