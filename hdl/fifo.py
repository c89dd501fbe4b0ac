"""A synchronous FIFO kept in distributed (LUT) RAM.

:class:`amaranth.lib.fifo.SyncFIFO` reads its memory asynchronously; when the register that
takes ``r_data`` is merged into the read port, Yosys may place the memory in ECP5 block RAM,
whose ~5.8 ns clock-to-output then eats most of a clock. Elaborated for ECP5 (:data:`hdl.dsp.ECP5`)
this FIFO asks for distributed RAM (``ram_style = "distributed"``: ``TRELLIS_DPR16X4``), whose
read is a LUT delay; elsewhere the synthesis tool chooses.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Elaboratable, Module, Mux, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from .dsp import dsp_target, kept_register
from .parameters import check_int, check_power_of_two

__all__ = ["LutFIFO", "SlicedFIFO"]


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

    ``registered_ready``: ``r_rdy`` is a flip-flop (:func:`~hdl.dsp.kept_register`, cleared by the reset)
    loaded with its next value (set by a write, cleared by a read of the last entry), equal in every clock
    to the plain form's ``produce != consume``, with no carry chain in front of it. Its loads then start at
    a register, not at the compare's LUTs: for a FIFO whose ``r_rdy`` is routed across the device (the
    guard certificate's results, whose valid steps a pass's counter by the controller).
    """

    def __init__(self, *, width: int, depth: int, checked: bool = True, start: int = 0,
                 registered_ready: bool = False):
        check_int("LutFIFO width", width)
        check_power_of_two("LutFIFO depth", depth)
        if not isinstance(registered_ready, bool):
            raise TypeError(f"registered_ready must be a bool, not {registered_ready!r}")
        self.width, self.depth, self.checked, self.start = width, depth, checked, start % depth
        self.registered_ready = registered_ready
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
        if not self.registered_ready:
            m.d.comb += self.r_rdy.eq(produce != consume)
        m.d.comb += [
            self.w_rdy.eq(produce != (consume ^ (1 << bits))),
            self.level.eq((produce - consume)[:bits + 1]),
        ]
        do_write = self.w_en & self.w_rdy if self.checked else self.w_en
        do_read = self.r_en & self.r_rdy if self.checked else self.r_en
        if self.registered_ready:
            # ready after this clock: a write, or ready now and not the last entry read (no carry chain: the
            # last entry is `produce == consume + 1`, from a register that counts one read ahead; reset: empty)
            ahead = Signal(bits + 1, init=(self.start + 1) % (2 * self.depth))
            with m.If(do_read):
                m.d.sync += ahead.eq(ahead + 1)
            ready_next = do_write | (self.r_rdy & ~(do_read & (produce == ahead)))
            m.d.comb += self.r_rdy.eq(kept_register(m, ready_next, name="r_rdy_q", platform=platform, reset=True))
        m.d.comb += [
            write.addr.eq(produce[:bits]), write.data.eq(self.w_data), write.en.eq(do_write),
            read.addr.eq(consume[:bits]), self.r_data.eq(read.data),
        ]
        with m.If(do_write):
            m.d.sync += produce.eq(produce + 1)
        with m.If(do_read):
            m.d.sync += consume.eq(consume + 1)
        return m


