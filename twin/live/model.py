"""The observer's model: the ROM's plant state space augmented with what the nominal twin may get wrong.

State (continuous time)::

    x = [ z (r) | w lagged air (l), °C | d disturbances (q) | b thermometer offsets (o), °C ]

    ż = −Λ z + B u + Σⱼ cⱼ eⱼ(t) dⱼ,   ẇ = (u_room − w)/τ_lag + ν_w,   ḋⱼ = −dⱼ/τ_d + νⱼ,   ḃ = 0
    y_T = C_T [z, w] + D_T u + c_T + b + v,      drift = C_XYZ [z, w] + D_XYZ u + c_XYZ

Each disturbance dⱼ is a first-order Gauss–Markov process (stationary σⱼ, correlation time τ_d, intensity
2σⱼ²/τ_d; the air offset a random constant) acting on the plant through a fixed column cⱼ (a column of the
ROM's input matrix, or a modal coordinate) scaled by an *excitation* eⱼ(t) known at each step.

**Estimated** disturbances (the readings update them, so they move the estimate):

* ``power:<source>`` — the unknown part of each source's power, eⱼ = 1, σ = :attr:`NoiseModel.source_power` ×
  its reference power for a source whose driver the observer reads (the spindle), :attr:`NoiseModel.unread_power`
  × it for one it does not read (the feed drives: its whole power is unknown);
* ``ambient:<zone>`` of every zone driven by the room air reading — the zone air's slow difference from the
  reading (air pockets, a door, stratification), eⱼ = 1, σ = :attr:`NoiseModel.ambient_K`;
* ``concentrated:<k>`` — one heat source the model lacks, of σ_P = :attr:`NoiseModel.concentrated_W` W,
  concentrated somewhere on the machine (a hydraulic unit, a coolant line, a drive the model does not know):
  equally likely in each candidate cell of a 0.2 m grid over every part (:data:`CONCENTRATED_GRID_M`, the
  cells of :func:`twin.gap.discovery.source_cells`, 1 W spread uniformly by volume over the part's tets in
  the cell, as a HeatSource box).  With bᵢ the ROM's input column of that 1 W (rate of the modal
  coordinates per W; z₁ᵀbᵢ = 1, so a watt raises the machine's mean temperature by 1/C K/s), its second
  moment is S = σ_P² · meanᵢ bᵢbᵢᵀ (:func:`concentrated_moment`).  S = Σₖ μₖuₖuₖᵀ is factored by its
  eigen-decomposition; the components √μₖ uₖ kept are the fewest that carry :data:`CONCENTRATED_SHARE` of
  each drift axis's steady response (:func:`concentrated_components`), each a disturbance of σ_P with a
  dense column, eⱼ = 1.  They are estimated, not considered: the readings can show such a source, and
  when it is not in the model the filter gives its heat to what it does estimate (a zone's air, a feed
  drive) with a confident, wrong drift.  :class:`~twin.live.multiple_model.MultipleModelObserver` weighs
  several σ_P by how well each predicts the readings.

**Considered** disturbances (Schmidt–Kalman consider states: the covariance carries their uncertainty, so the
band does, but the readings never update them — a parameter error the filter should not chase with a few
thermometers; each acts as strongly as the physics it multiplies, and not at all when that physics is idle):

* ``convection:<zone>`` — the relative error δ of the zone's film coefficients (σ :attr:`NoiseModel.convection`;
  the gap diagnosis finds × 0.5 … 2 on real machines).  The extra heat flow δ·h·(T_air − T) is, for a surface
  of uniform temperature, the ambient input of the zone moved by δ·(T_air − T̄): eⱼ = T_air − T̄ with T̄ the
  zone's convection-weighted mean surface temperature, exact in the ROM: T̄ = bᵀz / bᵀz₁ (b the zone's
  ambient column, z₁ the uniform 1 °C state), evaluated on the present estimate;
* ``power_model:<source>`` of a source whose driver the observer reads — the relative error of its power model
  (σ :attr:`NoiseModel.power_model`, ± 30–50 % in the gap diagnosis): eⱼ = the modelled power, W;
* ``air:offset`` — the room air thermometer's constant offset (DS18S20 accuracy ±0.5 °C, uniform): the air of
  every zone driven by the reading is the reading minus it, eⱼ = 1;
* ``discrepancy:<k>`` — heat the model puts in the wrong place (a joint conductance, a source it lacks, an
  air pocket): a source of :attr:`NoiseModel.discrepancy` × the heat the model moves (the modelled power
  plus every zone's convective exchange, W) at an unknown place, equally likely in every unit of heat
  capacity.  Such a source excites the ROM's M-orthonormal modal coordinates isotropically, with variance
  P²/C per coordinate (C the machine's heat capacity, J/K = |z₁|²), so each disturbance is one modal
  coordinate; the coordinates kept are the fewest that carry :data:`DISCREPANCY_SHARE` of each drift
  axis's steady response to such a source (:func:`discrepancy_modes`).

The lagged air w follows its lag with σ :attr:`NoiseModel.ambient_K`; the offsets b are constant with the
sensor's accuracy as prior (DS18S20 ±0.5 °C uniform, one each; the S65 camera's spots share one, ±2 °C).
Measurement noise R per thermometer: the sensor's quantisation (DS18S20 0.0625²/12 K²) or noise (S65 0.08 K),
the ROM's reduction error and :attr:`NoiseModel.model_error_K`.

Discretisation is exact per sample interval (ZOH; Van Loan for the noise, :func:`models.kalman.discretize`).
The coupling block of the transition matrix is linear in the excitations (the disturbances' own dynamics do
not depend on them), so it is computed once per interval for unit excitations and scaled at each step.  The
disturbances' noise is propagated without their coupling inside one step (a second-order term for steps of
seconds to minutes against correlation times of hours).
"""
from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from models.kalman import discretize, noise_covariance

