"""Inputs of ``twin gap diagnose`` that were taken silently: an empty ``--effects`` list, a negative ``--pairs``, a
record without feed columns (feeds taken as 0 mm/min, said nowhere but a note), and a whole record in °F with no
air sensor to give it away."""
from decimal import Decimal
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest

from twin.core.dataset import KIND_OF_UNIT, ChannelInfo, Dataset, split_column
from twin.errors import TwinInputError

T = np.arange(241) * 120.0                      # 8 h every 2 min


def _dataset(columns, source="rig.csv"):
    """A dataset of ``{column: values}`` (``<name>_<unit>`` columns) with ``source`` as its file."""
    channels = [ChannelInfo(*split_column(c), KIND_OF_UNIT[split_column(c)[1]]) for c in columns]
    return Dataset(T, np.column_stack(list(columns.values())), channels, {"source": source})


@pytest.fixture(scope="module")
def machine():
    from twin.gap.diagnose import _machine

    return _machine("vmc_ram")


def _spindle():
    return np.repeat([0.0, 6000.0, 0.0], -(-len(T) // 3))[:len(T)]


NO_PAIRS = "n_pairs (--pairs) must be a whole number of top effects to pair, 0 (no pairs) or more, got "
NO_EFFECT = ("names no effect: give effects of the library (a list or a comma list), or leave it out for the whole "
             "library")


@pytest.mark.parametrize("option, value, said", [
    ("--effects", "", f"effects (--effects) '' {NO_EFFECT}"),
    ("--effects", " , ", f"effects (--effects) ' , ' {NO_EFFECT}"),
    ("--effects", "belt_drive,belt_drive", "effects (--effects) names effect 'belt_drive' more than once"),
    ("--pairs", "-1", NO_PAIRS + "-1"),
])
def test_an_empty_effect_list_or_a_negative_pair_count_is_refused(option, value, said, tmp_path, capsys):
    """``--effects ""`` fell back to the whole library and ``--pairs -1`` to no pairs, both silently."""
    from twin.cli import main

    code = main(["gap", "diagnose", "--measured", str(tmp_path / "none.csv"), "--out", str(tmp_path / "out"),
                 option, value])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and err.endswith(said), err


@pytest.fixture
def unbuilt(monkeypatch):
    """Fail loudly if a diagnosis got as far as building its machine (meshing): the arguments are checked first."""
    from twin.gap import diagnose

    def refuse(*args, **kwargs):
        raise AssertionError("the machine was built before the arguments were checked")
    monkeypatch.setattr(diagnose, "_machine", refuse)


@pytest.mark.parametrize("arguments, said", [
    ({"n_pairs": -1}, NO_PAIRS + "-1"),
    ({"n_pairs": 1.5}, NO_PAIRS + "1.5 (not a whole number)"),
    ({"n_pairs": None}, NO_PAIRS + "None (not a whole number)"),
    ({"effects": []}, f"effects (--effects) [] {NO_EFFECT}"),
    ({"effects": ""}, f"effects (--effects) '' {NO_EFFECT}"),
    ({"effects": ["belt_drive", "belt_drive"]}, "effects (--effects) names effect 'belt_drive' more than once"),
    ({"effects": "belt_drive, belt_drive"}, "effects (--effects) names effect 'belt_drive' more than once"),
    ({"holdout_fraction": 1.5}, "holdout_fraction (--holdout) must lie in [0.05, 0.8], got 1.5"),
    ({"step_s": 0.0}, "step_s (--step) must be a positive number of seconds, got 0"),
    # not numbers: None had ended in a TypeError from float(), a string or a bool had been read as a number
    *[({name: value}, f"{name} ({flag}) must {rule}, got {shown}")
      for name, flag, rule in (("holdout_fraction", "--holdout", "lie in [0.05, 0.8]"),
                               ("step_s", "--step", "be a positive number of seconds"))
      for value, shown in ((None, "None (not a number)"), ("60", "'60' (not a number)"), (float("nan"), "nan"),
                           (True, "True (not a number)"), (0.3 + 0.1j, "(0.3+0.1j) (not a number)"))],
    # other real numbers, out of range, shown as the float they are: a Fraction had raised a TypeError in the message
    ({"holdout_fraction": Fraction(9, 10)}, "holdout_fraction (--holdout) must lie in [0.05, 0.8], got 0.9"),
    ({"holdout_fraction": Decimal("0.9")}, "holdout_fraction (--holdout) must lie in [0.05, 0.8], got 0.9"),
    ({"step_s": np.array(-60.0)}, "step_s (--step) must be a positive number of seconds, got -60"),
    ({"n_pairs": True}, NO_PAIRS + "True (not a whole number)"),
    ({"n_pairs": "3"}, NO_PAIRS + "'3' (not a whole number)"),
])
def test_the_python_api_refuses_what_the_command_line_refuses(arguments, said, tmp_path, unbuilt):
    """``diagnose(n_pairs=-1)`` had fitted no pairs and ``effects=[]`` the whole library, silently: the checks
    were in the command line only.  They are the API's now, so both say the same."""
    from twin.gap.diagnose import diagnose

    with pytest.raises(TwinInputError) as err:
        diagnose(tmp_path / "none.csv", **arguments)
    assert str(err.value) == said


@pytest.mark.parametrize("arguments", [{"holdout_fraction": Fraction(3, 10)}, {"holdout_fraction": Decimal("0.3")},
                                       {"holdout_fraction": np.array(0.3)}, {"step_s": Fraction(60)},
                                       {"step_s": np.float32(60.0)}, {"n_pairs": np.int64(2)}])
def test_real_numbers_of_other_types_within_the_rules_are_taken(arguments, tmp_path, unbuilt):
    """``Decimal('0.3')`` and ``np.array(0.3)`` had been refused with "must lie in [0.05, 0.8], got
    Decimal('0.3')": they pass the checks now, up to the machine's build."""
    from twin.gap.diagnose import diagnose

    with pytest.raises(AssertionError, match="the machine was built"):
        diagnose(tmp_path / "none.csv", **arguments)


def test_effects_may_be_a_comma_list_as_on_the_command_line(tmp_path, unbuilt):
    """A comma list is split as ``--effects`` splits it (one name as a string had been read letter by letter)."""
    from twin.gap.diagnose import diagnose

    for effects in ("belt_drive", "belt_drive, convection_room", ["belt_drive"], None):
        with pytest.raises(AssertionError, match="the machine was built"):
            diagnose(tmp_path / "none.csv", effects=effects)


def test_a_record_without_feeds_says_they_are_taken_as_zero(machine):
    from twin.gap.measured import match_record

    columns = {"spindle_rpm": _spindle(), "T01_degC": np.full(len(T), 20.0), "A_top_degC": np.full(len(T), 20.0)}
    record = match_record(_dataset(columns), machine)
    assert record.report["assumed_inputs"] == [
        "axis feeds not measured (no feed_x/feed_y/feed_z column): taken as 0 mm/min"]
    columns["feed_x_mm_min"] = np.full(len(T), 2000.0)
    assert match_record(_dataset(columns), machine, "gap_quick_8h").report["assumed_inputs"] == [
        "axis feeds not measured (no feed_y/feed_z column): taken as those of scenario 'gap_quick_8h'"]
    columns.update(feed_y_mm_min=columns["feed_x_mm_min"], feed_z_mm_min=columns["feed_x_mm_min"])
    assert match_record(_dataset(columns), machine).report["assumed_inputs"] == []


def test_the_report_lists_the_assumed_feeds(machine):
    from twin.gap.measured import match_record
    from twin.gap.report import _record_lines

    columns = {"spindle_rpm": _spindle(), "T01_degC": np.full(len(T), 20.0), "A_top_degC": np.full(len(T), 20.0)}
    record = match_record(_dataset(columns), machine)
    model = SimpleNamespace(backend=SimpleNamespace(name="rom"), drive=SimpleNamespace(step_s=60.0))
    lines = _record_lines(SimpleNamespace(record=record, model=model, names=record.names))
    assert "- assumed: axis feeds not measured (no feed_x/feed_y/feed_z column): taken as 0 mm/min" in lines


def test_a_whole_record_in_fahrenheit_without_air_is_refused(machine):
    """Room temperature in °F (68) under every _degC column, no air sensor: it had been diagnosed as 68 °C."""
    from twin.gap.measured import match_record

    columns = {"spindle_rpm": _spindle(), **{f"T0{k}_degC": np.full(len(T), 68.0 + 0.2 * k) for k in range(1, 5)}}
    with pytest.raises(TwinInputError) as err:
        match_record(_dataset(columns), machine)
    message = str(err.value)
    assert "\n" not in message and message.startswith(
        "rig.csv: the 4 surface thermometers start at a median of 68.4 degC, above the 50 degC of shop air, and the "
        "record has no air sensor")
    assert "°F? (°F − 32)/1.8 = 20.22 °C" in message


@pytest.mark.parametrize("starts", [(120.0, 20.0), (120.0, 20.5, 21.0), (70.0,), (70.0, 75.0, 20.0, 21.0)])
def test_hot_surface_thermometers_short_of_most_of_them_are_not_refused(starts, machine):
    """A hot spindle housing can be real: neither one hot thermometer nor a lone one decides, only most of two or
    more."""
    from twin.gap.measured import match_record

    columns = {"spindle_rpm": _spindle(), **{f"T0{k + 1}_degC": np.full(len(T), s) for k, s in enumerate(starts)}}
    assert match_record(_dataset(columns), machine).names == [f"T0{k + 1}" for k in range(len(starts))]
