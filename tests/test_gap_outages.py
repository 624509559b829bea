"""Logging outages: which intervals are outages, and which rows after one the twin cannot be judged on."""
import numpy as np
import pytest

from twin.errors import TwinInputError
from twin.gap.outages import (
    OUTAGE_MIN_S,
    UnknownInputs,
    check_rows_left,
    describe,
    held_across,
    outage_intervals,
    outage_spans,
    unknown_rows,
)


def _found(t, inputs):
    spans = outage_spans(t, inputs)
    return spans, outage_intervals(t, spans)


def _record(step_s, gap_s, before_rpm, after_rpm):
    t = np.r_[np.arange(0.0, 3600.0, step_s), 3600.0 - step_s + gap_s + np.arange(0.0, 3600.0, step_s)]
    rpm = np.where(t < 3600.0, before_rpm, after_rpm).astype(float)
    return t, {"spindle_rpm": rpm}


def test_an_outage_is_a_long_interval_with_an_input_change_across_it():
    t, inputs = _record(120.0, 7200.0, 0, 9000)
    spans, found = _found(t, inputs)
    assert found.sum() == 1 and t[np.flatnonzero(found)[0]] == pytest.approx(3480.0)
    assert describe(t, inputs, spans) == [(3480.0, 10680.0, "spindle_rpm 0 → 9000")]


@pytest.mark.parametrize("step_s, gap_s, before, after", [
    (120.0, 7200.0, 9000, 9000),            # long, but the spindle ran at one speed through it
    (10.0, 300.0, 0, 9000),                 # 30 samples long, but shorter than OUTAGE_MIN_S: the timing floor's
    (120.0, 480.0, 0, 9000),                # four samples: a sampling irregularity
])
def test_no_outage_without_a_change_or_when_short(step_s, gap_s, before, after):
    assert gap_s < OUTAGE_MIN_S or before == after
    t, inputs = _record(step_s, gap_s, before, after)
    assert not _found(t, inputs)[1].any()


def test_unknown_rows_run_from_the_first_to_the_last_row_over_scale_after_the_start():
    t = np.arange(20) * 100.0
    spread = np.zeros((20, 2))
    spread[2, 0] = 5.0                       # before the outage: not the outage's doing
    spread[[6, 9], 1] = [-0.3, 0.25]
    rows = unknown_rows(t, 450.0, spread, np.array([0.1, 0.2]))
    assert np.flatnonzero(rows).tolist() == [6, 7, 8, 9]


def test_too_few_rows_left_is_refused_with_the_outage_and_a_holdout_that_works():
    t = np.arange(100) * 300.0
    unknown = UnknownInputs([(15000.0, 18000.0, "spindle_rpm 0 → 9000")], t >= 18000.0)
    with pytest.raises(TwinInputError, match=r"rec.csv: .*4.17–5.00 h \(spindle_rpm 0 → 9000\).*--holdout 0\.65"):
        check_rows_left(t < 20000.0, t >= 20000.0, unknown, t, "rec.csv")
    check_rows_left(t < 10000.0, t >= 10000.0, unknown, t, "rec.csv")   # fit and held-out rows before it: fine
    unknown.rows[:] = False                                              # the few rows are not the outage's doing
    check_rows_left(t < 29000.0, t >= 29000.0, unknown, t, "rec.csv")


def test_an_input_not_read_on_one_side_is_not_named_as_changed():
    t, inputs = _record(120.0, 7200.0, 0, 9000)
    inputs["feed_x_mm_min"] = np.where(t < 3600.0, np.nan, 500.0)
    spans, _ = _found(t, inputs)
    assert describe(t, inputs, spans) == [(3480.0, 10680.0, "spindle_rpm 0 → 9000")]


def test_an_input_not_read_on_logged_rows_is_an_outage_from_its_last_reading_to_its_next():
    """Rows logged every 2 min with the spindle column empty from 1 h to 3 h: as unknown as rows not logged."""
    t = np.arange(0.0, 4 * 3600.0 + 1, 120.0)
    rpm = np.where(t < 3600.0, 0.0, 9000.0)
    rpm[(t >= 3600.0) & (t < 3 * 3600.0)] = np.nan
    spans, found = _found(t, {"spindle_rpm": rpm})
    assert np.flatnonzero(found).tolist() == list(range(29, 90))     # from the row at 0.97 h to the one at 3 h
    assert describe(t, {"spindle_rpm": rpm}, spans) == [(3480.0, 10800.0, "spindle_rpm 0 → 9000")]
    short = np.where(t < 3600.0, 0.0, 9000.0)
    short[(t >= 3600.0) & (t < 3600.0 + 480.0)] = np.nan            # four readings lost: a sampling irregularity
    assert not _found(t, {"spindle_rpm": short})[1].any()


def test_an_outage_change_is_moved_to_its_start_or_its_end():
    values = np.array([0.0, 0.0, 0.0, 5.0, 5.0, 5.0, 7.0])            # filled: the step at the unread run's middle
    assert held_across(values, [(1, 5)], "start").tolist() == [0, 0, 5, 5, 5, 5, 7]
    assert held_across(values, [(1, 5)], "end").tolist() == [0, 0, 0, 0, 0, 5, 7]
    assert held_across(values, [], "start").tolist() == values.tolist()


def test_two_outages_that_share_a_row_keep_its_reading_apart():
    """One row logged in the middle of a long outage: two outages, its reading (5000 rpm) known and kept."""
    t = np.r_[np.arange(0.0, 3600.0, 60.0), 3 * 3600.0, 5 * 3600.0 + np.arange(0.0, 3600.0, 60.0)]
    rpm = np.where(t == 3 * 3600.0, 5000.0, 0.0)
    spans, _ = _found(t, {"spindle_rpm": rpm})
    assert describe(t, {"spindle_rpm": rpm}, spans) == [(3540.0, 10800.0, "spindle_rpm 0 → 5000"),
                                                        (10800.0, 18000.0, "spindle_rpm 5000 → 0")]
    for side in ("start", "end"):
        assert held_across(rpm, spans["spindle_rpm"], side)[60] == 5000.0


def test_one_inputs_outage_does_not_move_another_inputs_read_changes():
    """The spindle unread from 1 to 3 h; feed X read throughout, stepping 0 → 2000 mm/min at 1.5 h."""
    t = np.arange(0.0, 4 * 3600.0 + 1, 120.0)
    rpm = np.where(t < 3600.0, 0.0, 9000.0)
    rpm[(t >= 3600.0) & (t < 3 * 3600.0)] = np.nan
    feed = np.where(t < 1.5 * 3600.0, 0.0, 2000.0)
    inputs = {"spindle_rpm": rpm, "feed_x_mm_min": feed}
    spans, _ = _found(t, inputs)
    assert spans["feed_x_mm_min"] == [] and describe(t, inputs, spans) == [(3480.0, 10800.0, "spindle_rpm 0 → 9000")]
    assert held_across(feed, spans["feed_x_mm_min"], "start").tolist() == feed.tolist()


def test_a_speed_not_read_is_filled_as_a_step_at_the_middle_not_a_ramp():
    from twin.gap.measured import _fill_steps

    t = np.arange(10.0) * 60.0
    rpm = np.array([0.0, np.nan, np.nan, np.nan, np.nan, 9000.0, 9000.0, np.nan, 4500.0, np.nan])
    assert _fill_steps(t, rpm).tolist() == [0, 0, 0, 9000, 9000, 9000, 9000, 9000, 4500, 4500]
