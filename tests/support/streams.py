"""Stream testbench helpers for Amaranth's simulator (the cocotb benches have their own, in
:mod:`sim.cocotb_benches.common`: cocotb drives the simulator differently).

:func:`stream_put` and :func:`stream_get` move one payload through a ``lib.stream`` interface,
as in Amaranth's stream documentation (and Glasgow's ``gateware/stream.py``); a payload is a
nested dict (:func:`sim.payloads.pack`) or its raw bits. :func:`stream_producer` and
:func:`stream_consumer` move whole streams of raw beats with seeded random valid/ready stalls,
record the clock edge of every transfer and check the transfer rules of ``lib.stream`` on the
device's output; :func:`run_streams` runs a pair against a device's ``i`` and ``o`` streams.

The rules (``amaranth.lib.stream``): a transfer happens at a clock edge where ``valid`` and
``ready`` are both high; once ``valid`` is asserted, neither it nor ``payload`` may change until
a transfer; ``valid`` must not wait for ``ready``. Clock edges are counted from 0, the first
edge after the streams start.

An ``always_ready=True`` stream's ``ready`` is the constant 1: every edge with ``valid`` high is a
transfer. The helpers read it as such and never drive it, so a device with such a stream (a
pipeline that never stalls) is tested as it is; asking its consumer to stall (``p_ready`` < 1,
``ready_after``) is refused with a :class:`ValueError`.
"""

from __future__ import annotations

import numbers
import random
from dataclasses import dataclass, field

from amaranth.back import verilog
from amaranth.hdl import Const, Value
from amaranth.sim import Simulator

from sim.payloads import pack, unpack

__all__ = ["stream_put", "stream_get", "StreamRun", "stream_producer", "stream_consumer", "run_testbenches",
           "run_streams"]


def _always_ready(stream) -> bool:
    return stream.signature.always_ready


def _bits(stream, payload) -> int:
    return int(payload) if isinstance(payload, numbers.Integral) else pack(stream.payload.shape(), payload)


async def stream_put(ctx, stream, payload) -> int:
    """Offer ``payload`` (a nested dict or raw bits) on ``stream`` until it is taken, holding
    ``valid`` and the payload meanwhile; ``valid`` is low again on return. Returns the number of
    clock edges it took (1: taken at the first)."""
    ctx.set(Value.cast(stream.payload), _bits(stream, payload))
    ctx.set(stream.valid, 1)
    edges = 1
    while not (await ctx.tick().sample(stream.ready))[2]:
        edges += 1
    ctx.set(stream.valid, 0)
    return edges


async def stream_get(ctx, stream):
    """Take one payload from ``stream`` (``ready`` high until a transfer, low again on return);
    the payload as a nested dict (:func:`sim.payloads.unpack`), an integer for a plain shape.

    On an always-ready stream ``ready`` is left alone: this is the next edge with ``valid`` high,
    and a beat offered before the call was already taken (by nobody), as in hardware.
    """
    always_ready = _always_ready(stream)
    if not always_ready:
        ctx.set(stream.ready, 1)
    raw, = await ctx.tick().sample(Value.cast(stream.payload)).until(stream.valid)
    if not always_ready:
        ctx.set(stream.ready, 0)
    return unpack(stream.payload.shape(), raw)


@dataclass
class StreamRun:
    """What a producer/consumer pair saw."""

    outputs: list = field(default_factory=list)  # raw output payloads, in order
    in_cycles: list = field(default_factory=list)  # clock edge of each input transfer
    out_cycles: list = field(default_factory=list)  # clock edge of each output transfer
    watched: dict = field(default_factory=dict)  # name -> the watched signal at every edge the consumer saw


def stream_producer(stream, beats, run: StreamRun, *, seed=0, p_valid=1.0, start=0):
    """A testbench that puts the raw ``beats`` on ``stream`` (the device's input) and records
    each transfer's edge in ``run.in_cycles``.

    The transfers of :func:`stream_put`, back to back: ``valid`` and the beat are held until
    taken, and ``valid`` stays high from one beat to the next. With ``p_valid`` < 1 each cycle
    without a beat on offer offers the next one with that probability (seeded), else leaves
    ``valid`` low with random bits on ``payload``. ``start`` edges pass before the first beat.
    """
    payload, valid_signal = Value.cast(stream.payload), stream.valid
    width = len(payload)

    async def producer(ctx):
        if not len(beats):
            return
        if start:
            await ctx.tick().repeat(start)
        rng = random.Random(seed)
        index, cycle, valid = 0, 0, False

        def offer():  # a cycle with no beat on offer: offer the next, or idle
            nonlocal valid
            offered = p_valid >= 1 or rng.random() < p_valid
            ctx.set(payload, beats[index] if offered else rng.getrandbits(width))
            if offered != valid:
                ctx.set(valid_signal, offered)
            valid = offered

        offer()
        async for _, _, ready in ctx.tick().sample(stream.ready):
            taken = valid and ready
            if taken:
                run.in_cycles.append(cycle)
                index += 1
                if index == len(beats):
                    ctx.set(valid_signal, 0)
                    return
            cycle += 1
            if taken or not valid:
                offer()

    return producer


