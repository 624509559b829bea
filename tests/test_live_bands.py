"""twin live: the X and Y bands' calibration (the per-axis band inflation) and the Z band left as it was."""
from __future__ import annotations

import numpy as np
import pytest

from twin.errors import TwinInputError
from twin.live.cli import BANDS_NOTE, DEFAULT_THERMOMETERS
from twin.live.multiple_model import (
    BAND_INFLATION,
    HYPOTHESES_W,
    MultipleModelObserver,
    live_observer,
)
from twin.live.observer import DriftObserver
from twin.live.protocol import BELT, Case, RecordRun, axis_score, readings

THERMOMETERS = list(DEFAULT_THERMOMETERS)
UNINFLATED = (1.0, 1.0, 1.0)


@pytest.fixture(scope="module")
def rom():
    from twin.core.machine import build_machine
    from twin.rom.reduction import cached_rom

    return cached_rom(build_machine("vmc_ram"), 80)


@pytest.fixture(scope="module")
def belt_record():
    """Full FE record (60 s steps, cached) of six_part_cycle with the unmodelled 60 W belt drive on the carrier
    (a training record of the protocol): an X drift of ~2 µm the nominal, X-symmetric model has no cause for."""
    from twin.gap.truth import PhysicsChange, physics_truth

    change = PhysicsChange(sources=(BELT,), time_step_s=60.0, output_step_s=60.0)
    return physics_truth("six_part_cycle", change, noise=False)


def _run(observer, record, seed):
    T, air = readings(record, THERMOMETERS, seed)
    return observer.run(record.time_s, record["spindle"], air, T)


def test_the_shipped_factors_widen_x_and_y_and_leave_z():
    """The choice of ``python bench/bench_live.py --calibrate-xy`` on the training records (docs/live.md):
    X × 5, Y × 1.25, Z × 1 (Z's band is calibrated by the hypotheses, not by a factor)."""
    assert BAND_INFLATION == (5.0, 1.25, 1.0)


@pytest.mark.parametrize("hypotheses", [HYPOTHESES_W, (0.0,)], ids=["two hypotheses", "single filter"])
def test_live_observer_inflates_the_x_and_y_bands_only(rom, belt_record, hypotheses):
    """The observer ``twin live`` runs publishes the filter's X and Y band × the shipped factor and its own Z
    band; the drift is the same (the factor is on the published band, not in the filter)."""
    drift, band = _run(live_observer(rom, THERMOMETERS, hypotheses_W=hypotheses), belt_record, 1)
    plain_drift, plain = _run(live_observer(rom, THERMOMETERS, hypotheses_W=hypotheses, band_inflation=UNINFLATED),
                              belt_record, 1)
    np.testing.assert_array_equal(drift, plain_drift)
    np.testing.assert_allclose(band[:, 0], 5.0 * plain[:, 0], rtol=1e-12)
    np.testing.assert_allclose(band[:, 1], 1.25 * plain[:, 1], rtol=1e-12)
    np.testing.assert_array_equal(band[:, 2], plain[:, 2])


def test_z_band_is_the_mixture_of_the_hypotheses_as_before(rom, belt_record):
    """Z is unchanged: the shipped observer's Z band and drift are those of the two hypotheses' mixture built
    without any factor (the observer calibrated on 2026-11-27), and its members' bands are not inflated."""
    shipped = live_observer(rom, THERMOMETERS)
    drift, band = _run(shipped, belt_record, 2)
    reference_drift, reference = _run(MultipleModelObserver(rom, THERMOMETERS, HYPOTHESES_W), belt_record, 2)
    np.testing.assert_array_equal(drift[:, 2], reference_drift[:, 2])
    np.testing.assert_array_equal(band[:, 2], reference[:, 2])
    assert all(np.all(m.band_inflation == 1.0) for m in shipped.members)


def test_x_coverage_on_the_belt_drive_moves_as_documented(rom, belt_record):
    """On the 60 W belt drive (X drift ~2 µm, not in the model) the filter's own X band holds the truth in few
    samples (2.9 % on the 10 s training record, docs/live.md); × 5 it holds it in most (98.4 % there).  Two noise
    draws on the 60 s record: uninflated ≤ 30 %, shipped ≥ 85 %, and the Z coverage the same in both."""
    inside, inside_plain, z_inside, z_inside_plain = [], [], [], []
    true = belt_record.matrix(["X", "Y", "Z"])
    for seed in (1, 2):
        drift, band = _run(live_observer(rom, THERMOMETERS), belt_record, seed)
        _, plain = _run(live_observer(rom, THERMOMETERS, band_inflation=UNINFLATED), belt_record, seed)
        error = np.abs(drift - true)
        inside.append(error[:, 0] <= band[:, 0])
        inside_plain.append(error[:, 0] <= plain[:, 0])
        z_inside.append(error[:, 2] <= band[:, 2])
        z_inside_plain.append(error[:, 2] <= plain[:, 2])
    assert np.sqrt(np.mean(true[:, 0] ** 2)) > 1.0                     # a real X drift the model lacks
    assert np.mean(inside_plain) <= 0.30, np.mean(inside_plain)
    assert np.mean(inside) >= 0.85, np.mean(inside)
    assert np.mean(z_inside) == np.mean(z_inside_plain)


def test_axis_score_of_each_axis_and_a_corrected_band():
    """Coverage, mean band, error and interval score (width + 40 × the miss) per axis of a run, and of a band
    given in its place; Z is the default axis."""
    error = np.array([[0.5, 1.0, -3.0], [-2.0, 0.0, 1.0]])
    band = np.array([[1.0, 2.0, 2.0], [1.0, 2.0, 2.0]])
    truth = np.array([[1.0, 2.0, 4.0], [1.0, 2.0, 4.0]])
    run = RecordRun(Case("s", "e", "k"), error, band, truth, 1.0, 10.0)
    x = axis_score(run, "X")
    assert (x.axis, x.coverage, x.band_um, x.max_um, x.samples) == ("X", 0.5, 1.0, 2.0, 2)
    assert x.interval_score_um == pytest.approx(np.mean([2.0, 2.0 + 40.0 * 1.0]))
    assert x.rms_um == pytest.approx(np.sqrt((0.25 + 4.0) / 2)) and x.truth_rms_um == pytest.approx(1.0)
    z = axis_score(run)
    assert (z.axis, z.coverage) == ("Z", 0.5) and z.interval_score_um == pytest.approx(np.mean([4.0 + 40.0, 4.0]))
    wide = axis_score(run, "X", 5.0 * band[:, 0])
    assert (wide.coverage, wide.band_um, wide.interval_score_um) == (1.0, 5.0, 10.0)


@pytest.mark.parametrize("factors", [(1.0, 1.0), (0.5, 1.0, 1.0), (np.nan, 1.0, 1.0)])
def test_band_inflation_must_be_three_factors_of_at_least_one(rom, factors):
    with pytest.raises(TwinInputError, match="band_inflation"):
        DriftObserver(rom, THERMOMETERS, band_inflation=factors)


def test_the_summary_says_which_bands_are_calibrated_with_their_factors():
    """Every ``twin live`` summary names the X and Y factors the band carries and where Z's calibration is."""
    assert "X band × 5" in BANDS_NOTE and "Y band × 1.25" in BANDS_NOTE and "Z" in BANDS_NOTE
    assert "never checked" not in BANDS_NOTE

