"""Closed-loop flattening through the RTL: the core computes every node update and every step size.

The Python side plays the hardware-side controller exactly as the golden model
defines it (``golden_model.fixed.engine``): it streams the CSR neighbour lists,
collects the updated state, forms E_S and E_C from the RTL's results, feeds
them to the RTL step generator and applies the stopping rule. Each iteration
runs a measuring pass (``measure`` = 1: nothing moves, the E_C partial sums of
the current layout come out) and an update pass. Every iteration's state and
errors are compared bit for bit with the golden model running alongside.
"""

from __future__ import annotations

import random
import time

import cocotb
import numpy as np
from cocotb.triggers import ReadOnly, RisingEdge

from golden_model.fixed import SaturationCounter, half_dt_sq, quantize, to_float
from golden_model.fixed.engine import HOST_ROUNDING, FixedEngine, StopRule, energy_to_float, flipped_count, folded_count
from golden_model.fixed.measures import MomentumState, area_error, power_sum, shape_error
from golden_model.fixed.format import Overflow
from golden_model.modes import Step
from golden_model.results import Measurement
from hdl.layouts import entry_layout, errors_layout, result_layout, step_layout
from sim.payloads import pack, pass_beats, unpack, unpack_beats

from .common import StreamPort, StreamStats, formats, load_config, start_clock_and_reset, transfer, write_result
from .node_update import load_problem


class Controller:
    """Drives ``springflat_core``; keeps the RTL's state as raw arrays."""

    def __init__(self, dut, problem, config):
        self.dut, self.problem, self.fs = dut, problem, problem.fs
        self.rng = random.Random(config.get("seed", 0))
        self.p_valid, self.p_ready = config.get("p_valid", 1.0), config.get("p_ready", 1.0)
        self.entries, self.results = StreamPort(dut, "entries"), StreamPort(dut, "results")
        self.in_layout, self.out_layout = entry_layout(self.fs), result_layout(self.fs)
        self.positions = problem.initial_positions.copy()
        self.velocities = np.zeros_like(self.positions)
        self.stats = StreamStats()
        self.momentum = MomentumState()
        self.power = 0

    async def run_pass(self, measure: bool):
        """One pass over every node; returns (positions, velocities, error_sums, power) from the RTL."""
        self.dut.measure.value = int(measure)
        await RisingEdge(self.dut.clk)
        beats = pass_beats(self.in_layout, self.problem.stream, self.positions, self.velocities)
        out = await transfer(self.dut, self.entries, self.results, beats, self.problem.mesh.n_vertices,
                             rng=self.rng, p_valid=self.p_valid, p_ready=self.p_ready, stats=self.stats)
        # every result taken: the pass is done, and the core says so
        await ReadOnly()
        assert int(self.dut.idle.value) == 1, "all results taken but the core is not idle"
        await RisingEdge(self.dut.clk)
        got = unpack_beats(self.out_layout, out)
        positions = np.column_stack([got["position"]["x"], got["position"]["y"]])
        velocities = np.column_stack([got["velocity"]["x"], got["velocity"]["y"]])
        return positions, velocities, got["error_sum"], got["power"]

    async def measure(self, energy: int):
        """E_S, E_C (raw) and fold counts of the current layout, formed from RTL results.

        ``energy`` is the stopping rule's :func:`energy_raw` of this layout: the RTL does not form
        ``Σe²`` or ``c·h`` yet, so it comes from the golden model's pass over the same positions
        (checked equal to the RTL's every iteration) rather than from a second host-side pass."""
        positions, velocities, error_sums, power = await self.run_pass(measure=True)
        moved = not (np.array_equal(positions, self.positions) and np.array_equal(velocities, self.velocities))
        p = self.problem
        e_s = area_error(p.fs, p.area_reciprocal, p.mesh.faces, p.face_areas, self.positions)
        e_c = shape_error(p.fs, p.length_reciprocal, error_sums)
        self.energy_raw = energy
        m = Measurement(float(to_float(e_s, p.fs.error)), float(to_float(e_c, p.fs.error)), energy_to_float(p, energy),
                        flipped_count(p, self.positions), folded_count(p, self.positions))
        self.node_power = power
        self.power = power_sum(p.fs, power)
        return (e_s, e_c), m, error_sums, moved

    async def set_step(self, errors):
        """Variable step: the RTL step generator; fixed step: load Δt and ½Δt² directly;
        momentum: load β_k (the controller's counter and restart) into the Δt register."""
        dut, fs = self.dut, self.fs
        step = self.problem.params.mode.step
        if step is not Step.VARIABLE:
            if step is Step.MOMENTUM:
                dt, self.momentum = self.momentum.next(self.power, fs)
                half = 0
            else:
                dt = int(quantize(self.problem.params.dt, fs.dt, HOST_ROUNDING, Overflow.SATURATE))
                half = int(half_dt_sq(dt, fs))
            dut.step_load__payload.value = pack(step_layout(fs), {"dt": dt, "half_dt_sq": half})
            dut.step_load__valid.value = 1
            await RisingEdge(dut.clk)
            dut.step_load__valid.value = 0
        else:
            dut.errors__payload.value = pack(errors_layout(fs), {"area_error": errors[0], "shape_error": errors[1]})
            dut.errors__valid.value = 1
            await RisingEdge(dut.clk)
            while not int(dut.errors__ready.value):
                await RisingEdge(dut.clk)
            dut.errors__valid.value = 0
            waited = 0  # the step registers say when they hold the answer
            while True:
                await ReadOnly()
                if int(dut.step_valid.value):
                    break
                await RisingEdge(dut.clk)
                waited += 1
            assert waited == self.dut_step_latency - 1, f"step_valid after {waited} clocks"
        await RisingEdge(dut.clk)
        step = unpack(step_layout(fs), int(dut.step.value))
        return step["dt"], step["half_dt_sq"]


