"""Benches of the rsqrt unit and the step generator against the golden model."""

from __future__ import annotations

import random

import cocotb
import numpy as np
from cocotb.triggers import RisingEdge

from golden_model.fixed import rsqrt_with_config, step_size
from hdl import RsqrtUnit, StepGenerator
from sim.payloads import pack_beats, unpack_beats

from .common import StreamPort, formats, load_config, start_clock_and_reset, transfer, write_result


def rsqrt_inputs(cfg, n: int, seed: int) -> np.ndarray:
    """Boundaries (0, 1, max, powers of two ±1) and log-uniform random inputs."""
    top = cfg.fmt_in.raw_max
    powers = [1 << k for k in range(cfg.fmt_in.width)]
    special = {0, 1, 2, 3, top - 1, top} | {p + d for p in powers for d in (-1, 0, 1)}
    rng = np.random.default_rng(seed)
    random_values = np.exp2(rng.uniform(0, np.log2(float(top)), n)).astype(np.int64)
    values = np.array(sorted(v for v in special if 0 <= v <= top), dtype=np.int64)
    return np.clip(np.concatenate([values, random_values]), 0, top)


async def _check(dut, beats, expected: dict, layout, config, what: str):
    rng = random.Random(config.get("seed", 0))
    p_valid, p_ready = config.get("p_valid", 0.8), config.get("p_ready", 0.8)
    source, sink = StreamPort(dut, "i"), StreamPort(dut, "o")
    # a reset in the middle of the stream: everything in flight is dropped, then the whole stream again
    await transfer(dut, source, sink, beats, len(beats), rng=rng, p_valid=p_valid, p_ready=p_ready,
                   stop_after=min(40, len(beats)))
    dut.rst.value = 1
    await RisingEdge(dut.clk)
    await RisingEdge(dut.clk)
    dut.rst.value = 0
    outputs = await transfer(dut, source, sink, beats, len(beats), rng=rng, p_valid=p_valid, p_ready=p_ready)
    problems = []
    fields = unpack_beats(layout, outputs)
    for name, want in expected.items():
        got = fields[name]
        problems += [f"{what}: field '{name}', input #{int(i)}: rtl {int(got[i])} golden {int(want[i])}"
                     for i in np.flatnonzero(got != want)]
    return problems


@cocotb.test()
async def rsqrt_unit(dut):
    """Boundaries and random inputs, random stalls, a reset mid-stream; every output bit-exact."""
    config = load_config()
    fs = formats(config)
    cfg = fs.rsqrt_config()
    await start_clock_and_reset(dut, idle=("i__valid", "o__ready"))
    x = rsqrt_inputs(cfg, config.get("n", 1500), config.get("seed", 0))
    want = rsqrt_with_config(x, cfg)
    if config.get("broken_expectation"):  # a deliberately wrong golden value: the bench must fail
        want = want.copy()
        want[len(want) // 2] += 1
    layout = RsqrtUnit.output_layout(cfg)
    problems = await _check(dut, [int(v) for v in x], {"rsqrt": want}, layout, config, "rsqrt_unit")
    write_result({"inputs": len(x), "mismatches": len(problems), "first_mismatches": problems[:10]})
    assert not problems, f"{len(problems)} mismatches; first: {problems[0]}"


@cocotb.test()
async def step_generator(dut):
    """Every error value on each lane (the other fixed), random pairs; stalls and a reset mid-stream."""
    config = load_config()
    fs = formats(config)
    await start_clock_and_reset(dut, idle=("i__valid", "o__ready"))
    rng = np.random.default_rng(config.get("seed", 0))
    top = fs.error.raw_max
    n = config.get("n", 1500)
    lane = np.unique(np.concatenate([np.linspace(0, top, n // 2, dtype=np.int64), [0, 1, top - 1, top]]))
    area = np.concatenate([lane, rng.integers(0, top + 1, n // 2), np.full(len(lane), top // 3)])
    shape = np.concatenate([np.full(len(lane), top // 2), rng.integers(0, top + 1, n // 2), lane])
    layout_in, layout_out = StepGenerator.input_layout(fs), StepGenerator.output_layout(fs)
    beats = pack_beats(layout_in, {"area_error": area, "shape_error": shape})
    dt, half = step_size(area, shape, fs)
    if config.get("broken_expectation"):
        dt = dt.copy()
        dt[3] ^= 1
    problems = await _check(dut, beats, {"dt": dt, "half_dt_sq": half}, layout_out, config, "step_generator")
    write_result({"inputs": len(area), "mismatches": len(problems), "first_mismatches": problems[:10]})
    assert not problems, f"{len(problems)} mismatches; first: {problems[0]}"
