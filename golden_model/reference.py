"""Float reference of the paper's algorithm, as fixed by ``spec.md``.

Units: positions and lengths in the mesh's length unit, areas in its square,
time in the paper's dimensionless step units (``Δt = 0.01`` fixed), masses
``m_i = (rho/3)·Σ A_t``.

The model (spec "Model"):

* springs on the unique edges, rest length ``d_e = |Q_i − Q_j|``;
* force (eq. 2) ``f_i = Σ_j ½·C·(1 − d_ij/|P_j − P_i|)·(P_j − P_i)``;
* energy (eqs. 1, 3) ``E = Σ_i Σ_j ½·C·(|P_iP_j| − d_ij)² = Σ_e C·(L_e − d_e)²``,
  so ``f_i = −¼·∂E/∂P_i``;
* Euler (eqs. 7–9) ``P ← P + Δt·V + ½Δt²·a``, ``V ← V + Δt·a``, ``a = f/m``,
  then damping ``V ← (1 − γ)·V``; then the optional penalty (eqs. 10–11);
* errors ``E_S`` (eq. 12), ``E_C`` (eq. 14), flipped-triangle count;
* step: fixed ``Δt`` or variable (eqs. 18–20) with errors clamped to [0, 1];
  iteration ``k+1`` uses the errors measured after iteration ``k``;
* stopping (Algorithm 1): ``converged`` when ``E_S ≤ φ_S``, ``E_C ≤ φ_C`` and
  ``ΔE ≤ ε``; ``max-iterations`` after ``N_max``; ``diverged`` when a value
  stops being finite.  At least one iteration runs.

``jacobi`` (synchronous) is vectorised over edges; ``sequential`` follows
Algorithm 1 literally, node by node in index order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Callable, Literal

import numpy as np

from .mesh import Mesh, signed_areas_2d

__all__ = [
    "FlattenParams",
    "ParameterError",
    "SpringModel",
    "Measurement",
    "History",
    "FlattenResult",
    "flatten",
    "variable_step",
    "spring_forces",
    "spring_energy",
]

Status = Literal["converged", "max-iterations", "diverged"]
STEP_MODES = ("variable", "fixed")
UPDATE_ORDERS = ("jacobi", "sequential")


class ParameterError(ValueError):
    """A parameter outside its domain; the message is one line for the user."""


@dataclass(frozen=True)
class FlattenParams:
    """Parameters of one flattening run (defaults: the paper's Table II).

    Attributes:
        spring: spring constant ``C`` (> 0).
        density: area density ``rho`` (> 0), or ``"auto"`` for ``1/min m_i``
            with masses computed at ``rho = 1``.
        step: ``"variable"`` (eqs. 18–20) or ``"fixed"``.
        dt: the fixed step ``Δt`` (> 0), used when ``step == "fixed"``.
        update: ``"jacobi"`` (synchronous, what the hardware computes) or
            ``"sequential"`` (Algorithm 1, index order).
        damping: velocity damping ``γ`` in [0, 1); 0 is the paper.
        penalty: apply the overlap penalty (eqs. 10–11).
        penalty_kappa: ``κ`` ≥ 0, the fraction of the 3D altitude below which
            the penalty fires.
        penalty_gain: ``λ`` ≥ 0, the fraction of the shortfall moved per step.
        tol_area, tol_shape, tol_energy: ``φ_S``, ``φ_C``, ``ε`` (≥ 0).
        max_iter: ``N_max`` (≥ 1).
    """

    spring: float = 0.5
    density: float | str = 2.0
    step: str = "variable"
    dt: float = 0.01
    update: str = "jacobi"
    damping: float = 0.0
    penalty: bool = False
    penalty_kappa: float = 1.0
    penalty_gain: float = 1.0
    tol_area: float = 0.16
    tol_shape: float = 0.40
    tol_energy: float = 0.05
    max_iter: int = 100

    def __post_init__(self) -> None:
        def finite(name: str, value: float) -> float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(f"{name} must be a finite number, got {value!r}")
            return float(value)

        if finite("spring constant C", self.spring) <= 0:
            raise ParameterError(f"spring constant C must be > 0, got {self.spring}")
        if self.density != "auto" and finite("density", self.density) <= 0:
            raise ParameterError(f"density must be > 0 or 'auto', got {self.density}")
        if self.step not in STEP_MODES:
            raise ParameterError(f"step must be one of {STEP_MODES}, got {self.step!r}")
        if finite("dt", self.dt) <= 0:
            raise ParameterError(f"dt must be > 0, got {self.dt}")
        if self.update not in UPDATE_ORDERS:
            raise ParameterError(f"update must be one of {UPDATE_ORDERS}, got {self.update!r}")
        if not 0 <= finite("damping", self.damping) < 1:
            raise ParameterError(f"damping must be in [0, 1), got {self.damping}")
        for name in ("penalty_kappa", "penalty_gain", "tol_area", "tol_shape", "tol_energy"):
            if finite(name, getattr(self, name)) < 0:
                raise ParameterError(f"{name.replace('_', '-')} must be >= 0, got {getattr(self, name)}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, int) or self.max_iter < 1:
            raise ParameterError(f"max-iter must be an integer >= 1, got {self.max_iter!r}")

    def with_(self, **changes) -> "FlattenParams":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


# --------------------------------------------------------------------------- model


@dataclass(frozen=True, eq=False)
class SpringModel:
    """Everything the iteration needs that depends only on the mesh and ``P0``.

    Attributes:
        mesh: the 3D mesh.
        spring: ``C``.
        density: the ``rho`` in use (``"auto"`` resolved).
        masses: ``(V,)`` node masses.
        orientation: ``(F,)`` ±1, each face's orientation in ``P0`` (a face
            degenerate in ``P0`` takes the majority orientation).
        altitudes: ``(F, 3)`` 3D altitude ``h*`` from each corner to its
            opposite side.
    """

    mesh: Mesh
    spring: float
    density: float
    masses: np.ndarray
    orientation: np.ndarray
    altitudes: np.ndarray

    @classmethod
    def build(cls, mesh: Mesh, initial_positions: np.ndarray, spring: float, density: float | str) -> "SpringModel":
        rho = mesh.auto_density() if density == "auto" else float(density)
        signed = signed_areas_2d(initial_positions, mesh.faces)
        majority = 1.0 if np.sum(signed > 0) >= np.sum(signed < 0) else -1.0
        orientation = np.where(signed > 0, 1.0, np.where(signed < 0, -1.0, majority))
        opposite = mesh.vertices[np.roll(mesh.faces, -1, axis=1)] - mesh.vertices[np.roll(mesh.faces, -2, axis=1)]
        altitudes = 2.0 * mesh.face_areas[:, None] / np.linalg.norm(opposite, axis=2)
        return cls(mesh, float(spring), rho, mesh.masses(rho), orientation, altitudes)

    @property
    def inverse_masses(self) -> np.ndarray:
        return 1.0 / self.masses


def spring_forces(positions: np.ndarray, edges: np.ndarray, rest: np.ndarray, spring: float) -> np.ndarray:
    """Forces (eq. 2) on every node, ``(V, 2)``, all from the same positions."""
    delta = positions[edges[:, 1]] - positions[edges[:, 0]]
    length = np.hypot(delta[:, 0], delta[:, 1])
    return _accumulate(_edge_terms(delta, length, rest, spring), edges, len(positions))


def _edge_terms(delta: np.ndarray, length: np.ndarray, rest: np.ndarray, spring: float) -> np.ndarray:
    """Per-edge force on the edge's first node: ``½C·(1 − d/L)·Δ``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        coefficient = 0.5 * spring * (1.0 - rest / length)
    return coefficient[:, None] * delta


