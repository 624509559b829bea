"""Reduced-order model: exactness properties, accuracy against the full FE, persistence and errors."""
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp

import fea
from twin.core.scenario import load_scenario
from twin.core.simulate import simulate
from twin.rom.reduction import (DEFAULT_ORDER, FORMAT_VERSION, ROMError, ReducedModel, build_rom, cached_rom,
                                krylov_basis, simulate_rom)
from twin.rom.report import GOAL_TCP_UM, GOAL_TEMPERATURE_K, max_errors


def _fe_outputs(machine, rom, T, u):
    """The machine's channels (edge units) for a temperature field, in the ROM's output order."""
    values = machine.channel_values(machine.outputs.apply(T)[None, :], u[None, :])[0]
    names = [c.name for c in machine.channels]
    return values[[names.index(n) for n in rom.output_names]]


def test_uniform_start_is_exact_and_an_equilibrium(machine, rom):
    assert rom.info["uniform_residual"] < 1e-10
    T0 = 23.5
    u = rom.inputs_from_conditions([0.0], {}, T0)[0]
    z = rom.uniform(T0)
    expected = _fe_outputs(machine, rom, np.full(machine.thermal.n_nodes, T0), u)
    np.testing.assert_allclose(rom.outputs(z, u), expected, rtol=1e-9, atol=1e-9)
    # Uniform T0 with ambient T0 and no power stays put for a day (exact ZOH).
    t = np.arange(0.0, 86400.0 + 1, 600.0)
    Y = rom.simulate(t, np.tile(u, (len(t), 1)), z, "zoh")
    assert np.abs(Y - Y[0]).max() < 1e-9


def test_steady_state_has_the_exact_dc_gain(machine, rom):
    u = rom.inputs_from_conditions([9000.0], {"x": [3000.0], "y": [0.0], "z": [5000.0]},
                                   {z: [21.0 - 1.5 * i] for i, z in enumerate(rom.zones)}, 0.3)[0]
    T = fea.ThermalSolver(machine.thermal).steady_state(u)
    np.testing.assert_allclose(rom.outputs(rom.steady_state(u), u), _fe_outputs(machine, rom, T, u),
                               rtol=1e-7, atol=1e-7)


def test_inputs_from_conditions_match_the_machine(machine, rom):
    rpm = np.array([0.0, 4500.0, 12000.0])
    feeds = {"x": np.array([0.0, 1000.0, 200.0]), "y": np.array([500.0, 0.0, 300.0]), "z": np.array([0.0, 7000.0, 0.0])}
    amb = {z: np.array([20.0, 21.0, 19.0]) - i for i, z in enumerate(rom.zones)}
    np.testing.assert_allclose(rom.inputs_from_conditions(rpm, feeds, amb, 0.2),
                               machine.input_matrix(rpm, feeds, amb, 0.2), rtol=1e-14)


def test_krylov_rom_meets_the_goal_on_the_heat_cool_cycle(machine, rom):
    """Same θ-scheme and grid as the FE: the difference is the reduction error alone."""
    fe = simulate("heat_cool_9000", machine, noise=False).dataset
    errors = max_errors(simulate_rom(rom, "heat_cool_9000", scheme="theta"), fe)
    assert errors["temperature"] <= GOAL_TEMPERATURE_K
    assert errors["displacement"] <= GOAL_TCP_UM
    assert np.abs(fe["Z"]).max() > 5.0      # the cycle does drift


def test_zoh_is_exact_for_held_inputs(rom):
    """One ZOH step of h equals ten of h/10, and the matrix exponential of the continuous system."""
    u = rom.inputs_from_conditions([9000.0], {}, 20.0)[0]
    z0 = rom.uniform(20.0)
    one = rom.states([0.0, 600.0], np.tile(u, (2, 1)), z0, "zoh")[0]
    t = np.linspace(0.0, 600.0, 11)
    ten = rom.states(t, np.tile(u, (len(t), 1)), z0, "zoh")[0]
    np.testing.assert_allclose(one, ten, rtol=1e-10, atol=1e-12)
    ss = rom.state_space()
    n = rom.order
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n] = ss.A
    aug[:n, n] = ss.B @ u
    e = scipy.linalg.expm(aug * 600.0)
    np.testing.assert_allclose(one, e[:n, :n] @ z0 + e[:n, n], rtol=1e-9, atol=1e-9)


