"""Print the measured errors and orders of the fea verification suite (the figures of docs/verification.md).

The numbers come from the same functions that ``tests/test_fea_heat_verification.py``
and ``tests/test_fea_elastic_verification.py`` assert on, so the document and
the tests cannot drift apart.

    python bench/verification_orders.py            # default suite (about 15 s)
    python bench/verification_orders.py --slow     # adds the 3-D cube and the finest P1 beams (about 1 min)
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parents[1] / "tests"


def _load(name):
    spec = importlib.util.spec_from_file_location(name, TESTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _table(title, label, sizes, errors, theory=None):
    orders = _orders(sizes, errors)
    print(f"\n{title}" + (f"  (theory: order {theory})" if theory is not None else ""))
    print(f"  {label:>12}  {'error':>10}  {'order':>6}")
    for i, (h, e) in enumerate(zip(sizes, errors)):
        print(f"  {h:>12.4g}  {e:>10.3e}  {orders[i - 1]:>6.2f}" if i else f"  {h:>12.4g}  {e:>10.3e}  {'':>6}")


def _orders(sizes, errors):
    sizes, errors = np.asarray(sizes, float), np.asarray(errors, float)
    return np.log(errors[:-1] / errors[1:]) / np.log(sizes[:-1] / sizes[1:])


def _sequence(title, meshes, errors):
    print(f"\n{title}")
    print(f"  {'cells (x, y, z)':>16}  {'rel. error':>10}")
    for cells, e in zip(meshes, errors):
        print(f"  {str(cells):>16}  {e:>10.3e}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slow", action="store_true", help="include the slow refinements")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    heat = _load("test_fea_heat_verification")
    elastic = _load("test_fea_elastic_verification")

    print("== heat: transient slab against the Fourier series (L2 error at t = 0.1 s, °C per °C of amplitude)")
    _table("P1 in space, Crank-Nicolson dt = 5e-4 s", "h (m)", *heat.slab_space_study(), theory=2)
    _table("backward Euler, 1024 cells", "dt (s)", *heat.slab_time_study(1.0, heat.SLAB_BE_STEPS), theory=1)
    _table("Crank-Nicolson, 1024 cells", "dt (s)", *heat.slab_time_study(0.5, heat.SLAB_CN_STEPS), theory=2)
    cube_cells = (4, 8, 16, 32) if args.slow else (4, 8, 16)
    _table("unit cube sin·sin·sin mode, P1 in space (CN dt = 2.5e-4 s, t = 0.02 s)", "h (m)",
           *heat.cube_space_study(cube_cells), theory=2)

    print("\n== heat: NAFEMS T3, time-step error estimated by step doubling against the truth (CN, dt/64)")
    for theta in (1.0, 0.5):
        r = heat.nafems_t3_step_error(theta)
        name = "Crank-Nicolson" if theta == 0.5 else "backward Euler"
        print(f"{name} dt = 0.5 s: T(0.08 m, 32 s) = {r['T_32']:.4f} °C (truth {r['truth_32']:.4f}, NAFEMS "
              f"{heat.NAFEMS_T3_REFERENCE_C}); error at 32 s estimated {r['estimated_32']:+.4f} K, true "
              f"{r['true_32']:+.4f} K; largest over 0-32 s estimated {r['estimated_max']:.4f} K, true {r['true_max']:.4f} K")

    print("\n== heat: steady, lumped, radiation, joints, energy")
    profile, surface = heat.steady_slab_errors()
    print(f"slab with source + convection: max error / rise {profile:.2e} (faces {surface:.2e})")
    fin_profile, fin_rate = heat.fin_errors()
    print(f"pin fin cosh profile: max error / (T_b − T∞) {fin_profile:.2e}; heat rate rel. error {fin_rate:.2e}")
    lumped, one_percent = heat.lumped_cooling_error()
    print(f"lumped cooling: max |θ/θ0 − exp(−t/τ)| {lumped:.2e} (a 1 % error in τ gives {one_percent:.2e})")
    for theta, dt in ((0.5, 2.0), (1.0, 2.0)):
        err, final, linear = heat.radiation_cooling_error(theta, dt)
        name = "Crank-Nicolson" if theta == 0.5 else "backward Euler"
        print(f"full T⁴ radiation 500 → {final:.1f} °C, {name} dt = {dt:g} s: max error {err:.2e} K "
              f"(linearisation about 20 °C would be off by {linear:.1f} K)")
    _table("full T⁴ radiation, Crank-Nicolson, error at t = 600 s (K)", "dt (s)", *heat.radiation_time_study(), theory=2)
    print(f"linearised radiation vs exponential: max error {heat.linearised_radiation_error():.2e} K")
    drops, hot = heat.contact_joint_drop()
    expected = heat.Q_JOINT / heat.H_CONTACT
    print(f"contact joint: drop {drops.mean():.12f} K vs q/h_c = {expected} K "
          f"(max rel. error {np.abs(drops / expected - 1).max():.1e}); hot-end error {hot:.1e} K")
    layer = heat.thin_layer_drop()
    print(f"thin layer k = h_c·t: drop {layer:.12f} K (rel. error {abs(layer / expected - 1):.1e})")
    for theta in (1.0, 0.5):
        for full in (False, True):
            stored, imbalance = heat.energy_balance(theta, radiation_full=full)
            print(f"energy balance θ = {theta}, {'full' if full else 'linearised'} radiation: "
                  f"ΔE = {stored:.4e} J, |imbalance| / gross = {imbalance:.1e}")

    print("\n== elasticity")
    for degree in (1, 2):
        du, ds = elastic.free_expansion_errors(degree)
        print(f"free expansion P{degree}: max |u − αΔT x| / (αΔT L) {du:.1e}; max |σ| / ((3λ+2μ)αΔT) {ds:.1e}")
    p2_exact, p2_grad = elastic.gradient_beam_study(2, elastic.P2_BEAM_MESHES)
    _sequence(f"free beam, linear through-depth ΔT, κ = αΔT/h = {p2_exact:.6g} 1/m: P2", elastic.P2_BEAM_MESHES, p2_grad)
    grad_meshes = elastic.P1_GRADIENT_MESHES if args.slow else elastic.P1_GRADIENT_MESHES[:3]
    _, p1_grad = elastic.gradient_beam_study(1, grad_meshes)
    _sequence("  same, P1 (ν = 0.3: width refined with depth)", grad_meshes, p1_grad)
    _, p1_stall = elastic.gradient_beam_study(1, elastic.P1_BEAM_MESHES)
    _sequence("  same, P1 with one cell across the width (does not converge)", elastic.P1_BEAM_MESHES, p1_stall)
    bimetal_exact, p2_bi = elastic.bimetal_study(2, elastic.P2_BEAM_MESHES)
    _sequence(f"bimetal strip, Timoshenko κ = {bimetal_exact:.6g} 1/m: P2", elastic.P2_BEAM_MESHES, p2_bi)
    _, p2_nu = elastic.bimetal_study(2, elastic.P2_BEAM_MESHES, poisson=(0.3, 0.3))
    _sequence("  same, ν = 0.3 in both layers: P2", elastic.P2_BEAM_MESHES, p2_nu)
    _, p2_mixed = elastic.bimetal_study(2, elastic.P2_BEAM_MESHES, poisson=(0.3, 0.33))
    _sequence("  same, ν = 0.30 / 0.33 (unequal; the formula leaves the coupling out): P2", elastic.P2_BEAM_MESHES,
              p2_mixed)
    bi_meshes = elastic.P1_BEAM_MESHES + (((320, 1, 32),) if args.slow else ())
    _, p1_bi = elastic.bimetal_study(1, bi_meshes)
    _sequence("  same, P1", bi_meshes, p1_bi)
    print("  P1 observed orders: " + ", ".join(f"{o:.2f}" for o in np.log2(np.array(p1_bi[:-1]) / np.array(p1_bi[1:]))))
    for degree in (1, 2):
        y, direct, _ = elastic.adjoint_direct_mismatch(degree)
        rel = np.abs(y - direct) / np.abs(direct)
        print(f"adjoint vs direct P{degree}: max rel. difference {rel.max():.1e} over {len(y)} outputs "
              f"({', '.join(s.name for s in elastic.SPECS)})")
    print(f"\n(total {time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    sys.exit(main())
