"""Loading a mesh file of any supported format, and writing OBJ."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Callable

import numpy as np

from golden_model.files import read_file_bytes
from golden_model.mesh import HoledMesh, Holes, Mesh, MeshDefect, MeshError, oriented_mesh
from .obj import obj_line_hint, read_obj
from .off import read_off
from .ply import read_ply
from .polygons import UTF8_BOM, first_unplain, is_float, triangulate_polygons
from .seams import seams_hint

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")

#: What a scan's harmless defects need: the tools that remove them.
_REPAIRS = {MeshDefect.UNUSED_VERTEX: ("the unused vertices", "remove_unreferenced_vertices()",
                                       "Remove Unreferenced Vertices"),
            MeshDefect.DUPLICATE_FACE: ("the duplicate faces", "update_faces(unique_faces())", "Remove Duplicate Faces"),
            MeshDefect.ZERO_AREA_FACE: ("the faces of zero area", "update_faces(nondegenerate_faces())",
                                        "Remove Zero Area Faces")}


def repair_hint(exc: MeshError) -> str:
    """``"; remove <what> (trimesh's ..., MeshLab's ...)"`` for a refusal of a defect a scan often has and a
    mesh tool removes at once (an unused vertex, a duplicate or zero-area face), else ``""``."""
    if exc.defect not in _REPAIRS:
        return ""
    what, trimesh_call, meshlab_filter = _REPAIRS[exc.defect]
    return f"; remove {what} first (trimesh's {trimesh_call}, MeshLab's {meshlab_filter})"


def load_mesh(path: str | Path) -> Mesh:
    """Load and validate an OBJ, PLY, OFF or STL triangle mesh.

    The same as :func:`load_mesh_with_notes` without the notes.
    """
    return load_mesh_with_notes(path)[0]


def load_mesh_with_notes(path: str | Path, holes: Holes = Holes.REFUSE) -> tuple[Mesh, list[str]]:
    """Load and validate a mesh file; also return one-line notes on what was changed or ignored.

    Vertex *i* of the file is node *i* in every format but STL.  OBJ is read
    by :func:`read_obj`, PLY (ASCII and binary) and OFF by the project's own
    readers; polygons are fan-triangulated in file order (ear-clipped where a fan would fold), with a note (see
    :func:`read_obj`).  Binary STL goes through trimesh, text STL through
    :func:`read_text_stl`; STL stores each triangle
    with its own three corners and no shared vertices, so for STL only,
    exactly equal corner coordinates are merged, numbered in order of first
    appearance.  Faces wound against their neighbours are turned to agree
    with the majority (:func:`golden_model.mesh.oriented_mesh`), with a note; holes are refused as a
    :class:`golden_model.mesh.HoledMesh`, closed (:func:`golden_model.mesh.fill_holes`) or kept, as ``holes``
    says, with a note.

    A file that cannot be read raises :class:`MeshError` "cannot read mesh
    '<path>': <reason>" (no such file, permission denied, ...); one that is
    no valid file of its format "cannot parse mesh …"; one that is read but
    is no valid disk "invalid mesh …" with the validation's message (for OBJ
    followed by the file line it points at).
    """
    if not str(path).strip():
        raise MeshError("the mesh path is empty: name an OBJ, PLY, OFF or STL file")
    data = read_file_bytes(path, "mesh", MeshError)  # (before Path(), which drops a trailing '/')
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        # a name that is only a suffix ('.obj') is all stem, a hidden file's name
        bare = f": the name '{path.name}' has no stem (name it, for example, 'mesh{path.name.lower()}')" \
            if not suffix and path.name.lower() in MESH_SUFFIXES else ""
        raise MeshError(
            f"cannot read mesh '{path}': unknown format '{suffix}' (use {', '.join(MESH_SUFFIXES)}){bare}"
        )
    hint = ""
    if suffix == ".obj":
        obj = read_obj(path, data)
        vertices, faces, notes = obj.vertices, obj.faces, obj.notes
        if len(vertices) == 0 and len(faces) == 0 and any(
                line.strip() and not line.lstrip().startswith(b"#") for line in data.splitlines()):
            raise MeshError(f"cannot parse mesh '{path}': no 'v' or 'f' line in {len(data):,} bytes: not an OBJ "
                            "file (or not a text one)")
    elif suffix in (".ply", ".off"):
        where = f"cannot parse mesh '{path}'"
        vertices, polygons = (read_ply if suffix == ".ply" else read_off)(data, where)
        faces, _, notes = triangulate_polygons(vertices, polygons, where)
    else:
        vertices, faces, notes = read_stl(data, path)
    try:
        mesh, turned = oriented_mesh(vertices, faces, name=path.stem, holes=holes)
        return mesh, notes + turned
    except HoledMesh as exc:  # (the commands that can fill it say how)
        raise HoledMesh(f"invalid mesh '{path}': {exc}{seams_hint(vertices, faces)}") from None
    except MeshError as exc:
        seams = seams_hint(vertices, faces)
        if suffix == ".obj" and not (seams and exc.defect is MeshDefect.SEVERAL_PIECES):  # (pieces a weld may join)
            hint = obj_line_hint(exc, obj)
        raise MeshError(f"invalid mesh '{path}': {exc}{hint}{repair_hint(exc)}{seams}", faces=exc.faces,
                        vertices=exc.vertices, defect=exc.defect) from None


def read_stl(data: bytes, path: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """STL (binary through trimesh, text by :func:`read_text_stl`), equal corners merged."""
    import trimesh  # heavy import, only needed for STL

    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else 0
    binary = len(data) >= 84 and len(data) == 84 + 50 * count
    if binary and len(data) == 84:
        raise MeshError(f"invalid mesh '{path}': the binary STL holds 0 triangles")
    if not binary:
        data = data.removeprefix(UTF8_BOM)  # (a text editor's)
    if not binary and len(data) >= 84 and not (data.lstrip()[:5].lower() == b"solid" and b"facet" in data.lower()):
        raise MeshError(f"cannot parse mesh '{path}': not a text STL (no 'solid ... facet'), and as a binary STL "
                        f"its header's {count:,} triangles would take {84 + 50 * count:,} bytes, not {len(data):,} "
                        "(truncated or damaged?)")
    notes = []
    if not binary:
        vertices, faces = read_text_stl(data, f"cannot parse mesh '{path}'", notes)
    else:
        try:
            loaded = trimesh.load(io.BytesIO(data), file_type="stl", process=False, maintain_order=True, force="mesh")
            vertices = np.asarray(loaded.vertices, dtype=np.float64)
            faces = np.asarray(loaded.faces)
        except Exception as exc:  # trimesh raises many types on malformed files
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise MeshError(f"cannot parse mesh '{path}': {reason}") from None
    if len(vertices):
        corners = len(vertices)
        vertices, faces = _merge_exact_duplicates(vertices, faces)
        notes.append(f"merged {corners} STL triangle corners into {len(vertices)} shared vertices")
    return vertices, faces, notes


def read_text_stl(data: bytes, where: str, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """A text STL's triangles as ``(3F, 3)`` corners and ``(F, 3)`` faces (corner ``3f + k``), read line by
    line so that a malformed or truncated file is refused naming the line (``where``: the message's start).
    ``solid`` … ``endsolid`` may repeat; a file that ends after a whole facet without ``endsolid`` is read,
    with a note (it may be truncated)."""
    text = data.decode("utf-8", errors="replace")  # keywords and numbers are ASCII
    lines = text.splitlines()
    if lines and not text.endswith(("\n", "\r")):  # a line cut short: say so where the grammar breaks on it
        where_last = len(lines)
    else:
        where_last = 0

    def refused(line_no: int, what: str) -> MeshError:
        cut = ", the file's last line, cut short: truncated?" if line_no == where_last else ""
        return MeshError(f"{where}: line {line_no}: {what}{cut}")

    corners: list[list[float]] = []
    expect = "solid"  # the next keyword the grammar allows (with 'endsolid' after a facet)
    line_no = 0
    for line_no, line in enumerate(lines, start=1):
        words = line.split()
        if not words:
            continue
        keyword = words[0].lower()
        if expect == "solid":
            if keyword != "solid":
                raise refused(line_no, f"expected 'solid', got {_shown(line)}")
            expect = "facet"
        elif expect == "facet":
            if keyword == "endsolid":
                expect = "solid"
            elif keyword == "facet" and len(words) == 5 and words[1].lower() == "normal":
                _numbers(words[2:], refused, line_no)
                expect, loop = "outer", 0
            else:
                raise refused(line_no, f"expected 'facet normal nx ny nz' or 'endsolid', got {_shown(line)}")
        elif expect == "outer":
            if [w.lower() for w in words] != ["outer", "loop"]:
                raise refused(line_no, f"expected 'outer loop', got {_shown(line)}")
            expect = "vertex"
        elif expect == "vertex":
            if keyword == "vertex" and len(words) == 4:
                corners.append(_numbers(words[1:], refused, line_no))
                loop += 1
                expect = "endloop" if loop == 3 else "vertex"
            else:
                raise refused(line_no, f"expected 'vertex x y z' (corner {loop + 1} of 3), got {_shown(line)}")
        elif expect == "endloop":
            if keyword != "endloop":
                raise refused(line_no, "expected 'endloop' after three vertices (STL holds triangles), got "
                                       f"{_shown(line)}")
            expect = "endfacet"
        elif expect == "endfacet":
            if keyword != "endfacet":
                raise refused(line_no, f"expected 'endfacet', got {_shown(line)}")
            expect = "facet"
    if expect not in ("solid", "facet"):
        raise MeshError(f"{where}: the file ends inside facet {len(corners) // 3 + 1} (after line {line_no}): "
                        "truncated?")
    if expect == "facet":
        notes.append(f"no 'endsolid' after the last of {len(corners) // 3} facets (line {line_no}): the file may "
                     "be truncated")
    faces = np.arange(len(corners), dtype=np.int64).reshape(-1, 3)
    return np.array(corners, dtype=np.float64).reshape(-1, 3), faces


def _numbers(words: list[str], refused: Callable[[int, str], MeshError], line_no: int) -> list[float]:
    try:
        if first_unplain(words) is not None:
            raise ValueError
        return [float(w) for w in words]
    except ValueError:
        bad = next(w for w in words if not is_float(w))
        raise refused(line_no, f"{_shown(bad)} is not a number") from None


def _shown(text: str, limit: int = 40) -> str:
    """``text`` quoted for a one-line message, shortened."""
    text = text.strip()
    return repr(text if len(text) <= limit else text[:limit] + "…")


def _merge_exact_duplicates(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge bit-identical vertices, numbering them by first appearance."""
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return vertices[np.sort(first)], rank[inverse.reshape(-1)][faces]


def save_obj(path: str | Path, vertices: np.ndarray, faces: np.ndarray,
             comment: str = "written by springflat") -> None:
    """Write an OBJ with ``vertices`` (V×2 padded with z = 0, or V×3) and 1-based faces, after the one-line
    ``comment``."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertices.shape[1] == 2:
        vertices = np.column_stack([vertices, np.zeros(len(vertices))])
    with open(path, "w", encoding="utf-8") as out:  # (the comment may name the mesh: any text)
        out.write(f"# {comment}\n")
        np.savetxt(out, vertices, fmt="v %.17g %.17g %.17g")
        np.savetxt(out, np.asarray(faces) + 1, fmt="f %d %d %d")
