"""The verdict of a gap diagnosis: one of four outcomes, decided per channel group and per sensor.

Scales.  Every channel group g has a scale σ_g (:meth:`twin.gap.fit.Evaluator.set_weights`: the larger of its
noise level and the model tolerance), and every sensor j its own σ_j = max(noise_j, tolerance_g).  Both are
widened in quadrature by the *timing floor*: how far the nominal twin's held-out prediction moves when the
piecewise-constant inputs (spindle, feeds) are reconstructed with their change times at the earliest and at the
latest time the sampling allows (:func:`twin.gap.diagnose.reconstruct_inputs`).  A residual of that size is
what the record's sampling cannot resolve, so it is no evidence of an effect.  When the nominal twin has a gap,
σ_j is widened again by the sensor's *discretisation floor* (:mod:`twin.gap.discretisation`): how far its
held-out prediction moves on a coarser mesh, what the twin's own mesh cannot resolve there.

A *gap* is a held-out RMS above :data:`NOISE_FACTOR` × σ_g in some group, or above :data:`SENSOR_FACTOR` × σ_j
at some single sensor.  The sensor test keeps one thermometer with a 7× residual from being averaged away in a
group of 25.

A model (an effect or a pair) is *admissible* when it beats the nominal twin on held-out data by ΔBIC >
:data:`MIN_DELTA_BIC`, removes a material share (in some group, or at some sensor that has a gap, at least one
σ² of held-out mean square *and* at least :data:`MIN_MATERIAL_SHARE` of what is there: one σ² is nothing at a
sensor 15 σ off) and makes no group worse (its held-out mean square may not grow by more than
:data:`MAX_WORSENING` σ_g²): a model that degrades a group cannot be the explanation, however much it helps
another.

Outcomes (:data:`OUTCOMES`):

``no_significant_gap``  the nominal twin leaves no gap.
``explained``           an admissible model leaves no gap in any group and at any sensor.
``partly_explained``    an admissible model, but a gap remains (where, when and in which band is reported).
``not_explained``       a gap, and no admissible model in the library.

Evidence is ΔBIC and its log10 Bayes-factor equivalent ΔBIC / (2 ln 10): no exponential, no overflow.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .fit import GROUP_FLOOR, Evaluator, FitResult

if TYPE_CHECKING:
    from .diagnose import Diagnosis

OUTCOMES = ("no_significant_gap", "explained", "partly_explained", "not_explained")
MIN_DELTA_BIC = 10.0
MIN_MATERIAL = 1.0
MIN_MATERIAL_SHARE = 0.1
NOISE_FACTOR = 2.0
SENSOR_FACTOR = 4.0
MAX_WORSENING = 0.1


@dataclass
class Scales:
    """σ per channel group and per sensor (channel units), the timing floor included (module docstring)."""

    group: dict
    sensor: dict
    timing_group: dict = field(default_factory=dict)
    timing_sensor: dict = field(default_factory=dict)
    discretisation_sensor: dict = field(default_factory=dict)


def scales(evaluator: Evaluator, names: Sequence[str], timing: np.ndarray | None = None,
           discretisation: np.ndarray | None = None) -> Scales:
    """:class:`Scales` of an evaluator with weights set; ``timing`` (p,) is the per-sensor timing floor or None.

    Parameters
    ----------
    evaluator : Evaluator
        With weights set (its ``sigma`` per group and ``noise`` per channel, channel units).
    names : sequence of str, length p
        Names of the evaluator's channels.
    timing : ndarray, shape (p,), optional
        Per-sensor timing floor, channel units (K, µm, µε); NaN counts as 0, None as 0 everywhere.
    discretisation : ndarray, shape (p,), optional
        Per-sensor discretisation floor, channel units; widens σ_j only (NaN or None as 0).

    Returns
    -------
    Scales
        σ_g widened in quadrature by the timing floor, σ_j by the timing and discretisation floors, and the
        floors themselves (timing per group: their RMS; discretisation per sensor, only when given).
    """
    noise = np.nan_to_num(evaluator.noise)
    timing = np.zeros(len(names)) if timing is None else np.nan_to_num(np.asarray(timing, float))
    mesh = np.zeros(len(names)) if discretisation is None else np.nan_to_num(np.asarray(discretisation, float))
    sensor, t_sensor, group, t_group = {}, {}, {}, {}
    for g, idx in evaluator.groups().items():
        t_group[g] = float(np.sqrt(np.mean(timing[idx] ** 2)))
        group[g] = float(np.hypot(evaluator.sigma[g], t_group[g]))
        for j in idx:
            t_sensor[names[j]] = float(timing[j])
            sensor[names[j]] = float(np.linalg.norm([max(noise[j], GROUP_FLOOR[g]), timing[j], mesh[j]]))
    d_sensor = {} if discretisation is None else {n: float(v) for n, v in zip(names, mesh, strict=True)}
    return Scales(group, sensor, t_group, t_sensor, d_sensor)


def group_ratios(result: FitResult, sc: Scales) -> dict[str, float]:
    """Held-out RMS / σ_g per channel group.

    Parameters
    ----------
    result : FitResult
        A fitted model (or the nominal twin).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    dict of str to float
        Group → ratio (dimensionless).
    """
    return {g: result.summary["groups"][g]["hold_rms"] / s for g, s in sc.group.items()}


def sensor_ratios(result: FitResult, sc: Scales) -> dict[str, float]:
    """Held-out RMS / σ_j per sensor.

    Parameters
    ----------
    result : FitResult
        A fitted model (or the nominal twin).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    dict of str to float
        Sensor name → ratio (dimensionless; NaN without held-out samples).
    """
    return {n: result.summary["channels"][n]["hold_rms"] / s for n, s in sc.sensor.items()}


def flagged_sensors(result: FitResult, sc: Scales) -> list[tuple[str, float]]:
    """Sensors whose held-out RMS exceeds :data:`SENSOR_FACTOR` × σ_j, worst first: [(name, ratio)].

    Parameters
    ----------
    result : FitResult
        A fitted model (or the nominal twin).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    list of (str, float)
        Sensor name and held-out RMS / σ_j, by decreasing ratio.
    """
    r = sensor_ratios(result, sc)
    return sorted([(n, v) for n, v in r.items() if np.isfinite(v) and v > SENSOR_FACTOR], key=lambda p: -p[1])


def leaves_a_gap(result: FitResult, sc: Scales) -> bool:
    """True when some group exceeds :data:`NOISE_FACTOR` × σ_g or some sensor :data:`SENSOR_FACTOR` × σ_j.

    Parameters
    ----------
    result : FitResult
        A fitted model (or the nominal twin).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    bool
        Whether its held-out residual leaves a gap.
    """
    return worst(group_ratios(result, sc).values()) > NOISE_FACTOR or bool(flagged_sensors(result, sc))


def worst(ratios: Iterable[float]) -> float:
    """The largest finite ratio, NaN if none is finite.

    A group without a finite held-out residual (its channels missing there) says nothing; Python's ``max``
    would let it hide the others or not depending on the order.

    Parameters
    ----------
    ratios : iterable of float
        Held-out RMS / σ per group or sensor.

    Returns
    -------
    float
        The largest finite one, or NaN.
    """
    finite = [float(v) for v in ratios if np.isfinite(v)]
    return max(finite) if finite else float("nan")


def worsened_groups(result: FitResult, reference: FitResult, sc: Scales) -> list[str]:
    """Groups whose held-out mean square grows by more than :data:`MAX_WORSENING` σ_g² against ``reference``.

    Parameters
    ----------
    result : FitResult
        The model judged.
    reference : FitResult
        The model it is compared with (the nominal twin, or a single effect of a pair).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    list of str
        The worsened groups (groups with a non-finite RMS are skipped).
    """
    out = []
    for g, s in sc.group.items():
        a = reference.summary["groups"][g]["hold_rms"]
        b = result.summary["groups"][g]["hold_rms"]
        if np.isfinite(a) and np.isfinite(b) and (b * b - a * a) / s ** 2 > MAX_WORSENING:
            out.append(g)
    return out


def materiality(result: FitResult, reference: FitResult, sc: Scales) -> float:
    """max of (RMS_ref² − RMS²) / σ² over the groups and over the sensors with a gap in ``reference``.

    A group or sensor counts only where the model removes at least :data:`MIN_MATERIAL_SHARE` of the reference's
    held-out mean square there.

    Parameters
    ----------
    result : FitResult
        The model judged.
    reference : FitResult
        The model it is compared with.
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    float
        Held-out mean square removed, in units of σ² (dimensionless); −inf when nothing is comparable.
    """
    pairs = [(reference.summary["groups"][g]["hold_rms"], result.summary["groups"][g]["hold_rms"], s)
             for g, s in sc.group.items()]
    pairs += [(reference.summary["channels"][n]["hold_rms"], result.summary["channels"][n]["hold_rms"],
               sc.sensor[n]) for n, _ in flagged_sensors(reference, sc)]
    removed = [(a * a - b * b) / s ** 2 for a, b, s in pairs
               if np.isfinite(a) and np.isfinite(b) and a > 0 and a * a - b * b >= MIN_MATERIAL_SHARE * a * a]
    return float(max(removed, default=-np.inf))


def admissible(result: FitResult, reference: FitResult, sc: Scales) -> bool:
    """True when ``result`` beats ``reference`` by ΔBIC, materially, and worsens no group (module docstring).

    Parameters
    ----------
    result : FitResult
        The model judged.
    reference : FitResult
        The model it must beat.
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    bool
        ΔBIC > :data:`MIN_DELTA_BIC`, materiality ≥ :data:`MIN_MATERIAL` and no worsened group.
    """
    return (result.delta_bic - reference.delta_bic > MIN_DELTA_BIC
            and materiality(result, reference, sc) >= MIN_MATERIAL
            and not worsened_groups(result, reference, sc))


def parsimonious(ranking: Sequence[FitResult], nominal: FitResult, sc: Scales) -> FitResult | None:
    """The best admissible model; a pair only when each of its single effects leaves a gap and the pair is
    admissible against it (an effect is added only while a gap remains).  None when nothing is admissible.

    Parameters
    ----------
    ranking : sequence of FitResult
        Single-effect and pair fits, best first.
    nominal : FitResult
        The nominal twin.
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    FitResult or None
        The first admissible fit of ``ranking`` that passes the pair rule.
    """
    by_name = {r.name: r for r in ranking}
    for r in ranking:
        if not admissible(r, nominal, sc):
            continue
        singles = [by_name[e] for e in r.effects if e in by_name]
        if len(r.effects) == 1 or all(leaves_a_gap(s, sc) and admissible(r, s, sc) for s in singles):
            return r
    return None


def log10_evidence(delta_bic: float) -> float:
    """log10 of the Bayes-factor equivalent exp(ΔBIC / 2) of a ΔBIC (no overflow).

    Parameters
    ----------
    delta_bic : float
        ΔBIC.

    Returns
    -------
    float
        ΔBIC / (2 ln 10).
    """
    return float(delta_bic) / (2.0 * np.log(10.0))


def reductions(result: FitResult | None, nominal: FitResult) -> dict[str, dict[str, float]]:
    """Held-out RMS before and after per group: {group: {nominal_rms, fitted_rms, reduction}}.

    Parameters
    ----------
    result : FitResult or None
        The fitted model; None gives the nominal RMS as the fitted one (no reduction).
    nominal : FitResult
        The nominal twin.

    Returns
    -------
    dict of str to dict of str to float
        Group → ``nominal_rms`` and ``fitted_rms`` (channel units: K, µm, µε) and ``reduction``
        1 − fitted / nominal (dimensionless; NaN when the nominal RMS is 0).
    """
    out = {}
    for g, b in nominal.summary["groups"].items():
        a = result.summary["groups"][g]["hold_rms"] if result is not None else b["hold_rms"]
        out[g] = {"nominal_rms": b["hold_rms"], "fitted_rms": a,
                  "reduction": 1.0 - a / b["hold_rms"] if b["hold_rms"] > 0 else float("nan")}
    return out


@dataclass
class Verdict:
    """The decision (module docstring): outcome, the model it names (or None) and the figures behind it."""

    outcome: str
    winner: object
    best: object
    runner_up: object
    nominal_gap: dict
    nominal_flagged: list
    remaining_gap: dict
    remaining_flagged: list
    worsened: list
    material: float
    displaced: dict | None = None    # the library model the discovery displaced (:func:`displace`)

    @property
    def significant(self) -> bool:
        """True when a model is named (the outcome is ``explained`` or ``partly_explained``)."""
        return self.winner is not None

    def evidence(self) -> dict[str, str | float | None]:
        """ΔBIC of the named (else best) model vs the nominal and vs the runner-up, with log10 equivalents.

        Returns
        -------
        dict
            ``model`` (its name or None); with a model ``delta_bic_vs_nominal`` and ``log10_ratio_vs_nominal``;
            with a runner-up also ``runner_up``, ``delta_bic_vs_runner_up`` and ``log10_ratio_vs_runner_up``.
        """
        model = self.winner or self.best
        out = {"model": model.name if model is not None else None}
        if model is not None:
            out.update(delta_bic_vs_nominal=model.delta_bic, log10_ratio_vs_nominal=log10_evidence(model.delta_bic))
        if model is not None and self.runner_up is not None:
            dbic = self.runner_up.bic - model.bic
            out.update(runner_up=self.runner_up.name, delta_bic_vs_runner_up=dbic,
                       log10_ratio_vs_runner_up=log10_evidence(dbic))
        return out


def _outcome(nominal, ranking, sc):
    """``(winner or None, outcome)``: no gap, or the parsimonious admissible model and whether it leaves a gap."""
    if not leaves_a_gap(nominal, sc):
        return None, "no_significant_gap"
    winner = parsimonious(ranking, nominal, sc)
    if winner is None:
        return None, "not_explained"
    return winner, "partly_explained" if leaves_a_gap(winner, sc) else "explained"


def _runner_up(ranking, winner, best):
    """The best single-effect fit sharing no effect with the winner; without a winner, the best after ``best``."""
    if winner is not None:
        others = [r for r in ranking if not set(r.effects) & set(winner.effects) and len(r.effects) == 1]
    else:
        others = [r for r in ranking if r is not best]
    return others[0] if others else None


def _checks_after(model, nominal, sc):
    """``(group ratios, flagged sensors, worsened groups, materiality)`` of ``model`` (empty when None)."""
    if model is None:
        return {}, [], [], float("nan")
    return (group_ratios(model, sc), flagged_sensors(model, sc), worsened_groups(model, nominal, sc),
            materiality(model, nominal, sc))


def decide(nominal: FitResult, ranking: Sequence[FitResult], sc: Scales) -> Verdict:
    """:class:`Verdict` from the nominal result and the ranked fits (see the module docstring).

    Parameters
    ----------
    nominal : FitResult
        The nominal twin.
    ranking : sequence of FitResult
        Single-effect and pair fits, best first (may be empty).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    Verdict
        The outcome, the named model, the best fit, the runner-up and the checks behind them.
    """
    best = ranking[0] if ranking else None
    winner, outcome = _outcome(nominal, ranking, sc)
    return Verdict(outcome, winner, best, _runner_up(ranking, winner, best), group_ratios(nominal, sc),
                   flagged_sensors(nominal, sc), *_checks_after(winner or best, nominal, sc))


# ============================================================================= written forms

def displace(v: Verdict, by: str, delta_bic: float) -> None:
    """The named model gives way to effects found beyond the library (in place): the outcome becomes
    ``not_explained`` and the model stays the best candidate, with the reason.

    Called when the discovery on the *nominal* twin's residual fits the held-out record better (by ``delta_bic``,
    with every parameter counted) than the named model with the discovery on what it leaves: the library model
    then stands in for an effect it does not have (e.g. a spindle-power scale for a source on the ram), and
    "partly explained by it" would be a confident wrong answer.

    Parameters
    ----------
    v : Verdict
        A decision with a named model.
    by : str
        What displaced it, in words.
    delta_bic : float
        Held-out BIC of the named model with its discovery minus that of the nominal twin with its own.
    """
    v.displaced = {"model": v.winner.name, "by": by, "delta_bic": float(delta_bic)}
    v.best, v.winner, v.outcome = v.winner, None, "not_explained"


def role(d: Diagnosis, result: FitResult) -> str:
    """What the verdict makes of a ranked model: ``named``, ``displaced by the discovery`` or ``""``.

    Parameters
    ----------
    d : Diagnosis
        With its decision made.
    result : FitResult
        One of its ranked models.

    Returns
    -------
    str
        The role in words (empty for any other model).
    """
    if result is d.winner:
        return "named"
    return "displaced by the discovery" if d.decision.displaced and result is d.decision.best else ""


def parameters(result: FitResult | None) -> list[dict[str, str | float | list[float]]]:
    """Fitted parameters with 90 % intervals: [{name, value, interval90: [lo, hi], unit}].

    Parameters
    ----------
    result : FitResult or None
        A fitted model; None gives an empty list.

    Returns
    -------
    list of dict
        One per parameter, with its 90 % interval (:func:`~twin.gap.fit.interval90`), in its ``unit``.
    """
    if result is None:
        return []
    return [{"name": p["name"], "value": p["value"], "interval90": p["interval"], "unit": p["unit"]}
            for p in result.params()]


def flagged_table(d: Diagnosis) -> list[dict[str, str | float]]:
    """Sensors with a gap before or after the named (else best) model, worst first.

    Parameters
    ----------
    d : Diagnosis
        The diagnosis (its scales, decision, nominal and winner fits, evaluator and channel names).

    Returns
    -------
    list of dict
        ``name``, ``kind``, ``unit``, ``scale`` (σ_j) and ``nominal_rms`` (held-out, in ``unit``), and
        ``fitted_rms`` when a model is named.
    """
    sc, model = d.scales, d.winner or d.decision.best
    before = dict(flagged_sensors(d.nominal, sc))
    after = dict(flagged_sensors(model, sc)) if model is not None else {}
    out = []
    for n in sorted(set(before) | set(after), key=lambda n: -max(before.get(n, 0), after.get(n, 0))):
        kind = d.evaluator.kinds[d.names.index(n)]
        row = {"name": n, "kind": kind, "unit": UNIT[kind], "scale": sc.sensor[n],
               "nominal_rms": d.nominal.summary["channels"][n]["hold_rms"]}
        if d.winner is not None:
            row["fitted_rms"] = d.winner.summary["channels"][n]["hold_rms"]
        out.append(row)
    return out


UNIT = {"temperature": "K", "air": "K", "displacement": "µm", "strain": "µε"}


def _remainder(d):
    """Where, when and in which band the named model's worst remaining group or sensor misses."""
    model = d.winner
    groups = group_ratios(model, d.scales)
    g = max(groups, key=lambda k: groups[k] if np.isfinite(groups[k]) else -np.inf)
    parts = [f"{g} {groups[g]:.1f} × σ_g"]
    flagged = flagged_sensors(model, d.scales)
    if flagged:
        parts.append("sensors " + ", ".join(f"{n} {v:.1f} × σ" for n, v in flagged[:4]))
    for key, label in (("phases_after", "worst phase"), ("bands_after", "worst band")):
        table = d.where.get(key) or {}
        vals = {k: e.get(g) for k, e in table.items() if e.get(g) is not None and np.isfinite(e.get(g))}
        if vals:
            k = max(vals, key=vals.get)
            parts.append(f"{label} {k} ({vals[k]:.3g} {UNIT[g]})")
    return "; ".join(parts)


