"""SpringflatEngine in K lanes (``EngineCapacity(lanes=K)``, without the guard) on Amaranth's simulator: whole
flattenings loaded and read back over the bus, bit for bit against the golden model's ``run_image`` of the
same image (itself the one-lane run: ``tests/golden_model/test_image_lanes.py``)."""

import dataclasses

import numpy as np
import pytest
from amaranth.hdl import Value

from golden_model.engine_spec.image import EngineCapacity, build_image, constant_fault, run_image
from golden_model.fixed.engine import prepare
from hdl.engine import SpringflatEngine
from sim.generate import dome_grid
from sim.layouts import initial_layout
from support.engine_sim import (CAPACITY, FS, INIT, RUNS, PreloadableEngine, assert_same_run, image_of, load_directly,
                                preload_words, simulate)

pytestmark = pytest.mark.slow  # the whole engine on the Python simulator

GUARDLESS = dataclasses.replace(CAPACITY, guard=False)


def _lanes(k: int):
    return dataclasses.replace(GUARDLESS, lanes=k)


def _run(capacity, image, entry_bank_depth=8, over_the_bus=False):
    """Load ``image``, start, wait, read back: ``(result, read_back)``. ``over_the_bus``: the image written over
    the bus, then every block RAM's words read in the simulator and the entry and triangle windows read back
    over the bus; else written into the block RAMs directly (``load_directly``: a bus load is most of a short
    run's time on the Python simulator) with the run constants over the bus."""
    dut = PreloadableEngine(FS, capacity, entry_bank_depth=entry_bank_depth)
    out = {}

    def snapshot(ctx):
        out["loaded"] = {name: [ctx.get(Value.cast(ram.contents[i])) for i in range(ram.depth)]
                         for name, ram in dut.memory_windows.rams.items()}

    def host(driver, bus):
        if over_the_bus:
            driver.load(image)
            bus.in_simulator(snapshot)
            for name in ("entries", "triangles"):
                window = dut.register_map.window(name)
                out[name] = np.array([[bus.read(window.address(int(row), word)) for word in range(window.words)]
                                      for row in image.rows(name)], dtype=np.uint32)
        else:
            load_directly(driver, bus, dut, image)
        driver.start()
        out["result"] = driver.wait(poll=lambda: bus.idle(100), max_polls=5000)
        out["read_back"] = driver.read_back()

    simulate(dut, host)
    if over_the_bus:  # every word where the preload of the other tests puts it, every other word zero, and
        for name in ("entries", "triangles"):  # each share's and bank's words read back where they were written
            np.testing.assert_array_equal(out[name], image.memories()[name])
        expected = preload_words(dut.memory_windows, image)
        for name, words in out["loaded"].items():
            assert words == [expected.get(name, {}).get(i, 0) for i in range(len(words))], name
        assert set(expected) <= set(out["loaded"])
    return out["result"], out["read_back"]


def _check(capacity, image, **options):
    """A whole run of ``image`` on ``capacity`` as ``run_image`` has it."""
    expected = run_image(image, FS)
    result, read_back = _run(capacity, image, **options)
    assert result == expected.status
    assert_same_run(read_back, expected)
    return expected


# Two lanes with their entry shares in banks of 8 words (128 words a share: 16 banks each), and four lanes
# (64 words a share); the paper dynamics and the unguarded momentum step.
@pytest.mark.parametrize("lanes, run", [(2, "momentum-barrier"), (4, "paper-fixed-barrier-damped"),
                                        (2, "paper-variable")])
def test_lanes_run_the_one_lane_run_bit_exact(lanes, run):
    capacity = _lanes(lanes)
    image = image_of(RUNS[run], capacity, init=INIT.get(run, "tutte"))
    expected = run_image(image, FS)
    one_lane = run_image(image_of(RUNS[run], GUARDLESS, init=INIT.get(run, "tutte")), FS)
    assert (expected.status, expected.iterations) == (one_lane.status, one_lane.iterations)
    assert _check(capacity, image).iterations >= 4


@pytest.mark.parametrize("lanes", [2, 4])
def test_an_uneven_tail_and_shares_across_the_banks(lanes):
    """25 vertices (lane 0 holds a node more than the others) and 32 triangles; shares of 60 or 30 entries in
    banks of 8 words, so a share starts inside a bank's range and the last bank is short. Loaded over the
    bus: every block RAM holds what the other tests' preload writes."""
    mesh = dome_grid(5)
    capacity = EngineCapacity(32, 120, 64, guard=False, lanes=lanes)
    params = dataclasses.replace(RUNS["momentum-barrier"], max_iter=4)  # four iterations: each pass's tail four times
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, FS), capacity)
    assert mesh.n_vertices % lanes and image.rows("entries")[-1] > (lanes - 1) * capacity.lane_entries
    assert _check(capacity, image, over_the_bus=True).iterations == 4


def test_every_saturation_event_is_counted_once():
    """A layout 380 times too wide saturates the area pass's edges and areas: each lane's events once a pass
    (a lane's pass end pulsed again while the joined end was a clock behind, and counted them twice)."""
    image = image_of(dataclasses.replace(RUNS["paper-variable"], max_iter=2), _lanes(2), squeeze=380.0)
    assert _check(_lanes(2), image).saturations > 100


def test_lane_counts_that_do_not_add_up_answer_bad_constants():
    capacity = _lanes(2)
    image = image_of(RUNS["paper-variable"], capacity)
    changed = {**image.constants, "lane0_entries": image.constants["lane0_entries"] - 1,
               "lane1_entries": image.constants["lane1_entries"] + 1}  # adds up, but lane 1 reads a row too many
    assert constant_fault(changed, FS, capacity) is None
    broken = {**image.constants, "lane1_entries": image.constants["lane1_entries"] - 1}
    assert constant_fault(broken, FS, capacity) == "bad-constants"
    dut, out = SpringflatEngine(FS, capacity, entry_bank_depth=8), {}

    def host(driver, bus):  # START reads the run constants only: the memories are left empty
        driver.load(dataclasses.replace(image, constants=broken), memories=())
        driver.start()
        out["result"] = driver.wait(poll=lambda: bus.idle(10), max_polls=10)  # START answers at once
        out["iterations"] = driver.read_value("iterations")

    simulate(dut, host)
    assert (out["result"], out["iterations"]) == ("bad-constants", 0)
