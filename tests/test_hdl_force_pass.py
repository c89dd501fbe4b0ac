"""RTL force pass (hdl.ForcePass) against the golden model's ``node_terms``, in Amaranth's simulator.

Every node's ΣF, Σ|L − d|, ``inside`` and, with ``energy``, the exact Σe² and Σc·h are compared
bit for bit, in order, with random gaps in the input (the stream helpers of
:mod:`sim.stream_helpers`); both streams are always ready (the pass never stalls), so every
output is taken on the clock it is offered.
"""

import gc
import warnings

import numpy as np
import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.fixed import FormatSet
from golden_model.fixed.pipeline import NeighbourStream, neighbour_terms, node_terms, barrier_terms
from hdl import ForcePass, NodeUpdate
from sim.payloads import pack_beats, unpack_beats
from sim.stream_helpers import run_streams
from test_hdl_node_update import PRESETS, check_idle, random_stream


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
def test_random_nodes_with_input_gaps(preset, barrier, energy):
    fs = FormatSet.preset(preset)
    stream, positions, _ = random_stream(fs, 50, seed=31 + barrier, barrier=barrier)
    check_force_pass(ForcePass(fs, energy=energy), fs, stream, positions, seed=5, p_valid=0.7)


#: Independent pins of the stages the pass builds: front, barrier side line, rsqrt unit, back
#: (NodeUpdate's share is pinned in tests/test_hdl_node_update.py and docs/hardware.md).
STAGES = {"default": (14, 18, 28, 29), "narrow": (12, 15, 28, 23)}


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
        with pytest.raises(ValueError, match="more fraction bits than position"):
            ForcePass(FormatSet.preset("narrow").replace(delta="s3.16"))
        gc.collect()