@cocotb.test()
async def closed_loop(dut):
    config = load_config()
    fs = formats(config)
    problem = load_problem(config, fs)
    params = problem.params
    golden = FixedEngine(problem, SaturationCounter())
    ctl = Controller(dut, problem, config)
    ctl.dut_step_latency = int(config["step_latency"])
    await start_clock_and_reset(dut, idle=("entries__valid", "results__ready", "errors__valid", "step_load__valid",
                                           "measure", "momentum"))
    dut.half_spring.value = problem.half_spring
    dut.damping.value = problem.damping
    momentum = params.mode.step is Step.MOMENTUM
    dut.momentum.value = int(momentum)
    started = time.perf_counter()

    mismatches: list[str] = []

    def check(iteration: int, what: str, rtl, gold) -> None:
        rtl, gold = np.asarray(rtl), np.asarray(gold)
        if not np.array_equal(rtl, gold):
            where = np.argwhere(rtl != gold)
            node = tuple(int(v) for v in where[0])
            mismatches.append(f"iteration {iteration}: {what} differs at {len(where)} places; first at "
                              f"node/index {node}: rtl {int(rtl[node])} golden {int(gold[node])}")

    gold_current = golden.measure()
    errors, current, error_sums, moved = await ctl.measure(golden.energy_raw)
    check(0, "error_sums", error_sums, golden.terms.error_sums)
    check(0, "E_S/E_C", errors, golden.errors)
    if momentum:
        check(0, "power", ctl.node_power, golden.node_power)
    history = [current]
    rule = StopRule.of(params, problem.fs)  # the golden model's integer stopping rule
    energy_before = ctl.energy_raw
    status, k = "max-iterations", 0
    max_iter = min(params.max_iter, config.get("iterations") or params.max_iter)
    while k < max_iter:
        dt, half = await ctl.set_step(errors)
        golden.step_size(gold_current)
        check(k + 1, "dt", dt, golden.dt)
        if not momentum:
            check(k + 1, "half_dt_sq", half, problem.constants(golden.dt).half_dt_sq)
        if config.get("broken_expectation") and k == 1:  # the bench must be able to fail
            golden.raw_velocities[0, 0] += 1
        ctl.positions, ctl.velocities, _, _ = await ctl.run_pass(measure=False)
        golden.advance(0)
        check(k + 1, "positions", ctl.positions, golden.raw_positions)
        check(k + 1, "velocities", ctl.velocities, golden.raw_velocities)
        gold_after = golden.measure()
        errors, after, error_sums, moved = await ctl.measure(golden.energy_raw)
        check(k + 1, "error_sums", error_sums, golden.terms.error_sums)
        if momentum:
            check(k + 1, "power", ctl.node_power, golden.node_power)
        if moved:
            mismatches.append(f"iteration {k + 1}: the measuring pass moved a node")
        k += 1
        history.append(after)
        if rule.converged(energy_before, ctl.energy_raw, errors):
            status = "converged"
            break
        current, gold_current, energy_before = after, gold_after, ctl.energy_raw
    wall = time.perf_counter() - started

    from golden_model.reference import flatten
    reference = flatten(problem.mesh, config_initial(problem, config), params.with_(max_iter=max_iter))
    write_result({
        "mismatches": len(mismatches), "first_mismatches": mismatches[:10], "iterations": k, "status": status,
        "area_error": history[-1].area_error, "shape_error": history[-1].shape_error,
        "initial_area_error": history[0].area_error, "initial_shape_error": history[0].shape_error,
        "float_status": reference.status, "float_iterations": reference.iterations,
        "float_area_error": reference.final.area_error, "float_shape_error": reference.final.shape_error,
        "cycles": ctl.stats.cycles, "bench_seconds": wall, "cycles_per_second": ctl.stats.cycles / wall,
        "nodes": problem.mesh.n_vertices, "entries": int(len(problem.stream.neighbour)),
        "dynamics": params.dynamics, "barrier": params.barrier, "folded": history[-1].folded,
    })
    assert not mismatches, f"{len(mismatches)} mismatches; first: {mismatches[0]}"


def config_initial(problem, config):
    """The float P0 the problem was built from (the same layout the float reference starts at)."""
    from sim.layouts import initial_layout

    return initial_layout(problem.mesh, config.get("init", "tutte"))

