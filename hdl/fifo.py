"""A synchronous FIFO kept in distributed (LUT) RAM.

:class:`amaranth.lib.fifo.SyncFIFO` reads its memory asynchronously; when the register that
takes ``r_data`` is merged into the read port, Yosys may place the memory in ECP5 block RAM,
whose ~5.8 ns clock-to-output then eats most of a clock. Elaborated for ECP5 (:data:`hdl.dsp.ECP5`)
this FIFO asks for distributed RAM (``ram_style = "distributed"``: ``TRELLIS_DPR16X4``), whose
read is a LUT delay; elsewhere the synthesis tool chooses.
"""

from __future__ import annotations

from amaranth.hdl import Elaboratable, Module, Signal
from amaranth.lib.memory import Memory

from .dsp import dsp_target

__all__ = ["LutFIFO"]


class LutFIFO(Elaboratable):
    """First in, first out, ``depth`` (a power of two) entries of ``width`` bits.

    The interface is :class:`amaranth.lib.fifo.SyncFIFO`'s subset: ``w_data``, ``w_en``,
    ``w_rdy``, ``r_data`` (valid while ``r_rdy``), ``r_en``, ``r_rdy``, ``level``. A write
    is visible on the read side on the next clock; a read and a write may happen together.

    The read and write pointers carry one wrap bit, so empty and full are equality tests of
    two registers (no counter on the handshake paths). With ``checked=False`` the handshakes
    are not gated: the user guarantees never to write when full nor read when empty (the node
    header FIFO, whose reads follow its writes by construction). ``start`` is the pointers'
    reset value: FIFOs that split one wide queue into column slices get different starts, so
    that synthesis cannot merge their pointer registers and each pointer drives only its own
    slice's RAM cells.
    """

    def __init__(self, *, width: int, depth: int, checked: bool = True, start: int = 0):
        if width < 1:
            raise ValueError(f"LutFIFO width must be at least 1, not {width}")
        if depth < 2 or depth & (depth - 1):
            raise ValueError(f"LutFIFO depth must be a power of two of at least 2, not {depth}")
        self.width, self.depth, self.checked, self.start = width, depth, checked, start % depth
        self.w_data = Signal(width)
        self.w_en = Signal()
        self.w_rdy = Signal()
        self.r_data = Signal(width)
        self.r_en = Signal()
        self.r_rdy = Signal()
        self.level = Signal(range(depth + 1))

    def elaborate(self, platform):
        m = Module()
        # Only where the device has distributed RAM (iCE40 has none: Yosys would refuse).
        attrs = {"ram_style": "distributed"} if dsp_target(platform) == "ecp5" else {}
        m.submodules.storage = storage = Memory(shape=self.width, depth=self.depth, init=[], attrs=attrs)
        write = storage.write_port()
        read = storage.read_port(domain="comb")
        bits = (self.depth - 1).bit_length()
        produce = Signal(bits + 1, init=self.start)  # the top bit counts wraps
        consume = Signal(bits + 1, init=self.start)
        m.d.comb += [
            self.r_rdy.eq(produce != consume),
            self.w_rdy.eq(produce != (consume ^ (1 << bits))),
            self.level.eq((produce - consume)[:bits + 1]),
        ]
        do_write = self.w_en & self.w_rdy if self.checked else self.w_en
        do_read = self.r_en & self.r_rdy if self.checked else self.r_en
        m.d.comb += [
            write.addr.eq(produce[:bits]), write.data.eq(self.w_data), write.en.eq(do_write),
            read.addr.eq(consume[:bits]), self.r_data.eq(read.data),
        ]
        with m.If(do_write):
            m.d.sync += produce.eq(produce + 1)
        with m.If(do_read):
            m.d.sync += consume.eq(consume + 1)
        return m
