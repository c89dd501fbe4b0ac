"""RTL coarse-space node unit (hdl.CoarseNode) against the golden model's integer_basis, narrow_forces, coarse_sums
and node_moves, in Amaranth's simulator: every node's move and event count and the pass's sums, bit for bit."""

import numpy as np
import pytest
from amaranth.hdl import Value

from golden_model.coarse import basis_exponents
from golden_model.fixed import FormatSet
from golden_model.fixed.coarse import (BASIS_FRAC_BITS, MOVE_BITS, OPERAND_BITS, coarse_sums, integer_basis,
                                       move_shift, narrow_forces, node_moves)
from golden_model.fixed.format import SaturationCounter
from hdl.coarse_node import CoarseNode
from sim.payloads import pack_beats, unpack_beats
from support import PRESETS
from support.streams import run_streams, run_testbenches, top_level_verilog


def random_nodes(fs, n, rng):
    """``(uv, force)``: coordinates over [-1, 1] with both ends, forces over force_acc's range with its ends."""
    one = 1 << BASIS_FRAC_BITS
    uv = rng.integers(-one, one + 1, size=(n, 2))
    uv[:4] = [[one, one], [-one, -one], [one, -one], [0, 0]]
    f = fs.force_acc
    force = rng.integers(f.raw_min, f.raw_max + 1, size=(n, 2))
    force[:3] = [[f.raw_max, f.raw_min], [f.raw_max - 1, 1], [-1, f.raw_min + 1]]
    return uv, force


def run_node(fs, degree, uv, force, *, moves, coefficients=None, shift=0, seed=0, p_valid=1.0, basis_input=False):
    """The nodes through the RTL (with ``basis_input``, their basis from the golden model's ``integer_basis``):
    ``(outputs, sums, run, dut)``."""
    m = len(basis_exponents(degree))
    dut = CoarseNode(fs, degree, max_nodes=len(uv), basis_input=basis_input)
    basis = ({"phi": {k: column for k, column in enumerate(integer_basis(uv, degree)[:, 1:].T)}} if basis_input
             else {"uv": {"x": uv[:, 0], "y": uv[:, 1]}})
    beats = pack_beats(dut.i.payload.shape(), {**basis, "force": {"x": force[:, 0], "y": force[:, 1]}})
    c = np.zeros((m, 2), dtype=np.int64) if coefficients is None else coefficients

    def setup(ctx):
        ctx.set(dut.moves, int(moves))
        ctx.set(dut.move_shift, int(shift))
        for k in range(m):
            ctx.set(dut.coefficients[k].x, int(c[k, 0]))
            ctx.set(dut.coefficients[k].y, int(c[k, 1]))

    run = run_streams(dut, beats, setup=setup, start=1, seed=seed, p_valid=p_valid,
                      watch={"sums": Value.cast(dut.sums), "idle": dut.idle})
    assert run.watched["idle"][-1]
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    raw = unpack_beats(dut.sums.shape(), [run.watched["sums"][-1]])
    totals = np.array([[raw[k]["x"][0], raw[k]["y"][0]] for k in range(m)])
    return out, totals, run, dut


def check(name, got, expected):
    bad = np.flatnonzero(np.asarray(got) != np.asarray(expected))
    assert bad.size == 0, f"{name}: {bad.size} mismatches; first at {int(bad[0])}: rtl {np.ravel(got)[bad[0]]} " \
                          f"golden {np.ravel(expected)[bad[0]]}"


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("degree", [1, 3, 4])
def test_a_sums_pass_forms_the_exact_sums_of_the_narrowed_forces(preset, degree):
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(degree)
    uv, force = random_nodes(fs, 120, rng)
    out, totals, _, _ = run_node(fs, degree, uv, force, moves=False, p_valid=0.7, seed=degree)
    counter = SaturationCounter()
    phi = integer_basis(uv, degree)
    narrow = narrow_forces(fs, force, counter)
    check("sums", totals, coarse_sums(phi, narrow))
    check("moves", np.column_stack([out["move"]["x"], out["move"]["y"]]), np.zeros_like(force))
    check("saturations", out["saturations"], events_per_node(lambda k, counter: narrow_forces(fs, force[k:k + 1], counter),
                                                           len(force)))
    # the narrowing's clamp is exercised where it narrows (a force at force_acc's top rounds past it)
    assert (counter.total > 0) == (fs.force_acc.width > OPERAND_BITS)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("degree", [1, 3, 4])
