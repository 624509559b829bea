"""Benchmark of ``twin live``: the drift observer's accuracy and 95 % band against the full FE, its speed, OPC UA.

Prints:

1. The band's coverage (docs/live.md, "Calibration protocol"): per truth record of the *held-out*, the
   *seen (earlier held-out)* and the *seen* sets of :mod:`twin.live.protocol` — full-FE records with effects
   outside the nominal twin — the share
   of samples whose true Z lies inside the observer's 95 % band over the thermometer noise draws of the set,
   the mean band half-width and the Z error; pooled per set.
2. The issue's goals on ``heat_cool_9000`` (nominal and with the enclosure convection × 0.6) and ``etve_160h``
   (× 0.6): Z RMS / max error (µm) of the observer (ROM r = 80, the 6 default thermometers of ``twin live``,
   spindle speed, the room air T15 — all read through the DS18S20 model, seed 7), of the open-loop ROM (the
   scenario's inputs, no thermometers) and of MLR on the same thermometers + room air (trained on nominal noisy
   ROM records of the placement study's training scenarios, zero-referenced); the observer's real-time factor.
3. End-to-end samples/s through OPC UA on loopback: a replay server and the live client in one process
   (``twin live --replay``) on a ROM record of heat_cool_9000 (1141 samples), at a speed above what the client
   can follow.

    python bench/bench_live.py                 # everything (FE truths are cached after the first run)
    python bench/bench_live.py --skip-etve     # without etve_160h (its FE run takes minutes)
    python bench/bench_live.py --opcua-only    # the OPC UA throughput only
    python bench/bench_live.py --calibrate     # the training grid of the noise model and the setting it picks

``--calibrate`` runs the observer with each setting of :data:`GRID` on the *training* records only (never the
held-out or seen ones) and applies :func:`choose_setting`.
"""
from __future__ import annotations

import argparse
import asyncio
import dataclasses
import time

import numpy as np

from twin.live import protocol
from twin.live.cli import DEFAULT_THERMOMETERS

ROOM_AIR = protocol.ROOM_AIR
GOAL_CASES = protocol.SEEN
GOAL_SEED = 7
MLR_TRAIN = ("iso230_3_spindle_spectrum", "thesis_test_4", "six_part_cycle", "cutting_soft", "etve_5K")
#: Settings the calibration compares: the considered misplaced heat κ (fraction of the heat the model moves),
#: the NIS-driven widening (window s; 0 = off) and the considered concentrated source σ_P (W).  Everything else
#: of the noise model is set from the physics.  (κ = 0.1 of the first grid is left out: it was the widest and
#: never the choice on training; σ_P = 10 W already widens the Z band of heat_cool_9000 from 2.9 to 4.8 µm on a
#: ROM record, so 5 W is in.)
GRID = tuple((discrepancy, window, concentrated) for discrepancy in (0.0, 0.025, 0.05) for window in (0.0, 3600.0)
             for concentrated in (0.0, 5.0, 10.0, 20.0, 40.0))
#: The rule: the narrowest mean band among the settings whose pooled training coverage is ≥ 95 % and whose
#: worst training record is ≥ 80 %; if none qualifies, the one with the best worst record.
POOLED_MIN, RECORD_MIN = 0.95, 0.80


def observer_factory(rom, names, setting=None):
    """A function making a fresh observer: the shipped settings, or ``setting`` = (κ, window s, σ_P W)."""
    from twin.live.observer import ADAPTATION, NOISE, DriftObserver

    if setting is None:
        return lambda: DriftObserver(rom, names)
    noise = dataclasses.replace(NOISE, discrepancy=setting[0], concentrated_W=setting[2])
    adaptation = dataclasses.replace(ADAPTATION, window_s=setting[1])
    return lambda: DriftObserver(rom, names, noise, adaptation)


def rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def pooled(scores):
    """(coverage over every sample, the worst record's coverage, mean band µm) of :class:`~twin.live.protocol.RecordScore` s."""
    cover = np.array([s.coverage for s in scores])
    samples = np.array([s.samples for s in scores], float)
    return float(cover @ samples / samples.sum()), float(cover.min()), float(np.mean([s.band_um for s in scores]))


def choose_setting(results):
    """The setting :data:`GRID`'s rule picks from ``{setting: [RecordScore, …]}`` (training records only)."""
    summary = {k: pooled(v) for k, v in results.items()}
    fine = [k for k, (cover, worst, _) in summary.items() if cover >= POOLED_MIN and worst >= RECORD_MIN]
    if fine:
        return min(fine, key=lambda k: summary[k][2])
    return max(summary, key=lambda k: summary[k][1])


