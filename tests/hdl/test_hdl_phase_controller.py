"""PhaseController's copies for the large builds (``control_copies``): a register loaded from ``running_next``
equals ``running`` in every clock, whatever the run's inputs do (START, ABORT, the passes' ends, the domain's
reset): the memories' read-address copies are such registers (their ECP5 form: ``test_kept_register.py``);
and a controller with the copies answers as one without them in every clock, in every run mode.
The whole runs with the copies: ``test_engine.py``'s registered-select case and ``test_engine_guard.py``."""

import numpy as np
import pytest
from amaranth.hdl import ClockDomain, Module, Signal
from amaranth.lib.wiring import Out
from amaranth.sim import Simulator

from golden_model.engine_spec.image import ENGINE_RUN_MODES
from golden_model.engine_spec.register_map import STATES, RegisterMap
from hdl.phase_controller import PhaseController
from support.engine_sim import CAPACITY, FS


def _valid_constants(ctx, controller) -> None:
    """Run constants START accepts (a guarded run mode, a small mesh), so that runs start."""
    top = 1 << (FS.reciprocal.width - 1)
    mode = next(m for m in ENGINE_RUN_MODES if m.guarded)
    values = {"vertices": 20, "entries": 60, "triangles": 30, "mode": mode.code, "max_iter": 3, "dt": 1,
              "area_reciprocal": top, "length_reciprocal": top,
              "area_shift": FS.error.frac_bits + 2, "length_shift": FS.error.frac_bits + 2}
    for name, value in values.items():
        ctx.set(getattr(controller, name), value)


def test_a_copy_loaded_from_running_next_is_running_in_every_clock():
    controller = PhaseController(FS, RegisterMap.build(FS, CAPACITY), registered_verdict=True, control_copies=True)
    m = Module()
    m.domains.sync = sync = ClockDomain("sync")
    m.submodules.controller = controller
    copy = Signal(name="running_copy")
    m.d.sync += copy.eq(controller.running_next)
    seen = {"starts": 0, "ends": 0, "resets_while_running": 0, "aborts_while_running": 0}

    async def bench(ctx):
        rng = np.random.default_rng(85)
        _valid_constants(ctx, controller)
        was_running = 0
        for clock in range(20000):
            running = ctx.get(controller.running)
            reset = rng.random() < 0.0005
            abort = rng.random() < 0.001
            seen["resets_while_running"] += reset and running
            seen["aborts_while_running"] += abort and running
            ctx.set(sync.rst, reset)
            ctx.set(controller.start, rng.random() < 0.05)
            ctx.set(controller.abort, abort)
            for done in ("force_done", "area_done", "integrate_done", "guard_done", "passes_idle"):
                ctx.set(getattr(controller, done), rng.random() < 0.3)
            await ctx.tick()
            running = ctx.get(controller.running)
            assert ctx.get(copy) == running, f"running in clock {clock}"
            seen["starts"] += running and not was_running
            seen["ends"] += was_running and ctx.get(controller.state) == STATES.index("done")  # a result
            was_running = running

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    # the stimulus took runs through their starts, ends, ABORTs and resets
    assert min(seen.values()) >= 5, seen


@pytest.mark.parametrize("mode", [m.name for m in ENGINE_RUN_MODES])
def test_the_control_copies_change_no_answer(mode):
    """``control_copies`` (ABORT's copies, ``running_next``, the momentum step's pulse taken from the β
    request) changes no clock: two controllers, with and without the copies, fed the same random inputs
    (START, ABORT, the passes' ends, the pass sums, the domain's reset) in every run mode, give the same
    answers in every clock (state, result, phase flags, pass enables, requests' effects: the step, ``k``'s
    β, ITERATIONS, CYCLES)."""
    register_map = RegisterMap.build(FS, CAPACITY)
    plain = PhaseController(FS, register_map)
    copied = PhaseController(FS, register_map, control_copies=True)
    m = Module()
    m.domains.sync = sync = ClockDomain("sync")
    m.submodules.plain, m.submodules.copied = plain, copied
    answers = [name for name, member in plain.signature.members.items() if member.flow == Out]
    seen = {"steps": 0, "iterations": 0, "steps taken": set()}
    code = next(m.code for m in ENGINE_RUN_MODES if m.name == mode)

    async def bench(ctx):
        rng = np.random.default_rng(11)

        def put(name, value):
            for controller in (plain, copied):
                ctx.set(getattr(controller, name), value)

        for controller in (plain, copied):
            _valid_constants(ctx, controller)
        put("mode", code)
        put("max_iter", 40)
        for clock in range(12000):
            ctx.set(sync.rst, rng.random() < 0.0005)
            put("start", int(rng.random() < 0.05))
            put("abort", int(rng.random() < 0.0005))
            for done in ("force_done", "area_done", "integrate_done", "guard_done", "passes_idle"):
                put(done, int(rng.random() < 0.3))
            for name in ("length_sum", "square_sum", "barrier_sum"):  # measurements that never settle
                put(name, int(rng.integers(1 << 20, 1 << 24)))
            put("power_sum", int(rng.integers(-(1 << 10), 1 << 10)))  # S's sign: momentum restarts
            before = ctx.get(plain.iterations)
            await ctx.tick()
            for name in answers:
                assert ctx.get(getattr(copied, name)) == ctx.get(getattr(plain, name)), f"{name} in clock {clock}"
            seen["steps"] += ctx.get(plain.in_step)
            seen["steps taken"].add(ctx.get(plain.step_dt))
            seen["iterations"] += ctx.get(plain.iterations) == before + 1

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    # the runs iterated and took steps; the momentum mode's β_k with several k
    assert len(answers) > 20 and seen["steps"] >= 20 and seen["iterations"] >= 20, seen
    assert len(seen["steps taken"]) >= (5 if mode == "momentum" else 2), seen
