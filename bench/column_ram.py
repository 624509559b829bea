#!/usr/bin/env python
"""Shared FE benchmark "column-ram" (transient heat + quasi-static thermo-elasticity) with ``fea``.

The problem, meshes and reference results live in the shared benchmark folder
(``problem.md``; another folder with the environment variable ``COLUMN_RAM_DATA``).  One run:

  read the .vtu → mesh and facet groups → heat assembly → output operator (3
  point temperatures, and the tool-to-workpiece displacement d by 3 adjoint
  elastic solves, computed in a forked worker while the heat run goes on) →
  backward Euler, dt = 60 s, 480 steps, outputs at every step.

It reports the times of the phases, the wall time from reading the .vtu to
having every output (without and with interpreter start and imports), the
peak memory, the acceptance of problem.md §7 with the largest deviation over
all 480 steps, and checks the mesh facts of ``column_ram_<mesh>.json``.  It
exits non-zero if the acceptance or a fact check fails.

``--naive`` also times the straightforward alternative: a forward elastic
solve (same AMG hierarchy, same tolerance) at every step instead of adjoint
outputs.  On the fine mesh that takes minutes, so by default it solves at
every 20th step only and extrapolates to 480 solves (``--naive-steps``).

Every case runs in a fresh interpreter; ``--repeat N`` runs it N times and
reports the fastest (other jobs may share the machine).

    python bench/column_ram.py [coarse|fine|all] [--naive] [--repeat N] [--serial] [--json FILE]
"""
from __future__ import annotations

import time

SCRIPT_START = time.perf_counter()

import argparse  # noqa: E402
import hashlib  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

#: The shared benchmark folder: ``../shared/bench/column_ram`` beside the repository, or $COLUMN_RAM_DATA.
DATA = Path(os.environ.get("COLUMN_RAM_DATA")
            or Path(__file__).resolve().parents[2] / "shared" / "bench" / "column_ram")
N_STEPS, DT = 480, 60.0
REPORT_STEPS = (120, 240, 480)
T_TOL_K, D_TOL_REL = 0.05, 0.02
A_TIP, W_REF = (0.0, 0.65, 0.45), (0.0, 0.45, 0.0)
PROBES = {"T_A": (0.0, 0.65, 0.46), "T_B": (0.18, 0.65, 0.875), "T_C": (0.0, 0.0, 0.60)}
SUPPORTS = ((-0.25, 0.0, 0.0), (0.25, 0.0, 0.0), (-0.25, 0.45, 0.0))
OUTPUT_NAMES = ["T_A", "T_B", "T_C", "dx", "dy", "dz"]


def seconds_since_process_start():
    """Wall time since this interpreter started (Linux /proc), or None elsewhere."""
    try:
        start_ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return uptime - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # Linux: kB


# ---------------------------------------------------------------------- the problem
def ambient(t):
    return 20.0 + 2.5 * np.sin(2.0 * np.pi * np.asarray(t) / 86400.0)


def power(t):
    return np.where(np.asarray(t) < 14400.0, 150.0, 0.0)


def setup(fea, pv, name):
    """Read the mesh and build the heat problem (shared by the adjoint and naive runs)."""
    t = {}
    start = time.perf_counter()
    grid = pv.read(DATA / f"column_ram_{name}.vtu")
    t["read_s"] = time.perf_counter() - start
    mark = time.perf_counter()
    mesh = fea.TetMesh.from_pyvista(grid, "part")
    mesh.add_facet_group("convection", fea.Predicate(lambda c, n: c[:, 2] > 1e-3, "z > 1 mm"))
    mesh.add_facet_group("heated", fea.Predicate(
        lambda c, n: (c[:, 2] < 0.55) & (np.abs(c[:, 0]) <= 0.0901) & (np.abs(c[:, 1] - 0.65) <= 0.0901),
        "ram bottom 0.1 m"))
    t["mesh_s"] = time.perf_counter() - mark
    mark = time.perf_counter()
    materials = {region: fea.CAST_IRON for region in (1, 2, 3)}
    heat = fea.HeatProblem(mesh, materials)
    heat.add_convection("convection", 8.0, ambient="ambient")
    heat.add_heat_flux("heated", power="power")
    system = heat.assemble()
    t["heat_assembly_s"] = time.perf_counter() - mark
    elastic = fea.ElasticProblem(mesh, materials, degree=1, reference_temperature=20.0)
    elastic.add_kinematic_mount(*SUPPORTS)
    schedule = fea.InputSchedule(system, {"ambient": ambient, "power": power})
    return start, t, mesh, system, elastic, schedule