@pytest.mark.parametrize("shift", [-30, -3, 0, 1, 17, 30, MOVE_BITS + 1])
@pytest.mark.parametrize("limit", [1 << (OPERAND_BITS - 2), 4])  # the mantissas' range; small: moves near the clamp
def test_a_moves_pass_forms_each_nodes_move(preset, degree, shift, limit):
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(100 + degree + shift + limit)
    uv, force = random_nodes(fs, 60, rng)
    m = len(basis_exponents(degree))
    c = rng.integers(-limit, limit + 1, size=(m, 2))
    c[0] = [limit, -limit]
    shift = max(shift, -fs.accel.width)
    out, totals, _, _ = run_node(fs, degree, uv, force, moves=True, coefficients=c, shift=shift, seed=shift % 7)
    assert not totals.any()  # a moves pass leaves the sums alone
    phi = integer_basis(uv, degree)
    frac = fs.accel.frac_bits + shift
    assert move_shift(fs, frac) == shift
    counter = SaturationCounter()
    expected = node_moves(fs, phi, c, frac, counter)
    check("move.x", out["move"]["x"], expected[:, 0])
    check("move.y", out["move"]["y"], expected[:, 1])
    events = events_per_node(lambda k, counter: node_moves(fs, phi[k:k + 1], c, frac, counter), len(uv))
    check("saturations", out["saturations"], events)
    if shift <= -3 and limit > 4:
        assert counter.total > 0  # the clamp is exercised


def events_per_node(golden, n):
    """Each node's saturation events as the golden model's counter counts them: ``golden(k, counter)`` for node k."""
    counter, events = SaturationCounter(), []
    for k in range(n):
        before = counter.total
        golden(k, counter)
        events.append(counter.total - before)
    return events


#: Independent pins of the stages CoarseNode builds: the inputs and the narrowed forces (1), each basis level's
#: multiply and rounding (3 + 1), the landed operands (1), the products (3), the adder levels (⌈log2 m⌉), the
#: shift, the rounding and the clamp (3).
LATENCY = {1: 1 + 0 + 1 + 3 + 2 + 3, 3: 1 + 8 + 1 + 3 + 4 + 3, 4: 1 + 12 + 1 + 3 + 4 + 3}


@pytest.mark.parametrize("degree", sorted(LATENCY))
def test_one_node_per_clock_and_the_latency(degree):
    fs = FormatSet.preset("default")
    uv, force = random_nodes(fs, 40, np.random.default_rng(7))
    _, _, run, dut = run_node(fs, degree, uv, force, moves=True)
    assert dut.latency == LATENCY[degree]
    assert run.in_cycles == list(range(40))
    assert run.out_cycles == [c + LATENCY[degree] for c in range(40)]


def test_converts_to_verilog(monkeypatch):
    """Top level: the streams' constant ``ready`` is left out of the ports (amaranth-lang/amaranth#1574)."""
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    fs = FormatSet.preset("default")
    text = top_level_verilog(CoarseNode(fs, 3, 2048), "coarse_node")
    assert "module coarse_node" in text
    assert f"output [{2 * fs.accel.width + 2 - 1}:0] o__payload;" in text


