"""Fixed-point formats and bit-accurate quantisation primitives.

Conventions (the contract the RTL is checked against):

* A value in format ``f`` is held as a numpy ``int64`` *raw* integer;
  its real value is ``raw * 2**-f.frac_bits``.
* Every primitive that can lose precision takes an explicit
  :class:`Rounding` and every primitive that can leave a format's range takes
  an explicit :class:`Overflow`.  There are no implicit defaults.
* Format widths are at most 62 bits, and :func:`mul` refuses operand pairs
  whose widths sum to more than 63, so the exact product of any two raw values
  always fits in int64: *products wider than int64 are impossible by
  construction*.
* Every clamped element is counted in an optional :class:`SaturationCounter`
  under a caller-chosen name; every wrapped element is counted separately.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

__all__ = [
    "MAX_WIDTH",
    "MAX_PRODUCT_WIDTH",
    "Rounding",
    "Overflow",
    "Format",
    "raw_range",
    "SaturationCounter",
    "as_raw",
    "shift_round",
    "apply_overflow",
    "quantize",
    "requantize",
    "mul",
    "add",
    "sub",
    "to_float",
]

MAX_WIDTH = 62
"""Largest allowed format width in bits (sign bit included)."""

MAX_PRODUCT_WIDTH = 63
"""Largest allowed sum of operand widths of a multiplication (exact product fits int64)."""


class Rounding(str, Enum):
    """Rounding applied when fraction bits are dropped.

    ``FLOOR``        arithmetic shift right: round toward -inf (hardware drops bits).
    ``HALF_UP``      add half an lsb, then floor: ties go toward +inf
                     (fxpmath ``'nearest_posinf'`` / SystemC ``SC_RND``).
    ``NEAREST_EVEN`` round to nearest, ties to even
                     (fxpmath ``'around'`` / SystemC ``SC_RND_CONV``).
    """

    FLOOR = "floor"
    HALF_UP = "half_up"
    NEAREST_EVEN = "nearest_even"


class Overflow(str, Enum):
    """Action when a value leaves a format's raw range.

    ``SATURATE`` clamps to ``raw_min``/``raw_max`` (each clamped element is counted).
    ``WRAP``     keeps the low ``width`` bits (two's complement for signed formats).
    """

    SATURATE = "saturate"
    WRAP = "wrap"


_FORMAT_RE = re.compile(r"^\s*([su])(\d+)\.(\d+)\s*$", re.ASCII)  # ASCII: another script's digits are no bits


def raw_range(width: int, signed: bool) -> tuple[int, int]:
    """The smallest and largest raw integer of a ``width``-bit two's-complement (``signed``) or
    unsigned field."""
    return (-(1 << (width - 1)) if signed else 0), (1 << (width - int(signed))) - 1


@dataclass(frozen=True)
class Format:
    """A binary fixed-point format: ``[sign] int_bits . frac_bits``.

    ``width = signed + int_bits + frac_bits``; signed formats are two's complement.
    Written as ``"s3.16"`` (signed, 3 integer bits, 16 fraction bits: 20 bits wide)
    or ``"u0.18"`` (unsigned, 18 bits wide).
    """

    signed: bool
    int_bits: int
    frac_bits: int

    def __post_init__(self) -> None:
        if not isinstance(self.signed, bool):
            raise ValueError(f"Format.signed must be a bool, got {self.signed!r}")
        for attr in ("int_bits", "frac_bits"):
            v = getattr(self, attr)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ValueError(f"Format.{attr} must be an int, got {v!r}")
            if v < 0:
                raise ValueError(f"Format.{attr} must be >= 0, got {v}")
            object.__setattr__(self, attr, int(v))
        if not 1 <= self.width <= MAX_WIDTH:
            raise ValueError(
                f"Format {self}: width {self.width} bits is outside 1..{MAX_WIDTH}"
            )

    @classmethod
    def parse(cls, text: str | Format) -> Format:
        """Parse ``"s3.16"`` / ``"u0.18"``; a :class:`Format` is returned unchanged."""
        if isinstance(text, Format):
            return text
        m = _FORMAT_RE.match(str(text))
        shown = repr(str(text)) if len(str(text)) <= 40 else repr(str(text)[:40]) + "..."  # (not a page of digits)
        if m is None:
            raise ValueError(f"cannot parse fixed-point format {shown}: expected e.g. 's3.16' or 'u0.18'")
        int_bits, frac_bits = int(m.group(2)), int(m.group(3))
        if max(int_bits, frac_bits) > MAX_WIDTH:  # (said here: Format's own message would print every digit)
            raise ValueError(f"fixed-point format {shown}: its width is outside 1..{MAX_WIDTH} bits")
        return cls(m.group(1) == "s", int_bits, frac_bits)

    def __str__(self) -> str:
        return f"{'s' if self.signed else 'u'}{self.int_bits}.{self.frac_bits}"

    @property
    def width(self) -> int:
        """Total number of bits, sign bit included."""
        return int(self.signed) + self.int_bits + self.frac_bits

    @property
    def raw_min(self) -> int:
        """Smallest raw integer (``-2**(width-1)`` or 0)."""
        return raw_range(self.width, self.signed)[0]

    @property
    def raw_max(self) -> int:
        """Largest raw integer (``2**(width-1) - 1`` or ``2**width - 1``)."""
        return raw_range(self.width, self.signed)[1]

    @property
    def lsb(self) -> float:
        """Real value of one raw unit: ``2**-frac_bits``."""
        return 2.0 ** -self.frac_bits

    @property
    def min(self) -> float:
        """Smallest representable real value."""
        return self.raw_min * self.lsb

    @property
    def max(self) -> float:
        """Largest representable real value."""
        return self.raw_max * self.lsb

    def contains(self, raw: np.ndarray | int) -> bool:
        """True if every element of ``raw`` lies in ``[raw_min, raw_max]``."""
        r = as_raw(raw)
        return r.size == 0 or bool(r.min() >= self.raw_min and r.max() <= self.raw_max)

    def check(self, raw: np.ndarray | int, what: str = "value") -> np.ndarray:
        """Return ``raw`` as int64, raising ValueError if any element is out of range."""
        r = as_raw(raw)
        if not self.contains(r):
            raise ValueError(
                f"{what} out of range of format {self}: raw range "
                f"[{int(r.min())}, {int(r.max())}] not within [{self.raw_min}, {self.raw_max}]"
            )
        return r


@dataclass
class SaturationCounter:
    """Counts overflow events per signal name.

    ``saturations[name]`` is the number of elements clamped under ``name``;
    ``wraps[name]`` the number of elements that wrapped (debug aid: in a correct
    design wrapping only happens where it is intended).
    """

    saturations: dict[str, int] = field(default_factory=dict)
    wraps: dict[str, int] = field(default_factory=dict)

    def add_saturations(self, name: str, n: int) -> None:
        """Record ``n`` clamped elements under ``name`` (zero counts create no key)."""
        if n:
            self.saturations[name] = self.saturations.get(name, 0) + int(n)

    def add_wraps(self, name: str, n: int) -> None:
        """Record ``n`` wrapped elements under ``name``."""
        if n:
            self.wraps[name] = self.wraps.get(name, 0) + int(n)

    def __getitem__(self, name: str) -> int:
        """Saturation count for ``name`` (0 if never saturated)."""
        return self.saturations.get(name, 0)

    @property
    def total(self) -> int:
        """Total number of saturation events over all names."""
        return sum(self.saturations.values())

    @property
    def total_wraps(self) -> int:
        """Total number of wrap events over all names."""
        return sum(self.wraps.values())

    def merge(self, other: SaturationCounter) -> SaturationCounter:
        """Add ``other``'s counts into this counter; returns ``self``."""
        for k, v in other.saturations.items():
            self.add_saturations(k, v)
        for k, v in other.wraps.items():
            self.add_wraps(k, v)
        return self

    def reset(self) -> None:
        """Forget all counts."""
        self.saturations.clear()
        self.wraps.clear()

    def as_dict(self) -> dict[str, dict[str, int]]:
        """``{"saturations": {name: n}, "wraps": {name: n}}`` with sorted keys (JSON friendly)."""
        return {
            "saturations": dict(sorted(self.saturations.items())),
            "wraps": dict(sorted(self.wraps.items())),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Mapping[str, int]]) -> SaturationCounter:
        """Inverse of :meth:`as_dict`."""
        return cls(dict(d.get("saturations", {})), dict(d.get("wraps", {})))


