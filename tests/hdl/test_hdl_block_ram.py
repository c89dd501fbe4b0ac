"""``hdl.block_ram.BlockRam``: both forms read what a RAM reads, two clocks after the address.

The generic form (an Amaranth ``Memory`` read port and a data register) and the ECP5 form (``DP16KD``
instances with their output registers, on ``sim/models/DP16KD.v``, whose pins
``tests/sim/test_synth.py::test_dp16kd_model_is_the_ram_yosys_maps`` checks against Yosys's mapping) are
exported to Verilog and driven on Icarus with the same random writes and reads; every read port of
each is compared with a Python RAM, clock by clock.
"""

import os

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import Shape, unsigned
from amaranth.lib import data

from hdl.block_ram import BlockRam, dp16kd_banks
from hdl.dsp import ECP5

from support import refused_components
from support.ram_traffic import icarus_run, ram_reads, random_ram_traffic

pytestmark = pytest.mark.slow  # Icarus


@pytest.mark.parametrize("platform", [None, ECP5], ids=["generic", "ecp5"])
@pytest.mark.parametrize("shape, depth", [(unsigned(18), 1024), (unsigned(9), 1500), (unsigned(40), 600),
                                          (data.StructLayout({"x": 17, "y": 13}), 1024), (unsigned(4), 4096),
                                          (unsigned(40), 3000), (unsigned(30), 2100)])  # the last two in banks
def test_block_ram_reads_two_clocks_after_the_address(tmp_path, platform, shape, depth):
    check_block_ram(tmp_path, platform, shape, depth, pin_registers=False)


@pytest.mark.parametrize("platform", [None, ECP5], ids=["generic", "ecp5"])
@pytest.mark.parametrize("shape, depth", [(unsigned(40), 600), (unsigned(40), 3000)])  # the last in banks
def test_block_ram_with_pin_registers_reads_three_clocks_after_the_address(tmp_path, platform, shape, depth):
    """Every input a clock later: the read answers a clock later, a write lands a clock later."""
    check_block_ram(tmp_path, platform, shape, depth, pin_registers=True)


@pytest.mark.parametrize("platform", [None, ECP5], ids=["generic", "ecp5"])
@pytest.mark.parametrize("shape, depth, pin_registers", [(unsigned(40), 600, False), (unsigned(52), 3072, False),
                                                         (unsigned(40), 3000, True)])  # the last two in banks
def test_block_ram_with_registered_select_reads_three_clocks_later(tmp_path, platform, shape, depth, pin_registers):
    """The relays and the bank select (or, with one bank, the word) in three registers more: the read answers
    three clocks later."""
    check_block_ram(tmp_path, platform, shape, depth, pin_registers=pin_registers, registered_select=True)


def check_block_ram(tmp_path, platform, shape, depth, *, pin_registers, registered_select=False):
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    ram = BlockRam(shape, depth, read_ports=2, name="mem", pin_registers=pin_registers,
                   registered_select=registered_select)
    assert ram.latency == BlockRam.LATENCY + pin_registers + 3 * registered_select
    width = Shape.cast(shape).width
    abits = len(ram.write.addr)
    (tmp_path / "ram.v").write_text(verilog.convert(ram, name="ram", platform=platform))
    source = (tmp_path / "ram.v").read_text()
    assert ("DP16KD" in source and '"OUTREG"' in source) == (platform is ECP5)
    banks = dp16kd_banks(depth, width)[2]  # the registered select's kept flag copies are TRELLIS_FFs too
    assert ("TRELLIS_FF" in source) == (platform is ECP5 and (pin_registers or (registered_select and banks > 1)))
    rng = np.random.default_rng(depth + width)
    we, waddr, wdata, raddr = random_ram_traffic(rng, depth, width, 2500)
    want = ram_reads(we, waddr, wdata, raddr, depth, ram.latency - 1)
    for k in range(2):  # each read port, the other one reading elsewhere
        other = 1 - k
        ports = (f"ram dut(.clk(clk), .rst(1'b0), .write__en(we), .write__addr(waddr[{abits - 1}:0]), "
                 f".write__data(wdata[{width - 1}:0]), .read__{k}__addr(raddr[{abits - 1}:0]), "
                 f".read__{k}__data(q[{width - 1}:0]), .read__{other}__addr({abits}'d0), .read__{other}__data());")
        lines = icarus_run(tmp_path, ["ram.v"], "ram", ports, we, waddr, wdata, raddr)
        # from the latency's clock on (the generic form's registers start undefined)
        skip = ram.latency - 1
        assert [int(line[-width:], 2) for line in lines[skip:]] == want[skip:], f"read port {k}"


@pytest.mark.parametrize("platform", [None, ECP5], ids=["generic", "ecp5"])
@pytest.mark.parametrize("shape, depth, pin_registers, registered_select", [
    (unsigned(40), 600, False, False), (unsigned(30), 2100, False, False),  # the last in banks
    (unsigned(52), 3072, True, True)])  # the proposal memory's word and banks above DEFAULT_CAPACITY
