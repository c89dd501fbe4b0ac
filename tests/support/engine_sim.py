"""SpringflatEngine on Amaranth's simulator, driven as a host drives it: the shared mesh, capacity and runs of
``tests/hdl/test_engine*.py``, the threaded host driver on the simulated Wishbone bus, and the bit-for-bit
comparison of a read-back with the golden model's ``run_image``."""

from __future__ import annotations

import numpy as np
from amaranth.hdl import Value
from amaranth.sim import Simulator

from golden_model.engine_spec.image import BUS_WORD_BITS, UNGUARDED, EngineCapacity, build_image, node_word_layout
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from hdl.engine import SpringflatEngine
from sim.engine_driver import BusError, EngineDriver

from .wishbone import ThreadedBus

FS = FormatSet.preset("default")
CAPACITY = EngineCapacity(32, 256, 64)
MESH = dome_grid(4)  # 16 vertices, 66 entries, 18 triangles

RUNS = {
    "paper-variable": FlattenParams(density="auto", max_iter=4),
    "paper-fixed-barrier-damped": FlattenParams(density="auto", step="fixed", dt=0.2, damping=0.1, barrier=True,
                                                max_iter=4),
    # from the PCA layout the momentum restarts (S < 0) at the third and eighth steps
    "momentum-barrier": FlattenParams(dynamics="momentum", **UNGUARDED, max_iter=9),
}
INIT = {"momentum-barrier": "pca"}

# The guarded step (the momentum dynamics' default) from a Tutte layout squeezed across: steps are clipped
# by the certificate and one is rolled back, through the registered bank select's latencies and the guard
# decision's rise in parts; without the barrier and squeezed further, nodes are also held still (frozen)
# and the forces saturate.
GUARDED = {
    "clipped-and-rolled-back": (0.05, FlattenParams(dynamics="momentum", max_iter=12), True),
    "frozen-and-saturating": (0.02, FlattenParams(dynamics="momentum", barrier=False, max_iter=12), False),
}


def image_of(params: FlattenParams, capacity: EngineCapacity = CAPACITY, init: str = "tutte", squeeze: float = 1.0):
    """The image of ``MESH`` from its ``init`` layout, squeezed across (x scaled) by ``squeeze``."""
    layout = initial_layout(MESH, init) * np.array([squeeze, 1.0])
    return build_image(prepare(MESH, layout, params, FS), capacity)


class PreloadableEngine(SpringflatEngine):
    """:class:`SpringflatEngine` that keeps its :class:`~hdl.memory_windows.MemoryWindows` at elaboration
    (:attr:`memory_windows`), so that a testbench can write an image's rows into the block RAMs
    directly (:func:`preload`): over the bus each 32-bit word is a read-modify-write of some 13 clocks, and
    on the Python simulator a load took longer than the few iterations it fed. The hardware is
    :class:`SpringflatEngine`'s; ``tests/hdl/test_engine.py`` checks that a preload leaves every block RAM as
    the bus load does."""

    memory_windows = None

    def elaborate(self, platform):
        m = super().elaborate(platform)
        self.memory_windows = m.submodules.memories
        return m


#: Where the node window's fields (``node_word_layout``) live in the engine: memory, then its word's field.
NODE_FIELDS = {"position_x": ("positions", "x"), "position_y": ("positions", "y"),
               "velocity_x": ("velocities", "x"), "velocity_y": ("velocities", "y"),
               "inv_mass": ("weights", "inv_mass"), "inv_mass_barrier": ("weights", "inv_mass_barrier")}


