"""Discovery beyond the library: a sparse, spatially resolved search for what the effect library lacks.

API (what :mod:`twin.gap.diagnose` calls)::

    from twin.gap.discovery import discover
    found = discover(model, evaluator, base=None)   # GapModel, Evaluator with weights set (nominal_result)
    found.items        # [Discovery]: kind, label, part, position_m (3,), value, unit, interval (90 %),
                       #   driver, held_out {group: {"before_rms", "after_rms", "reduction"}}, delta_bic
    found.as_dict()    # JSON-able, for diagnosis.json "discoveries"
    found.summary()    # one line per discovery ("an unmodelled source of about 41 W … near (x, y, z) m on the column")
    render_discoveries(found, machine, path)  # 3-D render of the discovered sources (PNG)

``base`` is the :class:`~twin.gap.fit.FitResult` whose residual is searched
(the named library effect, or the nominal twin when ``None``).

The dictionary (one column per candidate, the linearised response of every
sensor channel to a unit change of it, around the nominal twin):

- **heat sources/sinks**: a volumetric source spread uniformly over the
  tetrahedra of one part whose centroids lie in a cube of edge
  :data:`GRID_M` (0.2 m) around each point of a 0.2 m grid over that part —
  on the thin walls of a casting this is a surface patch — times each
  :data:`DRIVERS` time signal (spindle speed, spindle running, axis feed);
- **convection** of every convection group (h × (1 + a)), and **contact
  conductance** of every joint (h_c × (1 + a)): the sensitivity ∂y/∂a is the
  response to the input −dA·T(t) + dB·u(t) along the nominal trajectory, dA,
  dB exact differences of two assemblies;
- **expansion coefficient of a part** (α × (1 + a)): drift and strain are
  linear in α·T, so ∂y/∂a is the output operator's columns of the part's
  nodes (interface nodes shared by their volume) applied to T(t);
- **sensor lag** of every sensor channel: lag(y, τ) ≈ y − τ·ẏ, ∂y/∂τ = −ẏ
  (constant offsets are eliminated per channel for every model already);
- **timing**: one delay δ of every sensor against the operating inputs
  (a logger clock offset, an input reconstruction a step late), ∂y/∂δ = −ẏ
  on all channels at once.

The responses come from a Galerkin reduced model whose basis is the
diagnosis engine's basis plus a block-Krylov basis of the *adjoint* (output
side, ``(A + sM)⁻¹ Cᵀ``): because M and A are symmetric, projecting on the
output Krylov space matches the moments of ``C (sM + A)⁻¹ b`` for *any*
load b, so one basis serves every candidate location.  Each driver signal is
filtered once per mode (exact zero-order hold); a candidate's response is
then a weighted sum of the modal responses (milliseconds per candidate).

Choice of the sparse method: **orthogonal matching pursuit with acceptance on
held-out evidence** (forward selection).  The dictionary has hundreds of
strongly correlated columns (neighbouring grid cells, a source and a
convection change of the same part); group lasso would need a penalty chosen
by cross-validation over a path of many solves and shrinks the powers it
reports, while OMP costs one least-squares update per step, keeps the
coefficients unbiased, and gives each step an interpretable atom that can be
judged like a library effect.  At each step the :data:`SHORTLIST` atoms that
most reduce the *fit* residual (after orthogonalisation against those
already chosen), and the best atom of every kind, are tried (a source atom's
position first refined on a 0.05 m sub-grid); of those accepted, the one with
the largest held-out ΔBIC is kept; an atom whose fitted value leaves its
physical range (:data:`RANGES`: a conductance or h not below 5 % of the
nominal, a lag not negative) is rejected.  An atom is accepted only
on the *held-out* part of the record: ΔBIC > :data:`MIN_DELTA_BIC` (n_eff
effective samples, :func:`twin.gap.fit.effective_samples`) and material in
some channel group (removes ≥ σ_g² of its held-out mean square).  The
accepted set as a whole must worsen no group against the base by more than
:data:`MAX_WORSENING`·σ_g² (an atom alone may, while another unexplained
component dominates that group, e.g. a timing error in the strain lines);
else atoms are dropped, the one whose removal helps most first.  The search stops at the
first step without an accepted atom or after :data:`MAX_ATOMS`.  The held-out
reductions reported are on the part that accepted the atoms (a validation
set, not a fresh test set).

Source atoms of one driver whose cells overlap (centroids within :data:`GRID_M`, any part and sign) are
reported as one **extended source** with their summed power (:func:`_extended_sources`): a source larger
than a cell, or of another shape, is fitted as neighbouring cells whose single powers are ill-determined
while their sum is not.

90 % intervals: moving-block bootstrap of the fit-part residual rows (blocks
of :data:`BLOCK_H` hours keep the autocorrelation and the cross-channel
correlation), the half-widths inflated by √(MS_hold / MS_fit) of the final
residual when the held-out misfit is larger (model discrepancy), and widened
to ± 1.645 sds of the larger of two discrepancies no residual resampling sees:
the split-half sd, where a value drifts between the two halves of the fit rows
(as the library's parameters are, :func:`twin.gap.diagnose.split_half_sd`), and the
shape-discrepancy sd (:func:`_discrepancy_sd`): an idealised signature fitted
to a real one puts part of the mismatch into the value, and the remainder shows
how large the mismatch is.  A source's
value also depends on where the dictionary puts it: a cube of fixed shape on
a grid stands for a source of unknown shape, and a cell nearer the sensors
fits the same record with less power.  So the value is profiled over position:
every cell of the 0.05 m sub-grid within ± :data:`PROFILE_REACH_M` is refitted
with the other atoms, the cells whose fit-part SSE is within χ²₃(0.90)/n_eff
(relative) of the best are plausible, and the interval is the bootstrap's
spread around the lowest and the highest plausible value (for an extended source,
that of any member's plausible positions).  The farthest
plausible cell gives the position's own claim, "plausible within r m".

Where to start.  The diagnosis (:func:`twin.gap.diagnose._better_start`) runs the search on the nominal twin's
residual and, when a library model is named, on what that model leaves; held-out BIC with every parameter
counted decides.  A library model standing in for an unlisted effect takes part of its signature, and the
search on what it leaves then finds the rest in the wrong place or of the wrong kind.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sp

from ..core.machine import Machine
from ..errors import TwinInputError
from ..infra.sweep import cached
from ..rom.reduction import krylov_basis, slowest_rate
from .drive import Drive
from .effects import scaled_definition, system_difference
from .engine import FullBackend, ReducedBackend, m_orthonormal_union
from .fit import GROUP_UNIT, Evaluator, FitResult, effective_samples, nominal_result, relative_bic
from .model import GapModel, Prediction
from .structure import Structure

#: Grid spacing and source cube edge, m.
GRID_M = 0.2
#: Sub-grid step of the position refinement of a source atom, m (± one grid half-step).
REFINE_M = 0.05
#: Time signals a candidate source may follow: name → (label, unit of the fitted power).  The spindle's
#: reference speed is the machine's (:func:`spindle_reference_rpm`); :func:`driver_unit` names it.
DRIVERS = {"spindle": ("∝ spindle speed", "W at the reference speed"),
           "spindle_on": ("while the spindle runs", "W"),
           "feed": ("∝ the largest axis feed", "W at 10 m/min")}
FEED_REFERENCE_MM_MIN = 10000.0
#: Spindle reference speed of a machine without a spindle-driven source, rpm.
DEFAULT_SPINDLE_REFERENCE_RPM = 9000.0
MIN_DELTA_BIC = 10.0
MIN_MATERIAL = 1.0
MAX_WORSENING = 0.1
MAX_ATOMS = 4
SHORTLIST = 5
BLOCK_H = 2.0
N_BOOTSTRAP = 300
#: Physical range of a fitted atom per kind (relative changes of h, h_c, α; lags and delays in s): an atom
#: fitted outside it is rejected (a negative conductance is a linearisation pushed past its meaning).
RANGES = {"convection": (-0.95, 10.0), "joint": (-0.95, 10.0), "expansion": (-0.5, 0.5), "sensor_lag": (0.0, 3600.0),
          "timing": (-900.0, 900.0), "source": (-np.inf, np.inf)}
#: Kinds of candidates (see the module docstring).
KINDS = ("source", "convection", "joint", "expansion", "sensor_lag", "timing")
#: Standard normal 95 % quantile: a 90 % two-sided interval of ± Z_90 sd.
Z_90 = 1.645
#: Reach of the position profile of a source's value, m (± around the reported position).
PROFILE_REACH_M = GRID_M
#: 90 % quantile of χ² with 3 degrees of freedom (the position), for the profile's plausible positions.
CHI2_3_90 = 6.251
#: Order of the output-side (adjoint) Krylov basis.
ADJOINT_ORDER = 120


@dataclass
class Discovery:
    """One accepted atom: what, where, how much (with a 90 % interval) and what it removes on held-out data."""

    kind: str                     # source, convection, joint, expansion, sensor_lag
    name: str
    label: str
    value: float
    unit: str
    interval: tuple               # 90 % (low, high), same unit
    part: str | None = None
    position_m: tuple | None = None
    driver: str | None = None
    delta_bic: float = 0.0
    held_out: dict = field(default_factory=dict)
    position_radius_m: float | None = None  # farthest plausible position of a source from position_m, m

    @property
    def resolved(self) -> bool:
        """True when the 90 % interval excludes 0 (a change of either sign is within it otherwise: not found)."""
        lo, hi = self.interval
        return bool(np.isfinite(lo) and np.isfinite(hi) and (lo > 0 or hi < 0))

    def sentence(self) -> str:
        """One line in words: a source's power, driver, position and part; else the label and the value.

        Returns
        -------
        str
            With the value and its 90 % interval in :attr:`unit`.
        """
        lo, hi = self.interval
        if self.kind == "source":
            what = "source" if self.value >= 0 else "sink"
            x, y, z = self.position_m
            return (f"an unmodelled heat {what} of about {abs(self.value):.3g} {self.unit} (90 %: {lo:.3g} … "
                    f"{hi:.3g}), {DRIVERS[self.driver][0]}, near ({x:.2f}, {y:.2f}, {z:.2f}) m on the {self.part}"
                    + (f" (plausible within {self.position_radius_m:.2f} m)" if self.position_radius_m else ""))
        return f"{self.label}: {self.value:+.3g} {self.unit} (90 %: {lo:+.3g} … {hi:+.3g})"


@dataclass
class DiscoveryResult:
    """What :func:`discover` found; ``held_out`` per group before (base) and after all accepted atoms."""

    items: list
    held_out: dict
    base: str
    candidates: int
    seconds: float
    rejected: list = field(default_factory=list)
    held_out_sse_ratio: float = 1.0   # weighted held-out SSE after all accepted atoms / before (the base's)
    n_atoms: int = 0                  # atoms accepted (fitted coefficients; an extended source counts its cells)

    def resolved(self) -> list[Discovery]:
        """The accepted atoms whose 90 % interval excludes 0 (:attr:`Discovery.resolved`): what was found."""
        return [d for d in self.items if d.resolved]

    def unresolved(self) -> list[Discovery]:
        """The accepted atoms whose 90 % interval includes 0: fitted, but neither sign is established."""
        return [d for d in self.items if not d.resolved]

    def summary(self) -> list[str]:
        """One line per resolved discovery (:meth:`Discovery.sentence`), then one per unresolved atom marked
        "not resolved (its 90 % interval includes 0)", or one line saying none was accepted.

        Returns
        -------
        list of str
            The lines.
        """
        if not self.items:
            return ["no atom of the dictionary is accepted on held-out data"]
        return [d.sentence() for d in self.resolved()] + [
            f"not resolved (its 90 % interval includes 0): {d.sentence()}" for d in self.unresolved()]

    def as_dict(self) -> dict[str, object]:
        """JSON-able form (for ``diagnosis.json``), with the :meth:`summary` lines.

        Returns
        -------
        dict
            ``base``, ``candidates``, ``seconds`` (s), ``held_out``, ``held_out_sse_ratio``, ``n_atoms``,
            ``items`` (each :class:`Discovery` as a dict, with ``resolved``: whether its 90 % interval excludes 0),
            ``rejected`` and ``summary``.
        """
        return {"base": self.base, "candidates": self.candidates, "seconds": self.seconds,
                "held_out": self.held_out, "held_out_sse_ratio": self.held_out_sse_ratio, "n_atoms": self.n_atoms,
                "items": [{**asdict(d), "resolved": d.resolved} for d in self.items], "rejected": self.rejected,
                "summary": self.summary()}


# ============================================================================= the response model
class ResponseModel:
    """Galerkin reduced model for arbitrary loads (see the module docstring), in modal coordinates.

    Nodal temperatures are ``VQ @ w`` (K) for modal states w, whose rates are :attr:`lam` (1/s).

    Parameters
    ----------
    structure : Structure
        Gives M, A (W/K) and the output matrix (FE channels, channel units).
    backend_basis : ndarray, shape (n_nodes, r_b), optional
        The diagnosis engine's M-orthonormal basis, added to the adjoint Krylov basis.
    order : int, default ADJOINT_ORDER
        Order of the adjoint (output-side) Krylov basis (at most n_nodes − 1).
    """

    def __init__(self, structure: Structure, backend_basis: np.ndarray | None = None, order: int = ADJOINT_ORDER):
        s = structure
        M, A = s.mass, s.stiffness
        lam1 = slowest_rate(SimpleNamespace(mass=M, stiffness=A))
        Ct = s.output_matrix.T.tocsc()
        adjoint = krylov_basis(SimpleNamespace(n_nodes=s.n_nodes, mass=M, stiffness=A, input_matrix=Ct),
                               min(order, s.n_nodes - 1), [0.0, 10 * lam1, 100 * lam1])
        blocks = [adjoint] + ([backend_basis] if backend_basis is not None else [])
        V = m_orthonormal_union(M, blocks)
        Ar = V.T @ (A @ V)
        lam, Q = np.linalg.eigh((Ar + Ar.T) / 2)
        self.lam = np.maximum(lam, 1e-14)
        self.VQ = V @ Q                                   # nodes ← modal coordinates
        self.C = np.asarray(s.output_matrix @ self.VQ)    # FE outputs ← modal coordinates
        self.structure = s

    def modal(self, loads: np.ndarray | sp.spmatrix) -> np.ndarray:
        """Modal input weights (r, k) of load columns (n, k).

        Parameters
        ----------
        loads : ndarray or sparse matrix, shape (n_nodes, k)
            Nodal heat loads per unit of some input (e.g. W/W, W/K).

        Returns
        -------
        ndarray, shape (r, k)
            ``(VQ)ᵀ loads``.
        """
        return np.asarray((sp.csr_matrix(loads).T @ self.VQ).T) if sp.issparse(loads) else self.VQ.T @ loads

    def filter(self, F: np.ndarray, step_s: float, start: np.ndarray | None = None) -> np.ndarray:
        """Modal states (N, r) for modal inputs F (N, r) held over each step (exact ZOH), from ``start`` or zero.

        Parameters
        ----------
        F : ndarray, shape (N, r)
            Modal inputs; row k is held over (t_{k−1}, t_k] (row 0 is not used).
        step_s : float
            Grid step, s.
        start : ndarray, shape (r,), optional
            Modal state at t₀ (default zero).

        Returns
        -------
        ndarray, shape (N, r)
            Modal states on the grid (nodal temperatures ``VQ @ w``, K).
        """
        e = np.exp(-self.lam * step_s)
        g = -np.expm1(-self.lam * step_s) / self.lam
        W = np.empty_like(F)
        w = np.zeros(F.shape[1]) if start is None else start
        W[0] = w
        gF = F * g
        for k in range(1, len(F)):
            w = e * w + gF[k]
            W[k] = w
        return W


def response_model(structure: Structure, backend: ReducedBackend | FullBackend) -> ResponseModel:
    """The :class:`ResponseModel` of a structure, once per process.

    Parameters
    ----------
    structure : Structure
        The diagnosis structure (the cache key is its identity).
    backend : ReducedBackend or FullBackend
        Its ``basis``, if it has one, is added to the response model's basis.

    Returns
    -------
    ResponseModel
        Built on the first call for ``structure``, then reused.
    """
    return cached(("gap-discovery-rom", id(structure)),
                  lambda: ResponseModel(structure, getattr(backend, "basis", None)))


# ============================================================================= the dictionary
def driver_signals(drive: Drive, machine: Machine) -> dict[str, np.ndarray]:
    """Time signals (N,) on the drive's grid, one per :data:`DRIVERS` entry (dimensionless, 1 at the reference).

    Held over each step as the drive holds the source powers: its step means where it has them
    (``Drive.step_mean``), else the grid values.

    Parameters
    ----------
    drive : Drive
        Operating conditions on the grid (spindle speed, rpm; feeds, mm/min).
    machine : Machine
        Gives the reference speed, rpm: the largest of its spindle-driven sources (9000 rpm without one).

    Returns
    -------
    dict of str to ndarray
        ``spindle``: |speed| / reference; ``spindle_on``: 1 while the spindle turns; ``feed``: the largest
        |axis feed| / :data:`FEED_REFERENCE_MM_MIN`; each shape (N,).
    """
    ref = spindle_reference_rpm(machine)

    def signals(rpm, feeds):
        rpm = np.abs(np.asarray(rpm, float))
        feed = np.max([np.abs(np.asarray(feeds[a], float)) for a in "xyz"], axis=0)
        return np.stack([rpm / ref, (rpm > 0).astype(float), feed / FEED_REFERENCE_MM_MIN], axis=-1)

    S = drive.step_mean(signals) if hasattr(drive, "step_mean") else signals(drive.spindle_rpm, drive.feed_mm_min)
    return dict(zip(DRIVERS, np.asarray(S).T))


def spindle_reference_rpm(machine: Machine) -> float:
    """The spindle reference speed of the spindle driver signal (:func:`driver_signals`).

    Parameters
    ----------
    machine : Machine
        Its spindle-driven sources give their reference speeds, rpm.

    Returns
    -------
    float
        The largest of them, rpm (:data:`DEFAULT_SPINDLE_REFERENCE_RPM` without one).
    """
    refs = [src.reference for src in machine.definition.sources if src.driver == "spindle"]
    return float(max(refs)) if refs else DEFAULT_SPINDLE_REFERENCE_RPM


def driver_unit(driver: str, machine: Machine) -> str:
    """Unit of the fitted power of a source following ``driver``, its reference named.

    Parameters
    ----------
    driver : str
        A :data:`DRIVERS` key.
    machine : Machine
        Gives the spindle reference speed (:func:`spindle_reference_rpm`).

    Returns
    -------
    str
        E.g. "W at 9000 rpm" (spindle), "W" (while the spindle runs), "W at 10 m/min" (feed).
    """
    if driver == "spindle":
        return f"W at {spindle_reference_rpm(machine):g} rpm"
    return DRIVERS[driver][1]


def _cell(part, part_tets, centroids, volumes, centre, grid_m, min_tets=3):
    """(part, tets, volume centroid) of the tets of a part whose centroids lie in the cube around ``centre``, or None."""
    sel = part_tets[np.all(np.abs(centroids[part_tets] - centre) <= grid_m / 2 + 1e-9, axis=1)]
    if sel.size < min_tets:
        return None
    return part, sel, (volumes[sel] @ centroids[sel]) / volumes[sel].sum()


def source_cells(machine: Machine, grid_m: float = GRID_M,
                 min_tets: int = 3) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Candidate source cells: per part and grid point, the tets with centroid in the cube → [(part, tets, centroid)].

    Parameters
    ----------
    machine : Machine
        Gives the mesh.
    grid_m : float, default GRID_M
        Grid spacing and cube edge, m.
    min_tets : int, default 3
        Fewest tetrahedra a cell needs.

    Returns
    -------
    list of (str, ndarray, ndarray)
        Part name, its tetrahedron ids in the cube (int), and their volume-weighted centroid (3,), m.
    """
    mesh = machine.mesh
    cents = mesh.points[mesh.tets].mean(axis=1)
    vol = np.abs(mesh.volumes)
    out = []
    for rid, part in sorted(mesh.region_names.items()):
        tets = np.flatnonzero(mesh.regions == rid)
        if tets.size == 0:
            continue
        lo, hi = cents[tets].min(axis=0), cents[tets].max(axis=0)
        axes = [np.arange(l + ((h - l) % grid_m) / 2, h + 1e-9, grid_m) if h - l > grid_m else np.array([(l + h) / 2])
                for l, h in zip(lo, hi)]
        for p in np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3):
            cell = _cell(part, tets, cents, vol, p, grid_m, min_tets)
            if cell is not None:
                out.append(cell)
    return out


