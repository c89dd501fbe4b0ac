"""Fixed-point helpers for the RTL: rounding and saturation exactly as :mod:`golden_model.fixed.format`.

``requantize(value, from_frac, fmt, rounding)`` is the hardware twin of the
golden model's ``requantize(raw, from_frac, fmt, rounding, "saturate")``: the
rounding shift :func:`shift_round`, then a clamp into ``fmt``.
"""

from amaranth.hdl import Cat, Const, Mux, Value, signed, unsigned

from golden_model.fixed import Format, Rounding
from golden_model.fixed.formats_set import FormatSetNotBuildable
from golden_model.fixed.dsp import DSP_WIDTH, Operand, dsp_partial_products

__all__ = ["FormatSetNotBuildable", "shape_of", "round_half_bit", "shift_round", "variable_shift", "saturate", "clamp",
           "requantize", "dsp_operands", "sum_round"]


def round_half_bit(t, rounding, sticky=Const(0)):
    """Drop bit 0 of ``t``, which holds the half-lsb, rounding with ``rounding``.

    ``sticky`` is 1 if any bit below the half-lsb was set (only nearest_even needs it). This
    is the golden model's ``t = raw >> (s-1); out = (t >> 1) + (t & 1)``:

    * floor: ``t >> 1``;
    * half_up: ``(t + 1) >> 1`` (one carry-in);
    * nearest_even: as half_up, and on an exact tie (``t[0] & ~sticky``) the lsb is cleared.
    """
    rounding = Rounding(rounding)
    t = Value.cast(t)
    if rounding is Rounding.FLOOR:
        return t.shift_right(1)
    rounded = (t + 1).shift_right(1)
    if rounding is Rounding.HALF_UP:
        return rounded
    tie = t[0] & ~sticky
    result = Cat(rounded[0] & ~tie, rounded[1:])
    return result.as_signed() if rounded.shape().signed else result


def shift_round(value, shift, rounding):
    """``value * 2**-shift`` rounded as :func:`golden_model.fixed.shift_round` does.

    ``shift`` is a constant; ``shift <= 0`` is an exact left shift. The result is wide enough
    for the exact value (the caller truncates only where the golden model's ranges allow it) and no
    wider: the shifts are ``shift_right`` (Amaranth's ``>>`` keeps the operand's width, so the
    rounding's carry chain and a saturation's range test behind it spanned copies of the sign).
    """
    rounding = Rounding(rounding)
    value = Value.cast(value)
    if shift <= 0:
        return value.shift_left(-shift)
    if rounding is Rounding.FLOOR:
        return value.shift_right(shift)
    sticky = value[:shift - 1].any() if shift > 1 else Const(0)
    return round_half_bit(value.shift_right(shift - 1), rounding, sticky)


def variable_shift(value, shift, rounding):
    """``(t, sticky)`` for a variable ``shift`` (an unsigned value, 0 allowed): ``t = (2·value) >> shift``
    (arithmetic), whose bit 0 is the half-lsb, and ``sticky``, any bit below it (only nearest_even
    reads it; ``Const(0)`` otherwise). :func:`round_half_bit` of the pair is :func:`shift_round`
    of ``value`` by ``shift`` (``shift = 0``: ``t = 2·value`` has no half bit, so it rounds back
    to ``value`` exactly). Two halves so that the shifter and the rounding's carry chain can sit
    in stages of their own.
    """
    rounding = Rounding(rounding)
    value, shift = Value.cast(value), Value.cast(shift)
    doubled = value.shift_left(1)
    t = doubled >> shift
    if rounding is not Rounding.NEAREST_EVEN:
        return t, Const(0)
    below = Cat(*(shift > i for i in range(len(doubled))))  # the bits shifted out past the half-lsb
    return t, (doubled.as_unsigned() & below).any()


def saturate(value, fmt):
    """``(clamped, overflow)``: non-negative ``value`` clamped to unsigned ``fmt``'s ``raw_max``."""
    if fmt.signed:
        raise ValueError(f"saturate() supports unsigned formats only, not {fmt}")
    return clamp(value, fmt)


