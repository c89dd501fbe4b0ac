"""A thin serialising I/O wrapper, so that a bare core with hundreds of ports can be placed and routed.

A core such as :class:`~hdl.node_update.NodeUpdate` has more port bits than an FPGA package has
pins (631 port bits for the default preset against 205 user I/O on an ECP5-85F CABGA381 and 39 on an
iCE40 UP5K SG48). :class:`SerialWrapper` puts every input port of the core behind one shift
register and every output port in front of another, so the wrapped design needs four signal
pins besides ``clk`` and ``rst``:

``si``, ``shift``
    On a clock edge with ``shift`` high, the input shift register moves up one bit and takes
    ``si`` in its bit 0.
``capture``, ``so``
    On a clock edge with ``capture`` high the input holding register loads the input shift
    register, and the output register loads every core output (payloads, ``valid``, ``ready``,
    ``step``); otherwise, with ``shift`` high, the output register moves down one bit. ``so``
    is its bit 0. The core's inputs (payloads, ``valid``, ``ready`` and the constants) are
    driven from the holding register, so every core input path starts at a flip-flop that the
    placer can put next to its users, and the shift chain stays compact; every core output
    path ends at a flip-flop.

The wrapper is for place and route only (it turns the core's I/O timing into register-to-register
paths, as in a system where the core sits between registers); it adds ``in_width + out_width``
flip-flops plus ``in_width`` for the holding register, and about one LUT per output bit, which
the synthesis report of the bare core does not include.
"""


from amaranth.hdl import Cat, Const, Module, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

__all__ = ["SerialWrapper"]


class SerialWrapper(wiring.Component):
    """Serialise every port of ``core`` (a :class:`~amaranth.lib.wiring.Component`).

    Attributes
    ----------
    in_width, out_width : :class:`int`
        Total bits of the core's input and output ports (the shift registers' lengths).
    """

    si: In(1)
    shift: In(1)
    capture: In(1)
    so: Out(1)

    def __init__(self, core: wiring.Component):
        if not isinstance(core, wiring.Component):
            raise TypeError(f"SerialWrapper needs an amaranth Component, not {core!r}")
        self.core = core
        self._inputs, self._outputs = [], []
        for path, member, value in core.signature.flatten(core):
            if not member.is_port or (member.flow == In and isinstance(value, Const)):
                continue  # a constant input (an always-ready stream's ready) is the core's own
            (self._inputs if member.flow == In else self._outputs).append(value)
        self.in_width = sum(len(Value.cast(v)) for v in self._inputs)
        self.out_width = sum(len(Value.cast(v)) for v in self._outputs)
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = self.core
        inputs = Cat(*(Value.cast(v) for v in self._inputs))
        outputs = Cat(*(Value.cast(v) for v in self._outputs))
        sr_in = Signal(max(1, self.in_width), name="sr_in")
        sr_out = Signal(max(1, self.out_width), name="sr_out")
        with m.If(self.shift):
            m.d.sync += sr_in.eq(Cat(self.si, sr_in[:-1]) if len(sr_in) > 1 else self.si)
        if self.in_width:
            held = Signal(self.in_width, name="held_in")
            with m.If(self.capture):
                m.d.sync += held.eq(sr_in)
            m.d.comb += inputs.eq(held)
        with m.If(self.capture):
            m.d.sync += sr_out.eq(outputs)
        with m.Elif(self.shift):
            m.d.sync += sr_out.eq(sr_out[1:])
        m.d.comb += self.so.eq(sr_out[0])
        return m
