"""Formats, quantisation primitives and FormatSet.

Primitives are checked against exact Python-integer references and against
fxpmath 0.4.10 configured the same way.  fxpmath rounding names (see
fxpmath/objects.py, Fxp._round and Config._rounding_aliases):

* ``'floor'``          np.floor                 == our floor
* ``'nearest_posinf'`` floor, +1 if frac >= 0.5 == our half_up  (alias SC_RND)
* ``'around'``         np.around (ties to even) == our nearest_even
* ``'trunc'`` (fxpmath's default) rounds toward zero: NOT floor (checked below).
"""

from __future__ import annotations

import json
import zlib
from fractions import Fraction

import numpy as np
import pytest

from golden_model.fixed import (
    CONTROLLER_FIELDS,
    FORMAT_FIELDS,
    Format,
    FormatSet,
    Rounding,
    SaturationCounter,
    add,
    mul,
    quantize,
    requantize,
    shift_round,
    sub,
    to_float,
)
from support import PRESETS

try:  # dev dependency, pinned: fxpmath==0.4.10 (rounding semantics read from that version)
    from fxpmath import Fxp
except ImportError:  # pragma: no cover
    Fxp = None
needs_fxpmath = pytest.mark.skipif(Fxp is None, reason="fxpmath not installed (pip install fxpmath==0.4.10)")

FXP_ROUNDING = {"floor": "floor", "half_up": "nearest_posinf", "nearest_even": "around"}
N = 100_000
FORMATS = ["s3.16", "u0.18", "s7.10", "u5.0", "s0.15", "u12.20", "s20.30"]


# ----------------------------------------------------------------- Format
def test_format_properties():
    f = Format.parse("s3.16")
    assert (f.signed, f.int_bits, f.frac_bits, f.width) == (True, 3, 16, 20)
    assert (f.raw_min, f.raw_max) == (-(1 << 19), (1 << 19) - 1)
    assert f.lsb == 2.0**-16 and f.min == -8.0 and f.max == 8.0 - 2.0**-16
    u = Format.parse("u0.18")
    assert (u.width, u.raw_min, u.raw_max, str(u)) == (18, 0, (1 << 18) - 1, "u0.18")
    assert u.max == 1 - 2.0**-18 and u.min == 0.0
    for s in FORMATS + ["u62.0", "s0.61", "u0.1"]:
        assert str(Format.parse(s)) == s
    assert Format.parse(f) is f
    assert Format(True, 3, 16) == f and hash(Format(True, 3, 16)) == hash(f)


@pytest.mark.parametrize(
    "args, msg",
    [
        ((False, 0, 0), "width 0"),
        ((True, 40, 22), "width 63"),
        ((False, -1, 5), "int_bits must be >= 0"),
        ((True, 2, -3), "frac_bits must be >= 0"),
        ((1, 2, 3), "signed must be a bool"),
        ((True, 2.0, 3), "int_bits must be an int"),
    ],
)
def test_format_validation(args, msg):
    with pytest.raises(ValueError, match=msg):
        Format(*args)


@pytest.mark.parametrize("text", ["3.16", "s3", "x3.16", "s-1.4", "s3.16.1", "", "s\uff11" "0.22", "u0.\u0663"])
def test_format_parse_errors(text):
    """Digits of other scripts (a fullwidth 1, an Arabic-Indic 3) are no bit counts, though int() takes them."""
    with pytest.raises(ValueError, match="cannot parse"):
        Format.parse(text)


def test_a_format_of_hundreds_of_digits_is_refused_without_echoing_them():
    assert Format.parse("s007.16") == Format.parse("s7.16") and Format.parse("u0.022") == Format.parse("u0.22")
    with pytest.raises(ValueError, match=r"^fixed-point format 's9{39}'\.\.\.: its width is outside 1\.\.62 bits$"):
        Format.parse("s" + "9" * 400 + ".1")
    with pytest.raises(ValueError, match=r"^cannot parse fixed-point format 'x{40}'\.\.\.: expected"):
        Format.parse("x" * 1000)


