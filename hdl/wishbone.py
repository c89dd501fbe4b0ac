"""Wishbone B4 classic: the engine's host bus (signature and the target-side handshake).

Names follow ``amaranth_soc.wishbone`` (``cyc``, ``stb``, ``we``, ``adr``, ``dat_w``, ``dat_r``,
``sel``, ``ack``, ``err``), so the engine plugs into an amaranth-soc or LiteX interconnect by
name. The signature is the *initiator's* view (``Out`` = driven by the host); a target takes
``In(wishbone.Signature(...))``.

Classic cycles (Wishbone B4 §3.2): the initiator holds ``cyc``, ``stb``, ``we``, ``adr``,
``dat_w`` and ``sel`` until the target answers with ``ack`` or ``err`` for one clock; a read's
``dat_r`` is valid with that ``ack``. ``adr`` addresses 32-bit words (byte address >> 2) and
``sel`` has one bit per byte; the engine accepts only whole words (``sel`` all ones).
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.engine_spec.image import BUS_WORD_BITS

from .dsp import kept_register
from .parameters import check_int

__all__ = ["Signature", "TargetHandshake", "DATA_WIDTH", "GRANULARITY"]

#: Bus data width (bits) and ``sel`` granularity (bits per ``sel`` bit).
DATA_WIDTH = BUS_WORD_BITS
GRANULARITY = 8


class Signature(wiring.Signature):
    """Wishbone B4 classic with ``err``, ``DATA_WIDTH``-bit data and ``addr_width``-bit word addresses."""

    def __init__(self, *, addr_width: int):
        check_int("addr_width", addr_width)
        self.addr_width = addr_width
        super().__init__({
            "cyc": Out(1),
            "stb": Out(1),
            "we": Out(1),
            "adr": Out(addr_width),
            "dat_w": Out(DATA_WIDTH),
            "sel": Out(DATA_WIDTH // GRANULARITY),
            "dat_r": In(DATA_WIDTH),
            "ack": In(1),
            "err": In(1),
        })

    def __eq__(self, other):
        return isinstance(other, Signature) and other.addr_width == self.addr_width

    def __repr__(self):
        return f"wishbone.Signature(addr_width={self.addr_width})"


class TargetHandshake(wiring.Component):
    """The target side of one classic cycle at a time.

    ``request`` is high for exactly one clock per bus cycle, the clock after the cycle starts (so a
    decoder has registered ``adr``/``we``/``dat_w`` to look at); the target then answers by
    raising ``done`` (with ``error`` for an ``err`` answer, and for reads ``data``) exactly
    any number of clocks after ``request`` (in the same clock at the earliest). ``ack``/``err``
    are registered and high for one clock; back-to-back cycles (``stb`` held high with the next
    request right after an answer) are taken. A cycle abandoned (``cyc`` low) before its answer gets
    none, but the target's late answer goes to the next cycle: a host must not abandon (docs/engine.md).

    Members
    -------
    bus : ``In(Signature(addr_width))``
    request : ``Out(1)``; ``address``, ``write``, ``write_data``, ``whole_word`` (``sel`` all ones): ``Out``
        The registered request.
    done, error : ``In(1)``; data : ``In(DATA_WIDTH)``
        The target's answer.
    address_copy : ``Out(addr_width)``, with ``address_copy=True``
        ``address`` in every clock, from a register of its own (kept apart from ``address``'s by
        :func:`~hdl.dsp.kept_register`), so that the placer can put it by the loads of one part of the
        target while ``address`` stays by the others.

    ``busy_copy``: the state (a cycle taken, not yet answered) in two flip-flops loaded with the same next
    value, the second kept apart by :func:`~hdl.dsp.kept_register`: ``busy`` for its own next value and the
    answer, the copy for the start of a cycle, whose loads are the request and the address and data
    registers. The logic of ``busy``'s next value then has no load but the two flip-flops and is placed by
    ``busy``, not between it and the registers the start loads. No clock changes.
    """

    def __init__(self, *, addr_width: int, address_copy: bool = False, busy_copy: bool = False):
        for flag, value in (("address_copy", address_copy), ("busy_copy", busy_copy)):
            if not isinstance(value, bool):
                raise TypeError(f"TargetHandshake {flag} must be a bool, not {value!r}")
        self.busy_copy = busy_copy
        copy = {"address_copy": Out(addr_width)} if address_copy else {}
        super().__init__({
            "bus": In(Signature(addr_width=addr_width)),
            "request": Out(1),
            "address": Out(addr_width),
            "write": Out(1),
            "write_data": Out(DATA_WIDTH),
            "whole_word": Out(1),
            "done": In(1),
            "error": In(1),
            "data": In(DATA_WIDTH),
            **copy,
        })

    def elaborate(self, platform):
        m = Module()
        bus = self.bus
        busy = Signal()  # a cycle has been taken and not yet answered
        # While ack/err is out, the initiator still shows the answered cycle's request: it takes
        # the answer at this clock edge and only then presents its next cycle (or drops stb).
        if self.busy_copy:  # busy's next value (as the statements below give it) into busy and its copy
            busy_next = bus.cyc & Mux(busy, ~self.done, bus.stb & ~bus.ack & ~bus.err)
            m.d.sync += busy.eq(busy_next)
            busy_for_start = kept_register(m, busy_next, name="busy_kept", platform=platform, reset=True)
        else:
            busy_for_start = busy
        start = bus.cyc & bus.stb & ~busy_for_start & ~bus.ack & ~bus.err
        m.d.sync += self.request.eq(start)
        loads = [self.address.eq(bus.adr), self.write.eq(bus.we), self.write_data.eq(bus.dat_w),
                 self.whole_word.eq(bus.sel.all())]
        with m.If(start):
            m.d.sync += loads if self.busy_copy else [busy.eq(1), *loads]
        if "address_copy" in self.signature.members:  # loaded and cleared as `address` is
            m.d.comb += self.address_copy.eq(kept_register(m, bus.adr, name="address_kept", platform=platform,
                                                           reset=True, enable=start))
        m.d.sync += [bus.ack.eq(0), bus.err.eq(0)]
        answer = [bus.ack.eq(bus.cyc & ~self.error), bus.err.eq(bus.cyc & self.error), bus.dat_r.eq(self.data)]
        with m.If(busy & self.done):
            m.d.sync += answer if self.busy_copy else [busy.eq(0), *answer]
        if not self.busy_copy:
            with m.If(~bus.cyc):
                m.d.sync += busy.eq(0)
        return m
