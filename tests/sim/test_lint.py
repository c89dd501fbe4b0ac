"""Verilator ``-Wall`` lint of the exported Verilog with the bundle's waiver file: clean, and every
waiver is needed (sim/lint.py)."""

import pytest

from golden_model.engine_spec.image import EngineCapacity
from golden_model.fixed import FormatSet
from sim.cocotb_support import PRIMITIVE_MODELS, prepare_environment, verilog_sources
from sim.engine_run import engine_directory, engine_sources
from sim.export import COMPONENTS
from sim.lint import WAIVER_FILE, WAIVERS, lint_warnings, waiver_text
from support import need_simulator

DEFAULT = FormatSet.preset("default")
#: The engine as the RTL tests build it (their cached export is shared).
CAPACITY = EngineCapacity(64, 512, 128)


def _rules(lines):
    """The rule names of Verilator's warning lines (``%Warning-RULE: ...``)."""
    return {line.split(":")[0].removeprefix("%Warning-") for line in lines if line.startswith("%Warning-")}


def _models(dsp):
    return [f"sim_models/{model.name}" for model in PRIMITIVE_MODELS.get(dsp, [])]


@pytest.fixture(scope="module")
def verilator():
    need_simulator("verilator")
    prepare_environment()


@pytest.mark.parametrize("dsp", [None, "ecp5"], ids=["generic", "ecp5"])
def test_every_component_lints_clean_with_the_waivers(verilator, dsp):
    directory = verilog_sources(DEFAULT, dsp)
    assert (directory / WAIVER_FILE).read_text() == waiver_text()
    for spec in COMPONENTS:
        warnings = lint_warnings([f"{spec.module}.v", *_models(dsp)], top=spec.module,
                                 waivers=directory / WAIVER_FILE, cwd=directory)
        assert warnings == [], (spec.module, warnings[:5])


def test_the_lint_command_the_docs_give_for_a_bundle_is_clean(verilator):
    """docs/hardware.md's ECP5 line, run as written in a bundle's layout: without ``--top-module`` the
    primitives' models the file does not instantiate were tops of their own (MULTITOP), so it failed."""
    import shlex
    import subprocess
    from pathlib import Path

    text = (Path(__file__).parents[2] / "docs" / "hardware.md").read_text()
    line = next(line for line in text.splitlines() if line.startswith("verilator --lint-only") and "sim_models" in line)
    argv = shlex.split(line.split("#")[0])
    directory = verilog_sources(DEFAULT, "ecp5")
    models = sorted(str(p.relative_to(directory)) for p in (directory / "sim_models").glob("*.v"))
    assert models, "the ECP5 export has its primitives' models in sim_models/"
    argv = [a for a in argv if a != "sim_models/*.v"] + models  # the shell's glob
    done = subprocess.run(argv, cwd=directory, capture_output=True, text=True)
    assert done.returncode == 0, (argv, done.stdout[-1500:], done.stderr[-1500:])


@pytest.mark.slow
@pytest.mark.parametrize("dsp", [None, "ecp5"], ids=["generic", "ecp5"])
def test_the_engine_lints_clean_and_every_waiver_is_needed(verilator, dsp):
    """Clean with the waivers; without them each waived rule fires (no waiver is left over from an old
    Verilog), on the files it names."""
    engine_sources(DEFAULT, CAPACITY, dsp=dsp)  # exports once, shared with the RTL tests
    directory = engine_directory(DEFAULT, CAPACITY, dsp)
    if dsp:  # the bundle's layout: the models beside the Verilog
        (directory / "sim_models").mkdir(exist_ok=True)
        for model in PRIMITIVE_MODELS[dsp]:
            (directory / "sim_models" / model.name).write_bytes(model.read_bytes())
    sources = ["springflat_engine.v", *_models(dsp)]
    assert lint_warnings(sources, top="springflat_engine", waivers=directory / WAIVER_FILE, cwd=directory) == []
    unwaived = _rules(lint_warnings(sources, top="springflat_engine", waivers=None, cwd=directory))
    waived = {waiver.rule for waiver in WAIVERS}
    assert unwaived <= waived
    if dsp:  # the flavour with the primitives' models breaks every waived rule
        assert unwaived == waived, waived - unwaived


def test_a_rule_the_waivers_do_not_name_still_fails(verilator, tmp_path):
    """The waivers are per rule: an output nothing drives is still reported, in a file of springflat's name."""
    (tmp_path / "node_update.v").write_text("module bad(input a, output y);\nendmodule\n")
    (tmp_path / WAIVER_FILE).write_text(waiver_text())
    warnings = lint_warnings(["node_update.v"], top="bad", waivers=tmp_path / WAIVER_FILE, cwd=tmp_path)
    assert _rules(warnings) == {"UNDRIVEN"}, warnings


def test_the_waivers_are_the_generated_files_own(verilator, tmp_path):
    """An FPGA engineer's own file linted beside the bundle's with its waiver file keeps every rule: a narrow
    operand widened there is reported, where in springflat's Verilog (the same text under a generated file's
    name) it is waived."""
    text = "module {0}(input [3:0] a, output [7:0] y);\n  assign y = a;\nendmodule\n"
    (tmp_path / WAIVER_FILE).write_text(waiver_text())
    (tmp_path / "mine.v").write_text(text.format("mine"))
    (tmp_path / "node_update.v").write_text(text.format("node_update"))
    assert "WIDTHEXPAND" in _rules(lint_warnings(["mine.v"], top="mine", waivers=tmp_path / WAIVER_FILE,
                                                 cwd=tmp_path))
    assert lint_warnings(["node_update.v"], top="node_update", waivers=tmp_path / WAIVER_FILE, cwd=tmp_path) == []
