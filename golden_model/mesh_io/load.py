"""Loading a mesh file of any supported format, and writing OBJ."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..files import read_file_bytes
from ..mesh import Mesh, MeshError, oriented_mesh
from .obj import obj_line_hint, read_obj
from .off import read_off
from .ply import read_ply
from .polygons import triangulate_polygons

MESH_SUFFIXES = (".obj", ".ply", ".off", ".stl")


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
    appearance.  Faces wound against their neighbours are turned to agree
    with the majority (:func:`golden_model.mesh.oriented_mesh`), with a note.

    A file that cannot be read raises :class:`MeshError` "cannot read mesh
    '<path>': <reason>" (no such file, permission denied, ...); one that is
    no valid file of its format "cannot parse mesh …"; one that is read but
    is no valid disk "invalid mesh …" with the validation's message (for OBJ
    followed by the file line it points at).
    """
    if not str(path).strip():
        raise MeshError("the mesh path is empty: name an OBJ, PLY, OFF or STL file")
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
        mesh, turned = oriented_mesh(vertices, faces, name=path.stem)
        return mesh, notes + turned
    except MeshError as exc:
        if suffix == ".obj":
            hint = obj_line_hint(str(exc), obj)
        raise MeshError(f"invalid mesh '{path}': {exc}{hint}") from None


def read_stl(data: bytes, path: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """STL (ASCII or binary) through trimesh, equal corners merged."""
    import trimesh  # heavy import, only needed for STL

    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else 0
    binary = len(data) >= 84 and len(data) == 84 + 50 * count
    if binary and len(data) == 84:
        raise MeshError(f"invalid mesh '{path}': the binary STL holds 0 triangles")
    if not binary and len(data) >= 84 and not (data.lstrip()[:5].lower() == b"solid" and b"facet" in data):
        raise MeshError(f"cannot parse mesh '{path}': not a text STL (no 'solid ... facet'), and as a binary STL "
                        f"its header's {count:,} triangles would take {84 + 50 * count:,} bytes, not {len(data):,} "
                        "(truncated or damaged?)")
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
