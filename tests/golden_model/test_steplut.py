"""exp-LUT step-size generator: table rounding, exhaustive accuracy, separability."""

from __future__ import annotations

import math
from decimal import Decimal, localcontext
from fractions import Fraction

import numpy as np
import pytest

from golden_model.fixed import (
    DT_MIN,
    Format,
    FormatSet,
    Rounding,
    SaturationCounter,
    dt_constant,
    exp_lut,
    exp_table,
    lut_value_float,
    step_size,
    step_size_error_bound,
    step_size_float,
    to_float,
)
from golden_model.fixed.steplut import measure_step_size
from support import PRESETS



def _variants():
    d = FormatSet.preset("default")
    return {
        "default": d,
        "narrow": FormatSet.preset("narrow"),
        "no_interp": d.replace(lut_interpolate=False, lut_index_bits=10, name="no_interp"),
        "floor": d.replace(rounding="floor", name="floor"),
        "nearest_even": d.replace(rounding="nearest_even", name="nearest_even"),
        "u1_error": d.replace(error="u1.15", lut_index_bits=7, name="u1_error"),
        "lut_finer": d.replace(lut_entry="u0.22", name="lut_finer"),  # not separable
        "direct": d.replace(error="u0.10", lut_index_bits=10, name="direct"),  # r = 0
    }


VARIANTS = _variants()


# ----------------------------------------------------------------- float reference
def test_step_size_float_formula():
    assert step_size_float(1.0, 1.0) == pytest.approx(0.21, abs=1e-15)
    assert step_size_float(0.0, 0.0) == pytest.approx(0.01 + 0.2 * math.exp(-5), abs=1e-15)
    assert step_size_float(2.0, -1.0) == step_size_float(1.0, 0.0)  # inputs clamped to [0, 1]
    e = np.linspace(0, 1, 11)
    np.testing.assert_allclose(step_size_float(e, 0.3), 0.01 + 0.1 * np.exp(-5 * (1 - e))
                               + 0.1 * math.exp(-3.5), rtol=1e-15)


def test_the_step_formula_is_written_once():
    """The step generator's float model is the float reference's ``variable_step``, constants and all."""
    from golden_model import reference
    from golden_model.fixed import steplut

    assert steplut.step_size_float is reference.variable_step
    assert (steplut.DT_MIN, steplut.LUT_SCALE, steplut.LUT_RATE) == (reference.STEP_MIN, reference.STEP_SCALE,
                                                                     reference.STEP_RATE)
    e = np.linspace(-0.5, 1.5, 21)
    assert np.array_equal(lut_value_float(e), reference.STEP_SCALE * reference.step_decay(e))
    assert reference.variable_step(0.3, 0.8) == float(step_size_float(np.array([0.3]), np.array([0.8]))[0])


# ----------------------------------------------------------------- table
@pytest.mark.parametrize("n, fmt_s", [(8, "u0.18"), (7, "u0.16"), (4, "u0.10"), (10, "u0.30")])
def test_exp_table_correctly_rounded(n, fmt_s):
    fmt = Format.parse(fmt_s)
    t = exp_table(n, fmt)
    assert t.shape == ((1 << n) + 1,) and np.all(np.diff(t) >= 0)
    assert t[-1] == ((1 << fmt.frac_bits) + 5) // 10  # 0.1 * 2**F rounded half up
    # independent evaluation: 80-digit Decimal, distance to the integer strictly < 1/2
    with localcontext() as ctx:
        ctx.prec = 80
        for k, v in enumerate(t.tolist()):
            x = (Decimal(-5 * ((1 << n) - k)) / (1 << n)).exp() / 10 * (1 << fmt.frac_bits)
            assert abs(x - v) < Decimal("0.5"), (k, v, x)
    # float64 evaluation agrees (no entry is near a tie)
    e = np.arange((1 << n) + 1) / (1 << n)
    np.testing.assert_array_equal(t, np.floor(lut_value_float(e) * 2.0**fmt.frac_bits + 0.5))


