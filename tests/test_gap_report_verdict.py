"""The written verdict of a gap diagnosis: discoveries whose 90 % interval includes 0 are not reported as found,
no NaN in the text or in ``diagnosis.json`` (strict JSON), the air assumptions and ``--scenario`` named as
they are, and the spindle reference speed of a discovered source given in rpm.

Fast: hand-made verdicts, discoveries and drives, no twin run.
"""
import argparse
import json
from types import SimpleNamespace

import numpy as np
import pytest

from twin.gap import verdict
from twin.gap.discovery import Discovery, DiscoveryResult
from twin.gap.fit import FitResult, Residual

NAN = float("nan")


def _result(name, groups, delta_bic=0.0, params=()):
    """A :class:`FitResult` with the given held-out RMS per group (no channels) and parameters."""
    summary = {"groups": {g: {"hold_rms": v} for g, v in groups.items()}, "channels": {}}
    r = FitResult(name, [name] if name != "nominal" else [], [], [], np.zeros(1), np.zeros(1),
                  Residual(np.zeros((1, 1)), np.zeros(1), {}, 0.0, 1.0), summary, 0.0, 0, True)
    r.delta_bic, r.bic = delta_bic, -delta_bic
    r.params = lambda: list(params)
    return r


def _alpha(lo=-0.0198, hi=0.0357):
    return Discovery("expansion", "alpha@ram", "expansion coefficient of the ram", 0.00791, "relative change", (lo, hi),
                     part="ram", delta_bic=12.0)


def _source(lo, hi, value=3.31):
    return Discovery("source", "source@ram", "heat source on the ram", value, "W", (lo, hi), part="ram",
                     position_m=(0.1, 0.2, 0.3), driver="spindle_on", delta_bic=15.0)


def _found(*items):
    return DiscoveryResult(list(items), {}, "nominal", 100, 1.0)


def _diagnosis(v, discovery=None, nominal=None, drive=None, air=()):
    nominal = nominal or _result("nominal", {"temperature": 0.2, "displacement": 1.2})
    return SimpleNamespace(decision=v, winner=v.winner, nominal=nominal, discovery=discovery, verdict="",
                           model=SimpleNamespace(drive=drive), record=SimpleNamespace(air=list(air)), where={},
                           names=[], scales=verdict.Scales({"temperature": 0.05, "displacement": 0.1}, {},
                                                           {"temperature": 0.0, "displacement": 0.0}, {}))


def _not_explained(best=None, displaced=None):
    return verdict.Verdict("not_explained", None, best, None, {"temperature": 3.0, "displacement": 5.0}, [], {}, [],
                           [], 2.0 if best is not None else NAN, displaced)


def test_an_atom_whose_interval_includes_zero_is_not_reported_as_discovered():
    """It read "discovered beyond the library: expansion coefficient of the ram: +0.00791 (90 %: -0.0198 … +0.0357)"
    with no change of α in the truth."""
    text = verdict.sentence(_diagnosis(_not_explained(), _found(_alpha())))
    assert "discovered beyond the library" not in text
    assert "nothing beyond the library was resolved" in text
    assert "not resolved (90 % interval includes 0): expansion coefficient of the ram" in text
    # a resolved atom is still reported as discovered, the unresolved one apart
    text = verdict.sentence(_diagnosis(_not_explained(), _found(_source(2.0, 6.0, 4.0), _source(-27.6, 33.7))))
    found, rest = text.split("; not resolved (90 % interval includes 0): ")
    assert "discovered beyond the library: an unmodelled heat source of about 4 W" in found
    assert "3.31 W" in rest and "3.31 W" not in found
    assert [d.resolved for d in _found(_source(2.0, 6.0), _source(-27.6, 33.7), _alpha(0.0, 0.03)).items] == \
        [True, False, False]


def test_the_discovery_summary_and_json_mark_unresolved_atoms():
    found = _found(_source(-27.6, 33.7))
    assert found.summary() == [f"not resolved (its 90 % interval includes 0): {found.items[0].sentence()}"]
    assert found.as_dict()["items"][0]["resolved"] is False
    block = verdict.to_json(_diagnosis(_not_explained(), found))
    assert block["discoveries"] == [] and [x["name"] for x in block["not_resolved"]] == ["source@ram"]


