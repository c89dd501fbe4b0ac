"""The synthesis flow (``springflat synth``) end to end on small components, so that it cannot rot.

* ECP5: Yosys ``synth_ecp5`` + nextpnr-ecp5 of the narrow-preset step generator (the smallest
  component: ~10 s once the YoWASP WASM is compiled; the first call of each tool on a fresh
  machine adds ~30 s, cached in ``~/.cache/YoWASP``). Every number in the JSON must be the one in
  the tools' own reports in the bundle.
* iCE40: the default-preset rsqrt unit needs more SB_MAC16 than a UP5K has: the plain
  "does not fit" message, exit status 2, and the synthesis numbers are still written.
* Bad requests (unknown target, bad frequency) exit with status 2 and a one-line message.
"""

from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

from sim import cli
from support.ram_traffic import icarus_run, ram_reads, random_ram_traffic
from sim.synth import TARGETS, SynthError, parse_nextpnr_log, parse_yosys_stat
from sim.synth_cli import add_parser

pytestmark = pytest.mark.slow  # simulator builds and place-and-route: minutes


@pytest.fixture(autouse=True)
def synth_registered(monkeypatch):
    """Make sure ``springflat synth`` exists (``sim/cli.py`` registers it with ``add_parser``)."""
    build = cli.build_parser

    def build_with_synth():
        parser = build()
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        if "synth" not in sub.choices:
            add_parser(sub)
        return parser

    monkeypatch.setattr(cli, "build_parser", build_with_synth)


def run(argv, capsys):
    try:
        status = cli.main(argv)
    except SystemExit as exc:  # argparse errors
        status = exc.code
    out, err = capsys.readouterr()
    return status, out, err


def test_ecp5_step_generator_narrow(tmp_path, capsys):
    out_dir = tmp_path / "bundle"
    status, out, err = run(["synth", "--target", "ecp5", "--formats", "narrow", "--components", "step_generator",
                            "--freq", "100", "--out", str(out_dir), "--json"], capsys)
    assert status == 0, err
    report = json.loads(out)
    assert report["target"] == "ecp5" and report["preset"] == "narrow" and report["top"] == "step_generator"
    for key in ("fmax_mhz", "luts", "ffs", "dsps", "brams"):
        assert isinstance(report[key], (int, float)) and not isinstance(report[key], bool), key
    comp = report["components"]["step_generator"]
    for key in ("fmax_mhz", "luts", "ffs", "dsps", "brams"):
        assert comp[key] == report[key]
    assert comp["latency"] > 0 and comp["ii"] == 1
    assert comp["throughput_per_s"] == pytest.approx(comp["fmax_mhz"] * 1e6)

    # The numbers are the tools' own: Yosys stat of the bare module, nextpnr's log after routing.
    stat = json.loads((out_dir / "step_generator.ecp5.stat.json").read_text())
    cells = stat["design"]["num_cells_by_type"]
    assert comp["dsps"] == cells.get("MULT18X18D", 0) >= 1
    assert comp["ffs"] == cells["TRELLIS_FF"] > 0
    assert comp["luts"] == cells.get("LUT4", 0) + 2 * cells.get("CCU2C", 0) > 0
    log = (out_dir / "step_generator_pnr.ecp5.nextpnr.log").read_text()
    lines = re.findall(r"Max frequency for clock '[^']+': ([0-9.]+) MHz", log)
    assert lines and comp["fmax_mhz"] == pytest.approx(float(lines[-1]), abs=0.01)
    assert comp["fmax_mhz"] > 20
    assert comp["critical_path"]["delay_ns"] == pytest.approx(1000 / comp["fmax_mhz"], rel=0.02)
    assert comp["pnr"]["utilisation"]["MULT18X18D"]["used"] == comp["dsps"]
    assert comp["fits"] and not report["does_not_fit"]

    # The handoff bundle.
    for name in ("step_generator.v", "step_generator_pnr.v", "exp_table.hex", "clock.lpf", "clock.sdc",
                 "interface.md", "interface.json", "synth_report.md", "synth_report.json", "reproduce.sh"):
        assert (out_dir / name).is_file(), name
    assert 'FREQUENCY PORT "clk" 100 MHZ;' in (out_dir / "clock.lpf").read_text()
    reproduce = (out_dir / "reproduce.sh").read_text()
    assert "#   springflat synth --target ecp5 --formats narrow" in reproduce and os.access(out_dir / "reproduce.sh", os.X_OK)
    assert reproduce.splitlines()[-3:] == ['"$YOSYS" -q -s step_generator.ecp5.ys',  # the tools on the bundle alone
                                           '"$YOSYS" -q -s step_generator_pnr.ecp5.ys',
                                           '"$NEXTPNR" ' + comp["nextpnr_command"].split(" ", 1)[1]]
    assert "Executing SYNTH_LATTICE pass" in (out_dir / "step_generator.ecp5.yosys.log").read_text()  # its whole log
    assert sorted(p.name for p in (out_dir / "sim_models").iterdir()) == ["DP16KD.v", "MULT18X18D.v", "TRELLIS_FF.v"]
    assert "Fmax" in (out_dir / "interface.md").read_text()
    assert "[ecp5 step_generator] nextpnr" in err  # progress names each tool step


