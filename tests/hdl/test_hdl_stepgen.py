"""RTL step generator (hdl.StepGenerator) against the golden model, in Amaranth's simulator.

Every output (``dt``, ``half_dt_sq``) is compared, in order, with ``step_size`` under seeded
random valid/ready stalls on both sides (the stream helpers of :mod:`support.streams`).

Why two one-lane sweeps plus a dt sweep verify *every* input pair (separability)
----------------------------------------------------------------------------------
By construction of the RTL the two lookup lanes (``area_error`` -> ``v_S``, ``shape_error``
-> ``v_C``) are independent and meet only in the register ``v_sum = v_S + v_C``; both outputs
are a function ``H`` of ``v_sum`` alone: ``dt = sat(sat(requant(v_sum)) + C)`` and
``half_dt_sq`` a function of ``dt``. So the RTL computes ``H(L_S(a) + L_C(b))`` and the golden
model ``H'(v(a) + v(b))``. When ``lut_entry`` and ``dt`` have the same lsb and ``C + 2 max T``
fits ``dt`` (:func:`separable`; both presets, asserted by ``test_presets_are_separable`` and by the
sweep itself), ``dt = C + v_sum`` exactly, so ``dt`` is injective in ``v_sum``. Then

1. sweep 1, all ``a`` with ``b = b0``: equal ``dt`` gives ``L_S(a) + L_C(b0) = v(a) + v(b0)``;
2. sweep 2, all ``b`` with ``a = a0``: ``L_S(a0) + L_C(b) = v(a0) + v(b)``;
3. adding them and subtracting the pair ``(a0, b0)`` of sweep 1:
   ``L_S(a) + L_C(b) = v(a) + v(b)`` for every pair, i.e. ``v_sum`` is right everywhere;
4. sweep 3 feeds one pair for every *reachable* sum ``s`` in ``{v(a) + v(b)}``, so
   ``H(s) = H'(s)`` (``dt`` and ``half_dt_sq``) for every ``s`` any pair can produce.

Hence RTL == golden model for all ``2**(2F)`` pairs (4.3e9 for u0.16) from
``2 * 2**F + |reachable sums|`` transfers (~183k for u0.16). Presets with the same step-path
parameters share one run.

The Python simulator manages ~12k transfers/s, so whole-domain lane sweeps are run up to
``LANE_SWEEP_LIMIT`` error values (u0.16). A wider error format (the default preset's u0.20:
2 x 1M transfers, ~2.5 min) gets a dense lane sweep instead: every ROM address with the
interpolation weights 0, 1, half-1, half, half+1 and max, a stride sweep and random values;
sweep 3 (every reachable sum) stays exhaustive. Steps 1-3 are then a sample, not a proof.
Random pairs with heavier stalls check the flow control on top.
"""

import gc
import warnings

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import UnusedElaboratable, unsigned

from golden_model.fixed import FormatSet, SaturationCounter, dt_constant, exp_lut, exp_table, step_size
from hdl import StepGenerator
from sim.payloads import pack_beats, unpack_beats
from support.streams import run_streams, run_testbenches, stream_get, stream_put
from test_hdl_rsqrt import PRESETS


def separable(fs):
    """The precondition of steps 1-3 of the module docstring: ``dt = C + v_S + v_C`` exactly, that is
    ``lut_entry`` and ``dt`` have the same lsb (no rounding) and ``C + 2 max T`` fits ``dt`` (no saturation)."""
    table = exp_table(fs.lut_index_bits, fs.lut_entry)
    return (fs.lut_entry.frac_bits == fs.dt.frac_bits
            and dt_constant(fs.dt) + 2 * int(table.max()) <= fs.dt.raw_max)


@pytest.mark.parametrize("preset", PRESETS)
def test_presets_are_separable(preset):
    """The whole-domain argument holds for every preset (the slow sweep asserts it again)."""
    assert separable(FormatSet.preset(preset))


def test_separable_refuses_a_rounded_sum():
    # entries finer than dt: v_S + v_C is rounded into dt, so dt no longer tells v_sum apart
    assert not separable(FormatSet.preset("default").replace(lut_entry="u0.21"))


def step_key(fs):
    """The FormatSet fields the step generator depends on."""
    return (fs.error, fs.lut_entry, fs.dt, fs.half_dt_sq, fs.lut_index_bits,
            fs.lut_interpolate, fs.rounding)


def distinct_step_presets():
    """One entry per distinct step-path configuration among the presets: (ids, preset name)."""
    groups = {}
    for name in PRESETS:
        groups.setdefault(step_key(FormatSet.preset(name)), []).append(name)
    return [pytest.param(names[0], id="+".join(names)) for names in groups.values()]