def output_specs(fea):
    return ([fea.PointTemperature(k, p) for k, p in PROBES.items()]
            + [fea.RelativeDisplacement(f"d{c}", A_TIP, W_REF, c) for c in "xyz"])


def factorise(fea, system, schedule, backend=None):
    """Factorise the step matrix through the public API: one step with a fresh solver (factor cached)."""
    solver = fea.ThermalSolver(system, theta=1.0, backend=backend)
    u = schedule.sample([0.0, DT])
    mark = time.perf_counter()
    solver.step(np.full(system.n_nodes, 20.0), u[0], u[1], DT)
    return solver, time.perf_counter() - mark


def run_adjoint(name, concurrent=True, backend=None):
    """The benchmark run: adjoint (influence) outputs, optionally computed concurrently."""
    import pyvista as pv

    import fea
    imports_s = time.perf_counter() - SCRIPT_START
    start, t, mesh, system, elastic, schedule = setup(fea, pv, name)
    mark = time.perf_counter()
    outputs = fea.build_output_operator(output_specs(fea), system, elastic, concurrent=concurrent)
    t["output_operator_s"] = time.perf_counter() - mark
    solver, t["factor_and_first_step_s"] = factorise(fea, system, schedule, backend)
    times = np.arange(N_STEPS + 1) * DT
    stamps = []
    mark = time.perf_counter()
    result = solver.run(20.0, times, schedule, outputs,
                        progress=lambda k, n: stamps.append((time.perf_counter(), len(outputs.deferred_rows) == 0)))
    end = time.perf_counter()
    t["loop_s"] = end - mark
    t["run_s"] = end - start
    since_start = seconds_since_process_start()
    t["process_s"] = since_start if since_start is not None else end - SCRIPT_START
    t["imports_s"] = imports_s
    t["per_step_ms"] = 1e3 * t["loop_s"] / N_STEPS
    arrived = next((k + 1 for k, (_, ready) in enumerate(stamps) if ready), None)
    t["rows_arrived_after_step"] = arrived
    t["wait_for_rows_s"] = end - stamps[-1][0]
    if arrived is not None and arrived < N_STEPS:
        later = np.diff([s for s, _ in stamps[arrived - 1:]])
        t["per_step_after_rows_ms"] = 1e3 * float(np.median(later))
    t["factorisation_s"] = t["factor_and_first_step_s"] - 1e-3 * t.get("per_step_after_rows_ms", t["per_step_ms"])
    stats = dict(outputs.stats)
    heat_solve = solver._factors(DT)[4]
    t["heat_backend"] = backend or fea.linsolve.default_backend()
    t["single_precision_solves_per_step"] = getattr(heat_solve, "solves", 0) / (N_STEPS + 1) or None
    return dict(mesh=name, mode="adjoint-concurrent" if concurrent and stats.get("worker_peak_rss_bytes")
                else "adjoint-serial", times=t, elastic=stats, outputs=result.outputs.tolist(),
                peak_rss_mb=peak_rss_mb(),
                worker_peak_rss_mb=(stats.get("worker_peak_rss_bytes") or 0) / 2**20 or None,
                facts=check_facts(fea, name, mesh, system))


