"""The components' parameter checks (``hdl/parameters.py``): one wording, and the components that use them."""

import pytest
from amaranth.hdl import unsigned

from golden_model.engine_spec.image import EngineCapacity
from golden_model.fixed import FormatSet
from hdl.block_ram import BlockRam
from hdl.coarse_coefficients import CoarseCoefficients
from hdl.coarse_node import CoarseNode
from hdl.engine import SpringflatEngine
from hdl.fifo import LutFIFO, SlicedFIFO
from hdl.parameters import check_in_range, check_int, check_power_of_two
from hdl.saturation_tally import SaturationTally
from hdl.wishbone import Signature
from support import refused_components


@pytest.mark.parametrize("value, minimum", [(1, 1), (7, 7), (2**40, 2)])
def test_an_int_at_or_above_its_minimum_is_taken(value, minimum):
    check_int("n", value, minimum)


@pytest.mark.parametrize("value, minimum", [(0, 1), (6, 7), (True, 1), (2.0, 1), ("2", 1), (None, 1)])
def test_anything_else_is_refused_naming_the_parameter_and_its_minimum(value, minimum):
    with pytest.raises(ValueError, match=rf"^n must be an int >= {minimum}, not {value!r}$".replace("(", r"\(")):
        check_int("n", value, minimum)


@pytest.mark.parametrize("value, taken", [(2, True), (1024, True), (1, False), (6, False), (0, False), (True, False),
                                          (4.0, False)])
def test_a_power_of_two_is_one_of_at_least_two(value, taken):
    if taken:
        check_power_of_two("depth", value)
    else:
        with pytest.raises(ValueError, match=rf"^depth must be a power of two >= 2, not {value!r}$"):
            check_power_of_two("depth", value)


@pytest.mark.parametrize("value, taken", [(1, True), (4, True), (0, False), (5, False), (True, False), (3.0, False)])
def test_an_int_in_its_range_is_taken(value, taken):
    if taken:
        check_in_range("degree", value, 1, 4)
    else:
        with pytest.raises(ValueError, match=rf"^degree must be an int in 1..4, not {value!r}$"):
            check_in_range("degree", value, 1, 4)


def test_the_components_refuse_through_the_checks():
    with refused_components():
        with pytest.raises(ValueError, match=r"^BlockRam read_ports must be an int >= 1, not 0$"):
            BlockRam(unsigned(8), 16, read_ports=0)
        with pytest.raises(ValueError, match=r"^count_bits must be an int >= 1, not 0$"):
            SaturationTally({"a": 1, "b": 1}, count_bits=0)
        with pytest.raises(ValueError, match=r"^entry_bank_depth must be a power of two >= 2, not 96$"):
            SpringflatEngine(FormatSet.preset("default"), EngineCapacity(64, 512, 128), entry_bank_depth=96)
        with pytest.raises(ValueError, match=r"^SlicedFIFO depth must be a power of two >= 2, not 0$"):
            SlicedFIFO(width=8, depth=0, slice_bits=4)
        with pytest.raises(ValueError, match=r"^LutFIFO width must be an int >= 1, not True$"):
            LutFIFO(width=True, depth=4)
        with pytest.raises(ValueError, match=r"^event source 'a'.s width must be an int >= 1, not 2.0$"):
            SaturationTally({"a": 2.0, "b": 1}, count_bits=4)
        for unit in (CoarseNode, CoarseCoefficients):
            with pytest.raises(ValueError, match=r"^degree must be an int in 1..4, not 5$"):
                unit("default", 5, 100)
            with pytest.raises(ValueError, match=r"^max_nodes must be an int >= 1, not 0$"):
                unit("default", 3, 0)
            with pytest.raises(TypeError, match=rf"^{unit.__name__} needs a FormatSet or a preset name, not 3$"):
                unit(3, 3, 10)
    with pytest.raises(ValueError, match=r"^addr_width must be an int >= 1, not 0$"):
        Signature(addr_width=0)
