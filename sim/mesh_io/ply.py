"""PLY (ASCII and binary) reader."""

from __future__ import annotations

import numpy as np

from golden_model.mesh import MeshError
from .polygons import INDEX_LIMIT, UTF8_BOM, Polygons, checked_polygons, first_unplain, is_float

#: PLY scalar types and their numpy codes (byte order added for binary files).
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply(data: bytes, where: str) -> tuple[np.ndarray, Polygons]:
    """Vertices (the ``vertex`` element's x, y, z, in file order) and faces of an ASCII or binary PLY file.

    Every element the header declares is read (so elements before or between
    ``vertex`` and ``face`` are skipped correctly); the faces are the
    ``face`` element's ``vertex_indices`` (or ``vertex_index``) lists, of any
    length; other lists (per-corner texture coordinates) are read past.  Refusals name the problem: not PLY, an unknown type, a value
    that is no number, a file shorter than its header says.
    """
    data = data.removeprefix(UTF8_BOM)  # (a text editor's; the header is text in binary files too)
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
    declared = {element for element, _, _ in elements}
    if "face" not in declared and len(vertices):
        other = sorted(declared - {"vertex"})
        raise MeshError(f"{where}: no 'face' element, {len(vertices)} vertices alone"
                        + (f" (its {', '.join(map(repr, other))} are not read: save the faces as a 'face' element)"
                           if other else ""))
    face_properties = next((props for element, _, props in elements if element == "face"), [])
    lists = [prop for prop, _, count_type in face_properties if count_type]
    name = next((n for n in ("vertex_indices", "vertex_index") if n in lists), lists[0] if lists else None)
    if name is None:  # the face's other lists (MeshLab's per-corner texcoord, ...) are not its corners
        index, sizes = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    else:
        numbers, sizes = values["face"][name]
        try:
            index = _whole_indices(numbers, "face")
        except ValueError as exc:
            raise MeshError(f"{where}: {exc}") from None
    return vertices, checked_polygons(index, sizes, len(vertices), lambda f: f"face {f}", where)


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
            columns = {props[0][0]: (block.reshape(count, length + 1)[:, 1:].ravel(),
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
                        length = _list_length(_ascii_numbers(tokens[pos:pos + 1], name, 1)[0], name)
                        raw[prop].extend(tokens[pos + 1:pos + 1 + length])
                        lengths[prop].append(length)
                        pos += 1 + length
            if pos > len(tokens):
                raise ValueError(f"the file ends inside element '{name}' (fewer values than the header declares)")
            for prop, items in raw.items():
                numbers = _ascii_numbers(items, name, len(items) if prop in lengths else count)
                columns[prop] = ((numbers, np.asarray(lengths[prop], dtype=np.int64))
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


def _list_length(value, element: str) -> int:
    """A list's length as the file gives it (a number of the header's count type): refused unless it
    is a whole number from 0 to :data:`INDEX_LIMIT` (no truncated fraction, no overflow)."""
    number = float(value)
    if not 0 <= number < INDEX_LIMIT or number != int(number):
        raise ValueError(f"element '{element}' has a list length {np.asarray(value)!s} that is not a whole "
                         "number of values")  # as the file's type prints it (a float32's 3.9, not 3.9000000953674316)
    return int(number)


def _whole_indices(numbers: np.ndarray, element: str) -> np.ndarray:
    """The int64 indices of PLY list values (as floats, ASCII, or of the header's type, binary; a float
    type is legal PLY); a fraction or a value past :data:`INDEX_LIMIT` is refused (no silent truncation
    or wrap-around)."""
    given = np.asarray(numbers)
    numbers = given.astype(np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(numbers) < INDEX_LIMIT) | (numbers != np.floor(numbers))
    if bad.any():
        first = np.flatnonzero(bad)[0]
        value = float(numbers[first])
        what = ("not a number" if value != value else "out of range" if not abs(value) < INDEX_LIMIT
                else "not an integer")
        # as the file's type prints it: the shortest exact form (a float32's 2.6, not 2.5999999046325684)
        raise ValueError(f"element '{element}' has an index {given[first]!s} that is {what}")
    return numbers.astype(np.int64)


def _ascii_numbers(items: list, element: str, expected: int) -> np.ndarray:
    if len(items) < expected:
        raise ValueError(f"the file ends inside element '{element}' (fewer values than the header declares)")
    try:
        if first_unplain(items) is not None:
            raise ValueError
        return np.array(items, dtype=np.bytes_).astype(np.float64)
    except ValueError:
        bad = next(t for t in items if not is_float(t.decode("ascii", errors="replace")))
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
            values[name] = {prop: (block[prop].ravel(), block[prop + "#"].astype(np.int64))
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
                    length = _list_length(take(counter[prop], 1, name)[0], name)
                    columns[prop].append(take(scalar[prop], length, name))
                    lengths[prop].append(length)
        values[name] = {prop: ((np.concatenate(items) if items else np.zeros(0, dtype=np.int64)),
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
        try:
            length = _list_length(np.frombuffer(body, dtype=counter, count=1, offset=offset)[0], "")
        except ValueError:
            return None  # the row-by-row read names the bad length
        offset += counter.itemsize + length * np.dtype(_PLY_TYPES[t]).itemsize
        if offset > len(body):  # (a row longer than the file: the row-by-row read says where it ends; numpy
            return None         # refuses a record of 2 GiB or more in its own words)
        fields += [(prop + "#", counter), (prop, order + _PLY_TYPES[t], (length,))]
    dtype = np.dtype(fields)
    if pos + dtype.itemsize * count > len(body):
        return None
    block = np.frombuffer(body, dtype=dtype, count=count, offset=pos)
    for prop, _, count_type in props:
        if count_type and not (block[prop + "#"] == block[prop].shape[1]).all():
            return None
    return dtype
