"""The host driver (sim/engine_driver.py) against the Python model of the engine on its bus (ModelBus)."""

import dataclasses

import numpy as np
import pytest

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed, prepare
from golden_model.engine_spec.image import EngineCapacity, build_image
from golden_model.engine_spec.register_map import RegisterMap
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from sim.engine_driver import BusError, DriverError, EngineDriver, ModelBus
from golden_model.engine_spec.image import UNGUARDED
from support import one_line

DEFAULT = FormatSet.preset("default")
CAPACITY = EngineCapacity(vertices=64, entries=400, triangles=128)
MAP = RegisterMap.build(DEFAULT, CAPACITY)
MESH = dome_grid(6)
P0 = initial_layout(MESH, "tutte")
PARAMS = FlattenParams(dynamics="momentum", **UNGUARDED, max_iter=40)


def _image(params=PARAMS, capacity=CAPACITY):
    return build_image(prepare(MESH, P0, params, DEFAULT), capacity)


@pytest.fixture
def bus():
    return ModelBus(MAP, DEFAULT, run_polls=3)


@pytest.mark.parametrize("params", [PARAMS, FlattenParams(density="auto", step="fixed", dt=0.2, max_iter=15)])
def test_a_run_over_the_bus_is_the_golden_models(bus, params):
    reference = flatten_fixed(MESH, P0, params, DEFAULT)
    driver = EngineDriver(bus, MAP)
    driver.load(_image(params))
    driver.start()
    polls = []
    assert driver.wait(poll=lambda: polls.append(1)) == reference.status
    assert len(polls) == 2  # running for three STATUS reads: two polls in between
    back = driver.read_back()
    state = reference.engine_state
    assert (back.state, back.result, back.iterations) == ("done", reference.status, reference.iterations)
    np.testing.assert_array_equal(back.positions, state.raw_positions)
    np.testing.assert_array_equal(back.velocities, state.raw_velocities)
    assert (back.area_error, back.shape_error, back.energy) == (*state.errors, state.energy_raw)
    assert back.saturations == reference.extra["saturations"]


def test_a_rerun_after_reloading_the_node_memory_only(bus):
    """A run writes only the node memory: reloading it (and the constants) runs the same image again,
    and the reload writes no other memory's words."""
    driver = EngineDriver(bus, MAP)
    image = _image()
    driver.load(image)
    driver.start()
    driver.wait()
    first = driver.read_back()
    written = []
    write = bus.write
    bus.write = lambda address, value: (written.append(address), write(address, value))[1]
    driver.load(image, memories=("nodes",))
    nodes = MAP.window("nodes")
    in_windows = [a for a in written if a >= min(w.base for w in MAP.windows)]
    assert len(in_windows) == image.nodes.size
    assert all(nodes.base <= a < nodes.base + nodes.depth * nodes.stride for a in in_windows)
    driver.start()
    driver.wait()
    again = driver.read_back()
    assert (again.result, again.iterations, again.energy) == (first.result, first.iterations, first.energy)
    np.testing.assert_array_equal(again.positions, first.positions)
    with pytest.raises(DriverError) as info:
        driver.load(image, memories=("nodes", "vertices"))
    assert one_line(info) == "no memory named 'vertices' (the engine has nodes, entries, triangles)"


def test_start_with_no_mesh_loaded(bus):
    driver = EngineDriver(bus, MAP)
    with pytest.raises(DriverError) as info:
        driver.start()
    assert one_line(info) == "no mesh loaded: call load(image) before start()"
    # the engine's own answer when START is written anyway
    control = MAP.register("CONTROL")
    bus.write(control.offset, 1 << next(f.lsb for f in control.fields if f.name == "start"))
    assert driver.wait() == "no-mesh"
    assert driver.read_back().iterations == 0


def test_an_image_for_another_capacity_is_refused(bus):
    driver = EngineDriver(bus, MAP)
    with pytest.raises(DriverError) as info:
        driver.load(_image(capacity=EngineCapacity(64, 400, 256)))
    assert one_line(info) == ("the image was built for capacity 64/400/256 (vertices/entries/triangles); "
                               "the engine has 64/400/128")
    guardless = dataclasses.replace(CAPACITY, guard=False)
    with pytest.raises(DriverError) as info:
        driver.load(_image(params=dataclasses.replace(PARAMS, max_iter=5), capacity=guardless))
    assert one_line(info) == ("the image was built for capacity 64/400/128 without the guard "
                               "(vertices/entries/triangles); the engine has 64/400/128")


def test_a_map_with_or_without_the_guard_must_match_the_engine(bus):
    with pytest.raises(DriverError) as info:
        EngineDriver(bus, RegisterMap.build(DEFAULT, dataclasses.replace(CAPACITY, guard=False))).identify()
    assert one_line(info) == "the engine was built with the step guard; the register map says without"