def _change(e):
    """A group's held-out change in words: "-70 %", or "no change" / "—" where the nominal RMS is 0 (no ratio)."""
    if np.isfinite(e["reduction"]):
        return f"{-100 * e['reduction']:+.0f} %"
    return "no change" if e["fitted_rms"] == e["nominal_rms"] else "—"


def _held_out_line(d, model):
    out = []
    for g, e in reductions(model, d.nominal).items():
        out.append(f"{g} {e['nominal_rms']:.3g} → {e['fitted_rms']:.3g} {UNIT[g]} ({_change(e)})")
    return "held-out RMS " + ", ".join(out)


def _no_gap_text(d):
    """The verdict when the nominal twin leaves no significant gap."""
    worst_sensor = worst(sensor_ratios(d.nominal, d.scales).values())
    text = ("no significant gap: the nominal twin's held-out residual is within noise, tolerance and timing "
            f"floor in every channel group (at most {worst(d.decision.nominal_gap.values()):.1f} × σ_g) and at every "
            f"sensor (at most {worst_sensor:.1f} × σ_j)")
    limited = mesh_limited(d.nominal, d.scales)
    if limited:
        text += ("; within the twin's discretisation floor only (the twin's mesh cannot tell a gap of that size "
                 "there): " + ", ".join(f"{n} ({d.scales.discretisation_sensor[n]:.3g})" for n in limited))
    return text


