"""``hdl.pipeline``'s delay lines against rows of registers: the same value in every clock, valid or not."""

import numpy as np
import pytest
from amaranth.hdl import Module, Signal, signed
from amaranth.sim import Simulator

from hdl.dsp import ECP5
from hdl.pipeline import LiveValues, Pipeline


def _run(m: Module, inputs: dict, outputs: dict, feed: dict[str, list[int]], clocks: int) -> dict[str, list[int]]:
    """Drive ``inputs`` from ``feed`` a clock at a time; the values of ``outputs`` after each clock."""
    seen = {name: [] for name in outputs}
    sim = Simulator(m)
    sim.add_clock(1e-6)

    async def bench(ctx):
        for t in range(clocks):
            for name, signal in inputs.items():
                ctx.set(signal, feed[name][t])
            await ctx.tick()
            for name, signal in outputs.items():
                seen[name].append(ctx.get(signal))

    sim.add_testbench(bench)
    sim.run()
    return seen


@pytest.mark.parametrize("stalls", [False, True], ids=["free-running", "stalling"])
def test_a_delay_line_is_a_row_of_registers(stalls):
    """Every length from 1 to 40 clocks (registers below ``LUT_DELAY_MIN``, memories of 4 to 64 words above),
    signed and unsigned, with ``advance`` low at random: each delay line shows what the same number of
    registers in a row shows, from the first clock on."""
    rng = np.random.default_rng(7)
    clocks = 200
    m = Module()
    data, advance = Signal(signed(13)), Signal(init=1)
    outputs = {}
    for n in range(1, 41):
        lines = Pipeline(m, Signal(), advance=advance if stalls else None)
        registers = Pipeline(m, Signal(), advance=advance if stalls else None)
        outputs[f"line{n}"] = lines.delayed(data, n, f"line{n}")
        row = data
        for i in range(n):
            row = registers.keep(row, f"row{n}_{i}")
        outputs[f"row{n}"] = row
    feed = {"data": rng.integers(-(1 << 12), 1 << 12, clocks).tolist(),
            "advance": (rng.random(clocks) < 0.7).astype(int).tolist() if stalls else [1] * clocks}
    seen = _run(m, {"data": data, "advance": advance}, outputs, feed, clocks)
    for n in range(1, 41):
        assert seen[f"line{n}"] == seen[f"row{n}"], n
        assert any(seen[f"row{n}"]), n  # the row did carry data


def test_live_values_carry_through_delay_lines_as_through_registers():
    """A value carried through 20 stages, read in the middle and at the end, a second one new in stage 6
    and a third dropped unread, and a stage that carries nothing: with delay lines each read gives what the
    register-per-carry build gives (the delays count carries, not stages), and the build has memories
    only with delay lines."""
    rng = np.random.default_rng(3)
    clocks = 120
    builds = {}
    for lines in (False, True):
        m = Module()
        a, b = Signal(8, name="a"), Signal(8, name="b")
        live, pipe = LiveValues(), Pipeline(m, Signal(), delay_lines=lines, platform=ECP5)
        live.step(pipe, "s1", a=a, dropped=b)
        for k in range(2, 6):
            live.step(pipe, f"s{k}")
        live.step(pipe, "s6", drop=("dropped",), b=b + live["a"])  # a read after five stages
        pipe.stage("bare")  # (a stage whose registers are not the live values')
        for k in range(7, 21):
            live.step(pipe, f"s{k}")
        builds[lines] = (m, {"a": a, "b": b}, {"a_end": live["a"], "b_end": live["b"]})
    feed = {"a": rng.integers(0, 256, clocks).tolist(), "b": rng.integers(0, 256, clocks).tolist()}
    seen = {lines: _run(m, inputs, outputs, feed, clocks) for lines, (m, inputs, outputs) in builds.items()}
    assert seen[True] == seen[False]
    assert seen[False]["a_end"][19:] == feed["a"][:clocks - 19]  # 20 registers: after clock t, a of clock t − 19
    memories = {lines: [name for name, _ in m._named_submodules.items() if name.endswith("_delay_line")]
                for lines, (m, _, _) in builds.items()}
    assert memories[False] == [] and len(memories[True]) == 3, memories  # a up to s5, a s5 to s20, b s6 to s20
