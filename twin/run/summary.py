"""A short readable summary of a run, and the quantities an ISO 230-3 test reports."""
from __future__ import annotations

import numpy as np

from fea.energy import ENERGY_FLOOR_K

from ..core.dataset import Dataset, name_listing
from ..errors import TwinInputError
from ..infra.tables import markdown_table


def tilt_urad(dataset: Dataset, probe_spacing_m: float) -> np.ndarray:
    """Tilt in the YZ plane from the two Y probes.

    Parameters
    ----------
    dataset : Dataset
        With the ``Y`` and ``Y_top`` drift channels, µm.
    probe_spacing_m : float
        Distance between the probes, m.

    Returns
    -------
    ndarray
        Tilt, µrad (= µm per m).
    """
    return (dataset["Y_top"] - dataset["Y"]) / probe_spacing_m


def run_summary(dataset: Dataset, wall_seconds: float | None, probe_spacing_m: float = 0.1,
                iso_test: str | None = None) -> dict:
    """The key figures of a run.

    Parameters
    ----------
    dataset : Dataset
        The run's (or a measured) dataset.
    wall_seconds : float or None
        Simulation wall time, s; None for a dataset this process did not simulate (``run_seconds`` is then null).
    probe_spacing_m : float
        Distance of the two Y probes, m (for the tilt).
    iso_test : str, optional
        ``"spindle"`` or ``"etve"``: add that ISO 230-3 test's quantities.

    Returns
    -------
    dict
        Peak drift per axis (µm, the change since the first sample, as ISO 230-3 takes it) and its time
        (h since the first sample), hottest sensor (°C, K), run time (s), time-integration and energy
        checks, ISO 230-3 quantities.

    Raises
    ------
    TwinInputError
        Fewer than two samples, or an ISO test whose channels the dataset lacks.
    """
    if len(dataset) < 2:
        raise TwinInputError(f"{dataset.metadata.get('source', 'the dataset')}: {len(dataset)} sample(s); a summary "
                             "needs at least two")
    elapsed = dataset.time_s - dataset.time_s[0]          # a logger's clock need not start at 0
    out = {"scenario": dataset.metadata.get("scenario"), "machine": dataset.metadata.get("machine"),
           "duration_h": float(elapsed[-1] / 3600.0), "samples": len(dataset),
           "run_seconds": None if wall_seconds is None else float(wall_seconds)}
    drift = {}
    for axis in dataset.names_of_kind("displacement"):
        v = change_since_start(dataset[axis])
        k = int(np.argmax(np.abs(v)))
        drift[axis] = {"peak_um": float(v[k]), "at_h": float(elapsed[k] / 3600.0), "range_um": float(np.ptp(v))}
    out["drift"] = drift
    surface = dataset.names_of_kind("temperature")
    if surface:
        rise = {n: float(dataset[n].max() - dataset[n][0]) for n in surface}
        hottest = max(surface, key=lambda n: dataset[n].max())
        out["hottest_sensor"] = {"name": hottest, "max_C": float(dataset[hottest].max()),
                                 "rise_K": rise[hottest]}
    out.update(_integration_checks(dataset.metadata))
    out.update(_iso230_3(dataset, drift, iso_test, probe_spacing_m))
    return out


def change_since_start(values: np.ndarray) -> np.ndarray:
    """A drift as ISO 230-3 takes it: the change since the first reading (a probe is seldom zeroed exactly).

    Parameters
    ----------
    values : ndarray
        Readings in time order (µm, or µrad for a tilt).

    Returns
    -------
    ndarray
        ``values − values[0]``, same unit.
    """
    values = np.asarray(values, float)
    return values - values[0]


def _integration_checks(meta):
    """The scheme, time step, step-error estimate and energy balance a run recorded in its metadata."""
    out = {}
    if meta.get("scheme"):
        out["time_integration"] = {"scheme": meta["scheme"], "time_step_s": meta.get("time_step_s"),
                                   "time_step_limit_s": meta.get("time_step_limit_s"),
                                   "step_error": meta.get("time_step_error")}
    if meta.get("energy_balance_relative_error") is not None:
        out["energy_balance_relative_error"] = meta["energy_balance_relative_error"]
    if meta.get("energy_balance"):
        out["energy_balance"] = meta["energy_balance"]
    return out


def _iso230_3(dataset, drift, iso_test, probe_spacing_m):
    """The ISO 230-3 quantities of an ETVE test (drift and ambient ranges) or a spindle test (drift, tilt)."""
    out = {}
    axes = [a for a in drift if a in ("X", "Y", "Z")]       # the ISO quantities are of the X/Y/Z drifts
    if iso_test == "etve":
        ambient = [n for n in dataset.names if n.startswith("ambient_") and dataset.info(n).unit == "degC"]
        if not ambient:
            raise TwinInputError(f"{dataset.metadata.get('source', 'the dataset')}: the ISO 230-3 ETVE summary needs "
                                 f"the room air: an ambient_<zone>_degC column; columns: {name_listing(dataset.names)}")
        out["iso230_3_etve"] = {
            "drift_range_um": {a: drift[a]["range_um"] for a in axes},
            "ambient_range_K": float(max(np.ptp(dataset[n]) for n in ambient)),
        }
    if iso_test == "spindle":
        tilt = change_since_start(tilt_urad(dataset, probe_spacing_m)) if "Y_top" in dataset else None
        out["iso230_3_spindle"] = {
            "max_abs_drift_um": {a: abs(drift[a]["peak_um"]) for a in axes},
            "max_abs_tilt_yz_urad": None if tilt is None else float(np.abs(tilt).max()),
        }
    return out


