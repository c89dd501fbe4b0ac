"""The engine's named Verilator builds (sim/engine_run.py, benchmarks/bench_sim_speed.py): the flags each
changes, and the harness that makes its own clock."""

import os

import pytest

from sim.engine_run import (INTERNAL_CLOCK_BUILDS, VERILATOR_BUILDS, VERILATOR_MAKE_FLAGS, VERILATOR_SPEED_FLAGS,
                            YOSYS_BUILDS, build_flags, simulation_harness)
from sim.top_names import ENGINE_MODULE
from support import REPO

VERILOG = f"""module {ENGINE_MODULE}(clk, rst, bus__cyc, bus__ack);
  input clk;
  input rst;
  input bus__cyc;
  output bus__ack;
endmodule
"""


def test_each_build_changes_one_thing_against_gpi_clock():
    flags, make = build_flags("verilator", "gpi-clock")
    assert (flags, make) == (VERILATOR_SPEED_FLAGS, VERILATOR_MAKE_FLAGS)
    assert build_flags("verilator") == build_flags("verilator", "internal-clock") == VERILATOR_BUILDS["default"]
    assert build_flags("verilator")[0] == flags + ("--timing",)  # the harness's own clock
    assert build_flags("verilator", "threads-2")[0] == flags + ("--threads", "2")
    assert "--x-assign" not in build_flags("verilator", "x-randomised")[0]
    assert "-fprofile-use" in build_flags("verilator", "pgo")[1]
    assert build_flags("icarus", "threads-2") == build_flags("icarus")  # one Icarus build
    with pytest.raises(ValueError, match="unknown Verilator build 'fast'"):
        build_flags("verilator", "fast")


def test_the_internal_clock_harness():
    """With its own clock the harness drives clk (10 ns period) and no longer takes it; otherwise the same."""
    plain, own = simulation_harness(VERILOG), simulation_harness(VERILOG, internal_clock=True)
    assert "  input clk," in plain and "always #" not in plain
    assert "  output reg clk," in own and "  input clk" not in own
    assert "  initial clk = 1'b0;\n  always #5 clk = ~clk;\n" in own
    for text in (plain, own):
        assert ".clk(clk)" in text and ".rst(rst_q)" in text and "always @(posedge clk) rst_q <= rst;" in text
    # the trials of the default: its clock, and its flags on Yosys's netlist or on another build of the engine
    assert INTERNAL_CLOCK_BUILDS == {"default", "internal-clock", "inline-all", "yosys-opt", "delay-lines"}


def test_an_engine_option_build_is_defaults_flags_on_another_export():
    """``delay-lines`` compiles the engine built with ``delay_lines=True`` with ``default``'s flags, exported to a
    directory of its own beside the default build's (the same format set and capacity)."""
    from golden_model.engine_spec.image import DEFAULT_CAPACITY
    from golden_model.fixed import FormatSet
    from sim.engine_run import ENGINE_OPTION_BUILDS, engine_directory

    assert build_flags("verilator", "delay-lines") == VERILATOR_BUILDS["default"]
    assert ENGINE_OPTION_BUILDS["delay-lines"] == {"delay_lines": True}
    fs = FormatSet.load("default")
    plain, other = (engine_directory(fs, DEFAULT_CAPACITY, options=o) for o in (None, ENGINE_OPTION_BUILDS["delay-lines"]))
    assert other.parent == plain.parent and other.name == f"{plain.name}-delay_lines-True"


def test_the_yosys_build_is_defaults_flags_on_yosys_s_optimised_netlist():
    """``yosys-opt`` changes the netlist Verilator compiles, not its flags; the vendor primitives of the ECP5
    netlist have no Verilog for Yosys's ``hierarchy`` to read, so that pairing is refused before any work."""
    from golden_model.engine_spec.image import DEFAULT_CAPACITY
    from golden_model.fixed import FormatSet
    from sim.engine_run import engine_sources

    assert build_flags("verilator", "yosys-opt") == VERILATOR_BUILDS["default"]
    assert "opt -full" in YOSYS_BUILDS["yosys-opt"] and f"-top {ENGINE_MODULE}" in YOSYS_BUILDS["yosys-opt"]
    with pytest.raises(ValueError, match="build 'yosys-opt' runs the generic netlist only, not the ecp5 one"):
        engine_sources(FormatSet.load("default"), DEFAULT_CAPACITY, "verilator", build="yosys-opt", dsp="ecp5")


