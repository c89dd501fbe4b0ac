"""RTL node-update datapath (hdl.NodeUpdate) against the golden model, in Amaranth's simulator.

Every node's new position, velocity and Σ|L − d| is compared bit for bit with
``golden_model.fixed.pipeline.node_update``, in order, under seeded random
valid/ready stalls on both sides (the stream helpers of :mod:`support.streams`).
"""

import gc
import warnings

import numpy as np
import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.builtin import builtin_mesh
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import FixedEngine, prepare
from golden_model.fixed.pipeline import BarrierEntries, NeighbourStream, NodeConstants, node_update
from golden_model.fixed import SaturationCounter
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from hdl import NodeUpdate
from sim.payloads import pass_beats, unpack_beats
from support import PRESETS
from support.streams import run_streams
from golden_model.engine_spec.image import UNGUARDED



def simulate(dut, beats, n_out, constants, *, momentum=False, **kw):
    """Stream ``beats`` into ``dut.i`` and collect ``n_out`` results (:func:`support.streams.run_streams`,
    which checks the stream rules), the constant inputs set first; ``idle`` recorded at every edge."""
    def setup(ctx):
        for port, value in zip((dut.dt, dut.half_dt_sq, dut.half_spring, dut.damping), constants):
            ctx.set(port, value)
        ctx.set(dut.momentum, momentum)

    # the constants are registered once: the streams start two edges later
    return run_streams(dut, beats, n_out, setup=setup, start=2, watch={"idle": dut.idle}, **kw)


def check_pass(dut, fs, stream, positions, velocities, constants, momentum=False, **kw):
    """One pass through the RTL against ``node_update``; returns the run."""
    beats = pass_beats(dut.i.payload.shape(), stream, positions, velocities)
    run = simulate(dut, beats, len(stream.indptr) - 1, (constants.dt, constants.half_dt_sq, constants.half_spring,
                                                        constants.damping), momentum=momentum, **kw)
    want = node_update(fs, positions, velocities, stream, constants, momentum=momentum)
    check_idle(run, stream)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    for name, got, expected in (
        ("position.x", out["position"]["x"], want.positions[:, 0]),
        ("position.y", out["position"]["y"], want.positions[:, 1]),
        ("velocity.x", out["velocity"]["x"], want.velocities[:, 0]),
        ("velocity.y", out["velocity"]["y"], want.velocities[:, 1]),
        ("error_sum", out["error_sum"], want.error_sums),
        ("power", out["power"], want.power),
    ):
        bad = np.flatnonzero(got != expected)
        if bad.size:
            i = int(bad[0])
            pytest.fail(f"{name}: {bad.size} mismatches; first at node {i}: rtl {int(got[i])} golden {int(expected[i])}")
    return run


def check_idle(run, stream):
    """``idle`` in every cycle: high exactly when the entries accepted so far end on a node
    boundary and every one of those nodes' results has been taken."""
    idle = run.watched["idle"]
    entries_in = np.searchsorted(run.in_cycles, np.arange(len(idle)))  # accepted before cycle c
    results_out = np.searchsorted(run.out_cycles, np.arange(len(idle)))
    nodes_in = np.searchsorted(stream.indptr, entries_in, side="right") - 1  # complete nodes among them
    expected = (stream.indptr[nodes_in] == entries_in) & (results_out == nodes_in)
    bad = np.flatnonzero(np.asarray(idle, dtype=bool) != expected)
    assert bad.size == 0, f"idle wrong in {bad.size} cycles, first {int(bad[0])}: rtl {idle[int(bad[0])]}"


