"""The coarse space of the guarded momentum step in integers (:mod:`golden_model.coarse` in float).

Sized for a datapath of 18 × 18 multipliers: every per-node product is of two 18-bit operands, and the
controller's ``M·g`` of two 25-bit ones. Values whose range changes over a run (the sums ``g``, the
coefficients ``c``) are held as mantissas with one exponent for the whole vector (block floating point),
chosen by their largest magnitude's leading one (``v``, or ``~v`` below 0, as the leading sign bits count it:
:func:`block_mantissas`); every shift by such an exponent rounds half up, and the move's
last rounding is the format set's.

The host computes the run constants once, from the fixed-point start layout:

* ``Φ`` [basis]: each node's ``m`` monomials of its start coordinates ``u, v`` in ``[-1, 1]``
  (:func:`golden_model.coarse.basis_coordinates`), ``u`` and ``v`` rounded to :data:`BASIS` and each monomial
  formed from a lower one by one product (:func:`integer_basis`), so that a node's basis follows from its two
  coordinates;
* ``M = (ΦᵀKΦ)⁺`` of that basis as integers ``M_raw = round(M·2^matrix_exponent)``, one exponent for the
  matrix, ``max |M_raw|`` in ``[2^(MATRIX_BITS − 1), 2^MATRIX_BITS)`` (a :data:`SUM_BITS`-bit signed value).

Each iteration, from the forces ``F`` [force_acc] of the last accepted layout (:func:`coarse_accel`):

1. ``F`` rounded to :data:`OPERAND_BITS` bits (:func:`narrow_force_format`; saturation counted as
   ``coarse_force``), and the ``2m`` sums ``g = ΦᵀF`` formed exactly;
2. ``g`` to mantissas of :data:`SUM_BITS` bits with one exponent (:func:`block_mantissas`), ``c = M·g`` formed
   exactly, and ``c`` to mantissas of :data:`OPERAND_BITS` bits with one exponent;
3. each node's coarse move ``Φ_i·c`` formed exactly, rounded (the format set's rounding) and saturated to
   [accel] (counted as ``coarse_move``), and added to ``F·w`` before the step scale
   (:func:`golden_model.fixed.guard.proposal`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..coarse import COARSE_DEGREE_MAX, basis_coordinates, basis_exponents, coarse_inverse
from .format import Format, Overflow, SaturationCounter, quantize, requantize, shift_round
from .formats_set import FormatSet
from .measures import FixedPointError

__all__ = ["OPERAND_BITS", "SUM_BITS", "MATRIX_BITS", "MATRIX_EXPONENT_BITS", "BASIS_FRAC_BITS", "BASIS", "CoarseConstants",
           "coarse_constants", "integer_basis", "narrow_force_format", "block_mantissas", "narrow_forces", "coarse_sums", "coefficients",
           "move_frac_base", "move_frac_bits", "MOVE_BITS", "move_shift_range", "move_shift", "node_moves",
           "coarse_accel", "MANTISSA_HEADROOM", "mantissa_magnitude_bits", "sum_bits"]

SAT = Overflow.SATURATE
#: Width of the per-node operands: the basis values, the narrowed forces and the coefficients' mantissas.
OPERAND_BITS = 18
#: Width of the sums' mantissas, ``g``, and of ``M``'s entries (the controller's operands).
SUM_BITS = 25
#: Magnitude bits of ``M``'s largest entry.
MATRIX_BITS = SUM_BITS - 1
#: Bits of ``M``'s exponent (signed): the engine's register for it.
MATRIX_EXPONENT_BITS = 8
#: Fraction bits of the basis values ``Φ`` (s1.16: values in [-1, 1], 1 exact).
BASIS_FRAC_BITS = OPERAND_BITS - 2
BASIS = Format(True, 1, BASIS_FRAC_BITS)
#: The bits a block mantissa leaves above its largest magnitude's leading one: its sign, and one for the
#: rounding up (:func:`block_mantissas`).
MANTISSA_HEADROOM = 2


@dataclass(frozen=True, eq=False)
class CoarseConstants:
    """The host's run constants of the coarse space: ``phi`` ``(V, m)`` raw [basis], ``matrix`` ``(m, m)``
    int64 ``M·2^matrix_exponent``."""

    phi: np.ndarray
    matrix: np.ndarray
    matrix_exponent: int


def integer_basis(uv: np.ndarray, degree: int) -> np.ndarray:
    """``(V, m)`` the monomials ``u^a·v^b`` [basis] of the raw coordinates ``uv`` ``(V, 2)`` [basis], in
    :func:`~golden_model.coarse.basis_exponents`' order: ``1``, then each from the one of a degree lower, times
    ``u`` where ``a > 0`` (else ``v``), rounded half up (|values| ≤ 1: no saturation)."""
    one = np.full(len(uv), 1 << BASIS_FRAC_BITS, dtype=np.int64)
    columns: dict[tuple[int, int], np.ndarray] = {(0, 0): one}
    for a, b in basis_exponents(degree)[1:]:
        lower, factor = ((a - 1, b), uv[:, 0]) if a else ((a, b - 1), uv[:, 1])
        columns[a, b] = shift_round(columns[lower] * factor, BASIS_FRAC_BITS, "half_up")
    return np.column_stack([columns[e] for e in basis_exponents(degree)])


def coarse_constants(raw_positions: np.ndarray, edges: np.ndarray, spring: float, degree: int) -> CoarseConstants:
    """The basis of the start layout ``raw_positions`` (any fixed-point scale: the basis is scaled to the layout's
    box) and ``M`` of that basis, rounded to :data:`MATRIX_BITS` bits with one exponent."""
    uv = quantize(basis_coordinates(raw_positions.astype(np.float64)), BASIS, "half_up", SAT)
    phi = integer_basis(uv, degree)
    inverse = coarse_inverse(np.ldexp(phi.astype(np.float64), -BASIS_FRAC_BITS), edges, spring)
    exponent = MATRIX_BITS - math.frexp(float(np.abs(inverse).max()))[1]
    if not -(1 << (MATRIX_EXPONENT_BITS - 1)) <= exponent < 1 << (MATRIX_EXPONENT_BITS - 1):
        raise FixedPointError(f"the coarse space's matrix (ΦᵀKΦ)⁻¹ has entries up to {float(np.abs(inverse).max()):.3g}: "
                              f"its exponent {exponent} does not fit {MATRIX_EXPONENT_BITS} bits; use another "
                              "--spring, or --coarse-degree 0")
    limit = (1 << MATRIX_BITS) - 1  # (rint may round the largest up to 2^MATRIX_BITS: held one below)
    matrix = np.clip(np.rint(np.ldexp(inverse, exponent)), -limit, limit).astype(np.int64)
    return CoarseConstants(phi, matrix, exponent)


def narrow_force_format(fs: FormatSet) -> Format:
    """The forces' format in the sums ``ΦᵀF``: :data:`OPERAND_BITS` bits with force_acc's integer bits (as many as
    fit), the rest fraction bits."""
    int_bits = min(fs.force_acc.int_bits, OPERAND_BITS - 1)
    return Format(True, int_bits, OPERAND_BITS - 1 - int_bits)


def mantissa_magnitude_bits(bits: int) -> int:
    """The magnitude bits a ``bits``-bit block mantissa keeps of the largest value (:data:`MANTISSA_HEADROOM`)."""
    return bits - MANTISSA_HEADROOM


def sum_bits(max_nodes: int) -> int:
    """Bits of an exact sum ``Σ Φ·F'`` over ``max_nodes`` nodes (signed): each product ``|Φ·F'| ≤ 2^16·2^17``, so
    the sum's magnitude is below ``2^(33 + bit_length(max_nodes))``."""
    return 2 * OPERAND_BITS - 2 + max_nodes.bit_length()