def _accumulate(terms: np.ndarray, edges: np.ndarray, n: int) -> np.ndarray:
    """Add each edge's term to its first node and subtract it from its second."""
    nodes = np.concatenate([edges[:, 0], edges[:, 1]])
    fx = np.bincount(nodes, weights=np.concatenate([terms[:, 0], -terms[:, 0]]), minlength=n)
    fy = np.bincount(nodes, weights=np.concatenate([terms[:, 1], -terms[:, 1]]), minlength=n)
    return np.column_stack([fx, fy])


def spring_energy(length: np.ndarray, rest: np.ndarray, spring: float) -> float:
    """Energy (eqs. 1, 3): ``Σ_e C·(L_e − d_e)²`` (each edge from both ends)."""
    return float(spring * np.sum((length - rest) ** 2))


def variable_step(area_error: float, shape_error: float) -> float:
    """Eqs. 18–20 with each error clamped to [0, 1] first."""
    e_s = min(max(area_error, 0.0), 1.0)
    e_c = min(max(shape_error, 0.0), 1.0)
    return 0.01 + 0.1 * (math.exp(-5.0 * (1.0 - e_s)) + math.exp(-5.0 * (1.0 - e_c)))


# --------------------------------------------------------------------------- measurement


@dataclass(frozen=True)
class Measurement:
    """The errors of one layout."""

    area_error: float
    shape_error: float
    energy: float
    flipped: int

    def finite(self) -> bool:
        return all(math.isfinite(v) for v in (self.area_error, self.shape_error, self.energy))


