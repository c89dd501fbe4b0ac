"""Faces as the PLY, OFF and OBJ readers find them, and their triangulation (fans, ear clipping where a fan
would fold); shared text helpers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from golden_model.mesh import COORDINATE_LIMIT, MeshError, boundary_crossings, hole_triangles

#: The byte-order mark a text editor may put before a UTF-8 file's text (OBJ, OFF, a text STL, a PLY header).
UTF8_BOM = b"\xef\xbb\xbf"

#: Largest magnitude a face index read from a text file may have; far beyond any vertex count, and
#: exactly representable in float64 (PLY ASCII numbers are read as floats), so a larger index is
#: refused as out of range instead of wrapping in the conversion to int64.
INDEX_LIMIT = 1 << 53


@dataclass(frozen=True)
class Polygons:
    """Faces as read: the corners of all faces in a row, each face's corner count, and how to name face f."""

    index: np.ndarray
    sizes: np.ndarray
    label: object  # callable: face number -> "line 12" / "face 3"


def triangulate_polygons(
    vertices: np.ndarray, polygons: Polygons, where: str
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Triangles of the faces (fans for polygons; a polygon's corner written twice in a row, as some exporters
    write a triangle as a quad, once), the face of each triangle, and the notes on polygons."""
    polygons, notes = _repeats_dropped(polygons, where)
    sizes = polygons.sizes
    if (sizes == 3).all():
        return polygons.index.reshape(-1, 3), np.arange(len(sizes)), notes
    faces, triangle_face = fan_triangulate(polygons.index, sizes)
    other = np.zeros(0, dtype=np.int64)
    if np.isfinite(vertices).all() and np.abs(vertices).max(initial=0.0) <= COORDINATE_LIMIT:
        poor = np.union1d(poor_fans(vertices, faces, triangle_face, sizes), np.flatnonzero(sizes > MAX_FAN_CORNERS))
        # a quad whose fan does not fold is simple; a polygon of more corners, or one to triangulate otherwise,
        # may cross itself and still have ears (a pentagram's) or a fan that does not fold
        suspect = np.union1d(poor, np.flatnonzero(sizes > 4))
        if len(crossing := crossing_polygons(vertices, polygons, suspect)):
            raise _no_surface(polygons, int(crossing[0]), where)
        clipped = refan(vertices, polygons, poor, faces)
        ear_clip(vertices, polygons, clipped, faces, triangle_face, where)
        other = poor
    # else the validation refuses the coordinates, with the right message, before anything uses the fans
    many = sizes > 3
    low, high = int(sizes[many].min()), int(sizes[many].max())
    polygon_count = plural(int(many.sum()), "polygon")
    triangle_count = plural(int((sizes[many] - 2).sum()), "triangle")
    span = f"{low}" if low == high else f"{low} to {high}"
    if not len(other):
        return faces, triangle_face, [*notes, f"{polygon_count} ({span} corners) fan-triangulated into {triangle_count}"]
    how = (", not as fans from the first corner" if len(other) == many.sum() else
           f" as fans from the first corner, {len(other)} otherwise")
    return faces, triangle_face, [*notes,
        f"{polygon_count} ({span} corners) triangulated into {triangle_count}{how} "
        f"({'first ' if len(other) > 1 else ''}{polygons.label(int(other[0]))}): that fan would fold, have a sliver or "
        "give its corner too many neighbours"]


#: A fan triangle under this share of its polygon's area is a sliver (a corner on a nearly straight side, as CAD
#: exporters leave them): the fan from a better corner is taken.
SLIVER_SHARE = 1e-3
#: Polygons of more corners are ear-clipped: a fan's first corner would have one neighbour for each (a 40-gon's,
#: 39: more than the datapath accumulates).
MAX_FAN_CORNERS = 8


def poor_fans(vertices: np.ndarray, faces: np.ndarray, triangle_face: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """The polygons whose fan from corner 0 has a triangle facing against the polygon (a reflex corner, seen
    from corner 0) or a sliver (:data:`SLIVER_SHARE`: a corner on a straight or nearly straight side)."""
    polygon = sizes[triangle_face] > 3
    if not polygon.any():
        return np.zeros(0, dtype=np.int64)
    a, b, c = (vertices[faces[polygon, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    # Newell normal of each polygon = the sum of its fan triangles' normals (exact for any fan)
    owner = triangle_face[polygon]
    newell = np.column_stack([np.bincount(owner, weights=normal[:, d], minlength=len(sizes)) for d in range(3)])
    facing = np.einsum("ij,ij->i", normal, newell[owner])  # twice the triangle's area times twice the polygon's
    return np.unique(owner[~(facing > SLIVER_SHARE * np.einsum("ij,ij->i", newell, newell)[owner])])


def refan(vertices: np.ndarray, polygons: Polygons, which: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The polygons ``which`` of up to :data:`MAX_FAN_CORNERS` corners fanned from the corner whose fan's
    smallest triangle is largest, where that one has no sliver (in ``faces``, in place); the rest, to be
    ear-clipped. Vectorised over the polygons of each corner count."""
    first = np.concatenate([[0], np.cumsum(polygons.sizes)[:-1]])
    triangles = np.concatenate([[0], np.cumsum(polygons.sizes - 2)[:-1]])
    rest = [which[polygons.sizes[which] > MAX_FAN_CORNERS]]
    for k in np.unique(polygons.sizes[which]):
        if k > MAX_FAN_CORNERS:
            continue
        group = which[polygons.sizes[which] == k]
        corners = polygons.index[first[group][:, None] + np.arange(k)]  # (m, k)
        points = vertices[corners]
        points = points - points.mean(axis=1, keepdims=True)  # (a mesh far from the origin: no cancellation)
        newell = np.cross(points, np.roll(points, -1, axis=1)).sum(axis=1)  # (m, 3): twice the vector area
        start = np.arange(k)[:, None]
        apex, b, c = start, (start + np.arange(1, k - 1)) % k, (start + np.arange(2, k)) % k  # (k, k - 2)
        double = np.cross(points[:, b] - points[:, apex], points[:, c] - points[:, apex])  # (m, k, k - 2, 3)
        smallest = np.einsum("mskd,md->msk", double, newell).min(axis=2)  # (m, k)
        best = smallest.argmax(axis=1)  # (the first of equals)
        good = smallest[np.arange(len(group)), best] > SLIVER_SHARE * np.einsum("md,md->m", newell, newell)
        for f, s, row in zip(group[good], best[good], corners[good]):
            faces[triangles[f]:triangles[f] + k - 2] = np.column_stack([np.full(k - 2, row[s]), row[b[s]], row[c[s]]])
        rest.append(group[~good])
    return np.sort(np.concatenate(rest))


def _repeats_dropped(polygons: Polygons, where: str) -> tuple[Polygons, list[str]]:
    """``polygons`` with each polygon's corner that repeats the one before it (the last repeating the first
    counts) written once, and a note; a triangle that repeats a corner is left to the validation's refusal (it
    is no polygon), a polygon left with fewer than 3 corners is refused."""
    index, sizes = polygons.index, polygons.sizes
    if not (sizes > 3).any():
        return polygons, []
    owner = np.repeat(np.arange(len(sizes)), sizes)
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    following = np.arange(len(index)) + 1
    following[first + sizes - 1] = first  # (the last corner is followed by the first)
    drop = (index == index[following]) & (sizes[owner] > 3)
    if not drop.any():
        return polygons, []
    left = sizes - np.bincount(owner[drop], minlength=len(sizes))
    if (short := left < 3).any():
        f = int(np.flatnonzero(short)[0])
        raise MeshError(f"{where}: {polygons.label(f)}: face with {plural(int(left[f]), 'distinct corner')} (a face "
                        "needs at least 3)")
    repeated = np.unique(owner[drop])
    note = (f"{plural(len(repeated), 'polygon')} wrote a corner twice in a row ({'first ' if len(repeated) > 1 else ''}"
            f"{polygons.label(int(repeated[0]))}), read once")
    return Polygons(index[~drop], left, polygons.label), [note]


def checked_polygons(index: np.ndarray, sizes: np.ndarray, n_vertices: int, label, where: str) -> Polygons:
    """Refuse faces with fewer than 3 corners or a corner outside the vertices (PLY, OFF: 0-based)."""
    short = sizes < 3
    if short.any():
        f = int(np.flatnonzero(short)[0])
        raise MeshError(f"{where}: {label(f)}: face with {plural(int(sizes[f]), 'corner')} (a face needs at least 3)")
    out = (index < 0) | (index >= n_vertices)
    if out.any():
        c = int(np.flatnonzero(out)[0])
        f = int(np.searchsorted(np.cumsum(sizes), c, side="right"))
        raise MeshError(f"{where}: {label(f)}: face refers to vertex {int(index[c])}, outside 0..{n_vertices - 1}")
    return Polygons(index.astype(np.int64), sizes.astype(np.int64), label)


def fan_triangulate(index: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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


def ear_clip(vertices: np.ndarray, polygons: Polygons, which: np.ndarray, faces: np.ndarray,
             triangle_face: np.ndarray, where: str) -> None:
    """The triangles of the polygons ``which`` in ``faces`` replaced by the polygon's ear clipping, wound as
    the polygon runs (:func:`golden_model.mesh.hole_triangles`, which fills a hole's loop run the other way);
    one where no ear is left is refused (the caller refuses those that cross themselves first)."""
    first = np.concatenate([[0], np.cumsum(polygons.sizes)[:-1]])
    triangles = np.concatenate([[0], np.cumsum(polygons.sizes - 2)[:-1]])  # (a polygon's fan is k - 2 in a row)
    for f in which:
        size = int(polygons.sizes[f])
        corners = polygons.index[first[f]:first[f] + size]
        try:
            faces[triangles[f]:triangles[f] + size - 2] = hole_triangles(vertices, corners[::-1])
        except MeshError:
            raise _no_surface(polygons, int(f), where) from None


def _no_surface(polygons: Polygons, f: int, where: str) -> MeshError:
    return MeshError(f"{where}: {polygons.label(f)}: polygon with {polygons.sizes[f]} corners cannot be triangulated: "
                     "its edge crosses itself or encloses no area, seen across it")


def crossing_polygons(vertices: np.ndarray, polygons: Polygons, which: np.ndarray) -> np.ndarray:
    """Those of the polygons ``which`` that, seen along their Newell normal, enclose no area or have two sides
    that are not neighbours meet (:func:`golden_model.mesh.boundary_crossings`, one call for all: each polygon
    laid flat in a place of its own): no triangulation of theirs is a piece of surface."""
    first = np.concatenate([[0], np.cumsum(polygons.sizes)[:-1]])
    flat_of, no_area = {}, []
    for k in np.unique(polygons.sizes[which]):
        group = which[polygons.sizes[which] == k]
        points = vertices[polygons.index[first[group][:, None] + np.arange(k)]]  # (m, k, 3)
        centred = points - points.mean(axis=1, keepdims=True)
        normal = np.cross(centred, np.roll(centred, -1, axis=1)).sum(axis=1)
        size = np.ptp(centred, axis=1).max(axis=1)
        flat_ones = ~(np.linalg.norm(normal, axis=1) > 1e-9 * size**2)
        normal[flat_ones] = [0.0, 0.0, 1.0]
        u = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal), axis=1)])
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        v = np.cross(normal / np.linalg.norm(normal, axis=1, keepdims=True), u)
        flat = np.stack([np.einsum("mkd,md->mk", centred, u), np.einsum("mkd,md->mk", centred, v)], axis=2)
        flat_of.update(zip(group.tolist(), flat / np.where(size > 0, size, 1.0)[:, None, None]))  # (within ±1)
        no_area.append(group[flat_ones])
    if not flat_of:
        return np.zeros(0, dtype=np.int64)
    order = sorted(flat_of)
    points = np.concatenate([flat_of[f] + [4.0 * place, 0.0] for place, f in enumerate(order)])
    ends = np.cumsum([len(flat_of[f]) for f in order])
    loops = [np.arange(end - len(flat_of[f]), end) for f, end in zip(order, ends)]
    crossing = [] if not boundary_crossings(points, loops) else \
        [f for f in order if boundary_crossings(flat_of[f], np.arange(len(flat_of[f])))]
    return np.union1d(np.concatenate(no_area), np.asarray(crossing, dtype=np.int64)).astype(np.int64)