def format_summary(summary: dict) -> str:
    """The summary as Markdown.

    Parameters
    ----------
    summary : dict
        From :func:`run_summary`.

    Returns
    -------
    str
        Markdown with units in every line and table header.
    """
    on = f" on {summary['machine']}" if summary.get("machine") else ""
    lines = [f"# Run summary: {summary['scenario']}{on}", "",
             f"- duration: {summary['duration_h']:.2f} h, {summary['samples']} samples",
             ] + ([f"- run time: {summary['run_seconds']:.1f} s (wall clock, simulation only)"]
                  if summary["run_seconds"] is not None else [])
    if "hottest_sensor" in summary:
        h = summary["hottest_sensor"]
        lines.append(f"- hottest sensor: {h['name']} at {h['max_C']:.2f} °C ({h['rise_K']:+.2f} K since the first "
                     "sample)")
    if "time_integration" in summary:
        lines.append(_time_integration_line(summary["time_integration"]))
    if "energy_balance" in summary:
        lines.append(_energy_line(summary["energy_balance"]))
    elif "energy_balance_relative_error" in summary:
        lines.append(f"- energy balance (stored vs in − out), max relative error: "
                     f"{summary['energy_balance_relative_error']:.1e}")
    drift = [(axis, d["peak_um"], d["at_h"], d["range_um"]) for axis, d in summary["drift"].items()]
    lines += ["", markdown_table(drift, ["channel", "peak drift since start (µm)", "at (h)", "range (µm)"],
                                 formats=[None, ".2f", ".2f", ".2f"]) if drift else "- no drift channel (µm)"]
    if "iso230_3_etve" in summary:
        e = summary["iso230_3_etve"]
        lines += ["", "## ISO 230-3 ETVE", "",
                  f"- ambient range: {e['ambient_range_K']:.2f} K",
                  *[f"- maximum drift range {a}: {v:.2f} µm" for a, v in e["drift_range_um"].items()]]
    if "iso230_3_spindle" in summary:
        s = summary["iso230_3_spindle"]
        lines += ["", "## ISO 230-3 spindle thermal distortion", "",
                  *[f"- maximum |drift| {a}: {v:.2f} µm" for a, v in s["max_abs_drift_um"].items()],
                  f"- maximum |tilt| in YZ: {s['max_abs_tilt_yz_urad']:.1f} µrad (µm/m)"
                  if s["max_abs_tilt_yz_urad"] is not None else "- tilt in YZ: not measured (no Y_top probe)"]
    return "\n".join(lines) + "\n"


def _time_integration_line(info):
    """The scheme and step, and the estimated time-step error when the run estimated it."""
    order = {"backward Euler": "first order", "Crank-Nicolson": "second order"}.get(info["scheme"], "")
    step = f", {info['time_step_s']:g} s steps" if info.get("time_step_s") else ""
    limit = info.get("time_step_limit_s")
    if step and limit and limit != info["time_step_s"]:
        step += f" (time_step_s = {limit:g} s is a limit: each sampling interval is split into equal steps)"
    line = f"- time integration: {info['scheme']}{f' ({order})' if order else ''}{step}"
    error = info.get("step_error")
    if error:
        parts = [f"{error[key]:.2g} {unit}" for key, unit in (("temperature_K", "K"), ("displacement_um", "µm"),
                                                             ("strain_ue", "µε")) if key in error]
        line += f"; estimated time-step error (step doubling) up to {', '.join(parts)}"
    return line


def _energy_line(balance):
    """The energy balance, against the loads and against what the scenario asks of the heat sources."""
    scale, moved = balance["throughput_J"], balance.get("loads_gross_J")
    basis = (f"the {scale:.3g} J through the loads" if moved is None or moved >= scale else
             f"{scale:.3g} J, the energy of {ENERGY_FLOOR_K * 1e3:g} mK over the whole machine (the loads moved only "
             f"{moved:.2g} J)")
    line = f"- energy balance: error {balance['stored_vs_loads']:.1e} of {basis}"
    if balance.get("sources_vs_scenario") is not None:
        line += (f"; heat sources injected {balance['sources_injected_J']:.4g} J of the "
                 f"{balance['sources_requested_J']:.4g} J the scenario asks for "
                 f"(error {balance['sources_vs_scenario']:.1e})")
    if not balance["ok"]:
        line += (f" — **FAILED** (tolerance {balance['tolerance']:.0e}): heat was lost or created, "
                 "the results are not to be trusted")
    return line