def test_ice40_does_not_fit(tmp_path, capsys):
    """The refusal, one line and the report still written: even the narrow formats' rsqrt unit needs more
    multipliers than an UP5K has (11 SB_MAC16 against 8; the narrow unit synthesises in half the default's
    time)."""
    out_dir = tmp_path / "ice"
    status, out, err = run(["synth", "--target", "ice40", "--formats", "narrow", "--components", "rsqrt_unit",
                            "--out", str(out_dir), "--quiet", "--json"], capsys)
    assert status == 2
    report = json.loads(out)  # the synthesis numbers are still reported
    comp = report["components"]["rsqrt_unit"]
    assert comp["dsps"] > TARGETS["ice40"].capacity["dsps"] and comp["fmax_mhz"] is None and not comp["fits"]
    lines = err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("springflat: error: does not fit iCE40 UP5K SG48: rsqrt_unit:")
    assert "SB_MAC16" in lines[0] and "> 8" in lines[0]
    assert (out_dir / "synth_report.md").is_file()


def test_an_output_that_would_replace_the_formats_file_is_refused_before_any_tool_runs(tmp_path, capsys,
                                                                                        monkeypatch):
    """``--formats out/interface.json --out out``: the bundle's interface.json would replace it. Refused once the
    Verilog is exported, before Yosys and nextpnr (minutes, an hour for the engine), not after them."""
    import sim.synth
    from golden_model.fixed.formats_set import FormatSet

    def no_tool(*args, **kwargs):
        raise AssertionError("a synthesis tool ran")

    monkeypatch.setattr(sim.synth.subprocess, "run", no_tool)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    formats = out_dir / "interface.json"
    formats.write_text(FormatSet.preset("narrow").to_json())
    before = formats.read_bytes()
    status, out, err = run(["synth", "--target", "ice40", "--components", "step_generator", "--formats", str(formats),
                            "--out", str(out_dir), "--quiet"], capsys)
    assert status == 2
    assert err.strip() == f"springflat: error: output '{formats}' is the same file as --formats '{formats}'"
    assert os.listdir(out_dir) == ["interface.json"] and formats.read_bytes() == before


def test_verilog_refuses_an_output_that_would_replace_the_formats_file_before_the_engines_export(tmp_path, capsys,
                                                                                                 monkeypatch):
    """``verilog --formats out/interface.json --out out``: refused before the engine's bundle (the longer half of
    the export); in a directory that holds no earlier bundle, at once, as a file of the user's."""
    import sim.export
    from golden_model.fixed.formats_set import FormatSet
    from sim.synth import BUNDLE_FILES_KEY

    def no_engine(*args, **kwargs):
        raise AssertionError("the engine was exported")

    monkeypatch.setattr(sim.export, "export_engine_bundle", no_engine)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    formats = out_dir / "interface.json"
    formats.write_text(FormatSet.preset("narrow").to_json())
    before = formats.read_bytes()
    status, out, err = run(["verilog", "--formats", str(formats), "--out", str(out_dir)], capsys)
    assert status == 2
    assert err.splitlines()[-1] == (f"springflat: error: --out '{out_dir}' holds interface.json, which this run would "
                                    "replace and no earlier run of this command wrote there: move it, or give a new "
                                    "directory")
    assert os.listdir(out_dir) == ["interface.json"] and formats.read_bytes() == before
    # in an earlier bundle's directory, whose files a new bundle replaces: once the components are exported
    bundle = tmp_path / "bundle"
    bundle.mkdir()
    formats = bundle / "rsqrt_unit.v"  # a bundle's name, the earlier bundle's file
    formats.write_text(FormatSet.preset("narrow").to_json())
    (bundle / "interface.json").write_text(json.dumps({"format_set": {}, "components": {},
                                                      BUNDLE_FILES_KEY: ["interface.json", "rsqrt_unit.v"]}))
    status, out, err = run(["verilog", "--formats", str(formats), "--out", str(bundle)], capsys)
    assert status == 2
    assert err.splitlines()[-1] == f"springflat: error: output '{formats}' is the same file as --formats '{formats}'"
    assert sorted(os.listdir(bundle)) == ["interface.json", "rsqrt_unit.v"]


