"""Generated blocks in docs/ (sim.docgen) are in step with the code, and the results file they read (sim.results)."""

import csv
import json
import re

import pytest

from sim import results
from sim.docgen import BLOCK, DOCS, GENERATORS, render, stale_blocks


#: Blocks whose generator elaborates the RTL or sweeps a unit's whole domain: seconds each.
SLOW_BLOCKS = {"node-update-flip-flops", "rsqrt-accuracy", "unit-figures"}


def _blocks() -> list:
    return [pytest.param(path.name, m.group("name"), marks=[pytest.mark.slow] if m.group("name") in SLOW_BLOCKS else [])
            for path in sorted(DOCS.glob("*.md")) for m in BLOCK.finditer(path.read_text(encoding="utf-8"))]


@pytest.mark.parametrize("doc, name", _blocks(), ids=lambda v: v)
def test_every_generated_block_in_the_docs_is_current(doc, name):
    text = (DOCS / doc).read_text(encoding="utf-8")
    for m in BLOCK.finditer(text):
        if m.group("name") == name:
            assert render(m.group(0)) == m.group(0), f"{doc}: block {name} is out of step: python -m sim.docgen"


def test_every_generator_has_a_block():
    assert sorted(GENERATORS) == sorted({p.values[1] for p in _blocks()})


def test_a_stale_block_is_found_and_rewritten(tmp_path):
    text = "intro\n<!-- generated: run-modes -->\nan old table\n<!-- end generated -->\nafter\n"
    fresh = render(text)
    assert "an old table" not in fresh and "`momentum-guarded`" in fresh
    assert fresh.startswith("intro\n") and fresh.endswith("<!-- end generated -->\nafter\n")
    assert render(fresh) == fresh
    assert len(BLOCK.findall(fresh)) == 1
    (tmp_path / "x.md").write_text(text)
    assert stale_blocks(tmp_path) == ["x.md: run-modes"]
    (tmp_path / "x.md").write_text(fresh)
    assert stale_blocks(tmp_path) == []


def test_an_unknown_block_is_named():
    with pytest.raises(KeyError, match="no generator for block 'nonsense'"):
        render("<!-- generated: nonsense -->\nx\n<!-- end generated -->\n")


# ----------------------------------------------------------------------------- tables from the code


def test_the_format_table_follows_a_changed_preset(monkeypatch):
    """A table is the code's, not a copy: change a preset and the generated text changes with it."""
    from golden_model.fixed import FormatSet
    from sim import doc_tables

    real = FormatSet.preset
    monkeypatch.setattr(doc_tables, "_preset",
                        lambda name: real(name).replace(inv_mass="u3.14") if name == "default" else real(name))
    table = doc_tables.format_presets()
    assert "| `inv_mass` | u3.14 | 17 | u3.15 | 18 |" in table
    assert "| `rsqrt_seed_bits` | 12 |  | 10 |  |" in table


def test_the_unit_table_counts_the_elaborated_multipliers():
    """``_mult18x18d`` counts the ECP5 multiplier instances the RTL elaborates to (as ``tests/hdl/test_dsp_cost.py``)."""
    from golden_model.fixed import FormatSet
    from hdl import RsqrtUnit, StepGenerator
    from sim.doc_tables import _mult18x18d

    fs = FormatSet.preset("narrow")
    assert _mult18x18d(StepGenerator(fs)) == 3
    assert _mult18x18d(StepGenerator(fs.replace(lut_interpolate=False))) == 1
    assert _mult18x18d(RsqrtUnit(fs.replace(rsqrt_newton_steps=0))) == 0


# ----------------------------------------------------------------------------- the results file

REPORT = {
    "target": "ecp5", "preset": "default", "freq_mhz": 150.0,
    "command": "springflat synth --target ecp5 --components springflat_core,springflat_engine --out x",
    "components": {
        "springflat_core": {"latency": 102, "ii": 1, "luts": 8903, "ffs": 25158, "dsps": 91, "brams": 8, "lutram": 688,
                            "fmax_mhz": 151.256, "does_not_fit": [],
                            "critical_path": {"summary": "a -> b: 6.61 ns"},
                            "nextpnr_command": "nextpnr-ecp5 --json x.json --seed 3 --router router1"},
        "springflat_engine": {"latency": None, "ii": None, "luts": 12558, "ffs": 32622, "dsps": 105, "brams": 226,
                              "lutram": 0, "fmax_mhz": None, "critical_path": None,
                              "does_not_fit": ["226 block RAMs (DP16KD) > 208"],
                              "capacity": {"vertices": 3328, "entries": 19968, "triangles": 6656}},
    },
}


def test_rows_from_a_synth_report():
    core, engine = results.rows_from_report(REPORT, "2026-11-26")
    assert (core["component"], core["seed"], core["fmax_mhz"], core["lut4"], core["lutram"], core["latency"],
            core["capacity"], core["critical_path"]) == ("springflat_core", "3", "151.26", "8903", "688", "102", "",
                                                         "a -> b: 6.61 ns")
    assert (engine["capacity"], engine["seed"], engine["fmax_mhz"], engine["latency"], engine["bram"],
            engine["critical_path"]) == ("3328/19968/6656", "", "", "", "226", "not placed: 226 block RAMs (DP16KD) > 208")
    assert core["command"] == engine["command"] == REPORT["command"] and core["date"] == "2026-11-26"


def test_a_new_run_replaces_its_configuration_only():
    old = results.rows_from_report(REPORT, "2026-11-20")
    other = dict(old[0], seed="1", fmax_mhz="140.00")
    new = results.rows_from_report(REPORT, "2026-11-26")
    merged = results.record([*old, other], new[:1])
    assert sorted((r["component"], r["seed"], r["date"]) for r in merged) == [
        ("springflat_core", "1", "2026-11-20"), ("springflat_core", "3", "2026-11-26"),
        ("springflat_engine", "", "2026-11-20")]


def test_record_writes_the_file_and_refuses_a_non_report(tmp_path, monkeypatch, capsys):
    path = tmp_path / "synthesis.csv"
    results.write_rows([], path)
    monkeypatch.setattr(results, "RESULTS", path)
    report = tmp_path / "synth_report.json"
    report.write_text(json.dumps(REPORT))
    assert results.main(["record", str(report), "--date", "2026-11-26"]) == 0
    assert [r["component"] for r in results.read_rows(path)] == ["springflat_core", "springflat_engine"]
    assert "recorded ecp5 default springflat_core - seed 3: 151.26" in capsys.readouterr().out
    report.write_text("{}")
    assert results.main(["record", str(report)]) == 2
    assert capsys.readouterr().err.startswith(f"sim.results: error: {report}: not a springflat synth report")
    assert len(results.read_rows(path)) == 2


def test_the_results_file_is_well_formed():
    """One row per configuration, each with its date, the command that produced it, and an Fmax or the
    reason it was not placed."""
    rows = results.read_rows()
    keys = [tuple(r[k] for k in results.KEY) for r in rows]
    assert len(keys) == len(set(keys))
    for r in rows:
        assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", r["date"]), r
        assert r["command"].startswith("springflat synth --target " + r["target"]), r
        assert r["fmax_mhz"] or r["critical_path"].startswith("not placed: "), r
        assert (r["component"] == "springflat_engine") == bool(r["capacity"]), r
    with results.RESULTS.open(newline="", encoding="utf-8") as f:
        assert tuple(next(csv.reader(f))) == results.FIELDS