def stream_consumer(stream, n_out, run: StreamRun, *, seed=1, p_ready=1.0, ready_after=0, start=0, drain=0,
                    max_cycles=None, watch=None, probe_ready=False):
    """A testbench that takes ``n_out`` raw payloads from ``stream`` (the device's output) into
    ``run.outputs``, recording each transfer's edge in ``run.out_cycles``.

    ``ready`` is random (seeded) with probability ``p_ready``, low for the first ``ready_after``
    cycles, and high once all ``n_out`` are in; ``drain`` more edges are then watched for an
    output too many. Checked at every edge: a payload offered and not taken is offered again,
    unchanged; no more than ``n_out`` outputs; fewer than ``max_cycles`` edges. With
    ``probe_ready``, also that ``valid`` and ``payload`` do not depend on ``ready`` (flipped and
    restored before every edge). ``watch`` (name -> signal) records signals at every edge in
    ``run.watched``.

    On an always-ready stream ``ready`` is not driven and every edge with ``valid`` high is a
    transfer; ``p_ready`` < 1 or ``ready_after`` > 0 raise :class:`ValueError`, and ``probe_ready``
    holds trivially.
    """
    always_ready = _always_ready(stream)
    if always_ready and (p_ready < 1 or ready_after > 0):
        raise ValueError(f"stream_consumer: the stream is always ready (ready is the constant 1): every valid beat "
                         f"is taken, it cannot stall (p_ready={p_ready}, ready_after={ready_after}); "
                         f"use p_ready=1, ready_after=0")
    watch = dict(watch or {})
    payload, valid_signal, ready_signal = Value.cast(stream.payload), stream.valid, stream.ready
    run.watched.update({name: [] for name in watch})

    async def consumer(ctx):
        if start:
            await ctx.tick().repeat(start)
        rng = random.Random(seed)
        held, cycle, ready = None, 0, None

        def offer_ready():
            if always_ready:
                return True
            new = cycle >= ready_after and (len(run.outputs) >= n_out or p_ready >= 1 or rng.random() < p_ready)
            if new != ready:
                ctx.set(ready_signal, new)
            if probe_ready:
                seen = ctx.get(valid_signal), ctx.get(payload)
                ctx.set(ready_signal, not new)
                assert (ctx.get(valid_signal), ctx.get(payload)) == seen, f"edge {cycle}: valid/payload depend on ready"
                ctx.set(ready_signal, new)
            return new

        ready = offer_ready()
        async for _, _, valid, value, *watched in ctx.tick().sample(valid_signal, payload, *watch.values()):
            for name, sample in zip(watch, watched):
                run.watched[name].append(sample)
            if held is not None:
                assert valid and value == held, f"edge {cycle}: an offered payload was withdrawn or changed"
            if valid and ready:
                assert len(run.outputs) < n_out, f"edge {cycle}: more than the {n_out} outputs expected"
                run.outputs.append(value)
                run.out_cycles.append(cycle)
            held = value if valid and not ready else None
            cycle += 1
            assert max_cycles is None or cycle < max_cycles, f"no progress: {len(run.outputs)} of {n_out} outputs"
            if len(run.outputs) >= n_out and cycle > (run.out_cycles[-1] if run.out_cycles else 0) + drain:
                return
            ready = offer_ready()

    return consumer


def run_testbenches(dut, *testbenches) -> None:
    """Simulate ``dut`` (its ``sync`` clock at 100 MHz) until every testbench has returned."""
    sim = Simulator(dut)
    sim.add_clock(1e-8)
    for testbench in testbenches:
        sim.add_testbench(testbench)
    sim.run()


def run_streams(dut, beats, n_out=None, *, seed=0, p_valid=1.0, p_ready=1.0, ready_after=0, start=0,
                setup=None, watch=None, probe_ready=False, one_at_a_time=False) -> StreamRun:
    """Simulate ``dut``: :func:`stream_producer` on ``dut.i``, :func:`stream_consumer` on ``dut.o``.

    ``n_out`` (default: one output per beat) outputs are collected, then ``dut.latency + 2`` more
    edges watched; the consumer's seed is ``seed + 1``. Either stream may be always ready
    (:func:`stream_consumer` refuses stalls on an always-ready ``o``). ``setup(ctx)``, if given, runs at time 0
    (constant inputs; the streams wait ``start`` edges). ``one_at_a_time``: the device takes a beat only
    once the last one's output is out (its progress budget is ``latency`` per beat). Returns the run once
    every beat went in and every output came out.
    """
    n_out = len(beats) if n_out is None else n_out
    run = StreamRun()
    per_beat = dut.latency + 1 if one_at_a_time else 1
    max_cycles = int(4 * (len(beats) * per_beat + dut.latency) / (p_valid * p_ready)) + 200 + ready_after
    testbenches = []
    if setup is not None:
        async def setup_bench(ctx):
            setup(ctx)
        testbenches.append(setup_bench)
    run_testbenches(dut, *testbenches,
                    stream_producer(dut.i, beats, run, seed=seed, p_valid=p_valid, start=start),
                    stream_consumer(dut.o, n_out, run, seed=seed + 1, p_ready=p_ready, ready_after=ready_after,
                                    start=start, drain=dut.latency + 2, max_cycles=max_cycles, watch=watch,
                                    probe_ready=probe_ready))
    assert len(run.in_cycles) == len(beats) and len(run.outputs) == n_out
    return run


def top_level_verilog(dut, name: str) -> str:
    """``dut`` converted to Verilog as the top module ``name``, its ports the signature's members less the
    constant ones (an ``always_ready`` stream's ``ready``; amaranth-lang/amaranth#1574)."""
    ports = [Value.cast(v) for _, _, v in dut.signature.flatten(dut) if not isinstance(v, Const)]
    return verilog.convert(dut, name=name, ports=ports)
