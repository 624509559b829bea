"""twin live: the observer against the full FE, and the OPC UA client against a real asyncua server on 127.0.0.1."""
from __future__ import annotations

import asyncio
import dataclasses

import numpy as np
import pytest

from twin.cli import main as twin_main
from twin.errors import TwinInputError
from twin.live.cli import (
    DEFAULT_THERMOMETERS,
    EXIT_NOT_OBSERVED,
    free_port,
    replay_session,
)
from twin.live.client import LiveClient
from twin.live.nodemap import load_node_map
from twin.live.observer import DriftObserver
from twin.live.replay import ReplayServer, default_node_map

THERMOMETERS = list(DEFAULT_THERMOMETERS)
CHANNELS = ["spindle", "T15", *THERMOMETERS]


@pytest.fixture(scope="module")
def machine():
    from twin.core.machine import build_machine

    return build_machine("vmc_ram")


@pytest.fixture(scope="module")
def rom(machine):
    from twin.rom.reduction import cached_rom

    return cached_rom(machine, 80)


def _sample(t, rpm=9000.0, temperature=20.0):
    return [rpm, 20.0] + [temperature + 1e-4 * t] * len(THERMOMETERS)


def _client(server, rom, tmp_path=None, **kw):
    node_map = default_node_map(THERMOMETERS, "T15", index=server.index)
    return LiveClient(server.endpoint, node_map, DriftObserver(rom, THERMOMETERS),
                      None if tmp_path is None else tmp_path / "log.csv", **kw)


async def _until_subscribed(client, task):
    while not client._subscribed and not task.done():
        await asyncio.sleep(0.01)


# ----------------------------------------------------------------------------- observer accuracy (truth: full FE)
def _fe_truth(scenario_name, change):
    """Full FE record of a coarser (60 s) copy of a scenario on a machine whose physics ``change`` alters
    (:func:`twin.gap.truth.physics_truth`, cached).  Not an inverse crime: the truth is another model (FE, changed
    physics, backward Euler); the observer only reads 6 thermometers and the room air through the DS18S20 model
    (:func:`twin.live.protocol.readings`) and the spindle speed."""
    from twin.gap.truth import physics_truth

    change = dataclasses.replace(change, time_step_s=60.0, output_step_s=60.0)
    return physics_truth(scenario_name, change, noise=False)


def test_observer_tracks_fe_truth_with_an_unmodelled_effect(rom):
    """heat_cool_9000 with the enclosure convection × 0.6 (the observer's ROM is nominal): the observer ``twin live``
    runs gets Z within 1 µm RMS, better than the open-loop ROM."""
    from twin.gap.truth import PhysicsChange
    from twin.live.multiple_model import live_observer
    from twin.live.protocol import readings
    from twin.rom.reduction import simulate_rom

    truth = _fe_truth("heat_cool_9000", PhysicsChange(convection={"enclosure": 0.6}))
    T, air = readings(truth, THERMOMETERS, 3)
    drift, _ = live_observer(rom, THERMOMETERS).run(truth.time_s, truth["spindle"], air, T)
    z = truth["Z"]
    err = drift[:, 2] - z
    open_loop = simulate_rom(rom, "heat_cool_9000", sample_times=truth.time_s)["Z"] - z
    rms = np.sqrt(np.mean(err ** 2))
    assert np.sqrt(np.mean(z ** 2)) > 20.0                      # a real drift to follow
    assert rms < 1.0
    assert rms < 0.7 * np.sqrt(np.mean(open_loop ** 2))          # the thermometers help


