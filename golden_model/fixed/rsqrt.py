"""Bit-accurate model of the hardware reciprocal-square-root unit.

Method (every width comes from :class:`RsqrtConfig`; the RTL reads them from it):

1. **Normalise.**  The raw input ``X >= 1`` (format ``fmt_in``, real value
   ``x = X * 2**-Fin``) has bit length ``b`` (leading-zero count).  Pick the
   exponent ``e`` in ``{b-1, b-2}`` with ``e - Fin`` even, so the mantissa
   ``M = X * 2**-e`` lies in ``[1, 4)`` and ``1/sqrt(x) = M**-0.5 * 2**(-(e-Fin)/2)``
   needs no irrational correction.  ``M`` is held as ``u2.Fm``
   (``M_raw = X * 2**(Fm - e)``, low bits dropped = floor if ``X`` is wider).
2. **Seed.**  ``y0 = seed_table[(M_raw >> (Fm + 2 - seed_bits)) - 2**(seed_bits-2)]``:
   the top ``seed_bits`` bits of the mantissa (whose two integer bits are never
   ``00``) address a ROM of ``3 * 2**(seed_bits-2)`` entries in ``u0.Fs``.
   Entry for interval ``[a, b)`` is ``1/sqrt((a+b)/2)`` correctly rounded
   (half up), computed exactly with integer square roots.
3. **Newton-Raphson**, ``newton_steps`` times, in the incremental form
   ``y <- y + y*(1 - M*y**2)/2`` (= ``y*(3 - M*y**2)/2``), ``y`` in ``u1.Fy``:

   * ``t1 = round(y*y)``          to ``u1.Fw``   (drop ``2*Fy - Fw`` bits)
   * ``t2 = round(M*t1)``         to ``u1.Fw``   (drop ``Fm`` bits)
   * ``h  = 1 - t2``              in ``s0.Fw``   (exact)
   * ``y  = y + round(y*h / 2)``  in ``u1.Fy``   (drop ``Fw + 1`` bits)

   all roundings half-up.
4. **Denormalise.**  ``R = round(y * 2**-s)`` (half up) with
   ``s = Fy - Fout + (e - Fin)/2``.  ``s <= 0`` (or ``R > raw_max``) saturates
   to ``fmt_out.raw_max``; so does ``X == 0``.  Each is counted.

Widths: ``Fy = Fm = Fw = out_value_bits + guard_bits`` where
``out_value_bits = fmt_out.int_bits + fmt_out.frac_bits``; ``Fs = seed_bits + guard_bits``
(capped at ``Fy``; ``= Fy`` when there are no Newton steps).

Accuracy contract: **faithful**, ``|R - min(2**Fout / sqrt(x), raw_max)| < 1`` for
every input (i.e. R is the floor or the ceiling of the exact value; saturated
inputs give exactly ``raw_max``).  A-priori budget in ``y`` ulps (``2**-Fy``):
mantissa truncation <= 0.5 (0 when ``fmt_in.width <= Fm + 2``), the three
roundings of a Newton step ~1.8, Newton residual ``1.5*eps**2/2**-Fy`` with
``eps <~ 2**-(seed_bits)`` the seed's relative error (squared again per extra
step); divided by ``2**s >= 2**guard_bits`` and added to the final rounding's
0.5 ulp this must stay below 1.  The budget is not tight enough to prove the
presets faithful, so the tests verify the contract exhaustively (all inputs of
width <= 24) and :func:`measure_rsqrt` reports the actual maximum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .format import (
    MAX_PRODUCT_WIDTH,
    Format,
    Rounding,
    SaturationCounter,
    as_raw,
    shift_round,
)

__all__ = [
    "RSQRT_GUARD_BITS",
    "RsqrtConfig",
    "rsqrt_seed_table",
    "rsqrt",
    "rsqrt_with_config",
    "rsqrt_stages",
    "rsqrt_exact",
    "bit_length",
    "measure_rsqrt",
]

RSQRT_GUARD_BITS = 3
"""Default extra fraction bits carried beyond the output's value bits (see module doc)."""

INTERNAL_ROUNDING = Rounding.HALF_UP
"""Rounding of the unit's internal steps (not a field of :class:`RsqrtConfig`); the RTL reads it here."""