def shape_of(fmt: Format):
    """The Amaranth shape holding raw values of ``fmt``."""
    return signed(fmt.width) if fmt.signed else unsigned(fmt.width)


def _out_of_range(value, fmt: Format):
    """``(over, under)`` of ``value`` against ``fmt``'s raw range, from the high bits alone.

    A format's range is the whole two's-complement (or unsigned) range of its width, so a
    value fits exactly when its bits above the format's sign position are copies of the sign
    (all zero if unsigned): OR/AND trees of LUTs, not a comparison carry chain.
    """
    value = Value.cast(value)
    width, w = len(value), fmt.width
    negative = value[-1] if value.shape().signed else Const(0)
    # magnitude bits that must be clear (non-negative) or set (negative) to fit
    lo = w - 1 if fmt.signed else w
    hi = width - 1 if value.shape().signed else width
    high = value[lo:hi] if hi > lo else None
    over = (~negative & high.any()) if high is not None else Const(0)
    if fmt.signed:
        under = (negative & ~high.all()) if high is not None else Const(0)
    else:
        under = negative
    return over, under


def clamp(value, fmt: Format):
    """``(clamped, overflow)``: ``value`` saturated into ``fmt``'s raw range."""
    assert fmt.raw_max == (1 << (fmt.width - fmt.signed)) - 1 and fmt.raw_min == (-(1 << (fmt.width - 1)) if fmt.signed else 0)
    value = Value.cast(value)
    over, under = _out_of_range(value, fmt)
    result = Mux(over, fmt.raw_max, Mux(under, fmt.raw_min, value))[:fmt.width]
    if fmt.signed:
        result = result.as_signed()
    return result, over | under


def requantize(value, from_frac: int, fmt: Format, rounding: Rounding):
    """``(result, overflow)``: ``value`` with ``from_frac`` fraction bits, rounded to ``fmt`` and saturated."""
    return clamp(shift_round(value, from_frac - fmt.frac_bits, rounding), fmt)


def dsp_operands(a, b, width=DSP_WIDTH):
    """``[(a_chunk, b_chunk, shift)]`` with ``a * b == sum((a_chunk * b_chunk) << shift)``.

    Each chunk pair is one 18×18 multiplier (:func:`hdl.dsp.registered_product`), sliced by the
    golden model's rule (:func:`golden_model.fixed.dsp.dsp_partial_products`, which the study's
    DSP cost counts with). Splitting a wide multiply by hand lets every partial product sit alone
    between registers.
    """
    a, b = Value.cast(a), Value.cast(b)

    def part(value, chunk):
        bits = value[chunk.lo:chunk.hi]
        return bits.as_signed() if chunk.signed else bits

    return [(part(a, ca), part(b, cb), ca.lo + cb.lo)
            for ca, cb in dsp_partial_products(Operand(len(a), a.shape().signed),
                                               Operand(len(b), b.shape().signed), width)]


def sum_round(add, shift, rounding, sub=(), const=0):
    """``round((const + sum(add) - sum(sub)) * 2**-shift)`` as :func:`shift_round` rounds it.

    For floor and half up the rounding is folded into the sum (half up adds ``2**(shift-1)``
    before the shift): ``K - x`` rounded is one subtraction from a constant, not two carry
    chains in series. Nearest-even rounds the exact sum with
    :func:`shift_round`. ``shift >= 1``.
    """
    rounding = Rounding(rounding)
    assert shift >= 1
    total = Const(const) if const else None
    if rounding is not Rounding.NEAREST_EVEN and rounding is not Rounding.FLOOR:
        total = Const(const + (1 << (shift - 1)))
    for term in add:
        total = Value.cast(term) if total is None else total + term
    for term in sub:
        total = -Value.cast(term) if total is None else total - term
    if rounding is Rounding.NEAREST_EVEN:
        return shift_round(total, shift, rounding)
    return total.shift_right(shift)
