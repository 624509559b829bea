"""Error report of reduced models against the full FE twin, over scenarios and orders.

For every scenario (default: all shipped ``scenarios/*.toml``) the full model
runs once (:func:`twin.core.simulate.simulate`, no noise); each ROM then runs the
same scenario with the **same θ-scheme on the same step grid**
(``simulate_rom(..., scheme="theta")``), so the differences are the
reduction error alone, not a difference of time discretisation.  The report
gives, per scenario, method and order, the largest absolute difference over
time and channels of

- surface thermometers (K),
- TCP drift X/Y/Z and Y_top (µm),
- strain lines (µε),

plus, for information, the difference of the exact zero-order-hold ROM (what
the FMUs run) from the FE at the largest order: that one includes the FE's
own backward-Euler time-discretisation error.

Bases are nested in the order (:func:`twin.rom.reduction.compute_basis`), so each method
computes one basis at the largest order and truncates it.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from meshes.tomlspec import DefinitionError

from ..core.scenario import SCENARIOS_DIR, load_scenario
from ..core.simulate import simulate
from ..errors import TwinInputError
from ..infra.cli_common import check_distinct
from ..infra.tables import markdown_table
from .reduction import METHODS, compute_basis, reduce_with_basis, simulate_rom

if TYPE_CHECKING:
    from ..core.dataset import Dataset
    from ..core.machine import Machine
    from ..core.scenario import Scenario

GROUPS = (("temperature", "K"), ("displacement", "um"), ("strain", "ue"))
#: The issue's goals: largest TCP drift and sensor temperature errors with r ≤ 100.
GOAL_TCP_UM = 0.05
GOAL_TEMPERATURE_K = 0.01


@dataclass
class ReportRow:
    """One ROM run of the report against the FE.

    Attributes
    ----------
    scenario : str
    method : str
        ``krylov`` or ``modal``.
    order : int
        Number of states.
    errors : dict of str to float
        Channel kind (``temperature``, ``displacement``, ``strain``) → largest |ROM − FE|, K, µm, µε.
    rom_seconds : float
        Wall time of the ROM run, s.
    """

    scenario: str
    method: str
    order: int
    errors: dict                 # kind → max abs error (K, µm, µε)
    rom_seconds: float

    def meets_goal(self) -> bool:
        """Whether this run meets the issue's TCP and temperature goals.

        Returns
        -------
        bool
            TCP drift error ≤ :data:`GOAL_TCP_UM` µm and thermometer error ≤ :data:`GOAL_TEMPERATURE_K` K
            (a kind the run lacks counts as met).
        """
        return (self.errors.get("displacement", 0.0) <= GOAL_TCP_UM and
                self.errors.get("temperature", 0.0) <= GOAL_TEMPERATURE_K)


@dataclass
class ErrorReport:
    """The result of :func:`error_report`.

    Attributes
    ----------
    rows : list of ReportRow
        One per scenario, method and order.
    fe_seconds : dict of str to float
        Scenario → wall time of its full FE run, s.
    basis_seconds : dict of str to float
        Method → wall time of its largest basis, s.
    zoh_errors : dict
        Scenario → {kind: error} of the zero-order-hold ROM of the first method at the largest order.
    failures : dict of str to str
        Scenario → why it is not in the report.
    """

    rows: list
    fe_seconds: dict             # scenario → wall s of the full FE run
    basis_seconds: dict          # method → wall s of its largest basis
    zoh_errors: dict = field(default_factory=dict)   # scenario → {kind: error} of the ZOH ROM at the largest order
    failures: dict = field(default_factory=dict)     # scenario → message

    def passes(self, method: str = "krylov", max_order: int = 100) -> int | None:
        """Smallest order ≤ max_order meeting the goals on every scenario, or None.

        Parameters
        ----------
        method : str, default "krylov"
        max_order : int, default 100

        Returns
        -------
        int or None
        """
        orders = sorted({r.order for r in self.rows if r.method == method and r.order <= max_order})
        for order in orders:
            rows = [r for r in self.rows if r.method == method and r.order == order]
            if rows and all(r.meets_goal() for r in rows):
                return order
        return None


def shipped_scenarios() -> list[str]:
    """Names of the scenarios shipped in ``scenarios/``, sorted.

    Returns
    -------
    list of str
    """
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))


def max_errors(rom_dataset: Dataset, fe_dataset: Dataset) -> dict[str, float]:
    """Largest |ROM − FE| per channel kind, over time and the channels both datasets have.

    Parameters
    ----------
    rom_dataset, fe_dataset : Dataset
        The same scenario on the same times.

    Returns
    -------
    dict of str to float
        Kind (``temperature``, ``displacement``, ``strain``) → error in K, µm, µε; a kind they do not share is
        absent.
    """
    out = {}
    for kind, _ in GROUPS:
        names = [c.name for c in fe_dataset.channels if c.kind == kind and c.name in rom_dataset]
        if names:
            out[kind] = float(np.abs(rom_dataset.matrix(names) - fe_dataset.matrix(names)).max())
    return out


def check_report_options(orders: Sequence[int], methods: Sequence[str]) -> tuple[list[int], list[str]]:
    """Refuse orders and methods the report cannot use, before any FE run (the FE runs take minutes).

    Parameters
    ----------
    orders : sequence of int
        ROM orders: at least one, each a whole number ≥ 1, none twice (it would be run and counted twice).
    methods : sequence of str
        Reduction methods of :data:`twin.rom.reduction.METHODS`: at least one, none twice.

    Returns
    -------
    orders : list of int
        Ascending.
    methods : list of str
        As given.

    Raises
    ------
    TwinInputError
        One line naming the option and the value.
    """
    if any(isinstance(r, bool) or int(r) != r or r < 1 for r in orders):
        raise TwinInputError(f"--orders must be positive integers, got {list(orders)}")
    check_distinct("--orders", [int(r) for r in orders], "order")
    check_distinct("--methods", list(methods), "method")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise TwinInputError(f"--methods: unknown ROM method {unknown[0]!r}; methods: {','.join(METHODS)}")
    return sorted(int(r) for r in orders), list(methods)


def named_scenarios(machine: Machine, names: Sequence[str]) -> dict[str, Scenario]:
    """The scenarios a user named, loaded and checked before any FE run.

    Unlike the default list (every shipped scenario, where one of another machine is left out and noted),
    a named scenario the report cannot run is a mistake of the user: refused at once.

    Parameters
    ----------
    machine : Machine
        The built machine.
    names : sequence of str
        Scenario names or TOML paths.

    Returns
    -------
    dict of str to Scenario
        In the order given.

    Raises
    ------
    TwinInputError
        A scenario named twice, an unknown name (the message lists the shipped scenarios), a bad scenario file,
        one the machine cannot run (speeds, feeds, zones), or one of another machine (both machines named).
    """
    check_distinct("--scenarios", [str(n) for n in names], "scenario")
    loaded = {}
    for name in map(str, names):
        try:
            loaded[name] = _named_scenario(machine, name)
        except DefinitionError as exc:    # its message lists the shipped scenarios for an unknown name
            raise TwinInputError(f"--scenarios {name}: {exc}") from None
    return loaded


def runs_on(scenario: Scenario, machine: Machine) -> bool:
    """Whether a scenario names this machine, by name or by the path of its file.

    Parameters
    ----------
    scenario : Scenario
        Its ``machine`` is a name, or the absolute path of a machine file.
    machine : Machine
        The built machine.

    Returns
    -------
    bool
        True when the scenario's machine is this one.
    """
    named = Path(scenario.machine)
    if named.is_absolute():
        return named == Path(machine.definition.source).resolve()
    return scenario.machine == machine.name


def _named_scenario(machine, name):
    """One named scenario, loaded; refused unless it is of ``machine`` and within its limits."""
    scenario = load_scenario(name)
    if not runs_on(scenario, machine):
        raise TwinInputError(f"--scenarios {name}: runs on machine {scenario.machine!r}, not on "
                             f"{machine.name!r} (--machine)")
    scenario.check_machine(machine.definition)    # speeds, feeds, zones: else its FE run fails
    return scenario


def _default_scenarios(machine, failures):
    """Every shipped scenario the machine runs; the others go to ``failures`` with why (another machine, a bad
    file)."""
    loaded = {}
    for name in shipped_scenarios():
        try:
            scenario = load_scenario(name)
        except Exception as exc:  # noqa: BLE001 - a shipped file may be broken in any way; the report goes on
            failures[name] = f"{type(exc).__name__}: {exc}"
            continue
        if not runs_on(scenario, machine):
            failures[name] = f"runs on machine {scenario.machine!r}, not {machine.name!r}"
        else:
            loaded[name] = scenario
    return loaded


def _fe_references(machine, scenarios, failures, say):
    """The full FE run of each scenario (name → (scenario, dataset)) and its wall time, s; a failed one goes to
    ``failures``."""
    references, fe_seconds = {}, {}
    for name, scenario in scenarios.items():
        try:
            start = time.perf_counter()
            references[name] = (scenario, simulate(scenario, machine, noise=False).dataset)
            fe_seconds[name] = time.perf_counter() - start
            say(f"FE {name}: {fe_seconds[name]:.1f} s")
        except Exception as exc:  # noqa: BLE001 - a scenario may fail in any way (FE input, solver);
            # the report names it in ``failures`` and goes on with the others
            failures[name] = f"{type(exc).__name__}: {exc}"
            say(f"FE {name}: failed ({failures[name]})")
    if not references:         # a report of nothing would read as a result (and exit 0)
        raise TwinInputError(f"no scenario could be run on {machine.name!r}: "
                             + "; ".join(f"{n}: {m}" for n, m in failures.items()))
    return references, fe_seconds


def error_report(machine: Machine, orders: Sequence[int] = (10, 20, 30, 40, 60, 80, 100),
                 methods: Sequence[str] = ("krylov", "modal"), scenarios: Sequence[str] | None = None,
                 points: Sequence[float] | None = None, progress: Callable[[str], object] | None = None
                 ) -> ErrorReport:
    """Run the report; ``progress(message)`` is called as it goes (e.g. ``print``).

    Orders, methods and named scenarios are checked before any FE run (:func:`check_report_options`,
    :func:`named_scenarios`).  Of the default scenarios, one that cannot be run on ``machine`` (another machine,
    a bad file) is left out and its reason kept in ``failures``; so is any scenario whose FE run fails.

    Parameters
    ----------
    machine : Machine
        A built machine.
    orders : sequence of int
        ROM orders, none twice.
    methods : sequence of str
        ``krylov`` and/or ``modal``, none twice.
    scenarios : sequence of str, optional
        Scenario names or paths of ``machine``, none twice (default :func:`shipped_scenarios`).
    points : sequence of float, optional
        Krylov expansion points, 1/s.
    progress : callable, optional
        Receives one line per step.

    Returns
    -------
    ErrorReport

    Raises
    ------
    TwinInputError
        A bad order, method or named scenario (before any FE run), or no scenario could be run.
    """
    say = progress or (lambda message: None)
    orders, methods = check_report_options(orders, methods)
    failures = {}
    loaded = _default_scenarios(machine, failures) if scenarios is None else named_scenarios(machine, scenarios)
    references, fe_seconds = _fe_references(machine, loaded, failures, say)
    rows, basis_seconds, zoh = [], {}, {}
    for method in methods:
        start = time.perf_counter()
        V, _ = compute_basis(machine, orders[-1], method, points)
        basis_seconds[method] = time.perf_counter() - start
        for order in orders:
            rom = reduce_with_basis(machine, V[:, :order], method)
            for name, (scenario, fe) in references.items():
                start = time.perf_counter()
                ds = simulate_rom(rom, scenario, scheme="theta")
                rows.append(ReportRow(name, method, order, max_errors(ds, fe), time.perf_counter() - start))
                if method == methods[0] and order == orders[-1]:
                    zoh[name] = max_errors(simulate_rom(rom, scenario, scheme="zoh"), fe)
            say(f"{method} r={order}: " + ", ".join(
                f"{r.scenario} T {r.errors.get('temperature', 0):.1e} K, TCP {r.errors.get('displacement', 0):.1e} µm"
                for r in rows if r.method == method and r.order == order))
    return ErrorReport(rows, fe_seconds, basis_seconds, zoh, failures)


def _method_headers(methods):
    """Three error columns per method, units named."""
    return [f"{m} {label}" for m in methods for label in ("T (K)", "TCP (µm)", "strain (µε)")]


def _errors(rows, fill):
    """The worst error per channel kind over ``rows`` (``fill`` where a kind or every row is missing)."""
    return [max((r.errors.get(kind, fill) for r in rows), default=fill) for kind, _ in GROUPS]


def _ordered_methods(report):
    """Krylov first, then modal, then any other method."""
    known = ("krylov", "modal")
    return sorted({r.method for r in report.rows}, key=lambda m: known.index(m) if m in known else len(known))


def format_summary(report: ErrorReport) -> str:
    """One Markdown table: per order, the worst error over all scenarios for each method.

    Parameters
    ----------
    report : ErrorReport

    Returns
    -------
    str
        A title line and the table (K, µm, µε; and on how many scenarios Krylov meets the goal).
    """
    methods = [m for m in ("krylov", "modal") if any(r.method == m for r in report.rows)]
    n = len({r.scenario for r in report.rows})
    table = []
    for order in sorted({r.order for r in report.rows}):
        cells = [e for m in methods for e in _errors([r for r in report.rows if r.method == m and r.order == order],
                                                     0.0)]
        met = sum(r.meets_goal() for r in report.rows if r.method == "krylov" and r.order == order)
        table.append([order, *cells, f"{met}/{n}"])
    return "\n".join([f"Worst over {n} scenarios (largest |ROM − FE| over time, channels and scenarios):", "",
                      markdown_table(table, ["r", *_method_headers(methods), "Krylov meets the goal on"],
                                     align="right", formats=".2e")])


def _scenario_section(report, name, methods):
    """One scenario's error-vs-order table, and its ZOH note."""
    rows = [r for r in report.rows if r.scenario == name]
    table = [[order, *(e for m in methods for e in _errors([r for r in rows if r.method == m and r.order == order],
                                                            float("nan")))]
             for order in sorted({r.order for r in rows})]
    lines = [f"**{name}** (full FE run {report.fe_seconds[name]:.1f} s)", "",
             markdown_table(table, ["r", *_method_headers(methods)], align="right", formats=".2e")]
    if name in report.zoh_errors:
        e = report.zoh_errors[name]
        lines += ["", f"ZOH ROM ({methods[0]}, r = {max(r.order for r in rows)}) vs the FE's backward Euler: "
                  f"T {e.get('temperature', 0):.2e} K, TCP {e.get('displacement', 0):.2e} µm "
                  "(time-discretisation difference of the FE step, not reduction error)"]
    return lines + [""]


def format_markdown(report: ErrorReport) -> str:
    """The error-vs-order tables (one per scenario: Krylov vs modal side by side) in Markdown.

    Parameters
    ----------
    report : ErrorReport

    Returns
    -------
    str
        The tables, then one line per scenario left out.
    """
    methods = _ordered_methods(report)
    lines = [line for name in sorted({r.scenario for r in report.rows})
             for line in _scenario_section(report, name, methods)]
    for name, message in report.failures.items():
        lines.append(f"- {name}: not reported ({message})")
    return "\n".join(lines)
