"""The placement study's report: validation K × method tables, test verdicts on the goals, files, render, plots."""
from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from models.selection import SEED_METHODS

from ..core.dataset import ChannelInfo, Dataset, json_default, project_version
from ..core.machine import Machine
from ..core.simulate import ScenarioInputs, machine_condition_channels
from ..core.variants import as_scenario
from ..infra.tables import markdown_table
from .candidates import Candidates
from .records import Record
from .scoring import best_k_pool
from .selection import OWN_METHODS

if TYPE_CHECKING:
    from ..core.scenario import Scenario
    from .study import PlacementResult


def _cell(rows, method, k, axis):
    for r in rows:
        if r["method"] == method and r["K"] == k and r["axis"] == axis:
            return r
    return None


def k_method_table(result: PlacementResult, axis: str) -> str:
    """Markdown K × method table of one axis: validation max |residual| / RMSE (µm), the best per K in bold.

    Parameters
    ----------
    result : PlacementResult
        The study's result (its ``config``, ``table`` and ``test`` are read).
    axis : str
        Drift axis.

    Returns
    -------
    str
        The table, ending with a newline.
    """
    methods = result.config["methods"]
    rows = []
    for k in range(1, result.config["k_max"] + 1):
        cells = [_cell(result.table, m, k, axis) for m in methods]
        best = min(r["max_residual"] for r in cells)
        texts = [f"{r['max_residual']:.2f} / {r['rmse']:.2f}" for r in cells]
        rows.append([k] + [f"**{t}**" if r["max_residual"] == best else t for r, t in zip(cells, texts)])
    return markdown_table(rows, ["K", *methods]) + "\n"


def _own_beats_seed_at_k(result, axis):
    """Per K: does an own method beat every seed method on the validation scores?"""
    cfg = result.config
    own = [m for m in cfg["methods"] if m in OWN_METHODS]
    seed = [m for m in cfg["methods"] if m in SEED_METHODS]
    return {k: min(_cell(result.table, m, k, axis)["max_residual"] for m in own)
            < min(_cell(result.table, m, k, axis)["max_residual"] for m in seed) for k in range(1, cfg["k_max"] + 1)}


def _validation_max(result, axis, row):
    return _cell(result.table, row["method"], row["K"], axis)["max_residual"]


def per_scenario_reductions(row: dict) -> dict:
    """Scenario → % of its own uncompensated max |drift change| that the set's max |residual| removes.

    Parameters
    ----------
    row : dict
        A row of the score table or of the test (its ``per_scenario``).

    Returns
    -------
    dict
        Scenario → reduction, % (negative: the compensation makes that scenario worse; nan if its drift does not
        change).
    """
    return {sc: 100 * (1 - p["max_residual"] / p["uncompensated_max"]) if p["uncompensated_max"] > 0 else np.nan
            for sc, p in row["per_scenario"].items()}


def verdicts(result: PlacementResult) -> dict:
    """Plain statements on the goals per axis, judged on the test scenarios with the sets chosen on validation:
    ≥ 80 % reduction with 4–5 sensors, on each test scenario and pooled; the best own method vs the best seed
    method (both chosen on validation).

    Parameters
    ----------
    result : PlacementResult
        The study's result (its ``config``, ``table`` and ``test`` are read).

    Returns
    -------
    dict
        Axis → the uncompensated peaks (µm), the chosen method and K with their validation and test max
        |residual| (µm); ``best_reduction_percent`` and ``goal_80_percent_pooled`` (the largest residual on any
        test scenario over the largest drift change on any); ``reduction_percent_per_scenario`` and
        ``goal_80_percent_scenarios`` (on how many test scenarios the goal is met); ``goal_80_percent``: met on
        every test scenario.  With both kinds of method, the best own and seed sets on the test, on how many test
        scenarios ours leaves less, and per K whether ours beat theirs on validation.
    """
    out = {}
    for axis in result.config["axes"]:
        best = result.test["best"][axis]
        each = per_scenario_reductions(best)
        entry = {"uncompensated_max": result.uncompensated_test[axis][0],
                 "validation_uncompensated_max": result.uncompensated[axis][0],
                 "best_method": best["method"], "best_K": best["K"],
                 "best_validation_max_residual": _validation_max(result, axis, best),
                 "best_max_residual": best["max_residual"], "best_reduction_percent": best["reduction_percent"],
                 "goal_80_percent_pooled": bool(best["reduction_percent"] >= 80.0),
                 "reduction_percent_per_scenario": each,
                 "goal_80_percent_scenarios": sum(bool(v >= 80.0) for v in each.values()),
                 "goal_80_percent": all(bool(v >= 80.0) for v in each.values())}
        if "own" in result.test:
            o, s = result.test["own"][axis], result.test["seed"][axis]
            entry.update(own_best=(o["method"], o["K"], o["max_residual"]),
                         seed_best=(s["method"], s["K"], s["max_residual"]),
                         own_beats_seed=bool(o["max_residual"] < s["max_residual"]),
                         own_beats_seed_scenarios=sum(o["per_scenario"][sc]["max_residual"]
                                                      < s["per_scenario"][sc]["max_residual"] for sc in each),
                         own_beats_seed_at_K_validation=_own_beats_seed_at_k(result, axis))
        out[axis] = entry
    return out