@pytest.mark.parametrize("argv, message", [
    (["synth", "--target", "xc7"], "invalid choice: 'xc7'"),
    (["synth", "--target", "ecp5", "--freq", "-5"], "frequency"),
    (["synth", "--target", "ecp5", "--components", "fpu"], "unknown component 'fpu'"),
    (["synth", "--target", "ecp5", "--formats", "no-such-preset"], ""),
    (["synth", "--target", "ecp5", "--components", "springflat_engine", "--capacity", "64", "1", "128"],
     "entries must be an int >= 2, got 1"),
    (["synth", "--target", "ecp5", "--components", "springflat_engine", "--capacity", "64", "300"],
     "expected 3 arguments"),
    (["synth", "--target", "ecp5", "--capacity", "64", "300", "128"], "add it to --components"),
    (["synth", "--target", "ecp5", "--seed", "99999999999999999999"], "nextpnr takes a 32-bit seed, -2147483648 to "
                                                                      "2147483647, not 99999999999999999999"),
    (["synth", "--target", "ecp5", "--seed", "one"], "argument --seed: expected an integer, got 'one'"),
    (["synth", "--target", "ecp5", "--baud", "9600"], "--baud sets the board's UART: add --board ulx3s-85f"),
    (["synth", "--board", "ulx3s-85f", "--lanes", "2"], "--lanes applies to --target ecp5 builds"),  # (not --no-guard)
    (["synth", "--target", "ecp5", "--components", "springflat_engine", "--lanes", "2"],
     "--lanes 2 builds the engine without the step guard: add --no-guard"),
    (["synth", "--target", "ecp5", "--lanes", "2", "--no-guard"], "builds springflat_engine: add it to --components"),
    (["synth", "--board", "ulx3s-85f", "--lanes", "2", "--no-guard"], "--lanes applies to --target ecp5 builds"),
    (["synth", "--target", "ecp5", "--lanes", "3"], "argument --lanes: invalid choice: 3"),
    (["verilog", "--lanes", "2"], "--lanes 2 builds the engine without the step guard: add --no-guard"),
])
def test_bad_requests(argv, message, capsys, tmp_path):
    status, out, err = run(argv + ["--out", str(tmp_path / "x")], capsys)
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("springflat: error:") and message in lines[0]


def test_nextpnr_argv_default_is_the_recorded_command_and_strong_adds_the_placer_weights():
    """The default is the command the engine's recorded rows ran (docs/results/synthesis.csv); strong adds
    the heap placer's criticality exponent 4 and timing weight 20, nothing else."""
    from sim.synth import nextpnr_argv

    recorded = ("--85k --package CABGA381 --lpf-allow-unconstrained --json springflat_engine_pnr.ecp5.json "
                "--freq 125 --report springflat_engine_pnr.ecp5.nextpnr.json --timing-allow-fail --router router1 "
                "--seed 1 --log springflat_engine_pnr.ecp5.nextpnr.log --lpf clock.lpf").split()
    assert nextpnr_argv(TARGETS["ecp5"], "springflat_engine_pnr", 125.0, "auto", 1) == recorded
    strong = nextpnr_argv(TARGETS["ecp5"], "springflat_engine_pnr", 125.0, "auto", 1, "strong")
    pairs = {(a, b) for a, b in zip(strong, strong[1:])}
    assert {("--placer-heap-critexp", "4"), ("--placer-heap-timingweight", "20")} <= pairs
    assert sorted(strong) == sorted(recorded + ["--placer-heap-critexp", "4", "--placer-heap-timingweight", "20"])
    with pytest.raises(SynthError, match="unknown placer timing 'fast'"):
        nextpnr_argv(TARGETS["ecp5"], "x", 125.0, "auto", 1, "fast")