# --------------------------------------------------------------------------- helpers


def _rounding(r: Rounding | str) -> Rounding:
    try:
        return Rounding(r)
    except ValueError:
        raise ValueError(
            f"unknown rounding {r!r}; expected one of {[m.value for m in Rounding]}"
        ) from None


def _overflow(o: Overflow | str) -> Overflow:
    try:
        return Overflow(o)
    except ValueError:
        raise ValueError(
            f"unknown overflow mode {o!r}; expected one of {[m.value for m in Overflow]}"
        ) from None


def _check_counter_name(counter: SaturationCounter | None, name: str | None) -> None:
    if counter is not None and not name:
        raise ValueError("a name is required when a SaturationCounter is given")


def as_raw(raw: np.ndarray | int) -> np.ndarray:
    """Convert integer input to an int64 array (0-d for scalars); refuses floats."""
    a = np.asarray(raw)
    if a.dtype == np.int64:
        return a
    if a.dtype == object or a.dtype == bool or not np.issubdtype(a.dtype, np.integer):
        if a.dtype == object and a.size and all(isinstance(v, int) for v in a.flat):
            if any(not -(1 << 63) <= v < (1 << 63) for v in a.flat):
                raise ValueError("raw integer does not fit in int64")
            return a.astype(np.int64)
        raise TypeError(f"raw values must be integers, got dtype {a.dtype}")
    if a.dtype == np.uint64 and a.size and int(a.max()) >= (1 << 63):
        raise ValueError("raw integer does not fit in int64")
    return a.astype(np.int64)