def test_band_is_not_overconfident_on_an_effect_kind_outside_the_calibration(rom):
    """A joint conductance is no effect kind of the training records the band was calibrated on
    (twin.live.protocol.TRAINING).  On the full-FE record of six_part_cycle (9000 rpm, the feeds the observer
    does not read) with the carrier–ram joint × 0.3, 60 s, the 95 % band of the observer ``twin live`` runs
    covers ≥ 90 % of the samples over 4 thermometer noise draws (Z error ~0.9 µm RMS; the band passes down to
    0.3–0.4 of its width of 2026-11-27, so a band that shrank to the size of the errors fails), and is not so wide
    as to say nothing (mean half-width ≤ 7 µm on a drift of ~35 µm; 5.1 µm on 2026-11-27, against 3.5 µm for
    the σ_P = 0 filter alone: the σ_P = 40 W hypothesis takes some weight while the machine heats)."""
    from twin.gap.truth import PhysicsChange
    from twin.live.multiple_model import live_observer
    from twin.live.protocol import readings

    truth = _fe_truth("six_part_cycle", PhysicsChange(joints={"carrier-ram": 0.3}))
    inside, bands = [], []
    for seed in range(1, 5):
        T, air = readings(truth, THERMOMETERS, seed)
        drift, band = live_observer(rom, THERMOMETERS).run(truth.time_s, truth["spindle"], air, T)
        inside.append(np.abs(drift[:, 2] - truth["Z"]) <= band[:, 2])
        bands.append(band[:, 2])
    assert np.mean(inside) >= 0.90, np.mean(inside)
    assert np.mean(bands) <= 7.0, np.mean(bands)


def test_observer_refuses_unknown_thermometer_and_time_going_back(rom):
    with pytest.raises(TwinInputError, match="'T99' is not a surface thermometer"):
        DriftObserver(rom, ["T01", "T99"])
    obs = DriftObserver(rom, ["T01"])
    with pytest.raises(TwinInputError, match="no basis"):
        obs.field()
    assert obs.step(0.0, 0.0, np.nan, [20.0]) is None            # no room air yet: not started
    e = obs.step(0.0, 0.0, 20.0, [20.0])
    assert np.allclose(e.drift_um, 0.0, atol=1e-6)                # idle in 20 °C air: no drift
    with pytest.raises(TwinInputError, match="not after"):
        obs.step(0.0, 0.0, 20.0, [20.0])


def test_readings_off_the_model_widen_the_band(rom):
    """The NIS-driven widening: readings that scatter about the model far more than it allows (0.3 K rms against
    its 0.05 K of model error) raise the inflation above 1 and widen the band against the observer without it;
    on readings the model expects, the adaptive observer is the plain one."""
    from twin.live.observer import ADAPTATION, Adaptation

    assert ADAPTATION.window_s > 0
    t = np.arange(0.0, 4 * 3600.0, 60.0)
    rpm, air = np.zeros(len(t)), np.full(len(t), 20.0)
    consistent = np.full((len(t), len(THERMOMETERS)), 20.0)
    scattered = consistent + np.random.default_rng(0).normal(0.0, 0.3, consistent.shape)
    runs = {}
    for label, readings, adaptation in (("plain", scattered, Adaptation()), ("adaptive", scattered, ADAPTATION),
                                        ("still", consistent, ADAPTATION), ("still plain", consistent, Adaptation())):
        obs = DriftObserver(rom, THERMOMETERS, adaptation=adaptation)
        runs[label] = (*obs.run(t, rpm, air, readings), obs.inflation)
    assert runs["adaptive"][2] > 2.0 and runs["still"][2] == 1.0
    assert runs["adaptive"][1][-1, 2] > 1.5 * runs["plain"][1][-1, 2]
    assert np.allclose(runs["still"][0], runs["still plain"][0]) and np.allclose(runs["still"][1], runs["still plain"][1])