def source_loads(machine: Machine, cells: Sequence[tuple[str, np.ndarray, np.ndarray | None]]) -> sp.csc_matrix:
    """Load columns (n, k): 1 W spread uniformly by volume over each cell's tetrahedra (as a HeatSource box).

    Parameters
    ----------
    machine : Machine
        Gives the mesh and the thermal nodes.
    cells : sequence of (str, ndarray, ndarray or None)
        Cells as :func:`source_cells` gives them; only the tetrahedron ids are used.

    Returns
    -------
    scipy.sparse.csc_matrix, shape (n_nodes, k)
        Nodal load per watt of each cell's source (W/W; each column sums to 1).
    """
    mesh, thermal = machine.mesh, machine.thermal
    vol = np.abs(mesh.volumes)
    rows, cols, vals = [], [], []
    for j, (_, tets, _) in enumerate(cells):
        w = vol[tets] / vol[tets].sum() / 4.0
        rows.append(thermal.tets[tets].ravel())
        cols.append(np.full(4 * len(tets), j))
        vals.append(np.repeat(w, 4))
    return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(thermal.n_nodes, len(cells)))


def part_output_columns(structure: Structure, rows: Sequence[int]) -> dict[str, sp.csr_matrix]:
    """Per part: the output rows (k, n) restricted to the part's nodes, interface nodes split by volume share.

    Parameters
    ----------
    structure : Structure
        Gives the mesh, the thermal nodes and the output matrix (FE channels, channel units per K).
    rows : sequence of int
        Rows of the output matrix (e.g. the drift and strain lines).

    Returns
    -------
    dict of str to scipy.sparse.csr_matrix
        Part → its share of the rows, shape (len(rows), n_nodes) (µm/K, µε/K); the parts' shares sum to
        the rows.
    """
    machine = structure.machine
    mesh, thermal = machine.mesh, machine.thermal
    vol = np.abs(mesh.volumes)
    n = thermal.n_nodes
    share = {}
    total = np.bincount(thermal.tets.ravel(), weights=np.repeat(vol, 4), minlength=n)
    C = sp.csr_matrix(structure.output_matrix[rows])
    for rid, part in sorted(mesh.region_names.items()):
        tets = np.flatnonzero(mesh.regions == rid)
        mine = np.bincount(thermal.tets[tets].ravel(), weights=np.repeat(vol[tets], 4), minlength=n)
        w = np.divide(mine, total, out=np.zeros(n), where=total > 0)
        if w.any():
            share[part] = C @ sp.diags(w)
    return share


