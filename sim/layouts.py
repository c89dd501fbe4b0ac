"""Initial planar layouts ``P0`` (V×2) for a mesh.

* ``tutte``: barycentric (Tutte) embedding.  The boundary loop is placed on a
  circle whose circumference equals the 3D boundary length, at arc-length
  positions (chord lengths of the 3D boundary edges); the interior solves the
  uniform graph Laplacian (each interior node at the mean of its neighbours)
  with one sparse LU factorisation for both coordinates.
* ``pca``: orthographic projection onto the least-squares plane through the
  centroid, centred at the origin.
* ``harmonic`` (libigl): Tutte's boundary circle, interior by the cotangent
  Laplacian (``igl.harmonic`` with ``k = 1``); differs from ``tutte`` only in
  the interior weights.
* ``lscm`` (libigl): least-squares conformal map with the two boundary
  vertices farthest apart in 3D pinned at their 3D distance, then scaled
  uniformly so that the summed 2D triangle area ``Σ|A'_t|`` equals the 3D
  area, and centred.
* ``arap`` (libigl): as-rigid-as-possible parameterisation
  (``igl.arap_precomputation`` / ``igl.arap_solve`` in 2D) started from the
  ``harmonic`` layout, one boundary vertex pinned at its start position (no
  dynamics), at most :data:`ARAP_MAX_ITERATIONS` local/global iterations,
  then centred.  ARAP keeps the 3D scale.
* ``slim`` (libigl): the ``tutte`` layout relaxed by SLIM (symmetric Dirichlet energy,
  ``igl.slim_solve``) for at most :data:`SLIM_MAX_ITERATIONS` iterations; SLIM's line search never
  inverts a triangle, so the result is fold-free like the Tutte start.
* a file: ``V`` rows ``x y`` (whitespace or comma separated; ``#`` comments),
  or an OBJ whose vertex *i* gives ``(x, y)`` of node *i* (read as the mesh
  reader reads OBJ: tabs, CRLF, continuations; faces other than the mesh's,
  or a z that is not 0, get a note: only x, y are used).  Coordinates must be
  finite and within ``|x| <= COORDINATE_LIMIT`` (1e50, as for meshes).  The
  file must be a regular file (a FIFO or a device is refused, never opened);
  an empty path is refused.

Every computed layout is oriented so that most faces are counter-clockwise
(mirrored otherwise), and a given one (a file, an array) is mirrored where its
bulk is clockwise (in y, which puts y-down texture coordinates upright), with
a note: a pattern is seen from the mesh's front, and a mirror image would be
cut the wrong way round. The dynamics does not depend on it.  libigl is
imported on first use of a libigl method; any libigl failure (an exception or
a non-finite result) is a :class:`LayoutError` naming the method.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from golden_model.files import read_file_bytes
from golden_model.mesh import COORDINATE_LIMIT, Mesh, MeshError, layout_orientation, signed_areas_2d
from golden_model.guard import ENERGY_FLOOR
from .mesh_io import read_obj_vertices
from .mesh_io.polygons import is_plain, plural

__all__ = ["LayoutError", "StartLayout", "start_layout", "AUTO_START", "ARRAY_WORDS", "initial_layout", "tutte_layout", "pca_layout", "harmonic_layout", "lscm_layout",
           "arap_layout", "slim_layout", "load_layout", "LAYOUT_METHODS", "ARAP_MAX_ITERATIONS", "NoDiskStart",
           "SLIM_MAX_ITERATIONS", "check_layout", "init_name", "ARRAY_START"]

LAYOUT_METHODS = ("tutte", "pca", "harmonic", "lscm", "arap", "slim")
#: The start of mesh files: ARAP; SLIM from Tutte where ARAP folds; LSCM where that is exact to the stop rule's
#: floor and more so than ARAP's (docs/guard.md).
AUTO_START = "auto"

ARAP_MAX_ITERATIONS = 100
"""Upper bound on ARAP local/global iterations (run in chunks of 10)."""
ARAP_TOLERANCE = 1e-9
"""ARAP stops early when a chunk moves no node more than this × the boundary length."""
SLIM_MAX_ITERATIONS = 20
"""Upper bound on SLIM iterations (run in chunks of 5)."""
SLIM_TOLERANCE = 0.05
"""SLIM stops after a chunk that lowered its symmetric Dirichlet energy by less than this fraction: the
dynamics takes it from there (docs/guard.md)."""


class LayoutError(ValueError):
    """A layout that cannot be used; the message is one line for the user."""


class NoDiskStart(LayoutError):
    """A computed start that needs the mesh's holes closed, where one cannot be (a slit kept as a cut-out)."""