def test_nextpnr_argv_router1_ripup_adds_the_timing_driven_ripup_and_nothing_else():
    """``router1-ripup`` is the default command with ``--tmg-ripup`` after ``--router router1``."""
    from sim.synth import nextpnr_argv

    ripup = nextpnr_argv(TARGETS["ecp5"], "springflat_engine_pnr", 125.0, "router1-ripup", 2)
    at = ripup.index("--router")
    assert ripup[at:at + 3] == ["--router", "router1", "--tmg-ripup"]
    assert ripup[:at + 2] + ripup[at + 3:] == nextpnr_argv(TARGETS["ecp5"], "springflat_engine_pnr", 125.0, "auto", 2)


def test_the_placer_timing_is_in_the_bundles_command_line(tmp_path):
    from sim.synth_cli import _command_line

    argv = ["synth", "--target", "ecp5", "--components", "springflat_engine", "--placer-timing", "strong", "--seed", "2"]
    line = _command_line(cli.build_parser().parse_args(argv), tmp_path / "o")
    assert "--placer-timing strong --seed 2" in line
    assert "--placer-timing" not in _command_line(cli.build_parser().parse_args(argv[:5]), tmp_path / "o")


def test_parsers():
    log = """Info: Device utilisation:
Info: \t          TRELLIS_IO:       6/    365     1%
Info: \t          MULT18X18D:       3/    156     1%
Info: \t              ALU54B:       0/     78     0%

Info: Max frequency for clock '$glbnet$clk$TRELLIS_IO_IN': 80.03 MHz (FAIL at 150.00 MHz)
Info: Critical path report for clock '$glbnet$clk$TRELLIS_IO_IN' (posedge -> posedge):
Info:       type curr  total name
Info:   clk-to-q  0.52  0.52 Source core.dt_TRELLIS_FF_Q_4.Q
Info:    routing  1.65  2.17 Net core.dt[4] (118,51) -> (119,58)
Info:                          Sink core.$4_MULT18X18D.B4
Info:                          Defined in:
Info:                               /work/main/hdl/stepgen.py:205
Info:                               /work/main/.venv/lib/python3.11/site-packages/amaranth/lib/memory.py:400
Info:      logic  3.93  6.10 Source core.$4_MULT18X18D.P12
Info:    routing  1.34  7.44 Net core.$4[12] (14,10) -> (14,9)
Info:                          Sink core.dt_sq_TRELLIS_FF_Q_7.M
Info:      setup  0.00  7.44 Source core.dt_sq_TRELLIS_FF_Q_7.M
Info: 4.45 ns logic, 2.99 ns routing

Info: Max frequency for clock '$glbnet$clk$TRELLIS_IO_IN': 134.37 MHz (FAIL at 150.00 MHz)
"""
    r = parse_nextpnr_log(log)
    assert r["fmax_mhz"] == 134.37 and r["timing_met"] is False and r["constraint_mhz"] == 150.0
    assert r["utilisation"] == {"TRELLIS_IO": {"used": 6, "available": 365},
                                "MULT18X18D": {"used": 3, "available": 156}}
    cp = r["critical_path"]
    assert cp["from"] == "core.dt" and cp["to"] == "core.dt_sq" and cp["delay_ns"] == 7.44
    assert cp["through"] == {"MULT18X18D": 1} and cp["rtl"] == ["hdl/stepgen.py:205", "amaranth/lib/memory.py:400"]
    stat = {"design": {"num_cells_by_type": {"LUT4": 10, "CCU2C": 4, "TRELLIS_FF": 7, "MULT18X18D": 2,
                                             "DP16KD": 1}}}
    res = parse_yosys_stat(stat, TARGETS["ecp5"])
    assert (res["luts"], res["ffs"], res["dsps"], res["brams"]) == (18, 7, 2, 1)


