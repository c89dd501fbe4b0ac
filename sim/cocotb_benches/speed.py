"""The simulator's own speed: the core kept busy with no Python per clock."""

from __future__ import annotations

import time

import cocotb
from cocotb.triggers import ClockCycles

from hdl.layouts import entry_layout
from sim.payloads import pack

from .common import formats, load_config, start_clock_and_reset, write_result
from .node_update import load_problem


@cocotb.test()
async def raw_speed(dut):
    """The simulator alone: the core kept busy by constant beats, no Python per clock."""
    config = load_config()
    fs = formats(config)
    problem = load_problem(config, fs)
    await start_clock_and_reset(dut, idle=("entries__valid", "results__ready", "errors__valid", "step_load__valid",
                                           "measure", "momentum"))
    dut.half_spring.value = problem.half_spring
    dut.damping.value = problem.damping
    layout = entry_layout(fs)
    one_node = pack(layout, {"first": 1, "last": 1, "node": {"inv_mass": int(problem.stream.inv_mass[0])},
                             "neighbour": {"rest": int(problem.stream.rest[0]),
                                           "position": {"x": int(problem.initial_positions[1, 0]),
                                                        "y": int(problem.initial_positions[1, 1])}}})
    dut.entries__payload.value = one_node  # a node of degree 1, over and over: the pipeline stays full
    dut.entries__valid.value = 1
    dut.results__ready.value = 1
    cycles = int(config.get("cycles", 20000))
    started = time.perf_counter()
    await ClockCycles(dut.clk, cycles)
    wall = time.perf_counter() - started
    write_result({"cycles": cycles, "bench_seconds": wall, "cycles_per_second": cycles / wall})
