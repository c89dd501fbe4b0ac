"""The guarded momentum step's coarse space: a two-level step that couples distant nodes.

The Jacobi-weighted step ``w·f`` moves each node by its own forces, so a smooth strain over the whole
patch takes about a dozen iterations per edge of radius to leave (``docs/guard.md``, "Speed to the
minimum"). The coarse space adds the best move, for the springs' graph Laplacian ``K``, in a small
space of smooth global functions::

    step = w·f + Φ·M·(Φᵀf),        M = (ΦᵀKΦ)⁻¹,        K = C·((1 + δ)·D − A),

``Φ`` the ``(V, m)`` monomials ``u^a·v^b``, ``a + b ≤ degree``, of the start layout's coordinates
(centred and scaled into ``[-1, 1]``), ``D`` the nodes' degrees, ``A`` the springs' adjacency and
``δ`` = :data:`STIFFNESS_SHIFT` (it keeps ``K`` regular on a free boundary). ``M`` is a run constant;
each iteration needs the ``2m`` sums ``Φᵀf`` and each node's ``Φ_i·c``. The guard is unchanged, so its
guarantees hold for any proposal.

Near the area floor the guard clips the global move node by node, and the clipped move can stop being
a descent direction, as a Laplacian-preconditioned one does. So a rolled-back plain gradient step taken
with the coarse move does not halve the step scale but takes the Jacobi step alone for
:data:`JACOBI_STEPS_AFTER_REJECTION` accepted steps (:class:`CoarseSchedule`). So does an accepted step taken
with it in which the guard shortened a node's move to ``2^-CLIP_HANDOVER_LEVEL`` or less: the move is pushing
a triangle towards the floor, where, without the barrier, the guard would otherwise hold its corners still
step after step (a developable strip stalled so, ``docs/guard.md``).

Numpy only: ``ΦᵀKΦ = C·(δ·ΦᵀDΦ + Σ_edges (Φ_i − Φ_j)(Φ_i − Φ_j)ᵀ)`` needs no sparse matrix.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .guard import StepScale

__all__ = ["DEFAULT_COARSE_DEGREE", "COARSE_DEGREE_MAX", "STIFFNESS_SHIFT", "JACOBI_STEPS_AFTER_REJECTION",
           "CLIP_HANDOVER_LEVEL", "SINGULAR_CUTOFF", "basis_exponents", "basis_coordinates", "basis", "coarse_stiffness", "coarse_inverse",
           "coarse_move", "CoarseSchedule", "clipped_deep"]

#: The degree a mesh file's guarded run takes by default (``sim.run_options.FILE_PARAMS``): it meets issue 25's
#: 120-iteration bound on the generated patches (``docs/guard.md``); :class:`~golden_model.params.FlattenParams`
#: itself defaults to none (0), the Jacobi step alone.
DEFAULT_COARSE_DEGREE = 3
#: The largest degree accepted: 15 functions; degree 4 measured no faster than 3.
COARSE_DEGREE_MAX = 4
#: ``δ`` in ``K = C·((1 + δ)·D − A)``.
STIFFNESS_SHIFT = 0.01
#: Accepted Jacobi steps after a rolled-back plain gradient step taken with the coarse move.
JACOBI_STEPS_AFTER_REJECTION = 20
#: An accepted step taken with the coarse move hands over to the Jacobi step too where a node's guard level
#: (:func:`golden_model.guard.guarded_moves`: its move shortened to ``2^-level``) reached this.
CLIP_HANDOVER_LEVEL = 2


def basis_exponents(degree: int) -> list[tuple[int, int]]:
    """The monomials' exponents ``(a, b)`` of ``u^a·v^b``, ``a + b ≤ degree``, by total degree then ``b``."""
    return [(total - b, b) for total in range(degree + 1) for b in range(total + 1)]


def basis_coordinates(positions: np.ndarray) -> np.ndarray:
    """``(V, 2)`` the layout's coordinates centred on its bounding box and scaled by its larger half-side,
    so that they lie in ``[-1, 1]`` (the coarse space does not depend on the scaling; the values' range does)."""
    low, high = positions.min(axis=0), positions.max(axis=0)
    half = float((high - low).max()) / 2.0
    return (positions - (low + high) / 2.0) / (half if half > 0 else 1.0)


