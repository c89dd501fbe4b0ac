"""Stream payloads as integers: packing golden-model values into RTL beats and back.

A payload is a nested dict of field values, as :meth:`amaranth.lib.data.Layout.const` takes it
(``{"position": {"x": 1, "y": 2}, "error_sum": 3}``; a field left out is 0), or a plain
integer for a payload that is not a layout. Two forms of the same thing:

* :func:`pack` / :func:`unpack`: one beat, through ``Layout.const`` / ``Layout.from_bits``;
* :func:`pack_beats` / :func:`unpack_beats`: many beats at once (a pass has thousands), the
  same nested dicts with an array of values in every leaf, field by field with numpy.

The many-beat form walks the layout with :func:`leaves`; ``tests/sim/test_payloads.py`` checks that
the two forms agree.
Shared by the Amaranth-simulator tests (:mod:`support.streams`) and the cocotb benches, so
both drive the hardware with exactly the same bits.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from amaranth.hdl import Const, Shape
from amaranth.lib import data

from golden_model.fixed.pipeline import NeighbourStream

__all__ = ["leaves", "pack", "unpack", "pack_beats", "unpack_beats", "pass_beats"]

#: Fields and whole payloads up to this width are packed in int64 arrays, wider ones in Python ints.
_INT64_BITS = 63


def leaves(shape, offset: int = 0, path: tuple = ()):
    """``(path, offset, width, signed)`` of every leaf field of a (nested) layout.

    A shape that is not a layout is one leaf, with the path ``()``.
    """
    if isinstance(shape, data.Layout):
        for name, field in shape:
            yield from leaves(field.shape, offset + field.offset, path + (name,))
    else:
        s = Shape.cast(shape)
        yield path, offset, s.width, s.signed


def pack(shape, payload) -> int:
    """The raw bits of one beat: ``payload`` a nested dict (or a ``data.Const``) for a layout,
    an integer for a plain shape. Values are taken modulo their field's width."""
    if isinstance(shape, data.Layout):
        return shape.const(payload).as_bits()
    s = Shape.cast(shape)
    return Const(payload, s).value & ((1 << s.width) - 1)


def unpack(shape, raw: int):
    """One beat's raw bits as a nested dict of field values (signed fields negative where
    their top bit is set); an integer for a plain shape. The inverse of :func:`pack`."""
    if isinstance(shape, data.Layout):
        return _as_dict(shape.from_bits(int(raw)))
    s = Shape.cast(shape)
    return Const(int(raw), s).value


def _as_dict(const: data.Const) -> dict:
    out = {}
    for name, _ in const.shape():
        value = const[name]
        out[name] = _as_dict(value) if isinstance(value, data.Const) else value
    return out


def _lookup(fields, path: tuple):
    """The value at ``path`` of a nested dict, or ``None`` if it has none."""
    for name in path:
        if not isinstance(fields, Mapping) or name not in fields:
            return None
        fields = fields[name]
    return fields


def _leaf_paths(fields, path: tuple = ()):
    if isinstance(fields, Mapping):
        for name, value in fields.items():
            yield from _leaf_paths(value, path + (name,))
    else:
        yield path


def pack_beats(shape, fields) -> list[int]:
    """The raw bits of many beats: ``fields`` is a nested dict like :func:`pack`'s with an
    array (one value per beat) in every leaf given, or an array for a plain shape."""
    columns = list(leaves(shape))
    known = {path for path, *_ in columns}
    unknown = [path for path in _leaf_paths(fields) if path not in known]
    if unknown:
        raise ValueError(f"no leaf field {'.'.join(map(str, unknown[0])) or '(whole payload)'} in {shape!r}")
    given = [(offset, width, np.asarray(value)) for path, offset, width, _ in columns
             if (value := _lookup(fields, path)) is not None]
    if not given:
        raise ValueError("pack_beats needs at least one field's values")
    n = max(len(np.atleast_1d(values)) for *_, values in given)
    wide = Shape.cast(shape).width > _INT64_BITS
    out = np.zeros(n, dtype=object if wide else np.int64)
    for offset, width, values in given:
        mask = (1 << width) - 1
        if width <= _INT64_BITS:
            bits = values.astype(np.int64) & mask
            out |= (bits.astype(object) if wide else bits) << offset
        else:
            out |= (values.astype(object) & mask) << offset
    return out.tolist()


def unpack_beats(shape, raw) -> dict | np.ndarray:
    """Many beats' raw bits as a nested dict with an int64 array in every leaf (an array for a
    plain shape). The inverse of :func:`pack_beats`."""
    wide = Shape.cast(shape).width > _INT64_BITS
    bits = np.array([int(r) for r in raw], dtype=object if wide else np.int64)
    out: dict = {}
    for path, offset, width, signed in leaves(shape):
        values = (bits >> offset) & ((1 << width) - 1)
        if width <= _INT64_BITS:
            values = values.astype(np.int64)
        if signed:
            values = values - (((values >> (width - 1)) & 1) << width)
        if not path:
            return values
        node = out
        for name in path[:-1]:
            node = node.setdefault(name, {})
        node[path[-1]] = values
    return out


def pass_beats(layout: data.Layout, stream: NeighbourStream, positions: np.ndarray,
               velocities: np.ndarray) -> list[int]:
    """The input beats of one pass: every node's entries in CSR order, its header on the first.

    With a fold barrier, each entry also carries its triangle's third corner, threshold and gain.
    """
    owner = stream.owner
    index = np.arange(len(owner))
    first = stream.indptr[:-1][owner] == index
    last = stream.indptr[1:][owner] - 1 == index
    fields = {
        "first": first.astype(np.int64), "last": last.astype(np.int64),
        "node": {
            "position": {"x": positions[owner, 0] * first, "y": positions[owner, 1] * first},
            "velocity": {"x": velocities[owner, 0] * first, "y": velocities[owner, 1] * first},
            "inv_mass": stream.inv_mass[owner] * first,
            "inv_mass_barrier": stream.header_inv_mass_barrier[owner] * first,
        },
        "neighbour": {
            "position": {"x": positions[stream.neighbour, 0], "y": positions[stream.neighbour, 1]},
            "rest": stream.rest,
        },
    }
    if stream.barrier is not None:
        fields["barrier"] = {
            "second": {"x": positions[stream.barrier.second, 0], "y": positions[stream.barrier.second, 1]},
            "threshold": stream.barrier.threshold,
            "gain": stream.barrier.gain,
        }
    return pack_beats(layout, fields)
