"""tests/support/streams.py on toy devices: a one-register stage that keeps the stream rules, and
faulty copies of it that each break one; the helpers must pass the first and catch the others."""

import gc
import warnings

import pytest
from amaranth.hdl import Module, Signal, UnusedElaboratable, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from support.streams import StreamRun, run_streams, run_testbenches, stream_get, stream_producer, stream_put

PAYLOAD = data.StructLayout({"a": signed(6), "b": data.StructLayout({"c": unsigned(3)})})


class Stage(wiring.Component):
    """``o`` is ``i`` one clock later (a register, ready when empty or being emptied).

    ``fault`` breaks it: ``"valid_needs_ready"`` shows ``o.valid`` only while ``o.ready`` is high,
    ``"withdraw"`` drops an output not taken at once, ``"change"`` changes it while it waits,
    ``"twice"`` offers the first output again after it was taken.
    """

    latency = 1

    def __init__(self, shape=unsigned(8), fault=None):
        self.fault = fault
        super().__init__({"i": In(stream.Signature(shape)), "o": Out(stream.Signature(shape))})

    def elaborate(self, platform):
        m = Module()
        valid = Signal()
        again = Signal(init=self.fault == "twice")
        m.d.comb += self.o.valid.eq(valid & self.o.ready if self.fault == "valid_needs_ready" else valid)
        with m.If(~valid | self.o.ready):
            m.d.comb += self.i.ready.eq(1)
            m.d.sync += [valid.eq(self.i.valid), self.o.payload.eq(self.i.payload)]
            with m.If(valid & again):
                m.d.comb += self.i.ready.eq(0)
                m.d.sync += [valid.eq(1), again.eq(0)]
        with m.Else():
            if self.fault == "withdraw":
                m.d.sync += valid.eq(0)
            if self.fault == "change":
                m.d.sync += self.o.payload.eq(Value.cast(self.o.payload) + 1)
        return m


BEATS = list(range(1, 200))


def test_a_stage_without_stalls_has_no_bubbles():
    run = run_streams(Stage(), BEATS)
    assert run.outputs == BEATS
    assert run.in_cycles == list(range(len(BEATS)))
    assert run.out_cycles == [c + 1 for c in range(len(BEATS))]


@pytest.mark.parametrize("p_valid, p_ready", [(0.5, 1.0), (1.0, 0.4), (0.7, 0.6)])
def test_a_stage_with_stalls_and_the_ready_probe(p_valid, p_ready):
    run = run_streams(Stage(), BEATS, seed=3, p_valid=p_valid, p_ready=p_ready, probe_ready=True)
    assert run.outputs == BEATS
    assert all(o > i for i, o in zip(run.in_cycles, run.out_cycles))
    if p_ready >= 1:
        assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [1] * len(BEATS)


def test_ready_low_at_first_and_a_later_start():
    run = run_streams(Stage(), BEATS[:5], ready_after=10, start=3)
    assert run.outputs == BEATS[:5]
    assert run.in_cycles == [0, 10, 11, 12, 13] and run.out_cycles == [10, 11, 12, 13, 14]


@pytest.mark.parametrize("fault, message, kw", [
    ("valid_needs_ready", "valid/payload depend on ready", dict(p_ready=0.5, probe_ready=True)),
    ("withdraw", "an offered payload was withdrawn or changed", dict(p_ready=0.5)),
    ("change", "an offered payload was withdrawn or changed", dict(p_ready=0.5)),
    ("twice", "more than the 199 outputs expected", {}),
])
def test_faulty_stages_are_caught(fault, message, kw):
    with pytest.raises(AssertionError, match=message):
        run_streams(Stage(fault=fault), BEATS, seed=4, **kw)


def test_the_producer_keeps_the_rules():
    """Under random stalls on both sides, i.valid never falls and i.payload never changes
    before a transfer, and every beat goes in once, in order."""
    dut = Stage()
    run = StreamRun()
    seen = []

    async def ready(ctx):  # a consumer of o that stalls now and then
        for k in range(2000):
            ctx.set(dut.o.ready, k % 3 != 0)
            await ctx.tick()

    async def monitor(ctx):
        async for _, _, valid, ready, payload in ctx.tick().sample(dut.i.valid, dut.i.ready, dut.i.payload):
            seen.append((valid, ready, payload))
            if len(seen) == 1500:
                return

    run_testbenches(dut, stream_producer(dut.i, BEATS, run, seed=5, p_valid=0.6), ready, monitor)
    taken = [payload for valid, ready, payload in seen if valid and ready]
    assert taken == BEATS and [c for c, (v, r, _) in enumerate(seen) if v and r] == run.in_cycles
    for (valid, ready, payload), (next_valid, _, next_payload) in zip(seen, seen[1:]):
        if valid and not ready:
            assert next_valid and next_payload == payload


