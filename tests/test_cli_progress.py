"""Progress bars count what the work counts: time steps, scenarios, fits, cases."""
import inspect
import weakref

import pytest

from twin.infra.progress import progress_bar


@pytest.mark.parametrize("unit", ["step", "scenario"])
def test_the_bar_shows_its_unit(unit, capsys):
    update = progress_bar("simulating", unit=unit)
    update(1, 4)
    update(4, 4)
    err = capsys.readouterr().err
    assert f"{unit}/s" in err and "sample/s" not in err


def test_a_bar_is_known_to_the_clean_up_before_it_draws(capsys, monkeypatch):
    """``close_bars`` (Ctrl-C's clean-up) must know a bar before its first line is on stderr: a Ctrl-C in
    between left the line open, and the one-line interrupt message joined the bar's line."""
    from twin.infra import progress

    drawn_when_registered = []

    class Registry(weakref.WeakSet):
        def add(self, bar):
            drawn_when_registered.append(capsys.readouterr().err)
            super().add(bar)

    monkeypatch.setattr(progress, "_open_bars", Registry())
    update = progress_bar("simulating", unit="step")
    update(0, 10)
    assert drawn_when_registered == [""]
    update(10, 10)
    assert "simulating" in capsys.readouterr().err


def test_the_unit_must_be_chosen():
    with pytest.raises(TypeError):
        progress_bar("simulating")


def test_commands_name_what_they_count():
    from twin.compensation import cli as compensation_cli
    from twin.gap import cli as gap_cli
    from twin.placement import cli as placement_cli
    from twin.run import cli as run_cli

    units = {name: inspect.getsource(getattr(module, name)) for module, name in
             ((run_cli, "cmd_run"), (compensation_cli, "cmd_study"), (placement_cli, "cmd_place"),
              (gap_cli, "cmd_diagnose"), (gap_cli, "cmd_benchmark"))}
    assert 'unit="step"' in units["cmd_run"]
    assert 'unit="scenario"' in units["cmd_study"]
    assert 'unit="simulation"' in units["cmd_place"]
    assert 'unit="fit"' in units["cmd_diagnose"]
    assert 'unit="case"' in units["cmd_benchmark"]
