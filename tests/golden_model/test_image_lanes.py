"""Lanes in the engine's contract: K datapaths, node ``i`` in lane ``i mod K``, each lane's entries in its
share of the entry memory (golden_model.engine_spec.image), on the bus (register map, driver, ModelBus)."""

import dataclasses
import re

import numpy as np
import pytest

from golden_model.engine_spec.image import (EngineCapacity, build_image, constant_fault, decode_entries, entry_lanes,
                                            lane_rows, run_image)
from golden_model.engine_spec.register_map import RegisterMap
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from golden_model.fixed.measures import FixedPointError
from golden_model.mesh import Mesh
from golden_model.params import FlattenParams
from sim.engine_driver import DriverError, EngineDriver, ModelBus
from sim.generate import dome_grid, generated_meshes
from sim.layouts import initial_layout

DEFAULT = FormatSet.preset("default")
ONE_LANE = EngineCapacity(vertices=64, entries=400, triangles=128)
MESH = dome_grid(6)
RUNS = {
    "momentum-guarded": FlattenParams(dynamics="momentum", max_iter=40),
    "paper-fixed-barrier": FlattenParams(density="auto", step="fixed", dt=0.2, barrier=True, max_iter=15),
}


def _lanes(k: int, capacity: EngineCapacity = ONE_LANE) -> EngineCapacity:
    return dataclasses.replace(capacity, lanes=k)


def _problem(mesh: Mesh = MESH, params: FlattenParams = RUNS["momentum-guarded"]):
    return prepare(mesh, initial_layout(mesh, "tutte"), params, DEFAULT)


def test_lane_k_runs_every_kth_node_with_its_entries_in_ring_order():
    # degrees 2, 3, 1, 3: lane 0 has nodes 0 and 2 (entries 0 1 | 5), lane 1 nodes 1 and 3 (2 3 4 | 6 7 8)
    order, counts = entry_lanes(np.array([0, 2, 5, 6, 9]), 2)
    assert order.tolist() == [0, 1, 5, 2, 3, 4, 6, 7, 8]
    assert counts.tolist() == [3, 6]
    order, counts = entry_lanes(np.array([0, 2, 5, 6, 9]), 4)
    assert order.tolist() == [0, 1, 2, 3, 4, 5, 6, 7, 8] and counts.tolist() == [2, 3, 1, 3]
    # lane k's share of the entries window starts at k·entries/K
    assert lane_rows(np.array([3, 6]), _lanes(2, EngineCapacity(8, 20, 8))).tolist() == [0, 1, 2, 10, 11, 12, 13, 14, 15]


@pytest.mark.parametrize("lanes", [2, 4])
@pytest.mark.parametrize("mesh", ["delaunay", "dome", "saddle"])
def test_the_lane_major_entries_decode_to_the_node_order_stream(mesh, lanes):
    problem = _problem(generated_meshes()[mesh])
    capacity = _lanes(lanes, EngineCapacity(vertices=1024, entries=8192, triangles=2048))
    image, stream = build_image(problem, capacity), problem.stream
    counts = [image.constants[f"lane{k}_entries"] for k in range(lanes)]
    assert sum(counts) == image.constants["entries"] == len(stream.neighbour)
    degrees = np.diff(stream.indptr)
    assert counts == [degrees[k::lanes].sum() for k in range(lanes)]
    # the rows of lane k are its nodes' entries, in node order
    lane1 = image.entries[counts[0]:counts[0] + counts[1]]
    _, neighbour, _, _ = decode_entries(lane1, DEFAULT, capacity, barrier=True)
    nodes = np.arange(1, len(degrees), lanes)
    np.testing.assert_array_equal(neighbour, np.concatenate([stream.neighbour[stream.indptr[i]:stream.indptr[i + 1]]
                                                             for i in nodes]))
    indptr, neighbour, rest, barrier = decode_entries(image.entries, DEFAULT, capacity, True, np.array(counts))
    for got, want in ((indptr, stream.indptr), (neighbour, stream.neighbour), (rest, stream.rest),
                      (barrier.second, stream.barrier.second), (barrier.gain, stream.barrier.gain)):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("lanes", [2, 4])
@pytest.mark.parametrize("run", RUNS)
def test_a_run_of_the_lane_image_is_the_one_lane_run(run, lanes):
    problem = _problem(params=RUNS[run])
    one, many = run_image(build_image(problem, ONE_LANE), DEFAULT), run_image(build_image(problem, _lanes(lanes)), DEFAULT)
    assert (many.status, many.iterations, many.energy, many.saturations) == \
        (one.status, one.iterations, one.energy, one.saturations)
    np.testing.assert_array_equal(many.positions, one.positions)
    np.testing.assert_array_equal(many.velocities, one.velocities)


def test_a_lane_over_its_share_of_the_entries_is_refused_in_one_line():
    """A fan's hub is in lane 0 with half the rim: the whole fits the entry memory, lane 0's share does not."""
    n = 30
    angles = np.linspace(0, np.pi, n - 1)
    vertices = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(n - 1)])
    vertices = np.vstack([[0.0, 0.0, 0.0], vertices])
    fan = Mesh(vertices, np.array([[0, k, k + 1] for k in range(1, n - 1)]))
    capacity = EngineCapacity(vertices=64, entries=120, triangles=64, lanes=2)
    assert len(fan.rings.neighbour) == 4 * n - 6 <= capacity.entries
    # lane 0: the hub's 29 entries and 14 rim vertices' 3; lane 1: 13 rim vertices' 3 and the rim's ends' 2
    message = ("lane 0 of 2 (vertices 0, 2, 4, ...) has 71 neighbour entries; a lane holds at most 60 "
               "(capacity entries=120, lanes=2)")
    with pytest.raises(FixedPointError, match=f"^{re.escape(message)}$"):
        build_image(_problem(fan), capacity)
    with pytest.raises(FixedPointError, match="lane 0 of 2"):
        capacity.check_mesh(fan)


