"""SpringflatEngine in K lanes (``EngineCapacity(lanes=K)``, without the guard) on Amaranth's simulator: whole
flattenings loaded and read back over the bus, bit for bit against the golden model's ``run_image`` of the
same image (itself the one-lane run: ``tests/golden_model/test_engine_lanes.py``)."""

import dataclasses

import numpy as np
import pytest

from golden_model.engine_spec.image import constant_fault, run_image
from hdl.engine import SpringflatEngine
from support.engine_sim import CAPACITY, FS, INIT, RUNS, assert_same_run, image_of, simulate

pytestmark = pytest.mark.slow  # the whole engine on the Python simulator

GUARDLESS = dataclasses.replace(CAPACITY, guard=False)


def _lanes(k: int):
    return dataclasses.replace(GUARDLESS, lanes=k)


def _run(capacity, image, entry_bank_depth=8):
    """Load ``image`` over the bus, start, wait, read back: ``(result, read_back, entries read back, cycles)``."""
    dut = SpringflatEngine(FS, capacity, entry_bank_depth=entry_bank_depth)
    window = dut.register_map.window("entries")
    out = {}

    def host(driver, bus):
        driver.load(image)
        out["entries"] = [[bus.read(window.address(int(row), word)) for word in range(window.words)]
                          for row in image.rows("entries")]
        driver.start()
        out["result"] = driver.wait(poll=lambda: bus.idle(100), max_polls=5000)
        out["read_back"] = driver.read_back()
        out["cycles"] = driver.read_value("cycles")

    simulate(dut, host)
    return out["result"], out["read_back"], np.array(out["entries"], dtype=np.uint32), out["cycles"]


# Two lanes with their entry shares in banks of 8 words (the second lane's share starts inside the first's
# last bank's words: 128 words a share), and four lanes; the paper dynamics and the unguarded momentum step.
@pytest.mark.parametrize("lanes, run", [(2, "momentum-barrier"), (4, "paper-fixed-barrier-damped"),
                                        (2, "paper-variable")])
def test_lanes_run_the_one_lane_run_bit_exact(lanes, run):
    capacity = _lanes(lanes)
    image = image_of(RUNS[run], capacity, init=INIT.get(run, "tutte"))
    expected = run_image(image, FS)
    one_lane = run_image(image_of(RUNS[run], GUARDLESS, init=INIT.get(run, "tutte")), FS)
    assert (expected.status, expected.iterations) == (one_lane.status, one_lane.iterations)
    result, read_back, entries, _ = _run(capacity, image)
    np.testing.assert_array_equal(entries, image.entries)  # each share's words read back where they were written
    assert result == expected.status and expected.iterations >= 4
    assert_same_run(read_back, expected)


def test_lane_counts_that_do_not_add_up_answer_bad_constants():
    capacity = _lanes(2)
    image = image_of(RUNS["paper-variable"], capacity)
    changed = {**image.constants, "lane0_entries": image.constants["lane0_entries"] - 1,
               "lane1_entries": image.constants["lane1_entries"] + 1}  # adds up, but lane 1 reads a row too many
    assert constant_fault(changed, FS, capacity) is None
    broken = {**image.constants, "lane1_entries": image.constants["lane1_entries"] - 1}
    assert constant_fault(broken, FS, capacity) == "bad-constants"
    result, read_back, _, _ = _run(capacity, dataclasses.replace(image, constants=broken))
    assert (result, read_back.iterations) == ("bad-constants", 0)