def basis(positions: np.ndarray, degree: int) -> np.ndarray:
    """``(V, m)`` the coarse space's functions at the nodes: the monomials up to ``degree`` of
    :func:`basis_coordinates` (``m = (degree + 1)(degree + 2)/2``)."""
    u = basis_coordinates(positions)
    return np.stack([u[:, 0] ** a * u[:, 1] ** b for a, b in basis_exponents(degree)], axis=1)


def coarse_stiffness(phi: np.ndarray, edges: np.ndarray, spring: float) -> np.ndarray:
    """``(m, m)`` ``ΦᵀKΦ`` for the springs' Laplacian ``K = C·((1 + δ)·D − A)``."""
    degree = np.bincount(edges.ravel(), minlength=len(phi)).astype(np.float64)
    difference = phi[edges[:, 0]] - phi[edges[:, 1]]
    return spring * (STIFFNESS_SHIFT * (phi.T * degree) @ phi + difference.T @ difference)


#: Singular values of ``ΦᵀKΦ`` below this fraction of its largest are dropped (:func:`coarse_inverse`).
SINGULAR_CUTOFF = 1e-12


def coarse_inverse(phi: np.ndarray, edges: np.ndarray, spring: float) -> np.ndarray:
    """``(m, m)`` ``M = (ΦᵀKΦ)⁺``, the run constant of the coarse move [1/C]: the pseudo-inverse, so that a basis
    whose functions are dependent on the nodes (fewer nodes than functions, or a rounded basis whose highest
    monomials vanish) moves in the span they have. ``Φ·M·Φᵀ`` is the same for every solution of the normal
    equations, as ``Φᵀf`` lies in the range of ``ΦᵀKΦ`` for a regular ``K``."""
    return np.linalg.pinv(coarse_stiffness(phi, edges, spring), rcond=SINGULAR_CUTOFF, hermitian=True)


def coarse_move(phi: np.ndarray, inverse: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """``(V, 2)`` ``Φ·M·(Φᵀf)``: the best move in the coarse space for the forces ``f`` [length]."""
    return phi @ (inverse @ (phi.T @ forces))


@dataclass(frozen=True)
class CoarseSchedule:
    """Whether the next step takes the coarse move, and the guard's step scale after a rolled-back step, in the
    float and the fixed-point model alike: the coarse move is taken where the run has a coarse space
    (``active``), but not while ``jacobi_left`` accepted Jacobi steps remain after a rolled-back plain gradient
    step that took it, or after an accepted one that the guard clipped to :data:`CLIP_HANDOVER_LEVEL`."""

    active: bool = False
    jacobi_left: int = 0

    @property
    def coarse(self) -> bool:
        return self.active and self.jacobi_left == 0

    def accepted(self, clipped: bool = False) -> "CoarseSchedule":
        """After an accepted step; ``clipped``: the guard shortened a node's move in it to
        ``2^-CLIP_HANDOVER_LEVEL`` or less (:func:`clipped_deep`)."""
        if self.coarse and clipped:
            return replace(self, jacobi_left=JACOBI_STEPS_AFTER_REJECTION)
        return replace(self, jacobi_left=max(0, self.jacobi_left - 1))

    def rejected(self, scale: StepScale, with_momentum: bool) -> tuple["CoarseSchedule", StepScale]:
        """After a rolled-back step: the schedule and the guard's scale. A plain gradient step taken with the
        coarse move keeps its scale and hands over to the Jacobi step; any other follows the guard's own rule
        (:meth:`~golden_model.guard.StepScale.rejected`)."""
        if self.coarse and not with_momentum:
            return replace(self, jacobi_left=JACOBI_STEPS_AFTER_REJECTION), scale
        return self, scale.rejected(with_momentum)


def clipped_deep(levels: np.ndarray) -> bool:
    """Whether a step's guard ``levels`` (a node's move shortened to ``2^-level``, ``GUARD_LEVELS + 1`` held) hand a
    coarse step over to the Jacobi step (:data:`CLIP_HANDOVER_LEVEL`)."""
    return bool(np.any(np.asarray(levels) >= CLIP_HANDOVER_LEVEL))
