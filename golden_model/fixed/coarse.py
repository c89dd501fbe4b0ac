"""The coarse space of the guarded momentum step in integers (:mod:`golden_model.coarse` in float).

The host computes the run constants once, from the fixed-point start layout:

* ``Φ`` [basis]: each node's ``m`` monomials of its start coordinates ``u, v`` in ``[-1, 1]``
  (:func:`golden_model.coarse.basis_coordinates`), ``u`` and ``v`` rounded half up to ``s1.BASIS_FRAC_BITS``
  and each monomial formed from a lower one by one integer product, rounded half up (:func:`integer_basis`),
  so that a node's basis follows from its two coordinates;
* ``M = (ΦᵀKΦ)⁻¹`` of that rounded ``Φ``, as integers ``M_raw = round(M·2^e)`` with one exponent ``e`` for
  the matrix (a block exponent: ``max |M_raw|`` just below ``2^MATRIX_BITS``).

Each iteration, from the forces ``F`` [force_acc] of the last accepted layout:

1. ``g = ΦᵀF``: ``2m`` exact integer sums (``Φ_raw·F_raw``: ``BASIS_FRAC_BITS`` + force_acc's fraction
   bits), as the energy's and ``S``'s sums are exact;
2. ``c = M·g``, exact, rounded half up once to :func:`coefficient_format` [position], saturating;
3. each node's coarse move ``Φ_i·c``, exact, rounded (the format set's rounding) and saturated to [accel],
   and added to the Jacobi term ``F·w`` before the step scale (:func:`golden_model.fixed.guard.proposal`).

Every saturation is counted (``coarse_coefficient``, ``coarse_move``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..coarse import basis_coordinates, basis_exponents, coarse_inverse
from .format import Format, Overflow, SaturationCounter, quantize, requantize, shift_round
from .formats_set import FormatSet
from .pipeline import exact_sum

__all__ = ["BASIS_FRAC_BITS", "MATRIX_BITS", "BASIS", "coefficient_format", "CoarseConstants", "coarse_constants",
           "integer_basis", "coarse_accel", "coarse_formats_problem"]

SAT = Overflow.SATURATE
#: Fraction bits of the basis values ``Φ`` (s1.16: 18 bits, one DSP operand).
BASIS_FRAC_BITS = 16
BASIS = Format(True, 1, BASIS_FRAC_BITS)
#: Magnitude bits of ``M``'s largest entry (a signed 25-bit mantissa with the matrix's exponent).
MATRIX_BITS = 24


def coefficient_format(fs: FormatSet) -> Format:
    """The coarse coefficients ``c`` [length]: position's range and fraction bits (a move in the coarse space
    spans at most the layout)."""
    return fs.position


@dataclass(frozen=True, eq=False)
class CoarseConstants:
    """The host's run constants of the coarse space: ``phi`` ``(V, m)`` raw [basis], ``matrix`` ``(m, m)``
    Python ints ``M·2^exponent``."""

    phi: np.ndarray
    matrix: tuple[tuple[int, ...], ...]
    exponent: int


def coarse_constants(fs: FormatSet, raw_positions: np.ndarray, edges: np.ndarray, spring: float,
                     degree: int) -> CoarseConstants:
    """Round the start layout's basis to [basis] and ``M`` of the rounded basis to :data:`MATRIX_BITS` bits."""
    layout = raw_positions.astype(np.float64)  # (the basis does not depend on the layout's scale)
    phi = integer_basis(quantize(basis_coordinates(layout), BASIS, "half_up", SAT), degree)
    inverse = coarse_inverse(np.ldexp(phi.astype(np.float64), -BASIS_FRAC_BITS), edges, spring)
    exponent = MATRIX_BITS - math.frexp(float(np.abs(inverse).max()))[1]  # max |M|·2^e in [2^23, 2^24)
    matrix = tuple(tuple(int(v) for v in row) for row in np.rint(np.ldexp(inverse, exponent)).astype(np.int64))
    return CoarseConstants(phi, matrix, exponent)


def coarse_formats_problem(fs: FormatSet, degree: int) -> str | None:
    """Why the coarse move ``Φ_i·c`` of ``degree`` would not be exact in int64 with ``fs``, in one line (``None``:
    it is)."""
    m = len(basis_exponents(degree))
    width = BASIS.width + coefficient_format(fs).width - 1 + math.ceil(math.log2(m))
    if width <= 63:
        return None
    return (f"the coarse move's sum of {m} products of basis {BASIS} and position {coefficient_format(fs)} takes "
            f"{width} bits > 63 in format set '{fs.name}': use a smaller --coarse-degree or position format")


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


def _round_half_up(value: int, shift: int) -> int:
    """``value·2^-shift`` rounded half up (an exact left shift where ``shift ≤ 0``)."""
    return (value + (1 << (shift - 1))) >> shift if shift > 0 else value << -shift


def coarse_accel(fs: FormatSet, constants: CoarseConstants, force: np.ndarray,
                 counter: SaturationCounter | None = None) -> np.ndarray:
    """``(V, 2)`` each node's coarse move ``Φ_i·M·(ΦᵀF)`` [accel] for the forces ``F`` [force_acc]."""
    phi, coefficient = constants.phi, coefficient_format(fs)
    sums = [[exact_sum(phi[:, k] * force[:, d]) for d in range(2)] for k in range(phi.shape[1])]
    # c = M·g: g at BASIS_FRAC_BITS + force_acc's fraction bits, M at `exponent`
    shift = constants.exponent + BASIS_FRAC_BITS + fs.force_acc.frac_bits - coefficient.frac_bits
    exact = [_round_half_up(sum(m * g[d] for m, g in zip(row, sums)), shift)
             for row in constants.matrix for d in range(2)]
    if counter is not None:
        counter.add_saturations("coarse_coefficient",
                                sum(not coefficient.raw_min <= v <= coefficient.raw_max for v in exact))
    c = np.array([min(max(v, coefficient.raw_min), coefficient.raw_max) for v in exact],
                 dtype=np.int64).reshape(-1, 2)
    move = phi @ c  # exact in int64: coarse_formats_problem
    return requantize(move, BASIS_FRAC_BITS + coefficient.frac_bits, fs.accel, fs.rounding, SAT, counter,
                      "coarse_move")
