"""RTL integrate stage (hdl.Integrator) against the golden model's ``integrate`` /
``integrate_momentum`` and ``node_power``, and the guarded mode's ``proposal``, in Amaranth's simulator.

Random nodes (state, force, both weights, ``inside``) in both dynamics, compared bit for bit and in
order, with random gaps in the input (the stream helpers of :mod:`support.streams`).
"""

import gc
import re
import warnings

import numpy as np
import pytest
from amaranth.back import rtlil
from amaranth.hdl import UnusedElaboratable, unsigned

from golden_model.fixed import FormatSet, SaturationCounter
from golden_model.fixed.guard import proposal
from golden_model.fixed.pipeline import NodeConstants, integrate, integrate_momentum, node_power
from golden_model.guard import SCALE_MAX_SHIFT
from hdl import Integrator, NodeUpdate
from hdl.dsp import ECP5
from hdl.fixedpoint import FormatSetNotBuildable
from sim.payloads import pack_beats, unpack_beats
from support.streams import run_streams
from test_hdl_force_pass import _Wrapped
from test_hdl_node_update import PRESETS, random_constants

SIDE = unsigned(20)


def random_nodes(fs, n, seed):
    """``n`` nodes: positions, velocities, forces over their formats' whole ranges (saturations
    included), weights around 1, ``inside`` on about a third, a random side value."""
    rng = np.random.default_rng(seed)

    def raw(fmt, size, scale=1.0):
        return rng.integers(int(fmt.raw_min * scale), int(fmt.raw_max * scale) + 1, size=size)

    return {
        "position": raw(fs.position, (n, 2), 1 / 64), "velocity": raw(fs.velocity, (n, 2), 1 / 4),
        "force": raw(fs.force_acc, (n, 2)),
        "inv_mass": rng.integers(1 << (fs.inv_mass.frac_bits - 2), 2 << fs.inv_mass.frac_bits, n),
        "inv_mass_barrier": rng.integers(1 << (fs.inv_mass.frac_bits - 3), 1 << fs.inv_mass.frac_bits, n),
        "inside": rng.random(n) < 0.3,
        "side": rng.integers(0, 1 << SIDE.width, n),
    }


def check_integrator(dut, fs, nodes, constants, momentum=False, scale_shift=0, propose=False, **kw):
    """The nodes through the RTL against the golden model; returns the run (``scale_shift`` and
    ``propose`` driven as given: the paper's step and a momentum step at shift 0 ignore them)."""
    vec = lambda a: {"x": a[:, 0], "y": a[:, 1]}  # noqa: E731
    beats = pack_beats(dut.i.payload.shape(), {
        "node": {"position": vec(nodes["position"]), "velocity": vec(nodes["velocity"]),
                 "inv_mass": nodes["inv_mass"], "inv_mass_barrier": nodes["inv_mass_barrier"]},
        "force": vec(nodes["force"]), "inside": nodes["inside"].astype(np.int64), "side": nodes["side"]})

    def setup(ctx):
        for port, value in ((dut.dt, constants.dt), (dut.half_dt_sq, constants.half_dt_sq),
                            (dut.damping, constants.damping), (dut.momentum, momentum),
                            (dut.scale_shift, scale_shift), (dut.propose, propose)):
            ctx.set(port, value)

    # the constants are registered once: the stream starts one edge later
    run = run_streams(dut, beats, setup=setup, start=1, watch={"idle": dut.idle}, **kw)
    weights = np.where(nodes["inside"], nodes["inv_mass_barrier"], nodes["inv_mass"])
    p, v, f = nodes["position"], nodes["velocity"], nodes["force"]
    if momentum:
        want_p, want_v = integrate_momentum(fs, p, v, f, weights, constants.dt)
    else:
        want_p, want_v = integrate(fs, p, v, f, weights, constants)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    for name, got, expected in (
        ("position.x", out["position"]["x"], want_p[:, 0]), ("position.y", out["position"]["y"], want_p[:, 1]),
        ("velocity.x", out["velocity"]["x"], want_v[:, 0]), ("velocity.y", out["velocity"]["y"], want_v[:, 1]),
        ("power", out["power"], node_power(fs, f, v)), ("side", out["side"], nodes["side"]),
    ):
        bad = np.flatnonzero(got != expected)
        if bad.size:
            i = int(bad[0])
            pytest.fail(f"{name}: {bad.size} mismatches; first at node {i}: rtl {int(got[i])} golden {int(expected[i])}")
    # idle: high exactly when every node taken in has come out
    idle = np.asarray(run.watched["idle"], dtype=bool)
    edges = np.arange(len(idle))
    expected_idle = np.searchsorted(run.in_cycles, edges) == np.searchsorted(run.out_cycles, edges)
    assert np.array_equal(idle, expected_idle), f"idle wrong at edge {int(np.flatnonzero(idle != expected_idle)[0])}"
    return run


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("momentum", [False, True])
@pytest.mark.parametrize("delay_lines", [False, True])
def test_random_nodes_with_input_gaps(preset, momentum, delay_lines):
    fs = FormatSet.preset(preset)
    constants = random_constants(fs, 7)
    if momentum:
        constants = NodeConstants(int(0.7 * (1 << fs.dt.frac_bits)), 0, constants.half_spring, 1 << fs.damping.frac_bits)
    dut = Integrator(fs, side=SIDE, delay_lines=delay_lines)
    check_integrator(dut, fs, random_nodes(fs, 300, seed=8 + momentum), constants, momentum=momentum, seed=9,
                     p_valid=0.6)