def mesh_limited(result: FitResult, sc: Scales) -> list[str]:
    """Sensors whose held-out RMS is a gap against σ_j without the discretisation floor, and none with it.

    Parameters
    ----------
    result : FitResult
        A fitted model (or the nominal twin).
    sc : Scales
        σ per group and per sensor, channel units.

    Returns
    -------
    list of str
        Sensor names, in channel order.
    """
    out = []
    for n, floor in sc.discretisation_sensor.items():
        rms, sigma = result.summary["channels"][n]["hold_rms"], sc.sensor[n]
        without = np.sqrt(max(sigma ** 2 - floor ** 2, 0.0))
        if SENSOR_FACTOR * without < rms <= SENSOR_FACTOR * sigma:
            out.append(n)
    return out


def _rejection_reasons(v, resolved=True):
    """Why the best candidate was not named: its ΔBIC, materiality or the groups it worsens (``resolved``: whether
    a displacing discovery has an atom whose 90 % interval excludes 0)."""
    why = []
    if v.best.delta_bic <= MIN_DELTA_BIC:
        why.append(f"ΔBIC {v.best.delta_bic:.1f} ≤ {MIN_DELTA_BIC:g}")
    if not np.isfinite(v.material):
        why.append("it removes no material share of the held-out gap in any group or flagged sensor")
    elif v.material < MIN_MATERIAL:
        why.append(f"materiality {v.material:.2f} < {MIN_MATERIAL:g}")
    if v.worsened:
        why.append(f"worsens {', '.join(v.worsened)}")
    if v.displaced and resolved:
        why.append(f"displaced by {v.displaced['by']}: they fit the held-out record better without it "
                   f"(ΔBIC {v.displaced['delta_bic']:.1f})")
    elif v.displaced:
        why.append("displaced: atoms fitted beyond the library on the nominal twin's residual fit the held-out record "
                   f"better without it (ΔBIC {v.displaced['delta_bic']:.1f}), though none of them is resolved")
    return "; ".join(why) or "its pair rule"


