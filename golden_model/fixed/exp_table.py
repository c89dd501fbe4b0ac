"""The step generator's exp lookup table: its correctly rounded entries and the width of their differences.

``T[k] = round_half_up(0.1*exp(-5(1 - k/2**n)) * 2**F)``, ``k = 0 .. 2**n`` (see
:mod:`golden_model.fixed.steplut`, which looks it up).  Apart from the step generator so that
:class:`~golden_model.fixed.FormatSet` can size the interpolation product (:func:`lut_slope_bits`)
without importing the generator, which takes a FormatSet.
"""

from __future__ import annotations

from decimal import Decimal, localcontext
from functools import lru_cache

import numpy as np

from ..reference import STEP_RATE as LUT_RATE, STEP_SCALE as LUT_SCALE
from .format import Format

__all__ = ["exp_table", "lut_slope_bits"]

_DEC_PREC = 60  # decimal digits used to evaluate the exact table entries
_TIE_MARGIN = Decimal(10) ** -40  # relative distance from a rounding tie that is decided safely


@lru_cache(maxsize=64)
def _exp_table_cached(index_bits: int, frac_bits: int) -> tuple[int, ...]:
    # Exact value x_k = 0.1 * exp(-5 (2**n - k) / 2**n) * 2**F.  The exponent is an exact
    # decimal; Decimal.exp is correctly rounded to 60 digits, so x_k is known to a
    # relative 1e-58.  Rounding half up is decided exactly unless x_k lies within a relative
    # 1e-40 of a tie, which is refused (it cannot happen: for k < 2**n x_k is transcendental
    # (Lindemann), for k = 2**n it is 2**F / 10, never an odd multiple of 1/2).
    n1 = 1 << index_bits
    out = []
    with localcontext() as ctx:
        ctx.prec = _DEC_PREC
        scale = Decimal(repr(LUT_SCALE))  # the decimal 0.1, exactly
        two_f = Decimal(1 << frac_bits)
        for k in range(n1 + 1):
            x = (Decimal(-LUT_RATE * (n1 - k)) / Decimal(n1)).exp() * scale * two_f
            fl = int(x.to_integral_value(rounding="ROUND_FLOOR"))
            frac = x - fl
            if abs(frac - Decimal("0.5")) <= _TIE_MARGIN * x:
                raise ArithmeticError(f"exp table entry {k} too close to a rounding tie")
            out.append(fl + (frac > Decimal("0.5")))
    return tuple(out)


def exp_table(index_bits: int, entry_fmt: Format) -> np.ndarray:
    """Raw table ``T[k] = round_half_up(0.1*exp(-5(1 - k/2**n)) * 2**F)``, ``k = 0..2**n``.

    ``2**index_bits + 1`` entries in ``entry_fmt`` (correctly rounded; see module doc).
    """
    if not 1 <= index_bits <= 20:
        raise ValueError(f"index_bits must be in 1..20, got {index_bits}")
    # Entries are <= 0.1 < 0.5 <= entry_fmt.max for any format: they always fit.
    return np.array(_exp_table_cached(int(index_bits), entry_fmt.frac_bits), dtype=np.int64)


def lut_slope_bits(index_bits: int, entry_fmt: Format) -> int:
    """Bits of the largest entry difference ``T[k+1] - T[k]`` (>= 0: the table is non-decreasing).

    The interpolation multiplies a difference by the low bits of E; the step generator's ROM
    stores the differences in this many bits.
    """
    table = exp_table(index_bits, entry_fmt)
    return max(1, int(np.diff(table).max()).bit_length())
