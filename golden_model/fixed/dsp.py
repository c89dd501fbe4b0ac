"""How a multiplication is split into 18×18 DSP partial products: the rule the RTL builds and the study costs.

``hdl.fixedpoint.dsp_operands`` slices a multiply's operands with :func:`dsp_chunks`, and
``hdl.dsp.registered_product`` maps a partial product onto a DSP block only when
:func:`is_dsp_block` says so; ``sim.study.cost`` counts DSP blocks of a format set with
:func:`dsp_blocks` over :meth:`~golden_model.fixed.FormatSet.products`.  One rule, so the
study's cost is the RTL's (``tests/hdl/test_hdl_node_update.py`` counts the ``MULT18X18D``
instances of the elaborated RTL against it).

The rule: an unsigned product (both operands unsigned) is cut into 18-bit unsigned slices.
In a signed product an unsigned slice is zero-extended into a signed 18-bit operand, so the
low slices are 17 bits and only a signed operand's top slice (its sign) takes 18.  Every
pair of slices is one partial product; a pair with a 1-bit slice is a multiplexer in the
fabric, not a DSP block.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["DSP_WIDTH", "Operand", "Chunk", "dsp_chunks", "dsp_partial_products", "is_dsp_block", "dsp_blocks"]

DSP_WIDTH = 18
"""Operand width of one DSP multiplier: ECP5 ``MULT18X18D`` is 18×18 signed (iCE40's
``SB_MAC16`` is 16×16, so an 18×18 partial product takes several)."""


class Operand(NamedTuple):
    """A multiplier operand as the hardware holds it: ``width`` bits, two's complement if ``signed``."""

    width: int
    signed: bool

    @classmethod
    def of(cls, fmt) -> "Operand":
        """The operand holding raw values of a :class:`~golden_model.fixed.Format`."""
        return cls(fmt.width, fmt.signed)


class Chunk(NamedTuple):
    """Bits ``lo .. hi - 1`` of an operand, read as signed if ``signed`` (the operand's top, sign slice)."""

    lo: int
    hi: int
    signed: bool

    @property
    def width(self) -> int:
        return self.hi - self.lo


def dsp_chunks(op: Operand, signed_product: bool, width: int = DSP_WIDTH) -> list[Chunk]:
    """Slices of ``op`` with ``value == sum(chunk << lo)``, each fitting one ``width``-bit DSP operand."""
    step = width - 1 if signed_product else width
    chunks, lo = [], 0
    while lo < op.width:
        top_signed = op.signed and op.width - lo <= width  # the rest fits one signed slice
        hi = op.width if top_signed else min(op.width, lo + step)
        chunks.append(Chunk(lo, hi, top_signed))
        lo = hi
    return chunks


def dsp_partial_products(a: Operand, b: Operand, width: int = DSP_WIDTH) -> list[tuple[Chunk, Chunk]]:
    """Every partial product of ``a * b``: ``a * b == sum((a_chunk * b_chunk) << (a_chunk.lo + b_chunk.lo))``."""
    signed_product = a.signed or b.signed
    return [(ca, cb) for ca in dsp_chunks(a, signed_product, width) for cb in dsp_chunks(b, signed_product, width)]


def is_dsp_block(width_a: int, width_b: int) -> bool:
    """Whether a partial product of these slice widths is a DSP block (a 1-bit slice makes it a multiplexer)."""
    return min(width_a, width_b) > 1


def dsp_blocks(a: Operand, b: Operand, width: int = DSP_WIDTH) -> int:
    """DSP blocks one ``a * b`` takes."""
    return sum(is_dsp_block(ca.width, cb.width) for ca, cb in dsp_partial_products(a, b, width))