# ============================================================================= projection onto the residual space
class _Projector:
    """Centre per channel on the fit rows, weight, and remove the nuisance responses, as the evaluator does."""

    def __init__(self, ev, nuisance):
        self.ev = ev
        self.fit_col = np.nonzero(ev.fit_mask)[1]
        self.hold_col = np.nonzero(ev.hold_mask)[1]
        weighted = [self._weighted(X) for X in nuisance]
        self.Nf = np.column_stack([W[ev.fit_mask] for W in weighted]) if weighted else np.zeros((len(self.fit_col), 0))
        self.Nh = np.column_stack([W[ev.hold_mask] for W in weighted]) if weighted else np.zeros((len(self.hold_col), 0))
        if weighted:
            self.state = ev.nuisance_entries(weighted)[ev.fit_mask]     # the entries the evaluator fits them on
            self.pinv = np.linalg.pinv(self.Nf[self.state])
        else:
            self.pinv = None

    def _weighted(self, X):
        """X centred per channel on the fit rows and weighted, as the evaluator's residuals are."""
        return (X - self.ev._centre(X)) * self.ev.sqrt_w

    def __call__(self, X):
        """(fit vector, held-out vector) of a response (n_times, p_eval)."""
        W = self._weighted(np.nan_to_num(X))
        f, h = W[self.ev.fit_mask], W[self.ev.hold_mask]
        if self.pinv is not None:
            c = self.pinv @ f[self.state]
            f, h = f - self.Nf @ c, h - self.Nh @ c
        return f, h