def _counter_clockwise(positions: np.ndarray, mesh: Mesh) -> np.ndarray:
    """Mirror ``positions`` in x when the layout's bulk is clockwise (its total signed area below 0:
    :func:`~golden_model.mesh.layout_orientation`, the orientation folds are counted against)."""
    if layout_orientation(positions, mesh.faces) < 0:
        positions = positions * np.array([-1.0, 1.0])
    return positions


def _boundary_circle(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Tutte's boundary: ``(loop, positions)`` on a circle of the 3D boundary length.

    The loop is :attr:`Mesh.boundary_loop`; its nodes sit at arc-length
    positions given by the chord lengths of the 3D boundary edges.
    """
    loop = mesh.boundary_loop
    chords = np.linalg.norm(mesh.vertices[np.roll(loop, -1)] - mesh.vertices[loop], axis=1)
    perimeter = chords.sum()
    radius = perimeter / (2 * np.pi)
    angles = 2 * np.pi * np.concatenate([[0.0], np.cumsum(chords[:-1])]) / perimeter
    return loop, radius * np.column_stack([np.cos(angles), np.sin(angles)])


def tutte_layout(mesh: Mesh) -> np.ndarray:
    """Tutte embedding with the boundary on a circle of the 3D boundary length."""
    loop, circle = _boundary_circle(mesh)
    positions = np.zeros((mesh.n_vertices, 2))
    positions[loop] = circle

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


# --------------------------------------------------------------------------- libigl layouts


def _igl(method: str):
    """The ``igl`` module, imported on first use (it takes ~0.3 s to import)."""
    try:
        import igl
    except ImportError as exc:
        raise LayoutError(f"{method} layout needs libigl (pip install libigl): {exc}") from None
    return igl


def _igl_arrays(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Contiguous float64 vertices and int64 faces, as libigl's bindings take them."""
    return (np.ascontiguousarray(mesh.vertices, dtype=np.float64),
            np.ascontiguousarray(mesh.faces, dtype=np.int64))


def _checked(method: str, function: str, positions, n_vertices: int) -> np.ndarray:
    """``positions`` (from ``igl.<function>``) as a finite (V, 2) float64 array, or a :class:`LayoutError`."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.shape != (n_vertices, 2):
        raise LayoutError(f"{method} layout failed: igl.{function} returned shape {positions.shape}, "
                          f"expected ({n_vertices}, 2)")
    if not np.isfinite(positions).all():
        bad = int(np.sum(~np.isfinite(positions).all(axis=1)))
        raise LayoutError(f"{method} layout failed: igl.{function} returned non-finite coordinates for {bad} of "
                          f"{n_vertices} vertices")
    return np.array(positions, dtype=np.float64, order="C")


def _libigl_failure(method: str, function: str, exc: Exception) -> LayoutError:
    """One line: the method, the libigl function and the first line of its exception."""
    text = str(exc).strip().splitlines()
    reason = f": {text[0]}" if text else ""
    return LayoutError(f"{method} layout failed: igl.{function} raised {type(exc).__name__}{reason}")


def _harmonic_positions(mesh: Mesh, method: str = "harmonic") -> np.ndarray:
    """Cotangent-harmonic interior for Tutte's boundary circle (not yet oriented)."""
    igl = _igl(method)
    vertices, faces = _igl_arrays(mesh)
    loop, circle = _boundary_circle(mesh)
    try:
        positions = igl.harmonic(vertices, faces, np.ascontiguousarray(loop, dtype=np.int64),
                                 np.ascontiguousarray(circle), 1)
    except Exception as exc:  # libigl raises RuntimeError/ValueError/TypeError
        raise _libigl_failure(method, "harmonic", exc) from None
    return _checked(method, "harmonic", positions, mesh.n_vertices)


def harmonic_layout(mesh: Mesh) -> np.ndarray:
    """Harmonic map with cotangent weights; the boundary exactly as :func:`tutte_layout`'s."""
    return _counter_clockwise(_harmonic_positions(mesh), mesh)


def _hull_vertices(points: np.ndarray) -> np.ndarray:
    """Sorted indices of ``points``' convex hull's vertices, where two points farthest apart lie; all of them for a
    set qhull cannot take (collinear). A flat set (a planar mesh's boundary) has no 3D hull: its hull in its plane."""
    from scipy.spatial import ConvexHull, QhullError

    centred = points - points.mean(axis=0)
    for flat in (centred, centred @ np.linalg.svd(centred, full_matrices=False)[2][:2].T):
        try:
            return np.sort(ConvexHull(flat).vertices)
        except (QhullError, ValueError):
            continue
    return np.arange(len(points))


#: Up to this many convex hull vertices LSCM's pins are the two farthest apart (every pair measured); beyond, the
#: ends of a double sweep. LSCM's layout is the same up to a rotation whichever two are pinned.
FARTHEST_PAIR_EXACT = 4096


def _farthest_pair(points: np.ndarray) -> tuple[int, int]:
    """Indices ``(a, b)``, ``a < b``, of two points far apart: the two farthest apart (the first such pair in row
    order among the convex hull's vertices) where the hull has at most :data:`FARTHEST_PAIR_EXACT` vertices; else
    the ends of a double sweep (the hull vertex farthest from the first, then the one farthest from it), at least
    half the greatest distance. A long strip's boundary is all of its vertices, and a half ring's outer arc is all
    on the hull, so measuring every pair grows with the square of the strip's length."""
    candidates = _hull_vertices(points) if len(points) > 3 else np.arange(len(points))
    hull = points[candidates]
    if len(hull) > FARTHEST_PAIR_EXACT:
        a = int(np.argmax(((hull - hull[0]) ** 2).sum(axis=1)))
        pair = (a, int(np.argmax(((hull - hull[a]) ** 2).sum(axis=1))))
    else:
        best, pair = -1.0, (0, 1)
        block = max(1, 2_000_000 // (3 * len(hull)))  # rows per block: about 16 MB of differences
        for start in range(0, len(hull), block):
            d2 = ((hull[start:start + block, None, :] - hull[None, :, :]) ** 2).sum(axis=2)
            r, c = divmod(int(np.argmax(d2)), len(hull))
            if d2[r, c] > best:
                best, pair = float(d2[r, c]), (start + r, c)
    a, b = (int(candidates[i]) for i in pair)
    return (a, b) if a < b else (b, a)


def lscm_layout(mesh: Mesh) -> np.ndarray:
    """LSCM with two pinned boundary vertices, scaled to the 3D area and centred."""
    igl = _igl("lscm")
    vertices, faces = _igl_arrays(mesh)
    loop = mesh.boundary_loop
    a, b = _farthest_pair(vertices[loop])
    pinned = np.array([loop[a], loop[b]], dtype=np.int64)
    distance = float(np.linalg.norm(vertices[pinned[1]] - vertices[pinned[0]]))
    targets = np.array([[0.0, 0.0], [distance, 0.0]])
    try:
        result = igl.lscm(vertices, faces, pinned, targets)
    except Exception as exc:
        raise _libigl_failure("lscm", "lscm", exc) from None
    positions = _checked("lscm", "lscm", result[0] if isinstance(result, tuple) else result, mesh.n_vertices)
    area_2d = float(np.abs(signed_areas_2d(positions, mesh.faces)).sum())
    if not (np.isfinite(area_2d) and area_2d > 0):
        raise LayoutError("lscm layout failed: the map has zero 2D area")
    positions = positions * np.sqrt(float(mesh.face_areas.sum()) / area_2d)
    positions -= positions.mean(axis=0)
    return _counter_clockwise(positions, mesh)


def arap_layout(mesh: Mesh) -> np.ndarray:
    """2D ARAP from the harmonic layout, one boundary vertex pinned, centred.

    libigl's tutorial 503 regularises the unconstrained solve with
    ``with_dynamics``; that changes the minimiser (a developable mesh keeps
    about 1 % edge-length error), so instead the first boundary vertex is held
    at its harmonic position, which removes the translation null space and
    leaves the ARAP energy itself.  Iterations run in chunks of 10 up to
    :data:`ARAP_MAX_ITERATIONS`, stopping after a chunk that moved no node
    more than :data:`ARAP_TOLERANCE` × the boundary length.
    """
    igl = _igl("arap")
    vertices, faces = _igl_arrays(mesh)
    positions = _harmonic_positions(mesh, "arap")
    loop = mesh.boundary_loop
    pinned = np.array([loop[0]], dtype=np.int32)
    targets = np.ascontiguousarray(positions[pinned.astype(np.int64)])
    perimeter = float(np.linalg.norm(vertices[np.roll(loop, -1)] - vertices[loop], axis=1).sum())
    chunk = 10
    data = igl.ARAPData()
    data.with_dynamics = False
    data.max_iter = chunk
    try:
        igl.arap_precomputation(vertices, faces, 2, pinned, data)
    except Exception as exc:
        raise _libigl_failure("arap", "arap_precomputation", exc) from None
    for _ in range(0, ARAP_MAX_ITERATIONS, chunk):
        try:
            moved = igl.arap_solve(targets, data, positions)
        except Exception as exc:
            raise _libigl_failure("arap", "arap_solve", exc) from None
        moved = _checked("arap", "arap_solve", moved, mesh.n_vertices)
        change = float(np.abs(moved - positions).max())
        positions = moved
        if change <= ARAP_TOLERANCE * perimeter:
            break
    positions -= positions.mean(axis=0)
    return _counter_clockwise(positions, mesh)


def slim_layout(mesh: Mesh) -> np.ndarray:
    """libigl's SLIM (symmetric Dirichlet) from :func:`tutte_layout`, free boundary, centred.

    Tutte's layout is fold-free and SLIM only takes steps that keep every triangle's orientation,
    so the result is fold-free too; it stops after a chunk of 5 iterations that lowered the symmetric
    Dirichlet energy by less than :data:`SLIM_TOLERANCE` (relative), or after :data:`SLIM_MAX_ITERATIONS`.
    """
    from .untangle import symmetric_dirichlet

    igl = _igl("slim")
    vertices, faces = _igl_arrays(mesh)
    positions = tutte_layout(mesh)
    if np.sum(signed_areas_2d(positions, mesh.faces)) < 0:  # SLIM needs the mesh's own winding
        positions = positions * np.array([-1.0, 1.0])
    # libigl's SLIM has absolute thresholds (a horn 1e-5 across came back with a hundred folded triangles): it runs
    # on the patch scaled to a mean edge length near 1 by a power of two, which rounds nothing (its energy is
    # scale-free, so nothing else changes)
    size = 2.0 ** round(math.log2(float(np.mean(mesh.rest_lengths))))
    vertices, positions = vertices / size, positions / size
    try:
        data = igl.slim_precompute(np.asfortranarray(vertices), np.asfortranarray(faces.astype(np.int32)),
                                   np.asfortranarray(positions), igl.MappingEnergyType.SYMMETRIC_DIRICHLET,
                                   np.zeros(0, dtype=np.int32), np.zeros((0, 2)), 0.0)
    except Exception as exc:
        raise _libigl_failure("slim", "slim_precompute", exc) from None
    chunk = 5
    energy = symmetric_dirichlet(mesh, positions * size)
    for _ in range(0, SLIM_MAX_ITERATIONS, chunk):
        try:
            moved = igl.slim_solve(data, chunk)
        except Exception as exc:
            raise _libigl_failure("slim", "slim_solve", exc) from None
        positions = _checked("slim", "slim_solve", moved, mesh.n_vertices) * size
        before, energy = energy, symmetric_dirichlet(mesh, positions)
        if not energy < (1.0 - SLIM_TOLERANCE) * before:
            break
    positions -= positions.mean(axis=0)
    return _counter_clockwise(positions, mesh)


def load_layout(path: str | Path, n_vertices: int, *, faces: np.ndarray | None = None,
                notes: list[str] | None = None, mesh_vertices: np.ndarray | None = None) -> np.ndarray:
    """Read a user layout: a text file of ``x y`` rows, or an OBJ's vertex (x, y).

    A file that cannot be read is a :class:`LayoutError` "cannot read layout
    '<path>': <reason>" (no such file, is a directory, a FIFO or a device,
    permission denied, ...); an empty path is refused.  For an OBJ, given the
    mesh's ``faces``, a layout whose faces are not the mesh's (as sets of
    corners), or whose z is not 0, gets a line in ``notes``: only the
    vertices' x, y are used. An OBJ whose vertices are the curved mesh's own (``mesh_vertices``; springflat's
    pattern ``.obj`` keeps the 3D mesh there and the pattern in ``vt``) is refused: its x, y are no layout.
    """
    if str(path) == "":
        raise LayoutError(f"the layout '' is empty: name a method ({', '.join((AUTO_START,) + LAYOUT_METHODS)}) or a file")
    try:
        data = read_file_bytes(path, "layout", LayoutError)  # (before Path(), which drops a trailing '/')
    except LayoutError as exc:
        path = Path(path)
        if len(path.parts) == 1 and not path.suffix and not os.path.lexists(path):  # a method's name mistyped?
            raise LayoutError(f"{exc}, nor a start method ({', '.join((AUTO_START,) + LAYOUT_METHODS)})") from None
        raise
    path = Path(path)
    if path.suffix.lower() == ".obj":
        try:
            vertices = read_obj_vertices(data, f"cannot parse layout '{path}'")
        except MeshError as exc:
            raise LayoutError(str(exc)) from None
        positions = vertices[:, :2]
        if len(vertices) == 0 and any(line.lstrip().startswith(b"vt ") for line in data.splitlines()):
            raise LayoutError(f"layout '{path}' holds texture coordinates (vt) but no vertices (v): --init reads an "
                              "OBJ's v lines (a flat mesh, as springflat's .flat.obj); give the layout as v lines, "
                              "or as a text file of 'x y' rows")
        if (mesh_vertices is not None and vertices.shape == mesh_vertices.shape and np.ptp(mesh_vertices[:, 2]) > 0
                and np.allclose(vertices, mesh_vertices, rtol=1e-6, atol=0.0)):
            raise LayoutError(f"layout '{path}' holds the 3D mesh itself, not a layout (a springflat pattern .obj keeps "
                              "the pattern in its vt, which --init does not read): give the pattern written as "
                              ".flat.obj, or a text file of 'x y' rows")
        if notes is not None and faces is not None and len(positions) == n_vertices:
            notes.extend(_obj_layout_notes(path, data, vertices, faces))
    else:
        try:
            text = data.decode("utf-8-sig").replace(",", " ")
            rows = [line.split("#")[0].split() for line in text.splitlines()]
            rows = [r for r in rows if r]
            if any(len(r) != 2 for r in rows):
                bad = next(k for k, r in enumerate(rows) if len(r) != 2)
                raise LayoutError(
                    f"layout '{path}': row {bad + 1} has {plural(len(rows[bad]), 'value')}, "
                    "expected 2 (x y)"
                )
            positions = np.array([[_layout_number(v, path, k) for v in r] for k, r in enumerate(rows)],
                                 dtype=np.float64).reshape(-1, 2)
        except UnicodeDecodeError as exc:
            raise LayoutError(f"cannot parse layout '{path}': not a text file (byte {exc.start} is not UTF-8 "
                              "text): a layout is a text file of 'x y' rows or an OBJ") from None
        except ValueError as exc:
            if isinstance(exc, LayoutError):
                raise
            raise LayoutError(f"cannot parse layout '{path}': {str(exc).splitlines()[0]}") from None
    return check_layout(positions, n_vertices, f"layout '{path}'", faces)


def _layout_number(text: str, path: Path, row: int) -> float:
    try:
        if not is_plain(text):  # float() reads 1_0 as 10 and any script's digits
            raise ValueError
        return float(text)
    except ValueError:
        raise LayoutError(f"cannot parse layout '{path}': row {row + 1} has {text[:20]!r}, not a number") from None


def check_layout(positions, n_vertices: int, what: str, faces: np.ndarray | None = None) -> np.ndarray:
    """``positions`` as a ``(n_vertices, 2)`` float64 array of finite coordinates within
    :data:`COORDINATE_LIMIT`, else a :class:`LayoutError` naming ``what`` (a layout file, the init array);
    with the mesh's ``faces``, also one in which some triangle has an area (not all on a line or a point)."""
    try:
        positions = np.asarray(positions)
    except ValueError:  # ragged rows (numpy's own words name its internals)
        raise LayoutError(f"{what}'s rows are not all of one length: expected ({n_vertices}, 2), one x y row per "
                          "vertex") from None
    if positions.dtype.kind not in "iuf":
        raise LayoutError(f"{what} holds {positions.dtype} values, not real numbers")
    if positions.ndim != 2 or positions.shape[1] != 2:
        raise LayoutError(f"{what} has shape {positions.shape}, expected ({n_vertices}, 2): one x y row per vertex")
    positions = positions.astype(np.float64)
    if len(positions) != n_vertices:
        raise LayoutError(f"{what} has {len(positions)} rows but the mesh has {n_vertices} vertices")
    if not np.isfinite(positions).all():
        raise LayoutError(f"{what} has a non-finite coordinate")
    magnitude = np.abs(positions).max(axis=1, initial=0.0)
    if (magnitude > COORDINATE_LIMIT).any():
        row = int(np.flatnonzero(magnitude > COORDINATE_LIMIT)[0])
        raise LayoutError(f"{what}: row {row + 1} has a coordinate of magnitude {magnitude[row]:.3g}, "
                          f"outside the supported range |x| <= {COORDINATE_LIMIT:g}")
    if faces is not None and not np.any(signed_areas_2d(positions, faces)):
        raise LayoutError(f"{what} has no triangle of non-zero area (its vertices on one line or point, or too "
                          "close together for an area to be represented): no start to flatten from")
    return positions


#: What :func:`initial_layout` and :func:`start_layout` call a start given as an array (the Python API's ``init``),
#: and how their notes and refusals name it.
ARRAY_START = "array"
ARRAY_WORDS = "the init array"


def init_name(init) -> str:
    """How a start is named to the user: the method or file as given, :data:`ARRAY_START` for an array."""
    return ARRAY_START if isinstance(init, np.ndarray) else str(init)


def _obj_layout_notes(path: Path, data: bytes, vertices: np.ndarray, faces: np.ndarray) -> list[str]:
    """What an OBJ layout has that is not used: faces other than the mesh's, a z that is not 0."""
    from .mesh_io import read_obj

    notes = []
    try:
        own = np.asarray(read_obj(path, data).faces, dtype=np.int64).reshape(-1, 3)
        if len(own) == 0:
            differ, what = True, "no faces"
        else:
            # each triangle as its vertex set (a turned winding is the same triangle)
            theirs = {tuple(t) for t in np.sort(faces, axis=1).tolist()}
            foreign = sum(tuple(t) not in theirs for t in np.sort(own, axis=1).tolist())
            differ = foreign > 0 or len(own) != len(faces)
            what = (f"{foreign} of its {len(own)} faces not among the mesh's {len(faces)}" if foreign else
                    f"{len(own)} faces where the mesh has {len(faces)}")
    except MeshError as exc:
        differ, what = True, f"faces that cannot be read ({str(exc).split(': ', 1)[-1]})"
    if differ:
        notes.append(f"layout '{path}' has {what}: only its vertices' x, y are used, in the mesh's vertex order")
    z = float(np.abs(vertices[:, 2]).max(initial=0.0))
    if z > 0:
        notes.append(f"layout '{path}' has z up to {z:.3g}, not a flat layout: only x, y are used (z dropped)")
    return notes


_METHODS = {"tutte": tutte_layout, "pca": pca_layout, "harmonic": harmonic_layout, "lscm": lscm_layout,
            "arap": arap_layout, "slim": slim_layout}


def initial_layout(mesh: Mesh, init: str | Path | np.ndarray, notes: list[str] | None = None) -> np.ndarray:
    """``P0`` for ``init`` = one of :data:`LAYOUT_METHODS`, :data:`AUTO_START` (here: ARAP as it is;
    :func:`start_layout` untangles), a layout file path (what an OBJ layout has that is not used goes
    to ``notes``, see :func:`load_layout`) or a ``(V, 2)`` array (checked as a file's rows are)."""
    if isinstance(init, np.ndarray):
        return _given(check_layout(init, mesh.n_vertices, ARRAY_WORDS, mesh.faces), mesh, ARRAY_WORDS, notes)
    name = "arap" if str(init) == AUTO_START else str(init)
    if name in _METHODS:  # (a method needs a disk: a mesh's holes are closed for it, their vertices its own)
        return _METHODS[name](_disk(mesh, name))
    return _given(load_layout(init, mesh.n_vertices, faces=mesh.faces, notes=notes, mesh_vertices=mesh.vertices),
                  mesh, f"the layout '{init}'", notes)


#: How far from the mesh's size (:func:`sim.untangle.size_factor`) a given layout may be and still be taken as it
#: is: a pattern of an earlier run (factor 1) or a computed start given back (0.75 to 2.1 measured: Tutte's,
#: PCA's, LSCM's, ARAP's of the built-ins) starts the same run again; beyond, another length unit is the likely
#: cause (a texture layout in [0, 1] of a mesh in millimetres), and it is scaled to the mesh's size, with a note.
SIZE_TOLERANCE = 3.0


def _given(positions: np.ndarray, mesh: Mesh, what: str, notes: list[str] | None) -> np.ndarray:
    """A layout the user gave, as the run starts from it: facing the front (:func:`_facing_the_front`), and scaled
    to the mesh's size (:func:`sim.untangle.size_factor`) where it is off by more than :data:`SIZE_TOLERANCE`,
    with a note: a texture layout in [0, 1] of a mesh in millimetres, say, which the guarded dynamics, whose
    steps are local and never grow a triangle through zero area, would otherwise have to grow a hundredfold."""
    from .untangle import size_factor

    positions = _facing_the_front(positions, mesh, what, notes)
    factor = size_factor(mesh, positions)
    if 1 / SIZE_TOLERANCE <= factor <= SIZE_TOLERANCE:
        return positions
    if notes is not None:
        notes.append(f"{what} is {1 / factor:.3g} times the mesh's size (another length unit?): scaled by "
                     f"{factor:.3g} to it (its edge lengths fitted to the mesh's)")
    return positions * factor


def _disk(mesh: Mesh, method: str) -> Mesh:
    """``mesh`` with its holes closed (:attr:`Mesh.disk`) for the start ``method``. A hole that cannot be closed
    (a slit, kept as a cut-out): ``pca``, a projection, takes the mesh as it is; any other method is refused
    (:class:`NoDiskStart`), saying what start works."""
    try:
        return mesh.disk
    except MeshError as exc:
        if method == "pca":
            return mesh
        raise NoDiskStart(f"the {method} layout, a start computed with the mesh's holes closed, cannot be had: "
                          f"{exc}; start from --init pca or from a layout of the mesh's vertices") from None


def _facing_the_front(positions: np.ndarray, mesh: Mesh, what: str, notes: list[str] | None) -> np.ndarray:
    """A given layout mirrored in y where its bulk is clockwise (its total signed area below 0 by more than
    rounding, 1e-9 of its bounding box: a degenerate layout is left as it is), with a note: a pattern is
    cut and printed as seen from the mesh's front (its faces' winding), as every computed start is; a
    mirror image (texture coordinates with y down, say) would be cut the wrong way round."""
    total = float(np.sum(signed_areas_2d(positions, mesh.faces), dtype=np.float64))
    extent = np.ptp(positions, axis=0)
    if total >= -1e-9 * float(extent[0] * extent[1]):  # counter-clockwise, or degenerate (rounding's sign)
        return positions
    if notes is not None:
        notes.append(f"{what} is a mirror image of the mesh (most of its area runs clockwise, as texture "
                     "coordinates with y down do): mirrored in y, so that the pattern shows the mesh's front")
    return positions * np.array([1.0, -1.0])  # y: a y-down texture layout comes out upright


@dataclass(frozen=True)
class StartLayout:
    """A start for the dynamics: ``positions`` (V, 2), ``method`` (what produced them, for the user),
    ``folded`` triangles left (0 unless untangling failed) and ``notes`` (one line each) on what was done."""

    positions: np.ndarray
    method: str
    folded: int
    notes: list[str] = field(default_factory=list)


def _folds(mesh: Mesh, positions: np.ndarray) -> int:
    from golden_model.mesh import folded_faces

    return int(np.count_nonzero(folded_faces(positions, mesh.faces)))


def start_layout(mesh: Mesh, init: str | Path | np.ndarray, progress=None,
                 slim: Callable[[], np.ndarray] | None = None,
                 floor_strain: float = math.sqrt(ENERGY_FLOOR)) -> StartLayout:
    """The initial layout for ``init`` (:data:`AUTO_START`, a method or a file), fold-free where possible.

    The guarded dynamics keeps a fold-free start fold-free but cannot clear a fold. ``auto`` is ARAP,
    or SLIM from Tutte (fold-free by construction) where ARAP folds or fails: measured on the corpus, that
    beats untangling ARAP's layout on E_C and on time; where ARAP is fold-free, LSCM's layout where that is
    exact and more so than ARAP's (:func:`_lscm_where_exact`). Any other start with folds is untangled
    (:func:`sim.untangle.untangle_layout`), which brings it to the mesh's size; a start that stays
    folded is returned with its count, and the notes say why. ``progress(text)`` is called before
    each long step. ``slim()`` gives :func:`slim_layout`'s layout of ``mesh`` when ARAP folds (default: it
    computes it; a caller may have started it beside ARAP, on another core). A computed start of a mesh with
    holes is computed on its disk (:attr:`Mesh.disk`: the holes closed); ``auto`` counts ARAP's folds with the
    fill's, so that its start, ARAP's or SLIM's, has each hole open and the right way round; any other start's
    folds are the mesh's own, untangled on the mesh (untangling a fill, which is no part of the pattern, can
    tangle the piece). ``floor_strain``: the stop rule's energy floor as an rms edge strain (the run's
    ``--tol-energy``: :func:`golden_model.guard.energy_floor_fraction`), within which LSCM's layout is exact
    enough to start from (:func:`_lscm_where_exact`).
    """
    from .untangle import untangle_layout

    say = progress or (lambda text: None)
    name = init_name(init)
    method = "arap" if name == AUTO_START else name
    described = (f"the {method} layout" if method in _METHODS else ARRAY_WORDS if name == ARRAY_START
                 else f"the layout '{name}'")
    closed = ""
    if name == AUTO_START:  # ARAP's folds counted with its fill's: where the fill folds, SLIM's fold-free disk
        closed = " (with the holes closed)" if mesh.n_holes else ""
        mesh = _disk(mesh, method)
    if name != ARRAY_START:
        say(f"computing {described}" if method in _METHODS else f"reading {described}")
    read_notes: list[str] = []
    try:
        positions = initial_layout(mesh, init if name == ARRAY_START else method, read_notes)
    except LayoutError as exc:  # (without libigl, SLIM below says so in its own words)
        if name != AUTO_START:
            raise
        notes = [f"{exc}: starting from SLIM on Tutte's layout instead (fold-free by construction)"]
        say(notes[-1])
        return StartLayout(slim_layout(mesh) if slim is None else slim(), "slim", 0, notes)
    folded = _folds(mesh, positions)
    if folded == 0:
        if name == AUTO_START:
            return _lscm_where_exact(mesh, positions, say, floor_strain)
        return StartLayout(positions, method, 0, read_notes)
    plural = "s" if folded != 1 else ""
    if name == AUTO_START:
        notes = [f"{described} folds {folded} triangle{plural}{closed}: starting from SLIM on Tutte's layout "
                 "instead (fold-free by construction)"]
        say(notes[-1])
        return StartLayout(slim_layout(mesh) if slim is None else slim(), "slim", 0, notes)
    notes = read_notes + [f"{described} folds {folded} triangle{plural}{closed}: untangling it"]
    say(notes[-1])
    untangled = untangle_layout(mesh, positions)
    if untangled.folded == 0:
        return StartLayout(untangled.positions, f"{method}, untangled", 0, notes)
    notes.append(f"untangling left {untangled.folded} of {folded} folded triangles{closed} after "
                 f"{untangled.seconds:.0f} s; "
                 "the guarded dynamics cannot clear them (the default --init auto starts fold-free)")
    if untangled.folded < folded:
        return StartLayout(untangled.positions, f"{method}, partly untangled",
                           untangled.folded, notes)
    return StartLayout(positions, method, folded, notes)


def rms_strain(mesh: Mesh, positions: np.ndarray) -> float:
    """``√(Σ_e (L_e − d_e)² / Σ_e d_e²)``: the springs' energy as an rms edge strain, as the stop rule's floor
    (:data:`golden_model.guard.ENERGY_FLOOR`) measures it."""
    rest = mesh.rest_lengths
    return float(np.sqrt(np.sum((mesh.layout_lengths(positions) - rest) ** 2) / np.sum(rest**2)))


def _lscm_where_exact(mesh: Mesh, arap: np.ndarray, say: Callable[[str], None], floor: float) -> StartLayout:
    """``auto`` where ARAP's layout is fold-free: LSCM's instead where that is fold-free, below the stop rule's
    energy floor (an rms edge strain of at most ``floor``) and below ARAP's strain: a developable patch,
    which LSCM, conformal, flattens exactly, and which ARAP may leave short of its minimum after its
    :data:`ARAP_MAX_ITERATIONS` (a long strip bent, which the dynamics, whose steps are local, does not
    undo within its cap). Only where LSCM is that exact: a lower energy alone does not make a better start
    (LSCM's layout shrinks a curved patch, and the runs from it end with a higher E_C). docs/guard.md, "The
    start", has the measurements."""
    say("computing the lscm layout (exact where the patch is developable)")
    try:
        lscm = lscm_layout(mesh)
    except LayoutError:  # (libigl's failure on a near-degenerate mesh: ARAP's layout is a fine start)
        return StartLayout(arap, "arap", 0, [])
    arap_strain, lscm_strain = rms_strain(mesh, arap), rms_strain(mesh, lscm)
    if _folds(mesh, lscm) or lscm_strain > floor or not lscm_strain < arap_strain:
        return StartLayout(arap, "arap", 0, [])
    said = [] if arap_strain <= floor else [  # (both within the floor: which one is no news; the run line names it)
        f"the arap layout is not as exact as the stop rule asks (an rms edge strain of {arap_strain:.2g}), the lscm "
        f"layout is ({lscm_strain:.2g}: a developable patch): starting from it"]
    return StartLayout(lscm, "lscm", 0, said)