@pytest.mark.parametrize("width, depth", [(18, 1024), (9, 2048), (4, 4096), (2, 8192)])
def test_dp16kd_model_reads_what_yosys_maps(tmp_path, width, depth):
    """``sim/models/DP16KD.v`` (the ECP5-flavour benches' block RAM) reads back the words Yosys's
    ``synth_ecp5`` packs into a DP16KD's INITVALs for an inferred ROM: an independent check of
    the packing that :func:`hdl.rom.dp16kd_initvals` writes and the model reads."""
    import shutil
    import subprocess

    from sim.cocotb_support import REPO
    from sim.synth import TOOL, run_tool

    if shutil.which("iverilog") is None:
        pytest.fail("Icarus Verilog (iverilog) is not on PATH")
    rng = np.random.default_rng(width)
    words = rng.integers(0, 1 << width, depth)
    abits = (depth - 1).bit_length()
    (tmp_path / "rom.v").write_text(
        f"module rom(input clk, input [{abits - 1}:0] addr, output reg [{width - 1}:0] q);\n"
        f"  reg [{width - 1}:0] mem [0:{depth - 1}];\n"
        f"  initial $readmemh(\"rom.hex\", mem);\n"
        f"  always @(posedge clk) q <= mem[addr];\nendmodule\n")
    (tmp_path / "rom.hex").write_text("".join(f"{w:x}\n" for w in words))
    code, log = run_tool(TOOL["yosys"], ["-q", "-p", "read_verilog rom.v; synth_ecp5 -top rom; write_verilog -noattr net.v"],
                          tmp_path, "yosys.log")
    assert code == 0, log[-2000:]
    netlist = (tmp_path / "net.v").read_text()
    assert netlist.count("DP16KD #(") == 1 and "LUT4" not in netlist  # one block RAM, nothing else
    (tmp_path / "tb.v").write_text(
        "`timescale 1ns/1ps\nmodule tb; reg clk = 0; reg [%d:0] addr = 0; wire [%d:0] q; integer i;\n"
        "rom dut(.clk(clk), .addr(addr), .q(q));\n"
        "initial begin for (i = 0; i < %d; i = i + 1) begin addr = i; #1 clk = 1; #1 clk = 0; $display(\"%%0d\", q); end "
        "$finish; end\nendmodule\n" % (abits - 1, width - 1, depth))
    subprocess.run(["iverilog", "-g2005", "-o", "tb.vvp", "tb.v", "net.v", str(REPO / "sim" / "models" / "DP16KD.v")],
                   cwd=tmp_path, check=True, capture_output=True)
    out = subprocess.run(["vvp", "-n", "tb.vvp"], cwd=tmp_path, check=True, capture_output=True, text=True).stdout
    read = [int(line) for line in out.split() if line.isdigit()]
    assert read == words.tolist()