@dataclass
class _Atom:
    kind: str
    name: str
    label: str
    unit: str
    fit: np.ndarray
    hold: np.ndarray
    part: str | None = None
    position: tuple | None = None
    driver: str | None = None
    scale: float = 1.0            # value = coefficient × scale


class Dictionary:
    """The candidate columns of :func:`discover` (see the module docstring), projected like the residual.

    Parameters
    ----------
    model : GapModel
        The diagnosis model (structure, backend, drive, measured times).
    evaluator : Evaluator
        With weights set; the atoms are its channels, centred, weighted and nuisance-projected.
    base_prediction : Prediction
        The prediction whose residual is searched (its nuisance responses are projected out).
    kinds : sequence of str, default KINDS
        Candidate kinds to build (of :data:`KINDS`).
    """

    def __init__(self, model: GapModel, evaluator: Evaluator, base_prediction: Prediction,
                 kinds: Sequence[str] = KINDS):
        s = model.structure
        self.model, self.ev, self.structure = model, evaluator, s
        self.rom = response_model(s, model.backend)
        self.step = model.drive.step_s
        nuis = [base_prediction.nuisance[n][:, evaluator.cols] for n in base_prediction.nuisance]
        self.project = _Projector(evaluator, nuis)
        self.p_fe = s.output_matrix.shape[0]
        self.signals = driver_signals(model.drive, s.machine)
        self._modal_drivers = {}
        self.atoms = []
        # nominal trajectory in modal coordinates (for the system and expansion sensitivities)
        U = model.U0
        u0 = model.U0_idle[0]
        self.U = U
        Bm = self.rom.modal(s.input_matrix)
        F = U @ Bm.T
        self.X = self.rom.filter(F, self.step, start=(Bm @ u0) / self.rom.lam)
        builders = {"source": self._sources, "convection": self._convection, "joint": self._joints,
                    "expansion": self._expansion, "sensor_lag": self._sensor_lag, "timing": self._timing}
        for k in kinds:
            builders[k](base_prediction)

    # --------------------------------------------------------------- helpers
    def _outputs(self, modal_states):
        """Channels of the evaluator at the measured times (n_times, p_eval) from modal states (N, r)."""
        return self._from_fe(modal_states @ self.rom.C.T)

    def _from_fe(self, fe_values):
        full = np.zeros((len(fe_values), len(self.structure.channels)))
        full[:, : self.p_fe] = fe_values
        return self.model.interp(full)[:, self.ev.cols]

    def _add(self, response, **kw):
        f, h = self.project(response)
        if np.dot(f, f) > 0:
            self.atoms.append(_Atom(fit=f, hold=h, **kw))

    def _driver_states(self, driver):
        if driver not in self._modal_drivers:
            x = self.signals[driver]
            self._modal_drivers[driver] = self.rom.filter(np.outer(x, np.ones(len(self.rom.lam))), self.step)
        return self._modal_drivers[driver]

    # --------------------------------------------------------------- candidates
    def source_atoms(self, cells: Sequence[tuple[str, np.ndarray, np.ndarray]], driver: str) -> list[_Atom]:
        """Projected atoms of unit sources in ``cells`` following ``driver``.

        Parameters
        ----------
        cells : sequence of (str, ndarray, ndarray)
            Part, tetrahedron ids and centroid (3,), m, as :func:`source_cells` gives them.
        driver : str
            Key of :data:`DRIVERS`.

        Returns
        -------
        list of _Atom
            One per cell: its projected fit and held-out vectors; its value is a power in the unit
            :func:`driver_unit` (W, at the driver's reference).
        """
        Z = self._driver_states(driver)
        bm = self.rom.modal(source_loads(self.structure.machine, cells))
        unit, atoms = driver_unit(driver, self.structure.machine), []
        for j, (part, _, centroid) in enumerate(cells):
            f, h = self.project(self._outputs(Z * bm[:, j]))
            atoms.append(_Atom("source", f"source@{part}({', '.join(f'{c:.2f}' for c in centroid)}):{driver}",
                               f"heat source on the {part}", unit, f, h, part, tuple(float(c) for c in centroid),
                               driver))
        return atoms

    def _sources(self, _):
        self.cells = source_cells(self.structure.machine)
        for driver in DRIVERS:
            self.atoms += [a for a in self.source_atoms(self.cells, driver) if np.dot(a.fit, a.fit) > 0]

    def _system_atom(self, kind, name, label, definition):
        s = self.structure

        def modal_terms():           # two assemblies (≈ 2 s): once per process and structure
            dA, dB = system_difference(s, definition)
            dB = sp.hstack([dB, sp.csc_matrix((dB.shape[0], s.n_inputs - dB.shape[1]))]).tocsc() \
                if dB.shape[1] < s.n_inputs else dB
            return self.rom.VQ.T @ (dA @ self.rom.VQ), self.rom.modal(dB)

        dAm, dBm = cached(("gap-discovery-term", id(s), name), modal_terms)
        # the sensitivity is the response to the input −dA·T(t) + dB·u(t) along the nominal trajectory T = VQ x
        F = -self.X @ dAm.T + self.U @ dBm.T
        self._add(self._outputs(self.rom.filter(F, self.step)), kind=kind, name=name, label=label,
                  unit="relative change")

    def _convection(self, _):
        d = self.structure.machine.definition
        for rule in d.convection:
            if rule.name in self.structure.machine.mesh.facet_groups:
                self._system_atom("convection", f"convection:{rule.name}",
                                  f"convection coefficient of group {rule.name!r}",
                                  scaled_definition(d, groups=(rule.name,)))

    def _joints(self, _):
        d = self.structure.machine.definition
        for a, b, _ in d.joints:
            self._system_atom("joint", f"joint:{a}-{b}", f"contact conductance of the {a}–{b} joint",
                              scaled_definition(d, joint=(a, b)))

    def _expansion(self, _):
        s = self.structure
        rows = [j for j, c in enumerate(s.channels[: self.p_fe]) if c.kind in ("displacement", "strain")]
        if not rows:
            return
        for part, Cp in part_output_columns(s, rows).items():
            fe = np.zeros((len(self.X), self.p_fe))
            fe[:, rows] = self.X @ np.asarray(Cp @ self.rom.VQ).T
            self._add(self._from_fe(fe), kind="expansion", name=f"expansion:{part}",
                      label=f"expansion coefficient of the {part}", unit="relative change", part=part)

    def _rates(self, base_prediction):
        """−ẏ of the base prediction on the sensor channels (zero on the air sensors, which drive the twin)."""
        rates = -np.gradient(base_prediction.values[:, self.ev.cols], self.model.times_s, axis=0)
        rates[:, [k == "air" for k in self.ev.kinds]] = 0.0
        return rates

    def _sensor_lag(self, base_prediction):
        rates = self._rates(base_prediction)
        for j, c in enumerate(self.ev.cols):
            R = np.zeros_like(rates)
            R[:, j] = rates[:, j]
            self._add(R, kind="sensor_lag", name=f"lag:{self.structure.names[c]}",
                      label=f"lag of sensor {self.structure.names[c]}", unit="s")

    def _timing(self, base_prediction):
        self._add(self._rates(base_prediction), kind="timing", name="timing",
                  label="delay of the sensors against the operating inputs (clock offset, input reconstruction)",
                  unit="s")


