"""The stream payload layouts of the datapath, in one place (``lib.data`` layouts built from a format set).

Every field's width comes from :class:`~golden_model.fixed.FormatSet`; the cocotb benches pack
and unpack with the same layouts (:mod:`sim.payloads`), and the Verilog export describes them in
``interface.json``.
"""

from __future__ import annotations

from amaranth.hdl import unsigned
from amaranth.lib import data

from golden_model.fixed import Format, FormatSet

from .fixedpoint import shape_of

__all__ = ["vector_layout", "node_layout", "barrier_layout", "entry_layout", "result_layout", "step_layout",
           "errors_layout"]


def vector_layout(fmt: Format) -> data.StructLayout:
    """A 2D vector of raw ``fmt`` values: fields ``x``, ``y``."""
    return data.StructLayout({"x": shape_of(fmt), "y": shape_of(fmt)})


def node_layout(fs: FormatSet) -> data.StructLayout:
    """A node's state: ``position`` [position], ``velocity`` [velocity], ``inv_mass`` [inv_mass]
    and ``inv_mass_barrier`` [inv_mass], the weight used instead while one of the node's
    triangles is inside the fold barrier (equal to ``inv_mass`` where that does not apply)."""
    return data.StructLayout({
        "position": vector_layout(fs.position),
        "velocity": vector_layout(fs.velocity),
        "inv_mass": shape_of(fs.inv_mass),
        "inv_mass_barrier": shape_of(fs.inv_mass),
    })


def barrier_layout(fs: FormatSet) -> data.StructLayout:
    """An entry's fold-barrier triangle: the third corner's ``position``, ``threshold`` κX* [area], ``gain`` G [barrier_gain]."""
    return data.StructLayout({
        "second": vector_layout(fs.position),
        "threshold": shape_of(fs.area),
        "gain": shape_of(fs.barrier_gain),
    })


def entry_layout(fs: FormatSet) -> data.StructLayout:
    """One input beat: a neighbour entry, with its node's header on the node's first entry.

    ``first``/``last`` mark a node's first and last neighbour entries; ``node``
    is read only when ``first`` is set; ``neighbour`` holds the neighbour's
    ``position`` and the edge's ``rest`` length [rest_length]; ``barrier`` the
    entry's fold-barrier triangle (``gain`` 0: none).
    """
    return data.StructLayout({
        "first": unsigned(1),
        "last": unsigned(1),
        "node": node_layout(fs),
        "neighbour": data.StructLayout({"position": vector_layout(fs.position), "rest": shape_of(fs.rest_length)}),
        "barrier": barrier_layout(fs),
    })


def result_layout(fs: FormatSet) -> data.StructLayout:
    """One output beat: the node's new ``position``, ``velocity``, ``error_sum`` Σ|L − d| [error_acc]
    and ``power`` F·V [power] (force and velocity of the *input* state)."""
    return data.StructLayout({
        "position": vector_layout(fs.position),
        "velocity": vector_layout(fs.velocity),
        "error_sum": shape_of(fs.error_acc),
        "power": shape_of(fs.power),
    })


def step_layout(fs: FormatSet) -> data.StructLayout:
    """``dt`` [dt] and ``half_dt_sq`` [half_dt_sq]."""
    return data.StructLayout({"dt": shape_of(fs.dt), "half_dt_sq": shape_of(fs.half_dt_sq)})


def errors_layout(fs: FormatSet) -> data.StructLayout:
    """``area_error`` (E_S) and ``shape_error`` (E_C), both [error]."""
    return data.StructLayout({"area_error": shape_of(fs.error), "shape_error": shape_of(fs.error)})