def test_block_ram_shares_a_copys_write_port_with_a_read_port(tmp_path, platform, shape, depth, pin_registers,
                                                              registered_select):
    """Three read ports in two copies: the third reads the first copy's write port, the same words with the
    same latency at every edge without a write; at an edge with a write its word is undefined (the generic
    form's all ones)."""
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    ram = BlockRam(shape, depth, read_ports=3, name="mem", pin_registers=pin_registers,
                   registered_select=registered_select, shared_write_port=True)
    assert (ram.copies, list(ram.shared_reads)) == (2, [2])
    width = Shape.cast(shape).width
    abits = len(ram.write.addr)
    (tmp_path / "ram.v").write_text(verilog.convert(ram, name="ram", platform=platform))
    rng = np.random.default_rng(depth + width)
    we, waddr, wdata, raddr = random_ram_traffic(rng, depth, width, 2500)
    skip = ram.latency - 1  # the generic form's registers start undefined
    want = ram_reads(we, waddr, wdata, raddr, depth, skip)
    # the clocks whose word answers a read issued at an edge with a write
    undefined = {k + skip for k in np.flatnonzero(we)}
    for k in range(3):  # each read port, the others reading elsewhere
        others = "".join(f", .read__{j}__addr({abits}'d{j}), .read__{j}__data()" for j in range(3) if j != k)
        ports = (f"ram dut(.clk(clk), .rst(1'b0), .write__en(we), .write__addr(waddr[{abits - 1}:0]), "
                 f".write__data(wdata[{width - 1}:0]), .read__{k}__addr(raddr[{abits - 1}:0]), "
                 f".read__{k}__data(q[{width - 1}:0]){others});")
        lines = icarus_run(tmp_path, ["ram.v"], "ram", ports, we, waddr, wdata, raddr)
        words = [line[-width:] for line in lines]
        checked = [c for c in range(skip, len(want)) if k not in ram.shared_reads or c not in undefined]
        assert len(checked) > len(want) // 3
        assert [int(words[c], 2) for c in checked] == [want[c] for c in checked], f"read port {k}"
        if k in ram.shared_reads and platform is None:
            assert {words[c] for c in undefined if c < len(words)} == {"1" * width}


def test_shared_write_port_takes_a_copy_per_two_read_ports():
    from hdl.dsp import ecp5_instance_count

    for read_ports, copies in ((1, 1), (2, 1), (3, 2), (4, 2)):
        shared = BlockRam(unsigned(66), 3072, read_ports=read_ports, shared_write_port=True)
        assert shared.copies == copies
        assert ecp5_instance_count(shared, "DP16KD") == 12 * copies  # 1K×18: 3 banks of 4 block RAMs
    with refused_components():  # never elaborated
        assert BlockRam(unsigned(66), 3072, read_ports=3).copies == 3


def test_block_ram_refuses_bad_parameters():
    with refused_components():  # collected here, not in whichever test runs when the collector next does
        with pytest.raises(ValueError, match="depth"):
            BlockRam(unsigned(8), 0)
        with pytest.raises(ValueError, match="read_ports must be an int >= 1"):
            BlockRam(unsigned(8), 16, read_ports=0)
        with pytest.raises(ValueError, match="width"):
            BlockRam(unsigned(0), 16)
        with pytest.raises(TypeError, match="registered_select must be a bool"):
            BlockRam(unsigned(8), 16, registered_select=1)
        with pytest.raises(TypeError, match="shared_write_port must be a bool"):
            BlockRam(unsigned(8), 16, read_ports=2, shared_write_port="yes")


def test_dp16kd_banks_takes_the_fewest_block_rams():
    assert dp16kd_banks(1024, 66) == (18, 1024, 1)  # 4 block RAMs
    assert dp16kd_banks(3072, 66) == (18, 1024, 3)  # 12, where one 4K x 4 bank takes 17
    assert dp16kd_banks(6144, 65) == (9, 2048, 3)  # 24, tied with 6 banks of 1K x 18: fewer banks
    assert dp16kd_banks(4096, 4) == (4, 4096, 1)


@pytest.mark.parametrize("shape, depth, read_ports, expected", [
    (unsigned(18), 3072, 2, 6),  # 1K×18: 3 banks of 1 block RAM, a copy per read port
    (unsigned(33), 1000, 1, 2),  # 1K×18: 1 bank, two slices side by side
    (unsigned(8), 4000, 1, 2),   # 4K×4 and 2K×9 both take 2; one bank (4K×4) wins the tie
])
def test_ecp5_instance_count_counts_the_block_rams_a_memory_maps_to(shape, depth, read_ports, expected):
    """The count benchmarks/bram_budget.py sizes capacities with, against the DP16KD configurations by hand."""
    from hdl.dsp import ecp5_instance_count

    ram = BlockRam(shape, depth, read_ports=read_ports)
    assert ecp5_instance_count(ram, "DP16KD") == expected
    assert ecp5_instance_count(ram, "MULT18X18D") == 0