def calibrate(rom, names):
    """Score every :data:`GRID` setting on the training records; print the table and the choice."""
    cases, seeds = protocol.SETS["training"]
    print(f"training: {len(cases)} records × seeds {', '.join(map(str, seeds))}\n")
    print("| misplaced heat κ | NIS window (s) | concentrated σ_P (W) | pooled coverage | worst record | "
          "mean band (µm) | Z RMS (µm) |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    results = {}
    for setting in GRID:
        make = observer_factory(rom, names, setting)
        results[setting] = [protocol.score(c, make, names, seeds) for c in cases]
        cover, worst, band = pooled(results[setting])
        e = rms([s.rms_um for s in results[setting]])
        print(f"| {setting[0]:g} | {setting[1]:g} | {setting[2]:g} | {100 * cover:.1f} % | {100 * worst:.1f} % | "
              f"{band:.2f} | {e:.2f} |", flush=True)
    best = choose_setting(results)
    print(f"\nchosen: misplaced heat {best[0]:g}, NIS window {best[1]:g} s, concentrated source {best[2]:g} W; "
          "per training record:\n")
    coverage_table(results[best])
    return best


def coverage_table(scores):
    """Print the per-record coverage table and the pooled row."""
    print("| record | effect kind | true Z RMS (µm) | observer Z RMS / max (µm) | in 95 % band | mean band (µm) |")
    print("|---|---|---:|---:|---:|---:|")
    for s in scores:
        print(f"| {s.case.label} | {s.case.kind} | {s.truth_rms_um:.1f} | {s.rms_um:.2f} / {s.max_um:.2f} | "
              f"{100 * s.coverage:.1f} % | {s.band_um:.2f} |")
    cover, worst, band = pooled(scores)
    print(f"| **pooled** | | | | **{100 * cover:.1f} %** (worst {100 * worst:.1f} %) | {band:.2f} |\n", flush=True)


def train_mlr(rom, names):
    """MLR Z ~ thermometers + room air, zero-referenced per record, on nominal ROM records (DS18S20 noise)."""
    from models.regression import MLRRegressor
    from twin.rom.reduction import simulate_rom

    X, y = [], []
    for k, scenario in enumerate(MLR_TRAIN):
        ds = simulate_rom(rom, scenario)
        T, air = protocol.readings(ds, names, 100 + k)
        inputs = np.column_stack([T, air])
        X.append(inputs - inputs[0])
        y.append(ds["Z"] - ds["Z"][0])
    return MLRRegressor().fit(np.vstack(X), np.concatenate(y))


def goal_table(rom, names, cases):
    """The issue's goal table: observer vs open-loop ROM vs MLR on the same sensors, and the real-time factor."""
    from twin.live.observer import DriftObserver
    from twin.rom.reduction import simulate_rom

    mlr = train_mlr(rom, names)
    print(f"observer: ROM r = {rom.order}, thermometers {', '.join(names)} + spindle speed + room air {ROOM_AIR} "
          f"(DS18S20, seed {GOAL_SEED})")
    print(f"MLR: same thermometers + {ROOM_AIR}, trained on nominal ROM records of {', '.join(MLR_TRAIN)}\n")
    print("| scenario | truth (full FE) | Z RMS (µm) | observer RMS / max (µm) | open-loop ROM RMS / max | "
          "MLR RMS / max | observer real-time factor |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for case in cases:
        truth = protocol.truth(case)
        z = truth["Z"]
        T, air = protocol.readings(truth, names, GOAL_SEED)
        observer = DriftObserver(rom, names)
        start = time.perf_counter()
        drift, _ = observer.run(truth.time_s, truth["spindle"], air, T)
        wall = time.perf_counter() - start
        e_obs = drift[:, 2] - z
        e_ol = simulate_rom(rom, case.scenario, sample_times=truth.time_s)["Z"] - z
        inputs = np.column_stack([T, air])
        e_mlr = mlr.predict(inputs - inputs[0]) - z
        rtf = (truth.time_s[-1] - truth.time_s[0]) / wall
        print(f"| {case.scenario} | {case.effect} | {rms(z):.2f} | {rms(e_obs):.2f} / {np.abs(e_obs).max():.2f} | "
              f"{rms(e_ol):.2f} / {np.abs(e_ol).max():.2f} | {rms(e_mlr):.2f} / {np.abs(e_mlr).max():.2f} | "
              f"{rtf:,.0f} |", flush=True)
    print()


def opcua_throughput(rom, names, speed):
    """Replay a ROM record through a loopback OPC UA server into the live client; print the samples/s."""
    from twin.live.cli import replay_session
    from twin.live.observer import DriftObserver
    from twin.rom.reduction import simulate_rom

    dataset = simulate_rom(rom, "heat_cool_9000")          # the content does not matter for the throughput
    stats, wall = asyncio.run(replay_session(dataset, names, DriftObserver(rom, names), speed, ROOM_AIR))
    t = np.array([h[0] for h in stats.history])
    print(f"OPC UA on loopback (replay of heat_cool_9000, {len(dataset)} samples at {speed:g}×): "
          f"server published in {wall:.2f} s; client fused {stats.samples} samples in {stats.wall_s:.2f} s "
          f"(connect included) = {stats.samples / stats.wall_s:.0f} samples/s; late {stats.late}, "
          f"reconnects {stats.reconnects}; times in order: {bool(np.all(np.diff(t) > 0))}")


def main(argv=None):
    from twin.core.machine import build_machine
    from twin.rom.reduction import cached_rom

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-etve", action="store_true", help="leave out etve_160h (its FE run takes minutes)")
    parser.add_argument("--speed", type=float, default=20000.0, help="replay speed for the OPC UA throughput")
    parser.add_argument("--opcua-only", action="store_true", help="only the OPC UA throughput (no FE run)")
    parser.add_argument("--calibrate", action="store_true", help="only the training grid and the chosen setting")
    args = parser.parse_args(argv)

    names = list(DEFAULT_THERMOMETERS)
    rom = cached_rom(build_machine("vmc_ram"), 80)
    if args.calibrate:
        calibrate(rom, names)
        return
    if not args.opcua_only:
        for name in ("held-out", "seen (earlier held-out)", "seen"):
            cases, seeds = protocol.SETS[name]
            cases = [c for c in cases if not (args.skip_etve and c.scenario == "etve_160h")]
            print(f"{name} records, seeds {seeds[0]}–{seeds[-1]}:\n")
            coverage_table([protocol.score(c, observer_factory(rom, names), names, seeds) for c in cases])
        goal_table(rom, names, [c for c in GOAL_CASES if not (args.skip_etve and c.scenario == "etve_160h")])
    opcua_throughput(rom, names, args.speed)


if __name__ == "__main__":
    main()
