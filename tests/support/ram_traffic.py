"""Random RAM traffic, a Python RAM and an Icarus run with the DP16KD model: shared by the block RAM tests."""

import numpy as np
import pytest


def random_ram_traffic(rng, depth: int, width: int, clocks: int):
    """Per clock: write enable, write address, write data, read address. No read of the address being
    written at the same clock (a collision, undefined on the device), but many reads of a word the
    clock after its write."""
    we = rng.integers(0, 2, clocks)
    waddr = rng.integers(0, depth, clocks)
    wdata = rng.integers(0, 1 << width, clocks)
    raddr = np.where(rng.random(clocks) < 0.3, np.roll(waddr, 1), rng.integers(0, depth, clocks))
    raddr = np.where((we == 1) & (raddr == waddr), (raddr + 1) % depth, raddr)
    return we, waddr, wdata, raddr


def ram_reads(we, waddr, wdata, raddr, depth: int, data_registers: int) -> list[int]:
    """What a RAM that registers its read address, then ``data_registers`` times its data, shows after each clock."""
    memory, reads = [0] * depth, []
    for k in range(len(we)):
        reads.append(memory[int(raddr[k])])  # the word before this clock's write (no collision)
        if we[k]:
            memory[int(waddr[k])] = int(wdata[k])
    return [0] * data_registers + reads[:len(reads) - data_registers]


def icarus_run(tmp_path, module_files, top: str, ports: str, we, waddr, wdata, raddr) -> list[str]:
    """Drive ``top`` (ports ``clk, we, waddr, wdata, raddr, q`` named in ``ports``) with the traffic on
    Icarus with ``sim/models/DP16KD.v`` and ``TRELLIS_FF.v``; the value of ``q`` after each clock, as printed (may hold x)."""
    import shutil
    import subprocess

    from sim.cocotb_support import REPO

    if shutil.which("iverilog") is None:
        pytest.fail("Icarus Verilog (iverilog) is not on PATH")
    for name, values in (("we", we), ("waddr", waddr), ("wdata", wdata), ("raddr", raddr)):
        (tmp_path / f"{name}.hex").write_text("".join(f"{int(v):x}\n" for v in values))
    n = len(we)
    (tmp_path / "tb.v").write_text(
        "`timescale 1ns/1ps\nmodule tb; reg clk = 0; reg [63:0] we_m [0:%d]; reg [63:0] wa_m [0:%d];\n"
        "reg [63:0] wd_m [0:%d]; reg [63:0] ra_m [0:%d]; reg we; reg [63:0] waddr, wdata, raddr; wire [63:0] q;\n"
        "integer i;\n%s\ninitial begin $readmemh(\"we.hex\", we_m); $readmemh(\"waddr.hex\", wa_m);\n"
        "$readmemh(\"wdata.hex\", wd_m); $readmemh(\"raddr.hex\", ra_m);\n"
        "for (i = 0; i < %d; i = i + 1) begin we = we_m[i][0]; waddr = wa_m[i]; wdata = wd_m[i]; raddr = ra_m[i];\n"
        "#1 clk = 1; #1 clk = 0; $display(\"%%b\", q); end $finish; end\nendmodule\n"
        % (n - 1, n - 1, n - 1, n - 1, ports, n))
    subprocess.run(["iverilog", "-g2005", "-o", "tb.vvp", "tb.v", *module_files,
                    str(REPO / "sim" / "models" / "DP16KD.v"), str(REPO / "sim" / "models" / "TRELLIS_FF.v")],
                   cwd=tmp_path, check=True, capture_output=True)
    out = subprocess.run(["vvp", "-n", "tb.vvp"], cwd=tmp_path, check=True, capture_output=True, text=True).stdout
    return [line for line in out.split() if set(line) <= set("01xz")]

