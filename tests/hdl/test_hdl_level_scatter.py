"""RTL level scatter (hdl.LevelScatter) against the golden model's ``node_levels``, in Amaranth's
simulator: each node's level is the largest of its updates', whatever their order and repeats."""

import gc
import warnings

import numpy as np
import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.guard import GUARD_LEVELS, node_levels
from hdl.level_scatter import LevelScatter
from support.streams import run_testbenches

DEPTH = 64


def run_passes(passes, depth=DEPTH):
    """Each pass ``(clears, updates)`` (node lists; updates ``(node, level)`` pairs, ``None`` for a clock
    without one), then, once idle, a lookup of the last update's node and of every node; returns the levels
    read after each pass."""
    dut = LevelScatter(depth)
    seen = []

    async def bench(ctx):
        for clears, updates in passes:
            for node in clears:
                ctx.set(dut.clear.valid, 1)
                ctx.set(dut.clear.payload, int(node))
                await ctx.tick()
            ctx.set(dut.clear.valid, 0)
            for beat in updates:
                ctx.set(dut.update.valid, beat is not None)
                if beat is not None:
                    ctx.set(dut.update.payload, {"node": beat[0], "level": beat[1]})
                await ctx.tick()
            ctx.set(dut.update.valid, 0)
            waited = 0
            while not ctx.get(dut.idle):
                await ctx.tick()
                waited += 1
                assert waited <= LevelScatter.LATENCY, "idle never rose"
            # the last update's node first, in the clock idle rises (its write must have landed), then all
            beats = [b for b in updates if b is not None]
            order = [beats[-1][0] if beats else 0, *range(depth)]
            levels = []
            lag = LevelScatter.LOOKUP_LATENCY - 1  # each answer after the third edge from its lookup's clock
            for k in range(len(order) + lag):
                ctx.set(dut.lookup, order[min(k, len(order) - 1)])
                await ctx.tick()
                if k >= lag:
                    levels.append(ctx.get(dut.level))
            assert levels[0] == levels[1 + order[0]], f"node {order[0]} read before its last write landed"
            seen.append(np.array(levels[1:len(order)]))

    run_testbenches(dut, bench)
    return seen


def expected(passes, depth=DEPTH):
    """The levels after each pass: cleared nodes to 0, then each the largest of its updates'."""
    state, out = np.zeros(depth, dtype=np.int64), []
    for clears, updates in passes:
        state[list(clears)] = 0
        beats = [b for b in updates if b is not None]
        if beats:
            nodes = np.array([b[0] for b in beats])
            levels = np.array([b[1] for b in beats])
            # node_levels takes faces: one corner per "face" here
            new = node_levels(levels, nodes[:, None], depth)
            state = np.maximum(state, new)
        out.append(state.copy())
    return out


def random_updates(rng, n, nodes, p_gap):
    beats = []
    for _ in range(n):
        if rng.random() < p_gap:
            beats.append(None)
        beats.append((int(rng.choice(nodes)), int(rng.integers(0, GUARD_LEVELS + 2))))
    return beats


def test_each_hazard_distance_and_an_update_after_a_clear():
    """The hazards one by one, each node's last update the lower: the same node in consecutive clocks,
    two clocks apart, three apart, four apart (the write that collides with the read), five apart (after
    the writes it could miss), clears between passes, an update right after its node's clear, and a pass
    whose last update raises its node (read back in the clock ``idle`` rises)."""
    passes = [([], [(5, 3), (5, 1)]), ([], [(6, 4), (7, 0), (6, 1)]), ([], [(8, 5), None, None, (8, 1)]),
              ([], [(10, 4), (11, 0), None, (12, 1), (10, 2)]), ([], [(14, 6), None, None, None, None, (14, 2)]),
              ([], [(9, 2), (9, 6), (9, 1), (9, 0), (9, 3)]), ([9, 5], [(5, 1), (9, 0)]),
              ([10], [(10, 1), (13, 0), (10, 0)]), ([], [(20, 2), (21, 5)])]
    got = run_passes(passes)
    for k, (g, w) in enumerate(zip(got, expected(passes))):
        np.testing.assert_array_equal(g, w, err_msg=f"pass {k}")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_passes_with_hot_nodes_and_clears(seed):
    rng = np.random.default_rng(seed)
    passes = []
    for k in range(4):
        hot = rng.choice(DEPTH, size=int(rng.integers(2, 12)), replace=False)
        clears = list(range(DEPTH)) if k == 2 else list(rng.choice(DEPTH, size=10, replace=False))
        updates = random_updates(rng, 300, hot, p_gap=0.3)
        # then each hot node's level once more, lower, in consecutive clocks and two apart
        updates += [(int(n), 0) for n in hot] + [(int(n), 1) for n in np.repeat(hot, 2)]
        passes.append((clears, updates))
    got = run_passes(passes)
    want = expected(passes)
    assert any(w.max() == GUARD_LEVELS + 1 for w in want) and all((w > 0).any() for w in want)
    for k, (g, w) in enumerate(zip(got, want)):
        np.testing.assert_array_equal(g, w, err_msg=f"pass {k}")


def test_parameter_validation():
    # A component whose __init__ raises is still reported as unused when collected.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(ValueError, match="depth must be an int >= 1"):
            LevelScatter(0)
        gc.collect()