# --------------------------------------------------------------------------- primitives


def shift_round(raw: np.ndarray | int, shift: np.ndarray | int, rounding: Rounding | str) -> np.ndarray:
    """Return ``raw * 2**-shift`` rounded to an integer (int64).

    ``shift`` may be an array (per-element shifts, broadcast against ``raw``).
    ``shift <= 0`` is an exact left shift: the caller guarantees it does not
    overflow int64.  ``shift > 0`` drops ``shift`` bits with ``rounding``:

    * floor:        ``raw >> s``
    * half_up:      ``t = raw >> (s-1); (t >> 1) + (t & 1)``
      (= ``(raw + 2**(s-1)) >> s``, without any risk of overflowing int64)
    * nearest_even: as half_up, except exact ties go to the even neighbour.
    """
    mode = _rounding(rounding)
    r = as_raw(raw)
    s = np.asarray(shift, dtype=np.int64)
    if s.ndim == 0 and int(s) <= 0:
        return r << np.int64(-int(s))
    # |raw| <= 2**63, so shifting by more than 64 gives the same as 64 (63 for floor).
    sr = np.clip(s, 1, 64)
    if mode is Rounding.FLOOR:
        out = r >> np.minimum(sr, 63)
    else:
        t = r >> (sr - 1)  # keeps the half-lsb bit as bit 0
        if s.ndim == 0 and int(s) >= 2:  # |t| <= 2**62: t + 1 cannot overflow
            out = (t + 1) >> 1
        else:
            out = (t >> 1) + (t & 1)  # = (t + 1) >> 1, without overflow at t = 2**63 - 1
        if mode is Rounding.NEAREST_EVEN:
            # tie: half bit set and nothing below it; then drop the +1 if result is odd
            below = r - (t << (sr - 1))
            tie = ((t & 1) == 1) & (below == 0)
            out = np.where(tie & ((out & 1) == 1), out - 1, out)
    if np.any(s <= 0):
        left = r << np.clip(-s, 0, 63)
        out = np.where(s <= 0, left, out)
    return np.asarray(out, dtype=np.int64)


def apply_overflow(
    raw: np.ndarray | int,
    fmt: Format,
    overflow: Overflow | str,
    counter: SaturationCounter | None = None,
    name: str | None = None,
) -> np.ndarray:
    """Bring int64 ``raw`` into ``fmt``'s raw range by saturating or wrapping.

    Saturation events are counted under ``counter.saturations[name]``, wrap
    events under ``counter.wraps[name]``.
    """
    mode = _overflow(overflow)
    _check_counter_name(counter, name)
    r = as_raw(raw)
    # Fast path (two reductions, no temporaries): everything already in range.
    if r.size == 0 or (r.max() <= fmt.raw_max and r.min() >= fmt.raw_min):
        return r
    hi = r > fmt.raw_max
    lo = r < fmt.raw_min
    n_out = int(np.count_nonzero(hi | lo))
    if mode is Overflow.SATURATE:
        if counter is not None:
            counter.add_saturations(name, n_out)
        return np.asarray(
            np.where(hi, np.int64(fmt.raw_max), np.where(lo, np.int64(fmt.raw_min), r)),
            dtype=np.int64,
        )
    if counter is not None:
        counter.add_wraps(name, n_out)
    return _wrap(r, fmt)