def test_format_check():
    f = Format.parse("s1.2")
    assert f.contains([-8, 7]) and not f.contains([8])
    with pytest.raises(ValueError, match="out of range of format s1.2"):
        f.check(np.array([0, -9]), "x")


# ----------------------------------------------------------------- shift_round
def _ref_shift(x: int, s: int, mode: str) -> int:
    if s <= 0:
        return x << -s
    q = Fraction(x, 1 << s)
    if mode == "floor":
        return x >> s
    if mode == "half_up":
        return (x + (1 << (s - 1))) >> s
    return round(q)  # Python's round(Fraction) is half-to-even


@pytest.mark.parametrize("mode", [m.value for m in Rounding])
def test_shift_round_exact(mode):
    rng = np.random.default_rng(1)
    lo, hi = -(1 << 63), (1 << 63) - 1
    xs = np.concatenate([
        rng.integers(lo, hi, 3000, dtype=np.int64, endpoint=True),
        rng.integers(-5000, 5000, 3000),
        [lo, hi, lo + 1, hi - 1, 0, 1, -1, 2, -2, 3, -3],
    ]).astype(np.int64)
    for s in [1, 2, 3, 7, 31, 62, 63, 64, 65, 80]:
        got = shift_round(xs, s, mode)
        ref = np.array([_ref_shift(int(x), s, mode) for x in xs], dtype=np.int64)
        np.testing.assert_array_equal(got, ref, err_msg=f"shift {s}")
    # ties, per-element shift arrays and left shifts
    small = np.arange(-64, 65, dtype=np.int64)
    shifts = np.tile(np.array([-2, 0, 1, 2, 3], dtype=np.int64), 26)[: small.size]
    got = shift_round(small, shifts, mode)
    ref = [_ref_shift(int(x), int(s), mode) for x, s in zip(small, shifts)]
    np.testing.assert_array_equal(got, ref)


def test_rounding_names():
    assert [m.value for m in Rounding] == ["floor", "half_up", "nearest_even"]
    assert shift_round(np.int64(-3), 1, "floor") == -2  # -1.5 -> -2
    assert shift_round(np.int64(-3), 1, "half_up") == -1  # -1.5 -> -1
    assert shift_round(np.int64(-3), 1, "nearest_even") == -2
    assert shift_round(np.int64(-5), 1, "nearest_even") == -2
    with pytest.raises(ValueError, match="unknown rounding"):
        shift_round(1, 1, "trunc")
    with pytest.raises(TypeError, match="integers"):
        shift_round(np.array([1.5]), 1, "floor")


# ----------------------------------------------------------------- quantize vs fxpmath
def _fxp_raw(x, fmt: Format, rounding: str, overflow: str) -> np.ndarray:
    q = Fxp(x, signed=fmt.signed, n_word=fmt.width, n_frac=fmt.frac_bits,
            rounding=FXP_ROUNDING[rounding], overflow=overflow)
    return np.asarray(q.val).astype(np.int64)


