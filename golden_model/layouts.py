"""Initial planar layouts ``P0`` (V×2) for a mesh.

* ``tutte``: barycentric (Tutte) embedding.  The boundary loop is placed on a
  circle whose circumference equals the 3D boundary length, at arc-length
  positions (chord lengths of the 3D boundary edges); the interior solves the
  uniform graph Laplacian (each interior node at the mean of its neighbours)
  with one sparse LU factorisation for both coordinates.
* ``pca``: orthographic projection onto the least-squares plane through the
  centroid, centred at the origin.
* a file: ``V`` rows ``x y`` (whitespace or comma separated; ``#`` comments),
  or an OBJ whose vertex *i* gives ``(x, y)`` of node *i*.

Both computed layouts are oriented so that most faces are counter-clockwise
(mirrored otherwise), which makes pictures comparable; the flattening itself
does not depend on it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .mesh import Mesh, signed_areas_2d

__all__ = ["LayoutError", "initial_layout", "tutte_layout", "pca_layout", "load_layout", "LAYOUT_METHODS"]

LAYOUT_METHODS = ("tutte", "pca")


class LayoutError(ValueError):
    """A layout that cannot be used; the message is one line for the user."""


def _counter_clockwise(positions: np.ndarray, mesh: Mesh) -> np.ndarray:
    """Mirror ``positions`` in x when most of the mesh's faces are clockwise."""
    if np.sum(signed_areas_2d(positions, mesh.faces) < 0) > mesh.n_faces / 2:
        positions = positions * np.array([-1.0, 1.0])
    return positions


def tutte_layout(mesh: Mesh) -> np.ndarray:
    """Tutte embedding with the boundary on a circle of the 3D boundary length."""
    loop = mesh.boundary_loop
    chords = np.linalg.norm(mesh.vertices[np.roll(loop, -1)] - mesh.vertices[loop], axis=1)
    perimeter = chords.sum()
    radius = perimeter / (2 * np.pi)
    angles = 2 * np.pi * np.concatenate([[0.0], np.cumsum(chords[:-1])]) / perimeter
    positions = np.zeros((mesh.n_vertices, 2))
    positions[loop] = radius * np.column_stack([np.cos(angles), np.sin(angles)])

    interior = np.ones(mesh.n_vertices, dtype=bool)
    interior[loop] = False
    if interior.any():
        i, j = mesh.edges.T
        n = mesh.n_vertices
        adjacency = sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
        degree = np.asarray(adjacency.sum(axis=1)).ravel()
        laplacian = (sp.diags(degree) - adjacency).tocsr()
        inner = np.flatnonzero(interior)
        a_ii = laplacian[inner][:, inner].tocsc()
        rhs = -laplacian[inner][:, loop] @ positions[loop]
        positions[inner] = spla.splu(a_ii).solve(np.asarray(rhs))
    return _counter_clockwise(positions, mesh)


def pca_layout(mesh: Mesh) -> np.ndarray:
    """Orthographic projection onto the least-squares plane, centred.

    The in-plane axes are the two leading principal directions; each axis's
    sign is fixed so that its largest-magnitude component is positive, so the
    result does not depend on the SVD's sign convention.
    """
    centred = mesh.vertices - mesh.vertices.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    axes = vt[:2]
    signs = np.sign(axes[np.arange(2), np.argmax(np.abs(axes), axis=1)])
    positions = centred @ (axes * signs[:, None]).T
    return _counter_clockwise(positions, mesh)


def load_layout(path: str | Path, n_vertices: int) -> np.ndarray:
    """Read a user layout: a text file of ``x y`` rows, or an OBJ's vertex (x, y)."""
    path = Path(path)
    if not path.is_file():
        raise LayoutError(f"cannot read layout '{path}': no such file")
    if path.suffix.lower() == ".obj":
        positions = _obj_vertex_xy(path)
    else:
        try:
            text = path.read_text(encoding="utf-8").replace(",", " ")
            rows = [line.split("#")[0].split() for line in text.splitlines()]
            rows = [r for r in rows if r]
            if any(len(r) != 2 for r in rows):
                bad = next(k for k, r in enumerate(rows) if len(r) != 2)
                raise LayoutError(
                    f"layout '{path}': row {bad + 1} has {len(rows[bad])} values, expected 2 (x y)"
                )
            positions = np.array(rows, dtype=np.float64).reshape(-1, 2)
        except (UnicodeDecodeError, ValueError) as exc:
            if isinstance(exc, LayoutError):
                raise
            raise LayoutError(f"cannot parse layout '{path}': {str(exc).splitlines()[0]}") from None
    if len(positions) != n_vertices:
        raise LayoutError(f"layout '{path}' has {len(positions)} rows but the mesh has {n_vertices} vertices")
    if not np.isfinite(positions).all():
        raise LayoutError(f"layout '{path}' has a non-finite coordinate")
    return positions


def _obj_vertex_xy(path: Path) -> np.ndarray:
    """(x, y) of the ``v`` records of an OBJ file, in file order."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
        rows = [line.split()[1:3] for line in lines if line.startswith("v ")]
        return np.array(rows, dtype=np.float64).reshape(-1, 2)
    except (UnicodeDecodeError, ValueError) as exc:
        raise LayoutError(f"cannot parse layout '{path}': {str(exc).splitlines()[0]}") from None


def initial_layout(mesh: Mesh, init: str | Path) -> np.ndarray:
    """``P0`` for ``init`` = ``'tutte'``, ``'pca'`` or a layout file path."""
    if str(init) == "tutte":
        return tutte_layout(mesh)
    if str(init) == "pca":
        return pca_layout(mesh)
    return load_layout(init, mesh.n_vertices)
