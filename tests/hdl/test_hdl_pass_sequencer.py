"""PassSequencer's down-counters for the large builds (``down_counters``): the fetch counters' issues and
ends from down-counters' sign bits, and the sizes' and pass enables' copies. Two sequencers fed the same
random inputs (fetch enables, phases, the guard's restarts, unit results), the one without them its pass
enables and the guard's restart pulses a clock late, answer the same in every clock: addresses, the units'
valid bits and the passes' ends; ``passes_idle`` too, but that the one with them counts a pass as fetching
from its enable's rise. The
whole runs through the large builds: ``test_engine.py``'s registered-select case and ``test_engine_guard.py``."""

import re

import numpy as np
import pytest
from amaranth.back import rtlil
from amaranth.hdl import ClockDomain, Module
from amaranth.sim import Simulator

from golden_model.engine_spec.register_map import RegisterMap
from hdl.dsp import ECP5
from hdl.pass_sequencer import FETCH_COUNTERS, FETCH_FLAGS, RESTART_PULSES, PassSequencer
from support.engine_sim import CAPACITY, FS

#: The one-bit inputs driven at random in every clock, each with its probability of being high.
RANDOM_FLAGS = {
    "fetch_force": 0.8, "fetch_area": 0.8, "fetch_nodes": 0.8, "in_start": 0.02, "in_step": 0.02,
    "in_force": 0.5, "in_area": 0.5, "in_integrate": 0.5, "running": 0.9, "area_clear": 0.05,
    "guarded": 0.5, "half_rate": 0.3, "node_restart": 0.02, "triangle_restart": 0.02,
    "force_idle": 0.7, "area_idle": 0.7, "integrator_idle": 0.7,
}
#: The answers compared in every clock.
ANSWERS = ("entry_index", "tri_index", "node_index", "node_of_entry", "force_out_index", "node_out_index",
           "force_done", "area_done", "integrate_done", "passes_idle", "node_landed", "triangle_landed")
#: The streams into the units, whose valid bits are compared in every clock.
UNITS = ("force_entry", "triangle_out", "node_out")
#: The inputs the sequencer with down-counters reads through copies, a clock late.
LATE = (*FETCH_FLAGS, *RESTART_PULSES.values())
SIZES = {"vertices": CAPACITY.vertices, "entries": CAPACITY.entries, "triangles": CAPACITY.triangles}


@pytest.mark.parametrize("seed", [0, 1])
def test_the_down_counters_are_the_plain_sequencer_with_its_enables_and_restarts_a_clock_late(seed):
    register_map = RegisterMap.build(FS, CAPACITY)
    plain, counted = PassSequencer(FS, register_map), PassSequencer(FS, register_map, down_counters=True)
    m = Module()
    m.domains.sync = ClockDomain("sync")
    m.submodules.plain, m.submodules.counted = plain, counted
    seen = {"issued": 0, "ends": 0}

    async def bench(ctx):
        rng = np.random.default_rng(seed)

        def put(name, value):
            for seq in (plain, counted):
                ctx.set(getattr(seq, name), value)

        late = dict.fromkeys(LATE, 0)  # the pass enables and restart pulses of the clock before, the plain one's
        rises = [False, False]  # an enable rose two clocks ago, a clock ago

        def put_enables(enables):
            """This clock's pass enables and restart pulses: the counted sequencer's; the plain one's are the
            clock before's."""
            for flag in LATE:
                ctx.set(getattr(counted, flag), enables[flag])
                ctx.set(getattr(plain, flag), late[flag])
            rises.append(any(enables[flag] and not late[flag] for flag in FETCH_FLAGS))
            del rises[0]
            late.update(enables)

        for clock in range(4000):
            if clock % 1000 == 0:  # new sizes (0 included), then both passes' restarts a few clocks later:
                # the sizes are run constants, still from a restart to its pass's end (no fetch meanwhile)
                for flag in RANDOM_FLAGS.keys() - set(LATE):
                    put(flag, 0)
                for _ in range(2):
                    put_enables(dict.fromkeys(LATE, 0))
                    await ctx.tick()
                for name, top in SIZES.items():
                    put(name, int(rng.integers(0, top + 1)))
                await ctx.tick().repeat(3)
                put("in_start", 1)
                put("in_step", 1)
                await ctx.tick()
            draws = {flag: int(rng.random() < p) for flag, p in RANDOM_FLAGS.items()}
            for flag, value in draws.items():
                if flag not in LATE:
                    put(flag, value)
            put_enables({flag: draws[flag] for flag in LATE})
            for stream in ("forces", "integrated"):  # the units' results
                valid = int(rng.random() < 0.3)
                for seq in (plain, counted):
                    ctx.set(getattr(seq, stream).valid, valid)
            await ctx.tick()
            for name in ANSWERS:
                if name != "passes_idle":
                    assert ctx.get(getattr(counted, name)) == ctx.get(getattr(plain, name)), f"{name} in clock {clock}"
            # passes_idle answers for the enables two clocks before: after a rise, never idle where the plain
            # one is not (it may be busy where the plain one, its enable still low, is idle)
            idle = {seq: ctx.get(seq.passes_idle) for seq in (plain, counted)}
            if rises[0]:
                assert idle[counted] <= idle[plain], f"passes_idle in clock {clock}"
            else:
                assert idle[counted] == idle[plain], f"passes_idle in clock {clock}"
            for unit in UNITS:
                assert ctx.get(getattr(counted, unit).valid) == ctx.get(getattr(plain, unit).valid), f"{unit} in clock {clock}"
            seen["issued"] += sum(ctx.get(getattr(plain, unit).valid) for unit in UNITS)
            seen["ends"] += ctx.get(plain.area_done) + ctx.get(plain.force_done) + ctx.get(plain.integrate_done)

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert seen["issued"] > 1000 and seen["ends"] > 50, seen  # the passes ran, and ended


