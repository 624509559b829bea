"""Compensation studies on twin data: transfer across operating conditions, the thesis protocol, hybrid models.

- :func:`cross_condition_study` — the lesson of seed 003 (models trained on one
  condition do not transfer): train on one scenario family, test on every
  other; a transfer matrix per axis (Markdown + PNG heat map).
- :func:`thesis_protocol_study` — train on the heating/cooling Test IV, test on
  Tests I, II, III, V and VI (thesis §5).
- :func:`hybrid_study` — grey-box compensation: the nominal twin predicts the
  drift from the measured spindle speed and ambient, a data-driven model learns
  the twin's residual from the measured temperatures; compared with pure
  physics and pure data-driven on the same held-out records.  The "measured"
  records come from a *perturbed* twin (scaled source powers and convection,
  sensor noise), the physics model is the nominal twin: a known sim-to-real gap.

All simulations are independent tasks of :func:`twin.infra.sweep.run_tasks`.
Inputs and targets are zero-referenced per record (see :mod:`twin.compensation.store`).
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from models import select_sensors

from ..core.dataset import ChannelInfo, Dataset, json_default
from ..core.scenario import available_scenarios
from ..core.simulate import simulate
from ..errors import TwinInputError
from ..infra.outdir import atomic_directory, check_output_folder
from ..infra.sweep import run_tasks
from ..placement.study import MachineSpec, _scenario_obj, _zero_ref
from .store import dataset_label, fit_compensation_model
from .train import format_table, physics_prediction, score

#: Scenario families of the cross-condition study: the first available scenario of each is used.
FAMILIES = {
    "soft cutting": ("cutting_soft",),
    "hard cutting": ("cutting_hard",),
    "spindle heat/cool": ("heat_cool_9000", "iso230_3_spindle", "iso230_3_spindle_short"),
    "ETVE": ("iso230_3_etve", "etve_5K", "etve_summer"),
    "step speed": ("step_speed",),
}
THESIS_TRAIN = "thesis_test_4"
THESIS_TEST = ("thesis_test_1", "thesis_test_2", "thesis_test_3", "thesis_test_5", "thesis_test_6")
INSTRUMENT_NOISE = {"temperature": "DS18S20", "displacement": "NCDT", "strain": "FBG", "camera": "none"}
#: The sim-to-real gap of the hybrid study: what the "real" machine has that the nominal twin does not.
DEFAULT_GAP = {"source_scale": (("front_bearings", 1.3), ("rear_bearings", 1.2), ("spindle_motor", 0.8),
                                ("xy_drives", 1.2)),
               "convection_scale": 0.8}
HYBRID_TRAIN = ("thesis_test_4", "heat_cool_9000", "step_speed", "etve_5K")
HYBRID_TEST = ("thesis_test_3", "cutting_hard", "iso230_3_spindle_spectrum", "etve_summer")


@dataclass(frozen=True)
class SimulateTask:
    """A picklable sweep task: one scenario on a (possibly perturbed) machine → a Dataset."""

    machine: MachineSpec
    scenario: object
    noise: bool = True
    instrument_noise: bool = True     # force the thesis instruments' noise even if the scenario has none
    seed: int | None = None

    def __call__(self):
        sc = _scenario_obj(self.scenario)
        if self.noise and self.instrument_noise:
            sc = replace(sc, noise={**INSTRUMENT_NOISE, **{k: v for k, v in sc.noise.items() if v != "none"}})
        sc = replace(sc, record_camera=False)
        ds = simulate(sc, self.machine.build(), noise=self.noise, seed=self.seed).dataset
        if self.machine.perturbed:
            ds.metadata["effects"] = [{"kind": "perturbed twin", "source_scale": self.machine.source_scale,
                                       "convection_scale": self.machine.convection_scale}]
        return ds


@dataclass(frozen=True)
class PhysicsTask:
    """A picklable sweep task: the nominal twin's drift prediction for a record."""

    machine: MachineSpec
    dataset: object
    outputs: tuple = ("Z", "Y")
    backend: str = "fe"

    def __call__(self):
        return physics_prediction(self.machine.build(), self.dataset, self.outputs, self.backend)