from ..core.noise import MODELS
from ..errors import TwinInputError
from ..infra.sweep import cached
from ..rom.reduction import ReducedModel

if TYPE_CHECKING:
    from ..core.machine import Machine

AXES = ("X", "Y", "Z")
#: DS18S20 accuracy (°C, ± uniform) and resolution (°C) of the twin's thermometer model.
OFFSET_C = MODELS["DS18S20"]["offset_per_sensor"]
RESOLUTION_C = MODELS["DS18S20"]["resolution"]
#: Sensor models a thermometer may have (:data:`twin.core.noise.MODELS`): the DS18S20 has an offset of its own,
#: ±0.5 °C, and 0.0625 °C steps; the S65 thermal camera's spots share one offset, ±2 °C, with 0.08 °C rms noise.
SENSOR_MODELS = ("DS18S20", "S65")
#: Worst ROM (r = 80) − FE thermometer error over the shipped scenarios, K (docs/rom_fmu.md).
ROM_ERROR_K = 2.43e-3
#: Drivers the observer reads (the spindle speed); sources driven by anything else are unknown inputs.
READ_DRIVERS = ("spindle", "constant")
#: Share of each drift axis's steady response to misplaced heat that the kept discrepancy coordinates carry.
DISCREPANCY_SHARE = 0.95
#: Share of each drift axis's steady response to one concentrated source that the kept components carry.
CONCENTRATED_SHARE = 0.95
#: Grid spacing and cube edge of the candidate cells of the concentrated source, m.
CONCENTRATED_GRID_M = 0.2
#: RMS about idle of the spindle's load over a machine's unknown past, fraction of its power at top speed: a load
#: anywhere between idle and top speed, uniformly (1/√3), the prior of a start whose history is not known.
LOAD_RMS = 1.0 / np.sqrt(3.0)


@dataclass(frozen=True)
class NoiseModel:
    """What the nominal twin may get wrong and how the thermometers read: the sizes of the observer's noise.

    Attributes
    ----------
    source_power : float
        Estimated: standard deviation of the unknown part of each read source's power, fraction of its
        reference power.
    unread_power : float
        Estimated: standard deviation of the power of a source whose driver is not read, fraction of its
        reference power.
    ambient_K : float
        Estimated: standard deviation of each read zone air's slow difference from the room air reading (and of
        the lagged air about its lag), K.
    convection : float
        Considered: standard deviation of the relative error of each zone's film coefficients, 1.
    power_model : float
        Considered: standard deviation of the relative error of each read source's power model, 1 (0: none).
    discrepancy : float
        Considered: standard deviation of the misplaced heat, fraction of the heat the model moves, 1 (0: none).
    concentrated_W : float
        Estimated: standard deviation σ_P of one heat source the model lacks, concentrated in an unknown
        0.2 m cell of the machine, W (0: none).
    correlation_time_s : float
        Correlation time of every disturbance but the air offset (a constant), s.
    model_error_K : float
        Thermometer-level model error not carried by the disturbances, K (rms).
    start_spread_K : float
        Prior standard deviation of the start state about the idle steady state in the room air, K.
    start_at_rest : bool
        The machine is known to have stood idle in the room air long enough to be in equilibrium with it: the start
        prior is that state with :attr:`start_spread_K` only (:meth:`ObserverModel.prior`, the observer's only prior
        until 2026-11-28).  False (the default): its past is unknown, and the observer starts from two priors, at
        rest and with its past unknown (:meth:`ObserverModel.prior`), weighed by the first readings
        (:class:`~twin.live.observer.DriftObserver`).
    """

    source_power: float = 0.3
    unread_power: float = 0.5
    ambient_K: float = 1.0
    convection: float = 0.4
    power_model: float = 0.4
    discrepancy: float = 0.05
    concentrated_W: float = 0.0
    correlation_time_s: float = 4 * 3600.0
    model_error_K: float = 0.05
    start_spread_K: float = 0.3
    start_at_rest: bool = False