def block_mantissas(values: np.ndarray, bits: int) -> tuple[np.ndarray, int]:
    """``values`` (int64) as ``bits``-bit signed mantissas with one exponent ``e ≥ 0``: ``values ≈ m·2^e``, ``e`` the
    least that leaves the largest magnitude a bit below the mantissas' limit (so that rounding half up never
    overflows it). The magnitude is counted as two's complement's leading sign bits count it, ``v`` for ``v ≥ 0``
    and ``−v − 1`` (``~v``) below 0: hardware forms that with an XOR a bit, where ``|v|`` takes a carry chain.
    ``−2^k`` then counts as ``k`` bits, and its mantissa ``−2^(bits − MANTISSA_HEADROOM)`` at the most still
    fits."""
    largest = int(np.where(values < 0, ~values, values).max()) if values.size else 0
    exponent = max(0, largest.bit_length() - mantissa_magnitude_bits(bits))
    return shift_round(values, exponent, "half_up"), exponent


def narrow_forces(fs: FormatSet, force: np.ndarray, counter: SaturationCounter | None = None) -> np.ndarray:
    """``(V, 2)`` the forces [force_acc] rounded half up to :func:`narrow_force_format`, saturating
    (``coarse_force``)."""
    return requantize(force, fs.force_acc.frac_bits, narrow_force_format(fs), "half_up", SAT, counter, "coarse_force")