def _available(names):
    known = set(available_scenarios())
    return [n for n in names if n in known or Path(str(n)).exists()]


def simulate_many(scenarios, machine=MachineSpec(), scheduler="local", noise=True, progress=None):
    machine.build()       # mesh and operator caches ready before the workers start (none meshes twice)

    return run_tasks([SimulateTask(machine, s, noise) for s in scenarios], scheduler=scheduler, progress=progress)


def installed_thermometers(dataset):
    return dataset.names_of_kind("temperature")


def select_inputs(datasets, target, k=4, method="gm-influence+fcm", candidates=None, random_state=0):
    """Choose ``k`` input channels for ``target`` on training datasets by a seed method (zero-referenced)."""
    candidates = candidates or installed_thermometers(datasets[0])
    X = np.vstack([_zero_ref(d.matrix(candidates)) for d in datasets])
    y = np.concatenate([d[target] - d[target][0] for d in datasets])
    sel = select_sensors(X, y, method=method, n_select=min(k, len(candidates)), random_state=random_state)
    return [candidates[i] for i in sel.indices]


# ----------------------------------------------------------------------------- cross-condition
@dataclass
class StudyResult:
    name: str
    out_dir: Path | None
    tables: dict = field(default_factory=dict)     # name → list of row dicts
    markdown: str = ""
    data: dict = field(default_factory=dict)


def cross_condition_study(families=None, axes=("Z", "Y"), model="mlr", inputs=None, k=4,
                          select_method="gm-influence+fcm", machine="vmc_ram", mesh_size_m=None,
                          scheduler="local", out_dir=None, params=None, progress=None, log=print, overwrite=False):
    """Train on one scenario family, test on the others; the transfer matrix per axis.

    ``inputs``: fixed input channels, or None to choose ``k`` of the installed
    thermometers on each training family with ``select_method`` (as a user
    would on their one training condition).  Cells are the held-out max
    |residual|, RMSE and improvement %; the diagonal is the training fit.
    ``out_dir`` is checked before the work (``overwrite``: see :func:`twin.infra.outdir.check_output_folder`).
    """
    check_output_folder(out_dir, overwrite, inputs=(machine,))
    families = dict(families or FAMILIES)
    chosen = {}
    for fam, names in families.items():
        avail = _available(names)
        if avail:
            chosen[fam] = avail[0]
        elif log:
            log(f"family {fam!r}: none of {list(names)} is available, left out")
    if len(chosen) < 2:
        raise TwinInputError(f"the cross-condition study needs ≥ 2 families with an available scenario; "
                             f"have {chosen}")
    spec = MachineSpec(machine, mesh_size_m)
    data = dict(zip(chosen, simulate_many(list(chosen.values()), spec, scheduler, progress=progress)))
    rows, matrices, used_inputs = [], {}, {}
    for axis in axes:
        M = np.full((len(data), len(data)), np.nan)
        for i, (train_fam, train_ds) in enumerate(data.items()):
            ins = list(inputs) if inputs else select_inputs([train_ds], axis, k, select_method)
            used_inputs[(train_fam, axis)] = ins
            cm = fit_compensation_model([train_ds], ins, axis, model, params)
            for j, (test_fam, test_ds) in enumerate(data.items()):
                s = score(cm.target_values(test_ds), cm.predict(test_ds))
                M[i, j] = s["improvement_percent"]
                rows.append({"axis": axis, "train": train_fam, "test": test_fam, "rmse": s["rmse"],
                             "max_residual": s["max_residual"], "improvement_percent": s["improvement_percent"],
                             "uncompensated_max": s["uncompensated_max"], "inputs": " ".join(ins)})
        matrices[axis] = M
    fams = list(data)
    md = [f"# Cross-condition transfer ({model}, inputs: "
          f"{'fixed ' + ', '.join(inputs) if inputs else f'{k} installed thermometers chosen by {select_method} on the training family'})",
          "", "Scenarios: " + ", ".join(f"{f} = `{s}`" for f, s in chosen.items()) + ".",
          "Rows: trained on; columns: tested on. Cell: improvement % = (1 − max|residual| / max|drift change|) × 100 "
          "(max |residual| in µm in brackets); the diagonal is the training fit.", ""]
    for axis in axes:
        md += [f"## {axis}", "", "| train \\ test | " + " | ".join(fams) + " |", "|---|" + "---|" * len(fams)]
        for i, f in enumerate(fams):
            cells = []
            for j, g in enumerate(fams):
                r = next(r for r in rows if r["axis"] == axis and r["train"] == f and r["test"] == g)
                cells.append(f"{r['improvement_percent']:.0f} % ({r['max_residual']:.1f})")
            md.append(f"| **{f}** | " + " | ".join(cells) + " |")
        off = [matrices[axis][i, j] for i in range(len(fams)) for j in range(len(fams)) if i != j]
        diag = [matrices[axis][i, i] for i in range(len(fams))]
        md += ["", f"Mean improvement: on the training family {np.mean(diag):.0f} %, on other families "
               f"{np.mean(off):.0f} % (median {np.median(off):.0f} %).", ""]
        md.append("Inputs per training family: " + "; ".join(f"{f}: {', '.join(used_inputs[(f, axis)])}"
                                                               for f in fams) + "\n")
    result = StudyResult("cross-condition", None, {"transfer": rows}, "\n".join(md) + "\n",
                         {"families": chosen, "matrices": {a: m.tolist() for a, m in matrices.items()}})
    if out_dir is not None:
        _write(result, out_dir, overwrite,
               lambda tmp: _heatmaps(matrices, fams, axes, tmp / "transfer_matrix.png", model))
    return result