def _not_explained_text(v, resolved=True):
    """The verdict when no library model is admissible (``resolved`` as for :func:`_rejection_reasons`)."""
    text = (f"gap not explained by the library: nominal held-out residual up to "
            f"{worst(v.nominal_gap.values()):.1f} × σ_g "
            f"({', '.join(f'{g} {r:.1f}' if np.isfinite(r) else f'{g} —' for g, r in v.nominal_gap.items())})")
    if v.nominal_flagged:
        text += "; sensors " + ", ".join(f"{n} {r:.1f} × σ" for n, r in v.nominal_flagged[:4])
    if v.best is not None:
        text += f"; best candidate {v.best.name} rejected ({_rejection_reasons(v, resolved)})"
    return text


def _explained_text(d):
    """The verdict when a library model is named: its values, held-out change, evidence and any remainder."""
    v = d.decision
    ev = v.evidence()
    values = ", ".join(f"{p['name']} = {p['value']:.3g} (90 %: {p['interval90'][0]:.3g} … "
                       f"{p['interval90'][1]:.3g}) {p['unit']}" for p in parameters(v.winner))
    head = "gap explained by" if v.outcome == "explained" else "gap partly explained by"
    text = f"{head} {v.winner.name} ({values}); {_held_out_line(d, v.winner)}"
    text += f"; ΔBIC {ev['delta_bic_vs_nominal']:.1f} vs nominal"
    if "runner_up" in ev:
        text += (f", {ev['delta_bic_vs_runner_up']:.1f} vs the runner-up {ev['runner_up']} "
                 f"(log10 evidence ratio {ev['log10_ratio_vs_runner_up']:.1f})")
    if v.outcome == "partly_explained":
        text += f"; what remains: {_remainder(d)}"
    return text


