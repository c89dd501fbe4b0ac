"""Wavefront OBJ reader: the polygonal part, vertex numbering kept."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from golden_model.files import read_file_bytes
from golden_model.mesh import MeshDefect, MeshError, one_line
from .polygons import Polygons, first_unplain, is_int, plural, text_coordinates, triangulate_polygons

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
        faces: ``(F, 3)`` int64, 0-based; polygons already triangulated (:func:`triangulate_polygons`).
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
    if data is None:
        data = read_file_bytes(path, "mesh", MeshError)  # (before Path(), which drops a trailing '/')
    path = Path(path)
    where = f"cannot parse mesh '{path}'"
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
            raise MeshError(f"{where}: line {line_of(i)}: free-form geometry ({_quoted(key)}) is not supported")
        elif key in OBJ_HARMLESS:
            if key in groups:
                groups[key] += 1
        elif key in OBJ_IGNORED:
            ignored[key] = ignored.get(key, 0) + 1
        else:
            unknown.setdefault(key, [0, i])[0] += 1

    vertex_line = line_of(np.asarray(vertex_at, dtype=np.int64))
    face_line = line_of(np.asarray(face_at, dtype=np.int64))
    vertices = text_coordinates(coords, vertex_line, where)
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

    polygons = Polygons(index, sizes, lambda f: f"line {lines[f]}")
    faces, triangle_face, notes = triangulate_polygons(vertices, polygons, where)
    triangle_line = lines[triangle_face]
    if len(sizes) == 0 and ignored.keys() & {"l", "p"}:
        raise MeshError(f"{where}: no faces ('f'), only line ('l') or point ('p') elements")
    for key, count in ignored.items():
        notes.append(f"ignored {plural(count, *OBJ_IGNORED[key])}")
    if unknown:
        total = plural(sum(count for count, _ in unknown.values()), "unknown statement")
        listed = [f"{_quoted(key)} ({count}, first at line {line_of(first)})" for key, (count, first) in unknown.items()]
        notes.append(f"ignored {total}: {', '.join(listed[:5])}{', ...' if len(listed) > 5 else ''}")
    if extra_values:
        v_lines = plural(extra_values, "'v' line")
        notes.append(f"ignored the extra values (weight w or colour r g b) of {v_lines}")
    if groups["o"] > 1 or groups["g"] > 1:
        parts = [plural(groups["o"], "'o' object"), plural(groups["g"], "'g' group")]
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
    return text_coordinates(coords, lines, where)



def _obj_corner_slots(
    corners: list[str], corner_line: np.ndarray, where: str
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The vertex, texture and normal index of each face corner, and whether each is written."""
    fast = _obj_uniform_corners(corners) if first_unplain(corners) is None else None
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
            if first_unplain(strings) is not None:
                raise ValueError
            slots.append(np.fromiter(map(int, strings), dtype=np.int64, count=len(strings)))
        except ValueError:
            c = next(c for c, text in enumerate(strings) if not is_int(text))
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
            count, verb = plural(int(before[c]), what, words), "precedes" if before[c] == 1 else "precede"
            raise MeshError(line + f"face refers to {what} {raw[c]} but only {count} {verb} it")
        raise MeshError(line + f"face refers to {what} {raw[c]} but the file has only {plural(total, what, words)}")
    return resolved


def obj_line_hint(exc: MeshError, obj: ObjContents) -> str:
    """Where in the file the faces and vertices a validation refusal names are (it numbers them from 0, after
    fan triangulation): `` (file line n)`` for the one the message starts with, `` (vertex 4: file line 5)``
    for one it names later, `` (its vertices: file lines 28 and 29)`` for an edge, `` (file lines 7 and 9)`` for
    two faces, and each piece's first face line for a file of several pieces."""
    if exc.defect is MeshDefect.SEVERAL_PIECES:
        return _pieces_hint(obj)
    faces = [int(obj.face_line[f]) for f in exc.faces if f < len(obj.face_line)]
    vertices = [int(obj.vertex_line[v]) for v in exc.vertices if v < len(obj.vertex_line)]
    if len(exc.faces) == 2:
        return f" (file lines {faces[0]} and {faces[1]})" if len(faces) == 2 else ""
    if len(exc.vertices) == 2:
        return f" (its vertices: file lines {vertices[0]} and {vertices[1]})" if len(vertices) == 2 else ""
    named = [("face", exc.faces, faces), ("vertex", exc.vertices, vertices)]
    for kind, numbers, lines in named:
        if len(numbers) == 1 and lines:
            first = str(exc).startswith(f"{kind} {numbers[0]} ")
            return f" (file line {lines[0]})" if first else f" ({kind} {numbers[0]}: file line {lines[0]})"
    return ""


def _pieces_hint(obj: ObjContents) -> str:
    """`` (its pieces' faces start at file lines 10, 145: ...)``: where each piece of a file of several begins,
    the pieces found as the faces joined through their shared vertices."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = obj.faces
    n = len(obj.vertices)
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    graph = coo_matrix((np.ones(len(rows)), (rows, np.concatenate([faces[:, 1], faces[:, 2]]))), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    _, first = np.unique(label[faces[:, 0]], return_index=True)  # each piece's first face
    starts = sorted(int(line) for line in obj.face_line[first])
    shown = ", ".join(map(str, starts[:5])) + (", ..." if len(starts) > 5 else "")
    return f" (its pieces' faces start at file lines {shown}: flatten each from a file of its own)"


def _quoted(keyword: str, limit: int = 20) -> str:
    """A statement's keyword from the file, quoted for a note: control characters escaped (an escape
    sequence would colour the terminal), shortened."""
    return "'" + one_line(keyword if len(keyword) <= limit else keyword[:limit] + "…") + "'"
