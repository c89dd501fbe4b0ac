"""RTL saturation tally (hdl.SaturationTally) against a clock-by-clock Python model of its contract: the
count of every event, four edges after it is reported, stopping at the count's maximum, and ``clear``; in
both forms (the count's maximum by a multiplexer after the adder, or by overflow bits held)."""

import random

import pytest
from amaranth.sim import Simulator

from hdl.saturation_tally import SaturationTally


def reference(stimulus, sources, count_bits):
    """The count after each edge: an event reported at clock t is counted at the edge t + 4 (its register,
    the pairs' sums, their sum, the count), the sum stops at ``2**count_bits − 1``, and ``clear`` at a clock
    empties the count at its edge (the events summed into that edge are lost, the later ones counted)."""
    maximum = (1 << count_bits) - 1
    in_flight = [0, 0, 0]  # the sums reported one, two and three clocks before
    count, counts = 0, []
    for events, clear in stimulus:
        arriving = in_flight.pop()
        count = 0 if clear else min(count + arriving, maximum)
        in_flight.insert(0, sum(events[name] for name in sources))
        counts.append(count)
    return counts


@pytest.mark.parametrize("sources, count_bits", [({"a": 3, "b": 3}, 4), ({"a": 2, "b": 1, "c": 3, "d": 1}, 6),
                                                 ({f"s{k}": 2 for k in range(8)}, 5), ({"a": 6, "b": 5}, 4)])
@pytest.mark.parametrize("overflow_bits", [False, True])
def test_counts_every_event_stops_at_the_maximum_and_clears(sources, count_bits, overflow_bits):
    rng = random.Random(count_bits)
    stimulus = []
    for t in range(600):
        busy = (t // 50) % 2 == 0  # bursts of events between quiet stretches
        events = {name: rng.randrange(1 << width) if busy and rng.random() < 0.5 else 0
                  for name, width in sources.items()}
        stimulus.append((events, t % 150 == 149 or rng.random() < 0.01))
    expected = reference(stimulus, sources, count_bits)
    top = expected.index((1 << count_bits) - 1)  # the run reaches the maximum
    assert min(expected[top:]) == 0  # and is cleared after it

    dut = SaturationTally(sources, count_bits=count_bits, overflow_bits=overflow_bits)
    seen = []

    async def bench(ctx):
        for events, clear in stimulus:
            for name, value in events.items():
                ctx.set(getattr(dut, f"{name}_events"), value)
            ctx.set(dut.clear, clear)
            await ctx.tick()
            seen.append((ctx.get(dut.saturations), ctx.get(dut.saturated)))

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    counts = [count for count, _ in seen]
    assert counts == expected
    assert [flag for _, flag in seen[1:]] == [int(count != 0) for count in counts[:-1]]  # a clock later