def air_assumptions(d: Diagnosis, lagged: bool = True) -> list[str]:
    """What the twin assumed for the convection zones without an air sensor, in words.

    A scenario (``--scenario``) supplies the ambient of the room zone only; every other zone without an air
    sensor is taken as the room air (through its lag, if it has one) — e.g. a front zone whose door opens in the
    scenario does not get those openings.

    Parameters
    ----------
    d : Diagnosis
        Its record's air sensors (their zones) and its model's measured drive (zones, room zone, lags in s, and
        the scenario's room ambient, °C, when the room has no air sensor).
    lagged : bool, default True
        Include the zones the machine models as the room air through a lag (the enclosure): that is its model of
        them, not an assumption about missing data; the verdict sentence leaves them out.

    Returns
    -------
    list of str
        One phrase per zone without an air sensor (empty without a measured drive).
    """
    drive = getattr(d.model, "drive", None)
    if not hasattr(drive, "zones") or not hasattr(drive, "room_zone"):
        return []
    sensed = {zone for _, zone, *_ in d.record.air}
    room, out = drive.room_zone, []
    if room not in sensed:
        source = ("the scenario's ambient" if getattr(drive, "fallback_room", None) is not None
                  else "the mean of all air sensors")
        out.append(f"room zone {room!r} (no air sensor) taken as {source}")
    for z in drive.zones:
        lag = drive.lags_s.get(z)
        if z != room and z not in sensed and (lagged or not lag):
            out.append(f"zone {z!r} (no air sensor) taken as the room air"
                       + (f" through a {lag / 3600:g} h lag" if lag else ""))
    return out