@dataclass(frozen=True)
class Disturbance:
    """One disturbance state: its name, how its excitation is formed, σ and its column into the plant state.

    Attributes
    ----------
    name : str
        ``convection:<zone>``, ``power:<source>``, ``air:offset``, ``ambient:<zone>``, ``discrepancy:<k>`` or
        ``concentrated:<k>``.
    excitation : str
        ``one``, ``power`` (the modelled power of plant input ``index``, W), ``convection`` (zone air − mean
        surface temperature, K) or ``heat`` (the heat the model moves, W).
    sigma : float
        Stationary standard deviation, in the unit of the state (1, W or K).
    column : numpy.ndarray
        (n,) the plant state's rate per unit of state × excitation.
    feed : numpy.ndarray
        (k,) the ROM outputs' change per unit of state × excitation (air channels read the ambients).
    index : int
        The plant input the excitation reads (``power``), or the zone's ambient column in the ROM's inputs
        (``convection``); −1 otherwise.
    lagged : int
        For ``convection`` of a lagged zone, its air's position among the lagged states; −1 otherwise.
    constant : bool
        A random constant (no decay, no process noise) instead of a Gauss–Markov process.
    consider : bool
        A *consider* state: its uncertainty is carried in the covariance, but the readings do not update it.
    """

    name: str
    excitation: str
    sigma: float
    column: np.ndarray
    feed: np.ndarray
    index: int = -1
    lagged: int = -1
    constant: bool = False
    consider: bool = False


def checked_thermometers(rom: ReducedModel, thermometers: list[str]) -> list[str]:
    """The thermometer names as a list, each a surface thermometer output of ``rom``.

    Parameters
    ----------
    rom : ReducedModel
        The ROM.
    thermometers : list of str
        Thermometer output names.

    Returns
    -------
    thermometers : list of str
        The names, checked.

    Raises
    ------
    TwinInputError
        If the list is empty or a name is not a ``temperature`` output of the ROM.
    """
    thermometers = list(thermometers)
    if not thermometers:
        raise TwinInputError("the observer needs at least one thermometer")
    kinds = dict(zip(rom.output_names, rom.output_kinds))
    for name in thermometers:
        if kinds.get(name) != "temperature":
            known = [n for n, k in kinds.items() if k == "temperature"]
            raise TwinInputError(f"thermometer {name!r} is not a surface thermometer of the ROM of "
                                 f"{rom.machine!r}; thermometers: {', '.join(known)}")
    return thermometers


def discrepancy_modes(rom: ReducedModel, share: float = DISCREPANCY_SHARE) -> np.ndarray:
    """The modal coordinates that carry ``share`` of each drift axis's steady response to misplaced heat.

    An isotropic modal heat input (see the module docstring) moves drift axis a in steady state by
    Σₖ Cₐₖ/λₖ · qₖ, so coordinate k carries (Cₐₖ/λₖ)² of its variance.  Coordinates are taken in order of
    their largest share over the axes until every axis has ``share``.

    Parameters
    ----------
    rom : ReducedModel
        The ROM.
    share : float, default DISCREPANCY_SHARE
        Share (0…1) of each axis's steady variance the kept coordinates carry.

    Returns
    -------
    numpy.ndarray
        Indices of the kept modal coordinates (in order of importance).
    """
    return _fewest_carrying(np.square(steady_rows(rom)), share)


def steady_rows(rom: ReducedModel, outputs: Sequence[str] = AXES) -> np.ndarray:
    """The steady change of ROM outputs per unit constant rate of each modal coordinate: C/λ.

    Parameters
    ----------
    rom : ReducedModel
        The ROM.
    outputs : sequence of str
        Output names (default: the X, Y, Z drift).

    Returns
    -------
    numpy.ndarray
        (len(outputs), r), in the outputs' units (µm, °C) per unit rate.
    """
    return np.array([rom.output_matrix[rom.output_index(name)] for name in outputs]) / rom.eigenvalues


def _fewest_carrying(parts, share):
    """Indices of the fewest columns of ``parts`` (axes × candidates, variances) that carry ``share`` of each
    row's sum, taken in order of their largest share over the rows."""
    parts = parts / parts.sum(axis=1, keepdims=True)
    order = np.argsort(-parts.max(axis=0))
    carried = np.cumsum(parts[:, order], axis=1)
    count = int(np.argmax(np.all(carried >= share, axis=0))) + 1
    return order[:count]


