"""The register bank (hdl.register_bank) on a small map of its own: each field acts as its access type says.

The registers carry misleading names (the ``w1c`` register is called CONTROL, the ``w1p`` one STATUS):
a bank that picked behaviour by register name would fail here.
"""

import gc
import warnings

import pytest
from amaranth.hdl import Module, UnusedElaboratable
from amaranth.lib import wiring
from amaranth.lib.wiring import In
from amaranth.sim import Simulator

from golden_model.engine_spec.image import DEFAULT_CAPACITY
from golden_model.engine_spec.register_map import BitField, Register, RegisterMap
from hdl import wishbone
from hdl.register_bank import RegisterBank
from support.wishbone import wishbone_read, wishbone_write

ADDR_WIDTH = 4
MAGIC = 0x5A5A_0F0F


def small_map() -> RegisterMap:
    registers = (
        Register("MAGIC", 0, "ro", "a constant", (BitField("value", 0, 32, "ro", "", value="magic"),),
                 "identification", reset=MAGIC),
        Register("STATUS", 1, "rw", "pulses and a stored bit", (
            BitField("go", 0, 1, "w1p", "", value="go"),
            BitField("halt", 1, 1, "w1p", "", value="halt"),
            BitField("enable", 4, 1, "rw", "", value="enable")), "control"),
        Register("CONTROL", 2, "w1c", "flags and a level", (
            BitField("flags", 0, 2, "w1c", "", value="flags"),
            BitField("level", 8, 3, "ro", "", value="level")), "control"),
        Register("WIDE_LO", 4, "rw", "", (BitField("value", 0, 32, "rw", "", value="wide"),), "run constants"),
        Register("WIDE_HI", 5, "rw", "", (BitField("value", 0, 8, "rw", "", value="wide", value_lsb=32),),
                 "run constants"),
        Register("COUNT", 6, "ro", "", (BitField("value", 0, 20, "ro", "", value="count"),), "results"),
    )
    return RegisterMap("test", 0, DEFAULT_CAPACITY, registers, ())


class Bench(wiring.Component):
    """The bank behind a Wishbone handshake, no memory windows."""

    bus: In(wishbone.Signature(addr_width=ADDR_WIDTH))

    def __init__(self, registered_write: bool = False):
        self.bank = RegisterBank(small_map(), addr_width=ADDR_WIDTH, copies=("wide",),
                                 registered_write=registered_write)
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.submodules.hs = hs = wishbone.TargetHandshake(addr_width=ADDR_WIDTH)
        m.submodules.bank = bank = self.bank
        wiring.connect(m, wiring.flipped(self.bus), hs.bus)
        m.d.comb += [bank.request.eq(hs.request), bank.address.eq(hs.address), bank.write.eq(hs.write),
                     bank.write_data.eq(hs.write_data), bank.whole_word.eq(hs.whole_word),
                     hs.done.eq(bank.done), hs.error.eq(bank.error), hs.data.eq(bank.data)]
        return m


def run(dut, bench):
    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()


def never_elaborated(test):
    """Run ``test``, whose banks are never elaborated, with their ``UnusedElaboratable`` warnings collected
    here rather than in a later test."""
    def run_it():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UnusedElaboratable)
            test()
            gc.collect()
    run_it.__name__, run_it.__doc__ = test.__name__, test.__doc__
    return run_it


@never_elaborated
def test_the_ports_follow_the_access_types():
    bank = RegisterBank(small_map(), addr_width=ADDR_WIDTH, copies=("wide",))
    flows = {name: member.flow for name, member in bank.signature.members.items()}
    assert {n: flows[n] for n in ("go", "halt", "enable", "flags", "wide", "wide_held")} == \
        dict.fromkeys(("go", "halt", "enable", "flags", "wide", "wide_held"), wiring.Out)
    assert {n: flows[n] for n in ("flags_set", "flags_clear", "level", "count")} == \
        dict.fromkeys(("flags_set", "flags_clear", "level", "count"), wiring.In)
    assert "magic" not in flows  # a constant: no port
    assert len(bank.wide) == 40 and len(bank.count) == 20 and len(bank.flags) == 2