@pytest.mark.parametrize("width, depth", [(18, 1024), (9, 2048), (4, 4096), (30, 1024)])
def test_dp16kd_model_is_the_ram_yosys_maps(tmp_path, width, depth):
    """``sim/models/DP16KD.v`` as a RAM: Yosys's ``synth_ecp5`` maps an inferred simple dual-port RAM
    (one write port, one registered read) to DP16KDs, and that netlist on the model reads what a RAM
    reads, so the model's write pins (WE, CE, the 18-bit configuration's byte enables on AD1/AD0) and
    read pins are the device's as Yosys uses them: the ones :class:`hdl.block_ram.BlockRam` drives. A
    read of the row being written at the same clock reads X."""
    from sim.synth import TOOL, run_tool

    abits = (depth - 1).bit_length()
    (tmp_path / "ram.v").write_text(
        f"module ram(input clk, input we, input [{abits - 1}:0] waddr, input [{width - 1}:0] wdata,\n"
        f"           input [{abits - 1}:0] raddr, output reg [{width - 1}:0] q);\n"
        f"  (* no_rw_check *) reg [{width - 1}:0] mem [0:{depth - 1}];\n"
        f"  integer i; initial for (i = 0; i < {depth}; i = i + 1) mem[i] = 0;\n"
        f"  always @(posedge clk) begin if (we) mem[waddr] <= wdata; q <= mem[raddr]; end\nendmodule\n")
    code, log = run_tool(TOOL["yosys"], ["-q", "-p", "read_verilog ram.v; synth_ecp5 -top ram; write_verilog -noattr net.v"],
                          tmp_path, "yosys.log")
    assert code == 0, log[-2000:]
    netlist = (tmp_path / "net.v").read_text()
    assert netlist.count("DP16KD #(") == -(-width // {1024: 18, 2048: 9, 4096: 4}[depth])
    rng = np.random.default_rng(width + depth)
    we, waddr, wdata, raddr = random_ram_traffic(rng, depth, width, 3000)
    ports = ("ram dut(.clk(clk), .we(we), .waddr(waddr[%d:0]), .wdata(wdata[%d:0]), .raddr(raddr[%d:0]), .q(q[%d:0]));"
             % (abits - 1, width - 1, abits - 1, width - 1))
    lines = icarus_run(tmp_path, ["net.v"], "ram", ports, we, waddr, wdata, raddr)
    assert [int(line[-width:], 2) for line in lines] == ram_reads(we, waddr, wdata, raddr, depth, 0)
    # a collision: the row being written is read at the same clock
    we[:] = 1
    raddr[:] = waddr
    lines = icarus_run(tmp_path, ["net.v"], "ram", ports, we, waddr, wdata, raddr)
    assert all("x" in line[-width:] for line in lines[1:])


def test_the_help_names_every_component_synth_takes(capsys):
    """--components' help lists what the option accepts: every exported component and the engine."""
    from sim.export import COMPONENTS
    from sim.top_names import ENGINE_MODULE

    with pytest.raises(SystemExit):
        cli.main(["synth", "--help"])
    text = " ".join(capsys.readouterr().out.split())  # argparse's line wrapping undone
    for module in [c.module for c in COMPONENTS] + [ENGINE_MODULE]:
        assert f"{module}," in text or f"{module} (default" in text, module


def test_the_engine_is_constrained_at_its_own_target_unless_freq_says_otherwise():
    """An engine that meets its 125 MHz must not be reported as missing the components' 150 MHz."""
    from sim.synth import DEFAULT_FREQ, ENGINE, default_freq

    assert default_freq("ecp5", [ENGINE]) == 125.0
    assert default_freq("ecp5", ["springflat_core", ENGINE]) == 125.0
    assert default_freq("ecp5", ["springflat_core"]) == DEFAULT_FREQ["ecp5"] != 125.0
    assert default_freq("ice40", [ENGINE]) == DEFAULT_FREQ["ice40"]


def test_a_bundle_into_an_earlier_ones_directory_leaves_none_of_its_files_that_it_did_not_write(tmp_path):
    """An ice40 synth into an ECP5 bundle's directory kept the ECP5 primitives' models and logs beside generic
    Verilog. The files the earlier bundle's interface.json lists that this run does not write go; every other
    file stays, also one named as a bundle's file (a user's clock.lpf beside a plain Verilog bundle was deleted
    by name); a run whose tools fail leaves the earlier bundle whole, with its logs added. A directory with no
    bundle's list holds the user's files: a bundle that would replace them is refused, and they stay."""
    from sim.outputs import OutputError
    from sim.synth import BUNDLE_FILES_KEY, build_in_place

    out = tmp_path / "bundle"
    earlier = ["sim_models/DP16KD.v", "step_generator.ecp5.ys", "step_generator_pnr.ecp5.nextpnr.log",
               "step_generator.v", "reproduce.sh", "README.md"]
    for name in earlier + ["notes.txt", "my_top.v", "clock.lpf", "synth_report.md"]:  # the last four: the user's
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text("earlier\n")
    mine = tmp_path / "project"  # no bundle here (no bundle's interface.json): files of those names are the user's
    mine.mkdir()
    (mine / "reproduce.sh").write_text("mine\n")
    (mine / "interface.json").write_text('{"mine": 1}\n')

    def failing(directory, shown):  # the Verilog exported, then Yosys failed
        (directory / "interface.json").write_text('{"format_set": {}, "components": {}}\n')
        (directory / "step_generator.ice40.yosys.log").write_text("yosys failed\n")
        raise SynthError("yosys failed")

    (out / "interface.json").write_text(json.dumps({"format_set": {}, "components": {},  # the earlier bundle's
                                                    BUNDLE_FILES_KEY: earlier + ["interface.json", "../x", "/etc/x"]}))
    with pytest.raises(SynthError):
        build_in_place(out, "narrow", failing)
    assert all((out / name).read_text() == "earlier\n" for name in earlier) and (out / "interface.json").is_file()
    assert (out / "step_generator.ice40.yosys.log").is_file()

    def ice40(directory, shown):
        for name in ("step_generator.v", "step_generator.ice40.ys", "reproduce.sh"):
            (directory / name).write_text("new\n")
        (directory / "interface.json").write_text('{"format_set": {}, "components": {}}\n')
        return {}

    build_in_place(out, "narrow", ice40)
    kept = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    assert kept == ["clock.lpf", "interface.json", "my_top.v", "notes.txt", "reproduce.sh", "step_generator.ice40.ys",
                    "step_generator.v", "synth_report.md"]  # sim_models/ too, emptied; the failed run's log too
    assert (out / "step_generator.v").read_text() == "new\n" and (out / "notes.txt").read_text() == "earlier\n"
    assert json.loads((out / "interface.json").read_text())[BUNDLE_FILES_KEY] == [
        "interface.json", "reproduce.sh", "step_generator.ice40.ys", "step_generator.v"]  # what this run wrote
    with pytest.raises(OutputError, match=r"holds interface.json, reproduce.sh, which this run would replace and no "
                                          r"earlier run of this command wrote there"):
        build_in_place(mine, "narrow", ice40)
    assert sorted(p.name for p in mine.iterdir()) == ["interface.json", "reproduce.sh"]
    assert (mine / "reproduce.sh").read_text() == "mine\n"


def test_an_interface_json_that_is_a_fifo_is_not_read_for_an_earlier_bundle(tmp_path):
    """Whether ``--out`` holds an earlier bundle is read from its interface.json: a FIFO of that name would block
    the command; it is no bundle's."""
    import threading

    from sim.synth import earlier_bundle_files

    os.mkfifo(tmp_path / "interface.json")
    found = []
    reader = threading.Thread(target=lambda: found.append(earlier_bundle_files(tmp_path)), daemon=True)
    reader.start()
    reader.join(10)
    if reader.is_alive():  # (unblock the reader, so the thread ends)
        os.close(os.open(tmp_path / "interface.json", os.O_WRONLY | os.O_NONBLOCK))
    assert found == [()]


def test_an_earlier_bundles_list_removes_nothing_outside_its_directory(tmp_path):
    """interface.json is a file in the user's directory: a name in its list through a linked subdirectory
    (models -> ../victim), or with '..', or absolute, named a file elsewhere, which the cleanup removed."""
    from sim.synth import BUNDLE_FILES_KEY, build_in_place, earlier_bundle_files

    victim, out = tmp_path / "victim", tmp_path / "bundle"
    victim.mkdir()
    out.mkdir()
    (victim / "keep.txt").write_text("mine\n")
    (out / "models").symlink_to(victim)
    (out / "old.v").write_text("earlier\n")
    listed = ["models/keep.txt", "../victim/keep.txt", str(victim / "keep.txt"), "old.v", 7, ""]
    (out / "interface.json").write_text(json.dumps({"format_set": {}, "components": {}, BUNDLE_FILES_KEY: listed}))
    assert earlier_bundle_files(out) == ("old.v",)

    def bundle(directory, shown):
        (directory / "new.v").write_text("new\n")
        return {}

    build_in_place(out, "narrow", bundle)
    assert (victim / "keep.txt").read_text() == "mine\n" and not (out / "old.v").exists()


def test_a_board_build_runs_again_into_its_own_out_and_a_users_report_is_refused_before_the_tools(tmp_path):
    """A board build lists no bundle files (no interface.json): its report marks the directory as its own, so a
    second build (another seed) replaces it. A user's synth_report.md, which synth writes after its tools, is
    refused before them: the bundle was built, then thrown away."""
    from sim.board_build import LATE_FILES, REPORT_FILE
    from sim.outputs import OutputError
    from sim.synth import REPORT_FILES, build_in_place

    def board(directory, shown):
        for name in ("springflat_ulx3s.bit", "pins.md"):
            (directory / name).write_text("built\n")
        (directory / REPORT_FILE).write_text('{"board": "ulx3s-85f"}\n')
        return {}

    out = tmp_path / "board"
    build_in_place(out, "default", board, late=LATE_FILES, marker=(REPORT_FILE, "board"))
    build_in_place(out, "default", board, late=LATE_FILES, marker=(REPORT_FILE, "board"))  # (refused, as the user's)
    assert sorted(p.name for p in out.iterdir()) == ["board_report.json", "pins.md", "springflat_ulx3s.bit"]
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "synth_report.md").write_text("my notes\n")
    with pytest.raises(OutputError, match=r"holds synth_report.md, which this run would replace"):
        build_in_place(mine, "default", lambda directory, shown: pytest.fail("the tools ran"), late=REPORT_FILES)
    assert (mine / "synth_report.md").read_text() == "my notes\n"
