"""Triangle meshes: validation and the topology the models share.

A :class:`Mesh` is the 3D patch to flatten: ``V`` vertices ``Q`` (metres or any
consistent length unit) and ``F`` triangles.  Vertex *i* in a file is node *i*
everywhere in the project (float reference, fixed-point golden model, RTL
streams): nothing is merged or reordered, except for STL, which has no shared
vertices at all (see :func:`sim.mesh_io.load_mesh`, which reads mesh files).

Validation follows ``spec.md`` ("Bad input"): a mesh must be a single
connected manifold disk with exactly one boundary loop, no degenerate or
duplicate triangles, no out-of-range indices and only finite coordinates
within the supported range (:data:`COORDINATE_LIMIT`, :data:`MIN_MESH_SIZE`).
Every failure raises :class:`MeshError` with a one-line message naming the
problem.  A disk with holes (cut-outs: more boundary loops, no handles) is a
mesh only where it is asked for (``Mesh(..., allow_holes=True)``, :class:`Holes`).
"""

from __future__ import annotations

import enum
import unicodedata
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .graph import component_labels, count_components, parity_roots

__all__ = ["Mesh", "MeshError", "MeshDefect", "InconsistentOrientation", "HoledMesh", "Holes", "fill_holes",
           "boundary_loops", "unique_edges", "outer_loop", "hole_triangles", "loop_length", "loop_signed_area",
           "oriented_mesh", "orient_consistently", "triangle_areas_3d", "signed_areas_2d", "boundary_crossings",
           "turned_holes", "overlap_counts", "COORDINATE_LIMIT", "MIN_MESH_SIZE", "printable_name", "one_line",
           "valid_text"]

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


class MeshDefect(enum.Enum):
    """What a refusal is about, for a reader: a scan's defects a mesh tool removes at once, or several pieces."""

    UNUSED_VERTEX = enum.auto()
    DUPLICATE_FACE = enum.auto()
    ZERO_AREA_FACE = enum.auto()
    SEVERAL_PIECES = enum.auto()


class MeshError(ValueError):
    """A mesh that cannot be flattened; the message is one line for the user.

    Where the validation knows what it refuses, it says so too, for a reader that can point into the file:
    ``faces`` and ``vertices``, the ones the message names, numbered from 0 as the arrays are (a vertex, a
    face, an edge's two vertices, two faces), and ``defect`` (:class:`MeshDefect`, or ``None``)."""

    def __init__(self, message: str, *, faces: tuple[int, ...] = (), vertices: tuple[int, ...] = (),
                 defect: MeshDefect | None = None) -> None:
        super().__init__(message)
        self.faces, self.vertices, self.defect = tuple(map(int, faces)), tuple(map(int, vertices)), defect


class InconsistentOrientation(MeshError):
    """Two faces run through their shared edge the same way: the faces are not wound consistently
    (:func:`oriented_mesh` turns them to agree, where the mesh is orientable)."""


class HoledMesh(MeshError):
    """A disk with holes: more than one boundary loop (:func:`fill_holes` closes all but the outer one)."""


class Holes(enum.Enum):
    """What reading a mesh does with its holes, the boundary loops besides its outer edge."""

    #: refused (:class:`HoledMesh`): a scan's holes are usually defects, so the user chooses
    REFUSE = "refuse"
    #: closed by :func:`fill_holes`: the pattern covers them
    FILL = "fill"
    #: kept: cut-outs in the pattern (the start layouts are computed on the filled disk, :attr:`Mesh.disk`)
    KEEP = "keep"


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


def printable_name(name: str) -> str:
    """``name`` as one line of valid text, for the headers and titles of the files that carry it: the bytes
    of a file name that were not UTF-8 (Python's surrogate escapes) and control characters (a newline would
    start a record of its own in an OBJ header) as backslash escapes (``\\xff``, ``\\n``)."""
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in valid_text(name))


