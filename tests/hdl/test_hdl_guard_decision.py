"""RTL guard decision (hdl.GuardDecision) against the golden model's StepScale, EnergyWindow and
StopRule, in Amaranth's simulator: every decision of long random runs, bit for bit, with gaps and
back-pressure."""

import gc
import random
import warnings

import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.coarse import JACOBI_STEPS_AFTER_REJECTION, CoarseSchedule
from golden_model.engine_spec.image import DEFAULT_CAPACITY
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import ENERGY_TOL_FRAC_BITS, StopRule
from golden_model.guard import ENERGY_WINDOW, SCALE_GROW_AFTER, SCALE_MAX_SHIFT, EnergyWindow, StepScale
from golden_model.params import FlattenParams
from hdl.controller_units import EnergyCheck
from hdl.guard_decision import SPLIT_RISE_PARTS, GuardDecision
from sim.payloads import pack, unpack
from support import refused_components
from support.streams import run_streams

with refused_components():  # built for its width only (else reported unused in whichever test frees it)
    ENERGY_BITS = EnergyCheck(FormatSet.preset("default"), DEFAULT_CAPACITY.entries).energy_bits
TOLERANCE = StopRule.of(FlattenParams(tol_energy=1e-3), FormatSet.preset("default")).energy  # ε = 1e-3 raw


def golden(items, tolerance, floor, size=ENERGY_WINDOW, coarse=None):
    """``[(accepted, energy, settled, stalled, shift)]`` as ``Controller._advance_guarded`` and ``run`` decide;
    with ``coarse`` (the run has a coarse space, or not), each with ``CoarseSchedule.coarse`` after it (an item's
    optional fourth value: the step was clipped deep, ``clipped_deep``)."""
    rule = StopRule(area=0, shape=0, energy=tolerance, floor=floor)
    out, scale, window, kept = [], StepScale(), EnergyWindow(size), None
    schedule = CoarseSchedule(active=bool(coarse))
    for energy, first, with_momentum, *clipped in items:
        if first:
            scale, window, kept = StepScale(), EnergyWindow(size), energy
            schedule = CoarseSchedule(active=bool(coarse))
            window.push(energy)
            out.append((1, kept, 0, 0, 0) + ((int(schedule.coarse),) if coarse is not None else ()))
            continue
        accepted = energy <= kept
        if accepted:
            kept, scale, schedule = energy, scale.accepted_step(), schedule.accepted(bool(clipped and clipped[0]))
        else:
            schedule, scale = schedule.rejected(scale, with_momentum=bool(with_momentum))
        window.push(kept, accepted)
        settled = window.ready and rule.converged(window.oldest, kept, (0, 0))
        out.append((int(accepted), kept, int(settled), int(scale.stalled), scale.shift)
                   + ((int(schedule.coarse),) if coarse is not None else ()))
    return out


