"""RTL rsqrt unit (hdl.RsqrtUnit) against the golden model, in Amaranth's simulator.

Every output is compared, in order, with ``rsqrt_with_config`` (value and saturation flag)
under seeded random valid/ready stalls on both sides, driven by the stream helpers of
:mod:`support.streams` (shared with ``test_hdl_stepgen.py`` and ``test_hdl_node_update.py``).
"""

import gc
import warnings

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import UnusedElaboratable

import golden_model.fixed.rsqrt as golden_rsqrt
from golden_model.fixed import (
    Format,
    FormatSet,
    Rounding,
    RsqrtConfig,
    SaturationCounter,
    rsqrt_stages,
    rsqrt_with_config,
)
from hdl import RsqrtUnit
from hdl.fixedpoint import FormatSetNotBuildable
from sim.payloads import unpack_beats
from support import PRESETS
from support.streams import run_streams, run_testbenches, stream_get, stream_put


# --------------------------------------------------------------------------- inputs


def boundary_inputs(cfg):
    """0, 1, raw_max, every power of two and its neighbours, the saturation threshold and its
    neighbours, and one input per seed-ROM entry (each with random bits below the index)."""
    top = cfg.fmt_in.raw_max
    pw = [1 << k for k in range(cfg.fmt_in.width)]
    vals = {0, 1, 2, 3, top - 1, top} | {p + d for p in pw for d in (-1, 0, 1)}
    # Largest saturating input (saturation is monotone: bisect on the golden model's flag).
    lo, hi = 0, top
    if rsqrt_stages(top, cfg)["saturate"]:
        lo = hi
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if rsqrt_stages(mid, cfg)["saturate"] else (lo, mid)
    vals |= set(range(max(lo - 3, 0), min(lo + 4, top + 1)))
    # Seed index j: X = i << q with i = j + offset and q + seed_bits - 2 - Fin even (so that
    # the exponent is e = q + seed_bits - 2 and the top seed_bits of M are exactly i).
    rng = np.random.default_rng(1)
    for j in range(cfg.seed_table_size):
        i = j + cfg.seed_index_offset
        for q in range(cfg.fmt_in.width):
            if (q + cfg.seed_bits - 2 - cfg.fmt_in.frac_bits) % 2 == 0 and (i << q) <= top:
                low = int(rng.integers(0, 1 << q)) if q else 0
                vals.add((i << q) | low)
                break
    x = np.array(sorted(v for v in vals if 0 <= v <= top), dtype=np.int64)
    return x


