"""RTL force pass (hdl.ForcePass) against the golden model's ``node_terms``, in Amaranth's simulator.

Every node's ΣF, Σ|L − d|, ``inside`` and, with ``energy``, the exact Σe² and Σc·h are compared
bit for bit, in order, with random gaps in the input (the stream helpers of
:mod:`support.streams`); both streams are always ready (the pass never stalls), so every
output is taken on the clock it is offered.
"""

import gc
import re
import warnings

import numpy as np
import pytest
from amaranth.back import rtlil
from amaranth.hdl import Elaboratable, Module, UnusedElaboratable, unsigned

from golden_model.fixed import FormatSet, SaturationCounter
from golden_model.fixed.pipeline import BarrierEntries, NeighbourStream, neighbour_terms, node_terms, barrier_terms
from hdl import ForcePass, NodeUpdate
from hdl.dsp import ECP5
from hdl.fixedpoint import FormatSetNotBuildable
from hdl.layouts import force_saturations_max
from sim.payloads import pack_beats, unpack_beats
from support.streams import run_streams
from support import PRESETS
from test_hdl_node_update import check_idle, random_stream


def force_beats(layout, stream: NeighbourStream, positions: np.ndarray) -> list[int]:
    """The force pass's input beats: every node's entries in CSR order, its position on the first."""
    owner = stream.owner
    index = np.arange(len(owner))
    first = stream.indptr[:-1][owner] == index
    fields = {
        "first": first.astype(np.int64), "last": (stream.indptr[1:][owner] - 1 == index).astype(np.int64),
        "position": {"x": positions[owner, 0] * first, "y": positions[owner, 1] * first},
        "neighbour": {"position": {"x": positions[stream.neighbour, 0], "y": positions[stream.neighbour, 1]},
                      "rest": stream.rest},
    }
    if stream.barrier is not None:
        fields["barrier"] = {
            "second": {"x": positions[stream.barrier.second, 0], "y": positions[stream.barrier.second, 1]},
            "threshold": stream.barrier.threshold, "gain": stream.barrier.gain}
    return pack_beats(layout, fields)


def half_spring_of(fs):
    return int(0.25 * (1 << fs.spring.frac_bits))


def check_force_pass(dut, fs, stream, positions, **kw):
    """One pass through the RTL against ``node_terms``; returns the run."""
    half_spring = half_spring_of(fs)
    run = run_streams(dut, force_beats(dut.i.payload.shape(), stream, positions), len(stream.indptr) - 1,
                      setup=lambda ctx: ctx.set(dut.half_spring, half_spring), start=1,
                      watch={"idle": dut.idle}, **kw)
    want = node_terms(fs, positions, stream, half_spring)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    expected = {"force.x": want.force[:, 0], "force.y": want.force[:, 1], "error_sum": want.error_sums}
    got = {"force.x": out["force"]["x"], "force.y": out["force"]["y"], "error_sum": out["error_sum"],
           "inside": out["inside"]}
    if want.barrier_active is not None:  # without a barrier the entries' zero triangles mean nothing
        expected["inside"] = want.barrier_active
    if dut.energy:
        expected.update(error_squares=want.error_squares, barrier_energy=want.barrier_energies)
        got.update(error_squares=out["error_squares"], barrier_energy=out["barrier_energy"])
    for name, values in expected.items():
        bad = np.flatnonzero(got[name] != values)
        if bad.size:
            i = int(bad[0])
            pytest.fail(f"{name}: {bad.size} mismatches; first at node {i}: rtl {int(got[name][i])} "
                        f"golden {int(values[i])}")
    check_idle(run, stream)
    return run


def test_golden_energy_partials_are_the_per_entry_definition():
    """``NodeTerms.error_squares`` / ``barrier_energies``: each node's Σe² and Σc·h over its own entries
    (Python integers, exact), for a synthetic stream with a barrier."""
    fs = FormatSet.preset("default")
    stream, positions, _ = random_stream(fs, 40, seed=21, barrier=True)
    terms = node_terms(fs, positions, stream, half_spring_of(fs))
    _, e = neighbour_terms(fs, positions, stream, half_spring_of(fs))
    *_, ch = barrier_terms(fs, positions, stream)
    spans = list(zip(stream.indptr[:-1], stream.indptr[1:]))
    assert terms.error_squares.tolist() == [sum(int(v) ** 2 for v in e[a:b]) for a, b in spans]
    assert terms.barrier_energies.tolist() == [sum(int(v) for v in ch[a:b]) for a, b in spans]
    assert terms.barrier_energy_sum > 0 and terms.error_square_sum == sum(int(v) ** 2 for v in e)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("barrier", [False, True])