def run_naive(name, every=1):
    """A forward elastic solve per step (at every ``every``-th step, extrapolated to all steps)."""
    import pyvista as pv

    import fea
    start, t, mesh, system, elastic, schedule = setup(fea, pv, name)
    mark = time.perf_counter()
    temperatures = fea.build_output_operator(output_specs(fea)[:3], system)
    rows = elastic.point_rows([A_TIP] * 3 + [W_REF] * 3, "xyzxyz")
    L = (rows[:3] - rows[3:]).tocsr()
    F = elastic.thermal_load_operator(system)
    elastic.solve_load(np.zeros(elastic.n_dofs))          # stiffness, supports and AMG set-up
    t["elastic_setup_s"] = time.perf_counter() - mark
    solver, t["factor_and_first_step_s"] = factorise(fea, system, schedule)
    u = schedule.sample(np.arange(N_STEPS + 1) * DT)
    T = np.full(system.n_nodes, 20.0)
    out = np.full((N_STEPS + 1, 6), np.nan)
    out[0, :3], out[0, 3:] = temperatures.apply(T), 0.0
    solve_times = []
    mark = time.perf_counter()
    for k in range(1, N_STEPS + 1):
        T = solver.step(T, u[k - 1], u[k], DT)
        out[k, :3] = temperatures.apply(T)
        if k % every == 0:
            s = time.perf_counter()
            out[k, 3:] = L @ elastic.solve_load(F @ (T - 20.0))
            solve_times.append(time.perf_counter() - s)
    end = time.perf_counter()
    t["loop_s"] = end - mark
    t["run_s"] = end - start
    t["elastic_solves"] = len(solve_times)
    t["elastic_solve_mean_s"] = float(np.mean(solve_times))
    t["estimated_run_s"] = t["run_s"] + (N_STEPS - len(solve_times)) * t["elastic_solve_mean_s"]
    return dict(mesh=name, mode="naive", every=every, times=t, elastic=dict(elastic.stats),
                outputs=out.tolist(), peak_rss_mb=peak_rss_mb())


# ---------------------------------------------------------------------- checks
def acceptance(name, outputs):
    """problem.md §7 at the report times, and the largest deviations over every step computed."""
    ref = np.loadtxt(DATA / f"reference_{name}.csv", delimiter=",", skiprows=1)
    y = np.array(outputs, dtype=float)
    y[:, 3:] *= 1e6                                                  # m → µm
    dT = np.abs(y[:, :3] - ref[:, 2:5])
    dd = np.linalg.norm(y[:, 3:] - ref[:, 5:8], axis=1)
    dref = np.linalg.norm(ref[:, 5:8], axis=1)
    have = np.isfinite(dd)
    have[0] = False                                                  # d_ref = 0 at t = 0
    report = {}
    ok = True
    for k in REPORT_STEPS:
        rel = float(dd[k] / dref[k]) if np.isfinite(dd[k]) else None
        passed = bool(dT[k].max() <= T_TOL_K) and (rel is None or rel <= D_TOL_REL)
        ok &= passed
        report[k] = dict(T=y[k, :3].tolist(), d_um=y[k, 3:].tolist(), max_dT_K=float(dT[k].max()),
                         d_rel=rel, passed=passed)
    return dict(passed=bool(ok), report=report, max_dT_K=float(dT.max()),
                max_dd_um=float(dd[have].max()), max_dd_rel=float((dd[have] / dref[have]).max()),
                steps_with_d=int(have.sum()))


def check_facts(fea, name, mesh, system):
    """Compare the mesh with column_ram_<mesh>.json; returns a list of failures (empty when all agree)."""
    facts = json.loads((DATA / f"column_ram_{name}.json").read_text())
    failures = []

    def expect(label, ours, theirs, rel=1e-9):
        if isinstance(theirs, int):
            good = int(ours) == theirs
        else:
            good = abs(float(ours) - float(theirs)) <= rel * max(abs(float(theirs)), 1e-30)
        if not good:
            failures.append(f"{label}: ours {ours!r}, facts {theirs!r}")

    digest = hashlib.sha256((DATA / facts["file"]).read_bytes()).hexdigest()
    if digest != facts["sha256"]:
        failures.append(f"sha256 of {facts['file']} differs")
    expect("points", mesh.n_nodes, facts["n_points"])
    expect("cells", mesh.n_tets, facts["n_cells"])
    volumes = mesh.volumes
    expect("volume", volumes.sum(), facts["volume_m3"], 1e-12)
    for part, v in facts["part_volume_m3"].items():
        expect(f"volume of part {part}", volumes[mesh.regions == int(part)].sum(), v, 1e-12)
    expect("min tet volume", volumes.min(), facts["min_tet_volume_m3"], 1e-9)
    tet, local = mesh.boundary_facets()
    centroids, _, areas = mesh.facet_geometry(tet, local)
    groups = {"boundary": np.ones(len(tet), bool), "bottom_adiabatic": centroids[:, 2] <= 1e-3}
    for group in ("convection", "heated"):
        gt, gl = mesh.facet_group(group)
        groups[group] = np.isin(tet * 4 + local, gt * 4 + gl)
    for group, mask in groups.items():
        expect(f"{group} facets", int(mask.sum()), facts["facet_groups"][group]["n_facets"])
        expect(f"{group} area", areas[mask].sum(), facts["facet_groups"][group]["area_m2"], 1e-9)
    for group in ("convection", "heated"):
        expect(f"{group} area (fea)", mesh.facet_group_area(group), facts["facet_groups"][group]["area_m2"], 1e-9)
    for label, probe in facts["probes"].items():
        point = np.array(probe["point"])
        nodes, weights = np.array(probe["nodes"]), np.array(probe["weights"])
        if sorted(mesh.tets[probe["tet"]]) != sorted(nodes):
            failures.append(f"probe {label}: tet {probe['tet']} has nodes {mesh.tets[probe['tet']]}, facts {nodes}")
        if np.abs(weights @ mesh.points[nodes] - point).max() > 1e-12:
            failures.append(f"probe {label}: the facts' weights do not reproduce the point on this mesh")
        ours_tet, ours_w = mesh.locate([point])
        if np.abs(ours_w[0] @ mesh.points[mesh.tets[ours_tet[0]]] - point).max() > 1e-12:
            failures.append(f"probe {label}: fea locates it in tet {ours_tet[0]} with wrong weights")
        if label in ("A", "B", "C"):                         # the P1 rows fea uses for the temperatures
            row = system.point_weights([point]).toarray()[0]
            expected = np.zeros(system.n_nodes)
            np.add.at(expected, nodes, weights)
            if np.abs(row - expected).max() > 1e-9 and ours_tet[0] == probe["tet"]:
                failures.append(f"probe {label}: fea's weights differ from the facts'")
    for label, support in facts["supports"].items():
        d = np.linalg.norm(mesh.points - np.array(support["point"]), axis=1)
        if int(np.argmin(d)) != support["node"] or d.min() != support["distance"]:
            failures.append(f"support {label}: nearest vertex {int(np.argmin(d))} at {d.min():.2e} m, "
                            f"facts {support['node']}")
    return failures