# ============================================================================= the search
def _group_ms(ev, hold_vec, hold_col):
    """Held-out mean square per channel group in channel units."""
    r = hold_vec / ev.sqrt_w[hold_col]
    return {g: float(np.mean(r[np.isin(hold_col, idx)] ** 2)) for g, idx in ev.groups().items()
            if np.isin(hold_col, idx).any()}


def _residual_matrix(ev, proj, fit_vec, hold_vec):
    R = np.full(ev.Y.shape, np.nan)
    R[ev.fit_mask] = fit_vec / ev.sqrt_w[proj.fit_col]
    R[ev.hold_mask] = hold_vec / ev.sqrt_w[proj.hold_col]
    return SimpleNamespace(R=R)


def _group_change(ev, proj, old_hold, new_hold):
    """Held-out mean-square change per channel group, in units of σ_g² (positive: better)."""
    ms_old, ms_new = _group_ms(ev, old_hold, proj.hold_col), _group_ms(ev, new_hold, proj.hold_col)
    return {g: (ms_old[g] - ms_new[g]) / ev.sigma[g] ** 2 for g in ms_old}


def _judge(ev, proj, old, new, k_added):
    """(accepted, ΔBIC, reasons) of a step from residual vectors ``old`` to ``new`` = (fit, hold)."""
    n_eff = effective_samples(_residual_matrix(ev, proj, *old), ev, ev.hold_rows)
    sse_old, sse_new = float(old[1] @ old[1]), float(new[1] @ new[1])
    dbic = -relative_bic(max(sse_new, 1e-300) / max(sse_old, 1e-300), k_added, n_eff)
    change = _group_change(ev, proj, old[1], new[1])
    reasons = []
    if dbic <= MIN_DELTA_BIC:
        reasons.append(f"held-out ΔBIC {dbic:.1f} ≤ {MIN_DELTA_BIC:g}")
    if max(change.values()) < MIN_MATERIAL:
        reasons.append(f"not material (best group change {max(change.values()):.2f} σ²)")
    return not reasons, float(dbic), reasons


