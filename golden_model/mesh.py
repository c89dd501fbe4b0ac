"""Triangle meshes: loading, validation, and the topology the models share.

A :class:`Mesh` is the 3D patch to flatten: ``V`` vertices ``Q`` (metres or any
consistent length unit) and ``F`` triangles.  Vertex *i* in a file is node *i*
everywhere in the project (float reference, fixed-point golden model, RTL
streams): nothing is merged or reordered, except for STL, which has no shared
vertices at all (see :func:`load_mesh`).

Validation follows ``spec.md`` ("Bad input"): a mesh must be a single
connected manifold disk with exactly one boundary loop, no degenerate or
duplicate triangles, no out-of-range indices and only finite coordinates
within the supported range (:data:`COORDINATE_LIMIT`, :data:`MIN_MESH_SIZE`).
Every failure raises :class:`MeshError` with a one-line message naming the
problem; so does a file that cannot be read (the OS error in words).
"""

from __future__ import annotations

import errno
import io
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .files import read_regular_file

__all__ = ["Mesh", "MeshError", "load_mesh", "triangle_areas_3d", "signed_areas_2d", "COORDINATE_LIMIT",
           "MIN_MESH_SIZE", "describe_os_error"]

#: Relative area below which a triangle counts as degenerate: area ≤ this
#: times the squared longest edge of the mesh.
DEGENERATE_RELATIVE_AREA = 1e-12

#: Largest coordinate magnitude accepted in a mesh or a layout file.  The highest power of a
#: length any float64 computation takes is the fourth (a triangle's area is the norm of a cross
#: product, whose components are products of two lengths, squared inside the norm): with
#: |x| <= 1e50 that stays below ~1e203, a factor 1e105 under float64's overflow at 1.8e308,
#: which leaves room for the parameters (spring constant, density, gains) to scale energies.
COORDINATE_LIMIT = 1e50
#: Smallest accepted mesh size, as its longest edge (largest coordinate difference along an
#: edge).  Mirror of :data:`COORDINATE_LIMIT`: fourth powers stay above ~1e-200, a factor 1e108
#: over float64's smallest normal number (2.2e-308), so areas do not underflow to zero.
MIN_MESH_SIZE = 1e-50

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")


class MeshError(ValueError):
    """A mesh that cannot be flattened; the message is one line for the user."""


def describe_os_error(exc: OSError) -> str:
    """The OS error in the words of a one-line message: ``permission denied``, ``is a directory``, ..."""
    if exc.errno == errno.ENOENT:
        return "no such file"
    text = exc.strerror or str(exc) or type(exc).__name__
    return text[:1].lower() + text[1:]


def read_file_bytes(path: Path, what: str, error: type[ValueError]) -> bytes:
    """The bytes of the regular file ``path``; any OS error, and a path that is no regular file (a FIFO, a
    device: :func:`golden_model.files.read_regular_file`), becomes ``error("cannot read <what> '<path>': <reason>")``."""
    try:
        return read_regular_file(path)  # a FIFO or a device is refused, never opened
    except OSError as exc:
        raise error(f"cannot read {what} '{path}': {describe_os_error(exc)}") from None