def test_structured_filter_equals_the_generic_one(rom):
    """The observer's block-structured covariance step gives the generic Kalman filter's numbers; with consider
    states, the Schmidt–Kalman form P − KHP − (KHP)ᵀ + KSKᵀ with the consider rows of K zeroed; its
    log-likelihood of the readings is that of N(ν; 0, S) (scipy)."""
    from scipy.stats import multivariate_normal

    from models.kalman import KalmanFilter
    from twin.live.filtering import ModalKalmanFilter

    obs = DriftObserver(rom, THERMOMETERS)
    obs.start(0.0, 20.0)
    model = obs.model
    F, G, Q = obs._transition(10.0, obs._u)
    F22 = F[rom.order:, rom.order:]
    assert np.count_nonzero(F22 - np.diag(np.diagonal(F22)))          # the lagged air's row: F₂₂ is not diagonal
    args = (F, G, model.H, model.J, Q, model.R)
    fast = ModalKalmanFilter(rom.order, *args, None, model.couplings)
    consider = ModalKalmanFilter(rom.order, *args, model.consider, model.couplings)
    generic = KalmanFilter(*args)
    for kf in (fast, generic, consider):
        kf.reset(obs._kf.x, obs._kf.P)
    rng = np.random.default_rng(0)
    u = obs._u
    for k in range(30):
        y = 20.0 + 0.02 * k + rng.normal(0.0, 0.05, len(THERMOMETERS))
        y[k % 6] = np.nan if k % 5 == 0 else y[k % 6]
        P_before, x_before = consider.predict(u).P.copy(), consider.x.copy()
        seen = np.isfinite(y)
        H = model.H[seen]
        S = H @ P_before @ H.T + np.diag(model.R[seen])
        K = P_before @ H.T @ np.linalg.inv(S)
        K[model.consider] = 0.0
        consider.update(y, u)
        innovation = y[seen] - H @ x_before - model.J[seen] @ u
        assert np.isclose(consider.log_likelihood, multivariate_normal.logpdf(innovation, cov=S), rtol=1e-9)
        expected = P_before - K @ H @ P_before - (K @ H @ P_before).T + K @ S @ K.T
        assert np.allclose(consider.P, expected, atol=1e-10 * np.abs(expected).max())
        assert np.allclose(consider.x, x_before + K @ innovation)
        for kf in (fast, generic):
            kf.predict(u).update(y, u)
    assert np.allclose(fast.x, generic.x, rtol=1e-9, atol=1e-9 * np.abs(generic.x).max())
    assert np.allclose(fast.P, generic.P, rtol=1e-7, atol=1e-9 * np.abs(generic.P).max())


# ----------------------------------------------------------------------------- placement-chosen thermometers
@pytest.fixture(scope="module")
def rom_with_basis(machine):
    from twin.rom.reduction import cached_rom

    return cached_rom(machine, 80, keep_basis=True)


