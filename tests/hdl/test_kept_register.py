"""``hdl.dsp.kept_register``: the generic form (an Amaranth register) and the ECP5 form (``TRELLIS_FF`` instances
on ``sim/models/TRELLIS_FF.v``) exported to Verilog and driven on Icarus with the same random values and
resets (and enables), against a Python register, clock by clock. With ``reset`` both forms are cleared by the
domain's reset (a copy of a register with that reset), whatever the enable; without it the ECP5 form ignores the
reset. With ``enable`` the register holds while the enable is low."""

import os

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import Module
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from hdl.dsp import ECP5, kept_register

from support.ram_traffic import icarus_run

pytestmark = pytest.mark.slow  # Icarus

WIDTH = 4


class _Copy(wiring.Component):
    value: In(WIDTH)
    load: In(1)
    q: Out(WIDTH)

    def __init__(self, reset: bool, enable: bool):
        self.reset, self.enable = reset, enable
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.d.comb += self.q.eq(kept_register(m, self.value, name="copy", platform=platform, reset=self.reset,
                                            enable=self.load if self.enable else None))
        return m


@pytest.mark.parametrize("platform", [None, ECP5], ids=["generic", "ecp5"])
@pytest.mark.parametrize("reset", [True, False], ids=["reset", "no-reset"])
@pytest.mark.parametrize("enable", [False, True], ids=["always", "enable"])
def test_kept_register_is_its_value_a_clock_later_and_cleared_as_its_form_says(tmp_path, platform, reset, enable):
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    source = verilog.convert(_Copy(reset, enable), name="copy_top", platform=platform)
    assert ("TRELLIS_FF" in source) == (platform is ECP5)
    (tmp_path / "copy_top.v").write_text(source)
    rng = np.random.default_rng(WIDTH)
    clocks = 400
    resets = (rng.random(clocks) < 0.2).astype(int)
    values = rng.integers(0, 1 << WIDTH, clocks)
    loads = (rng.random(clocks) < 0.5).astype(int) if enable else np.ones(clocks, dtype=int)
    unused = np.zeros(clocks, dtype=int)
    ports = (f"copy_top dut(.clk(clk), .rst(we), .value(wdata[{WIDTH - 1}:0]), .load(raddr[0]), "
             f".q(q[{WIDTH - 1}:0]));")
    lines = icarus_run(tmp_path, ["copy_top.v"], "copy_top", ports, resets, unused, values, loads)
    cleared = reset or platform is None  # the generic register has the domain's reset either way
    want, held = [], 0
    for r, v, load in zip(resets, values, loads):
        held = 0 if (cleared and r) else int(v) if load else held
        want.append(held)
    assert resets.sum() > 40 and any(r and v for r, v in zip(resets, values))  # resets that clear a value
    assert not enable or sum(w != v for w, v in zip(want, values)) > 100  # held values that differ from the input
    assert [int(line[-WIDTH:], 2) for line in lines] == want