def plural(n: int, word: str, words: str | None = None) -> str:
    """``1 polygon``, ``2 polygons``; ``words`` for an irregular plural."""
    return f"{n} {word}" if n == 1 else f"{n} {words or word + 's'}"


def is_plain(text: str | bytes) -> bool:
    """Whether ``text`` holds only what a number in a mesh file is written with: ASCII, and no ``_``.
    Python's ``float`` and ``int`` also read digit separators (``1_0`` is 10) and any script's digits
    (``٣`` is 3), which no mesh format writes: taken silently, they would be other numbers than meant."""
    return text.isascii() and (b"_" if isinstance(text, bytes) else "_") not in text


def first_unplain(tokens) -> int | None:
    """The index of the first of ``tokens`` (str or bytes) that is not :func:`is_plain`, or None (one join
    and two scans where all are plain: files are large)."""
    if not len(tokens):
        return None
    if is_plain((b"" if isinstance(tokens[0], bytes) else "").join(tokens)):
        return None
    return next(k for k, token in enumerate(tokens) if not is_plain(token))


def is_float(text: str) -> bool:
    """Whether ``text`` is a number as a mesh file writes one (:func:`is_plain`, and ``float`` reads it)."""
    try:
        float(text)
    except ValueError:
        return False
    return is_plain(text)


def is_int(text: str) -> bool:
    """Whether ``text`` is an integer as a mesh file writes one (:func:`is_plain`, and ``int`` reads it)."""
    try:
        int(text)
    except ValueError:
        return False
    return is_plain(text)


def text_coordinates(coords: list[str], vertex_line: np.ndarray, where: str) -> np.ndarray:
    """``(V, 3)`` floats from the flat x, y, z strings; a token that is no number is refused with its line."""
    try:
        if first_unplain(coords) is not None:
            raise ValueError
        return np.fromiter(map(float, coords), dtype=np.float64, count=len(coords)).reshape(-1, 3)
    except ValueError:
        k = next(k for k, value in enumerate(coords) if not is_float(value))
        raise MeshError(
            f"{where}: line {vertex_line[k // 3]}: vertex coordinate {coords[k]!r} is not a number"
        ) from None