def test_a_displacement_by_unresolved_atoms_does_not_claim_a_discovery():
    """The displaced model's reason read "displaced by the effects discovered on the nominal twin's residual"."""
    best = _result("spindle_power_scale", {"temperature": 0.1, "displacement": 0.5}, 300.0)
    v = _not_explained(best, {"model": best.name, "by": "the effects discovered on the nominal twin's residual",
                              "delta_bic": 20.0})
    text = verdict.sentence(_diagnosis(v, _found(_alpha())))
    assert "discovered" not in text
    assert "though none of them is resolved" in text and "nothing beyond the library was resolved" in text


def _explained_with_a_zero_group():
    nominal = _result("nominal", {"temperature": 0.203, "air": 0.0, "displacement": 1.2})
    winner = _result("convection_enclosure", {"temperature": 0.0608, "air": 0.0, "displacement": 0.132}, 23.9,
                     [{"name": "convection_enclosure.scale", "value": 1.66, "interval": [1.49, 1.83], "unit": "×"}])
    v = verdict.Verdict("explained", winner, winner, None, {"temperature": 4.0, "air": NAN, "displacement": 12.0}, [],
                        {"temperature": 1.2, "air": NAN, "displacement": 1.3}, [], [], -np.inf)
    d = _diagnosis(v, nominal=nominal)
    d.scales = verdict.Scales({"temperature": 0.05, "air": 0.05, "displacement": 0.1}, {},
                              {"temperature": 0.0, "air": 0.0, "displacement": 0.0}, {})
    return d


def _strict(text):
    def refuse(token):
        raise ValueError(f"non-standard JSON constant {token}")
    return json.loads(text, parse_constant=refuse)


def test_no_nan_in_the_verdict_text_and_strict_json():
    """A noise-free twin dataset read "air 0 → 0 K (+nan %)" and wrote bare NaN into diagnosis.json."""
    d = _explained_with_a_zero_group()
    d.verdict = verdict.sentence(d)
    assert "nan" not in d.verdict.lower()
    assert "air 0 → 0 K (no change)" in d.verdict
    block = _strict(json.dumps(verdict.to_json(d)))
    assert block["held_out"]["air"]["reduction"] is None
    assert block["evidence"]["materiality"] is None and block["evidence"]["nominal_gap_over_scale"]["air"] is None
    assert block["held_out"]["temperature"]["reduction"] == pytest.approx(1 - 0.0608 / 0.203)
    with pytest.raises(ValueError):
        _strict('{"a": NaN}')


def test_strict_json_replaces_every_non_finite_number():
    from twin.gap.verdict import strict_json

    raw = {"a": np.float64("nan"), "b": [1.0, float("inf"), np.array([np.nan, 2.0])], "c": (np.int64(3), "x")}
    assert _strict(json.dumps(strict_json(raw), allow_nan=False)) == {"a": None, "b": [1.0, None, [None, 2.0]],
                                                                      "c": [3, "x"]}


def test_the_verdict_names_the_zones_taken_as_the_room_air():
    """With --scenario, a zone without an air sensor follows the room air, not the scenario; the verdict says so."""
    drive = SimpleNamespace(zones=["room", "enclosure", "front"], room_zone="room", lags_s={"enclosure": 10800.0},
                            fallback_room=None)
    d = _diagnosis(_not_explained(), drive=drive, air=[("A_top", "room", 0.0, np.zeros(3))])
    text = verdict.sentence(d)
    assert text.endswith("; assumed: zone 'front' (no air sensor) taken as the room air")
    assert verdict.to_json(d)["assumptions"] == [
        "zone 'enclosure' (no air sensor) taken as the room air through a 3 h lag",
        "zone 'front' (no air sensor) taken as the room air"]
    drive.fallback_room = np.zeros(3)
    assert verdict.air_assumptions(_diagnosis(_not_explained(), drive=drive))[0] == \
        "room zone 'room' (no air sensor) taken as the scenario's ambient"