def random_stream(fs, n_nodes, seed, max_degree=12, barrier=False):
    """Nodes of random degree 1..max_degree with random neighbours around them (a synthetic stream).

    With ``barrier``, each entry's triangle has a random third corner (one of the node's
    neighbours), threshold and gain (0 on about a fifth of the entries), so that some
    triangles are folded, some short of the threshold and some clear of it.
    """
    rng = np.random.default_rng(seed)
    degree = rng.integers(1, max_degree + 1, n_nodes)
    n_total = n_nodes + int(degree.sum())
    scale = 1 << fs.position.frac_bits
    positions = rng.integers(-4 * scale, 4 * scale, size=(n_total, 2))
    indptr = np.r_[0, np.cumsum(degree)]
    neighbour = n_nodes + np.arange(int(degree.sum()))
    owner = np.repeat(np.arange(n_nodes), degree)
    # neighbours at 0.3 .. 2.5 mean edges from their node, rest lengths around that
    angle = rng.uniform(0, 2 * np.pi, len(neighbour))
    radius = rng.uniform(0.3, 2.5, len(neighbour))
    positions[neighbour] = positions[owner] + (np.column_stack([np.cos(angle), np.sin(angle)])
                                               * radius[:, None] * scale).astype(np.int64)
    rest = (radius * rng.uniform(0.7, 1.3, len(radius)) * (1 << fs.rest_length.frac_bits)).astype(np.int64)
    inv_mass = rng.integers(1 << (fs.inv_mass.frac_bits - 2), 2 << fs.inv_mass.frac_bits, n_nodes)
    velocities = rng.integers(-(1 << fs.velocity.frac_bits), 1 << fs.velocity.frac_bits, size=(n_nodes, 2))
    entries = None
    if barrier:
        second = neighbour[indptr[owner] + rng.integers(0, degree[owner])]
        threshold = rng.uniform(0, 1.5, len(neighbour)) * (1 << fs.area.frac_bits)
        gain = rng.uniform(0, 4, len(neighbour)) * (rng.random(len(neighbour)) > 0.2) * (1 << fs.barrier_gain.frac_bits)
        entries = BarrierEntries(second, threshold.astype(np.int64), gain.astype(np.int64))
        # a second weight, taken where a triangle of the node is inside the barrier
        inv_mass_barrier = rng.integers(1 << (fs.inv_mass.frac_bits - 2), 2 << fs.inv_mass.frac_bits, n_nodes)
    stream = NeighbourStream(indptr, neighbour, rest, inv_mass, entries,
                             inv_mass_barrier if barrier else None)
    return stream, positions, velocities


def random_constants(fs, seed):
    rng = np.random.default_rng(seed)
    dt = int(rng.uniform(0.01, 0.21) * (1 << fs.dt.frac_bits))
    half = int(round(dt * dt / 2 / (1 << (2 * fs.dt.frac_bits - fs.half_dt_sq.frac_bits))))
    return NodeConstants(dt, half, int(0.25 * (1 << fs.spring.frac_bits)),
                         int(rng.uniform(0.9, 1.0) * (1 << fs.damping.frac_bits)))


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_random_nodes_of_degree_1_to_12_with_stalls(preset):
    fs = FormatSet.preset(preset)
    stream, positions, velocities = random_stream(fs, 60, seed=1)
    velocities_all = np.zeros_like(positions)
    velocities_all[:60] = velocities
    check_pass(NodeUpdate(fs), fs, stream, positions, velocities_all, random_constants(fs, 2),
               seed=3, p_valid=0.7, p_ready=0.6)


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("mesh_name", ["surf1", "surf2"])
def test_builtin_meshes_over_several_iterations(preset, mesh_name):
    """Every node of the mesh, the state of iterations 0..2 of a fixed-point flattening (four iterations
    of Surf2 with stalls and a reset run on the exported Verilog: ``tests/sim/test_cocotb.py``)."""
    fs = FormatSet.preset(preset)
    mesh, paper = builtin_mesh(mesh_name)
    params = FlattenParams(density=paper.density, damping=0.02)
    engine = FixedEngine(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), SaturationCounter())
    dut = NodeUpdate(fs)
    for iteration in range(3):
        engine.step_size(engine.measure())
        constants = engine.problem.constants(engine.dt)
        check_pass(dut, fs, engine.problem.stream, engine.raw_positions, engine.raw_velocities, constants,
                   seed=10 + iteration, p_valid=0.8, p_ready=0.7)
        engine.advance(0)


#: The documented latency (``docs/hardware.md``'s contract table; ``tests/test_docs.py`` checks that it says
#: these numbers): front + rsqrt unit + back + tail, plus the result FIFO's write and the output register.
LATENCY = {"default": (102, (14, 28, 29, 28)), "narrow": (91, (12, 28, 23, 25)), "wide": (102, (14, 28, 29, 28))}


