"""Stream payloads as integers: packing golden-model arrays into RTL beats and back.

Shared by the Amaranth-simulator tests and the cocotb benches, so both drive
the hardware with exactly the same bits.
"""

from __future__ import annotations

import numpy as np
from amaranth.hdl import Shape
from amaranth.lib import data

from golden_model.fixed.pipeline import NeighbourStream

__all__ = ["leaves", "pack", "unpack", "pass_beats"]


def leaves(layout: data.Layout, offset: int = 0, path: tuple = ()):
    """``(path, offset, width, signed)`` of every leaf field of a (nested) layout."""
    for name, field in layout:
        shape = field.shape
        if isinstance(shape, data.Layout):
            yield from leaves(shape, offset + field.offset, path + (name,))
        else:
            s = Shape.cast(shape)
            yield path + (name,), offset + field.offset, s.width, s.signed


def pack(layout: data.Layout, fields: dict) -> list[int]:
    """Raw payload integers from ``{path tuple: int array}`` (missing fields are 0)."""
    n = len(next(iter(fields.values())))
    out = [0] * n
    for path, offset, width, _ in leaves(layout):
        if path in fields:
            mask = (1 << width) - 1
            for k, v in enumerate(np.asarray(fields[path]).tolist()):
                out[k] |= (int(v) & mask) << offset
    return out


def unpack(layout: data.Layout, raw: list[int], path: tuple) -> np.ndarray:
    """One field of raw payload integers, sign-extended where signed."""
    for p, offset, width, signed in leaves(layout):
        if p == path:
            values = [(int(r) >> offset) & ((1 << width) - 1) for r in raw]
            if signed:
                values = [v - (1 << width) if v >> (width - 1) else v for v in values]
            return np.array(values, dtype=np.int64)
    raise KeyError(path)


def pass_beats(layout: data.Layout, stream: NeighbourStream, positions: np.ndarray,
               velocities: np.ndarray) -> list[int]:
    """The input beats of one pass: every node's entries in CSR order, its header on the first.

    With a fold barrier, each entry also carries its triangle's third corner, threshold and gain.
    """
    owner = stream.owner
    index = np.arange(len(owner))
    first = stream.indptr[:-1][owner] == index
    last = stream.indptr[1:][owner] - 1 == index
    barrier = {}
    if stream.barrier is not None:
        barrier = {
            ("barrier", "second", "x"): positions[stream.barrier.second, 0],
            ("barrier", "second", "y"): positions[stream.barrier.second, 1],
            ("barrier", "threshold"): stream.barrier.threshold,
            ("barrier", "gain"): stream.barrier.gain,
        }
    return pack(layout, {
        **barrier,
        ("first",): first.astype(np.int64), ("last",): last.astype(np.int64),
        ("node", "position", "x"): positions[owner, 0] * first, ("node", "position", "y"): positions[owner, 1] * first,
        ("node", "velocity", "x"): velocities[owner, 0] * first, ("node", "velocity", "y"): velocities[owner, 1] * first,
        ("node", "inv_mass"): stream.inv_mass[owner] * first,
        ("node", "inv_mass_barrier"): stream.header_inv_mass_barrier[owner] * first,
        ("neighbour", "position", "x"): positions[stream.neighbour, 0],
        ("neighbour", "position", "y"): positions[stream.neighbour, 1],
        ("neighbour", "rest"): stream.rest,
    })
