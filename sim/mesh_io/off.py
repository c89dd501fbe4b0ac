"""OFF reader (ASCII)."""

from __future__ import annotations

import numpy as np

from golden_model.mesh import MeshError
from .polygons import INDEX_LIMIT, Polygons, checked_polygons, is_int, plural, text_coordinates

#: OFF keywords: vertex colours (C), normals (N) and texture coordinates (ST) follow x y z and are ignored.
_OFF_KEYWORDS = frozenset(f"{st}{c}{n}OFF" for st in ("", "ST") for c in ("", "C") for n in ("", "N"))


def read_off(data: bytes, where: str) -> tuple[np.ndarray, Polygons]:
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
    if not rows:
        raise MeshError(f"{where}: the file is empty{' but for comments and blank lines' if text.strip() else ''}: "
                        "no 'OFF' header, no vertices, no faces")
    if rows[0][1][0] not in _OFF_KEYWORDS:
        raise MeshError(f"{where}: not an OFF file (it starts with {rows[0][1][0][:20]!r}; binary and 4D/nD OFF are "
                        "not supported)")
    count_line, header = rows[0][0], rows[0][1][1:]
    if header[:1] == ["BINARY"]:
        raise MeshError(f"{where}: binary OFF is not supported (write it as text OFF, PLY or OBJ)")
    rows = rows[1:]
    if not header:  # the counts are on the next line
        if not rows:
            raise MeshError(f"{where}: the OFF file has no vertex and face counts")
        (count_line, header), rows = rows[0], rows[1:]
    if len(header) < 2 or not all(is_int(t) for t in header[:3]) or min(int(t) for t in header[:2]) < 0:
        raise MeshError(f"{where}: line {count_line}: expected the counts 'vertices faces [edges]', "
                        f"got {' '.join(header)[:40]!r}")
    n_vertices, n_faces = int(header[0]), int(header[1])
    if len(rows) < n_vertices + n_faces:
        raise MeshError(f"{where}: the file ends early: the header declares {plural(n_vertices, 'vertex', 'vertices')} "
                        f"and {plural(n_faces, 'face')}, the file has {plural(len(rows), 'line')} of them")
    vertex_rows, face_rows = rows[:n_vertices], rows[n_vertices:n_vertices + n_faces]
    short = next(((number, tokens) for number, tokens in vertex_rows if len(tokens) < 3), None)
    if short is not None:
        raise MeshError(f"{where}: line {short[0]}: vertex with {len(short[1])} values (needs x y z)")
    coords = [value for _, tokens in vertex_rows for value in tokens[:3]]
    vertices = text_coordinates(coords, np.array([number for number, _ in vertex_rows]), where)
    lines = [number for number, _ in face_rows]
    uniform = _uniform_off_faces([tokens for _, tokens in face_rows])
    if uniform is not None:
        return vertices, checked_polygons(uniform[:, 1:].ravel(),
                                           uniform[:, 0], n_vertices, lambda f: f"line {lines[f]}", where)
    sizes, index = [], []
    for number, tokens in face_rows:
        if not is_int(tokens[0]) or len(tokens) < int(tokens[0]) + 1 or not all(
                is_int(t) for t in tokens[1:int(tokens[0]) + 1]):
            raise MeshError(f"{where}: line {number}: expected a face 'n i1 ... in', got {' '.join(tokens)[:40]!r}")
        size = int(tokens[0])
        corners = [int(t) for t in tokens[1:size + 1]]
        if any(not -INDEX_LIMIT <= i < INDEX_LIMIT for i in corners):  # beyond int64: no file has that many
            bad = next(i for i in corners if not -INDEX_LIMIT <= i < INDEX_LIMIT)
            raise MeshError(f"{where}: line {number}: face index {bad} is out of range")
        sizes.append(size)
        index.extend(corners)
    return vertices, checked_polygons(np.asarray(index, dtype=np.int64), np.asarray(sizes, dtype=np.int64),
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
