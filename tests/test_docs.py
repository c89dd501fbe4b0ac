"""The docs state numbers and tables that must match the code."""

import re
from pathlib import Path

from golden_model.fixed import FORMAT_FIELDS, FormatSet

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_fixed_point_format_table_matches_presets():
    text = (DOCS / "fixed-point.md").read_text()
    rows = {m.group(1): (m.group(2).strip(), m.group(3).strip())
            for m in re.finditer(r"^\| `(\w+)` \| ([^|]+) \|[^|]*\| ([^|]+) \|", text, re.M)}
    default, narrow = FormatSet.preset("default"), FormatSet.preset("narrow")
    for name in FORMAT_FIELDS + ("rsqrt_seed_bits", "rsqrt_newton_steps", "lut_index_bits", "lut_interpolate",
                                 "max_degree"):
        assert rows[name] == (str(getattr(default, name)), str(getattr(narrow, name))), name
    assert rows["rounding"] == (default.rounding.value, narrow.rounding.value)
