"""PhaseController's copies for the large builds (``control_copies``): a register loaded from ``running_next``
equals ``running`` in every clock, whatever the run's inputs do (START, ABORT, the passes' ends, the domain's
reset): the memories' read-address copies are such registers (their ECP5 form: ``test_kept_register.py``).
The whole runs with the copies: ``test_engine.py``'s registered-select case and ``test_engine_guard.py``."""

import numpy as np
from amaranth.hdl import ClockDomain, Module, Signal
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
