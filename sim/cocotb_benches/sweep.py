"""``stream_sweep`` (``sim/stream_sweep.py``): reset, then wait for the harness's ``done``.

The harness makes its own clock and feeds and collects the unit itself; Python does nothing per clock.
"""

from __future__ import annotations

import time

import cocotb
from cocotb.triggers import RisingEdge, Timer, with_timeout

from .common import CLOCK_NS, load_config, write_result


@cocotb.test()
async def sweep(dut):
    config = load_config()
    dut.rst.value = 1
    for _ in range(3):
        await RisingEdge(dut.clk)
    dut.rst.value = 0
    started = time.perf_counter()
    limit = (config["beats"] + 10_000) * 4 * CLOCK_NS  # one beat a clock, a latency of tens of clocks: ample
    await with_timeout(RisingEdge(dut.done), limit, "ns")
    await Timer(CLOCK_NS, unit="ns")
    write_result({"beats": config["beats"], "seconds": time.perf_counter() - started})