def random_inputs(cfg, n, seed):
    """``n/2`` uniform and ``n/2`` log-uniform inputs (dense at small x, where few bits drop)."""
    rng = np.random.default_rng(seed)
    top = cfg.fmt_in.raw_max
    uni = rng.integers(0, top + 1, n // 2)
    logu = np.exp2(rng.uniform(0, np.log2(float(top)), n - n // 2)).astype(np.int64)
    return np.clip(np.concatenate([uni, logu]), 0, top)


def check_rsqrt(dut, x, **kw):
    """Run ``x`` through ``dut``; compare every output and the saturation count; return run."""
    cfg = dut.config
    run = run_streams(dut, [int(v) for v in x], **kw)
    out = unpack_beats(dut.o.payload.shape(), run.outputs)
    got = out["rsqrt"]
    sat = out["saturated"].astype(bool)
    counter = SaturationCounter()
    want = rsqrt_with_config(x, cfg, counter)
    bad = np.flatnonzero(got != want)
    if bad.size:
        i = bad[0]
        st = {k: int(v[0]) for k, v in rsqrt_stages(x[i:i + 1], cfg).items()}
        pytest.fail(f"{bad.size} mismatches; first: x={int(x[i])} rtl={int(got[i])} "
                    f"golden={int(want[i])} stages={st}")
    np.testing.assert_array_equal(sat, rsqrt_stages(x, cfg)["saturate"])
    assert int(sat.sum()) == counter["rsqrt"]
    return run


# --------------------------------------------------------------------------- tests


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_golden_intermediates_fit_rtl_widths(preset):
    """The RTL holds every intermediate in its RsqrtConfig format (the golden model computes in
    int64). Check that the golden values fit, over the whole domain when it has at most 2**24
    inputs, else over the boundaries and 2**22 random inputs."""
    cfg = FormatSet.preset(preset).rsqrt_config()
    n = cfg.fmt_in.raw_max + 1
    if n <= 1 << 24:
        chunks = (np.arange(lo, min(n, lo + (1 << 21))) for lo in range(0, n, 1 << 21))
    else:
        chunks = [boundary_inputs(cfg), random_inputs(cfg, 1 << 22, seed=7)]
    fmts = {"m": cfg.mant_fmt, "y0": cfg.y_fmt, "y": cfg.y_fmt}
    for i in range(cfg.newton_steps):
        fmts.update({f"t1_{i}": cfg.ysq_fmt, f"t2_{i}": cfg.ysq_fmt, f"h_{i}": cfg.h_fmt,
                     f"y_{i}": cfg.y_fmt})
    for x in chunks:
        st = rsqrt_stages(x, cfg)
        for name, fmt in fmts.items():
            fmt.check(st[name], f"{preset} rsqrt intermediate {name}")
        assert int(st["seed_index"].min()) >= 0
        assert int(st["seed_index"].max()) < cfg.seed_table_size


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_boundaries_and_random_with_stalls(preset):
    """Boundary inputs and ~20k random inputs, random stalls on both sides."""
    cfg = FormatSet.preset(preset).rsqrt_config()
    rng = np.random.default_rng(3)
    x = np.concatenate([boundary_inputs(cfg), random_inputs(cfg, 20_000, seed=4)])
    rng.shuffle(x)
    check_rsqrt(RsqrtUnit(FormatSet.preset(preset)), x, seed=5, p_valid=0.75, p_ready=0.75)


@pytest.mark.parametrize("preset", PRESETS)
def test_throughput_and_latency(preset):
    """No stalls: N inputs on N consecutive edges, N outputs from edge ``latency`` on (N +
    latency edges in all: no bubbles). With input gaps and o.ready high every output leaves
    exactly ``latency`` edges after its input."""
    fs = FormatSet.preset(preset)
    dut = RsqrtUnit(fs)
    assert dut.latency == {"default": 28, "narrow": 28, "wide": 28}[preset]  # as documented in docs/hardware-units.md
    x = random_inputs(fs.rsqrt_config(), 400, seed=8)
    run = check_rsqrt(dut, x)
    assert run.in_cycles == list(range(len(x)))
    assert run.out_cycles == list(range(dut.latency, dut.latency + len(x)))
    run = check_rsqrt(dut, x, seed=9, p_valid=0.5)
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.latency] * len(x)


def test_output_independent_of_ready():
    """o.valid and o.payload never depend (combinationally) on o.ready."""
    fs = FormatSet.preset("narrow")
    x = random_inputs(fs.rsqrt_config(), 300, seed=10)
    check_rsqrt(RsqrtUnit(fs), x, seed=11, p_valid=0.8, p_ready=0.6, probe_ready=True)


def test_one_transfer_at_a_time():
    """stream_put/stream_get, one input in flight at a time: each result, as a dict, is the golden one."""
    fs = FormatSet.preset("narrow")
    cfg = fs.rsqrt_config()
    x = [0, 1, cfg.fmt_in.raw_max, *random_inputs(cfg, 6, seed=16).tolist()]
    want = rsqrt_with_config(np.array(x), cfg)
    saturated = rsqrt_stages(np.array(x), cfg)["saturate"]
    dut = RsqrtUnit(fs)
    results = []

    async def bench(ctx):
        for value in x:
            assert await stream_put(ctx, dut.i, value) == 1  # the unit is empty: taken at once
            results.append(await stream_get(ctx, dut.o))

    run_testbenches(dut, bench)
    assert results == [{"rsqrt": int(w), "saturated": int(s)} for w, s in zip(want, saturated)]


GENERIC_CONFIGS = [
    RsqrtConfig(Format(False, 7, 16), Format(False, 4, 14), 10, 0),  # seed only
    RsqrtConfig(Format(False, 7, 16), Format(False, 4, 14), 6, 2),  # two Newton steps
    RsqrtConfig(Format(False, 5, 12), Format(False, 3, 12), 3, 3),  # three steps, tiny ROM
    RsqrtConfig(Format(False, 7, 16), Format(False, 4, 14), 8, 1, guard_bits=1),
    RsqrtConfig(Format(False, 20, 20), Format(False, 2, 14), 10, 1),  # M floors input bits
    RsqrtConfig(Format(False, 12, 1), Format(False, 1, 17), 9, 1),  # odd Fin
    RsqrtConfig(Format(False, 0, 12), Format(False, 0, 16), 5, 2),  # nothing saturates by s
]


@pytest.mark.parametrize("cfg", GENERIC_CONFIGS, ids=str)
def test_generic_configs(cfg):
    """Non-preset configurations: every width really comes from the RsqrtConfig."""
    x = np.concatenate([boundary_inputs(cfg), random_inputs(cfg, 1000, seed=12)])
    check_rsqrt(RsqrtUnit(cfg), x, seed=13, p_valid=0.8, p_ready=0.8)


def test_parameter_validation():
    # A component whose __init__ raises is still reported as unused when collected.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        cfg = FormatSet.preset("default").rsqrt_config()
        with pytest.raises(TypeError, match=r"needs a FormatSet or an RsqrtConfig, not 'default'"):
            RsqrtUnit("default")
        with pytest.raises(FormatSetNotBuildable, match=r"input format must be unsigned, not s7\.16"):
            RsqrtUnit(RsqrtConfig(Format(True, 7, 16), cfg.fmt_out, 10, 1))
        with pytest.raises(FormatSetNotBuildable, match=r"output format must be unsigned, not s4\.13"):
            RsqrtUnit(RsqrtConfig(cfg.fmt_in, Format(True, 4, 13), 10, 1))
        gc.collect()


@pytest.mark.parametrize("preset", PRESETS)
def test_converts_to_verilog(preset, monkeypatch):
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    fs = FormatSet.preset(preset)
    cfg = fs.rsqrt_config()
    dut = RsqrtUnit(fs)
    text = verilog.convert(dut, name="rsqrt_unit")
    assert "module rsqrt_unit" in text
    ports = {
        "i__payload": f"input [{cfg.fmt_in.width - 1}:0]",
        "i__valid": "input", "i__ready": "output",
        "o__payload": f"output [{cfg.fmt_out.width}:0]",  # rsqrt + saturated
        "o__valid": "output", "o__ready": "input",
    }
    for name, decl in ports.items():
        assert any(line.strip().startswith(decl) and line.strip().endswith(f" {name};")
                   for line in text.splitlines()), f"port {name} ({decl}) missing"


@pytest.mark.parametrize("rounding", ["floor", "half_up", "nearest_even"])
def test_follows_golden_internal_rounding(rounding, monkeypatch):
    """The unit takes its rounding from the golden model (module constant), in every mode."""
    monkeypatch.setattr(golden_rsqrt, "INTERNAL_ROUNDING", Rounding(rounding))
    for cfg in (FormatSet.preset("narrow").rsqrt_config(), GENERIC_CONFIGS[1]):
        x = np.concatenate([boundary_inputs(cfg), random_inputs(cfg, 1500, seed=14)])
        check_rsqrt(RsqrtUnit(cfg), x, seed=15, p_valid=0.9, p_ready=0.9)