def sentence(d: Diagnosis) -> str:
    """The one-paragraph verdict of a :class:`~twin.gap.diagnose.Diagnosis`.

    Parameters
    ----------
    d : Diagnosis
        With its decision (and discovery, if any) made.

    Returns
    -------
    str
        The verdict text; whatever its kind, it ends with ``assumed: …`` when the twin took inputs the record
        lacks (feeds not measured, zones without an air sensor).
    """
    text = _no_gap_text(d) if d.decision.outcome == "no_significant_gap" else _gap_text(d)
    unknown = getattr(d, "unknown_inputs", None)
    # every kind says what was assumed: feeds taken as 0 can hide a gap as well as make one
    assumed = _assumptions(d, lagged=False)
    return (_unit_warning(d) + (unknown.sentence(d.record.time_s) if unknown is not None else "") + text
            + ("; assumed: " + ", ".join(assumed) if assumed else ""))


def _gap_text(d):
    """The verdict of a gap: explained or not, and what was discovered beyond the library."""
    found = d.discovery is not None and bool(getattr(d.discovery, "items", None))
    resolved = [x.sentence() for x in d.discovery.resolved()] if found else []
    text = (_not_explained_text(d.decision, bool(resolved)) if d.decision.outcome == "not_explained"
            else _explained_text(d))
    if resolved:
        text += "; discovered beyond the library: " + "; ".join(resolved)
    if found and len(resolved) < len(d.discovery.items):
        unresolved = d.discovery.unresolved()
        text += ("; " + ("" if resolved else "nothing beyond the library was resolved: ")
                 + "not resolved (90 % interval includes 0): " + "; ".join(x.sentence() for x in unresolved))
    return text