#: Independent pins of the stages the integrator builds (NodeUpdate's tail_stages).
LATENCY = {"default": 28, "narrow": 25, "wide": 28}


@pytest.mark.parametrize("preset", PRESETS)
def test_latency_pin(preset):
    with warnings.catch_warnings():  # built for their attributes only, never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        latencies = Integrator(preset).latency, Integrator(preset, side=SIDE).latency, NodeUpdate(preset).tail_stages
        gc.collect()
    assert latencies == (LATENCY[preset],) * 3


@pytest.mark.parametrize("preset", PRESETS)
def test_one_node_per_clock_and_the_measured_latency(preset):
    fs = FormatSet.preset(preset)
    dut = Integrator(fs, side=SIDE)
    assert dut.latency == LATENCY[preset]
    n = 100
    run = check_integrator(dut, fs, random_nodes(fs, n, seed=10), random_constants(fs, 11))
    assert run.in_cycles == list(range(n))
    assert run.out_cycles == [c + dut.latency for c in range(n)]


def test_refuses_what_it_cannot_build():
    with warnings.catch_warnings():  # the refused objects are never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match="Integrator needs a FormatSet"):
            Integrator(None)
        with pytest.raises(FormatSetNotBuildable, match="fraction bits"):
            Integrator(FormatSet.preset("narrow").replace(velocity="s3.16"))
        gc.collect()


# ---------------------------------------------------------------- saturation events