def _worsened(ev, proj, base_hold, hold):
    """Channel groups whose held-out mean square is worse than the base's by more than MAX_WORSENING·σ_g²."""
    return [g for g, c in _group_change(ev, proj, base_hold, hold).items() if c < -MAX_WORSENING]


def _out_of_range(atoms, coef):
    """Names of atoms whose coefficient lies outside :data:`RANGES`."""
    return [a.name for a, c in zip(atoms, coef) if not RANGES[a.kind][0] <= c <= RANGES[a.kind][1]]


def _shortlist(atoms, scores):
    """Indices to try at a step: the :data:`SHORTLIST` best by fit-part reduction and the best of every kind."""
    order = [i for i in np.argsort(scores)[::-1] if scores[i] > 0]
    best_of_kind = {}
    for i in order:
        best_of_kind.setdefault(atoms[i].kind, i)
    return list(dict.fromkeys(order[:SHORTLIST] + list(best_of_kind.values())))


def _solve(cols, target):
    F = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(F, target, rcond=None)
    return coef


def _neighbours(dictionary, atom, reach_m):
    """Source atoms of ``atom``'s part and driver on a :data:`REFINE_M` sub-grid within ± ``reach_m`` of it."""
    mesh = dictionary.structure.machine.mesh
    cents = mesh.points[mesh.tets].mean(axis=1)
    tets = np.flatnonzero(mesh.regions == mesh.region_id(atom.part))
    centre = np.array(atom.position)
    offsets = np.arange(-reach_m, reach_m + 1e-9, REFINE_M)
    vol = np.abs(mesh.volumes)
    cells = [_cell(atom.part, tets, cents, vol, centre + d, GRID_M)
             for d in np.stack(np.meshgrid(offsets, offsets, offsets, indexing="ij"), -1).reshape(-1, 3)]
    return dictionary.source_atoms([c for c in cells if c is not None], atom.driver)


def _refine(dictionary, atom, fit_residual, chosen):
    """A source atom moved on a :data:`REFINE_M` sub-grid around its cell (best fit-part reduction)."""
    best, best_score = atom, _score(atom.fit, fit_residual, chosen)
    for cand in _neighbours(dictionary, atom, GRID_M / 2):
        sc = _score(cand.fit, fit_residual, chosen)
        if sc > best_score:
            best, best_score = cand, sc
    return best


def _score(f, r, Q):
    """Fit-part SSE reduction of adding column f to the chosen ones (Q: an orthonormal basis of them)."""
    fo = f - Q @ (Q.T @ f) if Q.shape[1] else f
    nn = float(fo @ fo)
    return float(fo @ r) ** 2 / nn if nn > 1e-300 else 0.0


def _residuals(atoms, r_fit, r_hold):
    """``(fit, hold, coef)``: the weighted residuals once ``atoms`` are least-squares fitted on the fit part."""
    if not atoms:
        return r_fit, r_hold, np.zeros(0)
    coef = _solve([a.fit for a in atoms], r_fit)
    return (r_fit - np.column_stack([a.fit for a in atoms]) @ coef,
            r_hold - np.column_stack([a.hold for a in atoms]) @ coef, coef)


def _held_change(ev, proj, before_hold, after_hold):
    """Per channel group: held-out RMS before and after, its relative reduction, and the unit."""
    ms_before, ms_after = _group_ms(ev, before_hold, proj.hold_col), _group_ms(ev, after_hold, proj.hold_col)
    return {g: {"before_rms": float(np.sqrt(ms_before[g])), "after_rms": float(np.sqrt(ms_after[g])),
                "reduction": float(1 - np.sqrt(ms_after[g] / ms_before[g])) if ms_before[g] > 0 else 0.0,
                "unit": GROUP_UNIT[g]} for g in ms_before}


def _try_atom(dic, ev, proj, chosen, atom, current, Q, r_fit, r_hold):
    """``(atom, residuals, ΔBIC, accepted, reasons)`` of adding ``atom`` (a source refined first) to ``chosen``."""
    if atom.kind == "source":
        atom = _refine(dic, atom, current[0], Q)
    fit, hold, coef = _residuals(chosen + [atom], r_fit, r_hold)
    ok, dbic, reasons = _judge(ev, proj, current, (fit, hold), 1)
    outside = _out_of_range(chosen + [atom], coef)
    if outside:
        ok = False
        reasons.append(f"fitted outside the physical range: {', '.join(outside)}")
    return atom, (fit, hold), dbic, ok, reasons


def _forward(dic, ev, proj, r_fit, r_hold, max_atoms, rejected):
    """Greedy forward selection: at each step the shortlisted atom of best ΔBIC that passes :func:`_judge`.

    Returns ``(chosen atoms, (fit, hold) residuals)``; refused candidates are appended to ``rejected``.
    """
    chosen, Q, current = [], np.zeros((len(r_fit), 0)), (r_fit, r_hold)
    for _ in range(max_atoms):
        scores = np.array([_score(a.fit, current[0], Q) for a in dic.atoms])
        accepted = None
        for i in _shortlist(dic.atoms, scores):
            atom, new, dbic, ok, reasons = _try_atom(dic, ev, proj, chosen, dic.atoms[i], current, Q, r_fit, r_hold)
            if ok and (accepted is None or dbic > accepted[2]):
                accepted = (atom, new, dbic)
            elif not ok:
                rejected.append({"step": len(chosen) + 1, "name": atom.name, "reasons": reasons, "delta_bic": dbic})
        if accepted is None:
            break
        atom, current, dbic = accepted
        atom.delta_bic = dbic
        chosen.append(atom)
        Q, _ = np.linalg.qr(np.column_stack([a.fit for a in chosen]))
    return chosen, current