def _random_reals(fmt: Format, rng) -> np.ndarray:
    span = max(abs(fmt.min), fmt.max, fmt.lsb)
    x = rng.uniform(-2 * span, 2 * span, N)
    if not fmt.signed:
        x[: N // 4] = np.abs(x[: N // 4])
    # exact ties (k + 1/2) lsb, in and out of range
    k = rng.integers(-(1 << min(fmt.width, 50)), 1 << min(fmt.width, 50), N // 4)
    x[N // 2: N // 2 + N // 4] = (k + 0.5) * fmt.lsb
    x[-4:] = [fmt.max, fmt.min, fmt.max + fmt.lsb / 2, fmt.min - fmt.lsb / 2]
    return x


@needs_fxpmath
@pytest.mark.parametrize("fmt_s", FORMATS)
@pytest.mark.parametrize("rounding", ["floor", "half_up", "nearest_even"])
@pytest.mark.parametrize("overflow", ["saturate", "wrap"])
def test_quantize_matches_fxpmath(fmt_s, rounding, overflow):
    fmt = Format.parse(fmt_s)
    rng = np.random.default_rng(zlib.crc32(f"{fmt_s}{rounding}{overflow}".encode()))
    x = _random_reals(fmt, rng)
    c = SaturationCounter()
    got = quantize(x, fmt, rounding, overflow, c, "q")
    np.testing.assert_array_equal(got, _fxp_raw(x, fmt, rounding, overflow))
    assert fmt.contains(got)
    # every out-of-range element was counted, under the right key
    exact = _round_np(np.ldexp(x, fmt.frac_bits), rounding)
    n_out = int(np.count_nonzero((exact > fmt.raw_max) | (exact < fmt.raw_min)))
    assert n_out > 0
    if overflow == "saturate":
        assert c.as_dict() == {"saturations": {"q": n_out}, "wraps": {}}
    else:
        assert c.as_dict() == {"saturations": {}, "wraps": {"q": n_out}}


def _round_np(v, rounding):
    if rounding == "floor":
        return np.floor(v)
    if rounding == "nearest_even":
        return np.rint(v)
    return np.floor(v + 0.5)


@needs_fxpmath
def test_floor_is_not_fxpmath_default_trunc():
    fmt = Format.parse("s3.4")
    x = np.array([-0.01, -1.03, 1.03])
    ours = quantize(x, fmt, "floor", "saturate")
    fx_trunc = np.asarray(Fxp(x, True, fmt.width, fmt.frac_bits, rounding="trunc").val)
    assert list(ours) == [-1, -17, 16] and list(fx_trunc) == [0, -16, 16]


def test_quantize_special_values():
    f = Format.parse("s3.4")
    c = SaturationCounter()
    assert list(quantize([np.inf, -np.inf, 1e300], f, "half_up", "saturate", c, "x")) == [
        f.raw_max, f.raw_min, f.raw_max]
    assert c["x"] == 3 and c.total == 3
    with pytest.raises(ValueError, match="NaN"):
        quantize([np.nan], f, "floor", "saturate")
    with pytest.raises(ValueError, match="infinite"):
        quantize([np.inf], f, "floor", "wrap")
    with pytest.raises(ValueError, match="unknown overflow"):
        quantize([1.0], f, "floor", "clip")
    with pytest.raises(ValueError, match="name is required"):
        quantize([1.0], f, "floor", "saturate", SaturationCounter())
    # huge values wrap exactly like their exact integer would
    big = float(2**70 + 2**20 * 5)  # exactly representable
    assert int(quantize(big, Format.parse("u8.0"), "floor", "wrap")) == (2**70 + 2**20 * 5) % 256


# ----------------------------------------------------------------- requantize
@needs_fxpmath
@pytest.mark.parametrize("from_frac, fmt_s", [(30, "s3.16"), (20, "u0.18"), (5, "s7.10"),
                                              (12, "u5.0"), (0, "s0.15"), (16, "s3.16")])
@pytest.mark.parametrize("rounding", ["floor", "half_up", "nearest_even"])
@pytest.mark.parametrize("overflow", ["saturate", "wrap"])
def test_requantize_matches_fxpmath(from_frac, fmt_s, rounding, overflow):
    fmt = Format.parse(fmt_s)
    rng = np.random.default_rng(7)
    bits = min(52, fmt.int_bits + from_frac + 3)
    raw = rng.integers(-(1 << bits), 1 << bits, N, dtype=np.int64)
    raw[:8] = [0, 1, -1, (1 << bits) - 1, -(1 << bits), 2, -2, 3]
    d = from_frac - fmt.frac_bits
    if d >= 1:  # exact ties at the target lsb
        raw[8:5000] = (raw[8:5000] >> d << d) | (1 << (d - 1))
    c = SaturationCounter()
    got = requantize(raw, from_frac, fmt, rounding, overflow, c, "r")
    x = np.ldexp(raw.astype(np.float64), -from_frac)  # exact (|raw| < 2**53)
    np.testing.assert_array_equal(got, _fxp_raw(x, fmt, rounding, overflow))
    assert (c.total if overflow == "saturate" else c.total_wraps) > 0


def test_requantize_left_shift_never_overflows_int64():
    f = Format.parse("s10.40")  # 51 bits
    raw = np.array([1 << 40, -(1 << 40), 3, -3, (1 << 61) - 1, -(1 << 61)], dtype=np.int64)
    c = SaturationCounter()
    got = requantize(raw, 5, f, "floor", "saturate", c, "ls")
    ref = [max(f.raw_min, min(f.raw_max, int(r) << 35)) for r in raw]
    assert list(got) == ref and c["ls"] == 4
    got = requantize(raw, 5, f, "floor", "wrap", c, "ls")
    ref = [((int(r) << 35) - f.raw_min) % (1 << f.width) + f.raw_min for r in raw]
    assert list(got) == ref and c.wraps["ls"] == 4
    # shift beyond the width: everything wraps to 0
    assert list(requantize(np.array([5, -7]), 0, Format.parse("u0.30"), "floor", "wrap")) == [0, 0]


# ----------------------------------------------------------------- mul / add / sub
def _ref_mul(a, fa, b, fb, fo, rounding, overflow):
    out = []
    for x, y in zip(a.tolist(), b.tolist()):
        v = _ref_shift(x * y, fa.frac_bits + fb.frac_bits - fo.frac_bits, rounding)
        if overflow == "saturate":
            v = min(max(v, fo.raw_min), fo.raw_max)
        else:
            v = (v - fo.raw_min) % (1 << fo.width) + fo.raw_min
        out.append(v)
    return np.array(out, dtype=np.int64)


@pytest.mark.parametrize("fa_s, fb_s, fo_s", [("s3.14", "s3.14", "u7.16"), ("u3.15", "u4.14", "s2.15"),
                                              ("s30.0", "u32.0", "s20.10"), ("u31.0", "u32.0", "u62.0"),
                                              ("s0.30", "s0.31", "s0.40")])
@pytest.mark.parametrize("rounding", ["floor", "half_up", "nearest_even"])
@pytest.mark.parametrize("overflow", ["saturate", "wrap"])
def test_mul_exact(fa_s, fb_s, fo_s, rounding, overflow):
    fa, fb, fo = map(Format.parse, (fa_s, fb_s, fo_s))
    rng = np.random.default_rng(3)
    a = rng.integers(fa.raw_min, fa.raw_max, 2000, endpoint=True, dtype=np.int64)
    b = rng.integers(fb.raw_min, fb.raw_max, 2000, endpoint=True, dtype=np.int64)
    a[:4] = [fa.raw_min, fa.raw_max, fa.raw_min, fa.raw_max]
    b[:4] = [fb.raw_min, fb.raw_max, fb.raw_max, fb.raw_min]
    got = mul(a, fa, b, fb, fo, rounding, overflow)
    np.testing.assert_array_equal(got, _ref_mul(a, fa, b, fb, fo, rounding, overflow))


@needs_fxpmath
@pytest.mark.parametrize("rounding", ["floor", "half_up", "nearest_even"])
def test_mul_matches_fxpmath(rounding):
    fa, fb, fo = Format.parse("s3.14"), Format.parse("u4.14"), Format.parse("s4.13")
    rng = np.random.default_rng(5)
    a = rng.integers(fa.raw_min, fa.raw_max, N, endpoint=True, dtype=np.int64)
    b = rng.integers(fb.raw_min, fb.raw_max, N, endpoint=True, dtype=np.int64)
    for ov in ("saturate", "wrap"):
        got = mul(a, fa, b, fb, fo, rounding, ov)
        exact = to_float(a, fa) * to_float(b, fb)  # 37-bit product: exact in float64
        np.testing.assert_array_equal(got, _fxp_raw(exact, fo, rounding, ov))


def test_mul_refuses_products_wider_than_int64():
    a, b = Format.parse("s31.0"), Format.parse("u32.0")  # 32 + 32 = 64 bits
    with pytest.raises(ValueError, match=r"product dxd: s31.0 \(32 bits\) x u32.0 \(32 bits\) = 64"):
        mul(1, a, 1, b, Format.parse("s3.0"), "floor", "saturate", name="dxd")
    with pytest.raises(ValueError, match="operand a of product p out of range"):
        mul(1 << 20, Format.parse("s3.16"), 1, Format.parse("s3.16"), Format.parse("s3.16"),
            "floor", "saturate", name="p")


def test_add_sub():
    fa, fb, fo = Format.parse("s3.4"), Format.parse("u2.6"), Format.parse("s3.5")
    a = np.array([-128, 127, 5, -3], dtype=np.int64)
    b = np.array([255, 255, 1, 2], dtype=np.int64)
    for op, fn in ((add, lambda x, y: x + y), (sub, lambda x, y: x - y)):
        c = SaturationCounter()
        got = op(a, fa, b, fb, fo, "half_up", "saturate", c, "s")
        ref = [min(max(_ref_shift(fn(int(x) << 2, int(y)), 1, "half_up"), fo.raw_min), fo.raw_max)
               for x, y in zip(a, b)]
        assert list(got) == ref


def test_saturation_counter():
    c1, c2 = SaturationCounter(), SaturationCounter()
    f = Format.parse("u2.0")
    requantize(np.array([9, 1, 4, -1]), 0, f, "floor", "saturate", c1, "a")
    requantize(np.array([9]), 0, f, "floor", "wrap", c1, "a")
    requantize(np.array([9, 9]), 0, f, "floor", "saturate", c2, "b")
    requantize(np.array([0]), 0, f, "floor", "saturate", c2, "c")  # no event, no key
    assert c1["a"] == 3 and c1.total == 3 and c1.total_wraps == 1
    c1.merge(c2)
    d = c1.as_dict()
    assert d == {"saturations": {"a": 3, "b": 2}, "wraps": {"a": 1}}
    assert SaturationCounter.from_dict(json.loads(json.dumps(d))) == c1
    c1.reset()
    assert c1.total == 0 and c1.as_dict() == {"saturations": {}, "wraps": {}}


def test_to_float_and_scalars():
    f = Format.parse("s3.16")
    r = quantize(1.2345, f, "half_up", "saturate")
    assert r.shape == () and float(to_float(r, f)) == round(1.2345 * 65536) / 65536
    assert list(to_float(np.array([f.raw_min, f.raw_max]), f)) == [f.min, f.max]


# ----------------------------------------------------------------- FormatSet
@pytest.mark.parametrize("name", ["../out", "x\nmodule injected; endmodule", "a */ int x; /*", "", "n" * 65, "é",
                                  " lead", "trail "])
def test_a_name_that_could_leave_a_directory_or_a_comment_is_refused(name):
    """The name makes the synthesis bundle's directory and is written into the Verilog, the C header and the
    reports: a '/', a newline or '*/' would escape them."""
    with pytest.raises(ValueError, match=r"the format set's name .* must be 1 to 64 letters, digits, inner spaces"):
        FormatSet.from_dict({**FormatSet.preset("default").to_dict(), "name": name})
    for fine in ("base:default position=12 opt-03", "default, rsqrt u8.20, length_sq u7.28", "x", "n" * 64):
        assert FormatSet.preset("default").replace(name=fine).name == fine


@pytest.mark.parametrize("name", PRESETS)
def test_presets_load_and_roundtrip(name, tmp_path):
    fs = FormatSet.preset(name)
    assert fs.name == name and FormatSet.load(name) == fs
    assert set(FormatSet.presets()) >= {"default", "narrow", "wide"}
    p = tmp_path / "x.json"
    fs.save(p)
    assert FormatSet.load(p) == fs and FormatSet.load(str(p)) == fs
    assert FormatSet.from_dict(json.loads(fs.to_json())) == fs
    for p in fs.products():
        assert p.a.width + p.b.width <= 63 or not p.int64, p.name
    assert all(isinstance(getattr(fs, f), Format) for f in FORMAT_FIELDS)
    assert isinstance(fs.rounding, Rounding)


def test_a_format_file_missing_a_knob_or_giving_one_twice_is_named_in_one_line(tmp_path):
    """A missing knob was Python's "__init__() missing 1 required positional argument"; a key given twice was
    taken silently (the last value won). rounding and max_degree may be left out: they have defaults."""
    d = FormatSet.preset("default").to_dict()
    without = {k: v for k, v in d.items() if k not in ("lut_index_bits", "rsqrt_seed_bits")}
    with pytest.raises(ValueError, match=r"^FormatSet 'default': missing the knobs rsqrt_seed_bits, lut_index_bits$"):
        FormatSet.from_dict(without)
    optional = {k: v for k, v in d.items() if k not in ("rounding", "max_degree")}
    assert FormatSet.from_dict(optional) == FormatSet.preset("default").replace(name="default")
    path = tmp_path / "twice.json"
    path.write_text(json.dumps(d, indent=1).replace('"max_degree": 32', '"max_degree": 32, "max_degree": 33'))
    with pytest.raises(ValueError, match=r"^the key 'max_degree' is given twice$"):
        FormatSet.load(path)


def test_narrow_preset_respects_dsp_budget():
    """narrow: every node-datapath multiplier operand <= 18 bits except L = length_sq*r (rsqrt input)."""
    fs = FormatSet.preset("narrow")
    for p in fs.products():
        if p.unit == "node_update" and p.name != "length_sq*rsqrt (L)":
            assert max(p.a.width, p.b.width) <= 18, p
    d = FormatSet.preset("default")  # the controller's formats are not the datapath's cost
    assert all(getattr(fs, f).width <= getattr(d, f).width for f in FORMAT_FIELDS if f not in CONTROLLER_FIELDS)


def test_formatset_validation_messages():
    fs = FormatSet.preset("default")
    # 1/2 C * u (spring x spring): once unchecked, now the first product a wide spring fails
    with pytest.raises(ValueError, match=r"product spring\*spring \(1/2 C \* u\) needs 51 \+ 51 = 102"):
        fs.replace(spring="s30.20")
    with pytest.raises(ValueError, match=r"product delta\*delta -> length_sq needs 40 \+ 40 = 80"):
        fs.replace(delta="s20.19")
    with pytest.raises(ValueError, match="rest_length is non-negative and must be unsigned"):
        fs.replace(rest_length="s3.15")
    with pytest.raises(ValueError, match="delta must be a signed format"):
        fs.replace(delta="u3.14")
    with pytest.raises(ValueError, match=r"lut_index_bits 10 must be in 1..error.frac_bits \(9\)"):
        fs.replace(lut_index_bits=10, error="u0.9", reciprocal="u1.11")
    with pytest.raises(ValueError, match=r"error format u2.14 must be u0.F or u1.F"):
        fs.replace(error="u2.14")
    with pytest.raises(ValueError, match="unknown rounding"):
        fs.replace(rounding="trunc")
    with pytest.raises(ValueError, match="field velocity: cannot parse"):
        fs.replace(velocity="q3.14")
    with pytest.raises(ValueError, match="rsqrt_seed_bits 1 is outside its domain 2..16"):
        fs.replace(rsqrt_seed_bits=1)
    d = fs.to_dict()
    d["bogus"] = 1
    with pytest.raises(ValueError, match=r"unknown keys \['bogus'\]"):
        FormatSet.from_dict(d)
    d = fs.to_dict()
    del d["formats"]["dt"]
    with pytest.raises(ValueError, match=r"formats missing \['dt'\]"):
        FormatSet.from_dict(d)
    with pytest.raises(ValueError, match="unknown FormatSet preset 'nope'"):
        FormatSet.preset("nope")
    ok = fs.replace(delta="s3.15", name="study")
    assert ok.delta == Format(True, 3, 15) and ok != fs and ok.position == fs.position


def test_a_file_named_as_a_preset_must_hold_that_preset(tmp_path):
    """default.json copied and changed, its name kept: its runs, reports and study rows said 'default' (a study put
    base:default, failing, beside preset:default, meeting the target). A verbatim copy loads."""
    FormatSet.preset("default").save(tmp_path / "copy.json")
    assert FormatSet.load(tmp_path / "copy.json") == FormatSet.preset("default")
    FormatSet.preset("default").replace(velocity="s3.2").save(tmp_path / "changed.json")
    with pytest.raises(ValueError, match=r"^it is named 'default', a preset's name, but its formats are not that "
                                         r"preset's: give it a name of its own"):
        FormatSet.load(tmp_path / "changed.json")
    assert FormatSet.load(tmp_path / "copy.json").content() == FormatSet.preset("default").content()
