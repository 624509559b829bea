"""twin live: the at-rest start prior across a bridge, a saved adaptive factor below 1 or NIS average below 0, an
``Adaptation`` that would narrow the process noise, one BLAS thread per observer step, and the state's model identity
computed once per session (2026-11-28, s36)."""
from __future__ import annotations

import asyncio
import dataclasses
import json

import numpy as np
import pytest

from twin.errors import TwinInputError
from twin.live.cli import DEFAULT_THERMOMETERS

THERMOMETERS = list(DEFAULT_THERMOMETERS)
NONE_READ = np.full(len(THERMOMETERS), np.nan)
AT_ROOM = np.full(len(THERMOMETERS), 20.0)      # a machine at rest in 20 °C air, every thermometer at 20 °C


def _first_band_after_hours_unread(rom, noise, unread_s=3 * 3600.0):
    """The Z band (µm) and the at-rest prior's weight at the first readings, which come ``unread_s`` s after two
    samples that had the room air but no thermometer readings (a logger stalled before the thermometers came)."""
    from twin.live.observer import DriftObserver

    observer = DriftObserver(rom, THERMOMETERS, noise)
    observer.step(0.0, 0.0, 20.0, NONE_READ)
    observer.step(60.0, 0.0, 20.0, NONE_READ)
    e = observer.step(60.0 + unread_s + 60.0, 0.0, 20.0, AT_ROOM)
    return e.band_um[2], observer.rest_weight


def test_hours_bridged_before_the_first_readings_widen_the_at_rest_start_prior_too(rom):
    """Both start priors wait for the first readings; a 3 h time nobody read the inputs (the spindle may have run)
    comes first.  The at-rest hypothesis did not see that time either: after readings of a machine at rest, the
    mixture's Z band is at least that of an observer told the machine was at rest before the same 3 h (its prior
    widened by the same bridge), and far wider than the band with no time unread.  Without the widening the
    at-rest half stays the narrow prior of a machine known to be idle all along: 3.8 against 5.0 µm."""
    from twin.live.observer import NOISE

    band, rest_weight = _first_band_after_hours_unread(rom, NOISE)
    told_at_rest, _ = _first_band_after_hours_unread(rom, dataclasses.replace(NOISE, start_at_rest=True))
    no_time_unread, _ = _first_band_after_hours_unread(rom, NOISE, unread_s=0.0)
    assert rest_weight > 0.5                     # readings of a machine at rest: the at-rest half weighs most
    assert band >= told_at_rest, (band, told_at_rest)
    assert band > 2.0 * no_time_unread, (band, no_time_unread)


# ----------------------------------------------------------------------------- the state file
def _kept_session(rom, path, samples=4, every_s=0.0):
    """A :class:`~twin.live.resume.KeptObserver` of one hypothesis over ``samples`` samples 60 s apart (a machine at
    rest), saving at every sample with ``every_s`` = 0."""
    from twin.live.observer import DriftObserver
    from twin.live.resume import KeptObserver

    kept = KeptObserver(DriftObserver(rom, THERMOMETERS), path, every_s=every_s)
    for k in range(samples):
        kept.step(60.0 * k, 0.0, 20.0, AT_ROOM)
    return kept


@pytest.fixture(scope="module")
def saved(rom, tmp_path_factory):
    path = tmp_path_factory.mktemp("s36") / "state.json"
    assert _kept_session(rom, path).save()
    return path


@pytest.mark.parametrize("inflation, reason", [
    (0.5, "not a factor ≥ 1"), (0.999, "not a factor ≥ 1"), (0.0, "not a factor ≥ 1"), (-2.0, "not a factor ≥ 1"),
    (float("nan"), "not a finite number"), (float("inf"), "not a finite number")])
def test_a_state_whose_adaptive_factor_would_narrow_the_process_noise_is_refused(tmp_path, rom, saved, inflation,
                                                                               reason):
    """The adaptive widening multiplies the disturbances' process noise by max(1, NIS average)^power: a factor below
    1 (or not finite) in a state file was edited or corrupted, and a filter going on from it would give too narrow
    bands.  Refused naming the file, the field and the value."""
    from twin.live.observer import DriftObserver
    from twin.live.resume import read_state

    data = json.loads(saved.read_text())
    data["filters"][0]["inflation"] = inflation
    path = tmp_path / "state.json"
    path.write_text(json.dumps(data))
    with pytest.raises(TwinInputError) as refused:
        read_state(path, DriftObserver(rom, THERMOMETERS))
    message = str(refused.value)
    assert message.startswith(f"{path}: field filters[0].inflation = {inflation!r}: {reason}"), message


@pytest.mark.parametrize("nis", [-1e6, -1e-9])
def test_a_state_whose_nis_average_is_negative_is_refused(tmp_path, rom, saved, nis):
    """The NIS average starts at 1 and averages values ≥ 0: a negative one (edited or corrupted) would hold the
    adaptive factor max(1, ā)^power at 1 until it wore away, hours of bands too narrow.  Refused naming the file,
    the field and the value; 0 (readings that fit exactly) is read."""
    from twin.live.observer import DriftObserver
    from twin.live.resume import read_state

    data = json.loads(saved.read_text())
    path = tmp_path / "state.json"
    data["filters"][0]["nis"] = 0.0
    path.write_text(json.dumps(data))
    assert read_state(path, DriftObserver(rom, THERMOMETERS)).filters[0].nis == 0.0
    data["filters"][0]["nis"] = nis
    path.write_text(json.dumps(data))
    with pytest.raises(TwinInputError) as refused:
        read_state(path, DriftObserver(rom, THERMOMETERS))
    message = str(refused.value)
    assert message.startswith(f"{path}: field filters[0].nis = {nis!r}: not an average NIS ≥ 0"), message