def preload_words(windows, image, memories=None) -> dict[str, dict[int, int]]:
    """The words that writing ``image``'s rows of ``memories`` (default: all of :meth:`EngineImage.memories`) into
    the block RAMs of ``windows`` puts there, ``{block RAM: {address: word}}``, as the bus windows' write-back
    writes them: a node row's fields (unpacked with ``node_word_layout`` of the windows' format set) into the
    position, velocity and weight memories' words (:data:`NODE_FIELDS`), an entry or triangle row whole, its
    bus words side by side, the first the lowest. Each row at its window index (:meth:`EngineImage.rows`): the
    entries in banks of ``windows.entry_bank_depth`` rows (with K > 1 lanes, lane ``l``'s share in banks of its
    own, ``lane<l>_entries<b>``), and with lanes a node or triangle's row in bank ``index mod K`` at
    ``index // K``."""
    rams, lanes = windows.rams, windows.lanes
    rows = image.memories()
    members_of: dict[str, dict[str, str]] = {}  # memory -> {its word's member: the node field}
    for field, (ram_name, member) in NODE_FIELDS.items():
        members_of.setdefault(ram_name, {})[member] = field

    def banked(ram_name: str, index: int) -> tuple[str, int]:
        return (f"{ram_name}{index % lanes}", index // lanes) if lanes > 1 else (ram_name, index)

    def entry_bank(index: int) -> tuple[str, int]:
        if lanes == 1:
            bank, address = divmod(index, windows.entry_bank_depth)
            return f"entries{bank}", address
        lane, local = divmod(index, image.capacity.lane_entries)
        bank, address = divmod(local, windows.entry_bank_depth)
        return f"lane{lane}_entries{bank}", address

    words: dict[str, dict[int, int]] = {}
    for name in memories if memories is not None else rows:
        indices = image.rows(name)
        if name == "nodes":
            fields = node_word_layout(windows.fs, image.capacity).unpack(rows[name])
            for ram_name, members in members_of.items():
                for k, index in enumerate(indices):
                    ram, address = banked(ram_name, int(index))
                    word = {member: int(fields[field][k]) for member, field in members.items()}
                    words.setdefault(ram, {})[address] = rams[ram].shape.const(word).as_bits()
        else:
            for index, row_words in zip(indices, rows[name]):
                row = sum(int(word) << (BUS_WORD_BITS * k) for k, word in enumerate(row_words))
                ram, address = entry_bank(int(index)) if name == "entries" else banked(name, int(index))
                words.setdefault(ram, {})[address] = row
    return words


def preload(ctx, windows, image, memories=None) -> None:
    """Write ``image``'s rows of ``memories`` (default all) into the block RAMs of ``windows`` (a testbench's
    ``ctx``): the words of :func:`preload_words`."""
    for ram, words in preload_words(windows, image, memories).items():
        for address, word in words.items():
            ctx.set(Value.cast(windows.rams[ram].contents[address]), word)


def load_directly(driver, bus, dut: PreloadableEngine, image, memories=None) -> None:
    """``driver.load(image)`` with the memories (default all) written by :func:`preload` and only the run
    constants over the bus."""
    bus.in_simulator(lambda ctx: preload(ctx, dut.memory_windows, image, memories))
    driver.load(image, memories=())


def simulate(dut, host, watch=None):
    """Run ``host(driver, bus)`` (the synchronous driver, in a thread) against ``dut`` on the simulator."""
    bus = ThreadedBus(BusError, wait_states=watch.get("wait_states") if watch else None)
    bus.run(lambda: host(EngineDriver(bus, dut.register_map), bus))
    sim = Simulator(dut)
    sim.add_clock(1e-8)

    async def bench(ctx):
        await bus.serve(ctx, dut.bus)

    sim.add_testbench(bench)
    if watch and "watcher" in watch:
        sim.add_testbench(watch["watcher"], background=True)
    sim.run()
    return bus


def run_on_engine(dut, image, watch=None):
    """Load ``image`` (a :class:`PreloadableEngine`: :func:`load_directly`), start, wait, read back:
    ``(result, read_back)``."""
    out = {}

    def host(driver, bus):
        if isinstance(dut, PreloadableEngine):
            load_directly(driver, bus, dut, image)
        else:
            driver.load(image)
        driver.start()
        out["result"] = driver.wait(poll=lambda: bus.idle(100), max_polls=5000)
        out["read_back"] = driver.read_back()

    simulate(dut, host, watch)
    return out["result"], out["read_back"]


def assert_same_run(read_back, expected):
    assert read_back.result == expected.status
    assert read_back.iterations == expected.iterations
    assert read_back.saturations == expected.saturations
    assert (read_back.area_error, read_back.shape_error, read_back.energy) == (
        expected.area_error, expected.shape_error, expected.energy)
    np.testing.assert_array_equal(read_back.positions, expected.positions)
    np.testing.assert_array_equal(read_back.velocities, expected.velocities)


def guarded_image(case: str):
    """The image of ``GUARDED[case]``: the Tutte layout squeezed across by the case's factor."""
    squeeze, params, _ = GUARDED[case]
    return image_of(params, squeeze=squeeze)


def start_answers(driver, bus, constants: dict, change: dict) -> tuple[str, str]:
    """Write ``constants`` with ``change`` applied (the changed constants' words last, right before START: the
    check is current by then), START, and read STATUS (state, result) 20 clocks later; a run that started is
    aborted and drained."""
    constants = {**constants, **change}
    changed = set(driver.map.encode({k: constants[k] for k in change}))
    for offset, word in sorted(driver.map.encode(constants).items(), key=lambda item: (item[0] in changed, item[0])):
        bus.write(offset, word)
    driver.start()
    bus.idle(20)
    answer = driver._status_fields()
    if answer[0] == "running":
        driver.abort()
        bus.idle(400)
    return answer


def phase_spans(dut, phases):
    """A watcher (``simulate``'s ``watch={"watcher": ...}``) that records a run's phases: returns ``(watcher, spans,
    aborted_in, drained_at)``: each run's ``[phase, first clock, last clock]`` from START, and the phase a drain
    began in and its clock."""
    from golden_model.engine_spec.register_map import STATES

    spans, aborted_in, drained_at = [], [], []

    async def watch(ctx):
        phase, state, last, clock = dut.debug_signals["phase"], dut.debug_signals["state"], 0, 0
        while True:
            await ctx.tick()
            clock = clock + 1 if ctx.get(state) == STATES.index("running") else 0
            now = ctx.get(phase)
            if clock:
                if clock == 1 or spans[-1][0] != phases[now]:
                    spans.append([phases[now], clock - 1, clock - 1])
                spans[-1][2] = clock - 1
            if phases[now] == "drain" and phases[last] != "drain":
                aborted_in.append(phases[last])
                drained_at.append(clock)
            last = now

    return watch, spans, aborted_in, drained_at


def abort_after(driver, bus, dut, image, clocks: int) -> None:
    """Reload ``image``'s node memory (a run writes no other), START, ABORT ``clocks`` bus clocks later, and wait
    for the drain (STATUS idle): the next START may follow at once."""
    load_directly(driver, bus, dut, image, memories=("nodes",))
    driver.start()
    bus.idle(clocks)
    driver.abort()
    while driver.state() != "idle":
        bus.idle(50)


def load_and_snapshot(dut, image, over_the_bus: bool, rams=None, then=None) -> dict:
    """``image`` loaded into ``dut`` (a :class:`PreloadableEngine`) over the bus or preloaded, then every word of its
    block RAMs (those named in ``rams``, default all) read from the simulator: ``{block RAM: [words]}``. ``then``
    (``(driver, bus)``), if given, runs after the snapshot, in the same simulation."""
    contents = {}

    def snapshot(ctx):
        contents.update({name: [ctx.get(Value.cast(ram.contents[i])) for i in range(ram.depth)]
                         for name, ram in dut.memory_windows.rams.items() if rams is None or name in rams})

    def host(driver, bus):
        if over_the_bus:
            driver.load(image)
        else:
            load_directly(driver, bus, dut, image)
        bus.in_simulator(snapshot)
        if then is not None:
            then(driver, bus)

    simulate(dut, host)
    return contents


def aborts_then_a_whole_run(driver, bus, dut, image, drained_at: list, aborted_in: list, calibrate_at: int,
                            targets) -> object:
    """ABORT at the run's clock ``calibrate_at`` (as :func:`phase_spans` counts it; the lag from the bus's START to
    the run's first clock measured by that first abort, whose drain is then forgotten), then at each clock of
    ``targets``, each run from the reloaded node memory; then a whole run: its read-back."""
    abort_after(driver, bus, dut, image, calibrate_at)
    offset = drained_at[-1] - calibrate_at
    aborted_in.clear()
    for clock in targets:
        abort_after(driver, bus, dut, image, clock - offset)
    load_directly(driver, bus, dut, image, memories=("nodes",))
    driver.start()
    driver.wait(poll=lambda: bus.idle(100), max_polls=5000)
    return driver.read_back()
