"""Vertices that lie on one another with no edge between them: a seam an exporter left open.

Exporters split a vertex where its texture coordinates or normals differ (a UV seam), so one surface comes
as pieces that only touch. Read as it is, such a seam is a cut in the mesh: a seam from the edge inwards is a
slit the pattern opens, an inner one a hole, and a face-by-face file a heap of triangles. Nothing is joined
here (where two copies of a point belong together is the user's call); the reader says where it found them.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from golden_model.mesh import COORDINATE_LIMIT, unique_edges

__all__ = ["SEAM_TOLERANCE", "open_seams", "seams_note", "seams_hint"]

#: Two vertices closer than this share of the median edge length lie on one another: far below any edge of a
#: mesh worth flattening, above a float32 file's rounding of one point written twice.
SEAM_TOLERANCE = 1e-4
#: The nearest other boundary vertices each is paired with: more copies of one point than a corner has faces
#: (a face-by-face file writes a point once per face round it) are rare.
SEAM_NEIGHBOURS = 8


def open_seams(vertices: np.ndarray, faces: np.ndarray) -> tuple[int, int]:
    """``(vertices, places)``: how many boundary vertices lie on another boundary vertex (within
    :data:`SEAM_TOLERANCE` of the median edge length) with no edge between them, in how many places. Both copies
    of a point an open seam splits are on the boundary, so interior vertices close together (the corners of two
    slivers) are not looked at. Each vertex is paired with its :data:`SEAM_NEIGHBOURS` nearest others, so a heap
    of copies of one point (a depth camera's invalid pixels at the origin) costs no more than a seam, and the
    copies of a point a face-by-face file wrote with noise are one place, not a pair of nearest ones each."""
    faces = np.asarray(faces)
    vertices = np.asarray(vertices)
    if (faces.dtype.kind not in "iu" or faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0
            or vertices.ndim != 2 or vertices.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices)):
        return 0, 0  # (no mesh to look at: its refusal says why)
    faces = faces.astype(np.int64)
    n = len(vertices)
    edges, _, counts = unique_edges(faces)
    keys = edges[:, 0] * n + edges[:, 1]
    boundary = np.unique(edges[counts == 1])
    points = vertices[boundary].astype(np.float64)
    if len(boundary) < 2 or not np.isfinite(points).all() or np.abs(points).max() > COORDINATE_LIMIT:
        return 0, 0  # (refused for its coordinates: no distances to measure)
    ends = vertices[edges[:, 0]].astype(np.float64) - vertices[edges[:, 1]]
    length = float(np.median(np.linalg.norm(ends, axis=1)))
    if not length > 0:
        return 0, 0
    k = min(SEAM_NEIGHBOURS + 1, len(points))
    distance, nearest = cKDTree(points).query(points, k=k)
    # each point's own entry is not always the first: a copy at distance 0 may come before it
    close = ((distance <= SEAM_TOLERANCE * length) & (nearest < len(points))
             & (nearest != np.arange(len(points))[:, None]))
    a = np.repeat(boundary, k).reshape(-1, k)[close]
    b = boundary[nearest[close]]
    unjoined = ~np.isin(np.minimum(a, b) * n + np.maximum(a, b), keys)
    a, b = a[unjoined], b[unjoined]
    if len(a) == 0:
        return 0, 0
    involved = np.unique(np.concatenate([a, b]))
    index = np.searchsorted(involved, np.concatenate([a, b]))
    graph = coo_matrix((np.ones(len(a)), (index[: len(a)], index[len(a):])), shape=(len(involved),) * 2)
    return len(involved), int(connected_components(graph, directed=False)[0])


#: How to join the copies of a point, which springflat leaves to the user (where they belong together is theirs
#: to say).
WELD = "weld them first (trimesh's merge_vertices, MeshLab's Merge Close Vertices)"


def _what(count: int, places: int) -> str:
    return (f"{count} vertices lie on one another in {places} place{'s' if places != 1 else ''} with no edge "
            "between them")


def seams_note(vertices: np.ndarray, faces: np.ndarray) -> str | None:
    """The reader's note on a valid mesh with open seams (:func:`open_seams`), or ``None``."""
    count, places = open_seams(vertices, faces)
    if not count:
        return None
    return (f"{_what(count, places)}: the surface is cut there (an exporter's seam, where texture coordinates or "
            f"normals differ, leaves it so), and so is the pattern; if it is one piece there, {WELD}")


def seams_hint(vertices: np.ndarray, faces: np.ndarray) -> str:
    """What a refusal adds where the mesh has open seams: ``"; <what>: ..."``, or ``""``."""
    count, places = open_seams(vertices, faces)
    if not count:
        return ""
    return f"; {_what(count, places)} (an exporter's seam?): {WELD}, and it may be one disk"