def _heatmaps(matrices, labels, axes, path, model):
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


def _write(result, out_dir, overwrite, extra=None):
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


# ----------------------------------------------------------------------------- thesis protocol
def thesis_protocol_study(axes=("Z", "Y"), models=("anfis", "mlr"), inputs=None, k=4,
                          select_method="gm-influence+fcm", machine="vmc_ram", mesh_size_m=None,
                          scheduler="local", out_dir=None, progress=None, log=print, overwrite=False):
    """Train on Test IV, test on Tests I, II, III, V, VI (thesis §5): a table per axis and model."""
    check_output_folder(out_dir, overwrite, inputs=(machine,))
    tests = _available(THESIS_TEST)
    if not _available([THESIS_TRAIN]) or not tests:
        raise TwinInputError(f"the thesis protocol needs {THESIS_TRAIN} and some of {list(THESIS_TEST)}")
    if log and len(tests) < len(THESIS_TEST):
        log(f"missing thesis tests left out: {sorted(set(THESIS_TEST) - set(tests))}")
    spec = MachineSpec(machine, mesh_size_m)
    sims = simulate_many([THESIS_TRAIN] + tests, spec, scheduler, progress=progress)
    train_ds, test_ds = sims[0], sims[1:]
    rows, plots = [], {}
    for axis in axes:
        ins = list(inputs) if inputs else select_inputs([train_ds], axis, k, select_method)
        for model in models:
            cm = fit_compensation_model([train_ds], ins, axis, model)
            for ds in [train_ds] + test_ds:
                y, p = cm.target_values(ds), cm.predict(ds)
                s = score(y, p)
                rows.append({"axis": axis, "model": model, "dataset": dataset_label(ds),
                             "role": "training" if ds is train_ds else "test", "rmse": s["rmse"], "nse": s["nse"],
                             "max_residual": s["max_residual"], "improvement_percent": s["improvement_percent"],
                             "uncompensated_max": s["uncompensated_max"], "inputs": " ".join(ins)})
                plots[(axis, model, dataset_label(ds))] = (ds.time_s, y, p)
    md = ["# Thesis protocol: train on Test IV, test on Tests I, II, III, V, VI", "",
          f"Inputs: {'fixed ' + ', '.join(inputs) if inputs else f'{k} installed thermometers chosen by {select_method} on Test IV'}; "
          "metrics on the change since the start of each test (µm).", ""]
    cols = ["dataset", "role", "rmse", "nse", "max_residual", "improvement_percent", "uncompensated_max"]
    for axis in axes:
        for model in models:
            sub = [r for r in rows if r["axis"] == axis and r["model"] == model]
            md += [f"## {axis}, {model} (inputs {sub[0]['inputs']})", "", format_table(sub, cols)]
    result = StudyResult("thesis-protocol", None, {"thesis_protocol": rows}, "\n".join(md) + "\n")
    if out_dir is not None:
        def figs(tmp):
            from ..infra.plots import plot_measured_vs_predicted  # on use: it switches matplotlib to Agg

            for (axis, model, label), (t, y, p) in plots.items():
                plot_measured_vs_predicted(t, y, p, "um", f"{axis} on {label} ({model}, trained on Test IV)",
                                           tmp / f"{label}_{axis}_{model}.png")
        _write(result, out_dir, overwrite, figs)
    return result