def check_step(dut, area, shape, **kw):
    """Run the pairs through ``dut`` and compare both outputs with ``step_size``; return run."""
    fs = dut.fs
    area = np.asarray(area, dtype=np.int64)
    shape = np.asarray(shape, dtype=np.int64)
    run = run_streams(dut, pack_beats(dut.i.payload.shape(), {"area_error": area, "shape_error": shape}), **kw)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    want_dt, want_half = step_size(area, shape, fs)
    for name, got, want in (("dt", out["dt"], want_dt), ("half_dt_sq", out["half_dt_sq"], want_half)):
        bad = np.flatnonzero(got != want)
        if bad.size:
            i = bad[0]
            pytest.fail(f"{name}: {bad.size} mismatches; first: area_error={int(area[i])} "
                        f"shape_error={int(shape[i])} rtl={int(got[i])} golden={int(want[i])}")
    return run


def lookup_values(fs):
    """``v(E)`` of the golden model for every raw error ``E``."""
    e = np.arange(fs.error.raw_max + 1, dtype=np.int64)
    table = exp_table(fs.lut_index_bits, fs.lut_entry)
    return e, exp_lut(e, fs.error, table, fs.lut_index_bits, fs.lut_interpolate, fs.rounding)


def pairs_for_every_sum(fs):
    """One ``(a, b)`` per reachable ``v(a) + v(b)`` (the sumset is found with an FFT)."""
    e, v = lookup_values(fs)
    vals = np.unique(v)
    first = np.full(int(vals[-1]) + 1, -1, dtype=np.int64)
    first[v[::-1]] = e[::-1]  # smallest E giving each value
    ind = np.zeros(int(vals[-1]) + 1)
    ind[vals] = 1
    size = 1 << int(2 * len(ind)).bit_length()
    sumset = np.fft.irfft(np.fft.rfft(ind, size) ** 2, size)[:2 * len(ind) - 1] > 0.5
    need = sumset.copy()
    area, shape = [], []
    for u in vals[::-1]:  # large u first: the sparse top sums need both terms large
        sums = u + vals
        new = sums[need[sums]]
        if new.size:
            need[new] = False
            area.append(np.full(new.size, first[u]))
            shape.append(first[new - u])
            if not need.any():
                break
    assert not need.any()
    area, shape = np.concatenate(area), np.concatenate(shape)
    assert np.array_equal(np.sort(v[area] + v[shape]), np.flatnonzero(sumset))
    return area, shape


LANE_SWEEP_LIMIT = 1 << 16  # whole-domain lane sweeps up to this many error values (~5 s each)


