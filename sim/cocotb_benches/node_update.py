"""Bench of the node-update datapath: every node of a mesh over several iterations, bit for bit."""

from __future__ import annotations

import random

import cocotb
import numpy as np
from cocotb.triggers import RisingEdge

from golden_model.fixed import SaturationCounter
from golden_model.fixed.engine import FixedEngine, prepare
from golden_model.fixed.pipeline import node_update
from golden_model.params import FlattenParams
from hdl.layouts import entry_layout, result_layout
from sim.payloads import pass_beats, unpack_beats

from .common import StreamPort, StreamStats, formats, load_config, start_clock_and_reset, transfer, write_result


def compare(outputs: list[int], want, layout, iteration: int) -> list[str]:
    """Every differing (node, field), as readable lines."""
    got = unpack_beats(layout, outputs)
    fields = (("position.x", got["position"]["x"], want.positions[:, 0]),
              ("position.y", got["position"]["y"], want.positions[:, 1]),
              ("velocity.x", got["velocity"]["x"], want.velocities[:, 0]),
              ("velocity.y", got["velocity"]["y"], want.velocities[:, 1]),
              ("error_sum", got["error_sum"], want.error_sums))
    problems = []
    for name, rtl, golden in fields:
        for node in np.flatnonzero(rtl != golden):
            problems.append(f"iteration {iteration}, node {int(node)}, field {name}: "
                            f"rtl {int(rtl[node])} golden {int(golden[node])}")
    return problems


def load_problem(config, fs):
    from golden_model.builtin import builtin_mesh, is_builtin
    from sim.layouts import initial_layout
    from golden_model.mesh import Holes
    from sim.mesh_io import load_mesh_with_notes

    name = config.get("mesh", "surf2")  # a file read as the command read it: its holes refused, filled or kept
    holes = Holes(config.get("holes", Holes.REFUSE.value))
    mesh = builtin_mesh(name)[0] if is_builtin(name) else load_mesh_with_notes(name, holes=holes)[0]
    params = FlattenParams(**config.get("params", {"density": 2.0, "damping": 0.02}))
    return prepare(mesh, initial_layout(mesh, config.get("init", "tutte")), params, fs)


@cocotb.test()
async def node_update_passes(dut):
    """Several iterations of a fixed-point flattening, every node compared; stalls and a reset mid-stream."""
    config = load_config()
    fs = formats(config)
    problem = load_problem(config, fs)
    engine = FixedEngine(problem, SaturationCounter())
    in_layout, out_layout = entry_layout(fs), result_layout(fs)
    rng = random.Random(config.get("seed", 0))
    p_valid, p_ready = config.get("p_valid", 0.8), config.get("p_ready", 0.8)
    source, sink = StreamPort(dut, "i"), StreamPort(dut, "o")
    await start_clock_and_reset(dut, idle=("i__valid", "o__ready", "momentum"))
    dut.half_spring.value = problem.half_spring
    dut.damping.value = problem.damping
    stats, problems = StreamStats(), []
    n_nodes = problem.mesh.n_vertices
    for iteration in range(config.get("iterations", 4)):
        engine.step_size(engine.measure())
        constants = problem.constants(engine.dt)
        dut.dt.value, dut.half_dt_sq.value = constants.dt, constants.half_dt_sq
        await RisingEdge(dut.clk)  # the constants are registered
        beats = pass_beats(in_layout, problem.stream, engine.raw_positions, engine.raw_velocities)
        if iteration == 1:  # reset in the middle of the pass, then the whole pass again
            await transfer(dut, source, sink, beats, n_nodes, rng=rng, p_valid=p_valid, p_ready=p_ready,
                           stop_after=len(beats) // 2, stats=stats)
            dut.rst.value = 1
            await RisingEdge(dut.clk)
            dut.rst.value = 0
            await RisingEdge(dut.clk)
        outputs = await transfer(dut, source, sink, beats, n_nodes, rng=rng, p_valid=p_valid, p_ready=p_ready,
                                 stats=stats)
        want = node_update(fs, engine.raw_positions, engine.raw_velocities, problem.stream, constants)
        if config.get("broken_expectation") and iteration == 2:  # the bench must be able to fail
            want.positions[3, 1] += 1
        problems += compare(outputs, want, out_layout, iteration)
        engine.advance(0)
    write_result({"mismatches": len(problems), "first_mismatches": problems[:10], "cycles": stats.cycles})
    assert not problems, f"{len(problems)} mismatches; first: {problems[0]}"