# ----------------------------------------------------------------------------- hybrid
def hybrid_study(train=HYBRID_TRAIN, test=HYBRID_TEST, axes=("Z", "Y"), model="anfis", inputs=None, k=4,
                 select_method="gm-influence+fcm", gap=None, machine="vmc_ram", mesh_size_m=None,
                 physics_backend="fe", scheduler="local", out_dir=None, progress=None, log=print, overwrite=False):
    """Pure physics vs pure data-driven vs hybrid (physics + learned residual) on held-out records.

    "Measured" records: the twin with ``gap`` (default :data:`DEFAULT_GAP`:
    bearing and drive powers ±20–30 %, convection −20 %) and instrument noise.
    Physics: the nominal twin driven by the records' spindle speed, feeds and
    ambient (:func:`twin.compensation.train.physics_prediction`), started at rest.
    Data-driven: ``model`` on ``k`` thermometers (chosen on the training records).
    Hybrid: the same ``model`` and inputs fitted to the physics residual
    (measured − physics change); prediction = physics + learned residual.
    """
    check_output_folder(out_dir, overwrite, inputs=(machine,))

    gap = dict(DEFAULT_GAP if gap is None else gap)
    train, test = _available(train), _available(test)
    if not train or not test:
        raise TwinInputError(f"the hybrid study needs training and held-out scenarios; have {train}, {test}")
    truth = MachineSpec(machine, mesh_size_m, gap.get("source_scale", 1.0), gap.get("convection_scale", 1.0))
    nominal = MachineSpec(machine, mesh_size_m)
    t0 = time.perf_counter()
    nominal.build()
    truth.build()
    measured = run_tasks([SimulateTask(truth, s) for s in list(train) + list(test)], scheduler=scheduler,
                         progress=progress)
    physics = run_tasks([PhysicsTask(nominal, ds, tuple(axes), physics_backend) for ds in measured],
                        scheduler=scheduler, progress=progress)
    sim_s = time.perf_counter() - t0
    tr, te = list(range(len(train))), list(range(len(train), len(measured)))
    rows, curves, used = [], {}, {}
    for axis in axes:
        ins = list(inputs) if inputs else select_inputs([measured[i] for i in tr], axis, k, select_method)
        used[axis] = ins
        data_model = fit_compensation_model([measured[i] for i in tr], ins, axis, model)
        # residual datasets: the target replaced by measured − physics (both zero-referenced)
        resid = [_with_residual(ds, axis, phys[axis]) for ds, phys in zip(measured, physics)]
        hybrid_model = fit_compensation_model([resid[i] for i in tr], ins, f"{axis}_residual", model)
        for i in tr + te:
            ds = measured[i]
            y = ds[axis] - ds[axis][0]
            p_phys = physics[i][axis] - physics[i][axis][0]
            p_data = data_model.predict(ds)
            p_hyb = p_phys + hybrid_model.predict(resid[i])
            for name, p in (("physics (nominal twin)", p_phys), (f"data-driven ({model})", p_data),
                            (f"hybrid (twin + {model} residual)", p_hyb)):
                s = score(y, p)
                rows.append({"axis": axis, "approach": name, "dataset": dataset_label(ds),
                             "role": "training" if i in tr else "held-out", "rmse": s["rmse"],
                             "max_residual": s["max_residual"], "improvement_percent": s["improvement_percent"],
                             "uncompensated_max": s["uncompensated_max"]})
            curves[(axis, dataset_label(ds))] = (ds.time_s, y, p_phys, p_data, p_hyb)
    pooled = []
    for axis in axes:
        for approach in dict.fromkeys(r["approach"] for r in rows if r["axis"] == axis):
            sub = [r for r in rows if r["axis"] == axis and r["approach"] == approach and r["role"] == "held-out"]
            ys = np.concatenate([curves[(axis, r["dataset"])][1] for r in sub])
            k_ = {"physics": 2, "data-driven": 3, "hybrid": 4}[approach.split(" ")[0]]
            ps = np.concatenate([curves[(axis, r["dataset"])][k_] for r in sub])
            s = score(ys, ps)
            pooled.append({"axis": axis, "approach": approach, "rmse": s["rmse"], "max_residual": s["max_residual"],
                           "improvement_percent": s["improvement_percent"], "uncompensated_max": s["uncompensated_max"]})
    scale = gap.get("source_scale", 1.0)
    powers = (", ".join(f"{n} ×{f:g}" for n, f in scale) if isinstance(scale, (tuple, list))
              else f"every source ×{float(scale):g}")
    md = ["# Hybrid grey-box compensation vs pure physics vs pure data-driven", "",
          f"\"Measured\" records are made by a perturbed twin — source powers {powers}, every convection "
          f"coefficient ×{gap.get('convection_scale', 1.0):g} — with instrument noise (DS18S20, NCDT). The physics "
          f"model is the *nominal* twin driven by the records' spindle speed, feeds and ambient "
          f"({physics_backend.upper()} backend), started at rest. Data-driven and the residual model of the hybrid: "
          f"{model} on {k} thermometers chosen on the training records ({select_method}); the hybrid predicts "
          "physics + the learned residual (measured − physics)."]
    md += ["", f"Training records: {', '.join(train)}; held-out: {', '.join(test)}.", "",
           "## Held-out, pooled (µm)", "",
           format_table(pooled, ["axis", "approach", "rmse", "max_residual", "improvement_percent",
                                 "uncompensated_max"]),
           "## Per record (µm)", "",
           format_table(rows, ["axis", "approach", "dataset", "role", "rmse", "max_residual",
                               "improvement_percent"]),
           "Inputs: " + "; ".join(f"{a}: {', '.join(v)}" for a, v in used.items()), ""]
    result = StudyResult("hybrid", None, {"hybrid": rows, "hybrid_pooled": pooled}, "\n".join(md) + "\n",
                         {"gap": gap, "train": train, "test": test, "inputs": used, "simulation_s": sim_s})
    if out_dir is not None:
        _write(result, out_dir, overwrite,
               lambda tmp: _hybrid_plots(curves, te_labels=[dataset_label(measured[i]) for i in te], axes=axes,
                                         path=tmp / "hybrid_heldout.png"))
    return result


def _with_residual(ds, axis, physics_abs):
    r = (ds[axis] - ds[axis][0]) - (physics_abs - physics_abs[0])
    return Dataset(ds.time_s, np.column_stack([ds.values, r]),
                   ds.channels + [ChannelInfo(f"{axis}_residual", ds.info(axis).unit, "displacement")], ds.metadata)


def _hybrid_plots(curves, te_labels, axes, path):
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
