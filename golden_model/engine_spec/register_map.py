"""The engine's register map on its Wishbone B4 bus, as data: registers, bit fields, memory windows.

One :class:`RegisterMap` built from a :class:`~golden_model.fixed.FormatSet` and an
:class:`~golden_model.engine_spec.image.EngineCapacity` is the only description of the host
interface: the RTL decodes it, the driver (``sim/engine_driver.py``) and the exports
(markdown, JSON, C header: ``sim/register_map_export.py``) read it.

**Bus.** Wishbone B4 classic, 32-bit ``dat``; ``adr`` is a 32-bit-word address (byte address
>> 2); ``sel`` must be all ones.  ``err`` answers a partial access (``sel`` not all ones), an
address no register or memory word decodes to (the holes at the end of a window's stride
included), a write to a read-only register, and any memory-window access while the engine runs.

**Values wider than a word** are split over consecutive registers, least significant first:
``NAME_LO``/``NAME_HI`` for two words, ``NAME_0 .. NAME_k`` for more; signed values are two's
complement over the value's width (upper bits of the top word read 0).  The run mode's code and
the barrier bit share the ``MODE`` register (``MODE_FIELDS``).
"""

from __future__ import annotations

import json
import zlib
from dataclasses import asdict, dataclass, field

from .image import (BUS_WORD_BITS, ENERGY_TOL_INT_BITS, ITERATION_BITS, MODE_FIELDS, RESULTS, SATURATION_BITS,
                    EngineCapacity, MemoryLayout, WordField, energy_width, memory_layouts, run_constant_fields)
from ..fixed.engine import ENERGY_TOL_FRAC_BITS
from ..coarse import COARSE_DEGREE_MAX
from ..guard import SCALE_MAX_SHIFT
from ..modes import RUN_MODES
from ..fixed.formats_set import FormatSet

__all__ = ["MAGIC", "VERSION", "ACCESS", "STATES", "RESULTS", "REGISTER_BLOCKS", "BitField", "Register", "MemoryWindow",
           "RegisterMap", "format_hash"]

MAGIC = 0x5350_464C
"""ID register: ASCII ``SPFL``."""

VERSION = (2, 4)
"""(major, minor) of this register map; the major changes when an address or field moves."""

ACCESS = {
    "ro": "read only (a write to a register that is read only as a whole is a bus error; a read-only field of a "
          "register that also has a writable one ignores the write)",
    "rw": "read/write",
    "w1c": "read; writing 1 clears the bit, 0 leaves it",
    "w1p": "write 1 to act (a pulse); reads 0",
}
"""Access types of registers and fields."""

STATES = ("idle", "running", "done")
"""STATUS.state codes, in code order."""

REGISTER_BLOCKS = ("identification", "control", "results", "run constants")


def format_hash(fs: FormatSet) -> int:
    """CRC-32 of the format set's formats and knobs (not its name or notes): the FORMAT_HASH register."""
    return zlib.crc32(json.dumps(fs.content(), sort_keys=True).encode())


@dataclass(frozen=True)
class BitField:
    """Bits ``lsb .. lsb+width−1`` of a register.

    ``value``/``value_lsb``: the quantity this field carries a slice of (its bits from
    ``value_lsb`` up); ``signed`` applies to the whole value.  ``codes``: the meaning of
    each code, in code order (an enumeration field).
    """

    name: str
    lsb: int
    width: int
    access: str
    description: str
    value: str | None = None
    value_lsb: int = 0
    signed: bool = False
    fmt: str | None = None
    codes: tuple[str, ...] = ()

    @property
    def mask(self) -> int:
        """The field's bits in its register."""
        return ((1 << self.width) - 1) << self.lsb


@dataclass(frozen=True)
class Register:
    """One 32-bit register at word ``offset``; ``block`` groups it in the documentation."""

    name: str
    offset: int
    access: str
    description: str
    fields: tuple[BitField, ...]
    block: str
    reset: int = 0