def test_state_space_is_stable_and_consistent(rom):
    ss = rom.state_space()
    assert ss.A.shape == (rom.order, rom.order) and ss.B.shape == (rom.order, rom.n_inputs)
    assert ss.C.shape == (rom.n_outputs, rom.order) and ss.D.shape == (rom.n_outputs, rom.n_inputs)
    assert np.all(np.linalg.eigvals(ss.A).real < 0)
    assert {"T01", "X", "Y", "Z", "FBG1"} <= set(ss.output_names)
    np.testing.assert_allclose(ss.initial_state(20.0), rom.uniform(20.0))


def test_modal_truncation_runs_and_is_less_accurate(machine, rom):
    modal = build_rom(machine, 12, "modal")
    krylov = build_rom(machine, 12, "krylov")
    assert modal.method == "modal" and modal.order == 12
    assert np.all(np.diff(modal.eigenvalues) >= 0)
    u = rom.inputs_from_conditions([9000.0], {}, 20.0)[0]
    T = fea.ThermalSolver(machine.thermal).steady_state(u)
    z = rom.output_index("Z")
    exact = _fe_outputs(machine, rom, T, u)[z]
    assert abs(krylov.outputs(krylov.steady_state(u), u)[z] - exact) < 1e-6 * abs(exact)
    assert abs(modal.outputs(modal.steady_state(u), u)[z] - exact) > 1e-3 * abs(exact)


def test_save_load_round_trip_without_pickle(rom, tmp_path):
    path = rom.save(tmp_path / "rom.npz")
    data = np.load(path, allow_pickle=False)            # would raise on object arrays
    assert "meta" in data.files
    back = ReducedModel.load(path)
    for name in ("eigenvalues", "input_matrix", "output_matrix", "feedthrough", "offset", "uniform_state"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rom, name))
    assert back.output_names == rom.output_names and back.digest == rom.digest and back.sources == rom.sources