def concentrated_columns(machine: Machine, rom: ReducedModel, grid_m: float = CONCENTRATED_GRID_M) -> np.ndarray:
    """The ROM's input columns bᵢ of 1 W spread over each candidate cell of the machine (see the module docstring).

    The cells are :func:`twin.gap.discovery.source_cells` (a grid of ``grid_m`` over every part; the part's
    tetrahedra whose centroid lies in the cube), the loads :func:`twin.gap.discovery.source_loads` (uniform by
    volume, as a HeatSource box); bᵢ = Vᵀfᵢ with V the ROM's M-orthonormal modal basis, as the ROM maps a
    source's power.

    Parameters
    ----------
    machine : Machine
        The built machine the ROM was reduced from (its mesh and thermal nodes).
    rom : ReducedModel
        The ROM; its basis is used when kept, else the cached ROM of ``machine`` with its basis (same
        eigenvalues, or an error).
    grid_m : float, default CONCENTRATED_GRID_M
        Grid spacing and cube edge of the cells, m.

    Returns
    -------
    numpy.ndarray
        (r, k) rate of the modal coordinates per W of a source in each of the k cells (the unit of the ROM's
        input matrix for a power input; z₁ᵀbᵢ = 1).

    Raises
    ------
    TwinInputError
        If ``machine`` is not the one of ``rom``, or no kept basis matches ``rom``.
    """
    # on use: only an observer with the concentrated prior on needs the gap package and a machine
    from ..gap.discovery import source_cells, source_loads
    from ..rom.reduction import cached_rom, machine_digest

    if machine_digest(machine) != rom.digest:
        raise TwinInputError(f"the machine {machine.name!r} is not the one the ROM of {rom.machine!r} was built from")
    basis = rom.basis
    if basis is None:
        kept = cached_rom(machine, rom.order, rom.method, keep_basis=True)
        if not np.array_equal(kept.eigenvalues, rom.eigenvalues):
            raise TwinInputError(f"the ROM of {rom.machine!r} (r = {rom.order}) has no basis and the cached ROM "
                                 "with a basis is another reduction; build it with keep_basis=True")
        basis = kept.basis
    loads = source_loads(machine, source_cells(machine, grid_m))
    return np.asarray((loads.T @ basis).T)


def concentrated_moment(rom: ReducedModel, machine: Machine | None = None,
                        grid_m: float = CONCENTRATED_GRID_M) -> np.ndarray:
    """meanᵢ bᵢbᵢᵀ over the candidate cells (:func:`concentrated_columns`): the second moment of a 1 W source.

    Kept in memory and in the user cache, keyed by the ROM (machine digest, method, order, eigenvalues and
    input matrix) and ``grid_m``, so only the first observer of a ROM builds the cells.

    Parameters
    ----------
    rom : ReducedModel
        The ROM.
    machine : Machine, optional
        The machine it was reduced from (default: built from ``rom.machine``, the first time only).
    grid_m : float, default CONCENTRATED_GRID_M
        Grid spacing of the cells, m.

    Returns
    -------
    numpy.ndarray
        (r, r) second moment of the modal rates of a 1 W source at an unknown cell, per W².

    Raises
    ------
    TwinInputError
        If it is not cached and the machine cannot be built from ``rom.machine`` (pass ``machine``).
    """
    from meshes.cachefiles import checked, user_cache_dir, write_checked

    digest = hashlib.sha256(rom.eigenvalues.tobytes() + rom.input_matrix.tobytes() + repr(grid_m).encode())
    key = f"live-concentrated-{rom.method}-r{rom.order}-{rom.digest}-{digest.hexdigest()[:16]}.npy"

    def load_or_build():
        path = user_cache_dir() / key
        if path.exists() and checked(path) is not None:
            return np.load(path)
        columns = concentrated_columns(machine if machine is not None else _machine_of(rom), rom, grid_m)
        moment = columns @ columns.T / columns.shape[1]
        write_checked(path, lambda target: np.save(target, moment))
        return moment

    return cached(key, load_or_build)


def _machine_of(rom):
    """The machine ``rom`` was reduced from, built from its name (a shipped machine's, or a path)."""
    from ..core.machine import build_machine  # on use: a live observer otherwise never builds a machine

    try:
        return build_machine(rom.machine)
    except (OSError, TwinInputError) as exc:
        raise TwinInputError(f"the concentrated-heat prior needs the machine of the ROM ({rom.machine!r}), which "
                             f"could not be built ({exc}); pass its second moment (concentrated_moment(rom, "
                             "machine)) or set NoiseModel.concentrated_W = 0") from None


def concentrated_components(rom: ReducedModel, moment: np.ndarray, share: float = CONCENTRATED_SHARE) -> np.ndarray:
    """The leading components √μₖ uₖ of ``moment`` = Σ μₖuₖuₖᵀ that carry ``share`` of each axis's steady drift.

    Component k moves drift axis a in steady state with variance (Cₐ Λ⁻¹ √μₖ uₖ)² per W²; components are taken
    in order of their largest share over the axes until every axis has ``share`` (as :func:`discrepancy_modes`).

    Parameters
    ----------
    rom : ReducedModel
        The ROM.
    moment : numpy.ndarray
        (r, r) second moment of a 1 W source (:func:`concentrated_moment`).
    share : float, default CONCENTRATED_SHARE
        Share (0…1) of each axis's steady variance the kept components carry.

    Returns
    -------
    numpy.ndarray
        (r, c) the kept components, modal rate per W, most important first.
    """
    mu, vectors = np.linalg.eigh(0.5 * (moment + moment.T))
    components = vectors * np.sqrt(np.clip(mu, 0.0, None))
    kept = _fewest_carrying(np.square(steady_rows(rom) @ components), share)
    return components[:, kept]