@pytest.mark.parametrize("field, value, rule", [
    ("limit", 0.5, "a factor ≥ 1"), ("limit", float("inf"), "a factor ≥ 1"), ("power", -1.0, "an exponent ≥ 0"),
    ("window_s", -60.0, "a time ≥ 0 s"), ("window_s", float("nan"), "a time ≥ 0 s"), ("power", None, "an exponent ≥ 0"),
    ("limit", True, "a factor ≥ 1"), ("window_s", "3600", "a time ≥ 0 s")])
def test_an_adaptation_that_would_narrow_the_process_noise_is_refused(field, value, rule):
    """An observer with ``Adaptation(limit=0.5)`` or ``power=-1`` had run with a factor below 1 on the process
    noise (bands too narrow) and written states the next session refuses as corrupted."""
    from twin.live.observer import ADAPTATION, Adaptation

    with pytest.raises(TwinInputError) as refused:
        dataclasses.replace(ADAPTATION, **{field: value})
    assert str(refused.value) == f"Adaptation.{field} must be {rule}, finite, got {value!r}"
    assert Adaptation(window_s=0.0, power=0.0, limit=1.0).limit == 1.0       # the bounds themselves: no widening


def test_a_state_with_the_factor_at_1_or_above_is_read(tmp_path, rom, saved):
    from twin.live.observer import DriftObserver
    from twin.live.resume import read_state

    for inflation in (1.0, 37.5):
        data = json.loads(saved.read_text())
        data["filters"][0]["inflation"] = inflation
        path = tmp_path / "state.json"
        path.write_text(json.dumps(data))
        assert read_state(path, DriftObserver(rom, THERMOMETERS)).filters[0].inflation == inflation


@pytest.mark.parametrize("state_there", [False, True])
def test_the_model_identity_is_computed_once_per_session_and_the_state_written_is_unchanged(tmp_path, rom,
                                                                                            monkeypatch, saved,
                                                                                            state_there):
    """A session that saves at every sample: what identifies the model is worked out once, also when a state file
    is there to be checked against it first (it had been worked out again to read the file), and the file is what
    :func:`~twin.live.resume.state_text` gives with the identity computed afresh."""
    from twin.live import resume

    path = tmp_path / "state.json"
    if state_there:
        path.write_text(saved.read_text())
    computed = []
    original = resume.model_identity
    monkeypatch.setattr(resume, "model_identity", lambda observer: computed.append(1) or original(observer))
    kept = _kept_session(rom, path, samples=5)
    assert (kept.saved is not None) == state_there
    assert len(computed) == 1
    assert kept.path.read_text() == resume.state_text(kept.observer)
    assert json.loads(kept.path.read_text())["model"] == original(kept.observer)


# ----------------------------------------------------------------------------- BLAS threads in the live loop
def _blas_threads():
    """Threads of every BLAS pool loaded (numpy's and SciPy's OpenBLAS), by library file."""
    from threadpoolctl import threadpool_info

    return {i["filepath"]: i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}


def test_the_live_loop_runs_each_observer_step_with_one_blas_thread(rom):
    """A short ``twin live`` session against a replay server, in a process whose BLAS pools have two threads: inside
    every observer step each BLAS pool has one (a reduced model's matrices, where threads only cost), and the pools
    have their two again
    after the session (the cap is the observer's, not the process's)."""
    from threadpoolctl import threadpool_limits

    from twin.live.cli import free_port
    from twin.live.client import LiveClient
    from twin.live.observer import DriftObserver
    from twin.live.replay import ReplayServer, default_node_map

    observer, inside = DriftObserver(rom, THERMOMETERS), []
    step = observer.step
    observer.step = lambda *sample: inside.append(_blas_threads()) or step(*sample)
    t = np.arange(4) * 60.0
    values = np.array([[9000.0, 20.0, *AT_ROOM] for _ in t])

    async def session():
        async with ReplayServer(["spindle", "T15", *THERMOMETERS], port=free_port()) as server:
            client = LiveClient(server.endpoint, default_node_map(THERMOMETERS, "T15", index=server.index), observer)
            task = asyncio.create_task(client.run(until_time_s=t[-1], max_wall_s=60))
            while not client._subscribed and not task.done():
                await asyncio.sleep(0.01)
            await server.replay(t, values, 600.0)
            return await task

    with threadpool_limits(limits=2, user_api="blas"):
        assert set(_blas_threads().values()) == {2}
        stats = asyncio.run(session())
        after = _blas_threads()
    assert len(inside) >= stats.samples == len(t)        # the server's initial values make a sample of their own
    assert all(set(threads.values()) == {1} for threads in inside), inside
    assert set(after.values()) == {2}