def test_load_rejects_another_version(rom, tmp_path):
    import json

    path = rom.save(tmp_path / "rom.npz")
    data = dict(np.load(path, allow_pickle=False))
    meta = json.loads(str(data["meta"]))
    meta["version"] = FORMAT_VERSION + 1
    data["meta"] = np.array(json.dumps(meta))
    np.savez(tmp_path / "future.npz", **data)
    with pytest.raises(ROMError, match="version"):
        ReducedModel.load(tmp_path / "future.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ROMError, match="not a readable ROM"):
        ReducedModel.load(tmp_path / "junk.npz")


def test_every_unreadable_file_is_a_rom_error(tmp_path):
    """The narrowed except of ReducedModel.load still catches what a bad file raises (no traceback)."""
    np.savez(tmp_path / "good.npz", meta=np.array("{}"))
    whole = (tmp_path / "good.npz").read_bytes()
    np.savez(tmp_path / "no_meta.npz", eigenvalues=np.ones(2))
    np.savez(tmp_path / "bad_json.npz", meta=np.array("{not json"))
    np.save(tmp_path / "plain.npy", np.ones(3))
    (tmp_path / "empty.npz").write_bytes(b"")
    (tmp_path / "truncated.npz").write_bytes(whole[:len(whole) // 2])
    (tmp_path / "folder.npz").mkdir()
    for name in ("no_meta.npz", "bad_json.npz", "plain.npy", "empty.npz", "truncated.npz", "folder.npz",
                 "missing.npz"):
        with pytest.raises(ROMError, match=f"{name}: not a readable ROM file"):
            ReducedModel.load(tmp_path / name)


def test_a_rebuilt_rom_is_the_same_to_the_last_bit(machine):
    # ARPACK drew its own start vector: the slowest rate, hence the Krylov points and the ROM, changed in the
    # last digits
    for method in ("krylov", "modal"):
        first, second = (build_rom(machine, 20, method) for _ in range(2))
        for name in ("eigenvalues", "input_matrix", "output_matrix", "uniform_state"):
            assert np.array_equal(getattr(first, name), getattr(second, name)), (method, name)


def test_cache_is_keyed_by_the_machine(machine, rom):
    again = cached_rom(machine, DEFAULT_ORDER)
    assert again.info.get("from_cache")
    assert again.digest == rom.digest
    np.testing.assert_array_equal(again.eigenvalues, rom.eigenvalues)


def test_order_too_high_for_the_mesh_is_a_clear_error(machine):
    n = machine.thermal.n_nodes
    with pytest.raises(ROMError, match=f"exceeds the {n} thermal unknowns"):
        build_rom(machine, n + 1)
    with pytest.raises(ROMError, match="too high"):
        build_rom(machine, n, "modal")
    with pytest.raises(ROMError, match="positive"):
        build_rom(machine, 0)


def test_krylov_breakdown_is_a_clear_error():
    """Three distinct eigenvalues: the Krylov space of the input has dimension 3."""
    n = 30
    d = np.repeat([1.0, 2.0, 5.0], n // 3)
    system = SimpleNamespace(n_nodes=n, stiffness=sp.diags(d).tocsr(), mass=sp.identity(n, format="csr"),
                             input_matrix=sp.csr_matrix(np.ones((n, 1))))
    V = krylov_basis(system, 3, [0.0, 0.5])
    np.testing.assert_allclose(V.T @ V, np.eye(3), atol=1e-12)
    with pytest.raises(ROMError, match="broke down at dimension 3"):
        krylov_basis(system, 5, [0.0, 0.5])


def test_rom_runs_the_160h_etve(rom):
    # its speed is measured in bench/bench_rom_fmu.py, not asserted here
    ds = simulate_rom(rom, load_scenario("etve_160h"))
    assert len(ds) == 9601 and np.all(np.isfinite(ds.values))


# ----------------------------------------------------------------------------- plant inputs: zone lags as states
def test_plant_model_takes_what_a_plant_measures(rom):
    assert rom.lagged_zones == ["enclosure"] and rom.zone_lags_s["enclosure"] == pytest.approx(3 * 3600.0)
    assert "ambient:enclosure" not in rom.plant_input_names
    assert set(rom.input_names) - set(rom.plant_input_names) == {"ambient:enclosure"}
    ss = rom.plant_state_space()
    r = rom.order
    assert ss.A.shape == (r + 1, r + 1) and ss.B.shape == (r + 1, len(rom.plant_input_names))
    assert ss.C.shape == (rom.n_outputs, r + 1) and ss.D.shape == (rom.n_outputs, len(rom.plant_input_names))
    assert np.all(np.linalg.eigvals(ss.A).real < 0)
    # the lagged air obeys dw/dt = (room − w)/τ
    room = rom.plant_input_names.index("ambient:room")
    assert ss.A[r, r] == pytest.approx(-1 / 10800.0) and ss.B[r, room] == pytest.approx(1 / 10800.0)
    # a uniform machine in air at the same temperature is an equilibrium; a steady state is one too
    u = rom.plant_inputs_from_conditions([0.0], {}, {"room": 21.0, "front": 21.0})[0]
    assert np.abs(ss.A @ rom.plant_uniform(21.0) + ss.B @ u).max() < 1e-10
    u = rom.plant_inputs_from_conditions([9000.0], {"x": [3000.0]}, {"room": 22.0, "front": 19.0})[0]
    assert np.abs(ss.A @ rom.plant_steady_state(u) + ss.B @ u).max() < 1e-10


def test_plant_zoh_is_exact_against_the_matrix_exponential(rom):
    """Uneven steps, random held plant inputs: the closed-form step equals expm of the augmented system."""
    rng = np.random.default_rng(3)
    t = np.r_[0.0, np.cumsum(rng.uniform(1.0, 5000.0, 25))]
    k = len(t)
    U = rom.plant_inputs_from_conditions(rng.uniform(0, 12000, k), {a: rng.uniform(-5000, 5000, k) for a in "xyz"},
                                         {z: rng.uniform(15, 25, k) for z in rom.measured_zones}, 0.2)
    x0 = rom.plant_uniform(20.0, 17.0)
    X = rom.plant_states(t, U, x0)
    ss = rom.plant_state_space()
    n, m = ss.B.shape
    x = x0
    for i, h in enumerate(np.diff(t)):
        aug = np.zeros((n + m, n + m))
        aug[:n, :n], aug[:n, n:] = ss.A, ss.B
        e = scipy.linalg.expm(aug * h)
        x = e[:n, :n] @ x + e[:n, n:] @ U[i]
        np.testing.assert_allclose(X[i + 1], x, rtol=1e-9, atol=1e-9 * np.abs(x).max())
    np.testing.assert_allclose(rom.plant_outputs(X, U), X @ ss.C.T + U @ ss.D.T + ss.offset, rtol=1e-12, atol=1e-9)


def test_plant_step_has_no_cancellation_when_a_mode_matches_the_lag(rom):
    """λᵢ = 1/τ exactly: the cross term is h e^{−λh}, and it is continuous around it."""
    import dataclasses

    lam = float(rom.eigenvalues[0])
    h = 600.0
    at = dataclasses.replace(rom, zone_lags_s={"enclosure": 1.0 / lam}).plant_step_coefficients(h)[3][0, 0]
    near_rom = dataclasses.replace(rom, zone_lags_s={"enclosure": 1.0 / (lam * (1 + 1e-9))})
    near = near_rom.plant_step_coefficients(h)[3][0, 0]
    assert at == pytest.approx(h * np.exp(-lam * h), rel=1e-14)
    assert near == pytest.approx(at, rel=1e-6)


def test_cli_build_saves_into_a_new_folder(rom, tmp_path):
    from twin.cli import main

    out = tmp_path / "new" / "deeper" / "x.npz"
    assert main(["rom", "build", "--out", str(out)]) == 0
    assert ReducedModel.load(out).digest == rom.digest


def test_cli_build_refuses_a_file_name_that_is_not_npz_before_building(tmp_path, capsys, monkeypatch):
    from twin.cli import main
    from twin.rom import cli

    monkeypatch.setattr(cli, "machine_and_rom", lambda args: pytest.fail("built before the --out check"))
    assert main(["rom", "build", "--out", str(tmp_path / "rom.txt")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"twin rom build: error: {tmp_path / 'rom.txt'}: the file is written as .npz; its name must end in .npz"
    assert not (tmp_path / "rom.txt").exists()


def test_cli_build_of_order_one_prints_its_one_time_constant(capsys):
    from twin.cli import main

    assert main(["rom", "build", "--order", "1"]) == 0
    line = capsys.readouterr().out.splitlines()[1]
    assert "1 states; time constant " in line and "…" not in line, line


def test_error_report_tables_name_units_worst_errors_and_missing_cells():
    from twin.rom.report import ErrorReport, ReportRow, format_markdown, format_summary
    good = {"temperature": 0.5 * GOAL_TEMPERATURE_K, "displacement": 0.5 * GOAL_TCP_UM}
    bad = {"temperature": 2 * GOAL_TEMPERATURE_K, "displacement": 0.5 * GOAL_TCP_UM, "strain": 3.0}
    rows = [ReportRow("a", "krylov", 10, bad, 0.1), ReportRow("b", "krylov", 10, good, 0.1),
            ReportRow("a", "krylov", 20, good, 0.1), ReportRow("b", "krylov", 20, good, 0.1),
            ReportRow("a", "modal", 10, good, 0.1)]
    report = ErrorReport(rows, {"a": 1.0, "b": 2.0}, {"krylov": 1.0}, failures={"c": "no such machine"})
    assert report.passes() == 20 and report.passes("modal") == 10 and report.passes(max_order=10) is None
    summary = format_summary(report).splitlines()
    assert summary[2] == ("| r | krylov T (K) | krylov TCP (µm) | krylov strain (µε) | modal T (K) | modal TCP (µm) "
                          "| modal strain (µε) | Krylov meets the goal on |")
    assert summary[4] == "| 10 | 2.00e-02 | 2.50e-02 | 3.00e+00 | 5.00e-03 | 2.50e-02 | 0.00e+00 | 1/2 |"
    assert summary[5].endswith("| 2/2 |")
    tables = format_markdown(report)
    assert "**a** (full FE run 1.0 s)" in tables and "| 20 | 5.00e-03 | 2.50e-02 | – | – | – | – |" in tables
    assert tables.endswith("- c: not reported (no such machine)")