def lane_inputs(fs):
    """``(values, exhaustive)``: every raw error if there are at most ``LANE_SWEEP_LIMIT``,
    else every LUT index with the interpolation weights 0, 1, half-1, half, half+1 and max,
    a stride sweep of ``LANE_SWEEP_LIMIT / 2`` values and as many random ones."""
    top = fs.error.raw_max
    if top + 1 <= LANE_SWEEP_LIMIT:
        return np.arange(top + 1, dtype=np.int64), True
    r = fs.lut_frac_bits
    half = (1 << r) >> 1
    weights = np.unique(np.clip([0, 1, half - 1, half, half + 1, (1 << r) - 1], 0, (1 << r) - 1))
    idx = np.arange((top >> r) + 1, dtype=np.int64)
    grid = ((idx[:, None] << r) | weights[None, :]).ravel()
    stride = np.linspace(0, top, LANE_SWEEP_LIMIT // 2, dtype=np.int64)
    rand = np.random.default_rng(10).integers(0, top + 1, LANE_SWEEP_LIMIT // 2)
    values = np.unique(np.concatenate([grid, stride, rand, [0, top]]))
    return values[values <= top], False


@pytest.mark.slow
@pytest.mark.parametrize("preset", distinct_step_presets())
def test_lane_sweeps_and_every_reachable_sum(preset):
    """Sweeps 1-3 of the module docstring (light stalls): every input pair when the lanes are
    swept whole and the step path is separable."""
    fs = FormatSet.preset(preset)
    assert separable(fs), "steps 1-3 need dt = C + v_S + v_C exactly (no rounding, no saturation)"
    e, exhaustive = lane_inputs(fs)
    print(f"{preset}: lanes {'whole domain' if exhaustive else 'dense sweep'} ({e.size} values)")
    a0, b0 = fs.error.raw_max, 0
    sum_a, sum_b = pairs_for_every_sum(fs)
    area = np.concatenate([e, np.full_like(e, a0), sum_a])
    shape = np.concatenate([np.full_like(e, b0), e, sum_b])
    check_step(StepGenerator(fs), area, shape, seed=1, p_valid=0.97, p_ready=0.97)


@pytest.mark.parametrize("preset", PRESETS)
def test_random_pairs_with_stalls(preset):
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(2)
    top = fs.error.raw_max
    corners = np.array([0, 1, top - 1, top, (top + 1) // 2])
    ca, cb = (g.ravel() for g in np.meshgrid(corners, corners))
    area = np.concatenate([ca, rng.integers(0, top + 1, 5000)])
    shape = np.concatenate([cb, rng.integers(0, top + 1, 5000)])
    check_step(StepGenerator(fs), area, shape, seed=3, p_valid=0.7, p_ready=0.7)


#: The documented latencies (``docs/hardware.md``, the StepGenerator docstring; ``tests/test_docs.py``
#: checks that they say these numbers): the presets; without interpolation; a 20-bit ``dt``, whose
#: square takes 2 x 2 partial products and so two adder levels.
LATENCY = {"default": 17, "narrow": 17, "no_interpolation": 12, "wide_dt": 19}
LATENCY_FORMATS = {"no_interpolation": dict(lut_interpolate=False),
                   "wide_dt": dict(dt="u0.20", half_dt_sq="u0.20", lut_entry="u0.20")}


def latency_case(name):
    return FormatSet.preset(name) if name in PRESETS else FormatSet.preset("default").replace(**LATENCY_FORMATS[name])


@pytest.mark.parametrize("case", LATENCY)
def test_throughput_and_latency(case):
    """No stalls: N pairs in N consecutive edges and out from edge ``latency`` on (N + latency
    edges: no bubbles); with input gaps each output leaves ``latency`` edges after its input."""
    fs = latency_case(case)
    dut = StepGenerator(fs)
    assert dut.latency == LATENCY[case]
    rng = np.random.default_rng(4)
    area, shape = rng.integers(0, fs.error.raw_max + 1, (2, 400))
    run = check_step(dut, area, shape)
    assert run.in_cycles == list(range(400))
    assert run.out_cycles == list(range(dut.latency, dut.latency + 400))
    run = check_step(dut, area, shape, seed=5, p_valid=0.5)
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.latency] * 400


def test_output_independent_of_ready():
    fs = FormatSet.preset("default")
    rng = np.random.default_rng(6)
    area, shape = rng.integers(0, fs.error.raw_max + 1, (2, 300))
    check_step(StepGenerator(fs), area, shape, seed=7, p_valid=0.8, p_ready=0.6,
               probe_ready=True)


def test_one_transfer_at_a_time():
    """stream_put/stream_get with dict payloads, one pair in flight at a time, against step_size."""
    fs = FormatSet.preset("default")
    top = fs.error.raw_max
    pairs = [(0, 0), (top, top), (top, 0), (0, top), (top // 3, top // 2), (1, top - 1)]
    want_dt, want_half = step_size(*np.array(pairs).T, fs)
    dut = StepGenerator(fs)
    results = []

    async def bench(ctx):
        for area, shape in pairs:
            assert await stream_put(ctx, dut.i, {"area_error": area, "shape_error": shape}) == 1
            results.append(await stream_get(ctx, dut.o))

    run_testbenches(dut, bench)
    assert results == [{"dt": int(d), "half_dt_sq": int(h)} for d, h in zip(want_dt, want_half)]


VARIANTS = {
    "nearest_even": dict(rounding="nearest_even"),
    "floor": dict(rounding="floor"),
    "nearest_entry": dict(lut_interpolate=False),
    "nearest_entry_floor": dict(lut_interpolate=False, rounding="floor"),
    "index_is_error": dict(error="u0.10", lut_index_bits=10),  # r = 0: T[E]
    "u1_error_clamps": dict(error="u1.15", lut_index_bits=6),  # E > 1 clamps to 1
    "entry_finer_than_dt": dict(lut_entry="u0.21", rounding="nearest_even"),
    "entry_coarser_than_dt": dict(lut_entry="u0.15", half_dt_sq="u0.22"),
    "coarse_dt": dict(dt="u1.12", half_dt_sq="u0.10", lut_entry="u0.14"),
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_generic_formatsets(variant):
    """Non-preset knobs: every rounding mode, no interpolation, r = 0, a u1.F error, and
    requantisation between entry and dt lsbs. Uniform random pairs plus the corners."""
    fs = FormatSet.preset("default").replace(**VARIANTS[variant])
    rng = np.random.default_rng(8)
    top = fs.error.raw_max
    corners = np.array([0, 1, top, 1 << fs.error.frac_bits, (1 << fs.error.frac_bits) - 1])
    ca, cb = (g.ravel() for g in np.meshgrid(corners.clip(0, top), corners.clip(0, top)))
    area = np.concatenate([ca, rng.integers(0, top + 1, 1500)])
    shape = np.concatenate([cb, rng.integers(0, top + 1, 1500)])
    check_step(StepGenerator(fs), area, shape, seed=9, p_valid=0.8, p_ready=0.8)


def test_parameter_validation():
    # A component whose __init__ raises is still reported as unused when collected.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match=r"StepGenerator needs a FormatSet, not 'default'"):
            StepGenerator("default")
        with pytest.raises(TypeError, match=r"StepGenerator needs a FormatSet, not RsqrtConfig"):
            StepGenerator(FormatSet.preset("default").rsqrt_config())
        gc.collect()


@pytest.mark.parametrize("preset", PRESETS)
def test_converts_to_verilog(preset, monkeypatch):
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    fs = FormatSet.preset(preset)
    text = verilog.convert(StepGenerator(fs), name="step_generator")
    assert "module step_generator" in text
    ports = {
        "i__payload": f"input [{2 * fs.error.width - 1}:0]",  # area_error, shape_error
        "i__valid": "input", "i__ready": "output",
        "o__payload": f"output [{fs.dt.width + fs.half_dt_sq.width - 1}:0]",  # dt, half_dt_sq
        "o__valid": "output", "o__ready": "input",
    }
    for name, decl in ports.items():
        assert any(line.strip().startswith(decl) and line.strip().endswith(f" {name};")
                   for line in text.splitlines()), f"port {name} ({decl}) missing"


# ---------------------------------------------------------------- saturation events

def step_saturations(fs, area, shape):
    """The RTL's per-step ``saturations`` (a unit with ``saturations=True``, checked bit-exact first)."""
    dut = StepGenerator(fs, saturations=True)
    run = check_step(dut, area, shape, seed=13, p_valid=0.8, p_ready=0.7)
    return unpack_beats(dut.o.payload.shape(), run.outputs)["saturations"]


def golden_step_events(fs, area, shape):
    """``(SaturationCounter, per-step totals)`` of ``step_size``."""
    counter = SaturationCounter()
    step_size(area, shape, fs, counter)
    per_step = []
    for a, b in zip(area, shape):
        one = SaturationCounter()
        step_size(np.array([a]), np.array([b]), fs, one)
        per_step.append(one.total)
    return counter, np.array(per_step)


@pytest.mark.parametrize("variant", ["u1_error_clamps", "u1_error_nearest_entry"])
def test_saturations_count_every_golden_event(variant):
    """A ``u1.F`` error above 1.0 is clamped (``lut_input``, per lane): each step's ``saturations``
    is the number of events ``step_size`` counts for it, and they sum to its counter's total. (The
    other events, ``dt`` and ``half_dt_sq``, no format set can raise: ``dt ≤ C + 0.2 < 0.5``.)"""
    knobs = dict(VARIANTS["u1_error_clamps"], **({"lut_interpolate": False} if "nearest" in variant else {}))
    fs = FormatSet.preset("default").replace(**knobs)
    rng = np.random.default_rng(14)
    top, one = fs.error.raw_max, 1 << fs.error.frac_bits
    corners = np.array([0, one - 1, one, one + 1, top])
    ca, cb = (g.ravel() for g in np.meshgrid(corners, corners))
    area = np.concatenate([ca, rng.integers(0, top + 1, 600)])
    shape = np.concatenate([cb, rng.integers(0, top + 1, 600)])
    counter, per_step = golden_step_events(fs, area, shape)
    assert set(counter.saturations) == {"lut_input"} and per_step.max() == 2
    got = step_saturations(fs, area, shape)
    bad = np.flatnonzero(got != per_step)
    assert bad.size == 0, f"{bad.size} steps miscounted; first {int(bad[0])}: rtl {int(got[bad[0]])} golden " \
                          f"{int(per_step[bad[0]])}"
    assert int(got.sum()) == counter.total


@pytest.mark.parametrize("preset", PRESETS)
def test_saturations_zero_in_the_presets(preset):
    """The presets' u0.F errors cannot exceed 1.0 and their steps fit: every count is 0."""
    fs = FormatSet.preset(preset)
    top = fs.error.raw_max
    area = np.concatenate([[0, top, top, 0], np.random.default_rng(15).integers(0, top + 1, 300)])
    shape = np.concatenate([[0, top, 0, top], np.random.default_rng(16).integers(0, top + 1, 300)])
    counter, _ = golden_step_events(fs, area, shape)
    assert counter.total == 0
    assert not step_saturations(fs, area, shape).any()


def test_saturations_leave_the_default_build_alone():
    """``saturations=False`` (the default) has the layout it had; the count is 3 bits (5 events)."""
    fs = FormatSet.preset("default")
    assert StepGenerator.output_layout(fs) == StepGenerator.output_layout(fs, saturations=False)
    assert "saturations" not in dict(StepGenerator.output_layout(fs))
    assert StepGenerator.output_layout(fs, saturations=True)["saturations"].shape == unsigned(3)
