"""The written diagnosis: ``report.md`` with figures (PNG) and ``diagnosis.json``, in one result folder.

The report answers, in order: is there a significant gap (the verdict); the
data and how it was read (missing channels, NaNs, gaps, sampling, offsets);
(a) where the twin misses (sensors, drift axes, phases, frequency bands,
parts, a render); (b) which effect explains it (ranking with fitted values,
uncertainty and evidence); (c) how far the residual shrinks on held-out data.
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from ..core.dataset import json_default
from ..infra.outdir import atomic_directory
from ..infra.plots import save_figure
from ..infra.tables import markdown_table
from .attribution import RESOLVED
from .diagnose import Diagnosis
from .discovery import render_discoveries
from .discretisation import COARSENING
from .fit import GROUP_UNIT
from .verdict import parameters, role, strict_json
from .verdict import to_json as verdict_json

#: Largest constant offset of a thermometer in calibration, K (a type K thermocouple's class 2 tolerance is
#: ±2.5 K up to 333 °C; a class B Pt100's ±0.8 K at 100 °C).
THERMOMETER_ACCURACY_K = 3.0
#: How many sensors the data section names with their discretisation floor (the largest against σ_g).
LARGEST_FLOORS = 4
GROUP_LABEL = {"temperature": "surface temperatures", "air": "air sensors", "displacement": "TCP drift",
               "strain": "strain lines"}


def _f(v, spec=".3g"):
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    return format(v, spec)


def _save(fig, path):
    """Save a figure atomically (:func:`twin.infra.plots.save_figure`); the file name, for the Markdown links."""
    return save_figure(fig, path).name


def write_report(d: Diagnosis, out_dir: str | Path, render: bool = True, overwrite: bool = False) -> Path:
    """Write ``report.md``, ``diagnosis.json`` and the figures of a :class:`~twin.gap.diagnose.Diagnosis`.

    ``out_dir`` is written as :func:`twin.infra.outdir.atomic_directory` does (``overwrite`` likewise).

    Parameters
    ----------
    d : Diagnosis
        The diagnosis (a failed render adds a note to it).
    out_dir : str or Path
        The result folder.
    render : bool, default True
        Also make the off-screen 3-D renders (:func:`render_figures`).
    overwrite : bool, default False
        Replace an existing result folder.

    Returns
    -------
    Path
        The result folder.
    """
    out_dir = Path(out_dir)
    with atomic_directory(out_dir, overwrite) as tmp:
        figures = {"residuals": plot_residuals(d, tmp / "residuals.png"),
                   "ranking": plot_ranking(d, tmp / "ranking.png"),
                   "breakdown": plot_breakdown(d, tmp / "phases_bands.png")}
        att = plot_attribution(d, tmp / "attribution.png")
        if att:
            figures["attribution"] = att
        if render:
            try:
                figures.update(render_figures(d, tmp))
            except Exception as exc:  # pragma: no cover - off-screen rendering depends on the host
                d.notes.append(f"render skipped: {exc}")
        (tmp / "report.md").write_text(format_report(d, figures))
        (tmp / "diagnosis.json").write_text(json.dumps(strict_json(to_json(d)), indent=1, default=json_default,
                                                       allow_nan=False))
    return out_dir


def to_json(d: Diagnosis) -> dict[str, object]:
    """The machine-readable diagnosis.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis.

    Returns
    -------
    dict
        The content of ``diagnosis.json``: verdict, named model and ranking (fits, ΔBIC, held-out figures),
        noise and scales (channel units), nominal residual, shrinkage, where, attribution, import report, notes,
        timings (s); numpy values are converted by :func:`twin.core.dataset.json_default`.  The file itself is
        strict JSON: :func:`write_report` writes null for a non-finite number (:func:`twin.gap.verdict.strict_json`).
    """
    def res(r):
        return {"name": r.name, "params": r.params(), "delta_bic": r.delta_bic, "bic": r.bic,
                "sse_fit": r.residual.sse_fit, "sse_hold": r.residual.sse_hold, "groups": r.summary["groups"],
                "seconds": r.seconds, "evaluations": r.nfev, "notes": r.notes}
    attr = d.attribution.get("regions")
    win = d.attribution.get("winner")
    return {
        "verdict": verdict_json(d), "significant": d.significant,
        "winner": res(d.winner) if d.winner is not None else None,
        "runner_up": d.runner_up.name if d.runner_up is not None else None,
        "n_eff_hold": d.n_eff_hold,
        "split_s": d.split_s, "noise": d.noise, "gap_over_noise": d.gap_over_noise,
        "gap_over_tolerance": d.gap_over_tolerance, "group_scale": d.scales.group,
        "sensor_scale": d.scales.sensor, "timing_floor": d.scales.timing_sensor,
        "discretisation_floor": d.scales.discretisation_sensor or None,
        "nominal": {**res(d.nominal), "channels": d.nominal.summary["channels"],
                    "offsets": dict(zip(d.names, d.nominal.residual.offsets.tolist())),
                    "initial_state": d.nominal.residual.nuisance},
        "ranking": [res(r) for r in d.ranking], "shrinkage": d.shrinkage(),
        "where": d.where, "separation": d.separation,
        "attribution": {"regions": None if attr is None else {k: attr[k] for k in (
                            "rms_K", "shares", "influence", "observed_regions", "resolution", "sd_K", "resolved",
                            "unresolved_share")},
                        "winner": None if win is None else {"shares": win["shares"],
                                                            "field_time_s": win["field_time_s"]}},
        "data": d.record.report, "notes": d.notes, "skipped_effects": d.skipped, "timings": d.timings,
    }


# ============================================================================= figures
def plot_residuals(d: Diagnosis, path: str | Path, n_temperatures: int = 6) -> str:
    """Residuals over time: the worst thermometers and every drift axis, nominal and with the winner.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis.
    path : str or Path
        The PNG to write.
    n_temperatures : int, default 6
        Thermometers shown: those with the largest held-out nominal RMS.

    Returns
    -------
    str
        The file name (for the Markdown link).
    """
    ev, names = d.evaluator, d.names
    th = d.record.time_s / 3600.0
    temps = [j for j, k in enumerate(ev.kinds) if k == "temperature"]
    rms = {j: d.nominal.summary["channels"][names[j]]["hold_rms"] for j in temps}
    temps = sorted(temps, key=lambda j: -np.nan_to_num(rms[j]))[:n_temperatures]
    drift = [j for j, k in enumerate(ev.kinds) if k == "displacement"]
    panels = [("temperature", temps, "K"), ("displacement", drift, "µm")]
    panels = [p for p in panels if p[1]]
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 3.6 * len(panels)), sharex=True, squeeze=False)
    for ax, (kind, cols, unit) in zip(axes[:, 0], panels):
        for i, j in enumerate(cols):
            color = f"C{i}"
            ax.plot(th, d.nominal.residual.R[:, j], color=color, lw=1.0, label=f"{names[j]} nominal")
            if d.winner is not None:
                ax.plot(th, d.winner.residual.R[:, j], color=color, lw=1.0, ls="--", label=f"{names[j]} + effect")
        ax.axvspan(d.split_s / 3600.0, th[-1], color="grey", alpha=0.12, lw=0)
        ax.set_ylabel(f"residual, measured − twin ({unit})")
        ax.set_title(f"{GROUP_LABEL[kind]}: nominal (solid)"
                     + (f", with {d.winner.name} (dashed)" if d.winner is not None else "")
                     + "; held-out part shaded")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=3)
    axes[-1, 0].set_xlabel("time (h)")
    return _save(fig, path)


def plot_ranking(d: Diagnosis, path: str | Path, n: int = 12) -> str:
    """ΔBIC vs the nominal twin on held-out data of the leading models.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis.
    path : str or Path
        The PNG to write.
    n : int, default 12
        Models shown (ΔBIC below −50 drawn at −50).

    Returns
    -------
    str
        The file name (for the Markdown link).
    """
    top = d.ranking[:n]
    fig, ax = plt.subplots(figsize=(9, 0.35 * len(top) + 1.5))
    values = [max(r.delta_bic, -50) for r in top]
    colors = ["C2" if d.winner is not None and r is d.winner else "C0" for r in top]
    ax.barh(range(len(top)), values, color=colors)
    ax.set_yticks(range(len(top)), [r.name for r in top], fontsize=8)
    ax.invert_yaxis()
    ax.axvline(10, color="red", lw=0.8, ls="--")
    ax.set_xscale("symlog", linthresh=10)
    ax.set_xlabel("ΔBIC vs nominal on held-out data (higher is better; dashed: significance 10)")
    ax.grid(alpha=0.3, axis="x")
    return _save(fig, path)


def plot_breakdown(d: Diagnosis, path: str | Path) -> str:
    """RMS residual per phase and per frequency band, per channel group, before (and after) the winner.

    Bars are the RMS over the group scale σ_g (dimensionless).

    Parameters
    ----------
    d : Diagnosis
        The diagnosis (its ``where`` tables filled).
    path : str or Path
        The PNG to write.

    Returns
    -------
    str
        The file name (for the Markdown link).
    """
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    for ax, key, title in ((axes[0], "phases", "per operating phase (all rows)"),
                           (axes[1], "bands", "per frequency band (all rows)")):
        table = d.where[key]
        labels = list(table)
        groups = [g for g in ("temperature", "displacement", "strain") if g in d.evaluator.groups()]
        width = 0.8 / max(len(groups), 1)
        for i, g in enumerate(groups):
            before = [table[k].get(g, np.nan) / d.evaluator.sigma.get(g, 1) for k in labels]
            ax.bar(np.arange(len(labels)) + i * width, before, width, label=f"{GROUP_LABEL[g]} nominal", color=f"C{i}")
            after = d.where.get(f"{key}_after")
            if after:
                ax.bar(np.arange(len(labels)) + i * width, [after[k].get(g, np.nan) / d.evaluator.sigma.get(g, 1)
                                                            for k in labels], width * 0.5, color="black",
                       alpha=0.55, label=f"{GROUP_LABEL[g]} with effect" if i == 0 else None)
        ax.set_xticks(np.arange(len(labels)) + 0.4 - width / 2, labels, rotation=20, fontsize=8)
        ax.set_ylabel("RMS residual / group scale σ_g (–)")
        ax.set_title(title)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=7)
    return _save(fig, path)


def plot_attribution(d: Diagnosis, path: str | Path) -> str | None:
    """Shares of the drift residual explained by each part (model-free estimate, and through the winner).

    Parameters
    ----------
    d : Diagnosis
        The diagnosis (its ``attribution`` filled).
    path : str or Path
        The PNG to write.

    Returns
    -------
    str or None
        The file name (for the Markdown link), or None (no figure) without drift shares.
    """
    est = d.attribution.get("regions")
    if not est or not est["shares"]:
        return None
    axes_names = list(est["shares"])
    regions = est["regions"]
    fig, ax = plt.subplots(figsize=(10, 4))
    width = 0.8 / len(axes_names)
    for i, a in enumerate(axes_names):
        ax.bar(np.arange(len(regions)) + i * width, [est["shares"][a][r]["share"] for r in regions], width,
               label=f"{a} (model-free estimate)")
    win = d.attribution.get("winner")
    if win:
        for i, a in enumerate(axes_names):
            if a in win["shares"]:
                ax.scatter(np.arange(len(regions)) + i * width, [win["shares"][a][r]["share"] for r in regions],
                           marker="x", color="black", zorder=3, label="through the winner" if i == 0 else None)
    ax.set_xticks(np.arange(len(regions)) + 0.4 - width / 2, regions, rotation=20, fontsize=8)
    ax.set_ylabel("share of the drift residual (–)")
    ax.axhline(0, color="black", lw=0.6)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("Which part's temperature error explains the drift error")
    return _save(fig, path)


def _resolved_part_values(mesh, est):
    """``(node_values, clim)`` of the residual render: each mesh node gets its part's estimated error RMS (K) where
    the sensors resolve the part, else NaN (drawn in the render's NaN colour, grey: not a location); ``clim`` is
    (0, 1) K when no part is resolved, else None."""
    region = np.empty(mesh.n_nodes, dtype=int)
    region[mesh.tets.ravel()] = np.repeat(mesh.regions, 4)
    ids = sorted(mesh.region_names)
    rms = np.array([est["rms_K"][mesh.region_names[r]] if mesh.region_names[r] in est["resolved"] else np.nan
                    for r in ids])
    index = {r: i for i, r in enumerate(ids)}
    return rms[[index[r] for r in region]], None if np.isfinite(rms).any() else (0.0, 1.0)


def render_figures(d: Diagnosis, tmp: Path) -> dict[str, str]:
    """Off-screen renders: sensors and parts coloured by residual; the winner's temperature change.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis.
    tmp : Path
        The folder to write the PNGs to.

    Returns
    -------
    dict of str to str
        ``render_residuals`` (parts resolved by the sensors by estimated error RMS, K, the others grey; sensors by
        held-out residual RMS, K), and when there
        is a winner ``render_effect`` (its temperature change, K) and with a discovery ``render_discoveries`` →
        file name.
    """
    from ..infra.render import (
        render_machine,  # on use: pyvista/VTK take seconds to load
    )

    s = d.model.structure
    machine = s.machine
    out = {}
    est = d.attribution.get("regions")
    therm = [j for j, k in enumerate(d.evaluator.kinds) if k == "temperature"]
    pts = np.array([s.channels[s.index[d.names[j]]].position for j in therm])
    vals = [d.nominal.summary["channels"][d.names[j]]["hold_rms"] for j in therm]
    node_values, clim = _resolved_part_values(machine.mesh, est) if est is not None else (None, None)
    out["render_residuals"] = render_machine(
        machine, tmp / "render_residuals.png", node_values=node_values, clim=clim,
        scalar_label="part temperature error, RMS (K); grey = not resolved by the sensors", cmap="Oranges",
        points=pts, point_labels=[d.names[j] for j in therm], point_values=vals,
        point_label="sensor residual, held-out RMS (K)",
        title="Where the twin misses: resolved parts by estimated error (grey: not resolved), sensors by residual"
        ).name
    win = d.attribution.get("winner")
    if win is not None:
        field = machine.thermal.nodal_field(win["field"])
        lim = float(np.abs(field).max()) or 1.0
        out["render_effect"] = render_machine(
            machine, tmp / "render_effect.png", node_values=field, scalar_label="temperature change (K)",
            cmap="coolwarm", clim=(-lim, lim),
            title=f"{d.winner.name}: temperature change at t = {win['field_time_s'] / 3600:.1f} h").name
    if d.discovery is not None:
        png = render_discoveries(d.discovery, machine, tmp / "render_discoveries.png")
        if png is not None:
            out["render_discoveries"] = Path(png).name
    return out


def _table(rows, headers, spec=".3g"):
    """A Markdown table (:func:`twin.infra.tables.markdown_table`) as a list of lines, numbers as ``spec``."""
    return markdown_table(rows, headers, formats=spec).split("\n")


def _breakdown_table(key, table, groups, drift_names, rows=False):
    """Markdown lines of a phase or band table (:mod:`.where`): RMS per channel group (no air) and drift axis."""
    shown = [g for g in groups if g != "air"]
    headers = [key] + (["rows"] if rows else []) + [f"{GROUP_LABEL[g]} ({GROUP_UNIT[g]})" for g in shown] \
        + [f"{n} (µm)" for n in drift_names]
    body = [[name] + ([e["rows"]] if rows else []) + [e.get(g) for g in shown + drift_names]
            for name, e in table.items()]
    return _table(body, headers)


# ============================================================================= Markdown
def format_report(d: Diagnosis, figures: Mapping[str, str]) -> str:
    """``report.md``: verdict, data, (a) where, (b) which effect, discoveries, (c) shrinkage, timing.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis.
    figures : mapping of str to str
        Figure key (``residuals``, ``ranking``, ``breakdown``, optional ``attribution`` and renders) → file name
        in the result folder.

    Returns
    -------
    str
        The Markdown.
    """
    L = [f"# Gap diagnosis: {d.record.report.get('source')} on `{d.machine.name}`", "",
         f"**Verdict ({d.outcome.replace('_', ' ')}): {d.verdict}.**", ""]
    for section in (_data_section, _where_section, _parts_section, _which_section, _discovery_section,
                    _shrink_section, _timing_section):
        L += section(d, figures)
    return "\n".join(L)


def _groups(d):
    return [g for g in ("temperature", "air", "displacement", "strain") if g in d.evaluator.groups()]


def _record_lines(d):
    """What the record holds: sampling and gaps, sensors used and missing, empty and ignored channels, NaNs, inputs."""
    rec = d.record.report
    nans = ", ".join(f"{k} {v} (longest run {rec['longest_nan_run_s'][k]:g} s)" for k, v in rec["nan_counts"].items())
    longest = f", the longest {max(g['length_s'] for g in rec['gaps']):g} s" if rec["gaps"] else ""
    spindle = "measured" if rec["has_spindle"] else "from the scenario"
    return [(f"- {rec['rows']} rows over {rec['span_h']:.2f} h, sampling {rec['sampling_interval_s']:g} s"
             f" ({'regular' if rec['sampling_regular'] else 'irregular'}); {rec['n_gaps']} gap(s){longest}"),
            _grid_line(d),
            f"- sensors used ({len(d.names)}): {', '.join(d.names)}",
            f"- sensors of the machine not in the data: {', '.join(rec['sensors_missing']) or 'none'}",
            f"- channels with no value at all (left out): {', '.join(rec['channels_empty']) or 'none'}",
            f"- ignored channels: {', '.join(rec['channels_ignored']) or 'none'}",
            f"- NaNs (masked out of the residuals): {nans or 'none'}",
            (f"- inputs: spindle {spindle}; feeds {', '.join(rec['feeds']) or 'none'}; ambient from "
             f"{', '.join(rec['air_inputs']) or 'the scenario'}"),
            *(f"- assumed: {phrase}" for phrase in rec.get("assumed_inputs", []))]


def _grid_line(d):
    """The twin's time grid and backend."""
    backend = d.model.backend
    states = f", {backend.order} states" if hasattr(backend, "order") else ""
    return (f"- twin on a {d.model.drive.step_s:g} s grid ({backend.name} backend{states}), spindle and feeds as "
            "piecewise-constant signals integrated exactly over each step, interpolated to the measured times")


def _split_lines(d):
    """The fit/held-out split, the noise level and the timing floor per channel group."""
    noise = ", ".join(f"{GROUP_LABEL[g]} {d.noise[g]:.3g} {GROUP_UNIT[g]}" for g in _groups(d))
    floor = ", ".join(f"{GROUP_LABEL[g]} {d.scales.timing_group[g]:.3g} {GROUP_UNIT[g]}" for g in _groups(d))
    return [(f"- split: fit on t ≤ {d.split_s / 3600:.2f} h, held out after ({int(d.evaluator.hold_rows.sum())} "
             f"rows); effective independent held-out samples n_eff = {d.n_eff_hold:.0f}"),
            f"- noise level (median per group, from second differences): {noise}",
            ("- timing floor (held-out RMS change of the nominal twin when the input change times move by ± half a "
             f"sample): {floor}"),
            _discretisation_line(d)]


def _discretisation_line(d):
    """The largest per-sensor discretisation floors, or why none was measured."""
    floors = d.scales.discretisation_sensor
    head = (f"- discretisation floor (held-out RMS change of the nominal twin on a {COARSENING:g}× coarser mesh, "
            "same backend; it widens σ_j, not σ_g): ")
    if not floors:
        why = ("the nominal twin leaves no gap without it" if d.decision.outcome == "no_significant_gap"
               else "see the notes")
        return head + f"not measured ({why})"
    kinds = dict(zip(d.names, d.evaluator.kinds, strict=True))
    largest = sorted(floors, key=lambda n: floors[n] / d.scales.group[kinds[n]], reverse=True)[:LARGEST_FLOORS]
    return head + "largest " + ", ".join(f"{n} {floors[n]:.3g} {GROUP_UNIT[kinds[n]]}" for n in largest)


def _offset_lines(d):
    """The constant sensor offsets and the initial-state nuisance of the nominal fit; surface thermometer offsets
    no thermometer's accuracy explains are called out (°F or kelvin renamed to degC, a wrong calibration; an air
    sensor's may be the room's stratification)."""
    off, kinds = d.nominal.residual.offsets, d.evaluator.kinds
    big = [(n, o, GROUP_UNIT[k]) for n, o, k in zip(d.names, off, kinds) if abs(o) > 0.25]
    listed = ", ".join(f"{n} {o:+.2f} {u}" for n, o, u in big[:12]) or "all small"
    largest = ", ".join(f"{GROUP_LABEL[g]} {max(abs(o) for o, k in zip(off, kinds) if k == g):.3g} {GROUP_UNIT[g]}"
                        for g in _groups(d))
    nuisance = ", ".join(f"{k} {v:+.3g}" for k, v in d.nominal.residual.nuisance.items())
    lines = [(f"- constant offsets (estimated on the fit part, every model): largest |offset| {largest}; "
              f"{listed} (thermometer accuracy, probe zero, ambient level)")]
    beyond = [f"{n} {o:+.2f} K" for n, o, k in zip(d.names, off, kinds)      # air sensors: stratification
              if k == "temperature" and abs(o) > THERMOMETER_ACCURACY_K]
    if beyond:
        lines.append(f"- **offsets no thermometer's accuracy (±{THERMOMETER_ACCURACY_K:g} K) explains**: "
                     f"{', '.join(beyond)}; check these channels' unit (°F or kelvin under _degC) and calibration "
                     "before reading the rest")
    return [*lines, f"- initial state (nuisance, nominal): {nuisance}"]


def _data_section(d, figures):
    return ["## Data", "", *_record_lines(d), *_split_lines(d), *(f"- note: {note}" for note in d.notes),
            *_offset_lines(d), ""]


def _where_section(d, figures):
    ev, sc = d.evaluator, d.scales
    groups = _groups(d)
    rows = [[f"{GROUP_LABEL[g]} ({GROUP_UNIT[g]})", d.nominal.summary["groups"][g]["fit_rms"],
             d.nominal.summary["groups"][g]["hold_rms"], d.nominal.summary["groups"][g]["hold_max"],
             d.gap_over_noise[g], sc.group[g], d.gap_over_tolerance[g]] for g in groups]
    L = ["## (a) Where the twin misses", ""]
    L += _table(rows, ["channel group", "fit RMS", "held-out RMS", "held-out max", "held-out RMS / noise",
                       "scale σ_g", "held-out RMS / σ_g"])
    L += ["", f"![residuals]({figures['residuals']})", "",
          ("Per sensor (σ_j = max(noise, tolerance) with the timing and discretisation floors; after = with the "
           "named effect):"), ""]
    rows = []
    for j, n in enumerate(d.names):
        s = d.nominal.summary["channels"][n]
        after = d.winner.summary["channels"][n]["hold_rms"] if d.winner is not None else None
        rows.append([n, f"{ev.kinds[j]} ({GROUP_UNIT[ev.kinds[j]]})", s["fit_rms"], s["hold_rms"], s["hold_max"],
                     sc.sensor[n], s["hold_rms"] / sc.sensor[n], after])
    L += _table(rows, ["sensor", "kind", "fit RMS", "held-out RMS", "held-out max", "σ_j", "held-out RMS / σ_j",
                       "after: held-out RMS"])
    drift_names = [n for n, k in zip(d.names, ev.kinds) if k == "displacement"]
    L += ["", "By operating phase (RMS over all rows; phases from spindle speed and ambient activity):", ""]
    L += _breakdown_table("phase", d.where["phases"], groups, drift_names, rows=True)
    L += ["", "By frequency band (RMS over all rows):", ""]
    L += _breakdown_table("band", d.where["bands"], groups, drift_names)
    L += ["", f"![phases and bands]({figures['breakdown']})", ""]
    return L


def _region_lines(est):
    """Markdown lines of the model-free part attribution: what it is, which parts it resolves, the table."""
    L = [("Which part's temperature error explains the drift error (model-free: a uniform temperature error "
          "per part, ridge-estimated from the thermometer and drift residuals through the displacement "
          "influence operators; share = part's contribution · residual / |residual|²; resolution = diagonal of "
          "the model-resolution matrix, 1 where the data decide the part's error, 0 where only the prior does; "
          "sd = its posterior sd)."), "",
         (f"Parts with resolution below {RESOLVED:g} are not told apart by these sensors, so their individual "
          "errors and shares are not a location; only their combined share (last row) is read."), ""]
    lines = list(est["shares"])
    rows = [[r, "yes" if r in est["observed_regions"] else "no", est["rms_K"][r], est["resolution"][r],
             est["sd_K"][r]] + [est["shares"][a][r]["share"] for a in lines]
            + [est["influence"][a][r] for a in est["influence"]] for r in est["regions"]]
    rows.append(["unresolved parts together", "", None, None, None]
                + [est["unresolved_share"][a] for a in lines] + [None] * len(est["influence"]))
    L += _table(rows, ["part", "sensors on it", "est. error RMS (K)", "resolution", "sd (K)"]
                + [f"{a} share" for a in lines] + [f"{a} ({est['units'][a]}/K)" for a in est["influence"]],
                [None, None, ".2f", ".2f", ".2g"] + ["+.2f"] * (len(lines) + len(est["influence"])))
    return L + [""]


def _parts_section(d, figures):
    L = []
    if d.discovery is not None and d.discovery.resolved():
        L += ["Where, from the discovery: " + "; ".join(x.sentence() for x in d.discovery.resolved()), ""]
    est = d.attribution.get("regions")
    if est is not None and est["shares"]:
        L += _region_lines(est)
    win = d.attribution.get("winner")
    if win is not None:
        axes = list(win["shares"])
        L += [f"Through the named effect ({d.winner.name}): its drift change split exactly over the parts "
              "(share of the change; 'sensor/fixture' is the part not due to temperature):", ""]
        L += _table([[r] + [win["shares"][a][r]["share"] for a in axes] for r in win["shares"][axes[0]]],
                    ["part"] + axes, "+.2f")
        L.append("")
    for key, name in (("attribution", "attribution"), ("render_residuals", "render")):
        if key in figures:
            L += [f"![{name}]({figures[key]})", ""]
    return L


def _which_section(d, figures):
    groups = [g for g in _groups(d) if g != "air"]
    L = ["## (b) Which effect", "",
         f"Candidates: {len(d.singles)} effects of the library"
         + (f" (not applicable to this machine: {', '.join(d.skipped)})" if d.skipped else "")
         + f", and {len(d.pairs)} pairs (the leading effect with each other one, and pairs of the leaders). Ranked "
           "by ΔBIC against the nominal twin on the held-out part (n_eff · ln(SSE/SSE_nominal) + k · ln n_eff); "
           "90 % intervals from a HAC sandwich covariance inflated by the held-out misfit.", ""]
    rows = []
    for i, r in enumerate(d.ranking[:20]):
        params = "; ".join(f"{p['name'].split('.', 1)[1]} = {p['value']:.3g} ({p['interval90'][0]:.3g} … "
                           f"{p['interval90'][1]:.3g}) {p['unit']}" for p in parameters(r))
        mark = f" **({role(d, r)})**" if role(d, r) else ""
        rows.append([i + 1, r.name + mark, params, r.delta_bic,
                     r.residual.sse_hold / max(d.nominal.residual.sse_hold, 1e-300)]
                    + [r.summary["groups"][g]["hold_rms"] for g in groups] + ["; ".join(r.notes)])
    L += _table(rows, ["rank", "model", "parameters (90 %)", "ΔBIC", "held-out SSE / nominal"]
                + [f"held-out {GROUP_LABEL[g]} RMS ({GROUP_UNIT[g]})" for g in groups] + ["notes"])
    L += ["", f"![ranking]({figures['ranking']})", ""]
    ev = d.decision.evidence()
    if "runner_up" in ev:
        L.append(f"**Evidence:** {ev['model']} vs the runner-up {ev['runner_up']}: ΔBIC "
                 f"{ev['delta_bic_vs_runner_up']:.1f} (log10 evidence ratio {ev['log10_ratio_vs_runner_up']:.1f}; "
                 "> 2.2 is 'very strong' on the Kass–Raftery scale).")
    if d.separation and "error" not in d.separation:
        s = d.separation
        L.append(f"**Separating sensor** ({s['a']} vs {s['b']}): a thermometer on the {s['part']} at "
                 f"{s['position_m']} m (zone {s['zone']}) would see their fitted signatures differ by "
                 f"{s['difference_rms_K']:.3f} K RMS ({s['difference_over_noise']:.1f}× the noise); the nearest "
                 f"existing sensor is {s['nearest_sensor']} ({s['nearest_sensor_distance_m'] * 1e3:.0f} mm away); "
                 f"the best existing one, {s['best_existing_sensor']}, sees {s['best_existing_difference_rms_K']:.3f} K.")
    L.append("")
    if "render_effect" in figures:
        L += [f"![effect]({figures['render_effect']})", ""]
    return L


def _discovery_section(d, figures):
    if d.discovery is None:
        return []
    figure = [f"![discovered sources]({figures['render_discoveries']})", ""] if "render_discoveries" in figures else []
    return ["## Beyond the library (effect discovery)", ""] + [f"- {line}" for line in d.discovery.summary()] + [""] \
        + figure


def _shrink_section(d, figures):
    L = ["## (c) How far the residual shrinks (held-out part)", ""]
    if d.winner is None:
        return L + ["No effect is named, so the residual stays the nominal one.", ""]
    rows = []
    for k, s in d.shrinkage().items():
        label = f"{GROUP_LABEL[k]} ({GROUP_UNIT[k]})" if k in GROUP_LABEL else f"drift {k} (µm)"
        rows.append([label, f"{_f(s['before_rms'])} → {_f(s['after_rms'])}",
                     f"{_f(s['before_max'])} → {_f(s['after_max'])}", 100 * s["reduction"]])
    return L + [f"With {d.winner.name} added:", ""] + _table(
        rows, ["channels", "RMS before → after", "max before → after", "RMS reduction (%)"], ".0f") + [""]


def _timing_section(d, figures):
    t = d.timings
    return ["## Timing", "",
            f"engine {t.get('engine_s', 0):.1f} s (cached per process), nominal {t.get('nominal_s', 0):.1f} s, fits "
            f"{t.get('fits_s', 0):.1f} s, where/attribution {t.get('where_s', 0):.1f} s"
            + (f", discovery {t['discovery_s']:.1f} s" if "discovery_s" in t else "")
            + f"; total {t.get('total_s', 0):.1f} s.", ""]
