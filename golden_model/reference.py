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
  stops being finite, or the layout runs away (:func:`runaway_width`); ``stalled`` when the guarded
  step finds no step that lowers the energy (docs/guard.md).  At least one iteration runs.

``jacobi`` (synchronous) is vectorised over edges; ``sequential`` follows
Algorithm 1 literally, node by node in index order.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import numpy as np

from .coarse import CoarseSchedule, basis, clipped_deep, coarse_inverse, coarse_move
from .guard import ENERGY_FLOOR, GUARD_LEVELS, EnergyWindow, StepScale, energy_floor_fraction, guarded_moves
from .mesh import Mesh, folded_by_area, layout_orientation, signed_areas_2d
from .modes import Step
from .params import FlattenParams, ParameterError
from .results import FlattenResult, History, Measurement, Status

__all__ = [
    "SpringModel",
    "flatten",
    "variable_step",
    "step_decay",
    "STEP_MIN",
    "STEP_SCALE",
    "STEP_RATE",
    "spring_forces",
    "spring_energy",
    "barrier_forces",
    "barrier_energy",
    "momentum_beta",
    "node_weights",
    "barrier_active_nodes",
    "barrier_stiffness",
    "iterations_to_within",
]

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
        winding: ``σ`` = ±1, the orientation of the whole ``P0``
            (:func:`~golden_model.mesh.layout_orientation`): the sign every
            face has in a fold-free layout continuing ``P0``.
        barrier: ``(κ, μ)`` of the fold barrier, or ``None`` when it is off.
    """

    mesh: Mesh
    spring: float
    density: float
    masses: np.ndarray
    orientation: np.ndarray
    altitudes: np.ndarray
    winding: float = 1.0
    barrier: tuple[float, float] | None = None

    @classmethod
    def build(cls, mesh: Mesh, initial_positions: np.ndarray, spring: float, density: float | str,
              barrier: tuple[float, float] | None = None) -> "SpringModel":
        rho = mesh.auto_density() if density == "auto" else float(density)
        signed = signed_areas_2d(initial_positions, mesh.faces)
        majority = 1.0 if np.sum(signed > 0) >= np.sum(signed < 0) else -1.0
        orientation = np.where(signed > 0, 1.0, np.where(signed < 0, -1.0, majority))
        opposite = mesh.vertices[np.roll(mesh.faces, -1, axis=1)] - mesh.vertices[np.roll(mesh.faces, -2, axis=1)]
        altitudes = 2.0 * mesh.face_areas[:, None] / np.linalg.norm(opposite, axis=2)
        return cls(mesh, float(spring), rho, mesh.masses(rho), orientation, altitudes,
                   layout_orientation(initial_positions, mesh.faces), barrier)

    @property
    def inverse_masses(self) -> np.ndarray:
        return 1.0 / self.masses

    @cached_property
    def weights(self) -> np.ndarray:
        """``(V,)`` the momentum dynamics' weights ``w_i`` while node i's barrier is active
        (:func:`node_weights` with the barrier's stiffness)."""
        return node_weights(self.mesh, self.spring, self.barrier)

    @cached_property
    def spring_weights(self) -> np.ndarray:
        """``(V,)`` the momentum dynamics' weights ``w_i = 2/(C·deg_i)`` of a node whose triangles
        are all outside the barrier (the springs' stiffness alone)."""
        return node_weights(self.mesh, self.spring, None)

    def step_weights(self, positions: np.ndarray, signed: np.ndarray | None = None) -> np.ndarray:
        """``(V,)`` this iteration's ``w_i``: :attr:`weights` at nodes with a triangle inside the
        barrier (``X < κ·X*``, :func:`barrier_active_nodes`), :attr:`spring_weights` elsewhere."""
        if self.barrier is None:
            return self.spring_weights
        active = barrier_active_nodes(positions, self.mesh.faces, self.mesh.face_areas, self.winding,
                                      self.barrier[0], signed)
        return np.where(active, self.weights, self.spring_weights)


#: The momentum step stays stable while ``w_i`` times node i's stiffness is below about
#: ``2(1 + β)``; the springs alone use 2 of it (``w_i = 2/(C·deg_i)``), and the barrier's
#: stiffness may take the rest before the weight has to shrink.
MOMENTUM_STIFFNESS_BUDGET = 4.0


def barrier_stiffness(mesh: Mesh, spring: float, gain: float, threshold: float) -> np.ndarray:
    """``(V,)`` ``b_i = Σ_t ¼·μ·C·(|e_t|²/X*_t + 2κ)``: a bound on the barrier's stiffness at node i.

    ``e_t`` is the 3D edge of triangle t opposite node i, ``X*_t`` twice its 3D area: the
    first term is the Hessian of the barrier force with respect to the node's own position,
    the second the rotation with which an active triangle couples the node to its two
    neighbours (``c·∂(D.y, −D.x)/∂P_j``, ``c ≤ ¼μCκ`` on an unfolded triangle).
    """
    faces, vertices = mesh.faces, mesh.vertices
    stiffness = np.zeros(mesh.n_vertices)
    for k in range(3):
        opposite = vertices[faces[:, (k + 1) % 3]] - vertices[faces[:, (k + 2) % 3]]
        terms = 0.25 * gain * spring * (np.sum(opposite * opposite, axis=1) / (2.0 * mesh.face_areas)
                                         + 2.0 * threshold)
        stiffness += np.bincount(faces[:, k], weights=terms, minlength=mesh.n_vertices)
    return stiffness


def node_weights(mesh: Mesh, spring: float, barrier: tuple[float, float] | None = None) -> np.ndarray:
    """``w_i = Δt/m_i = 2/(C·deg_i)``: masses ``m_i = (C/2)·deg_i`` and ``Δt = 1``.

    ``C·deg_i`` bounds the stiffness of node i's springs, so these masses make
    every node equally fast (a Jacobi preconditioner); the energy minimum
    does not depend on them.  With the fold barrier (``(κ, μ)``), a node whose
    barrier stiffness ``b_i`` (:func:`barrier_stiffness`) would push it past the
    stability budget gets the smaller ``w_i = budget/(C·deg_i + 2·b_i)``.
    """
    degree = np.diff(mesh.neighbours[0])
    weights = 2.0 / (spring * degree)
    if barrier is not None:
        stiff = barrier_stiffness(mesh, spring, barrier[1], barrier[0])
        weights = np.minimum(weights, MOMENTUM_STIFFNESS_BUDGET / (spring * degree + 2.0 * stiff))
    return weights


def momentum_beta(k: int) -> float:
    """``β_k = k/(k+3)``: the momentum of the ``k``-th iteration since the last restart."""
    return k / (k + 3)


def _barrier_shortfall(positions: np.ndarray, faces: np.ndarray, winding: float, doubled_rest: np.ndarray,
                       kappa: float, signed: np.ndarray | None = None) -> np.ndarray:
    """Per face ``(κ − X/X*)₊`` with ``X = σ·2A'``."""
    if signed is None:
        signed = signed_areas_2d(positions, faces)
    return np.maximum(kappa - winding * 2.0 * signed / doubled_rest, 0.0)


def barrier_active_nodes(positions: np.ndarray, faces: np.ndarray, face_areas: np.ndarray, winding: float,
                         kappa: float, signed: np.ndarray | None = None) -> np.ndarray:
    """``(V,)`` bool: the nodes with a triangle inside the barrier, ``X_t < κ·X*_t``.

    Only there does the barrier add stiffness, so only there must the momentum step's weight
    shrink (:meth:`SpringModel.step_weights`); everywhere else the springs' weight keeps the
    dynamics as fast as without the barrier.
    """
    active = np.zeros(len(positions), dtype=bool)
    inside = _barrier_shortfall(positions, faces, winding, 2.0 * face_areas, kappa, signed) > 0
    active[faces[inside].ravel()] = True
    return active


def _scatter(nodes: np.ndarray, moves: np.ndarray, n: int) -> np.ndarray:
    """``(n, 2)``: the 2D ``moves`` summed onto their ``nodes``."""
    return np.column_stack([np.bincount(nodes, weights=moves[..., 0].ravel(), minlength=n),
                            np.bincount(nodes, weights=moves[..., 1].ravel(), minlength=n)])


def barrier_energy(positions: np.ndarray, faces: np.ndarray, face_areas: np.ndarray, winding: float,
                   kappa: float, gain: float, spring: float, signed: np.ndarray | None = None) -> float:
    """Fold-barrier energy ``Σ_t ½·μ·C·X*_t·(κ − X_t/X*_t)₊²``.

    ``X_t = σ·2A'_t`` is the face's doubled 2D area in the pattern's winding
    ``σ``, ``X*_t = 2A_t`` its doubled 3D area: zero while every face keeps
    at least ``κ`` of its area, growing quadratically as a face shrinks
    towards a fold and beyond.  On the springs' scale (``C``, lengths²).
    """
    doubled_rest = 2.0 * face_areas
    short = _barrier_shortfall(positions, faces, winding, doubled_rest, kappa, signed)
    return float(0.5 * gain * spring * np.sum(doubled_rest * short * short))


def barrier_forces(positions: np.ndarray, faces: np.ndarray, face_areas: np.ndarray, winding: float,
                   kappa: float, gain: float, spring: float, signed: np.ndarray | None = None) -> np.ndarray:
    """``(V, 2)`` barrier forces ``−¼·∂B/∂P`` (the springs' convention, eq. 2).

    Per face and corner ``i`` with the other corners ``j, k`` in winding order:
    ``f_i = ¼·μ·C·(κ − X/X*)₊ · σ·(P_j.y − P_k.y, P_k.x − P_j.x)``, the
    direction that grows the face's area fastest.  ``faces`` may be a subset
    of the mesh's (with their 3D ``face_areas``).
    """
    short = _barrier_shortfall(positions, faces, winding, 2.0 * face_areas, kappa, signed)
    active = np.flatnonzero(short)  # the barrier acts on few faces: only theirs are gathered
    faces = faces[active]
    coefficient = (0.25 * gain * spring * winding * short[active])[:, None]
    # (F, 3) per coordinate, corner i's column; j = i + 1 and k = i + 2 (mod 3) its side
    x, y = np.ascontiguousarray(positions[:, 0]).take(faces), np.ascontiguousarray(positions[:, 1]).take(faces)
    j, k = [1, 2, 0], [2, 0, 1]
    n = len(positions)
    nodes = faces.ravel()
    return np.column_stack([np.bincount(nodes, weights=(coefficient * (y[:, j] - y[:, k])).ravel(), minlength=n),
                            np.bincount(nodes, weights=(coefficient * (x[:, k] - x[:, j])).ravel(), minlength=n)])


def barrier_force_on(node: int, positions: np.ndarray, faces: np.ndarray, face_areas: np.ndarray, winding: float,
                     kappa: float, gain: float, spring: float) -> np.ndarray:
    """``(2,)`` the barrier force on ``node`` alone, from ``faces``, the node's own triangles (each holds it once):
    :func:`barrier_forces`'s row ``node``, the same terms added in the same order (bit for bit), at the cost of
    the node's triangles rather than of every node (the sequential update asks it node by node)."""
    short = _barrier_shortfall(positions, faces, winding, 2.0 * face_areas, kappa)
    active = np.flatnonzero(short)
    faces = faces[active]
    coefficient = 0.25 * gain * spring * winding * short[active]
    corner = np.argmax(faces == node, axis=1)
    rows = np.arange(len(faces))
    j, k = faces[rows, (corner + 1) % 3], faces[rows, (corner + 2) % 3]
    x, y = positions[:, 0], positions[:, 1]
    first = np.zeros(len(faces), dtype=np.intp)  # one bin: bincount adds in order, as barrier_forces's does
    return np.array([np.bincount(first, weights=coefficient * (y[j] - y[k]), minlength=1)[0],
                     np.bincount(first, weights=coefficient * (x[k] - x[j]), minlength=1)[0]])


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


def iterations_to_within(shape_errors, target: float, rel: float = 0.01, floor: float = 1e-4) -> int | None:
    """First iteration from which E_C stays within ``rel`` of ``target`` (or ``floor`` absolute).

    The measure of docs/dynamics.md: ``floor`` serves meshes whose converged E_C is 0
    (developable ones).  ``None`` when the last value is still outside.
    """
    errors = np.asarray(shape_errors)
    outside = np.flatnonzero(np.abs(errors - target) > max(rel * target, floor))
    if len(outside) == 0:
        return 0
    return None if outside[-1] + 1 >= len(errors) else int(outside[-1] + 1)


#: The variable step (eqs. 18–20): ``Δt = STEP_MIN + STEP_SCALE·(step_decay(E_S) + step_decay(E_C))``.
#: The only place the formula is written; the fixed-point step generator's table
#: (``golden_model.fixed.steplut``) is built from these constants and checked against it.
STEP_MIN = 0.01
STEP_SCALE = 0.1
STEP_RATE = 5


def step_decay(error):
    """``exp(−STEP_RATE·(1 − E))`` with ``E`` clamped to [0, 1]; a float or an array."""
    return np.exp(-STEP_RATE * (1.0 - np.clip(error, 0.0, 1.0)))


def variable_step(area_error, shape_error):
    """Eqs. 18–20 with each error clamped to [0, 1] first; floats or arrays (then elementwise)."""
    dt = STEP_MIN + STEP_SCALE * (step_decay(area_error) + step_decay(shape_error))
    return float(dt) if np.ndim(dt) == 0 else dt


# --------------------------------------------------------------------------- measurement


def measure(model: SpringModel, positions: np.ndarray, length: np.ndarray | None = None,
            signed: np.ndarray | None = None, energy: float | None = None) -> Measurement:
    """``E_S``, ``E_C``, energy and flipped count of ``positions``.

    ``length`` (the 2D edge lengths), ``signed`` (the faces' signed areas) and ``energy`` (springs and
    barrier) may be passed when already computed for ``positions``.
    """
    mesh = model.mesh
    if length is None:
        delta = positions[mesh.edges[:, 1]] - positions[mesh.edges[:, 0]]
        length = np.hypot(delta[:, 0], delta[:, 1])
    if signed is None:
        signed = signed_areas_2d(positions, mesh.faces)
    area_error = float(np.sum(np.abs(mesh.face_areas - np.abs(signed))) / np.sum(mesh.face_areas))
    shape_error = float(np.sum(np.abs(mesh.rest_lengths - length)) / np.sum(mesh.rest_lengths))
    flipped = int(np.sum(model.orientation * signed < 0))
    folded = int(np.count_nonzero(folded_by_area(signed)))
    if energy is None:
        energy = layout_energy(model, positions, length, signed)
    return Measurement(area_error, shape_error, energy, flipped, folded)


def layout_energy(model: SpringModel, positions: np.ndarray, length: np.ndarray, signed: np.ndarray) -> float:
    """The energy the stop rule and the guard watch: springs (eqs. 1, 3) plus the fold barrier, of
    ``positions`` with its edge ``length`` and faces' ``signed`` areas."""
    mesh = model.mesh
    energy = spring_energy(length, mesh.rest_lengths, model.spring)
    if model.barrier is not None:
        energy += barrier_energy(positions, mesh.faces, mesh.face_areas, model.winding, *model.barrier, model.spring,
                                 signed)
    return energy


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
    return _scatter(faces.ravel(), amount[..., None] * normal, len(positions))


def penalty_move_of(model: SpringModel, positions: np.ndarray, node: int, own_faces: np.ndarray, kappa: float,
                    gain: float) -> np.ndarray:
    """``(2,)`` :func:`penalty_moves`'s row ``node``, bit for bit, from ``own_faces``, the indices of the node's
    triangles in ascending order: computed over their corners only, renumbered, so that it costs the node's
    neighbourhood rather than every node (the sequential update asks it node by node)."""
    corners, local = np.unique(model.mesh.faces[own_faces], return_inverse=True)
    moves = penalty_moves(model, positions[corners], kappa, gain, faces=local.reshape(-1, 3),
                          orientation=model.orientation[own_faces], altitudes=model.altitudes[own_faces])
    return moves[np.searchsorted(corners, node)]


# --------------------------------------------------------------------------- iteration


def energy_floor(mesh: Mesh, params: FlattenParams) -> float:
    """The energy below which the stop rule's energy part holds whatever its change:
    ``energy_floor_fraction(ε)·C·Σd²`` in the guarded momentum mode; 0 (no floor) in the other modes, whose
    stop rule is the one the engine has, and with ``tol_energy = 0``, which asks for no energy stop."""
    if not (params.guard and params.tol_energy > 0):
        return 0.0
    return energy_floor_fraction(params.tol_energy) * params.spring * float(np.sum(mesh.rest_lengths**2))


#: The smallest ``C·Σd²`` (the springs' energy scale, mesh units²) a float run accepts: the guard's energy
#: floor at its largest (``ENERGY_FLOOR·C·Σd²``, an rms strain of 1e-3) is then a normal float. Below it, energies
#: lose their precision and then underflow to 0, and an unmoved layout passed the stop rule as converged.
MIN_ENERGY_SCALE = sys.float_info.min / ENERGY_FLOOR


def check_energy_scale(mesh: Mesh, spring: float) -> None:
    """Refuse a spring constant whose energies underflow on ``mesh`` (:data:`MIN_ENERGY_SCALE`)."""
    scale = spring * float(np.sum(mesh.rest_lengths**2))
    if scale < MIN_ENERGY_SCALE:
        raise ParameterError(
            f"spring constant C = {spring:g} is too small for this mesh: its energies (C times the squared "
            f"edge lengths, {scale:.3g} in all) underflow below what a float resolves (about "
            f"{MIN_ENERGY_SCALE:.0e}); bring --spring nearer 1, or the mesh's coordinates")


#: A layout wider than this many times the mesh's edges laid end to end (or than the start) has run away:
#: the mesh is connected, so a layout whose every edge is at most k times its 3D length is at most k times
#: their sum wide, and this one has an edge stretched ten thousandfold. The run is ``diverged`` while its
#: numbers are still finite: an undamped run, or the paper's overlap penalty as written, can grow for
#: thousands of iterations before anything overflows.
RUNAWAY_FACTOR = 1e4


def runaway_width(mesh: Mesh, start: np.ndarray) -> float:
    """The layout width past which a run from ``start`` has run away (:data:`RUNAWAY_FACTOR`), in the mesh's
    units: :data:`RUNAWAY_FACTOR` times the sum of the mesh's edge lengths, or the start's width if that is
    larger; widths are bounding-box sides, so a layout that merely drifts does not count."""
    return RUNAWAY_FACTOR * max(float(np.sum(mesh.rest_lengths)), float(np.ptp(mesh.vertices, axis=0).max()),
                                float(np.ptp(start, axis=0).max()))


def in_range(positions: np.ndarray, width: float) -> bool:
    """Whether ``positions`` are finite and no wider than ``width`` (:func:`runaway_width`)."""
    with np.errstate(invalid="ignore", over="ignore"):
        return bool(np.isfinite(positions).all() and np.ptp(positions, axis=0).max() <= width)


def _converged(energy_before: float, after: Measurement, params: FlattenParams, floor: float = 0.0) -> bool:
    """Algorithm 1's convergence test: ``after``'s errors, and its energy against ``energy_before``, the
    energy :attr:`FlattenParams.energy_window` iterations earlier: ``|ΔE| ≤ ε·E_before``, or
    ``E ≤ floor`` (:func:`energy_floor`)."""
    if energy_before == 0:
        change = 0.0 if after.energy == 0 else math.inf
    else:
        change = abs(after.energy - energy_before) / energy_before
    return (after.area_error <= params.tol_area and after.shape_error <= params.tol_shape
            and (change <= params.tol_energy or after.energy < floor))


@dataclass
class GuardRecord:
    """What the step guard did in a run: its scale, and counts of rolled-back steps and of node
    steps shortened (``clipped``: moved by less than the proposal) or stopped (``frozen``)."""

    scale: StepScale = field(default_factory=StepScale)
    rejected: int = 0
    clipped: int = 0
    frozen: int = 0

    def count_levels(self, levels: np.ndarray) -> None:
        self.clipped += int(np.count_nonzero(levels))
        self.frozen += int(np.count_nonzero(levels > GUARD_LEVELS))

    def summary(self) -> dict:
        return {"rejected_steps": self.rejected, "clipped_node_steps": self.clipped,
                "frozen_node_steps": self.frozen, "step_scale": self.scale.value}


class _Jacobi:
    """Synchronous update, vectorised over edges."""

    def __init__(self, model: SpringModel, params: FlattenParams, positions: np.ndarray):
        self.model, self.params = model, params
        self.edges = model.mesh.edges
        self.rest = model.mesh.rest_lengths
        self.inv_mass = model.inverse_masses[:, None]
        self.positions = positions.copy()
        self.velocities = np.zeros_like(positions)
        self.momentum_k = 0  # iterations since the last restart
        self.restart = False  # S < 0 seen in the last force pass
        self._refresh()
        self.guard = GuardRecord() if params.guard else None
        self.coarse = None  # the coarse space's Φ and M (golden_model.coarse)
        if params.coarse_degree:
            phi = basis(positions, params.coarse_degree)
            self.coarse = (phi, coarse_inverse(phi, self.edges, params.spring))
        self.coarse_schedule = CoarseSchedule(active=self.coarse is not None)
        self.accepted = True  # the last advance's step was taken
        self.stalled = False
        if self.guard is not None:
            self.energy = self.measure().energy  # of the last accepted layout

    def _refresh(self) -> None:
        # Edge vectors of the current layout serve both its measurement and
        # the next iteration's forces: computed once.
        x, y = np.ascontiguousarray(self.positions[:, 0]), np.ascontiguousarray(self.positions[:, 1])
        self.delta = np.column_stack([x.take(self.edges[:, 1]) - x.take(self.edges[:, 0]),
                                      y.take(self.edges[:, 1]) - y.take(self.edges[:, 0])])
        self.length = np.hypot(self.delta[:, 0], self.delta[:, 1])
        self.signed = signed_areas_2d(self.positions, self.model.mesh.faces)
        self._layout_energy = None  # energy_of_layout's, once asked for

    def measure(self) -> Measurement:
        return measure(self.model, self.positions, self.length, self.signed, self._layout_energy)

    def forces(self) -> np.ndarray:
        """Spring forces (eq. 2) plus the barrier's, all from the current positions."""
        p, model = self.params, self.model
        forces = _accumulate(_edge_terms(self.delta, self.length, self.rest, p.spring), self.edges, len(self.positions))
        if model.barrier is not None:
            forces += barrier_forces(self.positions, model.mesh.faces, model.mesh.face_areas, model.winding,
                                     *model.barrier, p.spring, self.signed)
        return forces

    def advance(self, dt: float) -> None:
        if self.params.mode.step is Step.MOMENTUM:
            self._advance_momentum()
            return
        p = self.params
        forces = self.forces()
        acceleration = forces * self.inv_mass
        self.positions += dt * self.velocities + (0.5 * dt * dt) * acceleration
        self.velocities += dt * acceleration
        if p.damping:
            self.velocities *= 1.0 - p.damping
        if p.penalty:
            self.positions += penalty_moves(self.model, self.positions, p.penalty_kappa, p.penalty_gain)
        self._refresh()

    def _advance_momentum(self) -> None:
        """``V ← β_k·V + w·f``, ``P ← P + V``; a restart (``V := 0``, ``k := 0``) one iteration after ``S < 0``.

        With the guard (:mod:`golden_model.guard`) the weights carry the step scale, each node moves by
        its guarded fraction of ``V`` (``V`` becomes the move taken), and a step that raises the energy
        is rolled back: the layout stays, ``V := 0``, ``k := 0`` and the scale halves.
        """
        p, guard = self.params, self.guard
        forces = self.forces()
        if self.restart:
            self.velocities[:] = 0.0
            self.momentum_k = 0
        power = float(np.sum(forces * self.velocities))  # S = Σ f·V, acted on next iteration
        step = self._force_step(forces)
        if guard is not None:
            step = guard.scale.value * step  # a power of two: exactly (s·w)·f
        proposal = momentum_beta(self.momentum_k) * self.velocities + step
        with_momentum = self.momentum_k > 0
        if guard is None:
            self.velocities = proposal
            self.positions += proposal
            self.momentum_k += 1
            self.restart = power < 0
            if p.penalty:
                self.positions += penalty_moves(self.model, self.positions, p.penalty_kappa, p.penalty_gain)
            self._refresh()
            return
        mesh = self.model.mesh
        moves, levels = guarded_moves(self.positions, proposal, mesh.faces, self.model.winding, 2.0 * mesh.face_areas)
        guard.count_levels(levels)
        before = (self.positions, self.delta, self.length, self.signed, self._layout_energy)
        self.positions = self.positions + moves
        self._refresh()
        energy = self.energy_of_layout()
        self.accepted = energy <= self.energy
        if self.accepted:
            self.energy = energy
            self.velocities = moves
            self.momentum_k += 1
            self.restart = power < 0
            guard.scale = guard.scale.accepted_step()
            self.coarse_schedule = self.coarse_schedule.accepted(clipped_deep(levels))
        else:
            self.positions, self.delta, self.length, self.signed, self._layout_energy = before
            self.velocities = np.zeros_like(self.velocities)
            self.momentum_k = 0
            self.restart = False
            guard.rejected += 1
            self._after_rejection(with_momentum)

    def _force_step(self, forces: np.ndarray) -> np.ndarray:
        """The momentum step's force term ``w·f`` (length units, before the guard's scale), ``w`` the step
        weights of the current layout (``SpringModel.step_weights``), plus the coarse move ``Φ·M·(Φᵀf)``
        where the coarse space is on and its schedule takes it."""
        step = self.model.step_weights(self.positions, self.signed)[:, None] * forces
        if self.coarse_schedule.coarse:
            step = step + coarse_move(*self.coarse, forces)
        return step

    def _after_rejection(self, with_momentum: bool) -> None:
        """A rolled-back step's effect on the guard's scale: it halves after a plain gradient step, but for
        one taken with the coarse move, after which the Jacobi step goes alone for a while
        (:class:`~golden_model.coarse.CoarseSchedule`)."""
        guard = self.guard
        self.coarse_schedule, guard.scale = self.coarse_schedule.rejected(guard.scale, with_momentum)
        self.stalled = guard.scale.stalled

    def energy_of_layout(self) -> float:
        """The energy the stop rule and the guard watch (springs + barrier) of the current layout."""
        if self._layout_energy is None:
            self._layout_energy = layout_energy(self.model, self.positions, self.length, self.signed)
        return self._layout_energy


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
        # incident faces of each node, for its own penalty and barrier
        corners = mesh.faces.ravel()
        self.face_of_corner = np.argsort(corners, kind="stable") // 3
        self.face_ptr = np.r_[0, np.cumsum(np.bincount(corners, minlength=mesh.n_vertices))]

    def measure(self) -> Measurement:
        return measure(self.model, self.positions)

    def advance(self, dt: float) -> None:
        p = self.params
        half_dt_sq = 0.5 * dt * dt
        pos, vel = self.positions, self.velocities
        model = self.model
        for i in range(len(pos)):
            lo, hi = self.indptr[i], self.indptr[i + 1]
            delta = pos[self.neighbour[lo:hi]] - pos[i]
            length = np.hypot(delta[:, 0], delta[:, 1])
            force = _edge_terms(delta, length, self.rest[lo:hi], p.spring).sum(axis=0)
            if model.barrier is not None:
                force += self._barrier_force(i)
            acceleration = force * self.inv_mass[i]
            pos[i] += dt * vel[i] + half_dt_sq * acceleration
            vel[i] += dt * acceleration
            if p.damping:
                vel[i] *= 1.0 - p.damping
            if p.penalty:
                self._penalty(i)

    def _barrier_force(self, i: int) -> np.ndarray:
        model = self.model
        incident = self.face_of_corner[self.face_ptr[i]:self.face_ptr[i + 1]]
        return barrier_force_on(i, self.positions, model.mesh.faces[incident], model.mesh.face_areas[incident],
                                model.winding, *model.barrier, self.params.spring)

    def _penalty(self, i: int) -> None:
        f = self.face_of_corner[self.face_ptr[i]:self.face_ptr[i + 1]]
        self.positions[i] += penalty_move_of(self.model, self.positions, i, f, self.params.penalty_kappa,
                                             self.params.penalty_gain)


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
    check_energy_scale(mesh, params.spring)
    barrier = (params.barrier_threshold, params.barrier_gain) if params.barrier else None
    model = SpringModel.build(mesh, initial_positions, params.spring, params.density, barrier)
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
        step = params.mode.step
        if step is Step.MOMENTUM:
            def step_size(_: Measurement) -> float:
                return 1.0  # Δt = 1: the weights w_i carry the step
        elif step is Step.FIXED:
            def step_size(_: Measurement) -> float:
                return params.dt
        else:
            def step_size(m: Measurement) -> float:
                return variable_step(m.area_error, m.shape_error)

    history = History()
    current = engine.measure()
    history.append(math.nan, current, accepted=None)  # (the start: no step)
    window = EnergyWindow(params.energy_window)
    window.push(current.energy)
    floor = energy_floor(engine.model.mesh, params)
    width = runaway_width(engine.model.mesh, initial_positions)
    saved = (engine.positions.copy(), engine.velocities.copy())
    status: Status = "max-iterations"
    k = 0
    while k < params.max_iter:
        dt = step_size(current)
        with np.errstate(over="ignore", invalid="ignore"):
            engine.advance(dt)
            after = engine.measure()
        if not (after.finite() and np.isfinite(engine.velocities).all() and in_range(engine.positions, width)):
            status = "diverged"
            engine.positions, engine.velocities = saved
            break
        k += 1
        accepted = getattr(engine, "accepted", True)
        history.append(dt, after, accepted)
        if on_iteration is not None:
            on_iteration(k, after)
        saved = (engine.positions.copy(), engine.velocities.copy())
        if getattr(engine, "stalled", False):
            status = "stalled"
            break
        window.push(after.energy, accepted)
        if window.ready and _converged(window.oldest, after, params, floor):
            status = "converged"
            break
        current = after
    guard = getattr(engine, "guard", None)
    extra = guard.summary() if guard is not None else {}
    return FlattenResult(engine.positions, engine.velocities, initial_positions.copy(), history,
                         status, k, params, density, engine=name, extra=extra)