def _intervals(cfg):
    """How often the records are, as the header says it: the most common interval, s, then the others' scenarios
    (sampled more coarsely than ``--record-interval``)."""
    by = {}
    for name, dt in cfg["record_intervals_s"].items():
        by.setdefault(dt, []).append(name)
    common = max(by, key=lambda dt: len(by[dt]))
    return f"every {common:g} s" + "".join(f"; every {dt:g} s for {', '.join(names)} (their own sampling)"
                                            for dt, names in by.items() if dt != common)


def _header(result):
    cfg, t = result.config, result.timings
    return [f"# Sensor placement on {cfg['machine']}", "",
            (f"- candidates: {cfg['n_candidates']} ({cfg['n_surface']} surface nodes of "
             f"{', '.join(cfg['parts'])}; {cfg['n_camera']} camera spots)"),
            f"- training scenarios (selection, model fit): {', '.join(cfg['train'])}",
            f"- validation scenarios (choice of method and K): {', '.join(cfg['validation'])}",
            f"- test scenarios (the chosen sets only, once): {', '.join(cfg['test'])}",
            "- each list is sorted by scenario name before anything is computed: the order given does not matter",
            (f"- compensation model scored: MLR with intercept on zero-referenced inputs and drift; sensor noise "
             f"{'DS18S20/S65/NCDT' if cfg['noise'] else 'none'} seeded by scenario name; records "
             f"{_intervals(cfg)}"),
            (f"- wall time: simulations {t['simulation_s']:.1f} s ({t['simulated']} run, {t['from_cache']} from "
             f"cache), selection {t['selection_s']:.1f} s, scoring {t['scoring_s']:.1f} s, "
             + (f"noise redrawn {t['redraw_s']:.1f} s, " if "redraw_s" in t else "") + f"total {t['total_s']:.1f} s"),
            ""]


def _goal_words(e):
    """The 80 % verdict: on how many test scenarios it is met (those missed, with their %), then pooled."""
    each = e["reduction_percent_per_scenario"]
    missed = [f"{sc}: {v:.1f} %" for sc, v in each.items() if not v >= 80.0]
    return (f"80 % goal met on {e['goal_80_percent_scenarios']} of {len(each)} test scenarios"
            + (f" (not on {', '.join(missed)})" if missed else "")
            + f"; pooled (the largest residual on any test scenario over the largest drift on any): "
              f"{e['best_max_residual']:.2f} µm, {e['best_reduction_percent']:.1f} % below "
              f"{e['uncompensated_max']:.2f} µm — {'met' if e['goal_80_percent_pooled'] else 'NOT met'}")