def _wrap(r: np.ndarray, fmt: Format) -> np.ndarray:
    """Keep the low ``fmt.width`` bits of int64 ``r`` (two's complement if signed)."""
    m = r & np.int64((1 << fmt.width) - 1)
    if fmt.signed:
        m = np.where(m > fmt.raw_max, m - np.int64(1 << fmt.width), m)
    return np.asarray(m, dtype=np.int64)


def _round_float(v: np.ndarray, mode: Rounding) -> np.ndarray:
    """Round float64 ``v`` to integral float64 values, exactly."""
    if mode is Rounding.FLOOR:
        return np.floor(v)
    if mode is Rounding.NEAREST_EVEN:
        return np.rint(v)  # IEEE round-half-even, exact
    f = np.floor(v)
    # f + 0.5 is exact whenever v is not already an integer (|v| < 2**52 then).
    return f + ((v != f) & (v >= f + 0.5))


def quantize(
    x: np.ndarray | float,
    fmt: Format,
    rounding: Rounding | str,
    overflow: Overflow | str,
    counter: SaturationCounter | None = None,
    name: str | None = None,
) -> np.ndarray:
    """Convert real values (float64) to raw integers of ``fmt`` (host-side conversion).

    ``x * 2**frac_bits`` is formed exactly (power-of-two scaling), rounded with
    ``rounding`` and brought into range with ``overflow``.  NaN is refused;
    +-inf saturates (and is refused under wrap).
    """
    mode = _rounding(rounding)
    ov = _overflow(overflow)
    _check_counter_name(counter, name)
    xa = np.asarray(x, dtype=np.float64)
    if np.isnan(xa).any():
        raise ValueError(f"quantize to {fmt}: NaN input")
    with np.errstate(over="ignore"):  # a value past float's range is +-inf here, and saturates below
        v = _round_float(np.ldexp(xa, fmt.frac_bits), mode)
    lim = float(1 << MAX_WIDTH)  # > every raw_max, exactly representable
    # Clipping to +-2**62 keeps out-of-range values out of range and makes the
    # int64 conversion exact, so range tests below are exact integer compares.
    r = np.clip(v, -lim, lim).astype(np.int64)
    if ov is Overflow.SATURATE:
        return apply_overflow(r, fmt, ov, counter, name)
    if np.isinf(v).any():
        raise ValueError(f"quantize to {fmt}: cannot wrap an infinite value")
    if counter is not None:
        counter.add_wraps(name, int(np.count_nonzero((r > fmt.raw_max) | (r < fmt.raw_min))))
    # fmod by a power of two is exact; its magnitude < 2**width fits int64.
    return _wrap(np.fmod(v, float(1 << fmt.width)).astype(np.int64), fmt)


