"""The lanes' join (hdl.lanes.LaneSums) against a Python model of its contract: a pass ends two clocks after its
last lane's end, with the lanes' sums; a whole sum's saturation is the sum's; a restart forgets the lanes seen."""

import random

import pytest
from amaranth.sim import Simulator

from golden_model.engine_spec.image import EngineCapacity
from golden_model.fixed import FormatSet
from hdl.lanes import LANE_PASSES, LaneSums

FS = FormatSet.preset("narrow")


def _passes(rng, lanes, error_max):
    """Passes of random lengths: each lane ends at its own clock with its own sums, one area pass over its
    maximum (lane 0 saturated alone), one whose lanes' totals pass it only together, one aborted (lane 0
    ends, then the restart) before a pass of its kind where lane 0 ends last."""
    passes = []
    for k in range(12):
        name = LANE_PASSES[k % 3]
        ends = [rng.randrange(1, 6) for _ in range(lanes)]
        sums = {"length_sum": [rng.randrange(1 << 10) for _ in range(lanes)],
                "square_sum": [rng.randrange(1 << 20) for _ in range(lanes)],
                "barrier_sum": [rng.randrange(1 << 20) for _ in range(lanes)],
                "power_sum": [rng.randrange(-1000, 1000) for _ in range(lanes)],
                "area_total": [rng.randrange(error_max // (2 * lanes)) for _ in range(lanes)]}
        saturated = [0] * lanes
        if k == 4:  # lane 0's running sum saturated, the others' 0: the lanes' sum is the maximum, the event is lane 0's
            sums["area_total"], saturated[0] = [error_max] + [0] * (lanes - 1), 1
        if k == 7:
            sums["area_total"] = [error_max // lanes + 1] * lanes
        if k == 8:  # after the aborted integrate pass: lane 0 ends last
            ends[0] = max(ends) + 1
        passes.append((name, ends, sums, saturated, k == 5))
    return passes


@pytest.mark.parametrize("lanes", [2, 4])
def test_a_pass_ends_after_its_last_lane_with_the_lanes_sums(lanes):
    rng = random.Random(lanes)
    dut = LaneSums(FS, EngineCapacity(64, 512, 128, guard=False, lanes=lanes))
    error_max = FS.error_acc.raw_max
    passes = _passes(rng, lanes, error_max)
    seen = []

    async def bench(ctx):
        ctx.set(dut.momentum, 1)
        for name, ends, sums, saturated, aborted in passes:
            for sum_name, values in sums.items():
                for lane, value in enumerate(values):
                    ctx.set(getattr(dut, f"{sum_name}_in")[lane], value)
            for lane, flag in enumerate(saturated):
                ctx.set(dut.area_saturated_in[lane], flag)
            for clock in range(1, max(ends) + 3):
                for lane, end in enumerate(ends):
                    ctx.set(getattr(dut, f"{name}_done_in")[lane], clock == end and not (aborted and lane))
                ctx.set(dut.restart, aborted and clock == max(ends) + 1)
                await ctx.tick()
                dones = {other: ctx.get(getattr(dut, f"{other}_done")) for other in LANE_PASSES}
                if any(dones.values()):
                    seen.append((clock, dones, {s: ctx.get(getattr(dut, s)) for s in sums},
                                 ctx.get(dut.length_events), ctx.get(dut.power_events), ctx.get(dut.area_events)))
            for lane in range(lanes):
                ctx.set(getattr(dut, f"{name}_done_in")[lane], 0)

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    expected = []
    for name, ends, sums, saturated, aborted in passes:
        if aborted:  # lane 0 ended, the others did not: no end, and the restart forgets lane 0
            continue
        area = sum(sums["area_total"])
        power = sum(sums["power_sum"])
        totals = {"length_sum": sum(sums["length_sum"]), "square_sum": sum(sums["square_sum"]),
                  "barrier_sum": sum(sums["barrier_sum"]), "power_sum": power, "area_total": min(area, error_max)}
        # (read after the edge a clock after the one that takes the last lane's end)
        expected.append((max(ends) + 1, name, {s: totals[s] for s in _sums_of(name)},
                         int(name == "force" and totals["length_sum"] > FS.error_acc.raw_max),
                         int(name == "integrate" and not FS.power_acc.raw_min <= power <= FS.power_acc.raw_max),
                         int(name == "area" and (area > error_max or any(saturated)))))
    got = [(clock, next(n for n, d in dones.items() if d), {s: values[s] for s in _sums_of(next(
        n for n, d in dones.items() if d))}, length, power, area) for clock, dones, values, length, power, area in seen]
    assert [sum(d.values()) for _, d, *_ in seen] == [1] * len(seen)  # one pass's end a clock
    assert got == expected
    assert any(e[5] for e in expected if e[1] == "area") and sum(e[5] for e in expected) == 2  # both saturations


def _sums_of(name):
    return {"force": ("length_sum", "square_sum", "barrier_sum"), "area": ("area_total",),
            "integrate": ("power_sum",)}[name]