def test_the_verdict_says_feeds_not_measured_were_taken_as_zero():
    """A record without feed columns was diagnosed with feeds of 0 mm/min, and only a note said so."""
    feeds = "axis feeds not measured (no feed_x/feed_y/feed_z column): taken as 0 mm/min"
    d = _diagnosis(_not_explained())
    d.record.report = {"assumed_inputs": [feeds]}
    assert verdict.sentence(d).endswith(f"; assumed: {feeds}")
    assert verdict.to_json(d)["assumptions"] == [feeds]


def test_diagnose_help_says_what_the_scenario_supplies():
    """--help claimed the scenario supplies missing "(spindle, feeds, ambient)"; it supplies only the room's."""
    from twin.gap.cli import register

    parser = argparse.ArgumentParser(prog="twin")
    register(parser.add_subparsers())
    diagnose = parser._subparsers._group_actions[0].choices["gap"]._subparsers._group_actions[0].choices["diagnose"]
    text = " ".join(a.help for a in diagnose._actions if "--scenario" in a.option_strings)
    assert "(spindle, feeds, ambient)" not in text
    assert "room zone's ambient" in text and "other zones without an air sensor follow the room air" in text


def test_a_spindle_driven_source_names_its_reference_speed():
    """The unit read "W at the reference speed" and never said which (9000 rpm)."""
    from twin.gap.discovery import driver_unit

    machine = SimpleNamespace(definition=SimpleNamespace(sources=[SimpleNamespace(driver="spindle", reference=9000.0),
                                                                  SimpleNamespace(driver="feed_x", reference=1.0)]))
    assert driver_unit("spindle", machine) == "W at 9000 rpm"
    assert driver_unit("feed", machine) == "W at 10 m/min"
    assert driver_unit("spindle", SimpleNamespace(definition=SimpleNamespace(sources=[]))) == "W at 9000 rpm"


def test_a_column_suspected_of_another_unit_leads_the_verdict():
    """A spindle logged in krpm was only a note in the report, while the verdict named a 1e5 W source."""
    d = _diagnosis(_not_explained(), _found(_source(9.87e4, 1.38e5, value=1.23e5)))
    d.record.report = {"unit_suspects": ["spindle_rpm"]}
    text = verdict.sentence(d)
    assert text.startswith("UNIT SUSPECTED: 'spindle_rpm' may be in another unit") and "1.23e+05 W" in text
    d.record.report = {"unit_suspects": []}
    assert "UNIT SUSPECTED" not in verdict.sentence(d)


def test_a_no_gap_verdict_on_a_suspected_unit_says_so_too():
    """A unit error can hide a gap as well as make one."""
    no_gap = verdict.Verdict("no_significant_gap", None, None, None, {"temperature": 0.5, "displacement": 0.8}, [],
                             {}, [], [], NAN, None)
    d = _diagnosis(no_gap)
    d.record.report = {"unit_suspects": ["feed_x_mm_min"]}
    text = verdict.sentence(d)
    assert text.startswith("UNIT SUSPECTED: 'feed_x_mm_min'") and "no significant gap" in text


def test_a_no_gap_verdict_lists_the_assumptions_too():
    """Feeds taken as 0 mm/min, or a zone taken as the room air, can hide a gap as well as make one: only a gap
    verdict had said "assumed: …"."""
    feeds = "axis feeds not measured (no feed_x/feed_y/feed_z column): taken as 0 mm/min"
    drive = SimpleNamespace(zones=["room", "enclosure", "front"], room_zone="room", lags_s={"enclosure": 10800.0},
                            fallback_room=None)
    no_gap = verdict.Verdict("no_significant_gap", None, None, None, {"temperature": 0.5, "displacement": 0.8}, [],
                             {}, [], [], NAN, None)
    d = _diagnosis(no_gap, drive=drive, air=[("A_top", "room", 0.0, np.zeros(3))])
    d.record.report = {"assumed_inputs": [feeds]}
    text = verdict.sentence(d)
    assert text.startswith("no significant gap: ")
    assert text.endswith(f"; assumed: {feeds}, zone 'front' (no air sensor) taken as the room air")
    d.record.report, d.model.drive = {}, None
    assert "assumed" not in verdict.sentence(d)