def _axis_section(result, axis, e):
    peak, rms = result.uncompensated[axis]
    pool = best_k_pool(result.config["k_max"])
    ks = f"K = {pool[0]}" + ("" if len(pool) == 1 else f"–{pool[-1]}")
    lines = [f"## {axis}: validation max |residual| / RMSE (µm); uncompensated {peak:.2f} / {rms:.2f} µm", "",
             k_method_table(result, axis),
             (f"- chosen on validation ({ks}): {e['best_method']} K = {e['best_K']} "
              f"({e['best_validation_max_residual']:.2f} µm); on the test: {_goal_words(e)}")]
    if "own_best" in e:
        o, s = e["own_best"], e["seed_best"]
        lines.append(f"- test: our best method on validation ({o[0]} K = {o[1]}: {o[2]:.2f} µm) "
                     f"{'beats' if e['own_beats_seed'] else 'does NOT beat'} the seed methods' best on validation "
                     f"({s[0]} K = {s[1]}: {s[2]:.2f} µm) pooled, and leaves less on {e['own_beats_seed_scenarios']} "
                     f"of {len(e['reduction_percent_per_scenario'])} test scenarios; K where ours is better on "
                     f"validation: {[k for k, b in e['own_beats_seed_at_K_validation'].items() if b]}")
    return lines + ["", *_per_scenario_table(result, axis), ""]


def _tested_sets(result, axis):
    """``(label, test row)`` of each distinct set scored on the test for ``axis``: the chosen one, the best own
    and the best seed method's."""
    labels = {}
    for key, label in (("best", "chosen"), ("own", "best own"), ("seed", "best seed")):
        if key in result.test:
            row = result.test[key][axis]
            labels.setdefault((row["method"], row["K"]), (row, []))[1].append(label)
    return [(" = ".join(names), row) for row, names in labels.values()]


def _per_scenario_table(result, axis):
    """Each set scored on the test × each test scenario: its own uncompensated max, max residual, RMSE, %."""
    rows = []
    for label, row in _tested_sets(result, axis):
        pct = per_scenario_reductions(row)
        rows += [[f"{label}: {row['method']} K = {row['K']}", sc, p["rows"], f"{p['uncompensated_max']:.2f}",
                  f"{p['max_residual']:.2f}", f"{p['rmse']:.2f}", f"{pct[sc]:.1f}",
                  "met" if pct[sc] >= 80.0 else "NOT met"] for sc, p in row["per_scenario"].items()]
    return [f"{axis} on each test scenario (µm; % below that scenario's own uncompensated max):", "",
            markdown_table(rows, ["set", "test scenario", "rows", "uncompensated max", "max residual", "RMSE",
                                  "% below", "80 % goal"])]


def _redraw_section(result):
    """How many chosen sensors the same method and K pick again with the sensor noise drawn anew."""
    lines = ["## The chosen sets with the sensor noise drawn again", "",
             ("The chosen method and K of each axis, run again on the same training scenarios with a second noise "
              "seed per scenario (the test scenarios' noise redrawn too):"), ""]
    for axis, r in result.redraw.items():
        gaps, others = r["others_distance_m"], r["K"] - r["shared"]
        span = f"{gaps[0]:.2f}" if len(gaps) == 1 else f"{min(gaps, default=0):.2f}–{max(gaps, default=0):.2f}"
        where = (f"; the other {others} {'lies' if others == 1 else 'lie'} {span} m from the nearest one picked "
                 f"again ({r['others_same_part']} of {others} on its part)" if gaps else "")
        lines.append(f"- {axis} ({r['method']} K = {r['K']}): {r['shared']} of the {r['K']} chosen sensors picked "
                     f"again ({', '.join(r['sensors'])}){where}; test max |residual| with the new noise "
                     f"{r['test_max_residual_chosen']:.2f} µm for the chosen set, {r['test_max_residual_again']:.2f} µm "
                     "for the new one")
    return lines + [""]


def _anfis_section(anfis):
    rows = [[a["axis"], a["method"], a["K"], f"failed: {a['error']}", "", ""] if "error" in a else
            [a["axis"], a["method"], a["K"], f"{a['max_residual']:.2f}", f"{a['rmse']:.2f}",
             f"{a['reduction_percent']:.1f}"] for a in anfis]
    return ["## ANFIS-FCM (3 rules) on the chosen method's sensors, test scenarios", "",
            markdown_table(rows, ["axis", "method", "K", "max residual (µm)", "RMSE (µm)", "reduction %"]), ""]