@dataclass(frozen=True)
class MemoryWindow:
    """A memory on the bus: entry ``i``'s word ``w`` at ``base + i·stride + w`` (``w < words``)."""

    name: str
    base: int
    depth: int
    words: int
    stride: int
    fields: tuple[WordField, ...]
    description: str

    @property
    def size(self) -> int:
        """Words the window decodes (a power of two; ``base`` is a multiple of it)."""
        return 1 << max(0, (self.depth * self.stride - 1).bit_length())

    def address(self, index: int, word: int = 0) -> int:
        return self.base + index * self.stride + word

    @property
    def field_lsbs(self) -> tuple[int, ...]:
        """Each field's first bit in the entry's word (word 0's bit 0 first), in field order: the offsets the
        images are packed with (:meth:`~golden_model.engine_spec.image.MemoryLayout.offsets`)."""
        return tuple(MemoryLayout(self.name, self.fields, self.depth).offsets().values())


_WINDOW_TEXT = {
    "nodes": "per vertex: state and weights (read back the layout here)",
    "entries": "per neighbour entry: nodes in order, each node's entries in ring order",
    "triangles": "per triangle: corners and 3D area (E_S)",
    "basis": "per vertex, with a coarse space: its basis values but the constant 1, from the start layout",
    "matrix": "with a coarse space: M = (Φ^T K Φ)^+ row-major, scaled by 2^MATRIX_EXPONENT",
}