class ObserverModel:
    """The augmented continuous model of the module docstring, with its per-interval discretisation.

    Parameters
    ----------
    rom : ReducedModel
        The ROM; its plant state space is the observer's core.
    thermometers : list of str
        The measured thermometer outputs of ``rom`` (``T18`` …, or placement points added to the ROM).
    noise : NoiseModel
        The sizes of the noise model.
    sensors : dict, optional
        Thermometer name → sensor model (:data:`SENSOR_MODELS`); default DS18S20.  DS18S20 thermometers have
        one offset state each, the S65 camera spots one offset state together.
    concentrated : numpy.ndarray, optional
        (r, r) second moment of a 1 W source at an unknown cell (:func:`concentrated_moment`), used when
        ``noise.concentrated_W`` > 0; default: :func:`concentrated_moment` of ``rom`` (cached).
    """

    def __init__(self, rom: ReducedModel, thermometers: list[str], noise: NoiseModel = NoiseModel(),
                 sensors: dict | None = None, concentrated: np.ndarray | None = None) -> None:
        self.rom, self.noise, self._moment = rom, noise, concentrated
        self.thermometers = checked_thermometers(rom, thermometers)
        self.sensors = [(sensors or {}).get(t, "DS18S20") for t in self.thermometers]
        bad = sorted(set(self.sensors) - set(SENSOR_MODELS))
        if bad:
            raise TwinInputError(f"unknown sensor model {bad[0]!r}; models: {', '.join(SENSOR_MODELS)}")
        ss = rom.plant_state_space()
        self.ss, self.input_names = ss, list(ss.input_names)
        self.n, self.p = ss.A.shape[0], len(self.thermometers)
        self.disturbances = self._disturbances()
        self.q = len(self.disturbances)
        self._offset_layout()
        self.size = self.n + self.q + self.offsets
        self._continuous()
        self._outputs()
        self._excitation_layout()
        self.couplings = self._coupling_layout()
        first = next((j for j, d in enumerate(self.disturbances) if d.consider), self.q)
        #: the consider states (the considered disturbances, after the estimated ones), or None
        self.consider = slice(self.n + first, self.n + self.q) if first < self.q else None
        self._steps, self._operating = {}, None

    # ------------------------------------------------------------------ disturbances
    def _disturbances(self):
        """Every disturbance of the module docstring, in the order of the state: the estimated, then the considered."""
        rom, ss, nm = self.rom, self.ss, self.noise
        out = []
        for src in rom.sources:              # unknown part of each source's power, learnt from the readings
            j = self.input_names.index(f"power:{src['name']}")
            share = nm.source_power if src["driver"] in READ_DRIVERS else nm.unread_power
            out.append(Disturbance(f"power:{src['name']}", "one", share * src["coefficient_W"],
                                   ss.B[:, j].copy(), ss.D[:, j].copy(), j))
        for zone in rom.measured_zones:
            j = self.input_names.index(f"ambient:{zone}")
            out.append(Disturbance(f"ambient:{zone}", "one", nm.ambient_K, ss.B[:, j].copy(), ss.D[:, j].copy()))
        return out + self._concentrated() + self._considered()

    def _considered(self):
        """The consider disturbances: parameter errors and misplaced heat the band carries, never estimated."""
        rom, ss, nm = self.rom, self.ss, self.noise
        zero_z, zero_y = np.zeros(self.n - rom.order), np.zeros(rom.n_outputs)
        out = []
        for zone in rom.zones:               # convection error of every zone: a flux into the structure
            col = rom.input_names.index(f"ambient:{zone}")
            lagged = rom.lagged_zones.index(zone) if zone in rom.lagged_zones else -1
            out.append(Disturbance(f"convection:{zone}", "convection", nm.convection,
                                   np.r_[rom.input_matrix[:, col], zero_z], zero_y, col, lagged, consider=True))
        for src in rom.sources:
            if nm.power_model > 0 and src["driver"] in READ_DRIVERS:
                j = self.input_names.index(f"power:{src['name']}")
                out.append(Disturbance(f"power_model:{src['name']}", "power", nm.power_model, ss.B[:, j].copy(),
                                       ss.D[:, j].copy(), j, consider=True))
        read_air = [self.input_names.index(f"ambient:{z}") for z in rom.measured_zones]
        out.append(Disturbance("air:offset", "one", OFFSET_C / np.sqrt(3), -ss.B[:, read_air].sum(axis=1),
                               -ss.D[:, read_air].sum(axis=1), constant=True, consider=True))
        if nm.discrepancy > 0:
            unit = 1.0 / np.sqrt(float(rom.uniform_state @ rom.uniform_state))    # 1/√C per W
            for k in discrepancy_modes(rom):
                column = np.zeros(self.n)
                column[k] = unit
                out.append(Disturbance(f"discrepancy:{k}", "heat", nm.discrepancy, column, zero_y, consider=True))
        return out

    def _concentrated(self):
        """The concentrated-heat disturbances: one per kept component of the source's second moment (σ_P, W)."""
        rom, sigma = self.rom, self.noise.concentrated_W
        if sigma <= 0:
            return []
        moment = concentrated_moment(rom) if self._moment is None else np.asarray(self._moment, float)
        zero_z, zero_y = np.zeros(self.n - rom.order), np.zeros(rom.n_outputs)
        return [Disturbance(f"concentrated:{k}", "one", sigma, np.r_[component, zero_z], zero_y)
                for k, component in enumerate(concentrated_components(rom, moment).T)]

    def _coupling_layout(self):
        """``(dense, single columns, their modal rows)`` of the block F₁₂ (see :class:`~twin.live.filtering.ModalKalmanFilter`).

        A disturbance whose column has one nonzero, in a modal coordinate (a misplaced-heat disturbance),
        drives that coordinate alone; the lagged air and every other disturbance (the concentrated heat's
        dense columns among them) couple densely; the offsets drive nothing.
        """
        r, lagged = self.rom.order, self.n - self.rom.order
        nonzero = [np.flatnonzero(d.column) for d in self.disturbances]
        single = [(lagged + j, int(nz[0])) for j, nz in enumerate(nonzero) if len(nz) == 1 and nz[0] < r]
        dense = [c for c in range(lagged + self.q) if c not in {col for col, _ in single}]
        return np.array(dense, int), np.array([c for c, _ in single], int), np.array([k for _, k in single], int)

    def _offset_layout(self):
        """The offset states: one per DS18S20 thermometer, one shared by the S65 spots; rows (p, o) and priors."""
        own = [j for j, s in enumerate(self.sensors) if s == "DS18S20"]
        camera = [j for j, s in enumerate(self.sensors) if s == "S65"]
        self.offsets = len(own) + int(bool(camera))
        rows = np.zeros((self.p, self.offsets))
        rows[own, np.arange(len(own))] = 1.0
        rows[camera, -1] = 1.0
        self._offset_rows = rows
        self._offset_variances = np.r_[np.full(len(own), OFFSET_C ** 2 / 3),
                                       np.full(int(bool(camera)), MODELS["S65"]["offset_common"] ** 2 / 3)]

    def _continuous(self):
        """A without and with unit couplings, B, and the process-noise intensities Qc (unit² per s)."""
        n, q, N, rom, nm = self.n, self.q, self.size, self.rom, self.noise
        m = self.ss.B.shape[1]
        constant = np.array([d.constant for d in self.disturbances])
        A = np.zeros((N, N))
        A[:n, :n] = self.ss.A
        A[np.arange(n, n + q), np.arange(n, n + q)] = np.where(constant, 0.0, -1.0 / nm.correlation_time_s)
        self._A0 = A
        self._A1 = A.copy()
        self._A1[:n, n:n + q] = np.column_stack([d.column for d in self.disturbances])
        self._B = np.vstack([self.ss.B, np.zeros((q + self.offsets, m))])
        lags = np.array([rom.zone_lags_s[z] for z in rom.lagged_zones])
        Qc = np.zeros((N, N))
        Qc[np.arange(rom.order, n), np.arange(rom.order, n)] = 2 * nm.ambient_K ** 2 / lags
        self.sigmas = np.array([d.sigma for d in self.disturbances])
        Qc[np.arange(n, n + q), np.arange(n, n + q)] = np.where(
            constant, 0.0, 2 * np.square(self.sigmas) / nm.correlation_time_s)
        self._Qc = Qc

    def _rows(self, names):
        """(C over the state without the disturbances' part, D and offset as [D, c], unit feeds (k, q))."""
        rom, ss = self.rom, self.ss
        idx = [rom.output_index(nm) for nm in names]
        H = np.hstack([ss.C[idx], np.zeros((len(idx), self.q + self.offsets))])
        feed = np.column_stack([d.feed[idx] for d in self.disturbances])
        return H, np.hstack([ss.D[idx], ss.offset[idx, None]]), feed

    def _outputs(self):
        n, q, nm = self.n, self.q, self.noise
        self.H, self.J, self._H_feed = self._rows(self.thermometers)
        self.H[:, n + q:] = self._offset_rows
        self.L, self.M, self._L_feed = self._rows(list(AXES))
        self.field_names = [a for a, k in zip(self.rom.output_names, self.rom.output_kinds) if k == "temperature"]
        self.Lf, self.Mf, self._Lf_feed = self._rows(self.field_names)
        reading = {"DS18S20": RESOLUTION_C ** 2 / 12, "S65": MODELS["S65"]["noise"] ** 2}
        self.R = np.array([reading[s] for s in self.sensors]) + ROM_ERROR_K ** 2 + nm.model_error_K ** 2
        self.feeds = bool(np.any(self._H_feed) or np.any(self._L_feed) or np.any(self._Lf_feed))

    def _of_kind(self, excitation):
        """Positions (in the disturbances) and disturbances whose excitation is ``excitation``."""
        picked = [(j, d) for j, d in enumerate(self.disturbances) if d.excitation == excitation]
        return np.array([j for j, _ in picked], int), [d for _, d in picked]

    def _excitation_layout(self):
        """Index arrays that form the excitations in a few vector operations per step."""
        rom = self.rom
        self._power, powered = self._of_kind("power")
        self._power_inputs = np.array([d.index for d in powered], int)
        self._conv, conv = self._of_kind("convection")
        b = rom.input_matrix[:, [d.index for d in conv]]
        self._conv_rows = (b / (rom.uniform_state @ b)).T           # zone mean surface temperature from z
        self._conv_hA = rom.uniform_state @ b                       # W/K per zone
        self._conv_is_lagged = np.array([d.lagged >= 0 for d in conv], bool)
        self._conv_lagged = np.array([rom.order + d.lagged for d in conv], int)[self._conv_is_lagged]
        read = [self.input_names.index(rom.input_names[d.index]) if d.lagged < 0 else -1 for d in conv]
        self._conv_read = np.array(read, int)[~self._conv_is_lagged]
        self._heat = self._of_kind("heat")[0]
        self._all_power = np.array([j for j, x in enumerate(self.input_names) if x.startswith("power:")], int)

    # ------------------------------------------------------------------ per step
    def excitations(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The disturbances' excitations eⱼ (q,) for the state ``x`` and the plant inputs ``u`` ([u, 1]).

        Parameters
        ----------
        x : numpy.ndarray
            (N,) the state (its modal part gives the zones' mean surface temperatures, °C).
        u : numpy.ndarray
            (m + 1,) the plant inputs (°C, K/m, W) and a trailing 1.

        Returns
        -------
        numpy.ndarray
            (q,) in W (power, heat), K (convection) or 1.
        """
        e = np.ones(self.q)
        e[self._power] = u[self._power_inputs]
        air = np.empty(len(self._conv))
        air[self._conv_is_lagged] = x[self._conv_lagged]
        air[~self._conv_is_lagged] = u[self._conv_read]
        difference = air - self._conv_rows @ x[:self.rom.order]
        e[self._conv] = difference
        e[self._heat] = np.abs(u[self._all_power]).sum() + self._conv_hA @ np.abs(difference)
        return e

    def matrices(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(F₀, ΔF, G, Q)`` of a step of ``dt`` s: F(e) = F₀ with ΔF·diag(e) in the coupling block.

        Parameters
        ----------
        dt : float
            Step, s (rounded to µs for the cache).

        Returns
        -------
        tuple of numpy.ndarray
            F₀ (N, N) without couplings, ΔF (n, q) the coupling block for unit excitations, G (N, m + 1) with
            a zero column for the constant, Q (N, N) the process-noise covariance of the step.
        """
        key = round(float(dt), 6)
        if key not in self._steps:
            if len(self._steps) > 64:          # irregular sampling: keep the cache bounded
                self._steps.clear()
            F0, G, Q = discretize(self._A0, self._B, key, self._Qc)
            F1, _, _ = discretize(self._A1, self._B, key)
            n, q = self.n, self.q
            self._steps[key] = (F0, F1[:n, n:n + q].copy(), np.hstack([G, np.zeros((len(F0), 1))]), Q)
        return self._steps[key]

    def output_rows(self, e: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(H, L, Lf)``: the thermometer, drift and field rows over the state for the excitations ``e``.

        Parameters
        ----------
        e : ndarray, shape (q,)
            The disturbances' excitations eⱼ (:meth:`excitations`).

        Returns
        -------
        H : ndarray, shape (n_thermometers, N)
            Thermometer rows, °C per state.
        L : ndarray, shape (3, N)
            Drift rows (X, Y, Z), µm per state.
        Lf : ndarray, shape (n_field, N)
            Field rows, °C per state.
        """
        if not self.feeds:
            return self.H, self.L, self.Lf
        n, q = self.n, self.q
        rows = []
        for base, feed in ((self.H, self._H_feed), (self.L, self._L_feed), (self.Lf, self._Lf_feed)):
            out = base.copy()
            out[:, n:n + q] = feed * e
            rows.append(out)
        return tuple(rows)

    def prior(self, room_C: float, unknown_past: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Start state and covariance: the idle steady state in ``room_C`` (°C), spread along the uniform field, and
        with ``unknown_past`` by :meth:`operating_moment` in the plant state.

        The mean is the machine at rest either way (the operating moment is about rest: a cold start is at its
        centre).  A machine whose spindle ran before the session is warm in a way the thermometers show only in
        part, and the prior at rest alone held a drift of −40 µm to be 2 µm ± 1 µm (2026-11-28).

        Parameters
        ----------
        room_C : float
            Room air, °C.
        unknown_past : bool
            The machine's past is unknown (else: at rest in equilibrium with the room air).

        Returns
        -------
        tuple of numpy.ndarray
            x₀ (N,) and P₀ (N, N), in the states' units (°C, W, K, 1) and their squares.
        """
        rom, n, q, nm = self.rom, self.n, self.q, self.noise
        u = self.plant_inputs(0.0, room_C)[0]
        x0 = np.zeros(self.size)
        x0[:n] = rom.plant_steady_state(u)
        s = np.r_[rom.uniform_state, np.ones(n - rom.order)]
        spread = nm.start_spread_K
        P0 = np.zeros((self.size, self.size))
        P0[:n, :n] = spread ** 2 * np.outer(s, s) + (0.1 * spread) ** 2 * np.diag(
            np.r_[np.full(rom.order, s[:rom.order] @ s[:rom.order] / rom.order), np.ones(n - rom.order)])
        if unknown_past:
            P0[:n, :n] += self.operating_moment()
        P0[n:n + q, n:n + q] = np.diag(np.square(self.sigmas))
        P0[n + q:, n + q:] = np.diag(self._offset_variances)
        return x0, P0

    def operating_moment(self) -> np.ndarray:
        """The second moment about rest of the plant state under plausible operation, (n, n) in °C² (the modal
        coordinates' units squared).

        The stationary covariance (continuous Lyapunov equation) of the plant (modes and lagged airs, with the
        lagged airs' own process noise) driven by two Gauss–Markov inputs of the model's correlation time
        :attr:`NoiseModel.correlation_time_s`: the spindle's load (its power at top speed × :data:`LOAD_RMS`)
        and the room air's past about its present reading (σ :attr:`NoiseModel.ambient_K`, every read zone).
        Zero-mean about rest.  The disturbances are left out: with their stationary effect in the prior, the
        first readings' sensor offsets were taken for heat (Z error 0.5 → 2 µm RMS on cold-start held-out
        records, 2026-11-28).  Computed once per model.
        """
        if self._operating is None:
            from scipy.linalg import solve_continuous_lyapunov

            A, Qc = self._history_system()
            moment = solve_continuous_lyapunov(A, -Qc)[:self.n, :self.n]
            self._operating = 0.5 * (moment + moment.T)
        return self._operating.copy()

    def unknown_inputs(self, dt: float, spindle_rpm: float) -> tuple[np.ndarray, np.ndarray]:
        """The plant state's response over ``dt`` s to inputs nobody read, about idle in the last room air read.

        The inputs are those of :meth:`operating_moment` — the spindle's load and the room air, Gauss–Markov
        about idle and the room air's reading — conditioned on what was read last: the load then was that of
        ``spindle_rpm``, and the room air its reading.  So the known load is forgotten at the correlation time
        (its mean decays as e^(−t/τ)) while the unknown part grows from nothing towards the operating moment;
        after many τ this is the unknown-past prior about rest.  The response to idle in the room air, the
        disturbances and the plant's own noise are not in it: they are the observer's ordinary prediction.

        Parameters
        ----------
        dt : float
            The time without readings, s.
        spindle_rpm : float
            The last spindle speed read, rpm.

        Returns
        -------
        tuple of numpy.ndarray
            The mean (n,) and the covariance (n, n) of the plant state's response, °C and °C².
        """
        from scipy.linalg import expm

        n = self.n
        A, Qc = self._history_system(spindle_rpm)
        Qc[:n, :n] = 0.0                   # the plant's own noise is in the ordinary prediction's Q
        return expm(A * dt)[:n, -1], noise_covariance(A, Qc, dt)[:n, :n]

    def _history_system(self, known_rpm=None):
        """``(A, Qc)``: the plant with the spindle's load and the room air's past appended as two Gauss–Markov
        inputs (:meth:`operating_moment`); with ``known_rpm`` (rpm) a third, noiseless one: the load at that speed,
        of unit start and forgotten at the same rate (:meth:`unknown_inputs`)."""
        n, nm = self.n, self.noise
        idle = self.plant_inputs(0.0, 0.0)[0]
        columns = [self.plant_inputs(float(self.rom.limits["max_spindle_rpm"]), 0.0)[0] - idle,
                   self.plant_inputs(0.0, 1.0)[0] - idle]
        if known_rpm is not None:
            columns.append(self.plant_inputs(float(known_rpm), 0.0)[0] - idle)
        steps, k = np.column_stack(columns), len(columns)
        rate = 1.0 / nm.correlation_time_s
        A, Qc = np.zeros((n + k, n + k)), np.zeros((n + k, n + k))
        A[:n, :n], Qc[:n, :n] = self._A0[:n, :n], self._Qc[:n, :n]
        A[:n, n:] = self._B[:n, :len(idle)] @ steps
        A[n:, n:] = -rate * np.eye(k)
        Qc[n:n + 2, n:n + 2] = np.diag(2.0 * rate * np.square([LOAD_RMS, nm.ambient_K]))
        return A, Qc

    def plant_inputs(self, spindle_rpm: ArrayLike, room_C: ArrayLike, feed_mm_min: dict | None = None) -> np.ndarray:
        """Plant inputs (k, m) for spindle speeds (rpm), room air (°C; every read zone at it) and feeds (mm/min).

        Parameters
        ----------
        spindle_rpm : array-like, shape (k,)
            Spindle speeds, rpm.
        room_C : array-like
            Room air, °C (broadcast to the speeds).
        feed_mm_min : dict or None
            Feed rate per axis, mm/min; None: no feed.

        Returns
        -------
        inputs : ndarray, shape (k, m)
            The ROM's plant inputs (source powers W, zone temperatures °C).
        """
        rpm = np.atleast_1d(np.asarray(spindle_rpm, float))
        room = np.broadcast_to(np.asarray(room_C, float), rpm.shape)
        ambient = {z: room for z in self.rom.measured_zones}
        return self.rom.plant_inputs_from_conditions(rpm, feed_mm_min, ambient, 0.0)
