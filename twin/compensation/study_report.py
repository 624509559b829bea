"""Reports of the compensation studies: their Markdown texts, figures and result folders."""
from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core.dataset import json_default
from ..infra.outdir import atomic_directory
from ..infra.tables import markdown_table
from .train import format_table


@dataclass
class StudyResult:
    """A study's tables (name → list of row dicts), its Markdown report, further data and its folder.

    Attributes
    ----------
    name : str
        The study (``cross-condition``, ``thesis-protocol``, ``hybrid``); names its files.
    out_dir : Path or None
        Its folder, once written.
    tables : dict of str to list of dict
        Table name → rows (one CSV each).
    markdown : str
        The report.
    data : dict
        Further JSON-ready results (matrices, chosen scenarios, inputs).
    """

    name: str
    out_dir: Path | None
    tables: dict = field(default_factory=dict)
    markdown: str = ""
    data: dict = field(default_factory=dict)


def write_study(result: StudyResult, out_dir: Path | str, overwrite: bool = False,
                extra: Callable[[Path], None] | None = None) -> None:
    """Write ``<name>.md``, one CSV per table and ``<name>.json`` atomically; ``extra(folder)`` adds figures.

    Parameters
    ----------
    result : StudyResult
        The study; its ``out_dir`` is set on success.
    out_dir : Path or str
        The folder (see :func:`twin.infra.outdir.atomic_directory`).
    overwrite : bool, default False
        Write into a non-empty folder that is not a twin output.
    extra : callable, optional
        ``extra(temporary folder)`` writes the figures.
    """
    import pandas as pd

    with atomic_directory(out_dir, overwrite) as tmp:
        (tmp / f"{result.name}.md").write_text(result.markdown, encoding="utf-8")
        for name, rows in result.tables.items():
            pd.DataFrame(rows).to_csv(tmp / f"{name}.csv", index=False)
        (tmp / f"{result.name}.json").write_text(json.dumps({"tables": result.tables, "data": result.data},
                                                            indent=1, default=json_default))
        if extra is not None:
            extra(tmp)
    result.out_dir = Path(out_dir)


def _inputs_text(inputs, k, select_method, where, counts=()):
    """The header's account of the inputs; ``counts``: how many were chosen on each training set."""
    if inputs:
        return "fixed " + ", ".join(inputs)
    return f"{k} installed thermometers chosen by {select_method} {where}{_fewer_text(k, counts)}"


def _fewer_text(k, counts):
    """`` (only n move there: that many chosen)`` when some count of chosen inputs is below ``k``, else ``""``.

    A thermometer that never moves on a training record is no candidate, so fewer than ``k`` may be chosen there:
    the report says so rather than claim ``k``.
    """
    fewer = sorted({n for n in counts if n < k})
    return f" (only {' or '.join(map(str, fewer))} move there: that many chosen)" if fewer else ""


# ----------------------------------------------------------------------------- cross-condition
def cross_condition_markdown(rows: list[dict], matrices: dict, chosen: dict, used_inputs: dict, axes: tuple,
                             model: str, inputs: Sequence[str] | None, k: int, select_method: str) -> str:
    """The transfer report: per axis a train × test table of improvement % (max |residual| in µm).

    Parameters
    ----------
    rows : list of dict
        One per (axis, training family, test family): ``improvement_percent`` and ``max_residual`` (µm).
    matrices : dict of str to ndarray
        Axis → transfer matrix of improvement % (training family × test family).
    chosen : dict of str to str
        Family → its scenario.
    used_inputs : dict
        (family, axis) → the input channels used.
    axes : tuple of str
        Drift axes.
    model : str
        Model name.
    inputs : sequence of str or None
        Fixed inputs, or None when they were chosen per family.
    k, select_method
        How many inputs were chosen, and by which method.

    Returns
    -------
    str
        Markdown, ending with a newline.
    """
    fams = list(chosen)
    md = [f"# Cross-condition transfer ({model}, inputs: "
          f"{_inputs_text(inputs, k, select_method, 'on the training family', map(len, used_inputs.values()))})",
          "", "Scenarios: " + ", ".join(f"{f} = `{s}`" for f, s in chosen.items()) + ".",
          "Rows: trained on; columns: tested on. Cell: improvement % = (1 − max|residual| / max|drift change|) × 100 "
          "(max |residual| in µm in brackets); the diagonal is the training fit.", ""]
    cell = {(r["axis"], r["train"], r["test"]): f"{r['improvement_percent']:.0f} % ({r['max_residual']:.1f})"
            for r in rows}
    for axis in axes:
        table = [[f"**{f}**"] + [cell[(axis, f, g)] for g in fams] for f in fams]
        md += [f"## {axis}", "", markdown_table(table, ["train \\ test", *fams])]
        M = matrices[axis]
        off = M[~np.eye(len(fams), dtype=bool)]
        md += ["", f"Mean improvement: on the training family {np.mean(np.diag(M)):.0f} %, on other families "
               f"{np.mean(off):.0f} % (median {np.median(off):.0f} %).", ""]
        md.append("Inputs per training family: " + "; ".join(f"{f}: {', '.join(used_inputs[(f, axis)])}"
                                                               for f in fams) + "\n")
    return "\n".join(md) + "\n"


