"""Bit-accurate model of the variable step-size generator (exp lookup table).

Algorithm (float): ``dt = 0.01 + 0.1*exp(-5(1 - E_S)) + 0.1*exp(-5(1 - E_C))`` with
the error measures ``E_S, E_C`` clamped to [0, 1]: the float reference's
:func:`~golden_model.reference.variable_step` (the one place the formula and its
constants are written; :func:`step_size_float` is that function).

Fixed point (all formats from a FormatSet ``fs``):

* Table: ``T[k] = round_half_up(f(k / 2**n) * 2**F_L)``, ``k = 0 .. 2**n`` (``2**n + 1``
  entries: the extra endpoint serves interpolation up to E = 1), where
  ``f(E) = 0.1*exp(-5(1-E))`` (**the factor 0.1 is folded into the entries**),
  ``n = fs.lut_index_bits`` and ``F_L = fs.lut_entry.frac_bits``.
* E is raw in ``fs.error`` (``u0.F`` or ``u1.F``).  With ``u0.F`` the value 1.0 is
  not representable: the producer of E saturates it to ``1 - 2**-F`` (a dt deficit
  of at most ``0.5 * 2**-F`` per term, the slope of f at 1 being 0.5).  With ``u1.F``
  inputs above 1.0 are clamped to exactly 1.0 here (counted as ``"lut_input"``).
* Lookup, ``r = F - n`` low bits of E below the index:
  interpolating: ``k = E >> r``, ``t = E mod 2**r``,
  ``v = T[k] + round((T[k'] - T[k]) * t / 2**r)`` with ``k' = min(k+1, 2**n)``
  (the difference is >= 0: the table is non-decreasing; product width
  ``lut_entry.width + r`` is checked by the FormatSet);
  not interpolating: ``v = T[round(E / 2**r)]`` (nearest entry; the entry below
  if ``fs.rounding`` is floor).  ``round`` is ``fs.rounding``.
* ``dt = C + requantize(v_S + v_C, F_L -> fs.dt)``, ``C = round_half_up(0.01)`` in
  ``fs.dt``; saturates into ``fs.dt`` (counted as ``"dt"``).  When
  ``F_L == fs.dt.frac_bits`` the requantisation is exact, so
  ``dt(E_S, E_C) = C + v(E_S) + v(E_C)`` is exactly separable.
* ``half_dt_sq = round(dt * dt / 2)`` into ``fs.half_dt_sq`` (``fs.rounding``,
  saturating, counted as ``"half_dt_sq"``).
"""

from __future__ import annotations

import numpy as np

from ..reference import STEP_MIN as DT_MIN, STEP_RATE as LUT_RATE, STEP_SCALE as LUT_SCALE, step_decay, variable_step
from .exp_table import exp_table, lut_slope_bits
from .format import (
    Format,
    Overflow,
    Rounding,
    SaturationCounter,
    apply_overflow,
    quantize,
    requantize,
    shift_round,
    to_float,
)
from .formats_set import FormatSet

__all__ = [
    "DT_MIN",
    "LUT_SCALE",
    "LUT_RATE",
    "DT_MAX",
    "step_size_float",
    "lut_value_float",
    "exp_table",
    "exp_lut",
    "lut_slope_bits",
    "dt_constant",
    "step_size",
    "half_dt_sq",
    "step_size_error_bound",
    "measure_step_size",
]

# DT_MIN: the constant term of dt (quantised in the dt format); LUT_SCALE: the factor of each
# exp term, folded into the table entries; LUT_RATE: the rate of exp(-LUT_RATE * (1 - E)).
DT_MAX = DT_MIN + 2 * LUT_SCALE
"""Largest step (E_S = E_C = 1)."""
step_size_float = variable_step
"""Float reference ``dt = 0.01 + 0.1*exp(-5(1-E_S)) + 0.1*exp(-5(1-E_C))``: :func:`~golden_model.reference.variable_step`."""

def lut_value_float(e: np.ndarray | float) -> np.ndarray:
    """``0.1*exp(-5(1 - E))`` in float64 (E clamped to [0, 1]): one term of :func:`step_size_float`."""
    return LUT_SCALE * step_decay(np.asarray(e, dtype=np.float64))


def exp_lut(
    e_raw: np.ndarray | int,
    error_fmt: Format,
    table: np.ndarray,
    index_bits: int,
    interpolate: bool,
    rounding: Rounding | str,
    counter: SaturationCounter | None = None,
    name: str = "lut_input",
) -> np.ndarray:
    """Look up ``0.1*exp(-5(1-E))`` for raw ``E`` in ``error_fmt``; result raw in the table's format.

    Inputs above 1.0 (only possible for ``u1.F``) are clamped to 1.0 and counted
    under ``name``.
    """
    e = error_fmt.check(e_raw, "error input of the exp LUT")
    one = 1 << error_fmt.frac_bits
    over = e > one
    if counter is not None:
        counter.add_saturations(name, int(np.count_nonzero(over)))
    e = np.minimum(e, one)
    r = error_fmt.frac_bits - index_bits
    if r < 0:
        raise ValueError(f"index_bits {index_bits} > error fraction bits {error_fmt.frac_bits}")
    n1 = 1 << index_bits
    if table.shape != (n1 + 1,):
        raise ValueError(f"table must have {n1 + 1} entries, got {table.shape}")
    if r == 0:
        return table[e]
    if not interpolate:
        return table[shift_round(e, r, rounding)]
    k = e >> r
    t = e & ((1 << r) - 1)
    t0 = table[k]
    t1 = table[np.minimum(k + 1, n1)]
    return t0 + shift_round((t1 - t0) * t, r, rounding)