def test_a_map_for_another_format_set_or_no_engine_is_refused(bus):
    narrow = RegisterMap.build(FormatSet.preset("narrow"), CAPACITY)
    with pytest.raises(DriverError, match=r"^the engine was built for another format set than 'narrow' \(FORMAT_HASH "
                                          r"differs\): the 'default' preset's: give --formats default$"):
        EngineDriver(bus, narrow).load(_image())

    class Silent:
        def read(self, address):
            return 0

        def write(self, address, value):
            pass

    with pytest.raises(DriverError, match=r"^no springflat engine on this bus: ID reads 0x00000000"):
        EngineDriver(Silent(), MAP).identify()


def test_bus_errors(bus):
    nodes = MAP.window("nodes")
    with pytest.raises(BusError, match=r"^bus error: read at unmapped word 0x7$"):
        bus.read(0x7)
    with pytest.raises(BusError, match=r"^bus error: read at unmapped word"):
        bus.read(nodes.address(0, nodes.words))  # the hole after an entry's words
    with pytest.raises(BusError, match=r"^bus error: write to read-only register ID"):
        bus.write(MAP.register("ID").offset, 0)
    with pytest.raises(BusError, match=r"partial writes are refused"):
        bus.write(MAP.register("MAX_ITER").offset, 5, sel=0b0011)
    driver = EngineDriver(bus, MAP)
    driver.load(_image())
    driver.start()
    with pytest.raises(BusError, match=r"^bus error: read of the nodes memory .* while the engine is running$"):
        bus.read(nodes.address(0))
    with pytest.raises(BusError, match=r"while the engine is running"):
        bus.write(MAP.window("entries").address(3, 1), 0)
    with pytest.raises(DriverError, match="^the engine is running: abort"):
        driver.load(_image())
    driver.wait()
    assert bus.read(nodes.address(0)) == driver.read_back().positions[0, 0] & 0xFFFF_FFFF


def test_the_interrupt_line_and_its_clear(bus):
    driver = EngineDriver(bus, MAP)
    driver.load(_image())
    driver.start(irq=True)
    status = MAP.register("STATUS")
    for _ in range(10):  # the run ends within run_polls STATUS reads
        if bus.irq:
            break
        bus.read(status.offset)
    assert bus.irq
    assert driver.wait() == "converged" and not bus.irq  # wait() clears irq_pending


def test_bad_constants_and_the_saturation_limit(bus):
    driver = EngineDriver(bus, MAP)
    driver.load(_image())
    bus.write(MAP.register("MAX_ITER").offset, 0)
    driver.start()
    assert driver.wait() == "bad-constants"
    saturating = FlattenParams(density="auto", step="fixed", dt=0.5, spring=5.0, max_iter=20)
    image = _image(saturating)
    driver.load(dataclasses.replace(image, constants={**image.constants, "saturation_limit": 10}))
    driver.start()
    assert driver.wait() == "diverged"
    status = MAP.register("STATUS")
    saturated = next(f for f in status.fields if f.name == "saturated")
    assert bus.read(status.offset) & saturated.mask and driver.read_back().saturations >= 10


def test_abort_and_a_wait_that_never_ends(bus):
    driver = EngineDriver(bus, MAP)
    with pytest.raises(DriverError, match="^the engine is idle: start"):
        driver.wait()
    driver.load(_image())
    driver.start()
    with pytest.raises(DriverError, match="^the engine is still running after 1 status polls$"):
        driver.wait(max_polls=1)
    driver.abort()
    back = driver.read_back()
    assert (back.state, back.result) == ("idle", "none")
    np.testing.assert_array_equal(back.positions, prepare(MESH, P0, PARAMS, DEFAULT).initial_positions)


COARSE_MAP = RegisterMap.build(DEFAULT, dataclasses.replace(CAPACITY, coarse_degree=3))


def test_a_coarse_run_over_the_bus_is_the_golden_models():
    """The driver loads the basis and matrix windows and the coarse run constants of a coarse build; the run
    is ``run_fixed``'s with the coarse move, not the one without it."""
    params = FlattenParams(dynamics="momentum", coarse_degree=3, max_iter=40)
    reference, plain = (flatten_fixed(MESH, P0, p, DEFAULT) for p in (params, params.with_(coarse_degree=0)))
    assert not np.array_equal(reference.engine_state.raw_positions, plain.engine_state.raw_positions)
    driver = EngineDriver(ModelBus(COARSE_MAP, DEFAULT, run_polls=1), COARSE_MAP)
    driver.load(_image(params, COARSE_MAP.capacity))
    driver.start()
    assert driver.wait() == reference.status
    back = driver.read_back()
    assert back.iterations == reference.iterations
    np.testing.assert_array_equal(back.positions, reference.engine_state.raw_positions)


def test_a_map_with_another_coarse_degree_than_the_engine_is_refused(bus):
    with pytest.raises(DriverError) as info:
        EngineDriver(bus, COARSE_MAP).identify()
    assert one_line(info) == ("the engine was built with a coarse space of degree 0 (0: none); the register map "
                              "says 3")
    with pytest.raises(DriverError, match="with a coarse space of degree 3 .*the engine has 64/400/128$"):
        EngineDriver(bus, MAP).load(_image(FlattenParams(dynamics="momentum", coarse_degree=3, max_iter=5),
                                           COARSE_MAP.capacity))