# ---------------------------------------------------------------------- driver
def child(args):
    if args.child == "naive":
        every = args.naive_steps
        if every is None:
            every = 1 if args.mesh == "coarse" else 20
        result = run_naive(args.mesh, every)
    else:
        result = run_adjoint(args.mesh, concurrent=not args.serial, backend=args.backend)
    result["acceptance"] = acceptance(args.mesh, result["outputs"])
    json.dump(result, sys.stdout)


def spawn(mesh, kind, args):
    cmd = [sys.executable, os.path.abspath(__file__), mesh, "--child", kind]
    if args.serial:
        cmd.append("--serial")
    if args.backend:
        cmd += ["--backend", args.backend]
    if args.naive_steps is not None:
        cmd += ["--naive-steps", str(args.naive_steps)]
    launched = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - launched
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr)
        raise SystemExit(f"{mesh} {kind} run failed (exit {proc.returncode})")
    result = json.loads(proc.stdout)
    result["times"]["subprocess_wall_s"] = wall     # launch to exit, including the fact checks
    return result


def fmt(x, unit="s", digits=2):
    return "—" if x is None else f"{x:.{digits}f} {unit}"


def print_adjoint(r, totals):
    t, e, a = r["times"], r["elastic"], r["acceptance"]
    print(f"\n== column-ram {r['mesh']}: {r['mode']}, heat solver {t['heat_backend']} (best of {len(totals)}: "
          + ", ".join(f"{x:.2f}" for x in totals) + " s)")
    print(f"  read .vtu {fmt(t['read_s'])}, mesh+groups {fmt(t['mesh_s'])}, "
          f"heat assembly {fmt(t['heat_assembly_s'])}, output operator {fmt(t['output_operator_s'])}")
    print(f"  heat factorisation {fmt(t['factorisation_s'])}, time loop {fmt(t['loop_s'])} "
          f"= {t['per_step_ms']:.1f} ms/step (outputs included)"
          + (f"; {t['per_step_after_rows_ms']:.1f} ms/step once the elastic rows are in"
             if t.get("per_step_after_rows_ms") else "")
          + (f"; {t['single_precision_solves_per_step']:.2f} single-precision solves/step"
             if t.get("single_precision_solves_per_step") else ""))
    where = "in the worker" if r["mode"] == "adjoint-concurrent" else "in the caller"
    print(f"  elastic ({where}): stiffness {fmt(e.get('stiffness_s'))}, {e.get('solver')} set-up "
          f"{fmt(e.get('solver_setup_s'))}, 3 adjoint solves + Fᵀz {fmt(e.get('influence_solve_s'))}, "
          f"CG iterations {e.get('iterations')}")
    if r["mode"] == "adjoint-concurrent":
        arrived = t["rows_arrived_after_step"]
        print(f"  elastic rows arrived after step {arrived if arrived else '480 (waited ' + fmt(t['wait_for_rows_s']) + ')'}")
    print(f"  TOTAL read .vtu → all outputs: {fmt(t['run_s'])}; from interpreter start (imports "
          f"{fmt(t['imports_s'])}): {fmt(t['process_s'])}")
    worker = f", worker {r['worker_peak_rss_mb']:.0f} MB (includes pages shared with the parent)" \
        if r.get("worker_peak_rss_mb") else ""
    print(f"  peak RSS: main {r['peak_rss_mb']:.0f} MB{worker}")
    print_acceptance(a)
    print("  mesh facts: " + ("all agree" if not r["facts"] else "FAIL: " + "; ".join(r["facts"])))


