"""SpringflatEngine's step guard on Amaranth's simulator: guarded whole runs bit for bit against the golden
model's ``run_image``, and ABORT in each of the guard's passes (the drain, then a clean rerun). The unguarded
runs and the bus's answers: ``tests/hdl/test_engine.py``."""

import pytest
from amaranth.sim import Simulator

from golden_model.engine_spec.image import run_image
from golden_model.params import FlattenParams
from sim.engine_driver import BusError, EngineDriver
from support.engine_sim import (CAPACITY, FS, GUARDED, PreloadableEngine, aborts_then_a_whole_run, assert_same_run,
                                guarded_image, image_of, load_directly, phase_spans, run_on_engine, simulate)
from support.wishbone import ThreadedBus, wishbone_write

pytestmark = pytest.mark.slow  # the whole engine on the Python simulator: seconds per iteration


@pytest.mark.parametrize("case", GUARDED)
def test_guarded_whole_run_matches_the_golden_model(case):
    registered_select = GUARDED[case][2]
    image = guarded_image(case)
    expected = run_image(image, FS)
    guard = expected.guard
    assert guard.clipped > 0
    assert guard.rejected > 0 if case == "clipped-and-rolled-back" else (guard.frozen > 0 and expected.saturations > 0)
    # (the registered select's run also with the datapaths' delay lines, a build option)
    dut = PreloadableEngine(FS, CAPACITY, registered_select=registered_select, delay_lines=registered_select)
    result, read_back = run_on_engine(dut, image)
    assert result == expected.status
    assert_same_run(read_back, expected)


def test_guarded_runs_aborted_in_every_pass_then_a_clean_rerun():
    """ABORT in the middle of each of the guard's passes (the scatters and proposals left half written), each
    followed by a reload of the node memory (a run writes no other): the last, whole run is bit-exact with
    the golden model (the propose pass clears what an aborted run left in the scatters). The clocks are
    taken from a first run's phases."""
    from hdl.phase_controller import PHASES

    # stretched across, the guarded run rolls back its fourth step (the golden model's record says so): the
    # run up to it
    image = image_of(FlattenParams(dynamics="momentum", max_iter=4), squeeze=4.0)
    assert run_image(image, FS).guard.rejected == 1
    guard_phases = ("decide", "rollback", "integrate", "stuck", "hold", "certify", "commit")
    dut = PreloadableEngine(FS, CAPACITY)
    watch, spans, aborted_in, drained_at = phase_spans(dut, PHASES)  # spans: [phase, first clock, last clock]
    out = {}

    def host(driver, bus):
        load_directly(driver, bus, dut, image)
        driver.start()
        driver.wait(poll=lambda: bus.idle(100), max_polls=5000)
        first_span = {}  # each guard phase's first span of at least 4 clocks: its middle clock
        for name, begin, end in spans:
            if name in guard_phases and name not in first_span and end - begin >= 4:
                first_span[name] = (begin + end) // 2
        assert set(first_span) == set(guard_phases), spans
        out["first_span"] = first_span
        out["read_back"] = aborts_then_a_whole_run(driver, bus, dut, image, drained_at, aborted_in,
                                                   first_span["decide"], first_span.values())

    simulate(dut, host, {"watcher": watch})
    assert set(aborted_in) == set(guard_phases), (aborted_in, out["first_span"])
    assert_same_run(out["read_back"], run_image(image, FS))


def test_abort_in_the_first_clock_of_a_guard_pass_drains_the_whole_pass():
    """ABORT whose registered copy falls in the first clock of a guard pass, when the pass's counter still
    stands at the previous pass's end (it restarts at that clock's end): the drain waits for the pass, so
    once STATUS reads idle nothing is in flight and nothing writes the node memory. The abort is written
    from the simulator's clock (not the host thread's), in three clocks around the one that lands it in
    the pass's first clock; a first run measures the passes' clocks and the abort's lag."""
    from golden_model.engine_spec.register_map import STATES
    from hdl.phase_controller import PHASES

    image = guarded_image("clipped-and-rolled-back")
    dut = PreloadableEngine(FS, CAPACITY)
    control = dut.register_map.register("CONTROL")
    start, abort = ({f.name: 1 << f.lsb for f in control.fields}[name] for name in ("start", "abort"))
    idle, running = STATES.index("idle"), STATES.index("running")
    targets = {"certify": "hold", "commit": "certify"}  # a triangle pass's restart, a node pass's
    log = []  # per clock: (phase name or None when not running, state, passes_idle, node memory written)
    bus = ThreadedBus(BusError)
    bus.run(lambda: load_directly(EngineDriver(bus, dut.register_map), bus, dut, image))

    async def watch(ctx):
        s = dut.debug_signals
        while True:
            await ctx.tick()
            state = ctx.get(s["state"])
            log.append((PHASES[ctx.get(s["phase"])] if state == running else None, state,
                        ctx.get(s["passes_idle"]), ctx.get(s["node_write"])))

    def first_clock(phase, since):
        return next(t for t in range(since, len(log)) if log[t][0] == phase)

    async def until(ctx, clock):
        while len(log) < clock:
            await ctx.tick()

    async def run(ctx, seen, abort_at):
        """START, then once phase ``seen`` has begun ABORT at the clock ``abort_at(START's clock)``; then
        80 clocks after STATUS reads idle. The clocks of START and of ABORT's write."""
        await wishbone_write(ctx, dut.bus, control.offset, start)
        began = len(log)
        while not any(phase == seen for phase, *_ in log[began:]):
            await ctx.tick()
        await until(ctx, abort_at(began))
        written = len(log)
        await wishbone_write(ctx, dut.bus, control.offset, abort)
        while log[-1][1] != idle:
            await ctx.tick()
        await ctx.tick().repeat(80)
        return began, written

    runs = {}

    async def bench(ctx):
        await bus.serve(ctx, dut.bus)
        # the first run: each pass's first clock from the hold pass's, and the lag from the abort's
        # write to the drain's first clock
        clocks = {}

        def in_commit(began):
            clocks.update({name: first_clock(name, began) for name in ("hold", "certify", "commit")})
            return clocks["commit"] + 3

        _, written = await run(ctx, "commit", in_commit)
        lag = first_clock("drain", clocks["commit"]) - written
        for target, before in targets.items():
            span = clocks[target] - clocks[before]
            for shift in (-1, 0, 1):
                def at(began):  # the drain's first clock is the pass's second: ABORT's copy in its first
                    return first_clock(before, began) + span + 1 - lag + shift
                runs[target, shift] = await run(ctx, before, at)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.add_testbench(watch, background=True)
    sim.run()

    landed_in_first_clock = set()
    for (target, shift), (began, _) in runs.items():
        drain = first_clock("drain", began)
        clocks_in_target = sum(1 for phase, *_ in log[began:drain] if phase == target)
        if clocks_in_target == 1 and log[drain - 1][0] == target:
            landed_in_first_clock.add(target)
        stopped = next(t for t in range(drain, len(log)) if log[t][1] == idle)
        after = log[stopped:stopped + 80]
        assert len(after) == 80
        assert all(passes_idle and not written for _, _, passes_idle, written in after), (target, shift, after)
    assert landed_in_first_clock == set(targets), runs