def _chosen_csv(path, rows):
    """A ``chosen_sensors.csv`` like ``twin place`` writes, axis Z, with (name, position) rows."""
    lines = ["axis,method,K,rank,name,kind,part,x_m,y_m,z_m"]
    lines += [f"Z,greedy-loso,{len(rows)},{k},{name},surface,x,{p[0]},{p[1]},{p[2]}"
              for k, (name, p) in enumerate(rows, start=1)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_observer_on_placement_points_is_the_observer_on_those_thermometers(tmp_path, machine, rom_with_basis):
    """Placement locations at the positions of machine thermometers get the ROM rows of those thermometers
    (barycentric FE row × basis), so the observer fusing them gives the same estimates."""
    from twin.live.placement import placement_rom, read_placement

    position = {c.name: c.position for c in machine.channels}
    chosen = ["T05", "T12", "T18", "T20"]
    csv = _chosen_csv(tmp_path / "chosen_sensors.csv", [(f"s{n}", position[n]) for n in chosen])
    placed = read_placement(tmp_path)
    assert placed.names == [f"s{n}" for n in chosen] and csv.exists()
    rom = placement_rom(rom_with_basis, machine, placed)
    for n in chosen:
        assert np.allclose(rom.output_matrix[rom.output_index(f"s{n}")], rom.output_matrix[rom.output_index(n)],
                           atol=1e-12)
    t = np.arange(0.0, 7200.0, 60.0)
    rpm, air = np.where(t < 3600.0, 9000.0, 0.0), np.full(len(t), 20.0)
    T = 20.0 + 0.8 * np.outer(1.0 - np.exp(-t / 1800.0), np.arange(1, 5) / 4)
    a = DriftObserver(rom, placed.names, sensors=placed.sensors).run(t, rpm, air, T)
    b = DriftObserver(rom_with_basis, chosen).run(t, rpm, air, T)
    assert np.allclose(a[0], b[0], atol=1e-9) and np.allclose(a[1], b[1], atol=1e-9)


def test_placement_location_off_the_machine_is_a_clear_error(tmp_path, machine, rom_with_basis):
    from twin.live.placement import placement_rom, read_placement

    csv = _chosen_csv(tmp_path / "chosen.csv", [("s000001", (0.0, 0.28, 0.89)), ("s000002", (3.0, 0.0, 0.0))])
    with pytest.raises(TwinInputError, match=r"chosen.csv: point thermometer s000002 at \(3.0, 0.0, 0.0\) m lies "
                                             r"outside the mesh"):
        placement_rom(rom_with_basis, machine, read_placement(csv))
    with pytest.raises(TwinInputError, match="chosen.csv: no sensor chosen for axis 'Y'; axes: Z"):
        read_placement(csv, "Y")
    csv.write_text(csv.read_text().replace("3.0,0.0,0.0", "3.0,abc,0.0"))
    with pytest.raises(TwinInputError, match="chosen.csv: s000002 y_m must be a number"):
        read_placement(csv)


@pytest.mark.slow          # two machine builds and a server start-up through the CLI: 30–70 s under load
def test_twin_live_takes_the_thermometers_a_placement_chose(tmp_path, machine, monkeypatch, capsys):
    """``twin live --replay … --thermometers-from chosen.csv``: the chosen locations are fused (the dataset names
    them as ``twin place`` datasets do); a location off the machine is one line naming the file and the point."""
    from twin.cli import main

    monkeypatch.chdir(tmp_path)
    position = {c.name: c.position for c in machine.channels}
    good = _chosen_csv(tmp_path / "good.csv", [("s_a", position["T18"]), ("s_b", position["T09"])])
    bad = _chosen_csv(tmp_path / "bad.csv", [("s_a", position["T18"]), ("s_c", (0.0, 3.0, 0.5))])
    t = np.arange(40) * 10.0
    rows = [f"{ti:g},9000,20,{20 + 1e-3 * ti:.4f},{20 + 5e-4 * ti:.4f}" for ti in t]
    (tmp_path / "rec.csv").write_text("time_s,spindle_rpm,T15_degC,s_a_degC,s_b_degC\n" + "\n".join(rows) + "\n")
    assert main(["live", "--replay", "rec.csv", "--thermometers-from", "bad.csv"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.csv: point thermometer s_c at (0.0, 3.0, 0.5) m lies outside" in err
    assert main(["live", "--replay", "rec.csv", "--thermometers-from", str(good), "--speed", "2000"]) == 0
    out = capsys.readouterr().out
    assert "fused 40 samples" in out and "from s_a, s_b + spindle speed + room air" in out


def test_choose_thermometers_among_placement_points(tmp_path, machine, rom_with_basis):
    """choose_thermometers picks among point outputs added to the ROM as among its own thermometers; a point
    at a machine thermometer's position is worth exactly that thermometer."""
    from twin.live.observer import choose_thermometers
    from twin.live.placement import placement_rom, read_placement

    position = {c.name: c.position for c in machine.channels}
    placed = read_placement(_chosen_csv(tmp_path / "c.csv", [("pT18", position["T18"]),
                                                                      ("pT03", position["T03"])]))
    rom = placement_rom(rom_with_basis, machine, placed)
    assert choose_thermometers(rom, 1, "Z", ["pT03", "pT18"], step_s=900.0) == \
        [{"T03": "pT03", "T18": "pT18"}[choose_thermometers(rom, 1, "Z", ["T03", "T18"], step_s=900.0)[0]]]


def test_camera_spots_share_one_offset(rom_with_basis, machine):
    """An S65 thermal camera has one offset for all its spots (twin.core.noise): the observer gives the spots one
    offset state together and every DS18S20 thermometer one of its own."""
    from twin.live.model import ObserverModel
    from twin.rom.points import with_point_thermometers

    position = {c.name: c.position for c in machine.channels}
    rom = with_point_thermometers(rom_with_basis, machine, ["cam1", "cam2"], [position["T03"], position["T05"]])
    model = ObserverModel(rom, ["T18", "cam1", "cam2"], sensors={"cam1": "S65", "cam2": "S65"})
    offsets = model.H[:, model.n + model.q:]
    assert offsets.shape == (3, 2) and np.array_equal(offsets, [[1, 0], [0, 1], [0, 1]])
    assert model.R[1] == model.R[2] > model.R[0]


# ----------------------------------------------------------------------------- node map
def test_node_map_errors_name_file_and_key(tmp_path):
    path = tmp_path / "map.toml"
    path.write_text('[inputs]\nspindle_speed = "ns=2;s=spindle"\n[thermometers]\nT01 = "ns=2;s=T01"\n')
    with pytest.raises(TwinInputError, match=r"map.toml: \[inputs\] has no room_air"):
        load_node_map(path)
    path.write_text('[inputs]\nspindle_speed = "ns=2;s=spindle"\nroom_air = "T15"\n[thermometers]\nT01 = 3\n')
    with pytest.raises(TwinInputError, match=r"map.toml: \[inputs\] room_air = 'T15': not an OPC UA node id"):
        load_node_map(path)
    path.write_text("[inputs\n")
    with pytest.raises(TwinInputError, match="map.toml: not valid TOML"):
        load_node_map(path)


def test_wrong_node_map_names_file_and_node(tmp_path, rom):
    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            node_map = default_node_map(THERMOMETERS, "T15", index=server.index)
            node_map.thermometers[THERMOMETERS[2]] = f"ns={server.index};s=T99"
            node_map.source = str(tmp_path / "machine.toml")
            client = LiveClient(server.endpoint, node_map, DriftObserver(rom, THERMOMETERS))
            await client.run(max_wall_s=20)

    with pytest.raises(TwinInputError, match=rf"machine.toml: \[thermometers\] {THERMOMETERS[2]} = "
                                             r"'ns=2;s=T99': no such node on opc.tcp://127.0.0.1"):
        asyncio.run(main())


# ----------------------------------------------------------------------------- replay, reconnect, NaN and late
def test_replay_speed_and_every_sample_fused_in_order(tmp_path, rom):
    t = np.arange(40) * 10.0
    values = np.array([_sample(ti) for ti in t])
    speed = 400.0

    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            client = _client(server, rom, tmp_path)
            task = asyncio.create_task(client.run(until_time_s=t[-1], max_wall_s=60))
            await _until_subscribed(client, task)
            wall = await server.replay(t, values, speed)
            stats = await task
            return wall, stats, await server.read_output("Z"), await server.read_output("Z_compensation")

    wall, stats, z_node, comp_node = asyncio.run(main())
    assert (t[-1] - t[0]) / speed <= wall < (t[-1] - t[0]) / speed + 5.0
    times = [h[0] for h in stats.history]
    assert times == list(t)                                      # every sample, in order, at its machine time
    assert stats.late == 0 and stats.reconnects == 0
    assert z_node == pytest.approx(stats.last.drift_um[2]) and comp_node == pytest.approx(-z_node)
    log = np.genfromtxt(tmp_path / "log.csv", delimiter=",", names=True)
    assert "Z_estimate_um" in log.dtype.names and np.allclose(log["time_s"], t)
    assert not (tmp_path / "log.csv.part").exists()


@pytest.mark.slow          # two server start-ups (asyncua builds its address space: 5–10 s each under load)
def test_reconnect_after_server_restart(rom):
    port = free_port()

    async def main():
        async with ReplayServer(CHANNELS, port=port) as server:
            client = _client(server, rom, backoff_s=0.1)
            task = asyncio.create_task(client.run(until_time_s=190.0, max_wall_s=90))
            await _until_subscribed(client, task)
            for k in range(10):
                await server.publish(10.0 * k, _sample(10.0 * k))
            while len(client.stats.history) < 10:
                await asyncio.sleep(0.02)
        client._subscribed = False
        async with ReplayServer(CHANNELS, port=port) as server:       # the machine is back
            await _until_subscribed(client, task)
            for k in range(10, 20):
                await server.publish(10.0 * k, _sample(10.0 * k))
                await asyncio.sleep(0.01)
            return await task

    stats = asyncio.run(main())
    assert stats.reconnects >= 1
    times = [h[0] for h in stats.history]
    assert times[:10] == [10.0 * k for k in range(10)] and times[-1] == 190.0


def test_nan_missing_and_late_samples(rom):
    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            client = _client(server, rom, late_after_s=0.3)
            task = asyncio.create_task(client.run(until_time_s=40.0, max_wall_s=60))
            await _until_subscribed(client, task)
            await server.publish(0.0, _sample(0.0))
            nan = _sample(10.0)
            nan[3] = np.nan                                            # a NaN reading
            await server.publish(10.0, nan)
            await server.publish(20.0, _sample(20.0)[:-1], CHANNELS[:-1])   # one node never reports
            while client.samples.done_until < 20.0 and not task.done():     # fused late_after_s after, under any load
                await asyncio.sleep(0.01)
            await server.publish(15.0, _sample(15.0))                  # late: 20 s was fused already
            await server.publish(30.0, _sample(30.0))
            await server.publish(40.0, _sample(40.0))
            return await task

    stats = asyncio.run(main())
    assert [h[0] for h in stats.history] == [0.0, 10.0, 20.0, 30.0, 40.0]
    assert stats.late == len(CHANNELS)
    assert stats.missing == 2 + 6                                       # NaN, absent, and the empty start sample
    assert np.all(np.isfinite(np.array([h[1] for h in stats.history])))


# ----------------------------------------------------------------------------- command line: inputs, ends, exit codes
def _dataset_with_camera(path, spots=30):
    """A small twin-made dataset (CSV + sidecar) with the replayed channels and a camera's spots."""
    from twin.core.dataset import ChannelInfo, Dataset

    channels = [ChannelInfo("spindle", "rpm", "spindle_speed", "", None), ChannelInfo("T15", "degC", "air", "", None),
                *(ChannelInfo(t, "degC", "temperature", "", None) for t in THERMOMETERS),
                *(ChannelInfo(f"cam{i:03d}", "degC", "camera", "", None) for i in range(spots))]
    t = np.arange(3) * 10.0
    Dataset(t, np.full((len(t), len(channels)), 20.0), channels).write(path)
    return path


@pytest.mark.parametrize("target", ["dataset", "sidecar"])
def test_log_never_replaces_the_replayed_dataset(tmp_path, capsys, target):
    dataset = _dataset_with_camera(tmp_path / "rec.csv")
    log = {"dataset": dataset, "sidecar": tmp_path / "rec.csv.json"}[target]
    before = log.read_bytes()
    assert twin_main(["live", "--replay", str(dataset), "--log", str(log), "--overwrite"]) == 2
    assert "the output would replace an input of this command" in capsys.readouterr().err
    assert log.read_bytes() == before


def test_log_never_replaces_the_node_map(tmp_path, capsys):
    node_map = tmp_path / "machine.toml"
    node_map.write_text(default_node_map(THERMOMETERS).to_toml())
    assert twin_main(["live", "--endpoint", f"opc.tcp://127.0.0.1:{free_port()}/", "--node-map", str(node_map),
                 "--log", str(node_map), "--overwrite", "--duration", "0.5"]) == 2
    assert "machine.toml: the output would replace an input of this command" in capsys.readouterr().err


@pytest.mark.parametrize("url", ["http://foo", "opc.tcp:///path", "opc.tcp://host:port/"])
def test_endpoint_that_is_no_opc_tcp_address_is_refused(tmp_path, capsys, url):
    node_map = tmp_path / "machine.toml"
    node_map.write_text(default_node_map(THERMOMETERS).to_toml())
    assert twin_main(["live", "--endpoint", url, "--node-map", str(node_map), "--duration", "5"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"twin live: error: --endpoint {url!r}: not an OPC UA address; use opc.tcp://HOST:PORT/…"


def test_unknown_room_air_lists_the_air_and_temperature_channels_not_the_camera_spots(tmp_path, capsys):
    dataset = _dataset_with_camera(tmp_path / "rec.csv")
    assert twin_main(["live", "--replay", str(dataset), "--room-air", "NOPE"]) == 2
    err = capsys.readouterr().err
    assert f"--room-air 'NOPE': no such channel in {dataset}" in err
    assert "T15" in err and THERMOMETERS[0] in err and "cam001" not in err


@pytest.mark.parametrize("late_after", ["nan", "inf", "-1"])
def test_a_late_after_that_never_or_always_fuses_at_once_is_refused(tmp_path, capsys, late_after):
    """NaN or ∞ would hold an incomplete sample for ever, a negative value fuse every sample at once."""
    dataset = _dataset_with_camera(tmp_path / "rec.csv")
    assert twin_main(["live", "--replay", str(dataset), "--late-after", late_after]) == 2
    assert f"--late-after must be a finite number of seconds ≥ 0, got {late_after}" in capsys.readouterr().err


def test_nothing_listening_exits_1_counting_every_failed_attempt(tmp_path, capsys):
    node_map = tmp_path / "machine.toml"
    node_map.write_text(default_node_map(THERMOMETERS).to_toml())
    endpoint = f"opc.tcp://127.0.0.1:{free_port()}/x/"
    assert twin_main(["live", "--endpoint", endpoint, "--node-map", str(node_map), "--duration", "0.5",
                      "--log", str(tmp_path / "drift.csv")]) == EXIT_NOT_OBSERVED == 1
    out, err = capsys.readouterr()
    assert "fused 0 samples" in out and "reconnects 0, failed connection attempts " in out
    assert "failed connection attempts 0" not in out and "log written" not in out
    assert f"twin live: the session ended disconnected from --endpoint {endpoint} after " in err
    assert not list(tmp_path.glob("drift.csv*"))


def test_server_gone_for_good_counts_the_failed_reconnects(rom):
    async def main():
        async with ReplayServer(CHANNELS, port=free_port()) as server:
            client = _client(server, rom, backoff_s=0.01, max_backoff_s=0.01)
            task = asyncio.create_task(client.run(max_wall_s=60))
            await _until_subscribed(client, task)
            await server.publish(0.0, _sample(0.0))
            while not client.stats.samples:
                await asyncio.sleep(0.02)
        while client.stats.failed_attempts < 2:                     # the server is gone: attempts fail
            await asyncio.sleep(0.02)
        task.cancel()
        return client.stats

    stats = asyncio.run(main())
    assert stats.samples == 1 and stats.reconnects == 0 and stats.failed_attempts >= 2
    assert not stats.ended_connected and stats.last_error


def test_replay_honours_late_after(tmp_path, rom, monkeypatch):
    from twin.core.dataset import Dataset

    waits = []

    class Recorded(LiveClient):
        def __init__(self, *args, **kw):
            super().__init__(*args, **kw)
            waits.append(self.late_after_s)

    monkeypatch.setattr("twin.live.client.LiveClient", Recorded)
    dataset = Dataset.read(_dataset_with_camera(tmp_path / "rec.csv", spots=0))
    stats, _ = asyncio.run(replay_session(dataset, THERMOMETERS, DriftObserver(rom, THERMOMETERS), speed=100.0,
                                          port=free_port(), late_after_s=0.25))
    assert waits == [0.25] and stats.samples == 3