@pytest.mark.parametrize("energy", [False, True])
@pytest.mark.parametrize("delay_lines", [False, True])
def test_random_nodes_with_input_gaps(preset, barrier, energy, delay_lines):
    fs = FormatSet.preset(preset)
    stream, positions, _ = random_stream(fs, 50, seed=31 + barrier, barrier=barrier)
    check_force_pass(ForcePass(fs, energy=energy, delay_lines=delay_lines), fs, stream, positions, seed=5, p_valid=0.7)


#: Independent pins of the stages the pass builds: front, barrier side line, rsqrt unit, back
#: (NodeUpdate's share is pinned in tests/hdl/test_hdl_node_update.py and docs/hardware.md).
STAGES = {"default": (14, 18, 28, 29), "narrow": (12, 15, 28, 23), "wide": (14, 18, 28, 29)}


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("energy", [False, True])
def test_stage_counts(preset, energy):
    with warnings.catch_warnings():  # built for its attributes only, never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        dut = ForcePass(preset, energy=energy)
        stages = dut.stages
        node_update = NodeUpdate(preset)
        shared = (node_update.front_stages, node_update.rsqrt_latency, node_update.back_stages)
        del dut, node_update
        gc.collect()
    assert (stages.front, stages.barrier, stages.rsqrt, stages.back) == STAGES[preset]
    assert shared == (stages.front, stages.rsqrt, stages.back)


@pytest.mark.parametrize("preset", PRESETS)
def test_no_gaps_and_the_measured_latency(preset):
    """Entries on consecutive clocks, each node's result exactly ``latency`` clocks after its last entry."""
    fs = FormatSet.preset(preset)
    stream, positions, _ = random_stream(fs, 40, seed=41, barrier=True)
    dut = ForcePass(fs, energy=True)
    assert dut.latency == sum(STAGES[preset]) - STAGES[preset][1]
    run = check_force_pass(dut, fs, stream, positions)
    assert run.in_cycles == list(range(len(stream.neighbour)))
    assert run.out_cycles == [int(c) + dut.latency for c in stream.indptr[1:] - 1]


def test_refuses_what_it_cannot_build():
    with warnings.catch_warnings():  # the refused objects are never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match="ForcePass needs a FormatSet"):
            ForcePass(3)
        with pytest.raises(FormatSetNotBuildable, match="more fraction bits than position"):
            ForcePass(FormatSet.preset("narrow").replace(delta="s3.16"))
        gc.collect()


# ---------------------------------------------------------------- saturation events