def one_line(text: str) -> str:
    """``text`` as one line for a terminal (an error line): a file name's undecodable bytes, control characters
    and line or paragraph separators as backslash escapes; every other character as it is (a no-break space
    in a file name stays one, so that the name can be copied from the message)."""
    return "".join(repr(ch)[1:-1] if unicodedata.category(ch) in ("Cc", "Zl", "Zp") else ch
                   for ch in valid_text(text))


def valid_text(text: str) -> str:
    """``text`` with the surrogates that stand for a file name's undecodable bytes as ``\\xff`` escapes."""
    text = str(text)
    try:
        raw = text.encode("utf-8", "surrogateescape")
    except UnicodeEncodeError:  # a surrogate that no undecodable byte gave
        raw = text.encode("utf-8", "backslashreplace")
    return raw.decode("utf-8", "backslashreplace")


@dataclass(frozen=True, eq=False)
class Mesh:
    """A validated triangle-mesh disk, or with ``allow_holes`` a disk with holes (cut-outs).

    Attributes:
        vertices: ``(V, 3)`` float64 3D positions ``Q``.
        faces: ``(F, 3)`` int64 vertex indices, 0-based.
        name: a label for reports (file stem or built-in name).
        allow_holes: whether boundary loops besides the outer edge are allowed (else :class:`HoledMesh`);
            handles never are.
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "mesh"
    allow_holes: bool = False
    _validated: bool = field(default=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", printable_name(self.name))
        vertices = np.ascontiguousarray(self.vertices, dtype=np.float64)
        faces = np.ascontiguousarray(self.faces)
        object.__setattr__(self, "vertices", vertices)
        _validate(vertices, faces, bool(self.allow_holes))
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
        return unique_edges(self.faces)[0]

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @cached_property
    def rest_lengths(self) -> np.ndarray:
        """``(E,)`` 3D edge lengths ``d_e`` (the springs' rest lengths)."""
        i, j = self.edges.T
        return np.linalg.norm(self.vertices[i] - self.vertices[j], axis=1)

    def layout_lengths(self, positions: np.ndarray) -> np.ndarray:
        """``(E,)`` edge lengths ``L_e`` of a ``(V, 2)`` layout, in :attr:`edges`' order (beside :attr:`rest_lengths`)."""
        i, j = self.edges.T
        return np.linalg.norm(positions[i] - positions[j], axis=1)

    @cached_property
    def face_areas(self) -> np.ndarray:
        """``(F,)`` 3D triangle areas ``A_t``."""
        return triangle_areas_3d(self.vertices, self.faces)

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """Each boundary loop's vertex indices in order, the outer edge first (:func:`outer_loop`), then the
        holes' (none on a disk). Each starts at its smallest vertex index and runs the way its sides run in
        their faces, so the faces are on its left: the outer edge placed counter-clockwise gives a
        consistently wound mesh positive orientation (and each hole's edge runs clockwise)."""
        loops = boundary_loops(self.faces)
        outer = outer_loop(self.vertices, loops)
        return [loops[outer], *loops[:outer], *loops[outer + 1:]]

    @property
    def boundary_loop(self) -> np.ndarray:
        """The outer edge's vertex indices in order (:attr:`boundary_loops`' first)."""
        return self.boundary_loops[0]

    @property
    def n_holes(self) -> int:
        return len(self.boundary_loops) - 1

    @cached_property
    def disk(self) -> "Mesh":
        """This mesh, with any holes closed (:func:`fill_holes`: triangles between each hole's vertices after
        the faces, no vertex added): what a start layout that needs a disk is computed on; its positions are
        this mesh's."""
        if self.n_holes == 0:
            return self
        fill = [hole_triangles(self.vertices, hole) for hole in self.boundary_loops[1:]]
        return Mesh(self.vertices, np.vstack([self.faces, *fill]), name=self.name)

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
        incident = np.bincount(self.faces.ravel(), weights=np.repeat(self.face_areas, 3), minlength=self.n_vertices)
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


#: Candidate side pairs :func:`boundary_crossings` tests at once (bounds its memory, about 100 MB).
_CROSSING_CHUNK = 1 << 20


def boundary_crossings(positions: np.ndarray, loops: np.ndarray | list[np.ndarray]) -> int:
    """How many pairs of sides of the closed polygons ``positions[loop]``, ``loop`` in ``loops``, meet (cross,
    touch or overlap), sides that follow one another not counted: 0 for a simple boundary.

    A fold-free layout of a disk covers no point twice exactly where its boundary is simple (a local
    homeomorphism of a disk onto the plane is one to one when the boundary's image is a simple closed
    curve), so a positive count on a fold-free pattern means flaps lying on each other: a cut pattern
    whose cut line crosses itself. On a disk with holes, a simple loop can still wrap the piece over a hole
    (:func:`turned_holes`); with none turned, the same holds. ``positions`` ``(V, 2)``, ``loops``: one loop
    (:attr:`Mesh.boundary_loop`) ``(n,)``
    or a list of them (:attr:`Mesh.boundary_loops`), which share no vertex. A sweep along the layout's longer
    extent: sides are paired only where their extents overlap on that axis and then on the other;
    orientation tests (float, so sides that all but touch may go either way) decide the rest. A side through
    a corner meets both sides there, and a side of length 0 makes the sides on either side of it meet.
    """
    one_loop = np.ndim(loops) == 1 if isinstance(loops, np.ndarray) else bool(len(loops)) and np.ndim(loops[0]) == 0
    loops = [loops] if one_loop else list(loops)
    starts = np.concatenate([np.asarray(loop, dtype=np.int64) for loop in loops])
    ends = np.concatenate([np.roll(np.asarray(loop, dtype=np.int64), -1) for loop in loops])
    points = np.asarray(positions, dtype=np.float64)
    a, b = points[starts], points[ends]
    n = len(a)
    if n < 4:
        return 0
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    axis = int(np.argmax(hi.max(axis=0) - lo.min(axis=0)))
    order = np.argsort(lo[:, axis], kind="stable")
    lo_sorted = lo[order, axis]
    reach = np.searchsorted(lo_sorted, hi[order, axis], side="right")  # sorted sides starting within mine
    counts = np.maximum(reach - np.arange(1, n + 1), 0)
    crossings, first = 0, 0
    cumulative = np.cumsum(counts)
    while first < n:
        last = int(np.searchsorted(cumulative, (cumulative[first - 1] if first else 0) + _CROSSING_CHUNK,
                                   side="right"))
        last = max(last, first + 1)
        block = counts[first:last]
        i = np.repeat(np.arange(first, last), block)
        j = i + 1 + (np.arange(int(block.sum())) - np.repeat(np.cumsum(block) - block, block))
        i, j = order[i], order[j]
        other = 1 - axis
        near = (lo[i, other] <= hi[j, other]) & (lo[j, other] <= hi[i, other])
        near &= (ends[i] != starts[j]) & (ends[j] != starts[i])  # sides that follow one another share a corner
        i, j = i[near], j[near]
        crossings += int(np.count_nonzero(_sides_meet(a[i], b[i], a[j], b[j])))
        first = last
    return crossings


def overlap_counts(positions: np.ndarray, faces: np.ndarray, loops: list[np.ndarray]) -> tuple[int, int | None]:
    """``(crossings, turned)`` of a fold-free layout ``positions`` ``(V, 2)`` with boundary ``loops``
    (:attr:`Mesh.boundary_loops`): its loops' sides that meet (:func:`boundary_crossings`), and, where none
    do and there are holes, the holes it wraps over (:func:`turned_holes`; ``None`` otherwise). Both 0: the
    layout covers no point twice."""
    crossings = boundary_crossings(positions, loops)
    return crossings, turned_holes(positions, faces, loops) if len(loops) > 1 and crossings == 0 else None


def turned_holes(positions: np.ndarray, faces: np.ndarray, loops: list[np.ndarray]) -> int:
    """How many of ``loops`` (:attr:`Mesh.boundary_loops`) beyond one run the pattern's own way round, on a layout
    whose loops' sides do not meet (:func:`boundary_crossings` 0; elsewhere the count means nothing): 0 where
    the fold-free layout ``positions`` ``(V, 2)`` covers no point twice, else the holes the piece wraps over.

    A fold-free layout covers each point as often as its boundary's loops wind round it, each taken the way
    its sides run in their faces. On a layout that covers no point twice, the covered area is one piece with
    holes: its outer edge runs the pattern's way round and each hole's edge the other way. Conversely, with
    loops that do not meet, one running the pattern's way (+1 inside it) and the others the other way (−1
    inside each), the count is never below 0 only if each of those lies inside the first and outside the
    others: 1 on the piece, 0 in a hole. A further loop run the pattern's way winds +1 round a hole the
    piece wraps over (its corners hold less angle than an open flat hole needs: on top of a bump), which the
    piece covers twice."""
    orientation = layout_orientation(positions, faces)
    points = np.asarray(positions, dtype=np.float64)
    running_its_way = sum(orientation * loop_signed_area(points[loop]) > 0 for loop in loops)
    return max(int(running_its_way) - 1, 0)


def _cross(o: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(p − o) × (q − o)`` row by row."""
    return (p[:, 0] - o[:, 0]) * (q[:, 1] - o[:, 1]) - (p[:, 1] - o[:, 1]) * (q[:, 0] - o[:, 0])


def _sides_meet(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Whether side ``ab`` meets side ``cd``, row by row, for sides whose boxes overlap: each side's ends
    are not strictly on one side of the other's line (collinear sides with overlapping boxes meet)."""
    d1, d2 = _cross(a, b, c), _cross(a, b, d)
    d3, d4 = _cross(c, d, a), _cross(c, d, b)
    return (np.sign(d1) * np.sign(d2) <= 0) & (np.sign(d3) * np.sign(d4) <= 0)


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


def unique_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique sorted edges, the edge index of each face side, and face counts per edge, of any ``(F, 3)`` array of
    non-negative vertex indices (a valid mesh's or not).

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
    _, side_edge, counts = unique_edges(faces)
    return sides[counts[side_edge] == 1]


def _validate(vertices: np.ndarray, faces: np.ndarray, allow_holes: bool = False) -> None:
    """Raise :class:`MeshError` unless the arrays form a single manifold disk (with ``allow_holes``, or a disk
    with holes)."""
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
        v = int(np.flatnonzero(bad)[0])
        raise MeshError(f"vertex {v} has a non-finite coordinate", vertices=(v,))
    magnitude = np.abs(vertices).max(axis=1)
    far = magnitude > COORDINATE_LIMIT
    if far.any():
        v = int(np.flatnonzero(far)[0])
        raise MeshError(f"vertex {v} has a coordinate of magnitude {magnitude[v]:.3g}, outside the supported range "
                        f"|x| <= {COORDINATE_LIMIT:g}", vertices=(v,))
    n = len(vertices)
    out = (faces < 0) | (faces >= n)
    if out.any():
        f = int(np.flatnonzero(out.any(axis=1))[0])
        raise MeshError(
            f"face {f} references vertex {int(faces[f][out[f]][0])}, out of range 0..{n - 1}", faces=(f,))
    faces = faces.astype(np.int64)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    if repeated.any():
        f = int(np.flatnonzero(repeated)[0])
        raise MeshError(f"face {f} repeats a vertex (degenerate triangle)", faces=(f,),
                        defect=MeshDefect.ZERO_AREA_FACE)
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    if (counts > 1).any():
        f = int(first[counts > 1].min())
        raise MeshError(f"face {f} is duplicated (same three vertices appear in another face)", faces=(f,),
                        defect=MeshDefect.DUPLICATE_FACE)
    used = np.zeros(n, dtype=bool)
    used[faces.ravel()] = True
    if not used.all():
        v = int(np.flatnonzero(~used)[0])
        raise MeshError(f"vertex {v} is not used by any face", vertices=(v,), defect=MeshDefect.UNUSED_VERTEX)

    edges, side_edge, counts = unique_edges(faces)
    differences = vertices[edges[:, 0]] - vertices[edges[:, 1]]
    size = float(np.abs(differences).max())  # no squares: cannot underflow
    # the longest edge's length, from the differences scaled by the largest (their squares could underflow)
    longest = size * float(np.linalg.norm(differences / size, axis=1).max()) if size > 0 else 0.0
    if 0 < longest < MIN_MESH_SIZE:  # 0: every face is degenerate, said below
        raise MeshError(f"mesh is too small: its longest edge is {longest:.3g} long, below the supported "
                        f"{MIN_MESH_SIZE:g} (squared lengths and areas would underflow); scale it up")
    areas = triangle_areas_3d(vertices, faces)
    degenerate = areas <= DEGENERATE_RELATIVE_AREA * longest**2
    if degenerate.any():
        f = int(np.flatnonzero(degenerate)[0])
        raise MeshError(f"face {f} is degenerate (zero area)", faces=(f,), defect=MeshDefect.ZERO_AREA_FACE)
    if (counts > 2).any():
        e = edges[np.flatnonzero(counts > 2)[0]]
        raise MeshError(f"mesh is non-manifold: edge ({e[0]}, {e[1]}) is shared by more than two faces",
                        vertices=tuple(e))

    n_parts = count_components(n, edges[:, 0], edges[:, 1])
    if n_parts != 1:
        raise MeshError(f"mesh is not a single disk: it has {n_parts} connected components",
                        defect=MeshDefect.SEVERAL_PIECES)
    _check_vertex_manifold(faces, side_edge, counts, n)
    same_way = _same_way_pairs(faces, side_edge, counts)
    if len(same_way):
        f, g = sorted(same_way[0, :2])
        a, b = edges[same_way[0, 2]]
        raise InconsistentOrientation(f"faces {f} and {g} run through their shared edge ({a}, {b}) the same way: "
                                      "the faces are not wound consistently", faces=(f, g))

    boundary = edges[counts == 1]
    if len(boundary) == 0:
        raise MeshError("mesh is not a disk: it is closed (no boundary loop)")
    on_boundary = np.unique(boundary)
    n_loops = count_components(n, boundary[:, 0], boundary[:, 1]) - (n - len(on_boundary))
    euler = n - len(edges) + len(faces)
    if n_loops != 1:
        message = f"mesh is not a disk: it has {n_loops} boundary loops where a disk has one (holes, or a tube's ends)"
        if euler != 2 - n_loops:  # a disk with holes has 2 - loops; closing them would not leave a disk
            raise MeshError(f"{message}, and handles (Euler characteristic {euler}, expected {2 - n_loops})")
        if not allow_holes:
            raise HoledMesh(message)
    elif euler != 1:
        raise MeshError(f"mesh is not a disk: Euler characteristic {euler} (handles), expected 1")


def _interior_side_pairs(side_edge: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two face sides (``3·face + k``) of every interior edge, in edge order."""
    sides = np.flatnonzero(counts[side_edge] == 2)
    pairs = sides[np.argsort(side_edge[sides], kind="stable")].reshape(-1, 2)
    return pairs[:, 0], pairs[:, 1]


def _interior_sides_run_same_way(faces: np.ndarray, side_edge: np.ndarray,
                                 counts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_interior_side_pairs`, and whether the two faces run their edge from the same vertex: in a
    consistently wound mesh each interior edge is run one way by one face and back by the other."""
    s, t = _interior_side_pairs(side_edge, counts)
    return s, t, faces.reshape(-1)[s] == faces.reshape(-1)[t]  # side k starts at corner k


def _same_way_pairs(faces: np.ndarray, side_edge: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``(face, face, edge)`` rows of the interior edges that both their faces run the same way."""
    s, t, same = _interior_sides_run_same_way(faces, side_edge, counts)
    return np.column_stack([s[same] // 3, t[same] // 3, side_edge[s[same]]])


def orient_consistently(faces: np.ndarray) -> tuple[np.ndarray, int]:
    """``faces`` with the fewest faces turned (two corners swapped) so that every interior edge is run both
    ways, and how many were turned. ``faces`` must form a connected manifold; a non-orientable one (a Möbius
    strip) raises :class:`MeshError`."""
    faces = np.asarray(faces, dtype=np.int64)
    _, side_edge, counts = unique_edges(faces)
    s, t, same = _interior_sides_run_same_way(faces, side_edge, counts)
    m = len(faces)
    root, turn = parity_roots(m, s // 3, t // 3, same)
    if (root != 0).any():
        f = int(np.flatnonzero(root != 0)[0])
        raise MeshError(f"mesh is not a single disk: face {f} shares no edge with face 0", faces=(f,))
    if 2 * turn.sum() > m:  # turn the fewer faces
        turn = ~turn
    result = faces.copy()
    result[turn] = result[turn][:, [0, 2, 1]]
    if len(_same_way_pairs(result, *unique_edges(result)[1:])):  # a turned face's sides are other edges
        raise MeshError("mesh is not orientable (like a Möbius strip): its faces cannot all be wound the same way")
    return result, int(turn.sum())


def oriented_mesh(vertices: np.ndarray, faces: np.ndarray, name: str = "mesh",
                  holes: Holes = Holes.REFUSE) -> tuple[Mesh, list[str]]:
    """A :class:`Mesh` of ``vertices`` and ``faces``, the faces first wound consistently if they are not
    (:func:`orient_consistently`), and its holes refused, closed (:func:`fill_holes`) or kept as ``holes``
    says; the notes say how many faces were turned and what was filled or kept. Any other problem raises
    :class:`MeshError` as ``Mesh`` does."""
    notes: list[str] = []
    turned = filled = False
    while True:
        try:
            mesh = Mesh(vertices, faces, name=name, allow_holes=holes is Holes.KEEP)
            if mesh.n_holes:
                notes.append(kept_holes_note(mesh))
            return mesh, notes
        except InconsistentOrientation:
            if turned:
                raise
            faces, count = orient_consistently(faces)
            turned = True
            plural = "s" if count != 1 else ""
            guess = ("; so nearly half face each way that which side is the front, the side the pattern shows, is a "
                     "guess: if it comes out mirrored, wind the faces the other way round" if count >= 0.4 * len(faces)
                     else "")
            notes.append(f"{count} face{plural} wound against {'their' if plural else 'its'} neighbours: turned to "
                         f"agree with the other {len(faces) - count} (the pattern's faces keep the turned winding){guess}")
        except HoledMesh:
            if holes is not Holes.FILL or filled:
                raise
            vertices, faces, note = fill_holes(vertices, faces)
            filled = True
            notes.append(note)
        except MeshError as exc:
            if filled:  # (a face or a count that is the fill's, not the file's; the fill appends its faces)
                raise MeshError(f"{exc}, with the holes closed", faces=exc.faces, vertices=exc.vertices,
                                defect=exc.defect) from None
            raise


def fill_holes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """``(vertices, faces, note)`` with every boundary loop but the outer edge closed by triangles between its
    own vertices (:func:`hole_triangles`), which come after the mesh's faces, wound as the mesh's (each hole
    side run back the other way). ``faces`` must be a consistently wound manifold (as :class:`Mesh` checks
    before it raises :class:`HoledMesh`). No vertex is added. The outer edge is :func:`outer_loop`'s. For a
    scan's holes, which are no part of the piece; a cut-out the piece must keep is not a hole to
    fill (the note says when the holes are more than :data:`LARGE_FILL` of the piece's area). A mesh with one
    loop is returned as it is, with no note."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    loops = boundary_loops(faces)
    if len(loops) < 2:
        return vertices, faces, ""
    outer = outer_loop(vertices, loops)
    holes = [loop for k, loop in enumerate(loops) if k != outer]
    fill = np.vstack([hole_triangles(vertices, loop) for loop in holes])
    lengths = np.array([loop_length(vertices[loop]) for loop in loops])
    share = triangle_areas_3d(vertices, fill).sum() / triangle_areas_3d(vertices, faces).sum()
    plural = "s" if len(holes) != 1 else ""
    note = (f"{len(holes)} hole{plural} closed by {len(fill)} triangle{'s' if len(fill) != 1 else ''} "
            f"({_edges_text(np.delete(lengths, outer), lengths[outer])}): the pattern covers "
            f"{'them' if plural else 'it'}")
    if share > LARGE_FILL:
        note += (f"; {'they are' if plural else 'it is'} {share:.0%} of the piece's area: a cut-out the piece must "
                 "keep is no hole to fill")
    return vertices, np.vstack([faces, fill]), note


#: The share of a piece's area past which the note on filled holes says they may be cut-outs.
LARGE_FILL = 0.1


def outer_loop(vertices: np.ndarray, loops: list[np.ndarray]) -> int:
    """Which of ``loops`` (:func:`boundary_loops`) is the piece's outer edge: the loop whose corners lie
    farthest apart (its box's diagonal). The piece's edge reaches round all of it, a hole only round its own
    part; neither a loop's length (a comb-shaped hole) nor its vector area (a sheet rolled nearly closed)
    says that."""
    return int(np.argmax([np.linalg.norm(np.ptp(vertices[loop], axis=0)) for loop in loops]))


def kept_holes_note(mesh: Mesh) -> str:
    """The note on a mesh whose holes are kept as cut-outs: how many, their edges' lengths."""
    lengths = np.array([loop_length(mesh.vertices[loop]) for loop in mesh.boundary_loops])
    holes = len(lengths) - 1
    plural = "s" if holes != 1 else ""
    return (f"{holes} hole{plural} kept as cut-out{plural} ({_edges_text(lengths[1:], lengths[0])}); a "
            f"computed start layout closes {'them' if plural else 'it'} first")


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Each boundary loop's vertices in order, walked the way its sides run in their faces. ``faces`` must be a
    consistently wound manifold (each boundary vertex starts one boundary side): :class:`MeshError` else."""
    sides = _directed_boundary_edges(np.asarray(faces, dtype=np.int64))
    following = dict(zip(sides[:, 0].tolist(), sides[:, 1].tolist()))
    if len(following) != len(sides) or set(following.values()) != set(following):
        raise MeshError("the boundary's sides do not make loops: the mesh is not a consistently wound manifold")
    loops, seen = [], set()
    for start in sorted(following):
        if start in seen:
            continue
        loop = [start]
        while following[loop[-1]] != start:
            loop.append(following[loop[-1]])
        seen.update(loop)
        loops.append(np.array(loop, dtype=np.int64))
    return loops


def hole_triangles(vertices: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """``(k - 2, 3)`` triangles between the ``k`` vertices of the hole whose edge runs ``loop`` (the way its
    sides run in their faces), wound as the mesh's faces (each side of the loop run back): ear clipping of the
    loop seen along its vector area's normal (``Σ vᵢ × vᵢ₊₁``: a saddle-shaped hole's edge is simple from
    there), each ear a corner that turns the loop's way and holds no other corner, so that a C- or L-shaped
    hole is covered once; the search goes on round the loop from each ear it clips, so the triangles do not all
    meet at one corner. :class:`MeshError` for a hole that encloses no area (a crack, a T-junction's slit) or
    where no ear is left (its edge crosses itself, seen along that normal; one that crosses itself may also be
    filled with a triangle turned over, which the run then counts as folded)."""
    polygon = np.asarray(loop, dtype=np.int64)[::-1]  # the fill runs each hole side the other way
    points = vertices[polygon] - vertices[polygon].mean(axis=0)
    normal = np.cross(points, np.roll(points, -1, axis=0)).sum(axis=0)
    size = float(np.ptp(points, axis=0).max())
    where = f"the hole whose edge runs through vertices {int(polygon[0])}, {int(polygon[1])}, {int(polygon[2])}"
    if np.linalg.norm(normal) <= 1e-9 * size**2:
        raise MeshError(f"{where}, ... cannot be filled: it encloses no area (a crack or a T-junction's slit)")
    u = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    u /= np.linalg.norm(u)
    v = np.cross(normal / np.linalg.norm(normal), u)
    flat = points @ np.column_stack([u, v])  # the loop turns counter-clockwise, seen along the normal
    turn = np.sign(loop_signed_area(flat))
    tolerance = 1e-12 * size**2
    alive = list(range(len(polygon)))
    triangles = []
    k = 0
    while len(alive) > 3:
        for step in range(len(alive)):
            k = (k + 1) % len(alive) if step else k % len(alive)
            a, b, c = alive[k - 1], alive[k], alive[(k + 1) % len(alive)]
            if turn * _cross(flat[[a]], flat[[b]], flat[[c]])[0] <= tolerance:  # turns the other way, or not
                continue
            others = flat[[r for r in alive if r not in (a, b, c)]]
            inside = np.all([turn * _cross(flat[[p]], flat[[q]], others) >= -tolerance
                             for p, q in ((a, b), (b, c), (c, a))], axis=0)
            if not inside.any():
                triangles.append(polygon[[a, b, c]])
                del alive[k]
                k += 1  # the next search starts past c, whose ear would share a with this one
                break
        else:
            raise MeshError(f"{where}, ... cannot be filled: its edge crosses itself, seen across the hole")
    triangles.append(polygon[alive])
    return np.array(triangles, dtype=np.int64)


def loop_length(points: np.ndarray) -> float:
    """The length of the closed polygon ``points`` (its last corner joined to its first)."""
    return float(np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1).sum())


def loop_signed_area(points: np.ndarray) -> float:
    """The signed area of the closed 2D polygon ``points`` ``(n, 2)``: positive when it runs counter-clockwise."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _edges_text(hole_edges: np.ndarray, outer_edge: float) -> str:
    """``edges 3.1 to 4.2 long, the piece's outer edge 40, in the mesh's units``: the holes' edges' lengths."""
    low, high = hole_edges.min(), hole_edges.max()
    lengths = f"{low:.4g}" if low == high else f"{low:.4g} to {high:.4g}"
    return (f"edge{'s' if len(hole_edges) != 1 else ''} {lengths} long, the piece's outer edge {outer_edge:.4g}, in "
            "the mesh's units")


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
    s, t = _interior_side_pairs(side_edge, counts)
    v_s_from = faces.reshape(-1)[side_from[s]]
    # Match corners of the same vertex on both sides of the shared edge.
    same = v_s_from == faces.reshape(-1)[side_from[t]]
    a = np.concatenate([side_from[s], side_to[s]])
    b = np.concatenate([np.where(same, side_from[t], side_to[t]), np.where(same, side_to[t], side_from[t])])
    m = 3 * n_faces
    label = component_labels(m, a, b)
    corner_vertex = faces.reshape(-1)
    fans = np.unique(corner_vertex * m + label)  # one key per (vertex, fan)
    fans_per_vertex = np.bincount(fans // m, minlength=n)
    if (fans_per_vertex > 1).any():
        v = int(np.flatnonzero(fans_per_vertex > 1)[0])
        raise MeshError(f"mesh is non-manifold at vertex {v} (its triangles form more than one fan: a pinch, or "
                        "holes or the outer edge meeting at a corner)", vertices=(v,))
