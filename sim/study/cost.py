"""The RTL cost model of a study: bits, DSP blocks and ROM bits of a format set."""

from __future__ import annotations

from dataclasses import dataclass

from golden_model.fixed.dsp import dsp_blocks as _dsp_blocks
from golden_model.fixed.formats_set import FormatSet
from golden_model.study.knobs import DATAPATH_FIELDS

#: The units whose multipliers the RTL instantiates (the controller's are not in the RTL).
RTL_UNITS = ("node_update", "rsqrt", "step_generator")


def multipliers(fs: FormatSet) -> list[tuple[str, int, int, int, int]]:
    """``(name, width_a, width_b, count, dsp_blocks_each)`` for every multiplication of the RTL.

    ``fs.products()`` of the node datapath, the rsqrt unit and the step generator, each split
    into 18×18 partial products by the RTL's own rule (:func:`golden_model.fixed.dsp.dsp_blocks`:
    a partial product with a 1-bit slice is a multiplexer, not a DSP block).
    """
    return [(p.name, p.a.width, p.b.width, p.count, _dsp_blocks(p.a, p.b))
            for p in fs.products() if p.unit in RTL_UNITS]


def dsp_blocks(fs: FormatSet) -> int:
    """18×18 DSP blocks of the node datapath (with its rsqrt unit) and the step generator."""
    return sum(count * each for _, _, _, count, each in multipliers(fs))


def datapath_bits(fs: FormatSet) -> int:
    """Sum of the widths of the node-datapath formats (:data:`DATAPATH_FIELDS`)."""
    return sum(getattr(fs, f).width for f in DATAPATH_FIELDS)


def rom_bits(fs: FormatSet) -> int:
    """rsqrt seed ROM (entries × seed fraction bits) + exp LUT (2**n + 1 entries × lut_entry width)."""
    cfg = fs.rsqrt_config()
    return cfg.seed_table_size * cfg.seed_frac_bits + ((1 << fs.lut_index_bits) + 1) * fs.lut_entry.width


@dataclass(frozen=True)
class Cost:
    """Hardware cost estimate of a FormatSet."""

    total_bits: int
    dsp: int
    rom_bits: int

    def key(self, metric: str = "bits") -> tuple[int, int, int]:
        """Lexicographic comparison key: ``bits`` or ``dsp`` first."""
        if metric == "dsp":
            return (self.dsp, self.total_bits, self.rom_bits)
        return (self.total_bits, self.dsp, self.rom_bits)

    def value(self, metric: str = "bits") -> int:
        return self.dsp if metric == "dsp" else self.total_bits


def cost(fs: FormatSet) -> Cost:
    return Cost(datapath_bits(fs), dsp_blocks(fs), rom_bits(fs))
