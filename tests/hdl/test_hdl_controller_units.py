"""The controller's sequential units (hdl.controller_units) against the golden model, in Amaranth's simulator.

Every output is compared bit for bit, in order, with the golden-model function the unit
mirrors (``Reciprocal.normalise``, ``energy_raw`` with ``StopRule.converged``,
``momentum_beta_raw``), under seeded random valid/ready stalls on both sides (the stream
helpers of :mod:`support.streams`, which also check the stream rules on ``o``).
"""

import gc
import re
import random
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from amaranth.back import rtlil, verilog
from amaranth.hdl import UnusedElaboratable

from golden_model.fixed import FormatSet, SaturationCounter
from golden_model.fixed.engine import ENERGY_TOL_FRAC_BITS, StopRule
from golden_model.fixed.measures import Reciprocal, energy_raw, momentum_beta_raw
from golden_model.engine_spec.image import ITERATION_BITS
from hdl.controller_units import BetaDivider, EnergyCheck, Normaliser
from hdl.dsp import ECP5
from sim.payloads import pack, unpack_beats
from support import PRESETS
from support.streams import StreamRun, run_testbenches, stream_consumer, stream_producer



def run_items(dut, beats, cycles, *, seed=0, p_valid=1.0, p_ready=1.0, setup=None):
    """Stream ``beats`` through a one-item-at-a-time unit that takes up to ``cycles`` edges per
    item; the outputs (raw) and the transfer edges. ``o`` is checked for the stream rules and
    for ``valid``/``payload`` not depending on ``ready``."""
    run = StreamRun()
    max_cycles = int(2 * len(beats) * (cycles + 2) / (p_valid * p_ready)) + 200
    benches = []
    if setup is not None:
        async def setup_bench(ctx):
            setup(ctx)
        benches.append(setup_bench)
    run_testbenches(dut, *benches,
                    stream_producer(dut.i, beats, run, seed=seed, p_valid=p_valid),
                    stream_consumer(dut.o, len(beats), run, seed=seed + 1, p_ready=p_ready, drain=cycles + 2,
                                    max_cycles=max_cycles, probe_ready=True))
    assert len(run.outputs) == len(beats)
    return run


def first_mismatch(name, got, want, inputs):
    bad = np.flatnonzero(np.asarray(got, dtype=object) != np.asarray(want, dtype=object))
    if bad.size:
        i = int(bad[0])
        pytest.fail(f"{name}: {bad.size} mismatches; first: {inputs(i)} rtl {got[i]} golden {want[i]}")


# ---------------------------------------------------------------- Normaliser

def normalise_cases(fs, rng, n):
    """``(sums, totals)``: totals log-uniform in [2, 2**62] (and the small ones), sums mostly
    in ``[0, 1.2·total]`` (E up to 1 and past it: saturation) plus the corners of ``error_acc``."""
    top = fs.error_acc.raw_max
    totals = [2, 3, 4, 5, 7, (1 << 62) - 1, 1 << 62, top, top + 1]
    totals += [int(2 ** x) + int(rng.integers(0, 1 << 20)) for x in rng.uniform(1, 62, n)]
    sums = []
    for total in totals:
        choice = rng.random()
        if choice < 0.1:
            sums.append(int(rng.integers(0, top + 1)))
        elif choice < 0.2:
            sums.append(min(total + int(rng.integers(-2, 3)), top))  # around E = 1
        else:
            sums.append(min(int(total * rng.uniform(0, 1.2)), top))
    corners = [(0, 1), (1, 1), (top, 1), (0, 2), (top, 2), (top, top), (top - 1, top), (0, 1 << 62),
               (top, 1 << 62), (1, 3), (2, 3)]
    return [s for s, _ in corners] + sums, [t for _, t in corners] + totals