@dataclass(frozen=True)
class RsqrtConfig:
    """All parameters and derived internal widths of the rsqrt unit (single source)."""

    fmt_in: Format
    fmt_out: Format
    seed_bits: int
    newton_steps: int
    guard_bits: int = RSQRT_GUARD_BITS

    def __post_init__(self) -> None:
        if self.seed_bits < 2:
            raise ValueError(f"rsqrt seed_bits must be >= 2, got {self.seed_bits}")
        if self.newton_steps < 0:
            raise ValueError(f"rsqrt newton_steps must be >= 0, got {self.newton_steps}")
        if self.guard_bits < 1:
            raise ValueError(f"rsqrt guard_bits must be >= 1, got {self.guard_bits}")
        if self.seed_bits > self.mant_frac_bits + 2:
            raise ValueError(
                f"rsqrt seed_bits {self.seed_bits} exceeds the mantissa width "
                f"{self.mant_fmt.width}"
            )
        if self.seed_frac_bits < self.seed_bits:  # a seed entry could round up to 1.0, outside u0.Fs
            raise ValueError(f"rsqrt seed_bits {self.seed_bits} needs seed entries of at least as many fraction bits; "
                             f"{self.fmt_out} (+ {self.guard_bits} guard bits) gives {self.seed_frac_bits}")
        for pname, fa, fb in self.products:
            if fa.width + fb.width > MAX_PRODUCT_WIDTH:
                raise ValueError(
                    f"rsqrt product {pname}: {fa} ({fa.width} bits) x {fb} ({fb.width} bits) "
                    f"= {fa.width + fb.width} bits > {MAX_PRODUCT_WIDTH}"
                )

    # ---- derived widths -------------------------------------------------
    @property
    def out_value_bits(self) -> int:
        """Output bits excluding a sign bit: ``fmt_out.int_bits + fmt_out.frac_bits``."""
        return self.fmt_out.int_bits + self.fmt_out.frac_bits

    @property
    def y_frac_bits(self) -> int:
        """Fy: fraction bits of the iterate ``y`` (format ``u1.Fy``)."""
        return self.out_value_bits + self.guard_bits

    @property
    def mant_frac_bits(self) -> int:
        """Fm: fraction bits of the normalised mantissa ``M`` (format ``u2.Fm``)."""
        return self.y_frac_bits

    @property
    def work_frac_bits(self) -> int:
        """Fw: fraction bits of ``y**2``, ``M*y**2`` and ``h``."""
        return self.y_frac_bits

    @property
    def seed_frac_bits(self) -> int:
        """Fs: fraction bits of seed-ROM entries (format ``u0.Fs``)."""
        if self.newton_steps == 0:
            return self.y_frac_bits
        return min(self.y_frac_bits, self.seed_bits + self.guard_bits)

    @property
    def mant_fmt(self) -> Format:
        return Format(False, 2, self.mant_frac_bits)

    @property
    def y_fmt(self) -> Format:
        return Format(False, 1, self.y_frac_bits)

    @property
    def seed_fmt(self) -> Format:
        return Format(False, 0, self.seed_frac_bits)

    @property
    def ysq_fmt(self) -> Format:
        """Format of ``t1 = y*y`` and ``t2 = M*t1`` (both < 2)."""
        return Format(False, 1, self.work_frac_bits)

    @property
    def h_fmt(self) -> Format:
        """Format of ``h = 1 - M*y**2`` (``|h| < 1/2`` for seed_bits >= 2)."""
        return Format(True, 0, self.work_frac_bits)

    @property
    def seed_index_shift(self) -> int:
        """ROM address = ``(M_raw >> seed_index_shift) - seed_index_offset``."""
        return self.mant_frac_bits + 2 - self.seed_bits

    @property
    def seed_index_offset(self) -> int:
        return 1 << (self.seed_bits - 2)

    @property
    def seed_table_size(self) -> int:
        return 3 << (self.seed_bits - 2)

    @property
    def products(self) -> tuple[tuple[str, Format, Format], ...]:
        """The multiplications one Newton step performs: (name, operand formats)."""
        return (
            ("y*y", self.y_fmt, self.y_fmt),
            ("M*y^2", self.mant_fmt, self.ysq_fmt),
            ("y*h", self.y_fmt, self.h_fmt),
        )

    def step_products(self, step: int) -> tuple[tuple[str, Format, Format], ...]:
        """:attr:`products` of Newton step ``step`` with the operand formats the unit holds.

        Step 0 squares the seed, which is below 1: ``u0.Fy`` (the ROM entry widened by
        wiring), one bit narrower than ``y_fmt``; everything else is as :attr:`products`.
        """
        if step == 0:
            seed_y = Format(False, 0, self.y_frac_bits)
            return (("y*y", seed_y, seed_y),) + self.products[1:]
        return self.products

    def denorm_shift(self, e: np.ndarray | int) -> np.ndarray:
        """Right shift ``s = Fy - Fout + (e - Fin)/2`` applied to ``y`` (``e - Fin`` even)."""
        e = np.asarray(e, dtype=np.int64)
        return self.y_frac_bits - self.fmt_out.frac_bits + (e - self.fmt_in.frac_bits) // 2

    def method_error(self) -> float:
        """The method's relative error before the output's rounding (a priori): the seed, the reciprocal
        square root of its interval's midpoint, is off by at most ``2^-seed_bits`` (the interval at
        ``M = 1``), and each Newton step ``y(3 − M·y²)/2`` takes an error ``e`` to ``1.5·e²``
        (measured below it: 0.18 for 2 seed bits and no step, 0.0037 with two)."""
        error = math.ldexp(1.0, -self.seed_bits)
        for _ in range(self.newton_steps):
            error = 1.5 * error * error
        return error

    def seed_table(self) -> np.ndarray:
        """The seed ROM contents for this configuration (raw ``u0.Fs``)."""
        return rsqrt_seed_table(self.seed_bits, self.seed_frac_bits)


