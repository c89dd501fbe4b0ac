"""``hdl.fifo.LutFIFO``'s ``registered_ready``: ``r_rdy`` from a flip-flop of its own changes no clock. Two FIFOs,
with and without it, fed the same random writes, reads and resets (reads and writes offered when empty and
when full), answer the same in every clock: ``r_rdy``, ``r_data`` while ready, ``w_rdy`` and ``level``; and
both keep the order against a Python queue. In the ECP5 form the flag is a kept ``TRELLIS_FF`` cleared by the
reset."""

import gc
import re
import warnings
from collections import deque

import numpy as np
import pytest
from amaranth.back import rtlil
from amaranth.hdl import UnusedElaboratable
from amaranth.hdl import ClockDomain, Module
from amaranth.sim import Simulator

from hdl.dsp import ECP5
from hdl.fifo import LutFIFO

DEPTH, WIDTH = 4, 6


@pytest.mark.parametrize("checked", [True, False])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_registered_ready_changes_no_clock(seed, checked):
    plain = LutFIFO(width=WIDTH, depth=DEPTH, checked=checked)
    registered = LutFIFO(width=WIDTH, depth=DEPTH, checked=checked, registered_ready=True)
    m = Module()
    m.domains.sync = domain = ClockDomain("sync")
    m.submodules.plain, m.submodules.registered = plain, registered
    rng = np.random.default_rng(seed)
    seen = {"empty": 0, "full": 0, "resets": 0, "reads": 0}

    async def bench(ctx):
        queue = deque()
        for clock in range(3000):
            reset = rng.random() < 0.005
            # unchecked: the user never writes a full FIFO nor reads an empty one
            write = rng.random() < (0.5 if clock % 400 < 200 else 0.3)
            read = rng.random() < (0.3 if clock % 400 < 200 else 0.6)
            if not checked:
                write &= len(queue) < DEPTH
                read &= len(queue) > 0
            data = int(rng.integers(1 << WIDTH))
            for fifo in (plain, registered):
                ctx.set(fifo.w_en, write)
                ctx.set(fifo.w_data, data)
                ctx.set(fifo.r_en, read)
            ctx.set(domain.rst, reset)
            answers = [(ctx.get(f.r_rdy), ctx.get(f.w_rdy), ctx.get(f.level)) for f in (plain, registered)]
            assert answers[0] == answers[1], (clock, answers)
            ready, w_ready, level = answers[0]
            assert (ready, level) == (len(queue) > 0, len(queue)), (clock, answers, len(queue))
            if ready:
                assert ctx.get(plain.r_data) == ctx.get(registered.r_data) == queue[0], clock
            seen["empty"] += level == 0
            seen["full"] += level == DEPTH
            await ctx.tick()
            if reset:
                queue.clear()
                seen["resets"] += 1
                continue
            popped = read and ready
            if popped:
                queue.popleft()
                seen["reads"] += 1
            if write and w_ready:
                queue.append(data)
        assert min(seen.values()) > 0, seen  # both ends reached, and reset

    sim = Simulator(m)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()


def test_the_registered_ready_is_a_kept_flip_flop_cleared_by_the_reset_in_the_ecp5_form():
    for registered_ready in (False, True):
        fifo = LutFIFO(width=WIDTH, depth=DEPTH, registered_ready=registered_ready)
        text = rtlil.convert(fifo, platform=ECP5, ports=[fifo.w_data, fifo.w_en, fifo.w_rdy, fifo.r_data,
                                                         fifo.r_en, fifo.r_rdy, fifo.level])
        kept = re.findall(r"^\s*cell \\TRELLIS_FF \\r_rdy_q_ff0\n((?:\s+(?:parameter|connect|attribute) .*\n)+)",
                          text, re.M)
        assert len(kept) == registered_ready
        for body in kept:
            assert re.search(r"connect \\LSR \\rst", body) and "LSR_OVER_CE" in body
            assert re.search(r"connect \\Q \\r_rdy\n", body)  # the port itself, no logic after the flip-flop


def test_registered_ready_must_be_a_bool():
    # An Elaboratable whose __init__ raises is still reported as unused when collected.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match="registered_ready must be a bool, not 1"):
            LutFIFO(width=WIDTH, depth=DEPTH, registered_ready=1)
        gc.collect()