@pytest.mark.parametrize("lanes, what", [(3, "lanes must be one of 1, 2, 4, got 3"),
                                         (True, "lanes must be one of 1, 2, 4, got True"),
                                         (2.0, "lanes must be one of 1, 2, 4, got 2.0"),
                                         (4, "entries = 402 is not a multiple of lanes = 4")])
def test_a_lane_count_the_engine_cannot_have_is_refused(lanes, what):
    with pytest.raises(ValueError, match=f"^EngineCapacity: {what}"):
        EngineCapacity(vertices=64, entries=402, triangles=128, lanes=lanes)


@pytest.mark.parametrize("change", [
    {"lane0_entries": 84},  # the lanes' sum is not ENTRIES
    {"lane0_entries": 201, "lane1_entries": 0, "entries": 201},  # over lane 0's share (200)
])
def test_start_answers_lane_counts_that_do_not_add_up_with_bad_constants(change):
    image = build_image(_problem(), _lanes(2))
    assert constant_fault(image.constants, DEFAULT, _lanes(2)) is None
    assert constant_fault({**image.constants, **change}, DEFAULT, _lanes(2)) == "bad-constants"


def test_the_register_map_says_the_lanes_and_holds_their_counts():
    one, two = RegisterMap.build(DEFAULT, ONE_LANE), RegisterMap.build(DEFAULT, _lanes(2))
    features = {f.name: f for f in two.register("FEATURES").fields}
    assert (features["lanes"].lsb, features["lanes"].width) == (1, 3)
    assert one.register("FEATURES").reset >> 1 == 1 and two.register("FEATURES").reset >> 1 == 2
    assert [r.name for r in two.registers if r.name.startswith("LANE")] == ["LANE0_ENTRIES", "LANE1_ENTRIES"]
    assert not [r.name for r in one.registers if r.name.startswith("LANE")]
    assert two.value_width("lane0_entries") == (ONE_LANE.entries // 2).bit_length()


@pytest.mark.parametrize("lanes", [2, 4])
def test_the_driver_writes_each_lane_at_its_share_and_the_run_is_the_one_lane_run(lanes):
    capacity = _lanes(lanes)
    regmap = RegisterMap.build(DEFAULT, capacity)
    bus = ModelBus(regmap, DEFAULT, run_polls=2)
    written = []
    write = bus.write
    bus.write = lambda address, word: (written.append(address), write(address, word))[1]
    image = build_image(_problem(), capacity)
    driver = EngineDriver(bus, regmap)
    driver.load(image)
    window = regmap.window("entries")
    indices = sorted({(a - window.base) // window.stride for a in written if window.base <= a < window.base + window.size})
    counts = [image.constants[f"lane{k}_entries"] for k in range(lanes)]
    assert indices == sorted(k * capacity.lane_entries + i for k, n in enumerate(counts) for i in range(n))
    driver.start()
    reference = run_image(build_image(_problem(), ONE_LANE), DEFAULT)
    assert driver.wait() == reference.status
    back = driver.read_back()
    assert back.iterations == reference.iterations
    np.testing.assert_array_equal(back.positions, reference.positions)


def test_a_map_with_other_lanes_than_the_engine_is_refused():
    bus = ModelBus(RegisterMap.build(DEFAULT, _lanes(2)), DEFAULT)
    with pytest.raises(DriverError, match="^the engine was built with 2 lane\\(s\\); the register map says 1$"):
        EngineDriver(bus, RegisterMap.build(DEFAULT, ONE_LANE)).identify()


@pytest.mark.parametrize("lanes, change, said", [
    (1, lambda c: {"entries": c["entries"] - 1}, r"the \d+ entries stop inside a node, after 35 of the 36 nodes' ends"),
    (2, lambda c: {"lane0_entries": c["lane0_entries"] + 1, "lane1_entries": c["lane1_entries"] - 1},
     r"lane 0's \d+ entries stop inside a node, after 18 of its 18 nodes' ends"),
    (2, lambda c: {"lane0_entries": c["entries"], "lane1_entries": 0}, r"lane 0's \d+ entries end 36 nodes, not its 18"),
])
def test_counts_that_add_up_but_do_not_end_the_nodes_are_refused_in_one_line(lanes, change, said):
    """START checks the counts against each other and the capacity, not against the entries' last flags: counts
    that cut a node's entries leave the RTL's force pass waiting for that node's end, a run that never ends and
    that ABORT cannot end. The model says so in one line rather than run something the engine does not."""
    capacity = _lanes(lanes) if lanes > 1 else ONE_LANE
    image = build_image(_problem(), capacity)
    wrong = dataclasses.replace(image, constants={**image.constants, **change(image.constants)})
    assert constant_fault(wrong.constants, DEFAULT, capacity) is None  # (what START checks: it starts)
    with pytest.raises(ValueError, match=rf"^run_image: {said}: the entry counts do not match the entries") as refused:
        run_image(wrong, DEFAULT)
    assert "\n" not in str(refused.value)
    regmap = RegisterMap.build(DEFAULT, capacity)  # the same on the bus model, the engine's stand-in
    driver = EngineDriver(ModelBus(regmap, DEFAULT), regmap)
    driver.load(wrong)
    with pytest.raises(ValueError, match=rf"^run_image: {said}"):
        driver.start()