class SlicedFIFO(wiring.Component):
    """A wide FIFO (unchecked handshakes) of :class:`LutFIFO` column slices, each with its own pointers.

    Parameters
    ----------
    width : :class:`int`
        Payload bits.
    depth : :class:`int`
        Entries, a power of two.
    slice_bits : :class:`int`
        Bits per column slice (the last one takes the rest).
    write_register : :class:`bool`
        Each slice registers its write (enable and data) before its memory, one clock later:
        the enable register of slice k takes ``w_stream.valid`` and slice k's own ``w_rdy``, so
        the slices' enable registers are distinct logic that synthesis cannot merge, and
        ``w_stream.valid`` reaches one LUT per slice instead of every slice's row decoders (one
        register for all the slices of a wide FIFO fans out across the die).
    registered : :class:`bool`
        ``False``: ``r_stream.payload`` is the memories' asynchronous read of the oldest entry
        (valid while ``r_stream.valid``), and ``r_stream.ready`` pops it. ``True``: each slice
        ends in two registers used in turn (one offered, the other refilling from the memory),
        so ``r_stream`` obeys the ``lib.stream`` rules at one transfer per clock, its payload a
        2:1 multiplexer of registers, and ``r_stream.ready`` reaches only a few flags per slice;
        it holds ``depth + 2`` entries.

    Attributes
    ----------
    w_stream : ``In(stream.Signature(width))``
        Writes; unchecked: the user never writes a full FIFO (``w_stream.ready`` tells).
    r_stream : ``Out(stream.Signature(width))``
        Reads (see ``registered``); unchecked: the unregistered form is never popped empty.

    Why slices: a read address that drives every cell of a wide, deep LUT RAM fans out to all of
    them; a slice's own pointers reach only its cells. The slices' pointers start at
    different values, so synthesis cannot merge them; they decide alike (same writes and reads,
    equal levels), so they stay in step, and slice 0's flags stand for all.
    """

    def __init__(self, *, width: int, depth: int, slice_bits: int, registered: bool = False,
                 write_register: bool = False):
        check_int("SlicedFIFO width", width)
        check_int("SlicedFIFO slice_bits", slice_bits)
        check_power_of_two("SlicedFIFO depth", depth)
        self.width, self.depth, self.slice_bits, self.registered = width, depth, slice_bits, registered
        self.write_register = write_register
        super().__init__({"w_stream": In(stream.Signature(width)), "r_stream": Out(stream.Signature(width))})

    def elaborate(self, platform):
        m = Module()
        parts = []
        for k, lo in enumerate(range(0, self.width, self.slice_bits)):
            bits = min(self.slice_bits, self.width - lo)
            m.submodules[f"slice{k}"] = fifo = LutFIFO(width=bits, depth=self.depth, checked=False, start=k)
            w_en, w_data = self.w_stream.valid, self.w_stream.payload[lo:lo + bits]
            if self.write_register:
                w_en_r = Signal(name=f"w_en{k}")
                w_data_r = Signal(bits, name=f"w_data{k}", reset_less=True)
                m.d.sync += [w_en_r.eq(w_en & fifo.w_rdy), w_data_r.eq(w_data)]
                w_en, w_data = w_en_r, w_data_r
            m.d.comb += [fifo.w_en.eq(w_en), fifo.w_data.eq(w_data)]
            if k == 0:
                m.d.comb += self.w_stream.ready.eq(fifo.w_rdy)
            if not self.registered:
                m.d.comb += fifo.r_en.eq(self.r_stream.ready)
                parts.append(fifo.r_data)
                if k == 0:
                    m.d.comb += self.r_stream.valid.eq(fifo.r_rdy)
                continue
            # Two registers per slice, used in turn: the head is offered, the other one refills.
            # A register's load enable is its own (registered) empty flag, never r_stream.ready,
            # which reaches only the flags and the head pointer (as the enable of every skid
            # register in every slice it would fan out across the die).
            regs = [Signal(bits, name=f"buf{k}_{n}", reset_less=True) for n in range(2)]  # data: no reset
            full = [Signal(name=f"full{k}_{n}") for n in range(2)]
            head = Signal(name=f"head{k}")  # the register offered
            fill = Signal(name=f"fill{k}")  # the register refilled next
            read = Signal(name=f"read{k}")
            take = Signal(name=f"take{k}")
            m.d.comb += [read.eq(fifo.r_rdy & ~Mux(fill, full[1], full[0])), fifo.r_en.eq(read),
                         take.eq(Mux(head, full[1], full[0]) & self.r_stream.ready)]
            for n in range(2):
                with m.If(read & (fill == n)):
                    m.d.sync += [regs[n].eq(fifo.r_data), full[n].eq(1)]
                with m.Elif(take & (head == n)):
                    m.d.sync += full[n].eq(0)
            with m.If(read):
                m.d.sync += fill.eq(~fill)
            with m.If(take):
                m.d.sync += head.eq(~head)
            parts.append(Mux(head, regs[1], regs[0]))
            if k == 0:
                m.d.comb += self.r_stream.valid.eq(Mux(head, full[1], full[0]))
        m.d.comb += self.r_stream.payload.eq(Cat(*parts))
        return m
