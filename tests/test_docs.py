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


def test_study_doc_states_the_presets_costs():
    from golden_model.study import cost

    text = " ".join((DOCS / "study.md").read_text().split())
    m = re.search(r"presets: `default` (\d+) bits, (\d+) DSP, ([\d ]+) ROM bits; `narrow` (\d+) bits, (\d+) DSP, "
                  r"([\d ]+) ROM bits", text)
    assert m, "docs/study.md no longer states the presets' costs"
    stated = [int(g.replace(" ", "")) for g in m.groups()]
    actual = [v for name in ("default", "narrow") for v in cost(FormatSet.preset(name)).key("bits")]
    assert stated == actual


def test_study_doc_lists_the_signal_classes():
    from golden_model.study import SIGNAL_CLASSES

    text = (DOCS / "study.md").read_text()
    rows = {m.group(1): tuple(f.strip() for f in m.group(2).split(","))
            for m in re.finditer(r"^\| `(\w+)` \| ([\w, ]+) \|", text, re.M)}
    assert {k: rows.get(k) for k in SIGNAL_CLASSES} == SIGNAL_CLASSES