@pytest.mark.parametrize("registered_write", [False, True])
def test_each_field_acts_as_its_access_type_says(registered_write):
    """Also with the writes a clock later (``registered_write``): every effect is in place by the write's answer."""
    dut = Bench(registered_write)
    bank = dut.bank
    pulses = []

    async def watch(ctx):
        async for _, _, go, halt in ctx.tick().sample(bank.go, bank.halt):
            if go or halt:
                pulses.append((go, halt))

    async def bench(ctx):
        # ro constant; ro from a port; a write to a ro register is an error and changes nothing
        assert (await wishbone_read(ctx, dut.bus, 0)).data == MAGIC
        ctx.set(bank.count, 0xABCDE)
        ctx.set(bank.level, 5)
        assert (await wishbone_read(ctx, dut.bus, 6)).data == 0xABCDE
        answer = await wishbone_write(ctx, dut.bus, 6, 0)
        assert answer.error
        assert (await wishbone_read(ctx, dut.bus, 0)).data == MAGIC
        # rw over two words, its copy a clock behind; an unmapped word is refused
        await wishbone_write(ctx, dut.bus, 4, 0x1234_5678)
        await wishbone_write(ctx, dut.bus, 5, 0x1FF)  # the upper word holds 8 bits
        assert ctx.get(bank.wide) == 0xFF_1234_5678
        assert (await wishbone_read(ctx, dut.bus, 5)).data == 0xFF
        assert ctx.get(bank.wide_held) == 0xFF_1234_5678
        assert (await wishbone_read(ctx, dut.bus, 3)).error
        for unmapped in (8, 12, 14):  # a mapped word's offset in the low bits, but a high bit set
            assert (await wishbone_read(ctx, dut.bus, unmapped)).error, unmapped
        assert (await wishbone_write(ctx, dut.bus, 12, 0xDEAD)).error  # WIDE_LO's offset, a high bit set
        assert ctx.get(bank.wide) == 0xFF_1234_5678
        # w1p: one clock high per write of 1, reads 0; the rw bit beside it is stored and read back
        await wishbone_write(ctx, dut.bus, 1, 0b1_0001)
        await wishbone_write(ctx, dut.bus, 1, 0b1_0010)
        assert (await wishbone_read(ctx, dut.bus, 1)).data == 0b1_0000
        assert ctx.get(bank.enable) == 1
        assert pulses == [(1, 0), (0, 1)]
        # w1c: set by hardware, read, cleared by writing 1 (0 leaves it); the ro field beside it reads its port
        ctx.set(bank.flags_set, 0b11)
        await ctx.tick()
        ctx.set(bank.flags_set, 0)
        assert (await wishbone_read(ctx, dut.bus, 2)).data == (5 << 8) | 0b11
        answer = await wishbone_write(ctx, dut.bus, 2, 0b01)
        assert not answer.error  # a w1c register takes writes
        assert (await wishbone_read(ctx, dut.bus, 2)).data == (5 << 8) | 0b10
        ctx.set(bank.flags_clear, 0b10)
        await ctx.tick()
        ctx.set(bank.flags_clear, 0)
        assert ctx.get(bank.flags) == 0
        # in one clock the set input wins over the clear input
        ctx.set(bank.flags_set, 0b01)
        ctx.set(bank.flags_clear, 0b11)
        await ctx.tick()
        ctx.set(bank.flags_set, 0)
        ctx.set(bank.flags_clear, 0)
        assert ctx.get(bank.flags) == 0b01

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_process(watch)
    sim.add_testbench(bench)
    sim.run()


@never_elaborated
def test_a_field_value_with_two_access_types_is_refused():
    registers = (
        Register("A", 0, "rw", "", (BitField("value", 0, 8, "rw", "", value="x"),), "run constants"),
        Register("B", 1, "rw", "", (BitField("value", 0, 8, "w1p", "", value="x", value_lsb=8),), "control"),
    )
    with pytest.raises(ValueError, match="x is rw in one field and w1p in another"):
        RegisterBank(RegisterMap("test", 0, DEFAULT_CAPACITY, registers, ()), addr_width=ADDR_WIDTH)


@never_elaborated
def test_a_copy_must_be_of_a_rw_value():
    with pytest.raises(ValueError, match="'count' is not one"):
        RegisterBank(small_map(), addr_width=ADDR_WIDTH, copies=("count",))


def test_an_address_width_too_narrow_for_the_map_is_refused_as_the_other_parameters_are():
    """The map's last word is 6: three address bits; the check words its refusal as every component's does."""
    from support import refused_components

    with refused_components():
        with pytest.raises(ValueError, match=r"^addr_width must be an int >= 3, not 2$"):
            RegisterBank(small_map(), addr_width=2)
        with pytest.raises(ValueError, match=r"^addr_width must be an int >= 3, not True$"):
            RegisterBank(small_map(), addr_width=True)
        assert RegisterBank(small_map(), addr_width=3).addr_width == 3


@pytest.mark.parametrize("registered_write", [False, True])
def test_a_registered_write_acts_a_clock_later(registered_write):
    """The bank driven directly (one clock of a registered request): a rw word is stored two clocks after
    the request (DEC, then the write's edge), three with ``registered_write``; the answer comes at the same
    clock either way."""
    bank = RegisterBank(small_map(), addr_width=ADDR_WIDTH, registered_write=registered_write)
    seen = {}

    async def bench(ctx):
        ctx.set(bank.request, 1)
        ctx.set(bank.address, 4)
        ctx.set(bank.write, 1)
        ctx.set(bank.write_data, 0x1234_5678)
        ctx.set(bank.whole_word, 1)
        for clock in range(1, 6):
            await ctx.tick()
            ctx.set(bank.request, 0)
            if ctx.get(bank.done):
                seen.setdefault("answer", clock)
            if ctx.get(bank.wide) == 0x1234_5678:
                seen.setdefault("stored", clock)

    sim = Simulator(bank)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    assert seen == {"stored": 2 + registered_write, "answer": 3}
