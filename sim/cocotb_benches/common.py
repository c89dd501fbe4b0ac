"""Clock, reset, configuration and a cycle-accurate stream driver for the benches."""

from __future__ import annotations

import json
import os
import random
import sys
from dataclasses import dataclass, field

from cocotb.clock import Clock
from cocotb.triggers import FallingEdge, ReadOnly, RisingEdge

from golden_model.fixed import FormatSet

CLOCK_NS = 10


def load_config() -> dict:
    with open(os.environ["SPRINGFLAT_BENCH_CONFIG"]) as f:
        return json.load(f)


def formats(config: dict) -> FormatSet:
    return FormatSet.from_dict(config["formats"])


def rewritten_modules() -> list[str]:
    """The loaded modules whose ``assert`` statements pytest rewrote (``COCOTB_REWRITE_ASSERTION_FILES``,
    :data:`sim.cocotb_support.REWRITE_ASSERTION_FILES`): the benches, nothing they import."""
    return sorted(name for name, module in list(sys.modules.items())
                  if type(getattr(getattr(module, "__spec__", None), "loader", None)).__name__
                  == "AssertionRewritingHook")


def write_result(result: dict) -> None:
    with open(os.environ["SPRINGFLAT_BENCH_RESULT"], "w") as f:
        json.dump({**result, "rewritten_modules": rewritten_modules()}, f, indent=1)


async def start_clock_and_reset(dut, idle: tuple[str, ...] = (), cycles: int = 3) -> None:
    """Start the clock and reset; the ``idle`` inputs are driven low from the start.

    An undriven ``valid`` is X in a 4-state simulator and can be taken as a beat.
    """
    for name in idle:
        getattr(dut, name).value = 0
    Clock(dut.clk, CLOCK_NS, unit="ns").start()
    dut.rst.value = 1
    for _ in range(cycles):
        await RisingEdge(dut.clk)
    dut.rst.value = 0


@dataclass
class StreamStats:
    cycles: int = 0
    in_cycles: list[int] = field(default_factory=list)
    out_cycles: list[int] = field(default_factory=list)


class StreamPort:
    """The ``<name>__valid/ready/payload`` signals of one stream port."""

    def __init__(self, dut, name: str):
        self.valid = getattr(dut, f"{name}__valid")
        self.ready = getattr(dut, f"{name}__ready")
        self.payload = getattr(dut, f"{name}__payload")


async def transfer(dut, source: StreamPort, sink: StreamPort, beats: list[int], n_out: int, *,
                   rng: random.Random | None = None, p_valid: float = 1.0, p_ready: float = 1.0,
                   stop_after: int | None = None, stats: StreamStats | None = None) -> list[int]:
    """Drive ``beats`` into ``source`` and collect ``n_out`` payloads from ``sink``, one clock at a time.

    With ``p_valid``/``p_ready`` < 1 each clock's valid/ready is random; the sink
    checks that an offered payload is never withdrawn or changed. ``stop_after``
    returns early after that many clocks (for a reset in the middle of a stream).
    """
    rng = rng or random.Random(0)
    stats = stats if stats is not None else StreamStats()
    if p_valid >= 1 and p_ready >= 1 and stop_after is None:
        return await _transfer_unstalled(dut, source, sink, beats, n_out, stats)
    outputs: list[int] = []
    index, cycle, held = 0, 0, None
    width = len(source.payload)
    limit = 20 * (len(beats) + 200) / max(p_valid * p_ready, 0.05)
    while index < len(beats) or len(outputs) < n_out:
        valid = index < len(beats) and (p_valid >= 1 or rng.random() < p_valid)
        source.valid.value = int(valid)
        source.payload.value = beats[index] if valid else rng.getrandbits(width)
        ready = p_ready >= 1 or rng.random() < p_ready
        sink.ready.value = int(ready)
        await ReadOnly()
        offered = bool(int(sink.valid.value))
        if held is not None:
            assert offered and int(sink.payload.value) == held, f"clock {cycle}: an offered payload was withdrawn"
        if valid and int(source.ready.value):
            index += 1
            stats.in_cycles.append(stats.cycles)
        if offered and ready:
            assert len(outputs) < n_out, f"clock {cycle}: more outputs than expected"
            outputs.append(int(sink.payload.value))
            stats.out_cycles.append(stats.cycles)
        held = int(sink.payload.value) if offered and not ready else None
        await RisingEdge(dut.clk)
        cycle += 1
        stats.cycles += 1
        if stop_after is not None and cycle >= stop_after:
            break
        assert cycle < limit, f"no progress after {cycle} clocks: {index}/{len(beats)} in, {len(outputs)}/{n_out} out"
    source.valid.value = 0
    return outputs


async def _transfer_unstalled(dut, source: StreamPort, sink: StreamPort, beats: list[int], n_out: int,
                              stats: StreamStats) -> list[int]:
    """:func:`transfer` without stalls, with one trigger per clock.

    With ``sink.ready`` held high, the source's ``ready`` depends only on the DUT's
    registers (it depends on nothing driven here), and the sink's valid/payload are registers: all
    are settled at the falling edge, where both the sample for the next rising
    edge and the beat to present at it are decided. Payloads are written only when
    they change.
    """
    outputs: list[int] = []
    sink.ready.value = 1
    index, presented, ready_at_edge, cycle = 0, False, False, 0
    limit = 20 * (len(beats) + 200)
    while index < len(beats) or len(outputs) < n_out:
        await FallingEdge(dut.clk)
        if presented and ready_at_edge:  # sampled at the previous falling edge: taken at the rising edge since
            index += 1
            stats.in_cycles.append(stats.cycles - 1)
            presented = False
        if not presented and index < len(beats):
            source.payload.value = beats[index]
            source.valid.value = 1
            presented = True
        elif not presented:
            source.valid.value = 0
        ready_at_edge = bool(int(source.ready.value))
        if int(sink.valid.value):  # taken at the next rising edge (ready is high)
            assert len(outputs) < n_out, f"clock {cycle}: more outputs than expected"
            outputs.append(int(sink.payload.value))
            stats.out_cycles.append(stats.cycles)
        cycle += 1
        stats.cycles += 1
        assert cycle < limit, f"no progress after {cycle} clocks: {index}/{len(beats)} in, {len(outputs)}/{n_out} out"
    await RisingEdge(dut.clk)  # the last beats transfer on this edge
    source.valid.value = 0
    return outputs
