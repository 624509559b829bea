"""Which part's temperature error explains the drift error, and which sensor would separate two effects.

Drift outputs are linear functionals of the temperature field: d = G (T − T_ref)
with G the adjoint influence rows over thermal nodes.  Splitting the sum over
the nodes of each region (part) attributes a drift change to the parts:

- :func:`region_estimate` (model-free, from the residuals alone): a
  temperature error that is uniform in each part, c_r(t), is estimated by
  ridge-regularised least squares from the thermometer residuals (each
  thermometer sees its part's c_r) and the drift residuals (Σ_r g_{a,r} c_r,
  g_{a,r} = G_a · 1_r, the drift of axis a per kelvin of part r); part r then
  explains g_{a,r} c_r(t) of axis a.  A few drift lines spread over many parts
  without thermometers do not determine every part's c_r: the **resolution** of
  a part, the diagonal of the model-resolution matrix
  (AᵀA + ridge·I/prior²)⁻¹ AᵀA of this linear inverse problem, says how much
  of the part's estimate the data decide (1) rather than the prior (0).  Only
  parts resolved at :data:`RESOLVED` are a location; the unresolved parts'
  shares are given as one combined share per line.
- :func:`effect_attribution` (through the fitted winner): the winner's
  temperature change δT(t) = V δz(t) from the reduced basis is split exactly,
  G_a δT = Σ_r G_{a,r} δT; what is left of the winner's drift change is the
  sensor model (fixture drift).
- :func:`separating_sensor`: the signatures of two fitted effects at candidate
  thermometer locations (surface nodes, farthest-point sampled) — the point
  where they differ most is where a new thermometer would separate them.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp

from .fit import Coordinates, Evaluator, FitResult, Residual
from .model import GapModel, output_effects
from .structure import Structure, facet_table, point_info

#: Smallest resolution (diagonal of the model-resolution matrix, dimensionless) of a part whose estimated
#: temperature error is read as a location.  At 0.5 the data weigh as much as the prior in the part's estimate
#: (one isolated part: data precision = prior precision); k parts the sensors see only in one fixed combination
#: share a resolution of at most 1/k each, so a pair the data cannot tell apart is never resolved.
RESOLVED = 0.5


def _drift_rows(structure, names):
    """Indices (into the structure's channels) of the drift/strain channels among ``names``."""
    return [structure.index[n] for n in names if structure.kinds[structure.index[n]] in ("displacement", "strain")]


def region_influence(structure: Structure, channel_rows: Sequence[int]) -> np.ndarray:
    """g (len(rows), n_regions): drift per kelvin of uniform warming of each region (channel units per K).

    Parameters
    ----------
    structure : Structure
        Gives the output matrix (FE channels, channel units) and the region of every node.
    channel_rows : sequence of int
        Rows of the structure's FE channels (drift or strain lines).

    Returns
    -------
    ndarray, shape (len(channel_rows), n_regions)
        Channel change per kelvin of each region of :attr:`Structure.region_names` (µm/K, µε/K).
    """
    regions = structure.region_names
    C = structure.output_matrix
    g = np.zeros((len(channel_rows), len(regions)))
    for k, r in enumerate(regions):
        ind = (structure.node_region == r).astype(float)
        g[:, k] = C[channel_rows] @ ind
    return g


def _observation_rows(structure, evaluator, residual, names, t_cols, d_cols, part_of):
    """``(rows, rhs, influence)`` of the region least squares: one row per thermometer (its part) and per drift
    or strain line (its region influence), each divided by its channel's σ; ``rhs`` holds the residual series
    (n_rows × n_times) and ``influence`` the region influence of each drift or strain line."""
    regions = structure.region_names
    d_rows = [structure.index[names[j]] for j in d_cols]
    g = region_influence(structure, d_rows) if d_rows else np.zeros((0, len(regions)))
    R = np.nan_to_num(residual.R)
    sig_T = evaluator.sigma.get("temperature", 0.1)
    rows, rhs = [], []
    for j in t_cols:
        a = np.zeros(len(regions))
        a[regions.index(part_of[names[j]])] = 1.0 / sig_T
        rows.append(a)
        rhs.append(R[:, j] / sig_T)
    for k, j in enumerate(d_cols):
        sig = evaluator.sigma.get("displacement", 1.0) if evaluator.kinds[j] == "displacement" else \
            evaluator.sigma.get("strain", 1.0)
        rows.append(g[k] / sig)
        rhs.append(R[:, j] / sig)
    return rows, rhs, g


def _drift_shares(c, g, R, names, d_cols, regions):
    """Per drift or strain line and region: the share of the line's residual its region temperature explains."""
    shares = {}
    for k, j in enumerate(d_cols):
        r = R[:, j]
        denom = max(float(r @ r), 1e-300)
        contrib = c * g[k]
        shares[names[j]] = {reg: {"share": float(contrib[:, i] @ r / denom),
                                  "rms": float(np.sqrt(np.mean(contrib[:, i] ** 2)))}
                            for i, reg in enumerate(regions)}
    return shares


def _resolution(A, lhs, regions):
    """``(resolution, sd_K)`` per region: the diagonal of the model-resolution matrix lhs⁻¹ AᵀA (dimensionless,
    in [0, 1]) and the posterior sd sqrt(diag lhs⁻¹), K (the rows of ``A`` are divided by σ, so lhs is in 1/K²)."""
    cov = np.linalg.inv(lhs)
    res = np.clip(np.diag(cov @ (A.T @ A)), 0.0, 1.0)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return dict(zip(regions, res.tolist())), dict(zip(regions, sd.tolist()))


def _unresolved_share(shares, resolved):
    """Per drift or strain line: the summed share of the regions not in ``resolved`` (dimensionless)."""
    return {line: float(sum(v["share"] for reg, v in per.items() if reg not in resolved))
            for line, per in shares.items()}


def region_estimate(structure: Structure, evaluator: Evaluator, residual: Residual, names: Sequence[str],
                    ridge: float = 1.0) -> dict[str, object] | None:
    """Model-free attribution (see the module docstring) → dict with c_r(t), per-axis shares, resolution and influence.

    Parameters
    ----------
    structure : Structure
        Gives the regions, the thermometers' parts and the region influence.
    evaluator : Evaluator
        With weights set (``sigma`` per group, channel units); its channels are ``names``.
    residual : Residual
        Residuals ``R`` (n_times, p) in channel units (K, µm, µε), e.g. of the nominal twin.
    names : sequence of str, length p
        Channel names of the evaluator's columns.
    ridge : float, default 1.0
        Ridge weight (dimensionless): the prior sd of c_r is the thermometers' residual RMS (at least 0.05 K)
        divided by √ridge.

    Returns
    -------
    dict or None
        ``regions`` (list of str); ``c`` ndarray, shape (n_times, n_regions), the uniform temperature error
        per region, K; ``rms_K`` per region, K; ``shares`` per drift/strain line and region: ``share`` of the
        line's residual (dimensionless) and ``rms`` (channel units); ``observed_regions`` (regions with a
        thermometer); ``resolution`` per region (dimensionless, 0–1: the diagonal of the model-resolution matrix,
        1 = the data decide the region's error, 0 = only the prior); ``sd_K`` per region, the posterior sd of
        c_r, K (the prior sd where nothing sees the region); ``resolved`` (sorted regions with resolution ≥
        :data:`RESOLVED`); ``unresolved_share`` per line, the summed share of the other regions
        (dimensionless); ``influence`` per line and region (channel units per K); ``units`` per line.  None
        when there is neither a thermometer nor a drift or strain line.
    """
    regions = structure.region_names
    info = structure.thermometer_info()
    part_of = dict(zip([structure.names[i] for i in structure.thermometers], info["part"]))
    t_cols = [j for j, n in enumerate(names) if n in part_of]
    d_cols = [j for j, n in enumerate(names) if evaluator.kinds[j] in ("displacement", "strain")]
    rows, rhs, g = _observation_rows(structure, evaluator, residual, names, t_cols, d_cols, part_of)
    if not rows:
        return None
    A = np.array(rows)
    R = np.nan_to_num(residual.R)
    prior = max(float(np.sqrt(np.mean(R[:, t_cols] ** 2))) if t_cols else 0.0, 0.05)
    lhs = A.T @ A + ridge * np.eye(len(regions)) / prior ** 2
    c = np.linalg.solve(lhs, A.T @ np.array(rhs)).T            # (n_times, n_regions)
    resolution, sd = _resolution(A, lhs, regions)
    resolved = sorted(r for r in regions if resolution[r] >= RESOLVED)
    shares = _drift_shares(c, g, R, names, d_cols, regions)
    return {"regions": regions, "c": c, "rms_K": {reg: float(np.sqrt(np.mean(c[:, i] ** 2)))
                                                  for i, reg in enumerate(regions)},
            "shares": shares, "observed_regions": sorted({part_of[names[j]] for j in t_cols}),
            "resolution": resolution, "sd_K": sd, "resolved": resolved,
            "unresolved_share": _unresolved_share(shares, set(resolved)),
            "influence": {names[j]: dict(zip(regions, g[k].tolist())) for k, j in enumerate(d_cols)},
            "units": {names[j]: "µm" if evaluator.kinds[j] == "displacement" else "µε" for j in d_cols}}


def effect_attribution(model: GapModel, result: FitResult, nominal: FitResult,
                       names: Sequence[str]) -> dict[str, object] | None:
    """Split the winner's drift change over the parts through the reduced basis (see the module docstring).

    Parameters
    ----------
    model : GapModel
        The diagnosis model; its backend must keep its reduced basis.
    result : FitResult
        The winner (its prediction with the reduced run).
    nominal : FitResult
        The nominal twin (its prediction with the reduced run).
    names : sequence of str
        Channel names; the drift and strain lines among them are attributed.

    Returns
    -------
    dict or None
        ``shares``: per drift/strain line, per region and ``sensor/fixture`` (the sensor models' part),
        ``share`` of the line's change (dimensionless) and ``rms`` (channel units: µm, µε) at the measured
        times; ``field_time_s``, s: the grid time of the largest change; ``field``: ndarray, shape (n_nodes,),
        the temperature change at that time, K.  None without a basis, a reduced run or a drift/strain line.
    """
    backend = model.backend
    if getattr(backend, "basis", None) is None or result.prediction is None or result.prediction.run is None:
        return None
    s = model.structure
    d_rows = _drift_rows(s, names)
    if not d_rows:
        return None
    regions = s.region_names
    run_w, run_n = result.prediction.run, nominal.prediction.run
    dZ = run_w.W @ run_w.Q.T - run_n.W @ run_n.Q.T             # (N, r) change of reduced state
    C = s.output_matrix[d_rows]
    out = {}
    total_field = np.zeros((len(dZ), len(d_rows)))
    parts = {}
    for r in regions:
        ind = sp.diags((s.node_region == r).astype(float))
        Gr = backend.reduce_rows(C @ ind)                       # (k, r)
        part = dZ @ Gr.T
        parts[r] = model.interp(part)
        total_field += part
    change = result.prediction.values[:, d_rows] - nominal.prediction.values[:, d_rows]
    sensor_part = change - model.interp(total_field)
    for k, row in enumerate(d_rows):
        name = s.names[row]
        c = change[:, k]
        denom = max(float(c @ c), 1e-300)
        entry = {r: {"share": float(parts[r][:, k] @ c / denom), "rms": float(np.sqrt(np.mean(parts[r][:, k] ** 2)))}
                 for r in regions}
        entry["sensor/fixture"] = {"share": float(sensor_part[:, k] @ c / denom),
                                   "rms": float(np.sqrt(np.mean(sensor_part[:, k] ** 2)))}
        out[name] = entry
    k_star = int(np.argmax(np.abs(total_field).max(axis=1)))
    field = backend.basis @ dZ[k_star]
    return {"shares": out, "field_time_s": float(model.drive.grid[k_star]), "field": field}


def candidate_points(structure: Structure, count: int = 300, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Candidate thermometer locations: outer-surface thermal nodes, farthest-point sampled → (nodes, points).

    Parameters
    ----------
    structure : Structure
        Gives the machine; nodes of convection facets other than inside ones and the floor are candidates.
    count : int, default 300
        Number of points (at most the number of candidate nodes).
    seed : int, default 0
        Seed of the random first point.

    Returns
    -------
    nodes : ndarray of int, shape (k,)
        Thermal node ids.
    points : ndarray, shape (k, 3)
        Their positions, m.
    """
    machine = structure.machine
    nodes, _, _, groups, _, _ = facet_table(machine)
    inside = {r.name for r in machine.definition.convection if r.inside or r.name == "floor"}
    keep = ~np.isin(groups, list(inside))
    cand = np.unique(nodes[keep].ravel())
    pts = machine.thermal.points[cand]
    rng = np.random.default_rng(seed)
    chosen = [int(rng.integers(len(cand)))]
    dist = np.linalg.norm(pts - pts[chosen[0]], axis=1)
    for _ in range(min(count, len(cand)) - 1):
        j = int(np.argmax(dist))
        chosen.append(j)
        dist = np.minimum(dist, np.linalg.norm(pts - pts[j], axis=1))
    return cand[chosen], pts[chosen]


def separating_sensor(model: GapModel, result_a: FitResult, result_b: FitResult, nominal: FitResult,
                      noise_K: float = 0.05, count: int = 300) -> dict[str, object] | None:
    """Where a new surface thermometer would tell effects A and B apart (dict), or None without a basis.

    Parameters
    ----------
    model : GapModel
        The diagnosis model; its backend must keep its reduced basis.  The candidate points are cached on it.
    result_a, result_b : FitResult
        The two fitted effects (predictions with their reduced runs).
    nominal : FitResult
        The nominal twin.
    noise_K : float, default 0.05
        Thermometer noise level, K (for ``difference_over_noise``; at least 1e-6).
    count : int, default 300
        Number of candidate points (:func:`candidate_points`).

    Returns
    -------
    dict or None
        ``a``, ``b`` (model names); the best candidate's ``position_m`` (m, rounded to mm), ``part``, ``zone``,
        ``difference_rms_K`` (RMS over the grid of the mean-free difference of the two effects' temperature
        changes, K) and ``difference_over_noise``; the ``nearest_sensor`` and its distance
        ``nearest_sensor_distance_m`` (m); the ``best_existing_sensor`` and its
        ``best_existing_difference_rms_K`` (K).
    """
    backend = model.backend
    if getattr(backend, "basis", None) is None:
        return None
    s = model.structure
    key = ("candidates", count)
    cache = getattr(model, "_candidate_cache", None)
    if cache is None or cache[0] != key:
        nodes, pts = candidate_points(s, count)

        info = point_info(s, pts)
        rows = backend.basis[nodes]                             # (k, r): one-hot node rows
        air = s.local_air_matrix(info["zone"], info["height"])
        model._candidate_cache = (key, (nodes, pts, info, rows, air))
    nodes, pts, info, rows, air = model._candidate_cache[1]

    def temps(result):
        run = result.prediction.run
        T = run.rows(rows)
        active = list(zip([_effect(model, n) for n in result.effects], _split(result, model)))
        U = result.prediction.inputs
        for e, th in output_effects(active):
            T = e.thermometer_change(th, T, U @ air.T, model.drive.step_s)
        return T

    base = temps(nominal)
    da = temps(result_a) - base
    db = temps(result_b) - base
    diff = (da - da.mean(axis=0)) - (db - db.mean(axis=0))
    score = np.sqrt(np.mean(diff ** 2, axis=0))
    j = int(np.argmax(score))
    therm = s.thermometer_info()
    near = int(np.argmin(np.linalg.norm(therm["position"] - pts[j], axis=1)))
    # the best existing thermometer, for comparison
    idx = s.thermometers
    ya = result_a.prediction.grid_values[:, idx] - nominal.prediction.grid_values[:, idx]
    yb = result_b.prediction.grid_values[:, idx] - nominal.prediction.grid_values[:, idx]
    dd = (ya - ya.mean(axis=0)) - (yb - yb.mean(axis=0))
    existing = np.sqrt(np.mean(dd ** 2, axis=0))
    e_best = int(np.argmax(existing))
    return {"a": result_a.name, "b": result_b.name,
            "position_m": [round(float(v), 3) for v in pts[j]], "part": str(info["part"][j]),
            "zone": str(info["zone"][j]), "difference_rms_K": float(score[j]),
            "difference_over_noise": float(score[j] / max(noise_K, 1e-6)),
            "nearest_sensor": s.names[idx[near]],
            "nearest_sensor_distance_m": float(np.linalg.norm(therm["position"][near] - pts[j])),
            "best_existing_sensor": s.names[idx[e_best]], "best_existing_difference_rms_K": float(existing[e_best])}


def _effect(model, name):
    return next(e for e in model.effects if e.name == name)


def _split(result, model):
    effects = [_effect(model, n) for n in result.effects]
    return [th for _, th in Coordinates(effects, model.structure.machine).split(result.values)]