def saturating_stream(fs, n_nodes, seed, *, mesh=False, barrier=True):
    """Entries that saturate every signal the formats let saturate: neighbours from 1/4096 to 32
    mean edges away (and coincident), rest lengths over the whole [rest_length] range, barrier
    thresholds and gains over their whole ranges, third corners near and far.

    ``mesh``: an undirected graph (each edge's two entries with one rest length), so that
    ``node_terms`` takes its per-edge path (``edge_terms``); otherwise a synthetic stream whose
    nodes include one of degree ``max_degree``. Returns ``(stream, positions, entry degrees)``.
    """
    rng = np.random.default_rng(seed)
    scale = 1 << fs.position.frac_bits

    def spread(size):  # offsets of log-uniform length in random directions, some exactly zero
        length = 2.0 ** rng.uniform(-12, 5, size) * (rng.random(size) > 0.05)
        angle = rng.uniform(0, 2 * np.pi, size)
        return (np.column_stack([np.cos(angle), np.sin(angle)]) * length[:, None] * scale).astype(np.int64)

    if mesh:
        n_total = n_nodes
        positions = rng.integers(-64 * scale, 64 * scale, size=(n_total, 2))
        pairs = {(int(a), int(b)) for a, b in rng.integers(0, n_nodes, (6 * n_nodes, 2)) if a != b}
        pairs = sorted({(min(a, b), max(a, b)) for a, b in pairs})
        for a, b in pairs[::2]:  # half the edges short or long whatever their nodes' places
            positions[b] = positions[a] + spread(1)[0]
        rest_of = dict(zip(pairs, rng.integers(0, fs.rest_length.raw_max + 1, len(pairs))))
        lists = [sorted([b for a, b in pairs if a == i] + [a for a, b in pairs if b == i]) for i in range(n_nodes)]
        keep = [i for i in range(n_nodes) if lists[i]]
        assert len(keep) == n_nodes, "every node needs an edge"
        degree = np.array([len(lst) for lst in lists])
        neighbour = np.concatenate([np.array(lst, dtype=np.int64) for lst in lists])
        owner = np.repeat(np.arange(n_nodes), degree)
        rest = np.array([rest_of[(min(i, j), max(i, j))] for i, j in zip(owner, neighbour)], dtype=np.int64)
    else:
        degree = rng.integers(1, 17, n_nodes)
        degree[n_nodes // 2] = fs.max_degree
        n_total = n_nodes + int(degree.sum())
        positions = rng.integers(-64 * scale, 64 * scale, size=(n_total, 2))
        neighbour = n_nodes + np.arange(int(degree.sum()))
        owner = np.repeat(np.arange(n_nodes), degree)
        near = rng.random(len(neighbour)) < 0.8
        positions[neighbour[near]] = positions[owner[near]] + spread(int(near.sum()))
        rest = rng.integers(0, fs.rest_length.raw_max + 1, len(neighbour))
    indptr = np.r_[0, np.cumsum(degree)]
    entries = None
    if barrier:
        n = len(neighbour)
        second = np.where(rng.random(n) < 0.5, neighbour[indptr[owner] + rng.integers(0, degree[owner])],
                          rng.integers(0, n_total, n))
        threshold = rng.integers(0, fs.area.raw_max + 1, n)
        gain = rng.integers(0, fs.barrier_gain.raw_max + 1, n) * (rng.random(n) > 0.2)
        entries = BarrierEntries(second, threshold, gain)
    inv_mass = np.full(n_nodes, 1 << fs.inv_mass.frac_bits)
    return NeighbourStream(indptr, neighbour, rest, inv_mass, entries), positions


def node_events(fs, stream, positions, half_spring):
    """``(V,)`` each node's saturation events by the golden model: ``node_terms`` of the node alone."""
    counts = []
    for i, (a, b) in enumerate(zip(stream.indptr[:-1], stream.indptr[1:])):
        barrier = None  # the node is node 0 of its stream: every other index moves up by one
        if stream.barrier is not None:
            barrier = BarrierEntries(stream.barrier.second[a:b] + 1, stream.barrier.threshold[a:b],
                                     stream.barrier.gain[a:b])
        alone = NeighbourStream(np.array([0, b - a]), stream.neighbour[a:b] + 1, stream.rest[a:b],
                                stream.inv_mass[:1], barrier)
        counter = SaturationCounter()
        node_terms(fs, np.vstack([positions[i], positions]), alone, half_spring, counter)
        counts.append(counter.total)
    return np.array(counts)


def run_saturations(fs, stream, positions, half_spring, *, barrier_on, beats_stream=None, delay_lines=False):
    """The RTL's per-node ``saturations`` (``beats_stream``: the stream whose triangles the beats carry)."""
    dut = ForcePass(fs, saturations=True, delay_lines=delay_lines)
    beats = force_beats(dut.i.payload.shape(), beats_stream or stream, positions)

    def setup(ctx):
        ctx.set(dut.half_spring, half_spring)
        ctx.set(dut.barrier, barrier_on)

    run = run_streams(dut, beats, len(stream.indptr) - 1, setup=setup, start=1, seed=11, p_valid=0.8)
    return unpack_beats(dut.o.payload.shape(), run.outputs)


@pytest.mark.parametrize("preset", [pytest.param("default", marks=pytest.mark.slow), "narrow"])  # default: 30-50 s
@pytest.mark.parametrize("barrier", [False, True])
@pytest.mark.parametrize("mesh", [False, True], ids=["synthetic", "mesh"])
@pytest.mark.parametrize("delay_lines", [False, True])
def test_saturations_count_every_golden_event(preset, barrier, mesh, delay_lines):
    """Each node's ``saturations`` is the number of events ``node_terms`` counts for it, and over
    the pass they sum to ``SaturationCounter().total`` (on a mesh: the per-edge path, each edge's
    events counted for both entries). Without the barrier its (random) triangles count nothing."""
    fs = FormatSet.preset(preset)
    half_spring = fs.spring.raw_max // 3
    stream, positions = saturating_stream(fs, 40 if not mesh else 60, seed=50 + barrier + 2 * mesh, mesh=mesh,
                                          barrier=barrier)
    assert (stream.edge_entries is not None) == mesh
    counter = SaturationCounter()
    want = node_terms(fs, positions, stream, half_spring, counter)
    # without the barrier the beats' triangles are filler as the engine sends them: third corners
    # anywhere (their Δb, D and X saturate), threshold and gain 0
    triangles = saturating_stream(fs, 40 if not mesh else 60, seed=50 + 2 * mesh, mesh=mesh)[0].barrier
    zero = np.zeros_like(triangles.gain)
    filler = NeighbourStream(stream.indptr, stream.neighbour, stream.rest, stream.inv_mass,
                             BarrierEntries(triangles.second, zero, zero))
    out = run_saturations(fs, stream, positions, half_spring, barrier_on=barrier,
                          beats_stream=None if barrier else filler, delay_lines=delay_lines)
    assert np.array_equal(out["force"]["x"], want.force[:, 0]) and np.array_equal(out["error_sum"], want.error_sums)
    per_node = node_events(fs, stream, positions, half_spring)
    assert per_node.sum() == counter.total
    bad = np.flatnonzero(out["saturations"] != per_node)
    assert bad.size == 0, (f"{bad.size} nodes miscounted; first {int(bad[0])}: rtl {int(out['saturations'][bad[0]])}"
                           f" golden {int(per_node[bad[0]])}")
    assert int(out["saturations"].sum()) == counter.total
    # the stream is designed to saturate: most of the names the format lets saturate did
    reachable = {"delta", "length_sq", "rsqrt", "one_minus_dr", "spring", "length", "force", "force_acc"}
    if barrier:
        reachable |= {"area_short", "barrier_coeff", "barrier_edge", "barrier_force"} | (
            {"area"} if preset == "narrow" else set())  # |Δa × Δb| < 128 fits the default's s8.22
    assert reachable <= set(counter.saturations), reachable - set(counter.saturations)


@pytest.mark.parametrize("preset", PRESETS)
def test_saturations_zero_without_events(preset):
    """A pass inside every range (gentle gains: the barrier's triangles inside it, none saturating)
    counts 0 on every node."""
    fs = FormatSet.preset(preset)
    stream, positions, _ = random_stream(fs, 30, seed=31, barrier=True)
    gentle = BarrierEntries(stream.barrier.second, stream.barrier.threshold, stream.barrier.gain // 64)
    stream = NeighbourStream(stream.indptr, stream.neighbour, stream.rest, stream.inv_mass, gentle)
    counter = SaturationCounter()
    node_terms(fs, positions, stream, half_spring_of(fs), counter)
    assert counter.total == 0
    out = run_saturations(fs, stream, positions, half_spring_of(fs), barrier_on=True)
    assert not out["saturations"].any()


def test_saturations_leave_the_default_build_alone():
    """``saturations=False`` (the default) has the layouts, ports and stages it had."""
    with warnings.catch_warnings():  # built for their attributes only, never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        plain, counting = ForcePass("default"), ForcePass("default", saturations=True)
        assert "saturations" not in dict(plain.o.payload.shape()) and not hasattr(plain, "barrier")
        assert counting.o.payload.saturations.shape() == unsigned(force_saturations_max(counting.fs).bit_length())
        assert force_saturations_max(counting.fs) == 32 * 18 + 3
        assert counting.stages == plain.stages
        del plain, counting
        gc.collect()


class _Wrapped(Elaboratable):
    """A component with constant ports (always-ready streams) converted as a submodule."""

    def __init__(self, dut):
        self.dut = dut

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = self.dut
        return m


@pytest.mark.parametrize("energy, saturations", [(False, False), (True, True)])
def test_each_accumulator_restarts_from_kept_copies_in_the_ecp5_form(energy, saturations):
    """In the ECP5 form every accumulator reads B10's valid and first bits from kept flip-flops of its own
    (one pair fanned out to all of them was a path across the device); the generic form has plain registers."""
    names = {"f_x", "f_y", "e", "inside"} | ({"e_sq", "ch"} if energy else set()) | ({"ev"} if saturations else set())
    for platform in (ECP5, None):
        top = _Wrapped(ForcePass("default", energy=energy, saturations=saturations))
        text = rtlil.convert(top, platform=platform, ports=[top.dut.i.valid, top.dut.o.valid])
        for bit in ("valid", "first"):
            copies = {name for name in names if f"b10_{bit}_{name}_ff0" in text}
            assert copies == (names if platform is ECP5 else set()), (bit, platform, copies)
            # each copy is read (beyond its declaration and the flip-flop driving it)
            read = {name for name in copies
                    if any(re.search(rf"\\b10_{bit}_{name}\b", line)
                           and not line.lstrip().startswith(("wire ", "connect \\Q ")) for line in text.splitlines())}
            assert read == copies, (bit, platform, read)
        kept = len(re.findall(r"^\s*cell \\TRELLIS_FF ", text, re.M))
        assert kept == (2 * len(names) if platform is ECP5 else 0), (platform, kept)