def triangle_areas_3d(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Areas of the triangles ``faces`` of 3D ``vertices`` (length units squared)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def signed_areas_2d(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed areas of 2D triangles (positive when counter-clockwise)."""
    # one coordinate at a time: gathering 1-D arrays is several times faster than gathering rows
    x, y = np.ascontiguousarray(positions[:, 0]), np.ascontiguousarray(positions[:, 1])
    xa, xb, xc = (x.take(faces[:, k]) for k in range(3))
    ya, yb, yc = (y.take(faces[:, k]) for k in range(3))
    return 0.5 * ((xb - xa) * (yc - ya) - (yb - ya) * (xc - xa))


@dataclass(frozen=True, eq=False)
class Mesh:
    """A validated triangle-mesh disk.

    Attributes:
        vertices: ``(V, 3)`` float64 3D positions ``Q``.
        faces: ``(F, 3)`` int64 vertex indices, 0-based.
        name: a label for reports (file stem or built-in name).
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "mesh"
    _validated: bool = field(default=False, repr=False)

    def __post_init__(self) -> None:
        vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        faces = np.ascontiguousarray(self.faces)
        object.__setattr__(self, "vertices", vertices)
        _validate(vertices, faces)
        object.__setattr__(self, "faces", faces.astype(np.int64))
        object.__setattr__(self, "_validated", True)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @cached_property
    def edges(self) -> np.ndarray:
        """``(E, 2)`` unique undirected edges ``(i, j)`` with ``i < j``, sorted."""
        return _unique_edges(self.faces)[0]

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @cached_property
    def rest_lengths(self) -> np.ndarray:
        """``(E,)`` 3D edge lengths ``d_e`` (the springs' rest lengths)."""
        i, j = self.edges.T
        return np.linalg.norm(self.vertices[i] - self.vertices[j], axis=1)

    @cached_property
    def face_areas(self) -> np.ndarray:
        """``(F,)`` 3D triangle areas ``A_t``."""
        return triangle_areas_3d(self.vertices, self.faces)

    @cached_property
    def boundary_loop(self) -> np.ndarray:
        """Boundary vertex indices in loop order.

        Starts at the smallest boundary vertex index and walks the way its
        outgoing boundary edge runs in its face, so the face is on the left:
        placing this loop counter-clockwise gives a consistently wound mesh
        positive orientation.
        """
        directed = _directed_boundary_edges(self.faces)
        start = int(directed[:, 0].min())
        adjacent: dict[int, list[int]] = {}
        for a, b in directed.tolist():
            adjacent.setdefault(a, []).append(b)
            adjacent.setdefault(b, []).append(a)
        first = directed[directed[:, 0] == start][0, 1]
        loop = [start, int(first)]
        for _ in range(len(directed) - 2):
            before, here = loop[-2], loop[-1]
            a, b = adjacent[here]
            loop.append(b if a == before else a)
        return np.asarray(loop, dtype=np.int64)

    @cached_property
    def neighbours(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CSR neighbour lists: ``(indptr, indices, edge_ids)``.

        Node ``i``'s neighbours are ``indices[indptr[i]:indptr[i+1]]`` in
        increasing index order; ``edge_ids`` gives the row of :attr:`edges`
        of each entry (so rest lengths are ``rest_lengths[edge_ids]``).
        This fixed order is the order the hardware streams neighbours in.
        """
        i, j = self.edges.T
        e = np.arange(self.n_edges)
        src = np.concatenate([i, j])
        dst = np.concatenate([j, i])
        eid = np.concatenate([e, e])
        order = np.lexsort((dst, src))
        indptr = np.zeros(self.n_vertices + 1, dtype=np.int64)
        np.cumsum(np.bincount(src, minlength=self.n_vertices), out=indptr[1:])
        return indptr, dst[order], eid[order]

    @cached_property
    def rings(self) -> "Rings":
        """Each node's neighbours in cyclic order around it (see :class:`Rings`)."""
        return _rings(self.faces, self.n_vertices, self.edges)

    def masses(self, density: float) -> np.ndarray:
        """Node masses (eq. 6): ``m_i = (rho/3)·Σ A_t`` over incident triangles."""
        incident = np.bincount(
            self.faces.ravel(), weights=np.repeat(self.face_areas, 3), minlength=self.n_vertices
        )
        return density / 3.0 * incident

    def auto_density(self) -> float:
        """The paper's ``rho = 1/min m_i`` with masses computed at ``rho = 1``."""
        return 1.0 / float(self.masses(1.0).min())


# --------------------------------------------------------------------------- orientation and rings


def layout_orientation(positions: np.ndarray, faces: np.ndarray) -> float:
    """``+1`` or ``−1``: the sign of the layout's total signed area.

    A consistently oriented mesh maps onto a fold-free layout with every face
    of one sign; which sign depends only on whether the layout is mirrored.
    The sign of the summed signed area is the orientation of the bulk of the
    pattern, whatever folds it has (``+1`` on a tie).
    """
    return 1.0 if float(np.sum(signed_areas_2d(positions, faces), dtype=np.float64)) >= 0 else -1.0


def folded_faces(positions: np.ndarray, faces: np.ndarray, orientation: float | None = None) -> np.ndarray:
    """``(F,)`` bool: faces whose 2D orientation disagrees with the pattern's (or is degenerate).

    ``orientation`` defaults to :func:`layout_orientation` of ``positions``:
    the mesh is consistently oriented, so in a usable pattern every face has
    the sign of the whole.  This is the honest fold count; the spec's
    ``flipped`` compares with each face's own sign in ``P0`` instead.
    """
    return folded_by_area(signed_areas_2d(positions, faces), orientation)


def folded_by_area(signed: np.ndarray, orientation: float | None = None) -> np.ndarray:
    """:func:`folded_faces` from the faces' signed areas (float, or exact integers at any scale)."""
    if orientation is None:
        orientation = 1.0 if float(np.sum(signed, dtype=np.float64)) >= 0 else -1.0
    return orientation * signed <= 0


@dataclass(frozen=True, eq=False)
class Rings:
    """Neighbour lists in cyclic order: node ``i``'s are ``neighbour[indptr[i]:indptr[i+1]]``.

    Consecutive entries ``k``, ``k+1`` of a node (cyclically: the last entry
    pairs with the first) are the node's incident triangle ``(i, j_k, j_k+1)``
    in the mesh's own winding, when ``face[k] >= 0``; a boundary node's ring
    starts after its boundary gap, so only its last pair has ``face = −1``.
    The degree and the set of neighbours are those of :attr:`Mesh.neighbours`.

    Attributes:
        indptr: ``(V+1,)``.
        neighbour: ``(N,)`` neighbour node ``j_k``.
        edge_id: ``(N,)`` row of :attr:`Mesh.edges` of the spring ``(i, j_k)``.
        next_neighbour: ``(N,)`` ``j_k+1`` (cyclic within the node).
        face: ``(N,)`` the face ``(i, j_k, j_k+1)``, or −1 where the pair is no face.
    """

    indptr: np.ndarray
    neighbour: np.ndarray
    edge_id: np.ndarray
    next_neighbour: np.ndarray
    face: np.ndarray


def _rings(faces: np.ndarray, n: int, edges: np.ndarray) -> Rings:
    """Walk each node's fan: corner ``a`` of face ``(a, b, c)`` links ``b → c``."""
    f = len(faces)
    owner = faces.ravel()  # corner k of face t: node faces[t, k]
    after = np.roll(faces, -1, axis=1).ravel()  # b
    before = np.roll(faces, -2, axis=1).ravel()  # c
    face_of = np.repeat(np.arange(f), 3)
    key = owner * n + after
    degree = np.bincount(np.concatenate([edges[:, 0], edges[:, 1]]), minlength=n)
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(degree, out=indptr[1:])
    # a fan starts at the corner whose 'after' is no other corner's 'before' (boundary nodes only)
    has_predecessor = np.isin(key, owner * n + before)
    neighbour = np.empty(indptr[-1], dtype=np.int64)
    next_neighbour = np.empty_like(neighbour)
    face = np.full(indptr[-1], -1, dtype=np.int64)
    corners_of = np.argsort(owner, kind="stable")
    corner_ptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(owner, minlength=n), out=corner_ptr[1:])
    for i in range(n):
        corners = corners_of[corner_ptr[i]:corner_ptr[i + 1]]
        succ = {int(after[c]): (int(before[c]), int(face_of[c])) for c in corners}
        starts = [int(after[c]) for c in corners if not has_predecessor[c]]
        j = starts[0] if starts else int(after[corners[0]])
        base = indptr[i]
        for k in range(degree[i]):
            neighbour[base + k] = j
            nxt = succ.get(j)
            if nxt is None:  # boundary: the fan ends; the ring closes over the gap
                next_neighbour[base + k] = neighbour[base]
                break
            next_neighbour[base + k], face[base + k] = nxt
            j = nxt[0]
    edge_index = {(int(a), int(b)): e for e, (a, b) in enumerate(edges.tolist())}
    owner_entries = np.repeat(np.arange(n), degree)
    lo, hi = np.minimum(owner_entries, neighbour), np.maximum(owner_entries, neighbour)
    edge_id = np.fromiter((edge_index[(int(a), int(b))] for a, b in zip(lo, hi)), dtype=np.int64, count=len(lo))
    return Rings(indptr, neighbour, edge_id, next_neighbour, face)


# --------------------------------------------------------------------------- topology


def _unique_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique sorted edges, the edge index of each face side, and face counts per edge.

    Face side ``k`` of face ``f`` is the edge ``(faces[f,k], faces[f,(k+1)%3])``.
    """
    sides = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    sides = np.sort(sides, axis=1)
    # one int64 key per edge: np.unique on 1-D keys is much faster than on rows
    n = int(faces.max()) + 1
    keys, side_edge, counts = np.unique(sides[:, 0] * n + sides[:, 1], return_inverse=True, return_counts=True)
    edges = np.column_stack([keys // n, keys % n])
    return edges, side_edge.reshape(-1), counts


def _directed_boundary_edges(faces: np.ndarray) -> np.ndarray:
    """Boundary edges ``(a, b)`` oriented as they appear in their face."""
    sides = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    _, side_edge, counts = _unique_edges(faces)
    return sides[counts[side_edge] == 1]


def _validate(vertices: np.ndarray, faces: np.ndarray) -> None:
    """Raise :class:`MeshError` unless the arrays form a single manifold disk."""
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"vertices must be a (V, 3) array, got shape {vertices.shape}")
    if len(vertices) == 0 or faces.size == 0:
        raise MeshError("mesh is empty (no vertices or no faces)")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshError(f"faces must be triangles, got face array of shape {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer):
        raise MeshError("face indices must be integers")
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise MeshError(f"vertex {int(np.flatnonzero(bad)[0])} has a non-finite coordinate")
    magnitude = np.abs(vertices).max(axis=1)
    far = magnitude > COORDINATE_LIMIT
    if far.any():
        v = int(np.flatnonzero(far)[0])
        raise MeshError(f"vertex {v} has a coordinate of magnitude {magnitude[v]:.3g}, outside the supported range "
                        f"|x| <= {COORDINATE_LIMIT:g}")
    n = len(vertices)
    out = (faces < 0) | (faces >= n)
    if out.any():
        f = int(np.flatnonzero(out.any(axis=1))[0])
        raise MeshError(
            f"face {f} references vertex {int(faces[f][out[f]][0])}, out of range 0..{n - 1}"
        )
    faces = faces.astype(np.int64)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    if repeated.any():
        raise MeshError(f"face {int(np.flatnonzero(repeated)[0])} repeats a vertex (degenerate triangle)")
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        f = int(first[counts > 1].min())
        raise MeshError(f"face {f} is duplicated (same three vertices appear in another face)")
    used = np.zeros(n, dtype=bool)
    used[faces.ravel()] = True
    if not used.all():
        raise MeshError(f"vertex {int(np.flatnonzero(~used)[0])} is not used by any face")

    edges, side_edge, counts = _unique_edges(faces)
    size = float(np.abs(vertices[edges[:, 0]] - vertices[edges[:, 1]]).max())  # no squares: cannot underflow
    if 0 < size < MIN_MESH_SIZE:  # size 0: every face is degenerate, said below
        raise MeshError(f"mesh is too small: its longest edge is about {size:.3g}, below the supported "
                        f"{MIN_MESH_SIZE:g} (squared lengths and areas would underflow); scale it up")
    longest = float(np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1).max())
    areas = triangle_areas_3d(vertices, faces)
    degenerate = areas <= DEGENERATE_RELATIVE_AREA * longest**2
    if degenerate.any():
        raise MeshError(f"face {int(np.flatnonzero(degenerate)[0])} is degenerate (zero area)")
    if (counts > 2).any():
        e = edges[np.flatnonzero(counts > 2)[0]]
        raise MeshError(f"mesh is non-manifold: edge ({e[0]}, {e[1]}) is shared by more than two faces")

    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    n_parts, _ = connected_components(graph, directed=False)
    if n_parts != 1:
        raise MeshError(f"mesh is not a single disk: it has {n_parts} connected components")
    _check_vertex_manifold(faces, side_edge, counts, n)

    boundary = edges[counts == 1]
    if len(boundary) == 0:
        raise MeshError("mesh is not a disk: it is closed (no boundary loop)")
    bgraph = sp.coo_matrix((np.ones(len(boundary)), (boundary[:, 0], boundary[:, 1])), shape=(n, n))
    on_boundary = np.unique(boundary)
    n_loops = connected_components(bgraph, directed=False)[0] - (n - len(on_boundary))
    if n_loops != 1:
        raise MeshError(f"mesh is not a disk: it has {n_loops} boundary loops (holes), expected one")
    euler = n - len(edges) + len(faces)
    if euler != 1:
        raise MeshError(f"mesh is not a disk: Euler characteristic {euler} (handles), expected 1")


def _check_vertex_manifold(faces: np.ndarray, side_edge: np.ndarray, counts: np.ndarray, n: int) -> None:
    """Each vertex's incident triangles must form one fan (no pinched vertices).

    Corners (face, vertex) are joined across every interior edge they share;
    a manifold vertex has all its corners in one connected group.
    """
    n_faces = len(faces)
    corner = np.arange(3 * n_faces).reshape(n_faces, 3)
    # Side k of face f runs from corner k to corner k+1.
    side_from = corner.reshape(-1)
    side_to = np.roll(corner, -1, axis=1).reshape(-1)
    interior = counts[side_edge] == 2
    sides = np.flatnonzero(interior)
    order = np.argsort(side_edge[sides], kind="stable")
    pairs = sides[order].reshape(-1, 2)  # the two face sides of each interior edge
    s, t = pairs[:, 0], pairs[:, 1]
    v_s_from = faces.reshape(-1)[side_from[s]]
    # Match corners of the same vertex on both sides of the shared edge.
    same = v_s_from == faces.reshape(-1)[side_from[t]]
    a = np.concatenate([side_from[s], side_to[s]])
    b = np.concatenate([np.where(same, side_from[t], side_to[t]), np.where(same, side_to[t], side_from[t])])
    m = 3 * n_faces
    graph = sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(m, m))
    _, label = connected_components(graph, directed=False)
    corner_vertex = faces.reshape(-1)
    fans = np.unique(corner_vertex * m + label)  # one key per (vertex, fan)
    fans_per_vertex = np.bincount(fans // m, minlength=n)
    if (fans_per_vertex > 1).any():
        v = int(np.flatnonzero(fans_per_vertex > 1)[0])
        raise MeshError(f"mesh is non-manifold at vertex {v} (its triangles form more than one fan)")


# --------------------------------------------------------------------------- I/O


def load_mesh(path: str | Path) -> Mesh:
    """Load and validate an OBJ, PLY, OFF or STL triangle mesh.

    The same as :func:`load_mesh_with_notes` without the notes.
    """
    return load_mesh_with_notes(path)[0]


def load_mesh_with_notes(path: str | Path) -> tuple[Mesh, list[str]]:
    """Load and validate a mesh file; also return one-line notes on what was changed or ignored.

    Vertex *i* of the file is node *i* in every format but STL.  OBJ is read
    by :func:`read_obj`, PLY (ASCII and binary) and OFF by the project's own
    readers; polygons are fan-triangulated in file order, with a note (see
    :func:`read_obj`).  STL goes through trimesh; it stores each triangle
    with its own three corners and no shared vertices, so for STL only,
    exactly equal corner coordinates are merged, numbered in order of first
    appearance.

    A file that cannot be read raises :class:`MeshError` "cannot read mesh
    '<path>': <reason>" (no such file, permission denied, ...); one that is
    no valid file of its format "cannot parse mesh …"; one that is read but
    is no valid disk "invalid mesh …" with the validation's message (for OBJ
    followed by the file line it points at).
    """
    path = Path(path)
    data = read_file_bytes(path, "mesh", MeshError)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(
            f"cannot read mesh '{path}': unknown format '{suffix}' (use {', '.join(MESH_SUFFIXES)})"
        )
    hint = ""
    if suffix == ".obj":
        obj = read_obj(path, data)
        vertices, faces, notes = obj.vertices, obj.faces, obj.notes
    elif suffix in (".ply", ".off"):
        where = f"cannot parse mesh '{path}'"
        vertices, polygons = (_read_ply if suffix == ".ply" else _read_off)(data, where)
        faces, _, notes = _triangulate_polygons(vertices, polygons, where)
    else:
        vertices, faces, notes = _read_stl(data, path)
    try:
        return Mesh(vertices, faces, name=path.stem), notes
    except MeshError as exc:
        if suffix == ".obj":
            hint = _obj_line_hint(str(exc), obj)
        raise MeshError(f"invalid mesh '{path}': {exc}{hint}") from None


def _read_stl(data: bytes, path: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """STL (ASCII or binary) through trimesh, equal corners merged."""
    import trimesh  # heavy import, only needed for STL

    binary = len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little")
    if binary and len(data) == 84:
        raise MeshError(f"invalid mesh '{path}': the binary STL holds 0 triangles")
    if not binary:
        # text: trimesh would guess a non-UTF-8 encoding with charset_normalizer (an optional
        # dependency); STL keywords and numbers are ASCII, so undecodable bytes are replaced
        data = data.decode("utf-8", errors="replace").encode("utf-8")
    try:
        loaded = trimesh.load(io.BytesIO(data), file_type="stl", process=False, maintain_order=True, force="mesh")
        vertices = np.asarray(loaded.vertices, dtype=np.float64)
        faces = np.asarray(loaded.faces)
    except Exception as exc:  # trimesh raises many types on malformed files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise MeshError(f"cannot parse mesh '{path}': {reason}") from None
    notes = []
    if len(vertices):
        corners = len(vertices)
        vertices, faces = _merge_exact_duplicates(vertices, faces)
        notes.append(f"merged {corners} STL triangle corners into {len(vertices)} shared vertices")
    return vertices, faces, notes


@dataclass(frozen=True)
class _Polygons:
    """Faces as read: the corners of all faces in a row, each face's corner count, and how to name face f."""

    index: np.ndarray
    sizes: np.ndarray
    label: object  # callable: face number -> "line 12" / "face 3"


def _triangulate_polygons(
    vertices: np.ndarray, polygons: _Polygons, where: str
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Triangles of the faces (fans for polygons), the face of each triangle, and the note on polygons."""
    sizes = polygons.sizes
    if (sizes == 3).all():
        return polygons.index.reshape(-1, 3), np.arange(len(sizes)), []
    faces, triangle_face = _fan_triangulate(polygons.index, sizes)
    if np.isfinite(vertices).all() and np.abs(vertices).max(initial=0.0) <= COORDINATE_LIMIT:
        _check_fans(vertices, faces, triangle_face, sizes, polygons.label, where)
    # else the validation refuses the coordinates, with the right message, before anything uses the fans
    many = sizes > 3
    low, high = int(sizes[many].min()), int(sizes[many].max())
    polygon_count = _plural(int(many.sum()), "polygon")
    triangle_count = _plural(int((sizes[many] - 2).sum()), "triangle")
    span = f"{low}" if low == high else f"{low} to {high}"
    return faces, triangle_face, [f"{polygon_count} ({span} corners) fan-triangulated into {triangle_count}"]


def _checked_polygons(index: np.ndarray, sizes: np.ndarray, n_vertices: int, label, where: str) -> _Polygons:
    """Refuse faces with fewer than 3 corners or a corner outside the vertices (PLY, OFF: 0-based)."""
    short = sizes < 3
    if short.any():
        f = int(np.flatnonzero(short)[0])
        raise MeshError(f"{where}: {label(f)}: face with {_plural(int(sizes[f]), 'corner')} (a face needs at least 3)")
    out = (index < 0) | (index >= n_vertices)
    if out.any():
        c = int(np.flatnonzero(out)[0])
        f = int(np.searchsorted(np.cumsum(sizes), c, side="right"))
        raise MeshError(f"{where}: {label(f)}: face refers to vertex {int(index[c])}, outside 0..{n_vertices - 1}")
    return _Polygons(index.astype(np.int64), sizes.astype(np.int64), label)


# ..................................................................... PLY

#: PLY scalar types and their numpy codes (byte order added for binary files).
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _read_ply(data: bytes, where: str) -> tuple[np.ndarray, _Polygons]:
    """Vertices (the ``vertex`` element's x, y, z, in file order) and faces of an ASCII or binary PLY file.

    Every element the header declares is read (so elements before or between
    ``vertex`` and ``face`` are skipped correctly); the faces are the
    ``face`` element's ``vertex_indices`` (or ``vertex_index``) lists, of any
    length.  Refusals name the problem: not PLY, an unknown type, a value
    that is no number, a file shorter than its header says.
    """
    if not data.startswith(b"ply"):
        raise MeshError(f"{where}: not a PLY file (it must start with 'ply')")
    marker = data.find(b"end_header")
    if marker < 0:
        raise MeshError(f"{where}: the PLY header has no 'end_header' line")
    newline = data.find(b"\n", marker)
    body = data[newline + 1:] if newline >= 0 else b""
    fmt, elements = None, []  # elements: (name, count, [(property, type, count type or None)])
    for number, line in enumerate(data[:marker].decode("ascii", errors="replace").splitlines(), 1):
        tokens = line.split()
        if not tokens or tokens[0] in ("ply", "comment", "obj_info"):
            continue
        if tokens[0] == "format" and len(tokens) == 3:
            fmt = tokens[1]
        elif tokens[0] == "element" and len(tokens) == 3 and tokens[2].isdigit():
            elements.append((tokens[1], int(tokens[2]), []))
        elif tokens[0] == "property" and elements and len(tokens) == 3 and tokens[1] in _PLY_TYPES:
            elements[-1][2].append((tokens[2], tokens[1], None))
        elif (tokens[0] == "property" and elements and len(tokens) == 5 and tokens[1] == "list"
              and tokens[2] in _PLY_TYPES and tokens[3] in _PLY_TYPES):
            elements[-1][2].append((tokens[4], tokens[3], tokens[2]))
        else:
            raise MeshError(f"{where}: header line {number} {line.strip()[:60]!r} is not PLY")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise MeshError(f"{where}: the PLY header has no 'format ascii|binary_little_endian|binary_big_endian 1.0'")
    try:
        if fmt == "ascii":
            values = _ply_ascii(body, elements)
        else:
            values = _ply_binary(body, elements, "<" if fmt == "binary_little_endian" else ">")
    except (ValueError, TypeError) as exc:
        raise MeshError(f"{where}: {str(exc).splitlines()[0]}") from None
    vertex = values.get("vertex")
    if vertex is None or not {"x", "y", "z"} <= vertex.keys():
        raise MeshError(f"{where}: no 'vertex' element with x, y and z")
    vertices = np.column_stack([np.asarray(vertex[k], dtype=np.float64) for k in "xyz"]).reshape(-1, 3)
    face_properties = next((props for element, _, props in elements if element == "face"), [])
    lists = [prop for prop, _, count_type in face_properties if count_type]
    name = next((n for n in ("vertex_indices", "vertex_index") if n in lists), lists[0] if lists else None)
    if name is None:
        index, sizes = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    else:
        index, sizes = values["face"][name]
    return vertices, _checked_polygons(index, sizes, len(vertices), lambda f: f"face {f}", where)


def _ply_ascii(body: bytes, elements) -> dict:
    """Each element's properties: a scalar as an array, a list as ``(flat values, lengths)``."""
    tokens = body.split()
    pos, values = 0, {}
    for name, count, props in elements:
        columns: dict = {}
        if all(count_type is None for _, _, count_type in props):
            width = len(props)
            block = _ascii_numbers(tokens[pos:pos + count * width], name, count * width).reshape(count, width)
            columns = {prop: block[:, k] for k, (prop, _, _) in enumerate(props)}
            pos += count * width
        elif len(props) == 1 and count and _uniform_ascii_list(tokens, pos, count):
            length = int(tokens[pos])
            block = _ascii_numbers(tokens[pos:pos + count * (length + 1)], name, count * (length + 1))
            columns = {props[0][0]: (_ascii_indices(block.reshape(count, length + 1)[:, 1:].ravel(), name),
                                     np.full(count, length, dtype=np.int64))}
            pos += count * (length + 1)
        else:
            raw = {prop: [] for prop, _, _ in props}
            lengths = {prop: [] for prop, _, count_type in props if count_type}
            for _ in range(count):
                for prop, _, count_type in props:
                    if count_type is None:
                        raw[prop].append(tokens[pos] if pos < len(tokens) else b"")
                        pos += 1
                    else:
                        length = int(_ascii_numbers(tokens[pos:pos + 1], name, 1)[0])
                        raw[prop].extend(tokens[pos + 1:pos + 1 + length])
                        lengths[prop].append(length)
                        pos += 1 + length
            if pos > len(tokens):
                raise ValueError(f"the file ends inside element '{name}' (fewer values than the header declares)")
            for prop, items in raw.items():
                numbers = _ascii_numbers(items, name, len(items) if prop in lengths else count)
                columns[prop] = ((_ascii_indices(numbers, name), np.asarray(lengths[prop], dtype=np.int64))
                                 if prop in lengths else numbers)
        values[name] = columns
    if pos < len(tokens):
        raise ValueError(f"{len(tokens) - pos} values after the last element the header declares")
    return values


def _uniform_ascii_list(tokens: list, pos: int, count: int) -> bool:
    """Whether ``count`` rows of one list property all have the length of the first."""
    first = tokens[pos] if pos < len(tokens) else b""
    if not first.isdigit():
        return False
    stride = int(first) + 1
    lengths = tokens[pos:pos + count * stride:stride]
    return len(lengths) == count and len(tokens) >= pos + count * stride and all(t == first for t in lengths)


#: Largest magnitude a face index read from a text file may have; far beyond any vertex count, and
#: exactly representable in float64 (PLY ASCII numbers are read as floats), so a larger index is
#: refused as out of range instead of wrapping in the conversion to int64.
_INDEX_LIMIT = 1 << 53


def _ascii_indices(numbers: np.ndarray, element: str) -> np.ndarray:
    """The int64 indices of ASCII PLY list values read as floats; a fraction or a value past
    :data:`_INDEX_LIMIT` is refused (no silent truncation or wrap-around)."""
    bad = ~(np.abs(numbers) < _INDEX_LIMIT) | (numbers != np.floor(numbers))
    if bad.any():
        value = float(numbers[np.flatnonzero(bad)[0]])
        what = "out of range" if not abs(value) < _INDEX_LIMIT else "not an integer"
        raise ValueError(f"element '{element}' has an index {value:.17g} that is {what}")
    return numbers.astype(np.int64)


def _ascii_numbers(items: list, element: str, expected: int) -> np.ndarray:
    if len(items) < expected:
        raise ValueError(f"the file ends inside element '{element}' (fewer values than the header declares)")
    try:
        return np.array(items, dtype=np.bytes_).astype(np.float64)
    except ValueError:
        bad = next(t for t in items if not _is_float(t.decode("ascii", errors="replace")))
        raise ValueError(f"element '{element}' has a value {bad.decode('ascii', errors='replace')[:20]!r} that is "
                         "not a number") from None


def _ply_binary(body: bytes, elements, order: str) -> dict:
    """As :func:`_ply_ascii` for a binary body in byte order ``order``."""
    pos, values = 0, {}

    def take(dtype: np.dtype, count: int, element: str) -> np.ndarray:
        nonlocal pos
        if pos + dtype.itemsize * count > len(body):
            raise ValueError(f"the file ends inside element '{element}' (shorter than the header declares)")
        array = np.frombuffer(body, dtype=dtype, count=count, offset=pos)
        pos += dtype.itemsize * count
        return array

    for name, count, props in elements:
        if len({prop for prop, _, _ in props}) != len(props):
            raise ValueError(f"element '{name}' declares a property twice")
        if all(count_type is None for _, _, count_type in props):
            block = take(np.dtype([(prop, order + _PLY_TYPES[t]) for prop, t, _ in props]), count, name)
            values[name] = {prop: block[prop] for prop, _, _ in props}
            continue
        uniform = _uniform_binary(body, pos, count, props, order)
        if uniform is not None:
            block = take(uniform, count, name)
            values[name] = {prop: (block[prop].ravel().astype(np.int64), block[prop + "#"].astype(np.int64))
                            if count_type else block[prop]
                            for prop, _, count_type in props}
            continue
        columns = {prop: [] for prop, _, _ in props}
        lengths = {prop: [] for prop, _, count_type in props if count_type}
        scalar = {prop: np.dtype(order + _PLY_TYPES[t]) for prop, t, _ in props}
        counter = {prop: np.dtype(order + _PLY_TYPES[c]) for prop, _, c in props if c}
        for _ in range(count):
            for prop, _, count_type in props:
                if count_type is None:
                    columns[prop].append(take(scalar[prop], 1, name)[0])
                else:
                    length = int(take(counter[prop], 1, name)[0])
                    columns[prop].append(take(scalar[prop], length, name))
                    lengths[prop].append(length)
        values[name] = {prop: ((np.concatenate(items).astype(np.int64) if items else np.zeros(0, dtype=np.int64)),
                               np.asarray(lengths[prop], dtype=np.int64)) if prop in lengths else np.asarray(items)
                        for prop, items in columns.items()}
    return values


def _uniform_binary(body: bytes, pos: int, count: int, props, order: str) -> np.dtype | None:
    """A record dtype for the element when every list in it has the length its first row has, else None."""
    if count == 0:
        return None
    fields, offset = [], pos
    for prop, t, count_type in props:
        if count_type is None:
            fields.append((prop, order + _PLY_TYPES[t]))
            offset += np.dtype(_PLY_TYPES[t]).itemsize
            continue
        counter = np.dtype(order + _PLY_TYPES[count_type])
        if offset + counter.itemsize > len(body):
            return None
        length = int(np.frombuffer(body, dtype=counter, count=1, offset=offset)[0])
        fields += [(prop + "#", counter), (prop, order + _PLY_TYPES[t], (length,))]
        offset += counter.itemsize + length * np.dtype(_PLY_TYPES[t]).itemsize
    dtype = np.dtype(fields)
    if pos + dtype.itemsize * count > len(body):
        return None
    block = np.frombuffer(body, dtype=dtype, count=count, offset=pos)
    for prop, _, count_type in props:
        if count_type and not (block[prop + "#"] == block[prop].shape[1]).all():
            return None
    return dtype


# ..................................................................... OFF

#: OFF keywords: vertex colours (C), normals (N) and texture coordinates (ST) follow x y z and are ignored.
_OFF_KEYWORDS = frozenset(f"{st}{c}{n}OFF" for st in ("", "ST") for c in ("", "C") for n in ("", "N"))


def _read_off(data: bytes, where: str) -> tuple[np.ndarray, _Polygons]:
    """Vertices (in file order) and faces of an ASCII OFF file.

    ``OFF`` (or ``COFF``, ``NOFF``, ``STOFF`` …), the counts ``V F [E]`` on
    the same line or the next, ``V`` lines whose first three numbers are
    x y z, then ``F`` lines ``n i1 … in [colour]``; ``#`` comments and blank
    lines anywhere.  Refusals name the line.
    """
    text = data.decode("utf-8-sig", errors="replace")
    lines = text.splitlines()
    if "#" in text:
        lines = [line.split("#", 1)[0] for line in lines]
    rows = [(number, tokens) for number, tokens in enumerate(map(str.split, lines), 1) if tokens]
    if not rows or rows[0][1][0] not in _OFF_KEYWORDS:
        first = rows[0][1][0][:20] if rows else "nothing"
        raise MeshError(f"{where}: not an OFF file (it starts with {first!r}; binary and 4D/nD OFF are not supported)")
    count_line, header = rows[0][0], rows[0][1][1:]
    if header[:1] == ["BINARY"]:
        raise MeshError(f"{where}: binary OFF is not supported (write it as text OFF, PLY or OBJ)")
    rows = rows[1:]
    if not header:  # the counts are on the next line
        if not rows:
            raise MeshError(f"{where}: the OFF file has no vertex and face counts")
        (count_line, header), rows = rows[0], rows[1:]
    if len(header) < 2 or not all(_is_int(t) for t in header[:3]) or min(int(t) for t in header[:2]) < 0:
        raise MeshError(f"{where}: line {count_line}: expected the counts 'vertices faces [edges]', "
                        f"got {' '.join(header)[:40]!r}")
    n_vertices, n_faces = int(header[0]), int(header[1])
    if len(rows) < n_vertices + n_faces:
        raise MeshError(f"{where}: the file ends early: the header declares {_plural(n_vertices, 'vertex', 'vertices')} "
                        f"and {_plural(n_faces, 'face')}, the file has {len(rows)} lines of them")
    vertex_rows, face_rows = rows[:n_vertices], rows[n_vertices:n_vertices + n_faces]
    short = next(((number, tokens) for number, tokens in vertex_rows if len(tokens) < 3), None)
    if short is not None:
        raise MeshError(f"{where}: line {short[0]}: vertex with {len(short[1])} values (needs x y z)")
    coords = [value for _, tokens in vertex_rows for value in tokens[:3]]
    vertices = _obj_coordinates(coords, np.array([number for number, _ in vertex_rows]), where)
    lines = [number for number, _ in face_rows]
    uniform = _uniform_off_faces([tokens for _, tokens in face_rows])
    if uniform is not None:
        return vertices, _checked_polygons(uniform[:, 1:].ravel(),
                                           uniform[:, 0], n_vertices, lambda f: f"line {lines[f]}", where)
    sizes, index = [], []
    for number, tokens in face_rows:
        if not _is_int(tokens[0]) or len(tokens) < int(tokens[0]) + 1 or not all(
                _is_int(t) for t in tokens[1:int(tokens[0]) + 1]):
            raise MeshError(f"{where}: line {number}: expected a face 'n i1 ... in', got {' '.join(tokens)[:40]!r}")
        size = int(tokens[0])
        corners = [int(t) for t in tokens[1:size + 1]]
        if any(not -_INDEX_LIMIT <= i < _INDEX_LIMIT for i in corners):  # beyond int64: no file has that many
            bad = next(i for i in corners if not -_INDEX_LIMIT <= i < _INDEX_LIMIT)
            raise MeshError(f"{where}: line {number}: face index {bad} is out of range")
        sizes.append(size)
        index.extend(corners)
    return vertices, _checked_polygons(np.asarray(index, dtype=np.int64), np.asarray(sizes, dtype=np.int64),
                                       n_vertices, lambda f: f"line {lines[f]}", where)


def _uniform_off_faces(rows: list[list[str]]) -> np.ndarray | None:
    """``(F, n+1)`` integers when every face row is ``n i1 … in`` with one n and nothing after; else None."""
    if not rows or len({len(tokens) for tokens in rows}) != 1:
        return None
    try:
        block = np.array(rows, dtype=np.bytes_).astype(np.int64)
    except (ValueError, UnicodeEncodeError, OverflowError):  # the slow path names the line
        return None
    return block if (block[:, 0] == block.shape[1] - 1).all() else None


# ..................................................................... OBJ

#: Free-form geometry statements: they define curves and surfaces the
#: project would silently drop, so a file using them is refused.
OBJ_FREE_FORM = frozenset(
    {"cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp", "end", "con"}
)
#: Grouping, display and render statements: accepted and ignored without a note.
OBJ_HARMLESS = frozenset(
    {"vt", "vn", "g", "o", "s", "mg", "usemtl", "mtllib", "usemap", "maplib", "bevel", "c_interp", "d_interp",
     "lod", "shadow_obj", "trace_obj", "ctech", "stech"}
)
#: Accepted, not used, and counted in a note.
OBJ_IGNORED = {
    "l": ("'l' line element", "'l' line elements"),
    "p": ("'p' point element", "'p' point elements"),
    "vp": ("'vp' parameter-space vertex", "'vp' parameter-space vertices"),
}


@dataclass(frozen=True, eq=False)
class ObjContents:
    """What :func:`read_obj` found.

    Attributes:
        vertices: ``(V, 3)`` float64, row *i* = the file's *i*-th ``v``.
        faces: ``(F, 3)`` int64, 0-based; polygons already fan-triangulated.
        face_line: ``(F,)`` file line of the ``f`` statement of each triangle.
        vertex_line: ``(V,)`` file line of each ``v`` statement.
        notes: one line per thing that was triangulated or ignored.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_line: np.ndarray
    vertex_line: np.ndarray
    notes: list[str]


def _obj_lines(text: str) -> tuple[list[str], list[int] | None]:
    """The file's statements, a trailing ``\\`` joining a line to the next; their line numbers if joined."""
    lines = text.splitlines()
    if "\\" not in text:
        return lines, None  # statement i is on line i + 1
    joined: list[str] = []
    numbers: list[int] = []
    pending = None
    for number, line in enumerate(lines, 1):
        if pending is None:
            if line.lstrip().startswith("#"):  # a comment continues nothing
                joined.append(line)
                numbers.append(number)
                continue
            start, pending = number, ""
        line = f"{pending} {line}"
        stripped = line.rstrip()
        if stripped.endswith("\\"):
            pending = stripped[:-1]
            continue
        joined.append(line)
        numbers.append(start)
        pending = None
    if pending is not None:
        joined.append(pending)
        numbers.append(start)
    return joined, numbers


def _plural(n: int, word: str, words: str | None = None) -> str:
    """``1 polygon``, ``2 polygons``; ``words`` for an irregular plural."""
    return f"{n} {word}" if n == 1 else f"{n} {words or word + 's'}"


def read_obj(path: str | Path, data: bytes | None = None) -> ObjContents:
    """Read the polygonal part of a Wavefront OBJ file, keeping vertex numbering.

    Accepted: ``v x y z [w]`` and ``v x y z r g b`` (weight and colours
    ignored); ``f`` with corners ``i``, ``i/t``, ``i//n`` or ``i/t/n``,
    1-based positive indices (counted over the whole file) or negative ones
    (relative to the vertices, texture coordinates or normals read so far);
    ``vt``, ``vn``, groups ``g``, objects ``o`` and the other grouping,
    material and display statements (ignored: several objects or groups
    make one mesh, as OBJ numbers vertices globally); ``#`` comments; a
    trailing ``\\`` continues a statement on the next line.  ``l``, ``p``
    and ``vp`` are ignored with a note, and so is any unknown statement.

    A polygon ``(c0, c1, …, c_{n-1})`` with ``n > 3`` corners becomes the
    fan ``(c0, ck, ck+1)``, ``k = 1 … n−2``, in the polygon's winding, with
    a note.  The fan must be a faithful triangulation: every fan triangle
    must face the way the polygon does (its normal has a positive dot
    product with the polygon's Newell normal), else the file is refused.

    Vertex *i* of the file (0-based) is row *i* of ``vertices``: nothing is
    merged, reordered or dropped; unused vertices are left to the mesh
    validation.  Refusals raise :class:`MeshError` "cannot parse mesh
    '<path>': line <n>: <construct>"; a file that cannot be read "cannot
    read mesh '<path>': <reason>".  ``data``: the file's bytes, if already read.
    Text is UTF-8 (a byte-order mark is skipped); lines end in LF, CRLF or CR;
    tokens are separated by any whitespace, tabs included.
    """
    path = Path(path)
    where = f"cannot parse mesh '{path}'"
    if data is None:
        data = read_file_bytes(path, "mesh", MeshError)
    text = data.decode("utf-8-sig", errors="replace")

    statements, numbers = _obj_lines(text)

    def line_of(i):  # file line of statement i (vectorised over arrays of i too)
        return np.asarray(i) + 1 if numbers is None else np.asarray(numbers, dtype=np.int64)[i]

    coords: list[str] = []  # x, y, z of every 'v', flat
    vertex_at: list[int] = []  # statement of each 'v'
    extra_values = 0
    n_vt = n_vn = 0
    corners: list[str] = []
    face_size: list[int] = []
    face_at: list[int] = []
    face_before: list[tuple[int, int, int]] = []  # (v, vt, vn) read before each face
    ignored: dict[str, int] = {}
    unknown: dict[str, list[int]] = {}  # keyword -> [count, first statement]
    groups: dict[str, int] = {"o": 0, "g": 0}

    for i, line in enumerate(statements):
        if "#" in line:
            line = line[: line.index("#")]
        tokens = line.split()
        if not tokens:
            continue
        key = tokens[0]
        if key == "v":
            if len(tokens) != 4:
                if len(tokens) < 4:
                    raise MeshError(
                        f"{where}: line {line_of(i)}: vertex 'v' with {len(tokens) - 1} "
                        f"coordinate{'' if len(tokens) == 2 else 's'} (needs x y z)"
                    )
                extra_values += 1
            coords.extend(tokens[1:4])
            vertex_at.append(i)
        elif key == "f":
            if len(tokens) < 4:
                raise MeshError(
                    f"{where}: line {line_of(i)}: face 'f' with {len(tokens) - 1} "
                    f"corner{'' if len(tokens) == 2 else 's'} (a face needs at least 3)"
                )
            corners.extend(tokens[1:])
            face_size.append(len(tokens) - 1)
            face_at.append(i)
            face_before.append((len(vertex_at), n_vt, n_vn))
        elif key == "vt":
            n_vt += 1
        elif key == "vn":
            n_vn += 1
        elif key in OBJ_FREE_FORM:
            raise MeshError(f"{where}: line {line_of(i)}: free-form geometry ('{key}') is not supported")
        elif key in OBJ_HARMLESS:
            if key in groups:
                groups[key] += 1
        elif key in OBJ_IGNORED:
            ignored[key] = ignored.get(key, 0) + 1
        else:
            unknown.setdefault(key, [0, i])[0] += 1

    vertex_line = line_of(np.asarray(vertex_at, dtype=np.int64))
    face_line = line_of(np.asarray(face_at, dtype=np.int64))
    vertices = _obj_coordinates(coords, vertex_line, where)
    sizes = np.asarray(face_size, dtype=np.int64)
    lines = np.asarray(face_line, dtype=np.int64)
    corner_face = np.repeat(np.arange(len(sizes)), sizes)
    before = np.asarray(face_before, dtype=np.int64).reshape(-1, 3)[corner_face]
    slots, written = _obj_corner_slots(corners, lines[corner_face], where)
    totals = (len(vertices), n_vt, n_vn)
    resolved = [
        _obj_resolve(slots[k], written[k], before[:, k], totals[k], lines[corner_face], what, where)
        for k, what in enumerate(("vertex", "texture coordinate", "normal"))
    ]
    index = resolved[0]

    polygons = _Polygons(index, sizes, lambda f: f"line {lines[f]}")
    faces, triangle_face, notes = _triangulate_polygons(vertices, polygons, where)
    triangle_line = lines[triangle_face]
    if len(sizes) == 0 and ignored.keys() & {"l", "p"}:
        raise MeshError(f"{where}: no faces ('f'), only line ('l') or point ('p') elements")
    for key, count in ignored.items():
        notes.append(f"ignored {_plural(count, *OBJ_IGNORED[key])}")
    if unknown:
        total = _plural(sum(count for count, _ in unknown.values()), "unknown statement")
        listed = [f"'{key}' ({count}, first at line {line_of(first)})" for key, (count, first) in unknown.items()]
        notes.append(f"ignored {total}: {', '.join(listed[:5])}{', ...' if len(listed) > 5 else ''}")
    if extra_values:
        v_lines = _plural(extra_values, "'v' line")
        notes.append(f"ignored the extra values (weight w or colour r g b) of {v_lines}")
    if groups["o"] > 1 or groups["g"] > 1:
        parts = [_plural(groups["o"], "'o' object"), _plural(groups["g"], "'g' group")]
        parts = [part for part, key in zip(parts, "og") if groups[key]]
        notes.append(f"{' and '.join(parts)} read as one mesh (OBJ numbers vertices across the whole file)")
    return ObjContents(vertices, faces, triangle_line, vertex_line, notes)


def read_obj_vertices(data: bytes, where: str) -> np.ndarray:
    """``(V, 3)`` coordinates of the ``v`` statements of an OBJ file's bytes, in file order.

    The text is read as by :func:`read_obj` (BOM, line ends, tabs, ``#``
    comments, ``\\`` continuations); nothing but ``v`` is looked at.  Used for
    layouts given as OBJ.  Refusals: :class:`MeshError` "<where>: line <n>: ...".
    """
    statements, numbers = _obj_lines(data.decode("utf-8-sig", errors="replace"))
    coords: list[str] = []
    at: list[int] = []
    for i, line in enumerate(statements):
        tokens = line.split("#", 1)[0].split()
        if tokens and tokens[0] == "v":
            if len(tokens) < 4:
                line_number = i + 1 if numbers is None else numbers[i]
                raise MeshError(f"{where}: line {line_number}: vertex 'v' with {len(tokens) - 1} "
                                f"coordinate{'' if len(tokens) == 2 else 's'} (needs x y z)")
            coords.extend(tokens[1:4])
            at.append(i)
    index = np.asarray(at, dtype=np.int64)
    lines = index + 1 if numbers is None else np.asarray(numbers, dtype=np.int64)[index]
    return _obj_coordinates(coords, lines, where)


def _obj_coordinates(coords: list[str], vertex_line: np.ndarray, where: str) -> np.ndarray:
    """``(V, 3)`` floats from the flat x, y, z strings; a token that is no number is refused with its line."""
    try:
        return np.fromiter(map(float, coords), dtype=np.float64, count=len(coords)).reshape(-1, 3)
    except ValueError:
        k = next(k for k, value in enumerate(coords) if not _is_float(value))
        raise MeshError(
            f"{where}: line {vertex_line[k // 3]}: vertex coordinate {coords[k]!r} is not a number"
        ) from None


def _obj_corner_slots(
    corners: list[str], corner_line: np.ndarray, where: str
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The vertex, texture and normal index of each face corner, and whether each is written."""
    fast = _obj_uniform_corners(corners)
    if fast is not None:
        return fast
    parts = [corner.split("/") for corner in corners]
    if not all(len(p) <= 3 for p in parts):
        c = next(c for c, p in enumerate(parts) if len(p) > 3)
        raise MeshError(f"{where}: line {corner_line[c]}: face corner {corners[c]!r} is not i, i/t, i//n or i/t/n")
    slots, written = [], []
    for k in range(3):
        present = [len(p) > k and p[k] != "" for p in parts]
        # the vertex index is never optional: an empty one fails the conversion below
        strings = [p[0] for p in parts] if k == 0 else [p[k] if ok else "0" for p, ok in zip(parts, present)]
        try:
            slots.append(np.fromiter(map(int, strings), dtype=np.int64, count=len(strings)))
        except ValueError:
            c = next(c for c, text in enumerate(strings) if not _is_int(text))
            raise MeshError(
                f"{where}: line {corner_line[c]}: face corner {corners[c]!r} is not i, i/t, i//n or i/t/n "
                "with integer indices"
            ) from None
        except OverflowError:  # beyond int64: far past any file's vertex count
            c = next(c for c, text in enumerate(strings) if not -(1 << 63) <= int(text) < 1 << 63)
            raise MeshError(f"{where}: line {corner_line[c]}: face corner {corners[c]!r}: index {strings[c]} is "
                            "out of range") from None
        written.append(np.array(present, dtype=bool))
    return slots, written


def _obj_uniform_corners(corners: list[str]) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
    """Fast path of :func:`_obj_corner_slots` when every corner has the same form; ``None`` otherwise."""
    if not corners:
        return None
    slashes = corners[0].count("/")
    if slashes > 2 or any(c.count("/") != slashes for c in corners):
        return None
    joined = " ".join(corners)
    doubles = joined.count("//")
    if doubles not in (0, len(corners)):
        return None
    form = (True, slashes >= 1 and doubles == 0, slashes == 2)  # which of i, t, n are written
    tokens = joined.replace("/", " ").split()
    width = sum(form)
    if len(tokens) != width * len(corners):  # an empty index somewhere: i/, /t, ...
        return None
    try:
        values = np.fromiter(map(int, tokens), dtype=np.int64, count=len(tokens)).reshape(-1, width)
    except (ValueError, OverflowError):  # the slow path names the corner
        return None
    columns = iter(values.T)
    slots = [next(columns) if on else np.zeros(len(corners), dtype=np.int64) for on in form]
    written = [np.full(len(corners), on) for on in form]
    return slots, written


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _is_int(text: str) -> bool:
    try:
        int(text)
    except ValueError:
        return False
    return True


def _obj_resolve(
    raw: np.ndarray, written: np.ndarray, before: np.ndarray, total: int, corner_line: np.ndarray,
    what: str, where: str,
) -> np.ndarray:
    """0-based indices from OBJ's 1-based positive and relative negative ones (-1 where not written)."""
    negative = raw < 0
    resolved = np.where(written, np.where(negative, before + raw, raw - 1), -1)
    zero = written & (raw == 0)
    too_far_back = negative & (resolved < 0)
    too_far_on = (raw > 0) & (resolved >= total)
    bad = zero | too_far_back | too_far_on
    if bad.any():
        c = int(np.flatnonzero(bad)[0])
        line = f"{where}: line {corner_line[c]}: "
        words = "vertices" if what == "vertex" else None
        if zero[c]:
            raise MeshError(line + f"face {what} index 0 (OBJ indices start at 1)")
        if too_far_back[c]:
            count, verb = _plural(int(before[c]), what, words), "precedes" if before[c] == 1 else "precede"
            raise MeshError(line + f"face refers to {what} {raw[c]} but only {count} {verb} it")
        raise MeshError(line + f"face refers to {what} {raw[c]} but the file has only {_plural(total, what, words)}")
    return resolved


def _fan_triangulate(index: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan ``(c0, ck, ck+1)`` of each polygon; also the polygon of each triangle."""
    first = np.zeros(len(sizes), dtype=np.int64)
    np.cumsum(sizes[:-1], out=first[1:])
    triangle_face = np.repeat(np.arange(len(sizes)), sizes - 2)
    triangle_start = np.zeros(len(sizes), dtype=np.int64)
    np.cumsum(sizes[:-1] - 2, out=triangle_start[1:])
    k = np.arange(len(triangle_face)) - triangle_start[triangle_face] + 1
    c0 = first[triangle_face]
    faces = np.column_stack([index[c0], index[c0 + k], index[c0 + k + 1]])
    return faces, triangle_face


def _check_fans(
    vertices: np.ndarray, faces: np.ndarray, triangle_face: np.ndarray, sizes: np.ndarray, label, where: str,
) -> None:
    """Refuse a polygon whose fan has a triangle facing against the polygon (not convex at corner 0)."""
    polygon = sizes[triangle_face] > 3
    if not polygon.any():
        return
    a, b, c = (vertices[faces[polygon, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    # Newell normal of each polygon = the sum of its fan triangles' normals (exact for any fan)
    owner = triangle_face[polygon]
    newell = np.column_stack([np.bincount(owner, weights=normal[:, d], minlength=len(sizes)) for d in range(3)])
    facing = np.einsum("ij,ij->i", normal, newell[owner])
    against = ~(facing > 0)
    if against.any():
        t = int(np.flatnonzero(against)[0])
        f = int(owner[t])
        raise MeshError(
            f"{where}: {label(f)}: polygon with {sizes[f]} corners cannot be fan-triangulated from its "
            "first corner (a fan triangle would be folded or of zero area)"
        )


def _obj_line_hint(message: str, obj: ObjContents) -> str:
    """`` (file line n)`` for a validation message that starts with a face or vertex number."""
    import re

    found = re.match(r"(face|vertex) (\d+) ", message)
    if not found:
        return ""
    number = int(found.group(2))
    lines = obj.face_line if found.group(1) == "face" else obj.vertex_line
    return f" (file line {lines[number]})" if number < len(lines) else ""


def _merge_exact_duplicates(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge bit-identical vertices, numbering them by first appearance."""
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return vertices[np.sort(first)], rank[inverse.reshape(-1)][faces]


def save_obj(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Write an OBJ with ``vertices`` (V×2 padded with z = 0, or V×3) and 1-based faces."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.shape[1] == 2:
        vertices = np.column_stack([vertices, np.zeros(len(vertices))])
    with open(path, "w", encoding="ascii") as out:
        out.write("# written by springflat\n")
        np.savetxt(out, vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(out, np.asarray(faces) + 1, fmt="f %d %d %d")