def check_normaliser(fs, sums, totals, saturations=False, **kw):
    """The unit's errors (and with ``saturations`` its saturation flags) against ``Reciprocal.normalise``
    and the events it counts; returns the unit, the run, the reciprocals, the golden errors and flags."""
    dut = Normaliser(fs, saturations=saturations)
    recips = [Reciprocal.of(t, fs.reciprocal.width) for t in totals]
    shape = dut.i.payload.shape()
    beats = [pack(shape, {"sum": s, "mantissa": r.mantissa, "shift": r.shift}) for s, r in zip(sums, recips)]
    run = run_items(dut, beats, dut.cycles(max(r.shift for r in recips)), **kw)
    counters = [SaturationCounter() for _ in sums]
    want = [r.normalise(s, fs.error, fs.rounding, c, "error") for s, r, c in zip(sums, recips, counters)]
    flags = [c.total for c in counters]
    inputs = lambda i: f"sum={sums[i]} total={totals[i]} {recips[i]}"
    if saturations:
        out = unpack_beats(dut.o.payload.shape(), run.outputs)
        first_mismatch("error", list(out["error"]), want, inputs)
        first_mismatch("saturations", list(out["saturations"]), flags, inputs)
    else:
        first_mismatch("error", run.outputs, want, inputs)
    return dut, run, recips, want, flags


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("saturations", [False, True])
def test_normaliser_random_totals_with_stalls(preset, saturations):
    fs = FormatSet.preset(preset)
    sums, totals = normalise_cases(fs, np.random.default_rng(1), 400)
    _, _, _, want, flags = check_normaliser(fs, sums, totals, saturations, seed=2, p_valid=0.7, p_ready=0.6)
    assert fs.error.raw_max in want and 0 in want  # saturated and zero results were among them
    # E ≥ 1 saturates; a result that is error's maximum without saturating (E just below 1) is not an event
    assert 0 < sum(flags) < sum(w == fs.error.raw_max for w in want)


@pytest.mark.parametrize("rounding", ["nearest_even", "floor"])
def test_normaliser_other_roundings(rounding):
    """Nearest-even reads the sticky bit (ties: only the half-lsb set)."""
    fs = FormatSet.preset("default").replace(rounding=rounding)
    rng = np.random.default_rng(3)
    sums, totals = normalise_cases(fs, rng, 150)
    # exact ties: total = 2^j, sum = total·(2k+1)·2^-(F+1) puts exactly the half-lsb in the result
    f = fs.error.frac_bits
    for j in range(f + 1, fs.error_acc.width):  # sum < 2**(j + 1) fits error_acc
        k = int(rng.integers(0, 1 << f))
        sums.append(((2 * k + 1) << j) >> (f + 1))
        totals.append(1 << j)
    check_normaliser(fs, sums, totals, seed=4, p_valid=0.8, p_ready=0.8)


@pytest.mark.parametrize("preset", PRESETS)
def test_normaliser_cycles(preset):
    """No stalls: each result leaves ``cycles(shift)`` edges after its input (documented formula),
    and the next input is taken on the edge after the result leaves."""
    fs = FormatSet.preset(preset)
    totals = [2, 1000, 1 << 30, (1 << 62) + 5]
    sums = [1, 500, 1 << 29, 1 << 33]
    dut, run, recips, _, _ = check_normaliser(fs, sums, totals)
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.cycles(r.shift) for r in recips]
    assert [dut.shift_steps(r.shift) for r in recips][-1] == dut.product_bits  # the capped shift
    assert run.in_cycles[1:] == [o + 1 for o in run.out_cycles[:-1]]
    # multiply steps + (shift − F − 2) shift steps + rounding + saturation + the output transfer
    assert dut.cycles(recips[0].shift) == fs.reciprocal.width + (recips[0].shift - fs.error.frac_bits - 2) + 3


# ---------------------------------------------------------------- EnergyCheck