def measure(model: SpringModel, positions: np.ndarray, length: np.ndarray | None = None) -> Measurement:
    """``E_S``, ``E_C``, energy and flipped count of ``positions``.

    ``length`` (the 2D edge lengths) may be passed when already computed.
    """
    mesh = model.mesh
    if length is None:
        delta = positions[mesh.edges[:, 1]] - positions[mesh.edges[:, 0]]
        length = np.hypot(delta[:, 0], delta[:, 1])
    signed = signed_areas_2d(positions, mesh.faces)
    area_error = float(np.sum(np.abs(mesh.face_areas - np.abs(signed))) / np.sum(mesh.face_areas))
    shape_error = float(np.sum(np.abs(mesh.rest_lengths - length)) / np.sum(mesh.rest_lengths))
    flipped = int(np.sum(model.orientation * signed < 0))
    return Measurement(area_error, shape_error, spring_energy(length, mesh.rest_lengths, model.spring), flipped)


# --------------------------------------------------------------------------- penalty


def penalty_moves(model: SpringModel, positions: np.ndarray, kappa: float, gain: float,
                  faces: np.ndarray | None = None, orientation: np.ndarray | None = None,
                  altitudes: np.ndarray | None = None) -> np.ndarray:
    """Penalty displacement (eqs. 10–11 as fixed by the spec) of every corner's node.

    For the corner P of each face with opposite side (A, B): ``h`` is P's
    signed distance to line AB, positive on the side the face had in ``P0``;
    when ``h ≤ κ·h*`` P moves by ``λ·(κ·h* − h)`` along AB's unit normal
    towards that side.  Returns ``(V, 2)`` summed moves (``faces`` etc. may
    restrict the computation to a subset of faces).
    """
    faces = model.mesh.faces if faces is None else faces
    orientation = model.orientation if orientation is None else orientation
    altitudes = model.altitudes if altitudes is None else altitudes
    p = positions[faces]  # (F, 3, 2): corner k is P, (k+1, k+2) its opposite side
    a = np.roll(p, -1, axis=1)
    b = np.roll(p, -2, axis=1)
    side = b - a
    side_length = np.hypot(side[..., 0], side[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        normal = orientation[:, None, None] * np.stack([-side[..., 1], side[..., 0]], axis=-1) / side_length[..., None]
    h = np.sum((p - a) * normal, axis=-1)
    target = kappa * altitudes
    amount = np.where(h <= target, gain * (target - h), 0.0)
    moves = amount[..., None] * normal
    n = len(positions)
    idx = faces.ravel()
    return np.column_stack([
        np.bincount(idx, weights=moves[..., 0].ravel(), minlength=n),
        np.bincount(idx, weights=moves[..., 1].ravel(), minlength=n),
    ])


# --------------------------------------------------------------------------- results


@dataclass
class History:
    """Per-iteration record; row 0 is the initial layout (``dt`` NaN there)."""

    dt: list[float] = field(default_factory=list)
    area_error: list[float] = field(default_factory=list)
    shape_error: list[float] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    flipped: list[int] = field(default_factory=list)

    def append(self, dt: float, m: Measurement) -> None:
        self.dt.append(dt)
        self.area_error.append(m.area_error)
        self.shape_error.append(m.shape_error)
        self.energy.append(m.energy)
        self.flipped.append(m.flipped)

    def __len__(self) -> int:
        return len(self.dt)

    def rows(self) -> list[tuple]:
        """``(iteration, dt, area_error, shape_error, energy, flipped)`` rows."""
        return [
            (k, self.dt[k], self.area_error[k], self.shape_error[k], self.energy[k], self.flipped[k])
            for k in range(len(self))
        ]


@dataclass
class FlattenResult:
    """Outcome of a flattening run.

    ``positions``/``velocities`` are the last finite state; ``iterations``
    counts the iterations that produced it.  ``status == "diverged"`` means
    iteration ``iterations + 1`` produced a non-finite value.
    """

    positions: np.ndarray
    velocities: np.ndarray
    initial_positions: np.ndarray
    history: History
    status: Status
    iterations: int
    params: FlattenParams
    density: float
    engine: str = "float"
    extra: dict = field(default_factory=dict)

    @property
    def final(self) -> Measurement:
        h = self.history
        return Measurement(h.area_error[-1], h.shape_error[-1], h.energy[-1], h.flipped[-1])

    @property
    def initial(self) -> Measurement:
        h = self.history
        return Measurement(h.area_error[0], h.shape_error[0], h.energy[0], h.flipped[0])

    def summary(self) -> dict:
        """The JSON summary the CLI prints."""
        final, initial = self.final, self.initial
        return {
            "status": self.status,
            "iterations": self.iterations,
            "area_error": final.area_error,
            "shape_error": final.shape_error,
            "energy": final.energy,
            "flipped": final.flipped,
            "initial_area_error": initial.area_error,
            "initial_shape_error": initial.shape_error,
            "initial_energy": initial.energy,
            "initial_flipped": initial.flipped,
            "engine": self.engine,
            "step": self.params.step,
            "update": self.params.update,
            "damping": self.params.damping,
            "penalty": self.params.penalty,
            "density": self.density,
            **self.extra,
        }


# --------------------------------------------------------------------------- iteration


def _converged(before: Measurement, after: Measurement, params: FlattenParams) -> bool:
    """Algorithm 1's convergence test on two consecutive measurements."""
    if before.energy == 0:
        change = 0.0 if after.energy == 0 else math.inf
    else:
        change = abs(after.energy - before.energy) / before.energy
    return (after.area_error <= params.tol_area and after.shape_error <= params.tol_shape
            and change <= params.tol_energy)


class _Jacobi:
    """Synchronous update, vectorised over edges."""

    def __init__(self, model: SpringModel, params: FlattenParams, positions: np.ndarray):
        self.model, self.params = model, params
        self.edges = model.mesh.edges
        self.rest = model.mesh.rest_lengths
        self.inv_mass = model.inverse_masses[:, None]
        self.positions = positions.copy()
        self.velocities = np.zeros_like(positions)
        self._refresh()

    def _refresh(self) -> None:
        # Edge vectors of the current layout serve both its measurement and
        # the next iteration's forces: computed once.
        self.delta = self.positions[self.edges[:, 1]] - self.positions[self.edges[:, 0]]
        self.length = np.hypot(self.delta[:, 0], self.delta[:, 1])

    def measure(self) -> Measurement:
        return measure(self.model, self.positions, self.length)

    def advance(self, dt: float) -> None:
        p = self.params
        forces = _accumulate(_edge_terms(self.delta, self.length, self.rest, p.spring), self.edges, len(self.positions))
        acceleration = forces * self.inv_mass
        self.positions += dt * self.velocities + (0.5 * dt * dt) * acceleration
        self.velocities += dt * acceleration
        if p.damping:
            self.velocities *= 1.0 - p.damping
        if p.penalty:
            self.positions += penalty_moves(self.model, self.positions, p.penalty_kappa, p.penalty_gain)
        self._refresh()


class _Sequential:
    """Algorithm 1 literally: nodes in index order, each seeing moved neighbours."""

    def __init__(self, model: SpringModel, params: FlattenParams, positions: np.ndarray):
        self.model, self.params = model, params
        mesh = model.mesh
        self.indptr, self.neighbour, edge_id = mesh.neighbours
        self.rest = mesh.rest_lengths[edge_id]
        self.inv_mass = model.inverse_masses
        self.positions = positions.copy()
        self.velocities = np.zeros_like(positions)
        if params.penalty:
            # incident faces of each node, for its own penalty
            faces = mesh.faces
            order = np.argsort(faces.ravel(), kind="stable")
            self.face_of_corner = order // 3
            self.face_ptr = np.r_[0, np.cumsum(np.bincount(faces.ravel(), minlength=mesh.n_vertices))]

    def measure(self) -> Measurement:
        return measure(self.model, self.positions)

    def advance(self, dt: float) -> None:
        p = self.params
        half_dt_sq = 0.5 * dt * dt
        pos, vel = self.positions, self.velocities
        for i in range(len(pos)):
            lo, hi = self.indptr[i], self.indptr[i + 1]
            delta = pos[self.neighbour[lo:hi]] - pos[i]
            length = np.hypot(delta[:, 0], delta[:, 1])
            force = _edge_terms(delta, length, self.rest[lo:hi], p.spring).sum(axis=0)
            acceleration = force * self.inv_mass[i]
            pos[i] += dt * vel[i] + half_dt_sq * acceleration
            vel[i] += dt * acceleration
            if p.damping:
                vel[i] *= 1.0 - p.damping
            if p.penalty:
                self._penalty(i)

    def _penalty(self, i: int) -> None:
        model = self.model
        f = self.face_of_corner[self.face_ptr[i]:self.face_ptr[i + 1]]
        faces = model.mesh.faces[f]
        moves = penalty_moves(model, self.positions, self.params.penalty_kappa, self.params.penalty_gain,
                              faces=faces, orientation=model.orientation[f], altitudes=model.altitudes[f])
        self.positions[i] += moves[i]


def flatten(
    mesh: Mesh,
    initial_positions: np.ndarray,
    params: FlattenParams = FlattenParams(),
    on_iteration: Callable[[int, Measurement], None] | None = None,
) -> FlattenResult:
    """Run the float reference from ``initial_positions`` (``(V, 2)``).

    ``on_iteration(k, measurement)`` is called after each iteration (for
    progress reporting).
    """
    initial_positions = np.asarray(initial_positions, dtype=np.float64)
    if initial_positions.shape != (mesh.n_vertices, 2):
        raise ParameterError(f"initial layout must have shape ({mesh.n_vertices}, 2), got {initial_positions.shape}")
    model = SpringModel.build(mesh, initial_positions, params.spring, params.density)
    engine = (_Jacobi if params.update == "jacobi" else _Sequential)(model, params, initial_positions)
    return run(engine, params, model.density, initial_positions, on_iteration, name="float")


def run(engine, params: FlattenParams, density: float, initial_positions: np.ndarray,
        on_iteration: Callable[[int, Measurement], None] | None = None, name: str = "float",
        step_size: Callable[[Measurement], float] | None = None) -> FlattenResult:
    """Algorithm 1's outer loop around an engine with ``measure()``/``advance(dt)``.

    ``step_size`` maps the last measurement to the next ``Δt`` (default: the
    float formula of eqs. 18–20, or ``params.dt`` for the fixed step).
    """
    if step_size is None:
        if params.step == "fixed":
            def step_size(_: Measurement) -> float:
                return params.dt
        else:
            def step_size(m: Measurement) -> float:
                return variable_step(m.area_error, m.shape_error)

    history = History()
    current = engine.measure()
    history.append(math.nan, current)
    saved = (engine.positions.copy(), engine.velocities.copy())
    status: Status = "max-iterations"
    k = 0
    while k < params.max_iter:
        dt = step_size(current)
        with np.errstate(over="ignore", invalid="ignore"):
            engine.advance(dt)
            after = engine.measure()
        if not (after.finite() and np.isfinite(engine.positions).all() and np.isfinite(engine.velocities).all()):
            status = "diverged"
            engine.positions, engine.velocities = saved
            break
        k += 1
        history.append(dt, after)
        if on_iteration is not None:
            on_iteration(k, after)
        saved = (engine.positions.copy(), engine.velocities.copy())
        if _converged(current, after, params):
            status = "converged"
            break
        current = after
    return FlattenResult(engine.positions, engine.velocities, initial_positions.copy(), history,
                         status, k, params, density, engine=name)