def _align(n: int, to: int) -> int:
    return -(-n // to) * to


class _Allocator:
    """Hands out word offsets block by block; a multi-word value starts at a multiple of its word count's
    power of two, a block at a multiple of 8."""

    def __init__(self) -> None:
        self.cursor = 0
        self.registers: list[Register] = []

    def block(self) -> None:
        self.cursor = _align(self.cursor, 8)

    def add(self, name: str, access: str, description: str, fields: tuple[BitField, ...], block: str,
            reset: int = 0) -> None:
        self.registers.append(Register(name, self.cursor, access, description, fields, block, reset))
        self.cursor += 1

    def value(self, name: str, width: int, access: str, description: str, block: str, signed: bool = False,
              fmt: str | None = None, reset: int = 0) -> None:
        """A ``width``-bit value over as many registers as it needs."""
        words = -(-width // BUS_WORD_BITS)
        self.cursor = _align(self.cursor, 1 << (words - 1).bit_length())
        for part in range(words):
            suffix = "" if words == 1 else ("_LO", "_HI")[part] if words == 2 else f"_{part}"
            bits = min(BUS_WORD_BITS, width - part * BUS_WORD_BITS)
            lsb = part * BUS_WORD_BITS
            text = description + (f" (bits {lsb + bits - 1}:{lsb})" if words > 1 else "")
            f = BitField("value", 0, bits, access, text, name, lsb, signed, fmt)
            self.add(name.upper() + suffix, access, text, (f,), block, (reset >> lsb) & ((1 << bits) - 1))


def _registers(fs: FormatSet, capacity: EngineCapacity) -> list[Register]:
    a = _Allocator()
    ident = "identification"
    a.value("id", 32, "ro", f"magic 0x{MAGIC:08X} ('SPFL')", ident, reset=MAGIC)
    a.add("VERSION", "ro", "register map version", (
        BitField("minor", 0, 16, "ro", "minor version", "version_minor"),
        BitField("major", 16, 16, "ro", "major version: changes when an address or field moves", "version_major"),
    ), ident, VERSION[0] << 16 | VERSION[1])
    a.value("format_hash", 32, "ro", f"CRC-32 of the format set's formats and knobs ('{fs.name}')", ident,
            reset=format_hash(fs))
    for what in ("vertices", "entries", "triangles"):
        a.value(f"cap_{what}", 32, "ro", f"capacity: {what} the memories hold", ident, reset=getattr(capacity, what))
    features = (
        BitField("guard", 0, 1, "ro", "the step guard's passes and memories: the guarded modes run", "feature_guard"),
        BitField("lanes", 1, 3, "ro", "K, the datapaths (lanes) each running a share of the nodes: vertex i in lane "
                                      "i mod K, its entries in that lane's share of the entries window "
                                      "(docs/engine.md)", "feature_lanes"),
        BitField("coarse", 4, COARSE_DEGREE_MAX.bit_length(), "ro", "the degree of the guarded step's coarse space "
                 "(its basis and matrix windows and run constants; docs/engine.md); 0: none", "feature_coarse"),
    )
    built = {"guard": int(capacity.guard), "lanes": capacity.lanes, "coarse": capacity.coarse_degree}
    a.add("FEATURES", "ro", "what the build has beside its capacity", features, ident,
          sum(built[f.name] << f.lsb for f in features))

    a.block()
    a.add("CONTROL", "rw", "start, abort, interrupt enable", (
        BitField("start", 0, 1, "w1p", "start a run from the loaded memories and run constants (ignored while "
                                       "running)", "start"),
        BitField("abort", 1, 1, "w1p", "stop a run (soft reset of the controller): state idle, result none; "
                                       "memories and run constants keep their contents", "abort"),
        BitField("irq_enable", 2, 1, "rw", "drive the interrupt line while irq_pending is set", "irq_enable"),
    ), "control")
    a.add("STATUS", "w1c", "state, result, interrupt", (
        BitField("state", 0, 2, "ro", "controller state", "state", codes=STATES),
        BitField("result", 4, 3, "ro", "result of the last run (diverged: saturation_limit reached; stalled: the guarded step's scale "
                                       f"fell below 2^-{SCALE_MAX_SHIFT}; no-mesh: "
                                       "VERTICES is 0; bad-constants: see docs/engine.md)", "result", codes=RESULTS),
        BitField("irq_pending", 8, 1, "w1c", "a run ended (state done); write 1 to clear", "irq_pending"),
        BitField("saturated", 9, 1, "ro", "the last run counted saturation events (SATURATIONS > 0)", "saturated"),
    ), "control")

    a.block()
    res = "results"
    a.value("iterations", ITERATION_BITS, "ro", "iterations of the last run", res)
    a.value("saturations", SATURATION_BITS, "ro", "saturation events of the last run (stops at the maximum)", res)
    a.value("area_error", fs.error.width, "ro", "E_S of the final layout, raw [error]", res, fmt="error")
    a.value("shape_error", fs.error.width, "ro", "E_C of the final layout, raw [error]", res, fmt="error")
    a.value("cycles", 64, "ro", "clock cycles of the last run, START to done", res)
    a.value("energy", energy_width(fs, capacity.entries), "ro", "3·energy of the final layout, raw (energy_raw)", res)

    a.block()
    constants = run_constant_fields(fs, capacity)
    a.add("MODE", "rw", "the run's mode and the fold barrier", _mode_fields(constants), "run constants")
    for c in constants:
        if c.name not in MODE_FIELDS:
            a.value(c.name, c.width, "rw", _constant_text(c.name), "run constants", c.signed, c.fmt)
    return a.registers


def _mode_fields(constants: tuple[WordField, ...]) -> tuple[BitField, ...]:
    """MODE's fields, :data:`MODE_FIELDS` from bit 0 up; ``mode`` names each code's run mode."""
    width = {c.name: c.width for c in constants}
    codes = tuple(m.name for m in sorted(RUN_MODES, key=lambda m: m.code))
    if [m.code for m in sorted(RUN_MODES, key=lambda m: m.code)] != list(range(len(RUN_MODES))):
        raise ValueError("the run modes' codes must be 0, 1, ... (MODE.mode's codes name them in order)")
    fields, lsb = [], 0
    for name in MODE_FIELDS:
        fields.append(BitField(name, lsb, width[name], "rw", _CONSTANT_TEXT[name], name,
                               codes=codes if name == "mode" else ()))
        lsb += width[name]
    return tuple(fields)


_CONSTANT_TEXT = {
    "vertices": "vertices of the loaded mesh (0: no mesh)",
    "entries": "neighbour entries of the loaded mesh",
    "triangles": "triangles of the loaded mesh",
    "mode": "the run mode (docs/guard.md's table; the guarded one: docs/engine-guard.md; on an engine built "
            "without the guard, FEATURES.guard 0, a guarded mode's run ends at once with result bad-constants)",
    "barrier": "1: the fold barrier's entry terms are on",
    "half_spring": "½C raw [spring]",
    "damping": "1 − γ raw [damping]",
    "dt": "the fixed step Δt raw [dt] (mode paper-fixed)",
    "area_reciprocal": "mantissa of 1/ΣA raw [reciprocal] (E_S)",
    "area_shift": "shift of 1/ΣA: E_S = Σ·mantissa·2^-shift",
    "length_reciprocal": "mantissa of 1/Σd raw [reciprocal] (E_C)",
    "length_shift": "shift of 1/Σd",
    "tol_area": "φ_S raw [error]",
    "tol_shape": "φ_C raw [error]",
    "tol_energy": f"ε raw, u{ENERGY_TOL_INT_BITS}.{ENERGY_TOL_FRAC_BITS}",
    "max_iter": "N_max",
    "saturation_limit": "stop as diverged after this many saturation events (0: never)",
    "coarse": "1: the guarded step takes the coarse move (the basis and matrix windows loaded)",
    "matrix_exponent": "the exponent e of the matrix window's scale: its entries are M·2^e",
    "energy_floor": "the stop rule's energy floor, raw as ENERGY: with E_S and E_C within φ, an energy below "
                    "it stops the run as converged (0: no floor)",
}


def _constant_text(name: str) -> str:
    if name.startswith("lane") and name.endswith("_entries"):
        k = name.removeprefix("lane").removesuffix("_entries")
        return (f"neighbour entries of lane {k}'s vertices ({k}, {k}+K, {k}+2K, ...), from the entries window's "
                f"index {k}*CAP_ENTRIES/K on; the lanes' sum is ENTRIES")
    return _CONSTANT_TEXT[name]


def _windows(fs: FormatSet, capacity: EngineCapacity, first_free: int) -> list[MemoryWindow]:
    windows, cursor = [], first_free
    for layout in memory_layouts(fs, capacity).values():
        size = 1 << max(0, (layout.depth * layout.stride - 1).bit_length())
        base = _align(cursor, size)
        windows.append(MemoryWindow(layout.name, base, layout.depth, layout.words, layout.stride, layout.fields,
                                    _WINDOW_TEXT[layout.name]))
        cursor = base + size
    return windows


@dataclass(frozen=True)
class RegisterMap:
    """The engine's bus map; :meth:`build` makes it, ``__post_init__`` checks it."""

    formats: str
    format_hash: int
    capacity: EngineCapacity
    registers: tuple[Register, ...]
    windows: tuple[MemoryWindow, ...]
    _by_offset: dict = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def build(cls, fs: FormatSet, capacity: EngineCapacity) -> "RegisterMap":
        registers = _registers(fs, capacity)
        register_space = 1 << (registers[-1].offset).bit_length()
        return cls(fs.name, format_hash(fs), capacity, tuple(registers),
                   tuple(_windows(fs, capacity, register_space)))

    def __post_init__(self) -> None:
        names = [r.name for r in self.registers]
        if len(set(names)) != len(names):
            raise ValueError(f"register map: duplicate register names {sorted({n for n in names if names.count(n) > 1})}")
        by_offset: dict[int, Register] = {}
        for r in self.registers:
            if r.offset in by_offset:
                raise ValueError(f"register map: {r.name} and {by_offset[r.offset].name} overlap at word {r.offset}")
            by_offset[r.offset] = r
            self._check_fields(r)
        object.__setattr__(self, "_by_offset", by_offset)
        end = max(by_offset) + 1
        for w in sorted(self.windows, key=lambda w: w.base):
            if w.stride & (w.stride - 1) or w.stride < w.words:
                raise ValueError(f"register map: window {w.name}: stride {w.stride} is not a power of two >= "
                                 f"{w.words} words")
            if w.base % w.size:
                raise ValueError(f"register map: window {w.name} at {w.base:#x} is not aligned to its size {w.size:#x}")
            if w.base < end:
                raise ValueError(f"register map: window {w.name} at {w.base:#x} overlaps what ends at {end:#x}")
            end = w.base + w.size
        if end > 1 << 30:
            raise ValueError(f"register map: {end:#x} words do not fit a 32-bit byte address")

    @staticmethod
    def _check_fields(r: Register) -> None:
        if r.access not in ACCESS:
            raise ValueError(f"register map: {r.name}: unknown access {r.access!r}")
        used = 0
        for f in r.fields:
            if f.access not in ACCESS or f.lsb < 0 or f.width < 1 or f.lsb + f.width > BUS_WORD_BITS:
                raise ValueError(f"register map: {r.name}.{f.name} (bits {f.lsb}+{f.width}, {f.access}) does not "
                                 f"fit a 32-bit register")
            if used & f.mask:
                raise ValueError(f"register map: {r.name}.{f.name} overlaps another field")
            used |= f.mask
        if r.reset & ~used:
            raise ValueError(f"register map: {r.name}: reset {r.reset:#x} sets bits outside its fields")

    @property
    def address_bits(self) -> int:
        """The width of the bus's word address ``adr``: enough for the last memory window's last word."""
        return (max(w.base + w.size for w in self.windows) - 1).bit_length()

    # ------------------------------------------------------------------ lookups
    def register(self, name: str) -> Register:
        for r in self.registers:
            if r.name == name:
                return r
        raise KeyError(f"no register {name!r}")

    def window(self, name: str) -> MemoryWindow:
        for w in self.windows:
            if w.name == name:
                return w
        raise KeyError(f"no memory window {name!r}")

    def decode(self, address: int) -> Register | tuple[MemoryWindow, int, int] | None:
        """What a word address selects: a register, ``(window, index, word)``, or ``None`` (a bus error)."""
        if address in self._by_offset:
            return self._by_offset[address]
        for w in self.windows:
            offset = address - w.base
            if 0 <= offset < w.size:
                index, word = divmod(offset, w.stride)
                return (w, index, word) if index < w.depth and word < w.words else None
        return None

    def value_fields(self, value: str) -> list[tuple[Register, BitField]]:
        """The register slices of a value, least significant first."""
        slices = [(r, f) for r in self.registers for f in r.fields if f.value == value]
        if not slices:
            raise KeyError(f"no register holds {value!r}")
        return sorted(slices, key=lambda s: s[1].value_lsb)

    def value_width(self, value: str) -> int:
        return sum(f.width for _, f in self.value_fields(value))

    def encode(self, values: dict[str, int]) -> dict[int, int]:
        """``{word offset: register word}`` writing ``values`` (raw ints) into their registers' slices;
        registers holding other fields too get those as 0."""
        words: dict[int, int] = {}
        for name, raw in values.items():
            width = self.value_width(name)
            lo, hi = (-(1 << (width - 1)), (1 << (width - 1)) - 1) if self.value_fields(name)[0][1].signed \
                else (0, (1 << width) - 1)
            if not lo <= raw <= hi:
                raise ValueError(f"{name} = {raw} does not fit its {width}-bit register")
            bits = raw & ((1 << width) - 1)
            for r, f in self.value_fields(name):
                words[r.offset] = words.get(r.offset, 0) | ((bits >> f.value_lsb) & ((1 << f.width) - 1)) << f.lsb
        return words

    def decode_value(self, value: str, read: dict[int, int]) -> int:
        """The raw value (sign-extended) from ``{word offset: register word}``."""
        slices = self.value_fields(value)
        raw = 0
        for r, f in slices:
            raw |= ((read[r.offset] >> f.lsb) & ((1 << f.width) - 1)) << f.value_lsb
        width = self.value_width(value)
        return raw - (1 << width) if slices[0][1].signed and raw >> (width - 1) else raw

    def reset_words(self) -> dict[int, int]:
        return {r.offset: r.reset for r in self.registers}

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict:
        return {
            "bus": {"protocol": "Wishbone B4 classic", "data_bits": BUS_WORD_BITS, "address": f"{BUS_WORD_BITS}-bit word",
                    "address_bits": self.address_bits,
                    "sel": "all ones", "err": "partial access, unmapped address, write to a read-only register, "
                                              "memory access while running"},
            "version": list(VERSION), "magic": MAGIC, "formats": self.formats, "format_hash": self.format_hash,
            "capacity": asdict(self.capacity), "access": ACCESS, "states": list(STATES), "results": list(RESULTS),
            "registers": [asdict(r) for r in self.registers],
            "windows": [{**asdict(w), "size": w.size,
                         "fields": [{**asdict(f), "lsb": lsb} for f, lsb in zip(w.fields, w.field_lsbs)]}
                        for w in self.windows],
        }

    @classmethod
    def from_dict(cls, d: dict) -> "RegisterMap":
        registers = tuple(Register(**{**r, "fields": tuple(BitField(**{**f, "codes": tuple(f["codes"])})
                                                                   for f in r["fields"])}) for r in d["registers"])
        windows = tuple(MemoryWindow(**{k: v for k, v in w.items() if k != "size"} | {
            "fields": tuple(WordField(**{k: v for k, v in f.items() if k != "lsb"}) for f in w["fields"])})
            for w in d["windows"])
        return cls(d["formats"], d["format_hash"], EngineCapacity(**d["capacity"]), registers, windows)