@lru_cache(maxsize=64)
def _seed_table_cached(seed_bits: int, seed_frac_bits: int) -> tuple[int, ...]:
    # Interval i (i = 2**(sb-2) .. 2**sb - 1) is [i, i+1) * 2**(2-sb); its midpoint is
    # c = (2i+1) / 2**(sb-1).  Entry = round_half_up(2**Fs / sqrt(c))
    #       = floor((floor(2 * 2**Fs / sqrt(c)) + 1) / 2)
    # and floor(2 * 2**Fs / sqrt(c)) = floor(sqrt(2**(2Fs+sb+1) / (2i+1)))
    #                                = isqrt(2**(2Fs+sb+1) // (2i+1))   (exact integers).
    num = 1 << (2 * seed_frac_bits + seed_bits + 1)
    lo = 1 << (seed_bits - 2)
    return tuple((math.isqrt(num // (2 * i + 1)) + 1) >> 1 for i in range(lo, 1 << seed_bits))


def rsqrt_seed_table(seed_bits: int, seed_frac_bits: int) -> np.ndarray:
    """Seed ROM: ``3 * 2**(seed_bits-2)`` raw entries in ``u0.<seed_frac_bits>``.

    Entry ``j`` serves mantissas ``M`` in ``[i, i+1) * 2**(2-seed_bits)`` with
    ``i = j + 2**(seed_bits-2)``; its value is ``1/sqrt`` of the interval midpoint
    ``(2i+1) / 2**(seed_bits-1)``, rounded half up.  The rounding is exact: it is
    computed with integer square roots only (no floating point), see the comment
    in ``_seed_table_cached``.  All entries are < 1 (``y0 < 1/sqrt(1 + 2**(1-seed_bits))``),
    so they fit ``u0.Fs`` whenever ``seed_frac_bits >= seed_bits``.
    """
    if seed_bits < 2:
        raise ValueError(f"seed_bits must be >= 2, got {seed_bits}")
    if seed_frac_bits < 1 or seed_frac_bits > 61:
        raise ValueError(f"seed_frac_bits must be in 1..61, got {seed_frac_bits}")
    t = np.array(_seed_table_cached(int(seed_bits), int(seed_frac_bits)), dtype=np.int64)
    if t.max() >= (1 << seed_frac_bits):  # cannot happen for seed_frac_bits >= seed_bits
        raise ValueError(f"seed table entry reaches 1.0 with seed_frac_bits={seed_frac_bits}")
    return t


def bit_length(x: np.ndarray) -> np.ndarray:
    """Vectorised ``int.bit_length`` for non-negative int64 (leading-zero count = W - result)."""
    x = as_raw(x)
    b = np.frexp(x.astype(np.float64))[1].astype(np.int64)
    # float conversion may round up to the next power of two for x >= 2**53: fix it.
    b = np.where((b > 0) & ((x >> np.maximum(b - 1, 0)) == 0), b - 1, b)
    return b


@lru_cache(maxsize=64)
def _config(fmt_in: Format, fmt_out: Format, seed_bits: int, newton_steps: int, guard_bits: int):
    return RsqrtConfig(fmt_in, fmt_out, seed_bits, newton_steps, guard_bits)


def rsqrt(
    x_raw: np.ndarray | int,
    fmt_in: Format,
    fmt_out: Format,
    seed_bits: int,
    newton_steps: int,
    counter: SaturationCounter | None = None,
    name: str = "rsqrt",
    guard_bits: int = RSQRT_GUARD_BITS,
) -> np.ndarray:
    """``1/sqrt(x)``: raw ``x`` in ``fmt_in`` (>= 0) to raw result in ``fmt_out``.

    See the module docstring for the method; ``x == 0`` and results above
    ``fmt_out.max`` saturate to ``fmt_out.raw_max`` and are counted under ``name``.
    """
    cfg = _config(fmt_in, fmt_out, int(seed_bits), int(newton_steps), int(guard_bits))
    return rsqrt_with_config(x_raw, cfg, counter, name)


def rsqrt_stages(x_raw: np.ndarray | int, cfg: RsqrtConfig) -> dict[str, np.ndarray]:
    """Every intermediate signal of the unit (raw int64), for RTL bring-up and debugging.

    Keys: ``x``, ``zero`` (bool), ``e`` (exponent, ``e - Fin`` even), ``m`` (mantissa
    ``u2.Fm``), ``seed_index`` (ROM address), ``y0`` (seed widened to ``u1.Fy``),
    ``y`` (after the Newton steps), per step ``i``: ``t1_i``, ``t2_i``, ``h_i``, ``y_i``;
    ``shift`` (denormalisation right shift ``s``), ``result`` (rounded, before
    saturation; meaningless where ``saturate``), ``saturate`` (bool).
    """
    x = cfg.fmt_in.check(x_raw, "rsqrt input")
    if x.size and int(x.min()) < 0:
        raise ValueError("rsqrt input must be non-negative")
    rnd = INTERNAL_ROUNDING
    fy, fm, fw = cfg.y_frac_bits, cfg.mant_frac_bits, cfg.work_frac_bits
    st: dict[str, np.ndarray] = {"x": x}
    zero = x == 0
    xs = np.where(zero, 1, x)

    # 1. normalise: e - Fin even, M = X * 2**-e in [1, 4)
    b = bit_length(xs)
    e = b - 1 - ((b - 1 - cfg.fmt_in.frac_bits) & 1)
    m = shift_round(xs, e - fm, Rounding.FLOOR)  # u2.Fm

    # 2. seed
    idx = (m >> cfg.seed_index_shift) - cfg.seed_index_offset
    y = cfg.seed_table()[idx] << np.int64(fy - cfg.seed_frac_bits)  # u0.Fs -> u1.Fy (exact)
    st.update(zero=zero, e=e, m=m, seed_index=idx, y0=y)

    # 3. Newton-Raphson, incremental form
    one_w = np.int64(1 << fw)
    for i in range(cfg.newton_steps):
        t1 = shift_round(y * y, 2 * fy - fw, rnd)  # u1.Fw
        t2 = shift_round(m * t1, fm, rnd)  # u1.Fw
        h = one_w - t2  # s0.Fw
        y = y + shift_round(y * h, fw + 1, rnd)  # u1.Fy
        st.update({f"t1_{i}": t1, f"t2_{i}": t2, f"h_{i}": h, f"y_{i}": y})

    # 4. denormalise; s <= 0 means a result >= 2**(Fy-1) > raw_max: saturate
    s = cfg.denorm_shift(e)
    r = shift_round(y, np.maximum(s, 1), rnd)
    st.update(y=y, shift=s, result=r, saturate=zero | (s <= 0) | (r > cfg.fmt_out.raw_max))
    return st


def rsqrt_with_config(
    x_raw: np.ndarray | int,
    cfg: RsqrtConfig,
    counter: SaturationCounter | None = None,
    name: str = "rsqrt",
) -> np.ndarray:
    """As :func:`rsqrt`, with a prebuilt :class:`RsqrtConfig`."""
    st = rsqrt_stages(x_raw, cfg)
    sat = st["saturate"]
    if counter is not None:
        counter.add_saturations(name, int(np.count_nonzero(sat)))
    return np.asarray(np.where(sat, np.int64(cfg.fmt_out.raw_max), st["result"]), dtype=np.int64)


def rsqrt_exact(x_raw: np.ndarray | int, fmt_in: Format, fmt_out: Format) -> np.ndarray:
    """Reference ``2**Fout / sqrt(x_raw * 2**-Fin)`` in output ulps, float64 (inf for 0)."""
    x = np.ldexp(as_raw(x_raw).astype(np.float64), -fmt_in.frac_bits)
    with np.errstate(divide="ignore"):
        return np.ldexp(1.0 / np.sqrt(x), fmt_out.frac_bits)


def _sweep_points(fmt_in: Format, n_points: int, seed: int) -> np.ndarray:
    """Dense non-exhaustive test vector (may repeat values): ``n_points`` evenly
    strided inputs, ``n_points/4`` log-uniform random ones (dense at small x, where
    the output has the fewest dropped bits), 0, 1, raw_max and every power of two
    with its neighbours."""
    top = fmt_in.raw_max
    pw = np.array([1 << k for k in range(fmt_in.width - int(fmt_in.signed))], dtype=np.int64)
    special = np.concatenate([[0, 1, 2, 3, top - 1, top], pw - 1, pw, pw + 1])
    stride = np.linspace(0, top, n_points, dtype=np.int64)
    rng = np.random.default_rng(seed)
    logu = np.exp2(rng.uniform(0, np.log2(float(top)), n_points // 4)).astype(np.int64)
    return np.clip(np.concatenate([special, stride, logu]), 0, top)


def measure_rsqrt(
    cfg: RsqrtConfig, sweep_points: int = 1 << 22, chunk: int = 1 << 21, seed: int = 0
) -> dict[str, float | int | bool]:
    """Measure the unit against float64 ``2**Fout / sqrt(x)`` (clamped to ``raw_max``).

    Exhaustive over all non-negative inputs when ``fmt_in.width <= 24``, else a
    sweep of about ``sweep_points`` points (see ``_sweep_points``).  Returns
    ``max_ulp_error`` (max ``|R - min(exact, raw_max)|`` in output ulps, float64
    reference: accurate to ~1e-9 ulp), ``at`` (an input reaching it),
    ``n_points``, ``n_saturated``, ``exhaustive``.
    """
    exhaustive = cfg.fmt_in.width <= 24
    if exhaustive:
        n = cfg.fmt_in.raw_max + 1
        chunks = (np.arange(lo, min(n, lo + chunk), dtype=np.int64) for lo in range(0, n, chunk))
        n_points = n
    else:
        pts = _sweep_points(cfg.fmt_in, sweep_points, seed)
        chunks = (pts[lo:lo + chunk] for lo in range(0, pts.size, chunk))
        n_points = int(pts.size)
    worst, at = 0.0, 0
    counter = SaturationCounter()
    for x in chunks:
        r = rsqrt_with_config(x, cfg, counter)
        ex = np.minimum(rsqrt_exact(x, cfg.fmt_in, cfg.fmt_out), float(cfg.fmt_out.raw_max))
        err = np.abs(r - ex)
        i = int(np.argmax(err))
        if err[i] > worst:
            worst, at = float(err[i]), int(x[i])
    return {"max_ulp_error": worst, "at": at, "n_points": n_points,
            "n_saturated": counter.total, "exhaustive": exhaustive}
