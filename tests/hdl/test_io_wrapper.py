"""The serial I/O wrapper used for place and route (hdl.io_wrapper.SerialWrapper), in Amaranth's simulator."""

import pytest
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out
from amaranth.sim import Simulator

from hdl.io_wrapper import SerialWrapper
from support import refused_components


class _Core(wiring.Component):
    """Registered ``b = a + 3`` and ``c = ~a`` (a stand-in core)."""

    a: In(7)
    b: Out(8)
    c: Out(7)

    def elaborate(self, platform):
        m = Module()
        m.d.sync += [self.b.eq(self.a + 3), self.c.eq(~self.a)]
        return m


@pytest.mark.parametrize("value", [0, 1, 0x55, 0x7F])
def test_bits_shifted_in_reach_the_core_and_its_outputs_shift_out(value):
    dut = SerialWrapper(_Core())
    assert (dut.in_width, dut.out_width) == (7, 15)
    got = []

    async def bench(ctx):
        ctx.set(dut.shift, 1)
        for bit in reversed(range(dut.in_width)):  # msb first: it ends at the top
            ctx.set(dut.si, (value >> bit) & 1)
            await ctx.tick()
        ctx.set(dut.shift, 0)
        ctx.set(dut.capture, 1)  # input holding register <- shift register
        await ctx.tick()
        ctx.set(dut.capture, 0)
        await ctx.tick()  # the core registers its outputs
        ctx.set(dut.capture, 1)  # output register <- core outputs
        await ctx.tick()
        ctx.set(dut.capture, 0)
        ctx.set(dut.shift, 1)
        word = 0
        for bit in range(dut.out_width):  # lsb first
            word |= ctx.get(dut.so) << bit
            await ctx.tick()
        got.append(word)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    b, c = got[0] & 0xFF, got[0] >> 8
    assert (b, c) == (value + 3, ~value & 0x7F)


def test_the_core_inputs_hold_while_bits_shift():
    """The core sees the holding register: shifting new bits in does not disturb it."""
    dut = SerialWrapper(_Core())

    async def bench(ctx):
        ctx.set(dut.shift, 1)
        for bit in reversed(range(7)):
            ctx.set(dut.si, (0x2A >> bit) & 1)
            await ctx.tick()
        ctx.set(dut.capture, 1)
        await ctx.tick()
        ctx.set(dut.capture, 0)
        for _ in range(5):  # more bits shift in; the core input stays
            ctx.set(dut.si, 1)
            await ctx.tick()
            assert ctx.get(dut.core.a) == 0x2A

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()


def test_a_non_component_is_refused():
    with refused_components():
        with pytest.raises(TypeError, match="Component"):
            SerialWrapper(object())