def check_energy(fs, capacity, half_spring, tolerance, items, load_copy=False, **kw):
    """``items`` ``(square_sum, barrier_sum, first)`` through an ``EnergyCheck``; each output against
    ``energy_raw`` and ``StopRule.converged``'s energy part with the previous item's energy."""
    dut = EnergyCheck(fs, capacity, load_copy=load_copy)
    shape = dut.i.payload.shape()
    beats = [pack(shape, {"square_sum": q, "barrier_sum": b, "first": f}) for q, b, f in items]

    def setup(ctx):
        ctx.set(dut.half_spring, half_spring)
        ctx.set(dut.tolerance, tolerance)

    run = run_items(dut, beats, dut.latency, setup=setup, **kw)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    energies = [energy_raw(fs, half_spring, q, b) for q, b, _ in items]
    rule = StopRule(area=0, shape=0, energy=tolerance)  # errors (0, 0) pass: only the energy part decides
    settled = [0 if f else int(rule.converged(energies[i - 1], energies[i], (0, 0)))
               for i, (_, _, f) in enumerate(items)]
    describe = lambda i: f"item {i} {items[i]} (previous energy {energies[i - 1] if i else None})"  # noqa: E731
    first_mismatch("energy", [int(e) for e in out["energy"]], energies, describe)
    first_mismatch("settled", [int(s) for s in out["settled"]], settled, describe)
    return dut, run, energies, settled