def test_put_and_get_dict_payloads():
    dut = Stage(PAYLOAD)
    payloads = [{"a": -5, "b": {"c": 7}}, {"a": 31, "b": {"c": 0}}, {"a": -32, "b": {"c": 3}}]
    got = []

    async def source(ctx):
        for payload in payloads:
            await stream_put(ctx, dut.i, payload)

    async def sink(ctx):
        for _ in payloads:
            got.append(await stream_get(ctx, dut.o))
            await ctx.tick().repeat(2)  # back-pressure: the source waits

    run_testbenches(dut, source, sink)
    assert got == payloads


class AlwaysReadyStage(wiring.Component):
    """``o`` is ``i`` one clock later, both streams ``always_ready`` (a pipeline that never stalls).

    ``fault="hold"`` keeps ``o.valid`` one clock longer after each beat: with ``ready`` the constant
    1 that is a second transfer of the same payload.
    """

    latency = 1

    def __init__(self, shape=unsigned(8), fault=None):
        self.fault = fault
        super().__init__({"i": In(stream.Signature(shape, always_ready=True)),
                          "o": Out(stream.Signature(shape, always_ready=True))})

    def elaborate(self, platform):
        m = Module()
        valid = Signal()
        m.d.sync += valid.eq(self.i.valid)
        with m.If(self.i.valid):
            m.d.sync += self.o.payload.eq(self.i.payload)
        if self.fault == "hold":
            earlier = Signal()
            m.d.sync += earlier.eq(valid)
            m.d.comb += self.o.valid.eq(valid | earlier)
        else:
            m.d.comb += self.o.valid.eq(valid)
        return m


@pytest.mark.parametrize("p_valid", [1.0, 0.4])
def test_always_ready_streams_take_every_valid_beat(p_valid):
    """Neither ``ready`` is driven (each is the constant 1): every beat goes in on the edge it is
    offered and comes out one edge later, taken on that edge."""
    run = run_streams(AlwaysReadyStage(), BEATS, seed=6, p_valid=p_valid, probe_ready=True)
    assert run.outputs == BEATS
    assert run.out_cycles == [c + 1 for c in run.in_cycles]
    if p_valid < 1:
        assert run.in_cycles[-1] > 1.5 * len(BEATS)  # the producer did leave gaps
    else:
        assert run.in_cycles == list(range(len(BEATS)))


def test_a_held_beat_on_an_always_ready_stream_is_a_second_transfer():
    with pytest.raises(AssertionError, match="more than the 199 outputs expected"):
        run_streams(AlwaysReadyStage(fault="hold"), BEATS, seed=7, p_valid=0.5)


@pytest.mark.parametrize("kw", [dict(p_ready=0.5), dict(ready_after=3)])
def test_stalling_an_always_ready_stream_is_refused(kw):
    with warnings.catch_warnings():  # refused before the simulator elaborates the stage
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(ValueError, match=r"^stream_consumer: the stream is always ready \(ready is the constant 1\): "
                                             r"every valid beat is taken, it cannot stall"):
            run_streams(AlwaysReadyStage(), BEATS, **kw)
        gc.collect()


def test_put_and_get_on_always_ready_streams():
    """stream_put's beats are taken on their first edge; stream_get takes the next valid beat
    without driving ``ready`` (a constant)."""
    dut = AlwaysReadyStage(PAYLOAD)
    payloads = [{"a": -5, "b": {"c": 7}}, {"a": 31, "b": {"c": 0}}, {"a": -32, "b": {"c": 3}}]
    edges, got = [], []

    async def source(ctx):
        for payload in payloads:
            edges.append(await stream_put(ctx, dut.i, payload))
            await ctx.tick().repeat(2)  # gaps: o.valid low between the beats

    async def sink(ctx):
        for _ in payloads:
            got.append(await stream_get(ctx, dut.o))

    run_testbenches(dut, source, sink)
    assert got == payloads and edges == [1, 1, 1]