def _prune(ev, proj, chosen, current, r_fit, r_hold, rejected):
    """Drop atoms until the set as a whole worsens no group against the base and stays in its physical range.

    The atom out of range goes first, else the one whose removal helps most.  ``chosen`` is changed in place;
    returns the ``(fit, hold)`` residuals of what remains.
    """
    while chosen:
        out = _out_of_range(chosen, _solve([a.fit for a in chosen], r_fit))
        if not out and not _worsened(ev, proj, r_hold, current[1]):
            break
        trials = []
        for a in chosen:
            fit, hold, _ = _residuals([b for b in chosen if b is not a], r_fit, r_hold)
            trials.append((a.name not in out, len(_worsened(ev, proj, r_hold, hold)), float(hold @ hold), a,
                           (fit, hold)))
        *_, dropped, current = min(trials, key=lambda x: x[:3])
        chosen.remove(dropped)
        rejected.append({"step": "final", "name": dropped.name, "delta_bic": dropped.delta_bic,
                         "reasons": ["outside its physical range after the refit" if dropped.name in out else
                                     "the accepted set worsened a channel group on held-out data"]})
    return current


def _position_profile(dic, chosen, coef, r_fit, n_eff):
    """Per chosen atom ``(values, radius_m)``: the coefficient vectors (k, len(chosen)) of its plausible positions.

    For a source atom, every position on the :data:`REFINE_M` sub-grid within ± :data:`PROFILE_REACH_M` is
    refitted together with the other atoms; a position is plausible when its fit-part SSE is within
    ``χ²₃(0.90) / n_eff`` (relative) of the best position's (a profile likelihood over the position with the
    effective sample count).  Each plausible position gives the whole refitted vector (the other atoms follow
    the moved one), so the range of any combination of the values is read from them.  ``radius_m`` is the
    farthest plausible position from the reported one.  Other kinds have no position: ``(coef[None], None)``.
    """
    sse = float(np.sum((r_fit - np.column_stack([a.fit for a in chosen]) @ coef) ** 2))
    out = []
    for i, a in enumerate(chosen):
        if a.kind != "source":
            out.append((coef[None], None))
            continue
        others = chosen[:i] + chosen[i + 1:]
        trials = [(sse, coef, a.position)]
        for cand in _neighbours(dic, a, PROFILE_REACH_M):
            cols = [b.fit for b in others + [cand]]
            c = _solve(cols, r_fit)
            trials.append((float(np.sum((r_fit - np.column_stack(cols) @ c) ** 2)), np.insert(c[:-1], i, c[-1]),
                           cand.position))
        bound = min(t[0] for t in trials) * (1.0 + CHI2_3_90 / n_eff)
        ok = [(c, pos) for s_, c, pos in trials if s_ <= bound] or [(coef, a.position)]
        radius = max(float(np.linalg.norm(np.subtract(pos, a.position))) for _, pos in ok)
        out.append((np.array([coef] + [c for c, _ in ok]), radius))
    return out