def energy_items_for(w, targets):
    """``(square_sum, barrier_sum)`` with ``energy_raw == target`` at ``½C = 1``: as much as fits in
    ``2·Σc·h`` (shifted), the rest (below three of its steps) in ``3·Σe²``, whose step is coprime."""
    items = []
    step_b = 2 << w.barrier_shift
    step_q = 3 << w.springs_shift
    for target in targets:
        b = min(target // step_b, (1 << w.barrier_bits) - 1)
        while (target - b * step_b) % step_q:
            b -= 1
        assert b >= 0 and (target - b * step_b) // step_q < 1 << w.square_bits
        items.append(((target - b * step_b) // step_q, b))
    return items


CAPACITY = 1 << 22  # entries: a 1.4M-triangle mesh


def energy_widths(fs, capacity):
    """An ``EnergyCheck``'s widths and shifts, from one built for them only (never elaborated)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        dut = EnergyCheck(fs, capacity)
        widths = SimpleNamespace(**{name: getattr(dut, name) for name in (
            "square_bits", "barrier_bits", "half_spring_bits", "tolerance_bits", "energy_bits", "springs_shift",
            "barrier_shift")})
        del dut
        gc.collect()
    return widths


@pytest.mark.parametrize("load_copy", [False, True])
@pytest.mark.parametrize("preset", PRESETS)
def test_energy_random_sums_with_stalls(preset, load_copy):
    fs = FormatSet.preset(preset)
    w = energy_widths(fs, CAPACITY)
    rng = random.Random(5)
    half_spring = rng.randrange(1, 1 << w.half_spring_bits)
    tolerance = rng.randrange(1, 1 << 36)  # ε up to ~0.06
    items = [(rng.getrandbits(w.square_bits), rng.getrandbits(w.barrier_bits), 1)]
    base = items[0]
    for _ in range(60):  # random relative changes around the previous energy, some within ε
        change = rng.choice([-1, 1]) * 10 ** rng.uniform(-12, 0)
        items.append(tuple(min(v + int(v * change), (1 << bits) - 1)
                           for v, bits in zip(base[:2], (w.square_bits, w.barrier_bits))) + (0,))
        base = items[-1]
    top = ((1 << w.square_bits) - 1, (1 << w.barrier_bits) - 1, 0)
    items += [(0, 0, 0), (0, 0, 0), (5, 0, 0), (0, 0, 0), (0, 1, 0), top]
    _, _, _, settled = check_energy(fs, CAPACITY, half_spring, tolerance, items, load_copy, seed=6, p_valid=0.6,
                                    p_ready=0.5)
    assert 0 < sum(settled) < len(items) - 1


@pytest.mark.parametrize("load_copy", [False, True])
@pytest.mark.parametrize("preset", PRESETS)
def test_energy_change_exactly_at_the_tolerance(preset, load_copy):
    """``|ΔE| = (ε·E_prev) >> 40`` settles, one more does not, above and below ``E_prev``; the
    largest ``ε·E_prev``; the largest sums with the largest ``½C``."""
    fs = FormatSet.preset(preset)
    w = energy_widths(fs, CAPACITY)
    tolerance = (1 << 35) + 12345
    previous = (1 << 70) + 987654321
    allowed = (tolerance * previous) >> ENERGY_TOL_FRAC_BITS
    targets = []
    for energy in (previous + allowed, previous + allowed + 1, previous - allowed, previous - allowed - 1,
                   previous + allowed - 1):
        targets += [previous, energy]
    items = [(q, b, int(i == 0)) for i, (q, b) in enumerate(energy_items_for(w, targets))]
    _, _, _, settled = check_energy(fs, CAPACITY, 1, tolerance, items, load_copy, seed=7, p_valid=0.8, p_ready=0.8)
    assert settled[1::2] == [1, 0, 1, 0, 1]
    # the widest values: largest sums, ½C, ε
    top_q, top_b = (1 << w.square_bits) - 1, (1 << w.barrier_bits) - 1
    items = [(top_q, top_b, 1), (top_q, top_b, 0), (top_q - 1, top_b, 0), (0, 0, 0)]
    _, _, energies, _ = check_energy(fs, CAPACITY, (1 << w.half_spring_bits) - 1, (1 << w.tolerance_bits) - 1, items,
                                     load_copy)
    assert max(energies).bit_length() == w.energy_bits


@pytest.mark.parametrize("load_copy", [False, True])
@pytest.mark.parametrize("preset", PRESETS)
def test_energy_latency(preset, load_copy):
    fs = FormatSet.preset(preset)
    dut, run, _, _ = check_energy(fs, 1000, 3, 1 << 30, [(7, 9, 1), (8, 9, 0), (8, 9, 0)], load_copy)
    # three clocks besides the multiply's and ε·E_prev's steps and E, the compare and output's: Σe² loaded, the
    # product copied, ε·E_prev copied beside the compare
    assert dut.latency == dut.square_bits + dut.energy_bits + 5 + 3
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.latency] * 3


# ---------------------------------------------------------------- BetaDivider

def check_beta(fs, ks, k_bits=21, **kw):
    dut = BetaDivider(fs, k_bits=k_bits)
    run = run_items(dut, [int(k) for k in ks], dut.latency, **kw)
    want = [momentum_beta_raw(int(k), fs) for k in ks]
    first_mismatch("beta", run.outputs, want, lambda i: f"k={ks[i]}")
    return dut, run, want


@pytest.mark.slow
def test_beta_every_k_to_5000():
    """β depends on ``dt`` alone, which both presets share (u0.18): one run covers them (~10 s)."""
    fs = FormatSet.preset("default")
    assert all(FormatSet.preset(p).dt == fs.dt for p in PRESETS)
    _, _, want = check_beta(fs, np.arange(5001), seed=8, p_valid=0.9, p_ready=0.9)
    assert want[0] == 0 and want[1] == momentum_beta_raw(1, fs)


@pytest.mark.parametrize("preset", PRESETS)
def test_beta_small_and_large_k_with_stalls(preset):
    """k = 0…300, random large k up to the port's width (β rounds up to 1 and is capped), and every
    k whose quotient is exact (``k + 3`` a power of two or three times one: a remainder reaches
    exactly the divisor; with ``k + 3 = 2^(F+1)`` or ``3·2^(F+1)`` the quotient is odd, so a
    divider one low there rounds differently)."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(9)
    exact = [m * (1 << j) - 3 for j in range(22) for m in (1, 3) if 0 <= m * (1 << j) - 3 < 1 << 21]
    ks = np.r_[np.arange(301), rng.integers(301, 1 << 21, 300), (1 << 21) - 1, (1 << 20), exact]
    _, _, want = check_beta(fs, ks, seed=10, p_valid=0.6, p_ready=0.6)
    assert fs.dt.raw_max in want  # the cap was reached


@pytest.mark.parametrize("dt", ["u0.10", "u1.12", "u0.24"])
def test_beta_other_dt_formats(dt):
    """A u1.F ``dt`` never reaches the cap (β < 1); other fraction widths change the quotient's length."""
    fs = FormatSet.preset("default").replace(dt=dt, half_dt_sq="u0.10")
    rng = np.random.default_rng(11)
    check_beta(fs, np.r_[np.arange(100), rng.integers(100, 1 << 21, 100)], seed=12, p_valid=0.8, p_ready=0.8)


def test_beta_as_wide_as_the_iteration_counter():
    """The engine's divider takes ``k`` as wide as ITERATIONS (``k`` counts iterations since the
    last restart, so it never wraps): k up to 2^32 − 1, where ``k + 3`` needs a 33rd bit."""
    fs = FormatSet.preset("default")
    top = (1 << ITERATION_BITS) - 1
    ks = [(1 << 21) - 1, 1 << 21, 3 << 20, (1 << 31) - 3, top - 2, top - 1, top]
    _, _, want = check_beta(fs, ks, k_bits=ITERATION_BITS)
    assert set(want) == {fs.dt.raw_max}


def test_beta_latency():
    fs = FormatSet.preset("default")
    dut, run, _ = check_beta(fs, [0, 1, 5, 1 << 20])
    assert dut.latency == fs.dt.frac_bits + 5 == 23
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.latency] * 4


# ---------------------------------------------------------------- all units

def test_parameter_validation():
    # A component whose __init__ raises is still reported as unused when collected.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        for unit in (Normaliser, BetaDivider):
            with pytest.raises(TypeError, match=f"{unit.__name__} needs a FormatSet or a preset name, not 3"):
                unit(3)
        with pytest.raises(TypeError, match="EnergyCheck needs a FormatSet"):
            EnergyCheck(None, 10)
        with pytest.raises(ValueError, match="entries_capacity must be an int >= 1, not 0"):
            EnergyCheck("default", 0)
        with pytest.raises(TypeError, match="load_copy must be a bool, not 1"):
            EnergyCheck("default", 10, load_copy=1)
        with pytest.raises(ValueError, match="k_bits must be an int >= 1, not 0"):
            BetaDivider("default", k_bits=0)
        gc.collect()


@pytest.mark.parametrize("unit", ["normaliser", "energy_check", "beta_divider"])
def test_converts_to_verilog(unit, monkeypatch):
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    dut = {"normaliser": lambda: Normaliser("default"), "energy_check": lambda: EnergyCheck("default", CAPACITY),
           "beta_divider": lambda: BetaDivider("default")}[unit]()
    text = verilog.convert(dut, name=unit)
    assert f"module {unit}" in text
    for port in ("i__valid", "i__ready", "o__valid", "o__ready"):
        assert f" {port};" in text


def test_the_load_copy_is_kept_apart_in_the_ecp5_form():
    """``load_copy``: in the ECP5 form ε·E_prev's load reads a kept flip-flop of its own, cleared by the reset
    (its LSR is the domain's reset), which Yosys cannot merge with the energy phase's flag; none without it."""
    for load_copy in (False, True):
        dut = EnergyCheck("narrow", 18432, load_copy=load_copy)
        text = rtlil.convert(dut, platform=ECP5, ports=[dut.i.valid, dut.o.valid])
        kept = re.findall(r"^\s*cell \\TRELLIS_FF \\load_allowed_ff(\d+)\n((?:\s+(?:parameter|connect|attribute) .*\n)+)",
                          text, re.M)
        assert [k for k, _ in kept] == (["0"] if load_copy else [])
        if load_copy:
            assert re.search(r"connect \\LSR \\rst", kept[0][1]) and "LSR_OVER_CE" in kept[0][1], kept[0][1]


@pytest.mark.parametrize("entries", [6, 8192, 12288, 18432])
def test_the_energy_checks_adder_holds_every_energy_the_energy_registers_hold(entries):
    """The check's width is its input registers' bound (energy_check_width), the ENERGY registers' the bound of
    any layout (energy_width): never narrower, so the registers' low bits are the energy itself."""
    from golden_model.engine_spec.image import energy_width

    for name in ("default", "narrow", "wide"):
        fs = FormatSet.preset(name)
        assert energy_widths(fs, entries).energy_bits >= energy_width(fs, entries), (name, entries)