def runs(seed: int, n_runs: int = 12, length: int = 90):
    """Random runs, each starting with ``first``: energies falling by 10^-6 … 10^-1 a step, with rises
    (rejected steps, some in long streaks that stall the scale), repeats, zeros and values near the
    floor and at the top of the width; ``with_momentum`` at random."""
    rng = random.Random(seed)
    items = []
    for r in range(n_runs):
        energy = rng.choice([rng.getrandbits(ENERGY_BITS), rng.getrandbits(40), rng.getrandbits(12), 0])
        items.append((energy, 1, 0))
        streak = 0
        for _ in range(length):
            if streak == 0 and rng.random() < 0.04:
                streak = rng.choice([2, 5, SCALE_MAX_SHIFT + 3])  # a run of rejections
            kind = rng.random()
            if streak:
                streak -= 1
                step = energy + rng.randint(1, max(1, energy // 100))  # a rise
            elif kind < 0.05:
                step = energy  # the same energy: accepted
            elif kind < 0.08:
                step = 0
            else:
                step = energy - int(energy * 10.0 ** rng.uniform(-6, -1))
            energy_in = min(max(step, 0), (1 << ENERGY_BITS) - 1)
            items.append((energy_in, 0, int(rng.random() < (0.3 if streak else 0.6))))
            if energy_in <= energy:
                energy = energy_in
    return until_stalled(items)


def until_stalled(items, coarse=None):
    """``items`` with each run cut after its first ``stalled`` decision: there a run ends."""
    kept, stopped = [], False
    for item, decision in zip(items, golden(items, TOLERANCE, 0, coarse=coarse)):
        stopped = False if item[1] else stopped
        if not stopped:
            kept.append(item)
        stopped = stopped or bool(decision[3])
    return kept


def run_decision(items, tolerance, floor, *, seed=0, p_valid=1.0, p_ready=1.0, rise_parts=1, coarse=None):
    """The items through the RTL: ``(dut, run, decisions)``; with ``coarse`` (``coarse_active``'s value) a build
    with the schedule, each decision with ``coarse_step`` as it reads at the decision's output."""
    dut = GuardDecision(ENERGY_BITS, rise_parts=rise_parts, coarse=coarse is not None)
    layout = dut.i.payload.shape()
    beats = [pack(layout, {"energy": e, "first": f, "with_momentum": w,
                           **({"clipped": c[0] if c else 0} if coarse is not None else {})}) for e, f, w, *c in items]

    def setup(ctx):
        ctx.set(dut.tolerance, tolerance)
        ctx.set(dut.floor, floor)
        if coarse is not None:
            ctx.set(dut.coarse_active, int(coarse))

    watch = {"coarse_step": dut.coarse_step} if coarse is not None else None
    run = run_streams(dut, beats, seed=seed, p_valid=p_valid, p_ready=p_ready, setup=setup, one_at_a_time=True,
                      watch=watch)
    shape = dut.o.payload.shape()
    got = [unpack(shape, raw) for raw in run.outputs]
    steps = [(run.watched["coarse_step"][cycle],) if coarse is not None else () for cycle in run.out_cycles]
    return dut, run, [(d["accepted"], d["energy"], d["settled"], d["stalled"], d["shift"]) + step
                      for d, step in zip(got, steps)]


@pytest.mark.parametrize("seed, rise_parts", [(1, 1), (2, 1), (3, SPLIT_RISE_PARTS)])
def test_decisions_are_the_golden_models_with_gaps_and_back_pressure(seed, rise_parts):
    items = runs(seed)
    floor = 1 << 30
    want = golden(items, TOLERANCE, floor)
    # the runs reach what the decision must get right
    assert {w[0] for w in want} == {0, 1} and {w[2] for w in want} == {0, 1} and {w[3] for w in want} == {0, 1}
    assert max(w[4] for w in want) > SCALE_MAX_SHIFT and any(0 < w[4] < 3 for w in want)
    _, _, got = run_decision(items, TOLERANCE, floor, seed=seed, p_valid=0.6, p_ready=0.5, rise_parts=rise_parts)
    mismatch = [k for k, (g, w) in enumerate(zip(got, want)) if g != w]
    assert not mismatch, f"{len(mismatch)} of {len(want)} differ, first at {mismatch[0]}: RTL {got[mismatch[0]]}, " \
                         f"golden {want[mismatch[0]]}"


def test_the_scale_grows_back_after_accepted_steps():
    """A plain gradient step rolled back halves the scale; SCALE_GROW_AFTER accepted steps double it again."""
    items = [(1000, 1, 0), (1001, 0, 0), (1002, 0, 0)] + [(900 - k, 0, 1) for k in range(SCALE_GROW_AFTER)]
    _, _, got = run_decision(items, TOLERANCE, 0)
    shifts = [g[4] for g in got]
    assert shifts[:3] == [0, 1, 2] and shifts[3 + SCALE_GROW_AFTER - 2] == 2 and shifts[-1] == 1
    assert got == golden(items, TOLERANCE, 0)


@pytest.mark.parametrize("rise_parts, latency", [(1, ENERGY_BITS + 5), (SPLIT_RISE_PARTS, ENERGY_BITS + 6)])
def test_latency(rise_parts, latency):
    dut, run, _ = run_decision([(5, 1, 0), (4, 0, 0), (9, 0, 1)], TOLERANCE, 0, rise_parts=rise_parts)
    assert dut.latency == latency
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [latency] * 3


@pytest.mark.parametrize("rise_parts", [1, 3, SPLIT_RISE_PARTS])
def test_the_rise_at_every_bit(rise_parts):
    """The rise ``E > E_kept`` where the energies differ first at each bit (the parts' edges among them):
    E's bit set (a rise, with every lower bit of E clear and of E_kept set, so the lower parts say the
    opposite) or clear (no rise), and E equal to E_kept. Each pair is a run of its own."""
    rng = random.Random(rise_parts)
    items = []
    for bit in range(ENERGY_BITS):
        top = rng.getrandbits(ENERGY_BITS) >> (bit + 1) << (bit + 1)
        below = (1 << bit) - 1
        low, high = top | below, top | (1 << bit)  # high > low: differ first at `bit`
        items += [(low, 1, 0), (high, 0, 0), (high, 1, 0), (low, 0, 0)]
    items += [(top, 1, 0), (top, 0, 0)]
    want = golden(items, TOLERANCE, 0)
    assert [w[0] for w in want[1::2]] == [0, 1] * ENERGY_BITS + [1]
    _, _, got = run_decision(items, TOLERANCE, 0, rise_parts=rise_parts)
    assert got == want


def test_parameter_validation():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(ValueError, match="energy_bits must be an int >= 2, not 1"):
            GuardDecision(1)
        with pytest.raises(ValueError, match="window must be an int >= 1, not 0"):
            GuardDecision(ENERGY_BITS, window=0)
        with pytest.raises(ValueError, match="rise_parts must be an int >= 1, not 0"):
            GuardDecision(ENERGY_BITS, rise_parts=0)
        with pytest.raises(ValueError, match=rf"rise_parts \({ENERGY_BITS + 1}\) must not exceed energy_bits"):
            GuardDecision(ENERGY_BITS, rise_parts=ENERGY_BITS + 1)
        gc.collect()


def test_the_energy_test_is_against_the_energy_a_window_back():
    """Energies falling by 0.15·ε a step (1.5·ε over the window: not settled) around a halving: the test
    the iteration the halving leaves the window must use ε times the energy a window back, not two back."""
    rate = 0.15 * TOLERANCE / 2**ENERGY_TOL_FRAC_BITS
    energies, energy = [], 1 << 60
    for k in range(40):
        energy = energy // 2 if k == 15 else energy - int(energy * rate)
        energies.append(energy)
    items = [(1 << 61, 1, 0)] + [(e, 0, 1) for e in energies]
    want = golden(items, TOLERANCE, 0)
    assert not any(w[2] for w in want) and all(w[0] for w in want)
    _, _, got = run_decision(items, TOLERANCE, 0)
    assert got == want


@pytest.mark.parametrize("over, floor_offset, settled", [(0, 0, 1), (1, 0, 0), (1, 1, 1)])
def test_the_energy_test_at_its_edges(over, floor_offset, settled):
    """The change over the window exactly ⌊ε·E_old⌋ (settled) or one more (not), and the energy exactly
    at the floor (not below it) or one under it (settled by the floor)."""
    old = (1 << 70) + 12345
    change = ((TOLERANCE * old) >> ENERGY_TOL_FRAC_BITS) + over
    kept = old - change
    items = [(old, 1, 0)] + [(old, 0, 0)] * (ENERGY_WINDOW - 1) + [(kept, 0, 0)]
    floor = kept + floor_offset
    want = golden(items, TOLERANCE, floor)
    assert want[-1][2] == settled and not any(w[2] for w in want[:-1])
    _, _, got = run_decision(items, TOLERANCE, floor)
    assert got == want


@pytest.mark.parametrize("high, low, settled", [(-1, 1, 0), (0, 1, 1), (1, -1, 1), (0, 0, 0)])
def test_the_floor_compare_across_the_energys_halves(high, low, settled):
    """The floor against the kept energy where their halves disagree (the compare is split at half the
    width): the floor's high half ``high`` above the energy's, its low half ``low`` above; the change
    over the window too large, so the floor alone settles the run."""
    half = ENERGY_BITS // 2
    old = (1 << 70) + 12345
    kept = old - (((TOLERANCE * old) >> ENERGY_TOL_FRAC_BITS) + 1)
    kept_high, kept_low = kept >> half, kept & ((1 << half) - 1)
    assert 0 < kept_low < (1 << half) - 1
    floor = ((kept_high + high) << half) | (kept_low + low)
    items = [(old, 1, 0)] + [(old, 0, 0)] * (ENERGY_WINDOW - 1) + [(kept, 0, 0)]
    want = golden(items, TOLERANCE, floor)
    assert want[-1][2] == settled
    _, _, got = run_decision(items, TOLERANCE, floor)
    assert got == want


def test_a_stalled_scale_stays_one_past_the_last_halving():
    items = [(10, 1, 0)] + [(11, 0, 0)] * (SCALE_MAX_SHIFT + 4)
    _, _, got = run_decision(items, TOLERANCE, 0)
    assert [g[4] for g in got][-3:] == [SCALE_MAX_SHIFT + 1] * 3 and all(g[3] for g in got[-3:])


@pytest.mark.parametrize("seed, coarse", [(4, True), (5, True), (6, False)])
def test_the_coarse_schedule_is_the_golden_models(seed, coarse):
    """With the schedule built: each decision and ``coarse_step`` after it as ``CoarseSchedule`` has them, with
    gaps and back-pressure; the runs roll back plain gradient steps that took the coarse move (the hand-over,
    which keeps the scale) and count the Jacobi steps down to the coarse move again."""
    rng = random.Random(seed + 100)
    # a step clipped deep now and then: an accepted coarse one hands over as a rolled-back gradient step does
    items = until_stalled([(*item, int(rng.random() < 0.03)) for item in runs(seed)], coarse=coarse)
    floor = 1 << 30
    want = golden(items, TOLERANCE, floor, coarse=coarse)
    _, _, got = run_decision(items, TOLERANCE, floor, seed=seed, p_valid=0.6, p_ready=0.5, coarse=coarse)
    mismatch = [k for k, (g, w) in enumerate(zip(got, want)) if g != w]
    assert not mismatch, f"{len(mismatch)} of {len(want)} differ, first at {mismatch[0]}: RTL {got[mismatch[0]]}, " \
                         f"golden {want[mismatch[0]]}"
    flags = [w[5] for w in want]
    assert set(flags) == ({0, 1} if coarse else {0})
    if coarse:  # a hand-over, then JACOBI_STEPS_AFTER_REJECTION accepted steps without the coarse move
        handovers = [k for k in range(1, len(items)) if flags[k - 1] and not flags[k] and not items[k][1]]
        assert handovers and any(want[k][4] == want[k - 1][4] and not items[k][2] for k in handovers)
        assert any(want[k][0] and items[k][3] for k in handovers)  # an accepted step clipped deep
        assert any(flags[k:k + JACOBI_STEPS_AFTER_REJECTION + 1] == [0] * JACOBI_STEPS_AFTER_REJECTION + [1]
                   for k in range(len(flags)))
