"""The harness alone: how fast the engine bench's clock and wait run a model that does almost nothing.

``harness_probe`` (``sim/engine_run.py``: a counter that raises ``irq`` after ``cycles`` clocks) under the
engine bench's clock (cocotb's GPI clock, ``impl="gpi"``) and its wait (one trigger on ``irq``): its simulated
cycles per second are the ceiling the harness sets on any model (``sim.engine_run.harness_ceiling``).
"""

from __future__ import annotations

import time

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import FallingEdge, RisingEdge, Timer

from .common import CLOCK_NS, load_config, write_result


@cocotb.test()
async def harness_ceiling(dut):
    """Clock, reset, then one wait on ``irq``; the wall time of the wait."""
    config = load_config()
    if not config.get("internal_clock"):  # else the harness makes its own
        Clock(dut.clk, CLOCK_NS, unit="ns", impl="gpi").start()
    dut.rst.value = 1
    await Timer(3 * CLOCK_NS, unit="ns")
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    started = time.perf_counter()
    await RisingEdge(dut.irq)
    seconds = time.perf_counter() - started
    write_result({"cycles": config["cycles"], "seconds": seconds, "cycles_per_second": config["cycles"] / seconds})