@pytest.mark.parametrize("preset", PRESETS)
def test_documented_latency(preset):
    with warnings.catch_warnings():  # built for its attributes only, never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        dut = NodeUpdate(FormatSet.preset(preset))
        stages = (dut.latency, (dut.front_stages, dut.rsqrt_latency, dut.back_stages, dut.tail_stages))
        del dut
        gc.collect()
    assert stages == LATENCY[preset]


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_no_bubbles(preset):
    """Never stalled: N entries go in on N consecutive clocks and the last result leaves latency clocks later
    (the documented latency, measured)."""
    fs = FormatSet.preset(preset)
    stream, positions, velocities = random_stream(fs, 40, seed=4)
    v = np.zeros_like(positions)
    v[:40] = velocities
    dut = NodeUpdate(fs)
    assert dut.latency == LATENCY[preset][0]
    run = check_pass(dut, fs, stream, positions, v, random_constants(fs, 5))
    n = len(stream.neighbour)
    assert run.in_cycles == list(range(n))
    last_entry = np.r_[stream.indptr[1:] - 1]
    assert run.out_cycles == [int(c) + dut.latency for c in last_entry]


def check_degree_one_nodes(dut, fs, n_nodes, seed, **kw):
    """``n_nodes`` nodes of one neighbour each through the RTL against the golden model."""
    stream, positions, velocities = random_stream(fs, n_nodes, seed=seed, max_degree=1)
    v = np.zeros_like(positions)
    v[:n_nodes] = velocities
    return check_pass(dut, fs, stream, positions, v, random_constants(fs, seed + 1), **kw)


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_no_bubbles_with_degree_1_nodes(preset):
    """One entry per node, never stalled: the credits cover the latency, so the input never waits."""
    fs = FormatSet.preset(preset)
    dut = NodeUpdate(fs)
    n = 3 * dut.latency
    run = check_degree_one_nodes(dut, fs, n, seed=6)
    assert run.in_cycles == list(range(n))
    assert run.out_cycles == [c + dut.latency for c in range(n)]


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_a_long_output_stall_fills_the_results_and_stops_the_input(preset):
    """o.ready low for a long time: exactly ``result_depth`` nodes are accepted, then i.ready falls."""
    fs = FormatSet.preset(preset)
    dut = NodeUpdate(fs)
    stall = 4 * dut.result_depth
    run = check_degree_one_nodes(dut, fs, 2 * dut.result_depth, seed=8, ready_after=stall)
    accepted_during_stall = sum(c < stall for c in run.in_cycles)
    assert accepted_during_stall == dut.result_depth


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("momentum", [False, True])
def test_random_nodes_with_barrier_triangles(preset, momentum):
    """Barrier terms on random triangles (folded, short of the threshold, clear) in both dynamics."""
    fs = FormatSet.preset(preset)
    stream, positions, velocities = random_stream(fs, 60, seed=11, barrier=True)
    v = np.zeros_like(positions)
    v[:60] = velocities
    constants = random_constants(fs, 12)
    if momentum:
        constants = NodeConstants(int(0.7 * (1 << fs.dt.frac_bits)), 0, constants.half_spring, 1 << fs.damping.frac_bits)
    check_pass(NodeUpdate(fs), fs, stream, positions, v, constants, momentum=momentum, seed=13, p_valid=0.8,
               p_ready=0.7)


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_momentum_flattening_over_several_iterations(preset):
    """A 4-ring spherical cap with the barrier: iterations 0..5 of the momentum dynamics, restarts included."""
    from sim.generate import spherical_cap
    fs = FormatSet.preset(preset)
    mesh = spherical_cap(4)
    params = FlattenParams(dynamics="momentum", **UNGUARDED)
    engine = FixedEngine(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), SaturationCounter())
    dut = NodeUpdate(fs)
    for iteration in range(6):
        engine.step_size(engine.measure())
        check_pass(dut, fs, engine.problem.stream, engine.raw_positions, engine.raw_velocities,
                   engine.problem.constants(engine.dt), momentum=True, seed=20 + iteration, p_valid=0.9, p_ready=0.8)
        engine.advance(0)
