"""Untangling a folded layout: Garanzha et al. 2021, "Foldover-free maps in 50 lines of code".

The guarded dynamics (:mod:`golden_model.guard`) keeps a fold-free layout fold-free but cannot
clear a fold it starts with. This module removes folds first. Each triangle's Jacobian ``J``
maps its 3D shape (laid flat in its own plane) onto the layout; the energy

    F_ε = Σ_t A_t·((1 − θ)·|J|²_F + θ·(1 + det² J)) / χ(det J, ε),   χ(D, ε) = (D + √(ε² + D²))/2,

is finite for every layout (also folded ones, ``det J ≤ 0``) while ``ε > 0``, and as ``ε`` shrinks
it approaches an energy that is infinite on folded triangles. Minimising ``F_ε`` with L-BFGS and
shrinking ``ε`` by the paper's rule after each minimisation drives every ``det J`` positive.
The boundary is free (the paper's 2D code holds it fixed): a pattern has no prescribed outline. With a free
boundary the paper's weights shrink the layout: while ``ε`` is large against ``det J`` (the paper starts at
``ε = 1``), ``χ`` hardly grows with ``det J`` and every term is smallest at ``J = 0``, and its area term
(``θ = 1/128``) barely holds a triangle's size. So the layout is first brought to the mesh's size (its edge
lengths fitted to the 3D ones), ``ε`` starts at :data:`UNTANGLE_EPS0` of a triangle at its 3D size, and
``θ`` is :data:`UNTANGLE_THETA`: measured in docs/guard.md ("The start").

The result is a start for the dynamics, not a final pattern: the shape energy makes triangles
conformal and the area term keeps them at their 3D size, so it is near an isometry wherever one
exists, and the dynamics then lowers the springs' energy from there without creating a fold.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from threadpoolctl import threadpool_limits

from golden_model.mesh import Mesh, layout_orientation

__all__ = ["UntangleResult", "untangle_layout", "at_mesh_size", "size_factor", "symmetric_dirichlet",
           "UNTANGLE_THETA", "UNTANGLE_EPS0", "UNTANGLE_EVALUATIONS"]

#: The weight of the area term against the shape term (the paper's, for a fixed boundary, is 1/128).
UNTANGLE_THETA = 0.5
#: ``ε`` of the first minimisation, against ``det J = 1`` of a triangle at its 3D size (the paper's is 1).
UNTANGLE_EPS0 = 0.01
#: The energy evaluations all minimisations together may take: a bound on the work that gives the same
#: result on a busy machine as on an idle one (a time limit would not).
UNTANGLE_EVALUATIONS = 20_000


@dataclass(frozen=True)
class UntangleResult:
    """``positions`` (V, 2), at the mesh's size (:func:`at_mesh_size`); ``folded`` triangles left (0 on success);
    ``rounds`` of ε; ``seconds``."""

    positions: np.ndarray
    folded: int
    rounds: int
    seconds: float


def _reference_gradients(mesh: Mesh) -> np.ndarray:
    """``(F, 3, 2)``: the gradient of each corner's barycentric coordinate on the triangle laid flat.

    ``J = Σ_i P_i ⊗ G_i`` is then the Jacobian of the affine map from the 3D triangle (in its own
    plane, the mesh's winding counter-clockwise) onto the layout.
    """
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    ab, ac = b - a, c - a
    length = np.linalg.norm(ab, axis=1)
    x_c = np.sum(ab * ac, axis=1) / length
    y_c = np.linalg.norm(np.cross(ab, ac), axis=1) / length
    # flat corners (0, 0), (length, 0), (x_c, y_c); inverse of the edge matrix [[length, x_c], [0, y_c]]
    inv = np.zeros((len(length), 2, 2))
    inv[:, 0, 0] = 1.0 / length
    inv[:, 0, 1] = -x_c / (length * y_c)
    inv[:, 1, 1] = 1.0 / y_c
    corners = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])
    return np.einsum("kj,fja->fka", corners, inv)  # G_k = corners[k] · E^-1


def symmetric_dirichlet(mesh: Mesh, positions: np.ndarray) -> float:
    """``Σ_t A_t·(|J|²_F + |J⁻¹|²_F)`` (SLIM's energy; infinite where a triangle is flat or folded)."""
    corner = np.asarray(positions, dtype=np.float64)[mesh.faces]
    jac = np.einsum("fkd,fka->fda", corner, _reference_gradients(mesh))
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    norm = np.sum(jac * jac, axis=(1, 2))
    with np.errstate(divide="ignore"):
        per_face = np.where(det > 0, norm * (1.0 + 1.0 / (det * det)), np.inf)
    return float(np.sum(mesh.face_areas * per_face))


def _chi(det: np.ndarray, eps: float) -> np.ndarray:
    root = np.sqrt(eps * eps + det * det)
    positive = det > 0
    # for det <= 0 the algebraically equal form avoids the cancellation of det + root
    return np.where(positive, 0.5 * (det + root), 0.5 * eps * eps / np.where(positive, 1.0, root - det))


def _energy_and_gradient(flat: np.ndarray, faces: np.ndarray, grads: np.ndarray, areas: np.ndarray,
                         eps: float, theta: float) -> tuple[float, np.ndarray, np.ndarray]:
    positions = flat.reshape(-1, 2)
    corner = positions[faces]  # (F, 3, 2)
    jac = np.einsum("fkd,fka->fda", corner, grads)  # J[d, axis]
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    cof = np.stack([np.stack([jac[:, 1, 1], -jac[:, 1, 0]], axis=1),
                    np.stack([-jac[:, 0, 1], jac[:, 0, 0]], axis=1)], axis=1)  # ∂det/∂J
    c1 = _chi(det, eps)
    c2 = 0.5 + det / (2.0 * np.sqrt(eps * eps + det * det))  # ∂χ/∂det
    shape = np.sum(jac * jac, axis=(1, 2)) / c1
    area_term = (1.0 + det * det) / c1
    energy = float(np.sum(areas * ((1.0 - theta) * shape + theta * area_term)))
    d_shape = (2.0 * jac - (shape * c2)[:, None, None] * cof) / c1[:, None, None]
    d_area = cof * ((2.0 * det - area_term * c2) / c1)[:, None, None]
    d_jac = areas[:, None, None] * ((1.0 - theta) * d_shape + theta * d_area)
    d_corner = np.einsum("fda,fka->fkd", d_jac, grads)
    gradient = np.zeros_like(positions)
    np.add.at(gradient, faces.ravel(), d_corner.reshape(-1, 2))
    return energy, gradient.ravel(), det


def size_factor(mesh: Mesh, positions: np.ndarray) -> float:
    """The factor that fits the layout's edge lengths ``L`` to the mesh's 3D ones ``d`` in least squares,
    ``Σ L·d / Σ L²`` (1 for a layout at a minimum of the springs' energy, whose scale it cannot lower; 1 where
    every edge has length 0)."""
    lengths = mesh.layout_lengths(positions)
    squares = float(lengths @ lengths)
    return float(lengths @ mesh.rest_lengths) / squares if squares > 0 else 1.0


def at_mesh_size(mesh: Mesh, positions: np.ndarray) -> np.ndarray:
    """``positions`` scaled by :func:`size_factor`."""
    return positions * size_factor(mesh, positions)


def untangle_layout(mesh: Mesh, positions: np.ndarray, *, max_rounds: int = 200,
                    max_evaluations: int = UNTANGLE_EVALUATIONS, theta: float = UNTANGLE_THETA,
                    eps0: float = UNTANGLE_EPS0, progress=None) -> UntangleResult:
    """Remove the folds of ``positions`` (V, 2), or as many as ``max_rounds`` rounds of ``ε`` and
    ``max_evaluations`` evaluations of the energy allow.

    The layout is brought to the mesh's size first (:func:`at_mesh_size`), and mirrored into the mesh's winding
    when its bulk is clockwise, and back at the end, so the pattern keeps its orientation.
    ``progress(rounds, folded)`` is called after each round.
    """
    start = time.monotonic()
    sigma = 1.0 if _winding_agrees(mesh, positions) else -1.0
    flip = np.array([sigma, 1.0])
    x = (at_mesh_size(mesh, np.asarray(positions, dtype=np.float64)) * flip).ravel()
    grads, areas, faces = _reference_gradients(mesh), mesh.face_areas, mesh.faces
    eps = eps0
    rounds = evaluations = 0
    _, _, det = _energy_and_gradient(x, faces, grads, areas, eps, theta)
    while rounds < max_rounds and evaluations < max_evaluations:
        rounds += 1
        before, _, _ = _energy_and_gradient(x, faces, grads, areas, eps, theta)
        with threadpool_limits(1):  # L-BFGS-B's small BLAS calls only lose time to threads
            result = minimize(_energy_and_gradient_only, x, args=(faces, grads, areas, eps, theta), jac=True,
                              method="L-BFGS-B", options={"maxiter": 2000, "maxfun": max_evaluations - evaluations,
                                                          "gtol": 1e-6})
        evaluations += result.nfev
        x = result.x
        after, _, det = _energy_and_gradient(x, faces, grads, areas, eps, theta)
        detmin = float(det.min())
        if progress is not None:
            progress(rounds, int(np.count_nonzero(det <= 0)))
        if detmin > 0 and abs(before - after) <= 1e-5 * after:
            break
        sigma_k = max(1.0 - after / before, 0.1) if before > 0 else 0.1
        mu = (1.0 - sigma_k) * float(_chi(np.array([detmin]), eps)[0])
        eps = max(1e-9, 2.0 * np.sqrt(mu * (mu - detmin))) if detmin < mu else 1e-9
    layout = at_mesh_size(mesh, x.reshape(-1, 2) * flip)
    return UntangleResult(layout, int(np.count_nonzero(det <= 0)), rounds, time.monotonic() - start)


def _energy_and_gradient_only(flat, faces, grads, areas, eps, theta):
    energy, gradient, _ = _energy_and_gradient(flat, faces, grads, areas, eps, theta)
    return energy, gradient


def _winding_agrees(mesh: Mesh, positions: np.ndarray) -> bool:
    """Whether the layout's bulk has the mesh's own winding (counter-clockwise faces)."""
    return layout_orientation(positions, mesh.faces) > 0