def plot_transfer(matrices: dict, labels: list[str], axes: tuple, path: Path, model: str) -> None:
    """Heat maps of the transfer matrices (improvement %, clipped to ±100) side by side.

    Parameters
    ----------
    matrices : dict of str to ndarray
        Axis → transfer matrix of improvement %.
    labels : list of str
        Family names, in matrix order.
    axes : tuple of str
        Drift axes, one panel each.
    path : Path
        The PNG to write.
    model : str
        Model name, in the titles.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, len(axes), figsize=(5.8 * len(axes), 5), squeeze=False)
    for a, axis in enumerate(axes):
        M = matrices[axis]
        shown = np.clip(M, -100, 100)
        im = ax[0, a].imshow(shown, cmap="RdYlGn", vmin=-100, vmax=100)
        for i in range(M.shape[0]):
            for j in range(M.shape[1]):
                ax[0, a].text(j, i, f"{M[i, j]:.0f}", ha="center", va="center", fontsize=9)
        ax[0, a].set_xticks(range(len(labels)), labels, rotation=35, ha="right")
        ax[0, a].set_yticks(range(len(labels)), labels)
        ax[0, a].set_xlabel("tested on")
        ax[0, a].set_ylabel("trained on")
        ax[0, a].set_title(f"{axis}: improvement % ({model})")
        fig.colorbar(im, ax=ax[0, a], shrink=0.8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ----------------------------------------------------------------------------- thesis protocol
def thesis_markdown(rows: list[dict], axes: tuple, models: tuple, inputs: Sequence[str] | None, k: int,
                    select_method: str) -> str:
    """The thesis-protocol report: one table per axis and model (µm).

    Parameters
    ----------
    rows : list of dict
        One per (axis, model, record): ``rmse``, ``max_residual``, ``uncompensated_max`` (µm), ``nse``,
        ``improvement_percent`` (%), ``role``, ``inputs``.
    axes, models : tuple of str
        Drift axes and model names.
    inputs : sequence of str or None
        Fixed inputs, or None when they were chosen on Test IV.
    k, select_method
        How many inputs were chosen, and by which method.

    Returns
    -------
    str
        Markdown, ending with a newline.
    """
    md = ["# Thesis protocol: train on Test IV, test on Tests I, II, III, V, VI", "",
          f"Inputs: {_inputs_text(inputs, k, select_method, 'on Test IV', [len(r['inputs'].split()) for r in rows])}; "
          "metrics on the change since the start of each test (µm).", ""]
    cols = ["dataset", "role", "rmse", "nse", "max_residual", "improvement_percent", "uncompensated_max"]
    for axis in axes:
        for model in models:
            sub = [r for r in rows if r["axis"] == axis and r["model"] == model]
            md += [f"## {axis}, {model} (inputs {sub[0]['inputs']})", "", format_table(sub, cols)]
    return "\n".join(md) + "\n"


def plot_thesis(plots: dict, folder: Path) -> None:
    """Measured vs predicted per (axis, model, test): ``<test>_<axis>_<model>.png``.

    Parameters
    ----------
    plots : dict
        (axis, model, record label) → (time_s, measured change, predicted change), µm.
    folder : Path
        Where the PNGs go.
    """
    from ..infra.plots import (
        plot_measured_vs_predicted,  # on use: it switches matplotlib to Agg
    )

    for (axis, model, label), (t, y, p) in plots.items():
        plot_measured_vs_predicted(t, y, p, "um", f"{axis} on {label} ({model}, trained on Test IV)",
                                   folder / f"{label}_{axis}_{model}.png")


# ----------------------------------------------------------------------------- hybrid
def hybrid_markdown(rows: list[dict], pooled: list[dict], gap: dict, train: list, test: list, used: dict,
                    model: str, k: int, select_method: str, physics_backend: str) -> str:
    """The hybrid report: the perturbation, pooled held-out scores and per-record scores (µm).

    Parameters
    ----------
    rows : list of dict
        One per (axis, approach, record): ``rmse``, ``max_residual`` (µm), ``improvement_percent``, ``role``.
    pooled : list of dict
        One per (axis, approach), pooled over the held-out records.
    gap : dict
        ``source_scale`` and ``convection_scale`` of the "measured" machine.
    train, test : list of str
        Training and held-out scenarios.
    used : dict of str to list of str
        Axis → input channels.
    model : str
        Model name.
    k, select_method
        How many inputs were chosen, and by which method.
    physics_backend : str
        ``fe`` or ``rom``.

    Returns
    -------
    str
        Markdown, ending with a newline.
    """
    scale = gap.get("source_scale", 1.0)
    powers = (", ".join(f"{n} ×{f:g}" for n, f in scale) if isinstance(scale, (tuple, list))
              else f"every source ×{float(scale):g}")
    md = ["# Hybrid grey-box compensation vs pure physics vs pure data-driven", "",
          f"\"Measured\" records are made by a perturbed twin — source powers {powers}, every convection "
          f"coefficient ×{gap.get('convection_scale', 1.0):g} — with instrument noise (DS18S20, NCDT). The physics "
          f"model is the *nominal* twin driven by the records' spindle speed, feeds and ambient "
          f"({physics_backend.upper()} backend), started at rest. Data-driven and the residual model of the hybrid: "
          f"{model} on {k} thermometers chosen on the training records ({select_method}){_fewer_text(k, map(len, used.values()))}; "
          "the hybrid predicts "
          "physics + the learned residual (measured − physics)."]
    md += ["", f"Training records: {', '.join(train)}; held-out: {', '.join(test)}.", "",
           "## Held-out, pooled (µm)", "",
           format_table(pooled, ["axis", "approach", "rmse", "max_residual", "improvement_percent",
                                 "uncompensated_max"]),
           "## Per record (µm)", "",
           format_table(rows, ["axis", "approach", "dataset", "role", "rmse", "max_residual",
                               "improvement_percent"]),
           "Inputs: " + "; ".join(f"{a}: {', '.join(v)}" for a, v in used.items()), ""]
    return "\n".join(md) + "\n"


def plot_hybrid(curves: dict, te_labels: list[str], axes: tuple, path: Path) -> None:
    """Measured, physics, data-driven and hybrid drift change (µm) over time (h) on every held-out record.

    Parameters
    ----------
    curves : dict
        (axis, record label) → (time_s, measured, physics, data-driven, hybrid), drift changes in µm.
    te_labels : list of str
        Held-out records, one row of panels each.
    axes : tuple of str
        Drift axes, one column each.
    path : Path
        The PNG to write.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(len(te_labels), len(axes), figsize=(6 * len(axes), 2.8 * len(te_labels)), squeeze=False)
    for i, label in enumerate(te_labels):
        for j, axis in enumerate(axes):
            t, y, pp, pd_, ph = curves[(axis, label)]
            a = ax[i, j]
            h = t / 3600
            a.plot(h, y, "k", lw=1.4, label="measured")
            a.plot(h, pp, lw=1, label="physics")
            a.plot(h, pd_, lw=1, label="data-driven")
            a.plot(h, ph, lw=1, ls="--", label="hybrid")
            a.set_title(f"{axis}, {label}", fontsize=9)
            a.set_ylabel("drift change (µm)")
            a.grid(alpha=0.3)
            if i == 0 and j == 0:
                a.legend(fontsize=7)
    for a in ax[-1]:
        a.set_xlabel("time (h)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
