"""rsqrt unit model: seed ROM, derived widths, and the faithful-rounding contract.

Contract checked here: for every input x the result R satisfies
``|R - min(2**Fout / sqrt(x), raw_max)| < 1`` (faithful; saturated to raw_max
above the output range, and for x = 0).  Exhaustive for input widths <= 24.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from golden_model.fixed import (
    Format,
    FormatSet,
    RsqrtConfig,
    SaturationCounter,
    bit_length,
    rsqrt_seed_table,
    rsqrt_stages,
    rsqrt_with_config,
)
from golden_model.fixed.rsqrt import _sweep_points, measure_rsqrt, rsqrt
from support import PRESETS

FAITHFUL = 1.0  # stated bound: strictly less than one output ulp


# ----------------------------------------------------------------- seed ROM
@pytest.mark.parametrize("sb, fs", [(2, 5), (6, 9), (9, 12), (10, 13), (12, 20)])
def test_seed_table_correctly_rounded(sb, fs):
    t = rsqrt_seed_table(sb, fs)
    assert t.shape == (3 << (sb - 2),) and t.dtype == np.int64
    assert np.all(np.diff(t) <= 0) and t.max() < (1 << fs)
    for j, k in enumerate(t.tolist()):
        i = j + (1 << (sb - 2))
        c = Fraction(2 * i + 1, 1 << (sb - 1))  # interval midpoint
        # k - 1/2 <= 2**fs / sqrt(c) < k + 1/2, squared (all terms positive)
        lhs, rhs = Fraction(2 * k - 1) ** 2 * c, Fraction(2 * k + 1) ** 2 * c
        assert lhs <= 4 * Fraction(1 << (2 * fs)) < rhs, (j, k)


def test_seed_table_args():
    with pytest.raises(ValueError, match="seed_bits must be >= 2"):
        rsqrt_seed_table(1, 8)


# ----------------------------------------------------------------- widths
def test_config_widths_derived():
    cfg = RsqrtConfig(Format.parse("u7.16"), Format.parse("u4.14"), 10, 1)
    fy = 4 + 14 + cfg.guard_bits
    assert cfg.y_frac_bits == cfg.mant_frac_bits == cfg.work_frac_bits == fy
    assert cfg.seed_frac_bits == 10 + cfg.guard_bits
    assert str(cfg.y_fmt) == f"u1.{fy}" and str(cfg.mant_fmt) == f"u2.{fy}"
    assert str(cfg.h_fmt) == f"s0.{fy}" and str(cfg.seed_fmt) == f"u0.{10 + cfg.guard_bits}"
    assert cfg.seed_table_size == 768 and cfg.seed_index_offset == 256
    assert cfg.seed_index_shift == fy + 2 - 10
    assert np.array_equal(cfg.seed_table(), rsqrt_seed_table(10, cfg.seed_frac_bits))
    assert all(a.width + b.width <= 63 for _, a, b in cfg.products)
    assert RsqrtConfig(Format.parse("u7.16"), Format.parse("u4.14"), 10, 0).seed_frac_bits == fy


@pytest.mark.parametrize("kw, msg", [
    (dict(seed_bits=1), "seed_bits must be >= 2"),
    (dict(newton_steps=-1), "newton_steps must be >= 0"),
    (dict(guard_bits=0), "guard_bits must be >= 1"),
    (dict(fmt_out=Format.parse("u10.20")), r"rsqrt product y\*y: u1.33 \(34 bits\)"),
])
def test_config_validation(kw, msg):
    args = dict(fmt_in=Format.parse("u7.16"), fmt_out=Format.parse("u4.14"), seed_bits=6,
                newton_steps=2)
    args.update(kw)
    with pytest.raises(ValueError, match=msg):
        RsqrtConfig(**args)


def test_bit_length():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.integers(0, 1 << 62, 20000), [0, 1, 2, 3],
                        [(1 << k) + d for k in range(2, 62) for d in (-1, 0, 1)]]).astype(np.int64)
    np.testing.assert_array_equal(bit_length(x), [int(v).bit_length() for v in x])


# ----------------------------------------------------------------- faithful contract
def faithful_violations(x: np.ndarray, r: np.ndarray, fin: Format, fout: Format) -> np.ndarray:
    """Exact integer check of |R - min(exact, raw_max)| < 1; returns the offending x.

    exact**2 = K / X with K = 2**(2 Fout + Fin):
    saturated (exact >= raw_max):  R == raw_max
    else:  exact < R + 1  <=>  K < (R+1)**2 X   and   R - 1 < exact <=> R <= 1 or (R-1)**2 X < K.
    """
    k = 1 << (2 * fout.frac_bits + fin.frac_bits)
    top = fout.raw_max
    assert (top + 1) ** 2 * fin.raw_max < 1 << 63 and k < 1 << 63, "use a smaller format"
    x0 = x == 0
    xs = np.where(x0, 1, x)
    sat = x0 | (top * top * xs <= k)
    ok_sat = r == top
    ok_hi = k < (r + 1) ** 2 * xs
    ok_lo = (r <= 1) | ((r - 1) ** 2 * xs < k)
    ok = np.where(sat, ok_sat, ok_hi & ok_lo)
    return x[~ok]


def _exhaustive(cfg: RsqrtConfig, chunk: int = 1 << 21) -> tuple[int, int]:
    bad, nsat = [], SaturationCounter()
    n = cfg.fmt_in.raw_max + 1
    for lo in range(0, n, chunk):
        x = np.arange(lo, min(n, lo + chunk), dtype=np.int64)
        st = rsqrt_stages(x, cfg)
        for i in range(cfg.newton_steps):  # internal signals stay inside their stated formats
            assert cfg.ysq_fmt.contains(st[f"t1_{i}"]) and cfg.ysq_fmt.contains(st[f"t2_{i}"])
            assert cfg.h_fmt.contains(st[f"h_{i}"]) and cfg.y_fmt.contains(st[f"y_{i}"])
        nsat.add_saturations("rsqrt", int(np.count_nonzero(st["saturate"])))
        r = np.where(st["saturate"], cfg.fmt_out.raw_max, st["result"])
        bad.extend(faithful_violations(x, r, cfg.fmt_in, cfg.fmt_out)[:10].tolist())
    return len(bad), nsat.total


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_rsqrt_faithful_presets(preset):
    """Exhaustive where the input is at most 24 bits wide, else a dense sweep plus all boundaries."""
    cfg = FormatSet.preset(preset).rsqrt_config()
    m = measure_rsqrt(cfg)
    assert m["exhaustive"] == (cfg.fmt_in.width <= 24)
    if m["exhaustive"]:
        n_bad, n_sat = _exhaustive(cfg)
        assert n_bad == 0
        # saturation count: x = 0 plus every x with 2**Fout/sqrt(x) rounding above raw_max
        assert n_sat >= 1
    assert m["max_ulp_error"] < FAITHFUL
    print(f"\n{preset}: rsqrt {cfg.fmt_in}->{cfg.fmt_out} seed {cfg.seed_bits} "
          f"newton {cfg.newton_steps}: max error {m['max_ulp_error']:.4f} ulp "
          f"over {m['n_points']} inputs ({'exhaustive' if m['exhaustive'] else 'sweep'}), "
          f"{m['n_saturated']} saturated")


@pytest.mark.parametrize("sb, steps", [(2, 3), (3, 2), (4, 2), (5, 2)])
def test_internal_formats_hold_for_coarse_seeds(sb, steps):
    cfg = RsqrtConfig(Format.parse("u6.12"), Format.parse("u4.12"), sb, steps)
    _exhaustive(cfg)  # asserts the internal formats (faithfulness needs enough steps: not checked)


def test_checker_detects_unfaithful_config():
    """The contract check can fail: one Newton step from a 6-bit seed is not enough."""
    cfg = RsqrtConfig(Format.parse("u7.16"), Format.parse("u4.14"), 6, 1)
    n_bad, _ = _exhaustive(cfg)
    assert n_bad > 0
    assert measure_rsqrt(cfg)["max_ulp_error"] > 10


@pytest.mark.parametrize("fin, fout, sb, steps", [
    ("u9.20", "u5.16", 8, 2),   # 29-bit input: dense sweep, mantissa truncation active
    ("u30.0", "u0.24", 7, 2),   # integer input, pure-fraction output
])
@pytest.mark.slow
def test_rsqrt_faithful_dense_sweep_wide_input(fin, fout, sb, steps):
    cfg = RsqrtConfig(Format.parse(fin), Format.parse(fout), sb, steps)
    assert cfg.fmt_in.width > 24
    pts = _sweep_points(cfg.fmt_in, 1 << 22, seed=1)
    assert pts.size >= 1 << 22
    r = rsqrt_with_config(pts, cfg)
    # float64 reference: exact/ulp carries a relative error ~1e-16, so a margin of 1e-6
    # ulp is safe; exact integer check on the boundary cases below.
    with np.errstate(divide="ignore"):  # x = 0 -> inf -> clamped to raw_max
        inv = 1 / np.sqrt(np.ldexp(pts.astype(float), -cfg.fmt_in.frac_bits))
    ex = np.minimum(np.ldexp(inv, cfg.fmt_out.frac_bits), cfg.fmt_out.raw_max)
    assert np.abs(r - ex).max() < FAITHFUL - 1e-6
    top = cfg.fmt_in.raw_max
    edge = [0, 1, 2, 3, top, top - 1] + [(1 << k) + d for k in range(1, cfg.fmt_in.width)
                                          for d in (-1, 0, 1)]
    edge = sorted(set(e for e in edge if 0 <= e <= top))
    re = rsqrt_with_config(np.array(edge, dtype=np.int64), cfg)
    kk = 1 << (2 * cfg.fmt_out.frac_bits + cfg.fmt_in.frac_bits)
    for x, rv in zip(edge, re.tolist()):
        if x == 0 or cfg.fmt_out.raw_max ** 2 * x <= kk:
            assert rv == cfg.fmt_out.raw_max, x
        else:
            assert kk < (rv + 1) ** 2 * x and (rv <= 1 or (rv - 1) ** 2 * x < kk), x


def test_rsqrt_special_cases_and_counting():
    fin, fout = Format.parse("u7.16"), Format.parse("u4.14")
    c = SaturationCounter()
    x = np.array([[0, 1 << 16], [1 << 14, 1 << 18]], dtype=np.int64)  # 0, 1, 1/4, 4
    r = rsqrt(x, fin, fout, 10, 1, c, "rsq")
    assert r.shape == (2, 2)
    assert r.tolist() == [[fout.raw_max, 1 << 14], [1 << 15, 1 << 13]]  # exact powers of two
    assert c["rsq"] == 1
    # 1/sqrt(x) = 16 exactly is one above raw_max: saturates and counts
    assert int(rsqrt(np.int64(1 << 8), fin, fout, 10, 1, c, "rsq")) == fout.raw_max
    assert c["rsq"] == 2
    with pytest.raises(ValueError, match="non-negative"):
        rsqrt(np.array([-1]), Format.parse("s7.16"), fout, 10, 1)
    with pytest.raises(ValueError, match="out of range"):
        rsqrt(np.array([1 << 23]), fin, fout, 10, 1)


def test_stages_expose_intermediates():
    cfg = FormatSet.preset("default").rsqrt_config()
    x = np.arange(1, 1 << 16, 7, dtype=np.int64)
    st = rsqrt_stages(x, cfg)
    m = st["m"]
    assert np.all((m >= 1 << cfg.mant_frac_bits) & (m < 4 << cfg.mant_frac_bits))
    assert np.all((st["e"] - cfg.fmt_in.frac_bits) % 2 == 0)
    assert np.all((st["seed_index"] >= 0) & (st["seed_index"] < cfg.seed_table_size))
    assert cfg.h_fmt.contains(st["h_0"]) and cfg.ysq_fmt.contains(st["t2_0"])
    assert cfg.y_fmt.contains(st["y"])
    np.testing.assert_array_equal(
        np.where(st["saturate"], cfg.fmt_out.raw_max, st["result"]), rsqrt_with_config(x, cfg))