def requantize(
    raw: np.ndarray | int,
    from_frac_bits: int,
    fmt: Format,
    rounding: Rounding | str,
    overflow: Overflow | str,
    counter: SaturationCounter | None = None,
    name: str | None = None,
) -> np.ndarray:
    """Re-express raw values having ``from_frac_bits`` fraction bits in ``fmt``.

    Fewer fraction bits: right shift with ``rounding``; more: exact left shift
    (values that would overflow are detected *before* shifting, so int64 never
    overflows).  Then saturate or wrap into ``fmt``.
    """
    _check_counter_name(counter, name)
    r = as_raw(raw)
    shift = int(from_frac_bits) - fmt.frac_bits
    if shift == 0:  # nothing to round: only the range
        return apply_overflow(r, fmt, overflow, counter, name)
    if shift > 0:
        return apply_overflow(shift_round(r, shift, rounding), fmt, overflow, counter, name)
    _rounding(rounding)  # validate even though a left shift never rounds
    ov = _overflow(overflow)
    k = -shift
    kk = min(k, 63)
    hi_lim = fmt.raw_max >> kk  # raw << k > raw_max  <=>  raw > raw_max >> k
    lo_lim = -((-fmt.raw_min) >> kk)  # raw << k < raw_min <=> raw < ceil(raw_min / 2**k)
    hi = r > hi_lim
    lo = r < lo_lim
    n_out = int(np.count_nonzero(hi | lo))
    if ov is Overflow.SATURATE:
        ok = np.where(hi | lo, np.int64(0), r)
        out = np.where(
            hi, np.int64(fmt.raw_max), np.where(lo, np.int64(fmt.raw_min), ok << np.int64(kk))
        )
        if counter is not None:
            counter.add_saturations(name, n_out)
        return np.asarray(out, dtype=np.int64)
    if counter is not None:
        counter.add_wraps(name, n_out)
    if k >= fmt.width:
        return np.zeros_like(r)
    # numpy's int64 << is modulo 2**64 and 2**width divides 2**64.
    return _wrap(r << np.int64(k), fmt)


def mul(
    a: np.ndarray | int,
    fa: Format,
    b: np.ndarray | int,
    fb: Format,
    out_fmt: Format,
    rounding: Rounding | str,
    overflow: Overflow | str,
    counter: SaturationCounter | None = None,
    name: str | None = None,
) -> np.ndarray:
    """Exact product of raw ``a`` (format ``fa``) and ``b`` (``fb``), requantised to ``out_fmt``.

    Raises ValueError if ``fa.width + fb.width > 63`` (the exact product might not
    fit int64) or if an operand is outside its format's range.
    """
    if fa.width + fb.width > MAX_PRODUCT_WIDTH:
        raise ValueError(
            f"product {name or '?'}: {fa} ({fa.width} bits) x {fb} ({fb.width} bits) "
            f"= {fa.width + fb.width} bits > {MAX_PRODUCT_WIDTH}; the exact product "
            f"would not fit int64"
        )
    ra = fa.check(a, f"operand a of product {name or '?'}")
    rb = fb.check(b, f"operand b of product {name or '?'}")
    return requantize(ra * rb, fa.frac_bits + fb.frac_bits, out_fmt, rounding, overflow, counter, name)


def _aligned_sum(a, fa: Format, b, fb: Format, sign: int, name: str | None):
    f = max(fa.frac_bits, fb.frac_bits)
    w = max(fa.int_bits, fb.int_bits) + f + 2  # sign + carry
    if w > MAX_PRODUCT_WIDTH:
        raise ValueError(f"sum {name or '?'}: aligned width {w} bits exceeds int64 headroom")
    ra = fa.check(a, f"operand a of {name or '?'}") << np.int64(f - fa.frac_bits)
    rb = fb.check(b, f"operand b of {name or '?'}") << np.int64(f - fb.frac_bits)
    return (ra + rb if sign > 0 else ra - rb), f


def add(
    a: np.ndarray | int,
    fa: Format,
    b: np.ndarray | int,
    fb: Format,
    out_fmt: Format,
    rounding: Rounding | str,
    overflow: Overflow | str,
    counter: SaturationCounter | None = None,
    name: str | None = None,
) -> np.ndarray:
    """Exact sum ``a + b`` (operands aligned to the larger fraction), requantised to ``out_fmt``."""
    s, f = _aligned_sum(a, fa, b, fb, +1, name)
    return requantize(s, f, out_fmt, rounding, overflow, counter, name)


def sub(
    a: np.ndarray | int,
    fa: Format,
    b: np.ndarray | int,
    fb: Format,
    out_fmt: Format,
    rounding: Rounding | str,
    overflow: Overflow | str,
    counter: SaturationCounter | None = None,
    name: str | None = None,
) -> np.ndarray:
    """Exact difference ``a - b``, requantised to ``out_fmt``."""
    s, f = _aligned_sum(a, fa, b, fb, -1, name)
    return requantize(s, f, out_fmt, rounding, overflow, counter, name)


def to_float(raw: np.ndarray | int, fmt: Format) -> np.ndarray:
    """Real value ``raw * 2**-frac_bits`` as float64 (exact while |raw| < 2**53)."""
    return np.ldexp(as_raw(raw).astype(np.float64), -fmt.frac_bits)