def print_acceptance(a):
    for k, rep in a["report"].items():
        d = "—" if rep["d_rel"] is None else f"{rep['d_rel']:.1e}"
        print(f"  step {k}: T = {np.round(rep['T'], 4).tolist()} °C, d = {np.round(rep['d_um'], 3).tolist()} µm, "
              f"|ΔT| {rep['max_dT_K']:.1e} K, ‖Δd‖/‖d_ref‖ {d}: {'pass' if rep['passed'] else 'FAIL'}")
    print(f"  over all steps: max |ΔT| {a['max_dT_K']:.1e} K, max ‖Δd‖ {a['max_dd_um']:.1e} µm, "
          f"max ‖Δd‖/‖d_ref‖ {a['max_dd_rel']:.1e} ({a['steps_with_d']} steps with d); "
          f"acceptance {'PASSED' if a['passed'] else 'FAILED'}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mesh", nargs="?", default="all", choices=["coarse", "fine", "all"])
    parser.add_argument("--naive", action="store_true", help="also time an elastic solve at every step")
    parser.add_argument("--naive-steps", type=int, default=None, metavar="K",
                        help="naive run: elastic solve at every K-th step (default 1 coarse, 20 fine)")
    parser.add_argument("--repeat", type=int, default=1, help="runs per case; the fastest is reported")
    parser.add_argument("--serial", action="store_true", help="compute the elastic rows in the caller")
    parser.add_argument("--backend", choices=["superlu", "mixed", "cholmod", "pardiso"],
                        help="heat solver backend (fea.linsolve; default: its automatic choice)")
    parser.add_argument("--json", type=Path, help="write all results to this file")
    parser.add_argument("--child", choices=["adjoint", "naive"], help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args)
    meshes = ["coarse", "fine"] if args.mesh == "all" else [args.mesh]
    results, failed = {}, False
    for mesh in meshes:
        runs = [spawn(mesh, "adjoint", args) for _ in range(max(1, args.repeat))]
        totals = [r["times"]["run_s"] for r in runs]
        best = runs[int(np.argmin(totals))]
        print_adjoint(best, totals)
        failed |= not all(r["acceptance"]["passed"] and not r["facts"] for r in runs)
        results[mesh] = dict(best=best, run_s=totals, process_s=[r["times"]["process_s"] for r in runs])
        if args.naive:
            naive = spawn(mesh, "naive", args)
            t = naive["times"]
            estimated = t["elastic_solves"] < N_STEPS
            total = t["estimated_run_s"] if estimated else t["run_s"]
            print(f"  naive (elastic solve every step, serial): {total:.1f} s"
                  + (f" ESTIMATED from {t['elastic_solves']} solves of mean {t['elastic_solve_mean_s']:.2f} s "
                     f"(measured run {t['run_s']:.1f} s)" if estimated else " measured")
                  + f"; ratio naive / adjoint = {total / best['times']['run_s']:.1f}")
            print_acceptance(naive["acceptance"])
            failed |= not naive["acceptance"]["passed"]
            results[mesh]["naive"] = naive
    if args.json:
        for r in results.values():
            r["best"].pop("outputs", None)
            if "naive" in r:
                r["naive"].pop("outputs", None)
        args.json.write_text(json.dumps(results, indent=1))
    if failed:
        print("\nFAILED: acceptance or mesh facts (see above)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
