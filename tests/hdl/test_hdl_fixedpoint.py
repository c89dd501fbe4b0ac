"""RTL fixed-point helpers (hdl.fixedpoint, hdl.pipeline) against the golden model's primitives, exhaustively.

``clamp`` decides overflow from the high bits (LUT trees, no comparison chain);
``aligned_add`` adds only the overlapping bits. Both are checked on every input of small
shapes in Amaranth's simulator against ``golden_model.fixed`` arithmetic.
"""

import itertools

import numpy as np
import pytest
from amaranth.hdl import Module, Signal, signed, unsigned
from amaranth.sim import Simulator

from golden_model.fixed import Format, Overflow, Rounding, requantize as gm_requantize, shift_round as gm_shift_round
from hdl.fixedpoint import clamp, requantize, round_half_bit, variable_shift
from hdl.pipeline import aligned_add


def _values(shape):
    lo, hi = (-(1 << (shape.width - 1)), 1 << (shape.width - 1)) if shape.signed else (0, 1 << shape.width)
    return range(lo, hi)


def _run_comb(inputs, outputs, cases):
    """Drive every case of ``inputs`` and sample ``outputs``; returns a list of tuples."""
    m = Module()
    for out, expr in outputs:
        m.d.comb += out.eq(expr)
    got = []

    async def bench(ctx):
        for case in cases:
            for sig, v in zip(inputs, case):
                ctx.set(sig, v)
            got.append(tuple(ctx.get(out) for out, _ in outputs))

    sim = Simulator(m)
    sim.add_testbench(bench)
    sim.run()
    return got


FORMATS = [Format(True, 2, 1), Format(False, 3, 1), Format(True, 0, 3), Format(False, 0, 2), Format(True, 5, 0)]
SHAPES = [signed(7), unsigned(7), signed(3), unsigned(2), signed(4)]


@pytest.mark.parametrize("fmt, shape", list(itertools.product(FORMATS, SHAPES)), ids=str)
def test_clamp_matches_the_golden_saturation_on_every_input(fmt, shape):
    x = Signal(shape)
    out = Signal(signed(fmt.width) if fmt.signed else unsigned(fmt.width))
    flag = Signal()
    result, overflow = clamp(x, fmt)
    values = list(_values(shape))
    got = _run_comb([x], [(out, result), (flag, overflow)], [(v,) for v in values])
    want = gm_requantize(np.array(values, dtype=np.int64), fmt.frac_bits, fmt, Rounding.FLOOR, Overflow.SATURATE)
    assert [g[0] for g in got] == [int(w) for w in want]
    assert [g[1] for g in got] == [int(v < fmt.raw_min or v > fmt.raw_max) for v in values]


@pytest.mark.parametrize("rounding", list(Rounding))
def test_requantize_matches_the_golden_model_on_every_input(rounding):
    fmt = Format(True, 1, 1)
    x = Signal(signed(7))
    out = Signal(signed(fmt.width))
    values = list(_values(x.shape()))
    got = _run_comb([x], [(out, requantize(x, 3, fmt, rounding)[0])], [(v,) for v in values])
    want = gm_requantize(np.array(values, dtype=np.int64), 3, fmt, rounding, Overflow.SATURATE)
    assert [g[0] for g in got] == [int(w) for w in want]


@pytest.mark.parametrize("a_shape, b_shape, a_shift, b_shift",
                         [(signed(5), signed(4), 0, 2), (unsigned(4), signed(5), 3, 0), (unsigned(5), unsigned(3), 1, 1),
                          (signed(4), unsigned(4), 4, 1)], ids=str)
def test_aligned_add_is_exact_on_every_input(a_shape, b_shape, a_shift, b_shift):
    a, b = Signal(a_shape), Signal(b_shape)
    value, shift = aligned_add(a, a_shift, b, b_shift)
    out = Signal(signed(len(value) + 1))
    cases = list(itertools.product(_values(a_shape), _values(b_shape)))
    got = _run_comb([a, b], [(out, value)], cases)
    assert shift == min(a_shift, b_shift)
    assert [g[0] << shift for g in got] == [(x << a_shift) + (y << b_shift) for x, y in cases]


@pytest.mark.parametrize("rounding", list(Rounding))
@pytest.mark.parametrize("shape", [signed(6), unsigned(5)], ids=str)
def test_variable_shift_rounds_as_the_golden_shift_round_on_every_input(rounding, shape):
    """``round_half_bit(*variable_shift(x, s))`` is ``shift_round(x, s)`` for every ``x`` and every
    ``s`` from 0 (exact) past the value's width."""
    x, s = Signal(shape), Signal(range(shape.width + 3))
    out = Signal(signed(shape.width + 2))
    cases = list(itertools.product(_values(shape), range(shape.width + 3)))
    t, sticky = variable_shift(x, s, rounding)
    got = _run_comb([x, s], [(out, round_half_bit(t, rounding, sticky))], cases)
    want = [int(gm_shift_round(np.int64(v), k, rounding)) for v, k in cases]
    assert [g[0] for g in got] == want