def _assumptions(d, lagged=True):
    """What the twin took for the inputs the record lacks: feeds (the record's import report) and air
    (:func:`air_assumptions`)."""
    return [*(getattr(d.record, "report", None) or {}).get("assumed_inputs", []), *air_assumptions(d, lagged)]


def _unit_warning(d):
    """What opens a verdict on a record with a column suspected of another unit (not in the notes alone: a
    spindle in krpm made the discovery report a 1e5 W source with an interval), else ''."""
    suspects = (getattr(d.record, "report", None) or {}).get("unit_suspects") or []
    if not suspects:
        return ""
    return (f"UNIT SUSPECTED: {', '.join(repr(c) for c in suspects)} may be in another unit than its header says "
            "(see the notes); every figure below takes the header's unit: ")


def to_json(d: Diagnosis) -> dict[str, object]:
    """The machine-readable verdict block of ``diagnosis.json``.

    Parameters
    ----------
    d : Diagnosis
        With its decision and verdict text made.

    Returns
    -------
    dict
        Strict-JSON-able (:func:`strict_json`: null for a figure that does not exist, e.g. the reduction of a group
        whose nominal RMS is 0): ``outcome``, ``explanation``, ``model``, ``parameters``, ``discoveries`` (the
        atoms whose 90 % interval excludes 0), ``not_resolved`` (the accepted atoms whose interval includes 0),
        ``assumptions`` (:func:`air_assumptions`), ``held_out`` (per group: RMS in ``unit``, σ_g ``scale`` and
        ``timing_floor``), ``flagged_sensors`` and ``evidence``.
    """
    v = d.decision
    model = v.winner
    held = reductions(model, d.nominal)
    found = d.discovery.as_dict()["items"] if d.discovery is not None else []
    for g, e in held.items():
        e["unit"] = UNIT[g]
        e["scale"] = d.scales.group[g]
        e["timing_floor"] = d.scales.timing_group[g]
    return strict_json({
        "outcome": v.outcome, "explanation": d.verdict, "model": model.name if model is not None else None,
        "parameters": parameters(model), "discoveries": [x for x in found if x["resolved"]],
        "not_resolved": [x for x in found if not x["resolved"]],
        "assumptions": _assumptions(d),
        "held_out": held, "flagged_sensors": flagged_table(d),
        "inputs_unknown": d.unknown_inputs.as_dict() if getattr(d, "unknown_inputs", None) is not None else None,
        "evidence": {**v.evidence(), "worsened_groups": v.worsened, "displaced": v.displaced,
                     "materiality": v.material, "nominal_gap_over_scale": v.nominal_gap,
                     "remaining_gap_over_scale": v.remaining_gap}})


def strict_json(value: object) -> object:
    """``value`` with every non-finite number (NaN, ±inf) replaced by None, recursively, for strict JSON.

    ``json.dumps`` writes NaN and Infinity by default, which strict parsers reject; numpy arrays and scalars
    become lists and Python numbers on the way.

    Parameters
    ----------
    value : object
        Dicts, lists, tuples, numbers, numpy arrays and scalars, or anything else (returned as it is).

    Returns
    -------
    object
        The same structure, ``null`` (None) where a number was not finite.
    """
    if isinstance(value, dict):
        return {k: strict_json(x) for k, x in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(x) for x in value]
    if isinstance(value, np.ndarray):
        return strict_json(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value