#: How a pass starts: its counter restarted in a phase before its enable rises (every pass), or, as the
#: guard's passes start, by a restart pulse in the enable's first clock while the counter still stands at the
#: end of a pass before (the triangle and node passes).
PULSES = {flag: RESTART_PULSES.get(counter) for flag, counter in zip(FETCH_FLAGS, FETCH_COUNTERS)}
STARTS = [(flag, "phase") for flag in FETCH_FLAGS] + [(flag, "pulse") for flag in FETCH_FLAGS if PULSES[flag]]


@pytest.mark.parametrize("down_counters", [False, True])
@pytest.mark.parametrize(("flag", "start"), STARTS)
def test_a_pass_is_never_idle_from_its_enables_rise_to_its_last_item(flag, start, down_counters):
    """The drain's end (``passes_idle``) in a pass started as the controller starts it: its counter restarted,
    then its enable raised, or (``pulse``) a pass run to its end, then its enable raised with the restart
    pulse. From the first clock ``passes_idle`` reads the enable in (two clocks after the rise) until the
    pass's last item has left the fetch, it is low, whether the pass issues in the enable's first clock or,
    with ``down_counters``, in the next (its counter restarted there, from the pulse's copy, a clock late)."""
    register_map = RegisterMap.build(FS, CAPACITY)
    seq = PassSequencer(FS, register_map, down_counters=down_counters)
    unit, phase = dict(zip(FETCH_FLAGS, zip(UNITS, ("in_force", "in_area", "in_integrate"))))[flag]
    pulse = PULSES[flag]
    items = 5

    async def run_pass(ctx, restart):
        """Raise the enable (with the restart pulse, if ``restart``) and count the items out until idle."""
        ctx.set(getattr(seq, flag), 1)
        if restart:
            ctx.set(getattr(seq, pulse), 1)
        await ctx.tick()
        if restart:
            ctx.set(getattr(seq, pulse), 0)
        await ctx.tick()
        issued = 0
        for _ in range(40):
            if issued == items and ctx.get(seq.passes_idle):
                break
            assert not ctx.get(seq.passes_idle), f"idle with {issued} of {items} items out"
            issued += ctx.get(getattr(seq, unit).valid)
            await ctx.tick()
        assert issued == items and ctx.get(seq.passes_idle)
        ctx.set(getattr(seq, flag), 0)
        await ctx.tick().repeat(4)

    async def bench(ctx):
        for name in SIZES:
            ctx.set(getattr(seq, name), items)
        for name in ("force_idle", "area_idle", "integrator_idle", "running"):
            ctx.set(getattr(seq, name), 1)
        ctx.set(getattr(seq, phase), 1)  # the items reach the unit in the pass's phase
        await ctx.tick().repeat(3)
        ctx.set(seq.in_start, 1)
        ctx.set(seq.in_step, 1)
        await ctx.tick()
        ctx.set(seq.in_start, 0)
        ctx.set(seq.in_step, 0)
        await ctx.tick().repeat(4)
        assert ctx.get(seq.passes_idle)  # restarted, no enable high: idle
        await run_pass(ctx, restart=False)
        if start == "pulse":  # the counter at the first pass's end, restarted by the pulse
            assert ctx.get(seq.passes_idle)
            await run_pass(ctx, restart=True)

    m = Module()
    m.domains.sync = ClockDomain("sync")
    m.submodules.seq = seq
    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()


def test_each_fetch_has_three_kept_copies_of_its_enable_in_the_ecp5_form():
    """``down_counters``: in the ECP5 form each pass enable has three kept flip-flops cleared by the reset, one the
    counter's issue reads (``<flag>_copy``), one the valid chain's (``<flag>_valid_copy``) and one the
    down-counter's (``<flag>_left_copy``), which Yosys cannot merge into one issue LUT placed between the
    counters and the chain; none without ``down_counters``."""
    register_map = RegisterMap.build(FS, CAPACITY)
    for down_counters in (False, True):
        seq = PassSequencer(FS, register_map, down_counters=down_counters)
        ports = [*(getattr(seq, name) for name in ("entry_index", "tri_index", "node_index", *FETCH_FLAGS)),
                 *(getattr(seq, unit).valid for unit in UNITS)]
        text = rtlil.convert(seq, platform=ECP5, ports=ports)
        kept = dict(re.findall(r"^\s*cell \\TRELLIS_FF \\(fetch_\w+?)_ff0\n((?:\s+(?:parameter|connect|attribute) .*\n)+)",
                               text, re.M))
        expected = {f"{flag}{kind}" for flag in FETCH_FLAGS for kind in ("_copy", "_valid_copy", "_left_copy")}
        assert set(kept) == (expected if down_counters else set())
        for name, body in kept.items():
            assert re.search(r"connect \\LSR \\rst", body) and "LSR_OVER_CE" in body, name
