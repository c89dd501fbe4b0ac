"""The controller's exact arithmetic: the error measures, the energy, the power sum and the momentum registers.

Integers throughout (raw values in the formats named in brackets, e.g. [error]); every
saturation is counted by name in the :class:`~golden_model.fixed.format.SaturationCounter`
given.  The controller (:mod:`.controller`) and the host side (:mod:`.engine`) both use them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import ParameterError
from .format import MAX_WIDTH, Format, Overflow, Rounding, SaturationCounter, requantize
from .formats_set import FormatSet
from .pipeline import exact_sum

__all__ = ["FixedPointError", "Reciprocal", "SAT", "momentum_beta_raw", "MomentumState", "energy_frac_bits",
           "energy_raw", "power_sum", "area_sum", "area_error", "length_sum", "shape_error", "ERROR_MEASURE_EVENTS"]

SAT = Overflow.SATURATE
#: The saturation sources of the error measures E_S and E_C themselves (:func:`area_error`, :func:`shape_error`):
#: ``error``'s range ends below 1, so a layout of E 1 or more is held at its top.
ERROR_MEASURE_EVENTS = ("area_error", "shape_error")


class FixedPointError(ParameterError):
    """A mesh or parameter set the formats cannot hold; one line for the user."""


@dataclass(frozen=True)
class Reciprocal:
    """``1/total`` as an integer mantissa and a shift: ``x/total ≈ x·mantissa·2^-shift``.

    Used by the controller to normalise an error sum into ``fs.error`` with one
    multiply and one rounding shift; the mantissa has ``fs.reciprocal``'s width
    (``u1.F``: in [1, 2)).
    """

    mantissa: int
    shift: int

    @classmethod
    def of(cls, total_raw: int, mantissa_bits: int) -> "Reciprocal":
        """``round_half_up(2**shift / total_raw)`` with exactly ``mantissa_bits`` bits."""
        if total_raw <= 0:
            raise FixedPointError("cannot normalise by a zero total")
        shift = mantissa_bits + total_raw.bit_length() - 1
        mantissa = ((1 << (shift + 1)) // total_raw + 1) >> 1
        if mantissa == 1 << mantissa_bits:  # total a power of two, or rounding carried
            mantissa, shift = mantissa >> 1, shift - 1
        return cls(mantissa, shift)

    def normalise(self, sum_raw: int, fmt: Format, rounding: Rounding, counter: SaturationCounter | None = None,
                  name: str | None = None) -> int:
        """``sum/total`` raw in ``fmt`` (``sum >= 0`` at the fraction bits ``total`` had).

        The product ``sum·mantissa`` is exact (a Python int: ``error_acc`` times ``reciprocal``
        is 64 bits in the default set, too wide for int64). The rounding reads only the
        bits from the result's half-lsb up and whether any bit below is set, so those are
        kept (the lowest as a sticky bit) and rounded by :func:`requantize` as everywhere
        else; a value past ``fmt``'s range saturates the same at any size, counted under
        ``name`` (an error measure of 1 or more in ``error`` = u0.F: E_S of a layout whose
        area is off by its whole area).
        """
        drop = self.shift - fmt.frac_bits  # >= 2: reciprocal has more fraction bits than fmt
        product = int(sum_raw) * self.mantissa
        kept = (product >> (drop - 2)) | int(product & ((1 << (drop - 2)) - 1) != 0)
        kept = min(kept, (fmt.raw_max + 1) << 2)
        return int(requantize(np.int64(kept), fmt.frac_bits + 2, fmt, rounding, SAT, counter, name))


def momentum_beta_raw(k: int, fs: FormatSet) -> int:
    """``β_k = k/(k+3)`` in [dt], rounded half up: the controller's one division per iteration."""
    return min((((k << fs.dt.frac_bits) << 1) // (k + 3) + 1) >> 1, fs.dt.raw_max)


@dataclass(frozen=True)
class MomentumState:
    """The controller's momentum registers: iterations since the last restart, and a pending restart."""

    k: int = 0
    restart: bool = False

    def next(self, power: int, fs: FormatSet) -> tuple[int, "MomentumState"]:
        """``(β [dt], next state)`` for the coming update pass, given ``S`` of its force pass.

        A pending restart zeroes the momentum (``β = 0``, i.e. ``V := 0``) and voids this
        pass's ``S``; otherwise ``S < 0`` schedules a restart for the next iteration.
        """
        if self.restart:
            return momentum_beta_raw(0, fs), MomentumState(1, False)
        return momentum_beta_raw(self.k, fs), MomentumState(self.k + 1, power < 0)


def energy_frac_bits(fs: FormatSet) -> int:
    """Fraction bits of :func:`energy_raw`: the finer of its spring part's (``½C·e²``) and barrier part's."""
    return max(fs.spring.frac_bits + 2 * fs.rest_length.frac_bits, fs.barrier_coeff.frac_bits + fs.area.frac_bits)


def energy_raw(fs: FormatSet, half_spring: int, square_sum: int, barrier_sum: int) -> int:
    """Three times the energy of a layout, exact, at :func:`energy_frac_bits` fraction bits (scaled units).

    ``half_spring`` is ``½C`` raw [spring]; ``square_sum`` is ``Σe²`` over the entries at twice
    rest_length's fraction bits and ``barrier_sum`` is ``Σc·h`` at barrier_coeff's plus area's
    (a pass's ``NodeTerms.error_square_sum`` and ``barrier_energy_sum``). Springs: ``½C·Σe²`` over
    the entries (each edge twice, as the float reference's ``Σ_edges C·(L − d)²``). Barrier: each
    triangle's ``½μC·X*·(κ − X/X*)²₊`` is ``2·c·h`` of each of its three entries. Three times the
    sum keeps both parts integers; the stopping rule only compares ratios.
    """
    springs_shift, barrier_shift = energy_shifts(fs)
    return ((3 * half_spring * int(square_sum)) << springs_shift) + ((2 * int(barrier_sum)) << barrier_shift)


def energy_shifts(fs: FormatSet) -> tuple[int, int]:
    """The left shifts that bring ``3·½C·Σe²`` (at spring's plus twice rest_length's fraction bits) and
    ``2·Σc·h`` (at barrier_coeff's plus area's) to :func:`energy_frac_bits` (:func:`energy_raw`)."""
    frac = energy_frac_bits(fs)
    return frac - fs.spring.frac_bits - 2 * fs.rest_length.frac_bits, frac - fs.barrier_coeff.frac_bits - fs.area.frac_bits


def power_sum(fs: FormatSet, power: np.ndarray, counter: SaturationCounter | None = None) -> int:
    """``S = Σ F·V`` [power_acc]: the controller's exact sum, saturated once."""
    return int(requantize(_int64_clamped(exact_sum(power)), fs.power.frac_bits, fs.power_acc, fs.rounding, SAT,
                          counter, "power_acc"))


def _int64_clamped(total: int) -> np.int64:
    """An exact sum as int64 for :func:`requantize`: one past the widest format's range at most (a sum
    beyond it saturates the same, counted once); every format is at most ``MAX_WIDTH`` bits."""
    limit = 1 << MAX_WIDTH
    return np.int64(max(-limit, min(limit, total)))


def _doubled_areas(fs: FormatSet, positions: np.ndarray, faces: np.ndarray,
                   counter: SaturationCounter | None = None) -> np.ndarray:
    """Twice the signed areas at twice ``face_edge``'s fraction bits.

    The edges ``P_b − P_a``, ``P_c − P_a`` are narrowed to ``face_edge`` (saturating, counted
    as ``face_edge``), so the cross product fits int64 (checked by :class:`FormatSet`); with
    position's fraction bits it is exact for every triangle whose edges are in range.
    """
    def edges(coord: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b, c = (np.take(coord, k) for k in faces.T)
        return tuple(requantize(d, fs.position.frac_bits, fs.face_edge, fs.rounding, SAT, counter, "face_edge")
                     for d in (b - a, c - a))

    (ux, vx), (uy, vy) = edges(positions[:, 0]), edges(positions[:, 1])
    return ux * vy - uy * vx


def area_sum(fs: FormatSet, faces: np.ndarray, face_areas: np.ndarray, positions: np.ndarray,
             counter: SaturationCounter | None = None) -> int:
    """``Σ|A − |A'||`` raw [error_acc], before normalising: the area pass's sum.

    ``faces`` (F, 3) corner indices into ``positions`` (V, 2) raw [position]; ``face_areas``
    (F,) the host's areas ``A`` raw [face_area]. The layout's ``|A'|`` are rounded to
    [face_area]; saturations count as ``face_edge``, ``face_area`` and ``area_sum``.
    """
    doubled = np.abs(_doubled_areas(fs, positions, faces, counter))
    area = requantize(doubled, 2 * fs.face_edge.frac_bits + 1, fs.face_area, fs.rounding, SAT, counter, "face_area")
    total = requantize(np.abs(face_areas - area).sum(), fs.face_area.frac_bits, fs.error_acc, fs.rounding, SAT,
                       counter, "area_sum")
    return int(total)


def area_error(fs: FormatSet, reciprocal: Reciprocal, faces: np.ndarray, face_areas: np.ndarray,
               positions: np.ndarray, counter: SaturationCounter | None = None) -> int:
    """``E_S`` raw [error]: :func:`area_sum` times ``reciprocal`` (1/ΣA); saturating at ``error``'s
    maximum counts as ``area_error``."""
    return reciprocal.normalise(area_sum(fs, faces, face_areas, positions, counter), fs.error, fs.rounding,
                                counter, ERROR_MEASURE_EVENTS[0])


def length_sum(fs: FormatSet, error_sums: np.ndarray, counter: SaturationCounter | None = None) -> int:
    """``Σ|L − d|`` raw [error_acc] over the nodes' partial sums ``error_sums`` (V,) [error_acc],
    saturated once (counted as ``length_sum``)."""
    return int(requantize(_int64_clamped(exact_sum(error_sums)), fs.error_acc.frac_bits, fs.error_acc, fs.rounding,
                          SAT, counter, "length_sum"))


def shape_error(fs: FormatSet, reciprocal: Reciprocal, error_sums: np.ndarray,
                counter: SaturationCounter | None = None) -> int:
    """``E_C`` raw [error]: :func:`length_sum` times ``reciprocal`` (1/(2Σd)); saturating at ``error``'s
    maximum counts as ``shape_error``."""
    return reciprocal.normalise(length_sum(fs, error_sums, counter), fs.error, fs.rounding, counter,
                                ERROR_MEASURE_EVENTS[1])
