"""The step guard of the momentum dynamics: the energy never rises and no step inverts a triangle.

Both guarantees hold by construction, whatever the mesh, the start or the barrier's settings
(``docs/guard.md``):

* **No inversion.** The momentum step proposes a move ``D_i`` for every node. A triangle's doubled
  signed area (in the pattern's winding σ) after moving its corners by fractions ``t_a, t_b, t_c``
  of their proposals,

      X(t) = X0 + Σ_i t_i·L_i + Σ_{i<j} t_i·t_j·Q_ij,
      L_a = σ·D_a × (P_b − P_c) (and cyclically),   Q_ab = σ·D_a × D_b (and cyclically),

  is multi-affine: affine in each ``t_i`` alone (a corner's move never multiplies itself). On
  the box ``[0, τ]³`` it therefore takes its minimum at one of the box's eight corners, so if
  ``X ≥ floor`` at the seven corner subsets that move (``t_i ∈ {0, τ}``, the eighth is ``X0``),
  every combination of fractions up to ``τ`` keeps ``X ≥ floor``. Each triangle gets the
  largest ``τ = 2^-r`` (``r`` = 0 … :data:`GUARD_LEVELS`) that passes, or 0 when none does;
  each node moves by the smallest ``τ`` of its triangles. Every triangle then keeps its area
  above its floor ``min(X0, max(X0/2^FLOOR_SHIFT, X*/2^FLOOR_MIN_SHIFT))`` (``X*`` its doubled 3D
  area): a step may shrink a triangle to an eighth of its area, never below ``2^-20`` of its 3D
  area, and never past zero. A fold-free layout stays fold-free.
* **Monotone energy.** A step whose layout has a higher total energy (springs + barrier) than
  the last accepted layout is rolled back: the positions return, the momentum restarts and the
  step scale ``s`` halves (``s = 2^-shift``); after :data:`SCALE_GROW_AFTER` accepted steps in a
  row it doubles again, up to 1. The scale multiplies the weights ``w_i``; a proposal of a
  stopped momentum is ``s·w_i·f_i``, a descent direction, so a small enough scale always
  lowers the energy unless the layout is stationary. A run whose scale falls below
  ``2^-SCALE_MAX_SHIFT`` has no step left that lowers its energy: it ends as ``stalled``.

The move fractions are powers of two so that the fixed-point model and the hardware take them
with shifts, exactly (``golden_model.fixed``); the float model here is their reference.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

__all__ = ["GUARD_LEVELS", "FLOOR_SHIFT", "FLOOR_MIN_SHIFT", "SCALE_GROW_AFTER", "SCALE_MAX_SHIFT",
           "ENERGY_WINDOW", "ENERGY_FLOOR", "energy_floor_fraction", "energy_floor_strain", "area_floor", "triangle_levels", "node_levels",
           "stuck_nodes", "guarded_moves",
           "StepScale", "EnergyWindow"]

#: Move fractions 1, 1/2, …, 2^-GUARD_LEVELS; a node none of them keeps safe does not move.
GUARD_LEVELS = 6
#: A step may shrink a triangle's area to 2^-FLOOR_SHIFT of what it was …
FLOOR_SHIFT = 3
#: … but never below 2^-FLOOR_MIN_SHIFT of its 3D area (nor a triangle already below that at all).
FLOOR_MIN_SHIFT = 20
#: Accepted steps in a row after which the step scale doubles (up to 1).
SCALE_GROW_AFTER = 20
#: A run whose step scale falls below 2^-SCALE_MAX_SHIFT is ``stalled``.
SCALE_MAX_SHIFT = 20
#: Iterations over which the momentum dynamics' stop rule measures the energy change.
ENERGY_WINDOW = 10
#: The momentum dynamics' stop rule also holds once the energy is below a fraction of ``C·Σ d²`` (the
#: energy of a layout with every edge at twice its length): ``E → 0`` on a developable patch, where its
#: relative change stays large however exact the layout is. This is the largest fraction, an rms strain of
#: 1e-3; a smaller ``--tol-energy`` lowers it (:func:`energy_floor_fraction`).
ENERGY_FLOOR = 1e-6


def energy_floor_fraction(tol_energy: float) -> float:
    """The stop rule's energy floor as a fraction of ``C·Σd²``: ``min(ε, 1e-3)²``, an rms strain of
    ``min(ε, 1e-3)`` (``ε`` the relative energy change the rule asks for, ``tol_energy``), at most
    :data:`ENERGY_FLOOR`. A tighter ``ε`` asks a developable patch, which the floor stops, for a more exact
    layout; a looser one would stop a patch whose minimum lies above the floor before it got there."""
    return min(ENERGY_FLOOR, tol_energy * tol_energy)


def energy_floor_strain(tol_energy: float) -> float:
    """:func:`energy_floor_fraction` as the rms edge strain it stands for: ``min(ε, 1e-3)``."""
    return math.sqrt(energy_floor_fraction(tol_energy))


def area_floor(doubled: np.ndarray, doubled_rest: np.ndarray) -> np.ndarray:
    """Per triangle the least doubled signed area a step may leave: ``min(X0, max(X0/8, X*·2^-20))``.

    ``doubled`` is ``X0`` (in the pattern's winding: positive when unfolded), ``doubled_rest``
    ``X* = 2A`` (3D). A folded triangle (``X0 ≤ 0``) may not fold further.
    """
    return np.minimum(doubled, np.maximum(doubled * 2.0**-FLOOR_SHIFT, doubled_rest * 2.0**-FLOOR_MIN_SHIFT))


def _corners(values: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)``, each ``(3, F)``: the corners' coordinates of ``values`` (``(V, 2)``), gathered one
    coordinate at a time (gathering 1-D arrays is several times faster than gathering rows)."""
    corners = np.ascontiguousarray(faces.T)
    return (np.ascontiguousarray(values[:, 0]).take(corners), np.ascontiguousarray(values[:, 1]).take(corners))


def _terms(positions: np.ndarray, proposal: np.ndarray, faces: np.ndarray, winding: float,
           doubled_rest: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Per triangle ``X0``, the linear terms ``L_a, L_b, L_c``, the pair terms ``Q_ab, Q_bc, Q_ca`` and the floor.

    With ``P`` a corner's position and ``M`` its move, each a cross product ``u × v = u.x·v.y − u.y·v.x``:
    ``X0 = σ·(P_b − P_a) × (P_c − P_a)``, ``L_k = σ·M_k × (P_k+1 − P_k+2)``, ``Q_k,k+1 = σ·M_k × M_k+1``.
    """
    (x, y), (mx, my) = _corners(positions, faces), _corners(proposal, faces)
    x0 = winding * ((x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]))
    linear = [winding * (mx[k] * (y[(k + 1) % 3] - y[(k + 2) % 3]) - my[k] * (x[(k + 1) % 3] - x[(k + 2) % 3]))
              for k in range(3)]
    pair = [winding * (mx[k] * my[(k + 1) % 3] - my[k] * mx[(k + 1) % 3]) for k in range(3)]  # ab, bc, ca
    return x0, linear, pair, area_floor(x0, doubled_rest)


def _levels(x0: np.ndarray, linear: list[np.ndarray], pair: list[np.ndarray], floor: np.ndarray,
            levels: int) -> np.ndarray:
    """The certificate on the terms: the first level whose seven moving subsets clear the floor."""
    level = np.full(len(x0), levels + 1, dtype=np.int64)
    # Every subset's area at the full step is at least X0 + Σ min(L_i, 0) − Σ |Q_ij|: where that bound
    # clears the floor (most triangles, most steps) level 0 holds without the seven subsets.
    bound = x0 + np.minimum(linear[0], 0) + np.minimum(linear[1], 0) + np.minimum(linear[2], 0) \
        - np.abs(pair[0]) - np.abs(pair[1]) - np.abs(pair[2])
    level[bound >= floor] = 0
    pending = np.flatnonzero(~(bound >= floor))
    if not len(pending):
        return level
    lin = [v[pending] for v in linear]
    quad = [v[pending] for v in pair]
    x0, floor = x0[pending], floor[pending]
    # the seven moving subsets: a, b, c, ab, bc, ca, abc
    zero = np.zeros_like(x0)
    subset_linear = np.stack([lin[0], lin[1], lin[2], lin[0] + lin[1], lin[1] + lin[2], lin[2] + lin[0],
                              lin[0] + lin[1] + lin[2]])
    subset_pair = np.stack([zero, zero, zero, quad[0], quad[1], quad[2], quad[0] + quad[1] + quad[2]])
    for r in range(levels + 1):  # the first level that passes; passing at 2^-r implies every smaller fraction
        tau = 2.0**-r
        safe = np.all(x0 + tau * subset_linear + (tau * tau) * subset_pair >= floor, axis=0)
        level[pending[safe]] = r
        keep = ~safe
        pending, x0, floor = pending[keep], x0[keep], floor[keep]
        subset_linear, subset_pair = subset_linear[:, keep], subset_pair[:, keep]
        if not len(pending):
            break
    return level


def triangle_levels(positions: np.ndarray, proposal: np.ndarray, faces: np.ndarray, winding: float,
                    doubled_rest: np.ndarray, levels: int = GUARD_LEVELS) -> np.ndarray:
    """``(F,)`` the smallest ``r`` in 0 … ``levels`` with every corner subset moving by ``2^-r`` of its
    proposal at or above the triangle's :func:`area_floor`; ``levels + 1`` where none is.

    ``positions`` and ``proposal`` are ``(V, 2)``; ``faces`` ``(F, 3)`` in the mesh's winding;
    ``winding`` σ = ±1 the pattern's orientation; ``doubled_rest`` ``(F,)`` = ``2A``.
    """
    return _levels(*_terms(positions, proposal, faces, winding, doubled_rest), levels)


def node_levels(face_levels: np.ndarray, faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """``(V,)`` each node's level: the largest of its triangles' (its smallest move fraction). ``faces`` is
    ``(F, k)``: each row's corners take its level (a test passes one corner slot, ``k = 1``)."""
    level = np.zeros(n_vertices, dtype=np.int64)
    raised = np.flatnonzero(face_levels)
    for corner in faces[raised].T:
        np.maximum.at(level, corner, face_levels[raised])
    return level


def _stuck(x0: np.ndarray, linear: list[np.ndarray], floor: np.ndarray, faces: np.ndarray, n_vertices: int,
           levels: int) -> np.ndarray:
    """See :func:`stuck_nodes`; from the certificate's terms."""
    stuck = np.zeros(n_vertices, dtype=bool)
    tau = 2.0**-levels
    for k in range(3):  # X(t) = X0 + t·L_k is affine: failing at the smallest fraction, it fails at every one
        stuck[faces[~(x0 + tau * linear[k] >= floor), k]] = True
    return stuck


def stuck_nodes(positions: np.ndarray, proposal: np.ndarray, faces: np.ndarray, winding: float,
                doubled_rest: np.ndarray, levels: int = GUARD_LEVELS) -> np.ndarray:
    """``(V,)`` bool: the nodes whose own move, alone, takes one of their triangles below its floor even at the
    smallest fraction ``2^-levels`` (or whose proposal is not finite). Such a node cannot move; holding it
    still first keeps it from freezing its neighbours, whose moves the certificate would otherwise judge
    together with its own."""
    x0, linear, _, floor = _terms(positions, proposal, faces, winding, doubled_rest)
    return _stuck(x0, linear, floor, faces, len(positions), levels) | ~np.isfinite(proposal).all(axis=1)


def guarded_moves(positions: np.ndarray, proposal: np.ndarray, faces: np.ndarray, winding: float,
                  doubled_rest: np.ndarray, levels: int = GUARD_LEVELS) -> tuple[np.ndarray, np.ndarray]:
    """``(moves (V, 2), node levels (V,))``: each node's proposal times ``2^-level`` (0 past ``levels``).

    Two rounds: the :func:`stuck_nodes` are held still, then every triangle's certificate is taken with
    their proposals at 0 (which only removes terms, so it stays sound for the still nodes)."""
    stuck = ~np.isfinite(proposal).all(axis=1)
    free = np.where(stuck[:, None], 0.0, proposal)
    x0, linear, pair, floor = _terms(positions, free, faces, winding, doubled_rest)
    stuck |= _stuck(x0, linear, floor, faces, len(positions), levels)
    held = [stuck[faces[:, k]] for k in range(3)]  # the certificate with the stuck nodes' terms at 0
    linear = [np.where(held[k], 0.0, linear[k]) for k in range(3)]
    pair = [np.where(held[k] | held[(k + 1) % 3], 0.0, pair[k]) for k in range(3)]
    level = node_levels(_levels(x0, linear, pair, floor, levels), faces, len(positions))
    level[stuck] = levels + 1
    moves = np.ldexp(free, -np.minimum(level, levels)[:, None])
    moves[level > levels] = 0.0
    return moves, level


@dataclass(frozen=True)
class StepScale:
    """The guard's step scale ``s = 2^-shift`` and the accepted steps since it last changed."""

    shift: int = 0
    accepted: int = 0

    @property
    def value(self) -> float:
        return 2.0**-self.shift

    @property
    def stalled(self) -> bool:
        return self.shift > SCALE_MAX_SHIFT

    def rejected(self, with_momentum: bool = False) -> "StepScale":
        """After a rolled-back step: a step that carried momentum overshot, and the restart is its cure
        (the scale stays); a plain gradient step was too long, and the scale halves."""
        return StepScale(self.shift, 0) if with_momentum else StepScale(self.shift + 1, 0)

    def accepted_step(self) -> "StepScale":
        if self.accepted + 1 >= SCALE_GROW_AFTER:
            return StepScale(self.shift - 1, 0) if self.shift > 0 else StepScale(0, SCALE_GROW_AFTER)
        return StepScale(self.shift, self.accepted + 1)


@dataclass
class EnergyWindow:
    """The stop rule's memory: the energy at the end of each of the last ``size`` iterations (and the one
    before them), and whether each iteration's step was taken.

    The rule compares the newest energy with the oldest, ``size`` iterations apart (a rolled-back
    iteration repeats its energy), and only once the window holds at least one taken step: a run
    whose every step is rolled back is not converged but ends ``stalled`` (:class:`StepScale`).
    Floats or exact integers alike.
    """

    size: int
    energies: deque = field(init=False)
    taken: deque = field(init=False)

    def __post_init__(self) -> None:
        self.energies = deque(maxlen=self.size + 1)
        self.taken = deque(maxlen=self.size)

    def push(self, energy, taken: bool = True) -> None:
        if self.energies:
            self.taken.append(taken)
        self.energies.append(energy)

    @property
    def ready(self) -> bool:
        return len(self.energies) == self.size + 1 and any(self.taken)

    @property
    def oldest(self):
        return self.energies[0]