def test_clear_and_passes_of_both_kinds_on_one_unit():
    """A sums pass, a moves pass (which leaves the sums alone, its moves those of the coefficients), then
    ``clear`` and a second sums pass: the sums are the second pass's alone."""
    fs = FormatSet.preset("default")
    rng = np.random.default_rng(11)
    degree, m = 3, len(basis_exponents(3))
    passes = [random_nodes(fs, 30, rng) for _ in range(3)]
    c = rng.integers(-(1 << 16), (1 << 16) + 1, size=(m, 2))
    shift = 20
    dut = CoarseNode(fs, degree, 64)
    shape = dut.i.payload.shape()
    seen = {"sums": [], "moves": []}

    async def bench(ctx):
        async def stream(uv, force):
            moves = []
            for k in range(len(uv)):
                ctx.set(Value.cast(dut.i.payload), pack_beats(shape, {"uv": {"x": uv[k:k + 1, 0], "y": uv[k:k + 1, 1]},
                                                                      "force": {"x": force[k:k + 1, 0],
                                                                                "y": force[k:k + 1, 1]}})[0])
                ctx.set(dut.i.valid, 1)
                _, _, valid, out = await ctx.tick().sample(dut.o.valid, Value.cast(dut.o.payload))
                if valid:
                    moves.append(out)
            ctx.set(dut.i.valid, 0)
            while not ctx.get(dut.idle):
                _, _, valid, out = await ctx.tick().sample(dut.o.valid, Value.cast(dut.o.payload))
                if valid:
                    moves.append(out)
            await ctx.tick()  # a node's share lands in the sums a clock after its output
            return moves

        await stream(*passes[0])
        seen["sums"].append(ctx.get(Value.cast(dut.sums)))
        ctx.set(dut.moves, 1)
        ctx.set(dut.move_shift, shift)
        for k in range(m):
            ctx.set(dut.coefficients[k].x, int(c[k, 0]))
            ctx.set(dut.coefficients[k].y, int(c[k, 1]))
        await ctx.tick()
        seen["moves"] = await stream(*passes[1])
        seen["sums"].append(ctx.get(Value.cast(dut.sums)))
        ctx.set(dut.moves, 0)
        ctx.set(dut.clear, 1)
        await ctx.tick()
        ctx.set(dut.clear, 0)
        await ctx.tick()
        await stream(*passes[2])
        seen["sums"].append(ctx.get(Value.cast(dut.sums)))

    run_testbenches(dut, bench)
    sums = [unpack_beats(dut.sums.shape(), [raw]) for raw in seen["sums"]]
    totals = [np.array([[s[k]["x"][0], s[k]["y"][0]] for k in range(m)]) for s in sums]
    golden = [coarse_sums(integer_basis(uv, degree), narrow_forces(fs, force)) for uv, force in passes]
    check("sums after the first pass", totals[0], golden[0])
    check("sums after the moves pass", totals[1], golden[0])
    check("sums after clear and the third pass", totals[2], golden[2])
    out = unpack_beats(dut.o.payload.shape(), seen["moves"])
    uv = passes[1][0]
    expected = node_moves(fs, integer_basis(uv, degree), c, fs.accel.frac_bits + shift)
    check("moves", np.column_stack([out["move"]["x"], out["move"]["y"]]), expected)


@pytest.mark.parametrize("degree", [1, 3, 4])
@pytest.mark.parametrize("shift", [-3, 17])
def test_the_basis_as_input_gives_the_same_sums_and_moves_with_fewer_stages(degree, shift):
    """``basis_input``: the node's basis values from its word (the engine's basis memory) instead of formed from
    ``u, v``, the same sums and moves bit for bit, the basis's stages left out (degree 1 has none)."""
    fs = FormatSet.preset("default")
    rng = np.random.default_rng(200 + degree)
    uv, force = random_nodes(fs, 60, rng)
    phi = integer_basis(uv, degree)
    _, totals, _, dut = run_node(fs, degree, uv, force, moves=False, p_valid=0.7, seed=degree, basis_input=True)
    check("sums", totals, coarse_sums(phi, narrow_forces(fs, force)))
    m = len(basis_exponents(degree))
    c = rng.integers(-(1 << 16), (1 << 16) + 1, size=(m, 2))
    out, _, run, _ = run_node(fs, degree, uv, force, moves=True, coefficients=c, shift=shift, basis_input=True)
    frac = fs.accel.frac_bits + shift
    check("moves", np.column_stack([out["move"]["x"], out["move"]["y"]]), node_moves(fs, phi, c, frac))
    basis_stages = {1: 0, 3: 8, 4: 12}[degree]
    assert dut.latency == LATENCY[degree] - basis_stages
    assert run.out_cycles == [k + dut.latency for k in range(60)]