def _chosen_section(result):
    pool = best_k_pool(result.config["k_max"])
    c = result.candidates
    rows = [[f"{axis} ({method})", j, c.names[i], c.kinds[i], c.parts[i], *c.points[i]]
            for axis, (method, _k, idx) in result.best.items() for j, i in enumerate(idx, start=1)]
    return [f"## Chosen locations (method and K = {pool[0]}{'' if len(pool) == 1 else f'–{pool[-1]}'} chosen on "
            "validation)", "",
            markdown_table(rows, ["axis", "#", "sensor", "kind", "part", "x (m)", "y (m)", "z (m)"], formats=".3f")]


def placement_summary(result: PlacementResult) -> str:
    """The Markdown report (``placement.md``): setup, K × method tables, verdicts and the test scenarios one by
    one per axis, ANFIS check, the chosen sets with the noise drawn again, chosen locations.

    Parameters
    ----------
    result : PlacementResult
        The study's result (its ``config``, ``table`` and ``test`` are read).

    Returns
    -------
    str
        Markdown, ending with a newline.
    """
    lines = _header(result)
    v = verdicts(result)
    for axis in result.config["axes"]:
        lines += _axis_section(result, axis, v[axis])
    if result.anfis:
        lines += _anfis_section(result.anfis)
    if result.redraw:
        lines += _redraw_section(result)
    return "\n".join(lines + _chosen_section(result)) + "\n"


def record_dataset(record: Record, candidates: Candidates, columns: list[int], machine: Machine,
                   scenario: Scenario | Path | str) -> Dataset:
    """A :class:`~twin.core.dataset.Dataset` of a (noisy) record: operating conditions, the chosen candidates as
    thermometers (°C, with positions) and the drift axes (µm) — what a machine fitted with those sensors
    would log, ready for ``twin train`` / ``twin evaluate``.

    Parameters
    ----------
    record : Record
        The record.
    candidates : Candidates
        The study's candidates.
    columns : list of int
        Candidates to include as thermometers.
    machine : Machine
        The machine (its operating-condition channels).
    scenario : Scenario, Path or str
        The record's scenario.

    Returns
    -------
    Dataset
    """
    sc = as_scenario(scenario)
    cond = ScenarioInputs(machine, sc).conditions(record.time_s)
    channels, cols = machine_condition_channels(machine, cond)
    for i in columns:
        channels.append(ChannelInfo(candidates.names[i], "degC", "temperature",
                                    f"placement candidate ({candidates.kinds[i]}, {candidates.parts[i]})",
                                    tuple(float(v) for v in candidates.points[i])))
        cols.append(record.temperatures[:, i])
    for axis, values in record.drift.items():
        channels.append(ChannelInfo(axis, "um", "displacement", f"TCP drift {axis}"))
        cols.append(values)
    meta = {"kind": "synthetic", "machine": machine.name, "scenario": record.scenario,
            "scenario_file": sc.source, "noise": "DS18S20/S65/NCDT (placement study)",
            "source": "twin place", "project_version": project_version()}
    return Dataset(record.time_s, np.column_stack(cols), channels, meta)


def _candidate_frame(result):
    """Every candidate: kind, part, coordinates (m), the methods' scores and the smallest K that chose it."""
    import pandas as pd

    c = result.candidates
    frame = pd.DataFrame({"name": c.names, "kind": c.kinds, "part": c.parts, "x_m": c.points[:, 0],
                          "y_m": c.points[:, 1], "z_m": c.points[:, 2]})
    for key, values in result.cand_scores.items():
        frame[key] = values
    for (method, axis), sets in result.selections.items():
        col = np.zeros(len(c), int)
        for k in range(len(sets), 0, -1):          # smallest K at which the candidate is chosen
            col[np.asarray(sets[k - 1], int)] = k
        frame[f"chosen_K_{method}_{axis}"] = col
    return frame


def _chosen_rows(result):
    c = result.candidates
    return [{"axis": axis, "method": method, "K": k, "rank": j, "name": c.names[i], "kind": c.kinds[i],
             "part": c.parts[i], "x_m": float(c.points[i, 0]), "y_m": float(c.points[i, 1]),
             "z_m": float(c.points[i, 2])}
            for axis, (method, k, idx) in result.best.items() for j, i in enumerate(idx, start=1)]