def coarse_sums(phi: np.ndarray, narrow: np.ndarray) -> np.ndarray:
    """``(m, 2)`` the exact sums ``Φᵀ·F`` of the basis [basis] and the narrowed forces (:func:`sum_bits`: int64 for
    fewer than ``2^29`` nodes)."""
    return phi.T @ narrow


def coefficients(constants: CoarseConstants, sums: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The coefficients ``c = M·g`` as :data:`OPERAND_BITS`-bit mantissas ``(m, 2)``, and the exponents of the sums'
    and the coefficients' mantissas: ``g`` to :data:`SUM_BITS` bits, ``M·g`` exact, then to :data:`OPERAND_BITS`."""
    g, sum_exponent = block_mantissas(sums, SUM_BITS)
    c, c_exponent = block_mantissas(constants.matrix @ g, OPERAND_BITS)  # |M·g| < 2^24·2^23·m
    return c, sum_exponent, c_exponent


def move_frac_base(fs: FormatSet) -> int:
    """The part of :func:`move_frac_bits` that the formats fix: the basis's fraction bits twice and the narrowed
    forces'."""
    return 2 * BASIS_FRAC_BITS + narrow_force_format(fs).frac_bits


def move_frac_bits(fs: FormatSet, constants: CoarseConstants, sum_exponent: int, c_exponent: int) -> int:
    """The fraction bits of the node products ``Φ_i·c``: :func:`move_frac_base` and ``M``'s exponent, less the two
    block exponents."""
    return move_frac_base(fs) + constants.matrix_exponent - sum_exponent - c_exponent


#: Bits of a node's exact ``Φ_i·c`` (signed): ``|Φ|, |c| ≤ 2^16``, at most 15 products.
MOVE_BITS = 2 * (OPERAND_BITS - 2) + math.ceil(math.log2(len(basis_exponents(COARSE_DEGREE_MAX)))) + 1


def move_shift_range(fs: FormatSet) -> tuple[int, int]:
    """The range :func:`move_shift` clamps to, ``(−accel.width, MOVE_BITS + 1)``: beyond the right end every value
    rounds to 0, beyond the left end every value but 0 saturates (the hardware's shifter spans the range)."""
    return -fs.accel.width, MOVE_BITS + 1


def move_shift(fs: FormatSet, frac_bits: int) -> int:
    """The right shift (negative: left) from ``Φ_i·c`` at ``frac_bits`` to [accel], clamped to
    :func:`move_shift_range`, where the result no longer changes."""
    low, high = move_shift_range(fs)
    return min(max(frac_bits - fs.accel.frac_bits, low), high)


def node_moves(fs: FormatSet, phi: np.ndarray, c: np.ndarray, frac_bits: int,
               counter: SaturationCounter | None = None) -> np.ndarray:
    """``(V, 2)`` each node's ``Φ_i·c``, exact (:data:`MOVE_BITS`), rounded (the format set's rounding) by
    :func:`move_shift` and saturated to [accel] (``coarse_move``)."""
    shift = move_shift(fs, frac_bits)
    return requantize(phi @ c, fs.accel.frac_bits + shift, fs.accel, fs.rounding, SAT, counter, "coarse_move")


def coarse_accel(fs: FormatSet, constants: CoarseConstants, force: np.ndarray,
                 counter: SaturationCounter | None = None) -> np.ndarray:
    """``(V, 2)`` each node's coarse move ``Φ_i·M·(ΦᵀF)`` [accel] for the forces ``F`` [force_acc]."""
    sums = coarse_sums(constants.phi, narrow_forces(fs, force, counter))
    c, sum_exponent, c_exponent = coefficients(constants, sums)
    return node_moves(fs, constants.phi, c, move_frac_bits(fs, constants, sum_exponent, c_exponent), counter)