def saturating_nodes(fs, n, seed):
    """Nodes that saturate every signal the formats let saturate: positions, velocities and forces
    over their formats' whole ranges, weights over the whole [inv_mass] range."""
    rng = np.random.default_rng(seed)

    def raw(fmt, size):
        return rng.integers(fmt.raw_min, fmt.raw_max + 1, size=size)

    nodes = {"position": raw(fs.position, (n, 2)), "velocity": raw(fs.velocity, (n, 2)),
             "force": raw(fs.force_acc, (n, 2)), "inv_mass": raw(fs.inv_mass, n),
             "inv_mass_barrier": raw(fs.inv_mass, n), "inside": rng.random(n) < 0.5}
    nodes["position"][: n // 4] //= 1 << 8  # some nodes far from the position range's ends
    return nodes


def golden_events(fs, nodes, constants, momentum):
    """``(SaturationCounter, per-node totals)`` of the golden model on ``nodes``."""
    weights = np.where(nodes["inside"], nodes["inv_mass_barrier"], nodes["inv_mass"])

    def count(rows):
        counter = SaturationCounter()
        p, v, f, w = (a[rows] for a in (nodes["position"], nodes["velocity"], nodes["force"], weights))
        if momentum:
            integrate_momentum(fs, p, v, f, w, constants.dt, counter)
        else:
            integrate(fs, p, v, f, w, constants, counter)
        if momentum:  # the power F·V (S) is formed, and counted, only in the momentum dynamics
            node_power(fs, f, v, counter)
        return counter

    n = len(weights)
    return count(slice(None)), np.array([count(slice(i, i + 1)).total for i in range(n)])


def integrator_saturations(fs, nodes, constants, momentum, delay_lines=False, **kw):
    """The RTL's per-node ``saturations`` (a unit with ``saturations=True``, checked bit-exact first)."""
    dut = Integrator(fs, side=SIDE, saturations=True, delay_lines=delay_lines)
    n = len(nodes["inside"])
    run = check_integrator(dut, fs, dict(nodes, side=np.arange(n)), constants, momentum=momentum,
                           seed=12, p_valid=0.8, **kw)
    return unpack_beats(dut.o.payload.shape(), run.outputs)["saturations"]


#: Formats whose steps and power can leave their ranges (the presets' cannot: |Δt·V + ½Δt²·a| < 16,
#: |Δt·a| < 16, |F·V| < 256), with an accel too wide to saturate instead.
TIGHT = dict(position="s3.22", velocity="s5.22", accel="s8.22", power="s3.24")
#: The events each case's saturating nodes raise (paper, momentum): every name somewhere.
REACHABLE = {
    "default": ({"accel", "position", "velocity", "damping"}, {"accel", "position", "velocity"}),
    "narrow": ({"accel", "position", "velocity", "damping"}, {"accel", "position", "velocity"}),
    "tight": ({"position_step", "position", "velocity_step", "velocity", "damping"},  # no power in the paper dynamics
              {"position", "velocity", "power"}),
}


@pytest.mark.parametrize("case", REACHABLE)
@pytest.mark.parametrize("momentum", [False, True])
@pytest.mark.parametrize("delay_lines", [False, True])
def test_saturations_count_every_golden_event(case, momentum, delay_lines):
    """Each node's ``saturations`` is the number of events the golden model counts for it
    (``integrate`` or ``integrate_momentum``, and with momentum ``node_power``); over the pass they sum to
    ``SaturationCounter().total``."""
    fs = FormatSet.preset("default").replace(**TIGHT) if case == "tight" else FormatSet.preset(case)
    nodes = saturating_nodes(fs, 400, seed=20 + momentum)
    if momentum:  # β up to 1
        constants = NodeConstants(fs.dt.raw_max, 0, 0, 1 << fs.damping.frac_bits)
    else:  # the largest step, and 1 − γ above 1 so that the damping saturates too
        constants = NodeConstants(fs.dt.raw_max, fs.half_dt_sq.raw_max, 0, fs.damping.raw_max)
    counter, per_node = golden_events(fs, nodes, constants, momentum)
    assert per_node.sum() == counter.total
    got = integrator_saturations(fs, nodes, constants, momentum, delay_lines)
    bad = np.flatnonzero(got != per_node)
    assert bad.size == 0, f"{bad.size} nodes miscounted; first {int(bad[0])}: rtl {int(got[bad[0]])} golden " \
                          f"{int(per_node[bad[0]])}"
    assert int(got.sum()) == counter.total
    reachable = REACHABLE[case][momentum]
    assert reachable <= set(counter.saturations), reachable - set(counter.saturations)


@pytest.mark.parametrize("momentum", [False, True])
def test_saturations_zero_without_events(momentum):
    fs = FormatSet.preset("default")
    nodes = random_nodes(fs, 150, seed=22)
    nodes["force"] //= 4
    constants = random_constants(fs, 23)
    if momentum:
        constants = NodeConstants(int(0.5 * (1 << fs.dt.frac_bits)), 0, 0, 1 << fs.damping.frac_bits)
    counter, _ = golden_events(fs, nodes, constants, momentum)
    assert counter.total == 0
    assert not integrator_saturations(fs, nodes, constants, momentum).any()


def test_saturations_leave_the_default_build_alone():
    """``saturations=False`` (the default) has no count field and the plain stages; the count is 4 bits
    (13 events), its last flags added in a stage of their own."""
    with warnings.catch_warnings():  # built for their attributes only, never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        plain, counting = Integrator("default", side=SIDE), Integrator("default", side=SIDE, saturations=True)
        assert "saturations" not in dict(plain.o.payload.shape())
        assert counting.o.payload.saturations.shape() == unsigned(4)
        assert plain.latency == LATENCY["default"]
        assert counting.latency == LATENCY["default"] + 1
        del plain, counting
        gc.collect()


def test_the_paper_step_ignores_the_proposal_inputs():
    """``scale_shift`` and ``propose`` leave the paper's step and its event count alone."""
    fs = FormatSet.preset("default")
    nodes = saturating_nodes(fs, 200, seed=24)
    constants = NodeConstants(fs.dt.raw_max, fs.half_dt_sq.raw_max, 0, fs.damping.raw_max)
    _, per_node = golden_events(fs, nodes, constants, False)
    assert per_node.any()
    got = integrator_saturations(fs, nodes, constants, False, scale_shift=SCALE_MAX_SHIFT - 3, propose=True)
    assert np.array_equal(got, per_node)


# ---------------------------------------------------------------- the guarded mode's proposal

def check_proposals(fs, nodes, beta, shift, seed, shift_copy=False, coarse=None):
    """One pass of proposals (``momentum``, ``propose``, ``scale_shift = shift``, β in ``dt``) against
    :func:`golden_model.fixed.guard.proposal`: ``V'`` bit for bit, the power as ever, and each node's
    ``saturations`` the events ``proposal`` and the guarded step's ``node_power`` (S, formed as it
    proposes) count for it; with ``coarse`` ``(n, 2)`` [accel], an integrator built to take the coarse move
    and ``proposal``'s ``coarse``. Returns the pass's golden counter."""
    n = len(nodes["inside"])
    dut = Integrator(fs, side=SIDE, saturations=True, shift_copy=shift_copy, coarse=coarse is not None)
    vec = lambda a: {"x": a[:, 0], "y": a[:, 1]}  # noqa: E731
    beats = pack_beats(dut.i.payload.shape(), {
        "node": {"position": vec(nodes["position"]), "velocity": vec(nodes["velocity"]),
                 "inv_mass": nodes["inv_mass"], "inv_mass_barrier": nodes["inv_mass_barrier"]},
        "force": vec(nodes["force"]), "inside": nodes["inside"].astype(np.int64), "side": np.arange(n),
        **({"coarse": vec(coarse)} if coarse is not None else {})})

    def setup(ctx):
        for port, value in ((dut.dt, beta), (dut.half_dt_sq, 0), (dut.damping, 0), (dut.momentum, 1),
                            (dut.scale_shift, shift), (dut.propose, 1)):
            ctx.set(port, value)

    run = run_streams(dut, beats, setup=setup, start=1, seed=seed, p_valid=0.7)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    weights = np.where(nodes["inside"], nodes["inv_mass_barrier"], nodes["inv_mass"])
    v, f = nodes["velocity"], nodes["force"]
    counter = SaturationCounter()
    want = proposal(fs, v, f, weights, beta, shift, counter, coarse)
    node_power(fs, f, v, counter)
    per_node = np.zeros(n, dtype=np.int64)
    for i in range(n):  # each node's own events
        node_counter = SaturationCounter()
        proposal(fs, v[i:i + 1], f[i:i + 1], weights[i:i + 1], beta, shift, node_counter,
                 None if coarse is None else coarse[i:i + 1])
        node_power(fs, f[i:i + 1], v[i:i + 1], node_counter)
        per_node[i] = node_counter.total
    assert per_node.sum() == counter.total
    for name, got, expected in (("velocity.x", out["velocity"]["x"], want[:, 0]),
                                ("velocity.y", out["velocity"]["y"], want[:, 1]),
                                ("power", out["power"], node_power(fs, f, v)), ("side", out["side"], np.arange(n)),
                                ("saturations", out["saturations"], per_node)):
        bad = np.flatnonzero(got != expected)
        assert bad.size == 0, f"shift {shift}, {name}: {bad.size} mismatches; first at node {int(bad[0])}: " \
                              f"rtl {int(got[bad[0]])} golden {int(expected[bad[0]])}"
    return counter


@pytest.mark.parametrize("case", [*PRESETS, "tight"])
@pytest.mark.parametrize("shift_copy", [False, True])
def test_proposals_at_every_step_scale(case, shift_copy):
    """Every shift 0 … SCALE_MAX_SHIFT + 1 with a random β: random nodes, and nodes that saturate (in the
    presets accel and velocity; in the tight formats velocity, and the position and the power too: a
    proposal counts the power's, not the position's). ``shift_copy``: the shift from its own copy of a."""
    fs = FormatSet.preset("default").replace(**TIGHT) if case == "tight" else FormatSet.preset(case)
    rng = np.random.default_rng(30)
    seen = set()
    for shift in range(SCALE_MAX_SHIFT + 2):
        beta = int(rng.integers(0, fs.dt.raw_max + 1))
        if shift % 3 == 1:
            nodes = random_nodes(fs, 40, seed=31 + shift)
        else:
            nodes = saturating_nodes(fs, 40, seed=31 + shift)
        seen |= set(check_proposals(fs, nodes, beta, shift, seed=shift, shift_copy=shift_copy).saturations)
    assert ({"velocity"} if case == "tight" else {"accel", "velocity"}) <= seen, seen
    if case == "tight":  # the unguarded step would count more on the same nodes: propose drops it
        nodes = saturating_nodes(fs, 100, seed=60)
        counter, per_node = golden_events(fs, nodes, NodeConstants(fs.dt.raw_max, 0, 0, 0), True)
        assert {"position", "power"} <= set(counter.saturations), counter
        proposed = check_proposals(fs, nodes, fs.dt.raw_max, 0, seed=61)
        assert proposed.total < counter.total


def test_shift_copy_is_kept_apart_in_the_ecp5_form():
    """``shift_copy``: in the ECP5 form the step scale's shift reads kept flip-flops of its own (one per bit of
    a, for x and y), which Yosys cannot merge with the register feeding the multipliers; none without it."""
    fs = FormatSet.preset("narrow")
    for shift_copy in (False, True):
        top = _Wrapped(Integrator(fs, saturations=True, shift_copy=shift_copy))
        text = rtlil.convert(top, platform=ECP5, ports=[top.dut.i.valid, top.dut.o.valid])
        kept = set(re.findall(r"^\s*cell \\TRELLIS_FF \\(t4_a_shift_[xy])_ff(\d+)", text, re.M))
        want = {(f"t4_a_shift_{k}", str(i)) for k in "xy" for i in range(fs.accel.width)} if shift_copy else set()
        assert kept == want, (shift_copy, sorted(kept ^ want)[:4])



@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("shift", [0, 3])
def test_proposals_with_the_coarse_move(preset, shift):
    """``coarse``: the node's coarse move added to ``a`` before the step scale, saturating in [accel], against
    :func:`golden_model.fixed.guard.proposal` with its ``coarse``: ``V'`` bit for bit and each node's events
    (the sum's clamp counted as ``accel``), with moves over [accel]'s range and its ends."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(70 + shift)
    n = 80
    coarse = rng.integers(fs.accel.raw_min, fs.accel.raw_max + 1, size=(n, 2))
    coarse[:4] = [[fs.accel.raw_max, fs.accel.raw_min], [0, 0], [fs.accel.raw_min, 1], [-1, fs.accel.raw_max]]
    beta = int(rng.integers(0, fs.dt.raw_max + 1))
    counter = check_proposals(fs, random_nodes(fs, n, seed=71 + shift), beta, shift, seed=shift, coarse=coarse)
    assert counter["accel"] > 0  # the sum's clamp is exercised


def test_the_coarse_move_takes_one_stage_more():
    with warnings.catch_warnings():  # built for their attributes only, never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        latencies = {coarse: Integrator("default", saturations=True, coarse=coarse).latency for coarse in (False, True)}
        with pytest.raises(ValueError, match="shift_copy copies a before the coarse move"):
            Integrator("default", shift_copy=True, coarse=True)
        gc.collect()
    assert latencies == {False: LATENCY["default"] + 1, True: LATENCY["default"] + 2}