def write_placement_report(result: PlacementResult, machine: Machine, folder: Path) -> None:
    """Write ``placement.md``, ``placement.json``, the CSV tables, ``chosen_sensors.png``, ``k_curves.png`` and
    (if the result keeps its records) ``datasets/<scenario>.csv`` into ``folder``.

    Parameters
    ----------
    result : PlacementResult
        The study's result, with its summary.
    machine : Machine
        The machine (for the render and the datasets).
    folder : Path
        An existing, empty folder.
    """
    import matplotlib

    matplotlib.use("Agg")
    import pandas as pd

    folder = Path(folder)
    (folder / "placement.md").write_text(result.summary, encoding="utf-8")
    rows = [{k: v for k, v in r.items() if k != "per_scenario"} | {"sensors": " ".join(r["sensors"])}
            for r in result.table]
    pd.DataFrame(rows).to_csv(folder / "k_method_table.csv", index=False)
    _candidate_frame(result).to_csv(folder / "candidate_scores.csv", index=False)
    chosen = _chosen_rows(result)
    pd.DataFrame(chosen).to_csv(folder / "chosen_sensors.csv", index=False)
    (folder / "placement.json").write_text(json.dumps({
        "config": {k: v for k, v in result.config.items() if k != "scenario_objects"}, "timings": result.timings,
        "uncompensated": result.uncompensated, "uncompensated_test": result.uncompensated_test,
        "verdicts": verdicts(result), "table": result.table, "test": result.test, "anfis": result.anfis,
        "redraw": result.redraw, "chosen": chosen}, indent=1, default=json_default))
    _render_chosen(result, machine, chosen, folder / "chosen_sensors.png")
    _plot_k_curves(result, folder / "k_curves.png")
    if getattr(result, "records", None):
        chosen_idx = sorted({i for _m, _k, idx in result.best.values() for i in idx})
        (folder / "datasets").mkdir()
        for rec, sc in zip(result.records, result.config["scenario_objects"]):
            record_dataset(rec, result.candidates, chosen_idx, machine, sc).write(
                folder / "datasets" / f"{rec.scenario}.csv")


def _render_chosen(result, machine, chosen, path):
    """One render: the best sets of every axis, labelled axis + rank."""
    from ..infra.render import (
        render_machine,  # on use: pyvista/VTK take seconds to load
    )

    pts = np.array([[r["x_m"], r["y_m"], r["z_m"]] for r in chosen])
    labels = [f"{r['axis']}{r['rank']}" for r in chosen]
    render_machine(machine, path, points=pts, point_labels=labels,
                   point_categories=[f"{r['axis']} drift: {r['method']}, K = {r['K']}" for r in chosen],
                   title="chosen sensors: " + ", ".join(f"{a}: {m} K={k}" for a, (m, k, _) in result.best.items()))


def _plot_k_curves(result, path):
    import matplotlib.pyplot as plt

    axes = result.config["axes"]
    fig, ax = plt.subplots(1, len(axes), figsize=(6 * len(axes), 4.5), squeeze=False)
    for j, axis in enumerate(axes):
        a = ax[0, j]
        for method in result.config["methods"]:
            rows = sorted((r for r in result.table if r["method"] == method and r["axis"] == axis),
                          key=lambda r: r["K"])
            a.plot([r["K"] for r in rows], [r["max_residual"] for r in rows], marker="o",
                   ls="-" if method in OWN_METHODS else "--", label=method)
        a.axhline(0.2 * result.uncompensated[axis][0], color="k", lw=0.8, ls=":", label="80 % reduction (validation)")
        t = result.test["best"][axis]
        a.plot([t["K"]], [t["max_residual"]], "k*", ms=13, label=f"chosen {t['method']} K = {t['K']} on test")
        a.set_yscale("log")
        a.set_xlabel("number of sensors K")
        a.set_ylabel("validation max |residual| (µm)")
        a.set_title(f"{axis}: uncompensated {result.uncompensated[axis][0]:.1f} µm (validation), "
                    f"{result.uncompensated_test[axis][0]:.1f} µm (test)")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