def test_the_builds_go_where_springflat_build_dir_says(tmp_path):
    """An FPGA engineer's checkout may be read-only, or an installed copy's directory site-packages: the
    variable moves the builds and ccache's store; unset, a checkout keeps them in its build/."""
    import subprocess
    import sys

    code = "import sim.cocotb_support as c; print(c.BUILD_ROOT); print(c.CCACHE_DIR)"
    env = {k: v for k, v in os.environ.items() if k != "SPRINGFLAT_BUILD_DIR"}
    moved = subprocess.run([sys.executable, "-c", code], env={**env, "SPRINGFLAT_BUILD_DIR": str(tmp_path)},
                           capture_output=True, text=True, check=True).stdout.split()
    assert moved == [str(tmp_path / "cocotb"), str(tmp_path / "ccache")]
    default = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                             check=True).stdout.split()
    assert default == [str(REPO / "build" / "cocotb"), str(REPO / "build" / "ccache")]


def test_a_cached_export_is_keyed_by_the_golden_models_sources_too(tmp_path, monkeypatch):
    """The RTL takes its tables and widths from golden_model (the exp table, the rsqrt seeds, the energy check's
    widths): an edit there kept the old Verilog, and a CI cache kept across commits checked the old design."""
    import shutil

    import sim.cocotb_support as support_module
    from golden_model.fixed import FormatSet

    for part in ("hdl", "golden_model"):
        shutil.copytree(REPO / part, tmp_path / part, ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "sim").mkdir()
    for name in ("export.py", "lint.py", "engine_run.py"):
        shutil.copy(REPO / "sim" / name, tmp_path / "sim" / name)
    monkeypatch.setattr(support_module, "REPO", tmp_path)
    fs = FormatSet.preset("default")
    keys = [support_module._formats_key(fs)]
    for edited in ("golden_model/fixed/exp_table.py", "hdl/rsqrt.py", "sim/engine_run.py"):
        with open(tmp_path / edited, "a") as source:
            source.write("\n# edited\n")
        keys.append(support_module._formats_key(fs))
    assert len(set(keys)) == len(keys), keys
    assert support_module._formats_key(fs) == keys[-1]  # (and nothing else moves it)


def test_a_failed_build_says_what_the_tool_said_and_keeps_its_log(tmp_path):
    """The message pointed at a log in a temporary directory already removed, and said nothing of the tool's
    own error: its last line is in the message, and the log is kept in the build directory."""
    import re
    import subprocess

    from support import SPRINGFLAT

    tools = tmp_path / "bin"
    tools.mkdir()
    (tools / "iverilog").write_text("#!/bin/sh\necho 'iverilog: springflat_core.v:7: syntax error' >&2\nexit 1\n")
    (tools / "iverilog").chmod(0o755)
    env = {**os.environ, "PATH": f"{tools}:{os.environ['PATH']}", "SPRINGFLAT_BUILD_DIR": str(tmp_path / "build")}
    done = subprocess.run([SPRINGFLAT, "rtl-check", "surf1", "--sim", "icarus"], capture_output=True, text=True,
                          env=env, timeout=300)
    assert done.returncode == 2, done.stderr
    error = done.stderr.splitlines()[-1]
    found = re.fullmatch(r"springflat: error: building springflat_core for icarus failed \(.*\): iverilog: "
                         r"springflat_core.v:7: syntax error; the log: (\S+)", error)
    assert found, error
    assert "syntax error" in open(found[1]).read()