def _split_half_sd(ev, chosen, r_fit, combine):
    """Delete-a-half jackknife sd of the reported values ``combine @ coef``, |c(first half) − c(second half)| / 2,
    each half of the fit rows fitted alone (as :func:`twin.gap.diagnose.split_half_sd` does for the library's
    parameters): a value that drifts through the record shows a discrepancy that no residual resampling sees."""
    time_of_entry = np.nonzero(ev.fit_mask)[0]
    rows = np.flatnonzero(ev.fit_rows)
    first = time_of_entry < rows[len(rows) // 2]
    F = np.column_stack([a.fit for a in chosen])
    halves = [combine @ np.linalg.lstsq(F[half], r_fit[half], rcond=None)[0] for half in (first, ~first)]
    return np.abs(halves[1] - halves[0]) / 2.0


def _discrepancy_sd(chosen, coef, combine, remainder):
    """Per reported value ``combine @ coef``: the sd of its bias from the dictionary's own discrepancy of shape.

    A candidate's response is an idealisation (a cube of fixed size for a source of any shape, a uniform change
    of h over a whole group): the true signature is ``c · (a + Δ)``.  Least squares puts the part of Δ along
    the fitted signature into the value (a bias the resampling cannot see) and leaves the part across it in the
    remainder.  With no preferred direction for Δ the part along is, at most, as large as the part across
    (one direction across: the worst case), so the value's relative sd is ``‖remainder‖ / ‖signature‖`` on the
    fit rows — noise and other unexplained effects included, so it errs wide.
    """
    F = np.column_stack([a.fit for a in chosen])
    rest = float(np.linalg.norm(remainder))
    out = np.empty(len(combine))
    for g, row in enumerate(combine):
        signal = float(np.linalg.norm(F @ (row * coef)))
        out[g] = rest / signal * abs(row @ coef) if signal > 0 else np.inf
    return out


def _extended_sources(chosen):
    """Groups of indices of ``chosen`` reported as one effect: source atoms of one driver whose cells overlap
    (centroids within :data:`GRID_M`, any part and sign) are one extended source, whose power is their sum —
    a source larger than a cell, or of another shape, is fitted as neighbouring cells (a pair of opposite sign
    is a shape correction); every other atom is a group of its own."""
    groups = []
    for i, a in enumerate(chosen):
        near = [g for g in groups if a.kind == "source" and all(
            chosen[j].kind == "source" and chosen[j].driver == a.driver
            and np.linalg.norm(np.subtract(chosen[j].position, a.position)) <= GRID_M + 1e-9 for j in g)]
        if near:
            near[0].append(i)
        else:
            groups.append([i])
    return groups


def _discoveries(dic, ev, proj, chosen, current, r_fit, r_hold, seed, n_eff):
    """The accepted atoms as :class:`Discovery` (an extended source, :func:`_extended_sources`, as one), each
    with its 90 % interval and its own held-out change.

    The interval is the bootstrap's (:func:`_bootstrap`), widened to ± :data:`Z_90` sds of the larger of the
    split-half sd (:func:`_split_half_sd`) and the shape-discrepancy sd (:func:`_discrepancy_sd`), around every
    plausible position's value (:func:`_position_profile`: of any member,
    for an extended source), so it carries the dictionary's own discrepancy of where a source sits.
    An extended source is reported at its strongest cell; its radius reaches every member's plausible positions.
    """
    if not chosen:
        return []
    coef = _solve([a.fit for a in chosen], r_fit)
    groups = _extended_sources(chosen)
    combine = np.zeros((len(groups), len(chosen)))
    for g, members in enumerate(groups):
        combine[g, members] = 1.0
    intervals = _bootstrap(ev, chosen, coef, current, dic.model.times_s, seed, combine)
    sds = np.maximum(_split_half_sd(ev, chosen, r_fit, combine), _discrepancy_sd(chosen, coef, combine, current[0]))
    profile = _position_profile(dic, chosen, coef, r_fit, n_eff)
    items = []
    for g, (members, c, (lo, hi), sd) in enumerate(zip(groups, combine @ coef, intervals, sds)):
        a = chosen[max(members, key=lambda j: abs(coef[j]))]
        lo, hi = min(lo, c - Z_90 * sd), max(hi, c + Z_90 * sd)
        plausible = np.concatenate([profile[j][0] @ combine[g] for j in members])
        p_lo, p_hi = plausible.min(), plausible.max()
        low, high = sorted((a.scale * (p_lo - (c - lo)), a.scale * (p_hi + (hi - c))))
        radius = None if a.kind != "source" else max(
            profile[j][1] + float(np.linalg.norm(np.subtract(chosen[j].position, a.position)))
            for j in members)
        # held-out change of each effect: the model without it against the model with all
        _, without, _ = _residuals([b for j, b in enumerate(chosen) if j not in members], r_fit, r_hold)
        name = a.name if len(members) == 1 else " + ".join(chosen[j].name for j in members)
        items.append(Discovery(a.kind, name, a.label, float(c * a.scale), a.unit, (float(low), float(high)),
                               a.part, a.position, a.driver, max(chosen[j].delta_bic for j in members),
                               _held_change(ev, proj, without, current[1]), radius))
    return items


def discover(model: GapModel, evaluator: Evaluator, base: FitResult | None = None, kinds: Sequence[str] = KINDS,
             max_atoms: int = MAX_ATOMS, seed: int = 0) -> DiscoveryResult:
    """Search the residual of ``base`` (default: the nominal twin) for unmodelled effects; see the module docstring.

    ``model`` is the :class:`~twin.gap.model.GapModel` and ``evaluator`` the
    :class:`~twin.gap.fit.Evaluator` of the diagnosis (weights set, e.g. by
    :func:`twin.gap.fit.nominal_result`); ``base`` a :class:`~twin.gap.fit.FitResult`.
    Returns a :class:`DiscoveryResult`; ``seed`` fixes the bootstrap.

    Parameters
    ----------
    model : GapModel
        The diagnosis model.
    evaluator : Evaluator
        The diagnosis evaluator, weights set.
    base : FitResult, optional
        The fit whose residual is searched (default: the nominal twin).
    kinds : sequence of str, default KINDS
        Candidate kinds (of :data:`KINDS`).
    max_atoms : int, default MAX_ATOMS
        Most atoms accepted.
    seed : int, default 0
        Seed of the bootstrap.

    Returns
    -------
    DiscoveryResult
        The accepted atoms, held-out change per group (channel units), candidate count, time (s), rejections.

    Raises
    ------
    TwinInputError
        A kind not in :data:`KINDS`.
    """
    t0 = time.perf_counter()
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown:
        raise TwinInputError(f"unknown discovery kind(s) {unknown}; kinds: {list(KINDS)}")
    ev = evaluator
    if base is None:
        base = nominal_result(model, ev)
    dic = Dictionary(model, ev, base.prediction, kinds)
    proj = dic.project
    weighted = np.nan_to_num(base.residual.R) * ev.sqrt_w
    r_fit, r_hold = weighted[ev.fit_mask], weighted[ev.hold_mask]
    rejected = []
    chosen, current = _forward(dic, ev, proj, r_fit, r_hold, max_atoms, rejected)
    current = _prune(ev, proj, chosen, current, r_fit, r_hold, rejected)
    n_eff = effective_samples(_residual_matrix(ev, proj, *current), ev, ev.fit_rows)
    items = _discoveries(dic, ev, proj, chosen, current, r_fit, r_hold, seed, n_eff)
    return DiscoveryResult(items, _held_change(ev, proj, r_hold, current[1]), base.name, len(dic.atoms),
                           time.perf_counter() - t0, rejected,
                           float(current[1] @ current[1]) / max(float(r_hold @ r_hold), 1e-300), len(chosen))


def _bootstrap(ev, chosen, coef, current, times_s, seed, combine):
    """90 % intervals of the reported values ``combine @ coef`` (see the module docstring)."""
    P = np.linalg.pinv(np.column_stack([a.fit for a in chosen]))
    rows = np.flatnonzero(ev.fit_mask.any(axis=1))
    dt = float(np.median(np.diff(times_s[rows]))) if len(rows) > 1 else 1.0
    block = int(max(1, min(len(rows) // 4, round(BLOCK_H * 3600.0 / dt))))
    E = np.zeros(ev.Y.shape)
    E[ev.fit_mask] = current[0]
    rng = np.random.default_rng(seed)
    n_blocks = int(np.ceil(len(rows) / block))
    draws = np.empty((N_BOOTSTRAP, len(coef)))
    for b in range(N_BOOTSTRAP):
        first = rng.integers(0, len(rows) - block + 1, n_blocks)
        src = (first[:, None] + np.arange(block)).ravel()[: len(rows)]
        E_star = np.zeros_like(E)
        E_star[rows] = E[rows[src]]          # whole rows move: all channels at one time stay together
        draws[b] = coef + P @ E_star[ev.fit_mask]
    values = combine @ coef
    lo, hi = np.percentile(draws @ combine.T, [5, 95], axis=0)
    ms_fit = float(current[0] @ current[0]) / max(len(current[0]), 1)
    ms_hold = float(current[1] @ current[1]) / max(len(current[1]), 1)
    inflate = np.sqrt(max(1.0, ms_hold / ms_fit)) if ms_fit > 0 else 1.0
    return [(c - inflate * (c - low), c + inflate * (high - c)) for c, low, high in zip(values, lo, hi)]


def render_discoveries(result: DiscoveryResult, machine: Machine, path: str | Path) -> Path | None:
    """3-D render (PNG) of the machine with the discovered sources marked and labelled with their power.

    Parameters
    ----------
    result : DiscoveryResult
        What :func:`discover` found.
    machine : Machine
        The machine rendered.
    path : str or Path
        The PNG file.

    Returns
    -------
    Path or None
        ``path``, or None (nothing written) when no source was discovered.
    """
    from ..infra.render import render_machine

    src = [d for d in result.items if d.kind == "source"]
    if not src:
        return None
    return render_machine(machine, path, points=np.array([d.position_m for d in src]),
                          point_labels=[f"{d.value:.0f} W" + ("" if d.resolved else " (not resolved)") for d in src],
                          title="discovered heat sources (beyond the library)")