def dt_constant(dt_fmt: Format) -> int:
    """Raw ``0.01`` in ``dt_fmt``, rounded half up (the constant ROM/wire value)."""
    return int(quantize(DT_MIN, dt_fmt, Rounding.HALF_UP, Overflow.SATURATE))


def step_size(
    e_s_raw: np.ndarray | int,
    e_c_raw: np.ndarray | int,
    fs: FormatSet,
    counter: SaturationCounter | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-point ``(dt, dt**2/2)`` as raw ``(fs.dt, fs.half_dt_sq)`` from raw errors in ``fs.error``."""
    table = exp_table(fs.lut_index_bits, fs.lut_entry)
    args = (fs.error, table, fs.lut_index_bits, fs.lut_interpolate, fs.rounding, counter)
    v = exp_lut(e_s_raw, *args) + exp_lut(e_c_raw, *args)
    v = requantize(v, fs.lut_entry.frac_bits, fs.dt, fs.rounding, Overflow.SATURATE, counter, "dt")
    dt = apply_overflow(v + dt_constant(fs.dt), fs.dt, Overflow.SATURATE, counter, "dt")
    return dt, half_dt_sq(dt, fs, counter)


def half_dt_sq(
    dt_raw: np.ndarray | int, fs: FormatSet, counter: SaturationCounter | None = None
) -> np.ndarray:
    """``dt**2/2`` raw in ``fs.half_dt_sq`` from raw ``dt`` in ``fs.dt`` (``fs.rounding``, saturating).

    The step generator's last stage; the fixed-step mode uses it too.
    """
    dt = fs.dt.check(dt_raw, "dt")
    # dt*dt fits int64 (checked by FormatSet: "dt*dt -> half_dt_sq"); /2 = one more fraction bit
    return requantize(dt * dt, 2 * fs.dt.frac_bits + 1, fs.half_dt_sq, fs.rounding,
                      Overflow.SATURATE, counter, "half_dt_sq")


def step_size_error_bound(fs: FormatSet) -> float:
    """A priori bound on ``|dt_fixed - step_size_float(E_S, E_C)|`` in dt ulps.

    E is taken at its represented value.  Per lookup (real units, h = 2**-n,
    u_L = lut lsb, rho = 1/2 for nearest roundings, 1 for floor):

    * entries: u_L/2 (linear interpolation of entries each off by <= u_L/2);
    * interpolating: + max|f''| h**2/8 = 2.5 h**2/8, + rounding of the product rho*u_L;
    * nearest entry: + max|f'| * (h*rho) = 0.5 h rho (index rounding).

    Plus ``rho*u_dt`` if the sum is requantised to fewer fraction bits, plus the
    exact ``|C - 0.01|``.
    """
    rho = 1.0 if fs.rounding is Rounding.FLOOR else 0.5
    h = 2.0 ** -fs.lut_index_bits
    u_l, u_dt = fs.lut_entry.lsb, fs.dt.lsb
    f1 = LUT_SCALE * LUT_RATE  # max f' on [0, 1]
    f2 = LUT_SCALE * LUT_RATE**2  # max f'' on [0, 1]
    per = u_l / 2
    if fs.lut_frac_bits > 0:
        per += (f2 * h * h / 8 + rho * u_l) if fs.lut_interpolate else f1 * h * rho
    total = 2 * per
    if fs.lut_entry.frac_bits > fs.dt.frac_bits:
        total += rho * u_dt
    c_err = abs(float(to_float(dt_constant(fs.dt), fs.dt)) - DT_MIN)
    return (total + c_err) / u_dt + 1e-9


def measure_step_size(fs: FormatSet) -> dict[str, float | bool]:
    """Exhaustive error of :func:`step_size` against :func:`step_size_float`, in dt ulps.

    Every representable E is looked up once.  When the lookups are summed
    without rounding (``lut_entry.frac_bits == dt.frac_bits``, as in the presets),
    ``dt(E_S, E_C) = C + v(E_S) + v(E_C)`` exactly, so the error over *all pairs* is
    ``e(E_S) + e(E_C) + c`` with ``e`` the per-lookup error and ``c = C - 0.01``;
    its maximum magnitude is ``max(|2 max e + c|, |2 min e + c|)`` (exact, not sampled).
    Otherwise ``separable`` is False and ``max_dt_ulp_error`` is that value plus the
    final rounding (an upper bound; sample pairs for the actual maximum).

    Returns ``max_dt_ulp_error`` (over all pairs), ``lookup_err_min/max``,
    ``const_err`` (all in dt ulps), ``bound`` (:func:`step_size_error_bound`),
    ``separable``.
    """
    e = np.arange(0, fs.error.raw_max + 1, dtype=np.int64)
    table = exp_table(fs.lut_index_bits, fs.lut_entry)
    v = exp_lut(e, fs.error, table, fs.lut_index_bits, fs.lut_interpolate, fs.rounding)
    ef = np.minimum(to_float(e, fs.error), 1.0)
    u = fs.lut_entry.lsb / fs.dt.lsb  # lut ulp in dt ulps
    err = v * u - lut_value_float(ef) / fs.dt.lsb
    c = dt_constant(fs.dt) - DT_MIN / fs.dt.lsb
    separable = fs.lut_entry.frac_bits == fs.dt.frac_bits
    worst = max(abs(2 * err.max() + c), abs(2 * err.min() + c))
    if not separable:  # the sum is rounded once more: upper bound instead of exact max
        worst += 1.0 if fs.rounding is Rounding.FLOOR else 0.5
    return {"max_dt_ulp_error": float(worst), "lookup_err_min": float(err.min()),
            "lookup_err_max": float(err.max()), "const_err": float(c),
            "bound": step_size_error_bound(fs), "separable": separable}