# ----------------------------------------------------------------- exhaustive accuracy
@pytest.mark.parametrize("name", list(VARIANTS))
def test_step_size_exhaustive(name):
    fs = VARIANTS[name]
    e_all = np.arange(0, fs.error.raw_max + 1, dtype=np.int64)
    zeros = np.zeros_like(e_all)
    c = SaturationCounter()
    dt_s, half_s = step_size(e_all, zeros, fs, c)
    dt_c, _ = step_size(zeros, e_all, fs, c)
    np.testing.assert_array_equal(dt_s, dt_c)  # symmetric in E_S, E_C
    assert fs.dt.contains(dt_s) and np.all(np.diff(dt_s) >= 0)  # monotone in E

    ef = np.minimum(to_float(e_all, fs.error), 1.0)  # represented E (u1.F clamps at 1)
    bound = step_size_error_bound(fs)
    err_1d = dt_s - step_size_float(ef, 0.0) / fs.dt.lsb
    assert np.abs(err_1d).max() <= bound

    # separability: dt(a, b) = C + v(a) + v(b) exactly when lookups are summed without rounding
    table = exp_table(fs.lut_index_bits, fs.lut_entry)
    v = exp_lut(e_all, fs.error, table, fs.lut_index_bits, fs.lut_interpolate, fs.rounding)
    rng = np.random.default_rng(0)
    a = rng.integers(0, fs.error.raw_max, 100_000, endpoint=True)
    b = rng.integers(0, fs.error.raw_max, 100_000, endpoint=True)
    dt_ab, half_ab = step_size(a, b, fs, c)
    m = measure_step_size(fs)
    if m["separable"]:
        np.testing.assert_array_equal(dt_ab, dt_constant(fs.dt) + v[a] + v[b])
        # hence the maximum over ALL pairs follows exactly from the 1-D sweep
        assert m["max_dt_ulp_error"] <= bound
    err_ab = dt_ab - step_size_float(ef[a], ef[b]) / fs.dt.lsb
    assert np.abs(err_ab).max() <= bound
    assert np.abs(err_ab).max() <= m["max_dt_ulp_error"] + 1e-9  # exact max or upper bound

    # half_dt_sq = round(dt**2 / 2) exactly (Python integers)
    k = 2 * fs.dt.frac_bits + 1 - fs.half_dt_sq.frac_bits
    for d, h in zip(dt_ab[:2000].tolist(), half_ab[:2000].tolist()):
        p = d * d
        if fs.rounding is Rounding.FLOOR:
            ref = p >> k
        elif fs.rounding is Rounding.HALF_UP:
            ref = (p + (1 << (k - 1))) >> k
        else:
            ref = round(Fraction(p, 1 << k))  # half to even
        assert h == ref
    assert c["dt"] == 0 and c["half_dt_sq"] == 0  # no saturation on the step path
    print(f"\n{name}: dt max error {m['max_dt_ulp_error']:.3f} dt ulps over all "
          f"(E_S, E_C) pairs (lookup error [{m['lookup_err_min']:.3f}, "
          f"{m['lookup_err_max']:.3f}], 0.01 -> {m['const_err']:+.3f}), bound {bound:.3f}")


@pytest.mark.parametrize("name", PRESETS)
def test_presets_dt_accuracy_is_a_few_ulps(name):
    m = measure_step_size(FormatSet.preset(name))
    assert m["separable"] and m["max_dt_ulp_error"] < m["bound"] <= 5.0


def test_error_input_clamping_u1():
    fs = VARIANTS["u1_error"]
    one = 1 << fs.error.frac_bits
    c = SaturationCounter()
    dt, _ = step_size(np.array([one, one + 1, fs.error.raw_max]), np.array([one] * 3), fs, c)
    assert len(set(dt.tolist())) == 1 and c["lut_input"] == 2  # E_S = one+1 and raw_max
    t = exp_table(fs.lut_index_bits, fs.lut_entry)
    assert dt[0] == dt_constant(fs.dt) + 2 * t[-1]
    with pytest.raises(ValueError, match="out of range"):
        step_size(np.array([-1]), np.array([0]), fs)


def test_dt_constant_and_scalars():
    fs = FormatSet.preset("default")
    c = dt_constant(fs.dt)
    assert abs(c * fs.dt.lsb - DT_MIN) <= fs.dt.lsb / 2
    dt, half = step_size(0, 0, fs)
    assert dt.shape == () and half.shape == ()
    assert abs(float(to_float(dt, fs.dt)) - float(step_size_float(0, 0))) < 5 * fs.dt.lsb
