"""The study's DSP cost is the RTL's: the golden model's split rule against the elaborated ``MULT18X18D`` instances.

``golden_model.fixed.dsp`` holds the one rule by which ``hdl.fixedpoint.dsp_operands`` slices a
multiply and ``hdl.dsp.registered_product`` decides DSP block or fabric multiplexer;
``FormatSet.products()`` lists every multiplication with the operands the RTL holds. These tests
elaborate the RTL for ECP5 and count its DSP blocks per unit, so a product missing from the list,
an operand of the wrong width or a rule that differs from the RTL's shows as a count mismatch.
"""

import re

import pytest
from amaranth.back import rtlil

from golden_model.fixed import FormatSet
from golden_model.fixed.dsp import Operand, dsp_blocks, dsp_chunks, dsp_partial_products
from sim.study.cost import cost
from hdl import NodeUpdate, RsqrtUnit, StepGenerator
from hdl.dsp import ECP5
from support import REPO

DEFAULT, NARROW = FormatSet.preset("default"), FormatSet.preset("narrow")

FORMAT_SETS = {
    "default": DEFAULT,
    "narrow": NARROW,
    # two Newton steps (the second squares a full-width y), no interpolation, wider operands
    "narrow_two_newton_steps_no_interpolation": NARROW.replace(rsqrt_newton_steps=2, lut_interpolate=False),
    "narrow_wider": NARROW.replace(delta="s3.16", position="s10.16", face_edge="s11.16", velocity="s3.16", spring="s2.17",
                                   inv_mass="u3.16", dt="u0.20", half_dt_sq="u0.19", lut_entry="u0.20"),
}


def mult18x18d(component) -> int:
    """``MULT18X18D`` instances in the component elaborated for ECP5."""
    return len(re.findall(r"^\s*cell \\MULT18X18D ", rtlil.convert(component, platform=ECP5), re.M))


def blocks_per_unit(fs: FormatSet) -> dict[str, int]:
    """DSP blocks of the RTL's units by the golden model's rule (the controller is not in the RTL)."""
    out = dict.fromkeys(("node_update", "rsqrt", "step_generator"), 0)
    for p in fs.products():
        if p.unit != "controller":
            out[p.unit] += p.count * dsp_blocks(p.a, p.b)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", FORMAT_SETS)
def test_dsp_cost_counts_the_rtls_dsp_blocks(name):
    fs = FORMAT_SETS[name]
    units = blocks_per_unit(fs)
    assert mult18x18d(RsqrtUnit(fs)) == units["rsqrt"]
    assert mult18x18d(StepGenerator(fs)) == units["step_generator"]
    assert mult18x18d(NodeUpdate(fs)) == units["node_update"] + units["rsqrt"]
    assert cost(fs).dsp == units["node_update"] + units["rsqrt"] + units["step_generator"]


def test_preset_dsp_counts():
    """The counts ``docs/hardware.md`` states (``tests/test_docs.py`` checks that it does)."""
    assert blocks_per_unit(DEFAULT) == {"node_update": 76, "rsqrt": 12, "step_generator": 3}
    assert blocks_per_unit(NARROW) == {"node_update": 25, "rsqrt": 12, "step_generator": 3}
    assert (cost(DEFAULT).dsp, cost(NARROW).dsp) == (91, 40)


def test_split_rule():
    # unsigned product: 18-bit slices
    assert dsp_chunks(Operand(40, False), signed_product=False) == [(0, 18, False), (18, 36, False), (36, 40, False)]
    # signed product: unsigned slices of 17 bits; the signed top slice takes up to 18
    assert dsp_chunks(Operand(35, True), signed_product=True) == [(0, 17, False), (17, 35, True)]
    assert dsp_chunks(Operand(18, False), signed_product=True) == [(0, 17, False), (17, 18, False)]
    # an unsigned 18-bit operand times a signed one: 17 x 18 is a DSP block, the 1-bit slice a multiplexer
    assert len(dsp_partial_products(Operand(18, False), Operand(18, True))) == 2
    assert dsp_blocks(Operand(18, False), Operand(18, True)) == 1
    assert dsp_blocks(Operand(26, True), Operand(26, True)) == 4


def test_dsp_width_is_defined_once():
    """The study and the RTL read the one ``DSP_WIDTH`` (``golden_model/fixed/dsp.py``)."""
    root = REPO
    defining = [str(p.relative_to(root)) for d in ("golden_model", "hdl", "sim") for p in (root / d).rglob("*.py")
                if re.search(r"^DSP_WIDTH\s*=", p.read_text(), re.M)]
    assert defining == ["golden_model/fixed/dsp.py"]
