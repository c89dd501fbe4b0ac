"""springflat verilog: files, stable port names, and an interface description that matches the Verilog."""

import json
import re
import subprocess
from pathlib import Path

import pytest

from golden_model.fixed import FormatSet
from support import REPO, SPRINGFLAT, refused_components


@pytest.fixture(scope="module")
def exported_run(tmp_path_factory):
    """The bundle's directory and what the command printed."""
    out = tmp_path_factory.mktemp("verilog")
    proc = subprocess.run([SPRINGFLAT, "verilog", "--formats", "narrow", "--out", out], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return out, proc.stdout


@pytest.fixture(scope="module")
def exported(exported_run):
    return exported_run[0]


def test_the_command_names_every_file_it_wrote(exported_run):
    out, stdout = exported_run
    named = set(re.findall(r"(?:^|, | )(" + re.escape(str(out)) + r"/[^\s,:;]+)", stdout, re.M))
    assert named == {str(p) for p in out.iterdir() if p.is_file()}


def test_the_bundles_readme_says_what_every_file_is(exported):
    """README.md lists every file the command wrote, each with what it is, and names the top."""
    readme = (exported / "README.md").read_text()
    listed = re.findall(r"^\| `([^`]+)` \| (.+) \|$", readme, re.M)
    assert sorted(name for name, _ in listed) == sorted(p.name for p in exported.iterdir() if p.is_file())
    assert all(what.strip() for _, what in listed)
    assert "The top for a system is `springflat_engine` in `springflat_engine.v`" in readme
    assert not [what for _, what in listed if re.search(r"(?<!\\)\|", what)]  # a '|' in a cell is escaped


def test_the_bundle_constrains_its_clock_at_the_engines_125_mhz(exported):
    """An FPGA tool given the bundle gets the clock the engine is timed for: 125 MHz, an 8 ns period."""
    assert (exported / "clock.sdc").read_text() == "create_clock -period 8.000 -name clk [get_ports clk]\n"


def _verilog_ports(text: str, module: str) -> dict[str, tuple[str, int]]:
    body = text[text.index(f"module {module}("):]
    body = body[:body.index("endmodule")]
    ports = {}
    for direction, msb, name in re.findall(r"^\s*(input|output)\s+(?:wire\s+|reg\s+)?(?:\[(\d+):0\]\s+)?\\?([\w$]+)\s*;",
                                           body, re.M):
        ports[name] = (direction, int(msb) + 1 if msb else 1)
    return ports


@pytest.mark.slow
def test_files_and_interface_match_the_verilog(exported):
    interface = json.loads((exported / "interface.json").read_text())
    assert interface["format_set"]["name"] == "narrow"
    assert FormatSet.from_dict(interface["format_set"]) == FormatSet.preset("narrow")
    for module, info in interface["components"].items():
        text = (exported / f"{module}.v").read_text()
        ports = _verilog_ports(text, module)
        assert ports == {p["name"]: (p["direction"], p["width"]) for p in info["ports"]}, module
        assert info["initiation_interval"] == (2 if module.endswith("_ii2") else 1) and info["latency"] > 0
    core = interface["components"]["springflat_core"]
    names = {p["name"] for p in core["ports"]}
    assert {"entries__payload", "entries__valid", "entries__ready", "results__payload", "results__valid",
            "results__ready", "errors__payload", "step_load__payload", "step", "measure", "half_spring",
            "damping"} <= names
    fields = {f["field"]: f for f in core["payload_layouts"]["entries__payload"]}
    width = {p["name"]: p["width"] for p in core["ports"]}["entries__payload"]
    assert sum(f["width"] for f in fields.values()) == width  # the fields tile the port
    assert fields["first"]["lsb"] == 0 and fields["node.position.x"]["format"] == "position s10.14"
    for module, rom, image in [("rsqrt_unit", "seed_rom", "rsqrt_seed.hex"), ("step_generator", "exp_rom",
                                                                            "exp_table.hex")]:
        inlined = {int(a): int(v, 16) for a, v in re.findall(rf"^\s*{rom}\[(\d+)\] = \d+'h([0-9a-f]+);",
                                                          (exported / f"{module}.v").read_text(), re.M)}
        words = [int(line, 16) for line in (exported / image).read_text().splitlines() if not line.startswith("//")]
        assert words == [inlined[a] for a in range(len(inlined))], image  # the ROM as $readmemh would fill it
    sources = re.findall(r'\(\* src = "([^"]*)" \*\)', (exported / "springflat_core.v").read_text())
    assert sources and not [s for s in sources if str(REPO) in s or s.startswith("/")]  # no paths of this machine
    assert any(s.startswith("hdl/") for s in sources) and any(s.startswith("amaranth/") for s in sources)
    assert "| `entries__payload` | input |" in (exported / "interface.md").read_text()


def test_the_board_builds_rtlil_names_its_sources_as_the_verilog_does():
    """The board build's RTLIL (what Yosys reads, and its debug Verilog) gets the same relative ``src``
    names as the bundles' Verilog, in both attribute syntaxes; a path outside the roots stays."""
    import contextlib

    from amaranth import hdl
    from sim.export import relative_sources

    stepgen = Path(REPO) / "hdl" / "stepgen.py"
    memory = Path(hdl.__file__).parent.parent / "lib" / "memory.py"
    stdlib = Path(contextlib.__file__)
    rtlil = (f'attribute \\src "{stepgen}:190|{memory}:400"\n  attribute \\src "/elsewhere/x.py:3"\n'
             f'  attribute \\src "{stdlib}:141"\n')
    verilog = f'(* src = "{stepgen}:190" *)\n'
    assert relative_sources(rtlil) == ('attribute \\src "hdl/stepgen.py:190|amaranth/lib/memory.py:400"\n'
                                       '  attribute \\src "/elsewhere/x.py:3"\n  attribute \\src "contextlib.py:141"\n')
    assert relative_sources(verilog) == '(* src = "hdl/stepgen.py:190" *)\n'


@pytest.mark.slow
def test_bad_formats_and_out(tmp_path):
    (tmp_path / "file").write_text("x")
    proc = subprocess.run([SPRINGFLAT, "verilog", "--out", tmp_path / "file"], capture_output=True, text=True)
    assert proc.returncode == 2 and "not a directory" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run([SPRINGFLAT, "verilog", "--formats", "nope", "--out", tmp_path / "v"], capture_output=True,
                          text=True)
    assert proc.returncode == 2 and "unknown FormatSet preset" in proc.stderr


# ------------------------------------------------------------------ the engine and its register map
@pytest.mark.slow
def test_the_register_map_gives_the_engines_ports_as_its_verilog_has_them(exported):
    """An FPGA engineer wires the module from register_map.md: its port table and the adr width it states
    are the Verilog's (the width moves with the capacity)."""
    ports = _verilog_ports((exported / "springflat_engine.v").read_text(), "springflat_engine")
    text = (exported / "register_map.md").read_text()
    table = {name: (direction, int(bits)) for name, direction, bits in
             re.findall(r"^\| `(\w+)` \| (input|output) \| (\d+) \|$", text, re.M)}
    assert table == ports and "irq" in table
    assert f"`adr` a {ports['bus__adr'][1]}-bit address of 32-bit words" in text
    # and when the answers come (tests/hdl/test_engine.py measures them): the bundle is all it may have
    from golden_model.engine_spec.image import DEFAULT_CAPACITY
    from hdl.engine import SpringflatEngine

    with refused_components():  # (built for its attribute only: collected here, not reported in a later test)
        clocks = SpringflatEngine("narrow", DEFAULT_CAPACITY).bus_answer_clocks  # the build exported
    assert (f"raises them {clocks['register']} clocks after `stb` rises for a register, {clocks['memory word']} "
            f"for a memory word (read or write) and {clocks['err']} for an `err`") in text
    assert "**A host must not abandon a cycle**" in text  # its late answer goes to the next cycle (docs/engine.md)
    assert re.search(rf"#define SPRINGFLAT_ADDR_BITS +0x{ports['bus__adr'][1]:X}u",
                     (exported / "springflat_regs.h").read_text())


@pytest.mark.slow
def test_the_engine_ships_with_its_register_map_at_the_default_capacity(exported):
    """Without --capacity the engine is DEFAULT_CAPACITY's; the JSON map is the one the golden model builds."""
    from golden_model.engine_spec.image import DEFAULT_CAPACITY
    from golden_model.engine_spec.register_map import RegisterMap

    for name in ("springflat_engine.v", "register_map.md", "register_map.json", "springflat_regs.h",
                 "memory_image.md"):
        assert (exported / name).is_file(), name
    rmap = RegisterMap.from_dict(json.loads((exported / "register_map.json").read_text()))
    assert rmap == RegisterMap.build(FormatSet.preset("narrow"), DEFAULT_CAPACITY)
    assert rmap.capacity == DEFAULT_CAPACITY


def test_the_bundles_interface_lists_its_files(exported):
    """What a later bundle into the same directory removes where it does not write it again (a user's file of a
    bundle file's name, clock.lpf say, was removed by its name)."""
    from sim.synth import BUNDLE_FILES_KEY, earlier_bundle_files

    files = sorted(p.relative_to(exported).as_posix() for p in exported.rglob("*") if p.is_file())
    assert json.loads((exported / "interface.json").read_text())[BUNDLE_FILES_KEY] == files
    assert earlier_bundle_files(exported) == tuple(files) and "clock.lpf" not in files


@pytest.mark.slow  # two elaborations of every component: ~20 s
def test_capacity_option_sizes_the_engine_and_its_map(tmp_path):
    from golden_model.engine_spec.image import EngineCapacity
    from golden_model.engine_spec.register_map import RegisterMap

    out = tmp_path / "v"
    proc = subprocess.run([SPRINGFLAT, "verilog", "--formats", "narrow", "--capacity", "64", "300", "128",
                           "--out", out], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    capacity = EngineCapacity(64, 300, 128)
    rmap = RegisterMap.from_dict(json.loads((out / "register_map.json").read_text()))
    assert rmap == RegisterMap.build(FormatSet.preset("narrow"), capacity)
    # The Verilog's word address reaches the last window's end and no further than twice it.
    end = max(w.base + w.size for w in rmap.windows)
    ports = _verilog_ports((out / "springflat_engine.v").read_text(), "springflat_engine")
    direction, adr_bits = ports["bus__adr"]
    assert direction == "input" and 2 ** (adr_bits - 1) < end <= 2 ** adr_bits
    assert {"bus__dat_w", "bus__dat_r", "bus__ack", "bus__err", "irq"} <= set(ports)
    header = (out / "springflat_regs.h").read_text()
    assert "capacity 64 vertices / 300 entries / 128 triangles" in header
    assert re.search(r"#define SPRINGFLAT_CAP_ENTRIES_RESET\s+0x12Cu", header)  # 300
    image = (out / "memory_image.md").read_text()
    entries = rmap.window("entries")
    assert f"| `entries` | `0x{entries.base:X}` | 300 | {sum(f.width for f in entries.fields)} |" in image
    assert "docs/engine.md" in image and "register_map.md" in image
    # and how each run constant is formed: the bundle sent the host's writer to docs/engine.md for them
    assert "| `tol_energy` | u8.40 | ε at 2^-40, rounded half up" in image and "| `energy_floor` |" in image


@pytest.mark.parametrize("capacity, message", [
    (["1", "300", "128"], "error: --capacity V E T: vertices must be an int >= 2, got 1"),  # (no class name)
    (["64", "300"], "expected 3 arguments"),
    (["64", "x", "128"], "argument --capacity: expected an integer, got 'x'"),
    (["268435456", "1073741824", "1073741824"], "do not fit a 32-bit byte address"),
    # memories no disk mesh could fill (a typo: 8 entries for 64 vertices), or that hold no triangle at all
    (["64", "8", "16"], "--capacity 64 8 16: a disk mesh of 64 vertices has at least 250 neighbour entries and 62 "
                        "triangles; these depths hold at most 3 vertices (give more entries or triangles, or fewer "
                        "vertices)"),
    (["64", "249", "62"], "these depths hold at most 63 vertices"),
    (["2", "2", "2"], "--capacity 2 2 2: a disk mesh of 3 vertices has at least 6 neighbour entries and 1 triangle; "
                      "these depths hold no mesh"),
])
def test_bad_capacity_is_one_line_and_writes_nothing(tmp_path, capacity, message):
    out = tmp_path / "v"
    proc = subprocess.run([SPRINGFLAT, "verilog", "--capacity", *capacity, "--out", out], capture_output=True,
                          text=True)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("springflat: error:"), proc.stderr
    assert message in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("preset", ["default", "narrow"])
def test_every_payload_field_is_given_the_format_it_holds(preset):
    """interface.md's formats: each multi-bit field has one, and it is as wide and as signed as the field
    (the fold barrier's fields were all given length_sq's, the core's none). The guard's 3-bit level and
    stuck counts are integers."""
    import gc
    import warnings

    from golden_model.fixed import Format
    from sim.export import COMPONENTS, describe

    fs = FormatSet.preset(preset)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (described, never elaborated: collected here, not in a later test)
        described = [describe(spec.build(fs), fs, spec.module) for spec in COMPONENTS]
        gc.collect()
    for info in described:
        for port, fields in info["payload_layouts"].items():
            for f in fields:
                where = (info["module"], port, f["field"])
                if f["width"] == 1 or f["field"] in ("level", "stuck"):
                    continue
                assert "format" in f, where
                fmt = Format.parse(f["format"].split()[1])
                assert (fmt.width, fmt.signed) == (f["width"], f["signed"]), where
    core = {f["field"]: f["format"] for info in described if info["module"] == "springflat_core"
            for f in info["payload_layouts"]["entries__payload"] if "format" in f}
    assert core["barrier.threshold"] == f"area {fs.area}" and core["barrier.gain"] == f"barrier_gain {fs.barrier_gain}"


@pytest.mark.slow  # every component elaborated for ECP5: ~30 s
def test_the_ecp5_target_writes_the_netlist_synth_places(tmp_path):
    """--target ecp5: the Verilog with the primitives synth maps (the netlist the bundle's clock was met with),
    their simulation models beside it, and a README that says which netlist it is."""
    out = tmp_path / "v"
    proc = subprocess.run([SPRINGFLAT, "verilog", "--formats", "narrow", "--target", "ecp5", "--out", out],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    engine = (out / "springflat_engine.v").read_text()
    assert "MULT18X18D" in engine and "DP16KD" in engine
    assert sorted(p.name for p in (out / "sim_models").iterdir()) == ["DP16KD.v", "MULT18X18D.v", "TRELLIS_FF.v"]
    readme = (out / "README.md").read_text()
    assert "This is the ECP5 netlist" in readme and "| `sim_models/` |" in readme
    assert f"{out / 'sim_models'}/" in proc.stdout


@pytest.mark.slow  # the engine elaborated for ECP5 to count its block RAMs, then exported: ~1 min
def test_a_capacity_the_85f_cannot_hold_is_said(tmp_path):
    """3328 vertices with the guard needs more DP16KD than the LFE5U-85F has (docs/synthesis.md's table): the
    bundle is still written (a larger device, another tool), with a note that it does not fit."""
    out = tmp_path / "v"
    proc = subprocess.run([SPRINGFLAT, "verilog", "--capacity", "3328", "19968", "6656", "--out", out],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    notes = [line for line in proc.stderr.splitlines() if line.startswith("springflat: note:")]
    assert len(notes) == 1 and "does not fit the largest ECP5" in notes[0], proc.stderr
    assert re.search(r"it needs \d+ block RAMs \(DP16KD\) where the ECP5 LFE5U-85F CABGA381 has 208", notes[0])
    assert (out / "springflat_engine.v").exists()


def test_a_users_files_in_out_are_refused_at_once_not_replaced(tmp_path):
    """A project directory with its own README.md and clock.sdc: the bundle replaced both without a word. Refused
    before the export's half minute, naming them; what no earlier bundle wrote there is the user's."""
    out = tmp_path / "project"
    out.mkdir()
    for name, text in (("README.md", "precious\n"), ("clock.sdc", "my constraints\n"), ("notes.txt", "mine\n")):
        (out / name).write_text(text)
    proc = subprocess.run([SPRINGFLAT, "verilog", "--out", out], capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines()[-1] == (
        f"springflat: error: --out '{out}' holds README.md, clock.sdc, which this run would replace and no earlier run "
        "of this command wrote there: move them, or give a new directory")
    assert sorted(p.name for p in out.iterdir()) == ["README.md", "clock.sdc", "notes.txt"]
    assert (out / "README.md").read_text() == "precious\n"


def test_a_capacity_deeper_than_the_85f_holds_gets_a_note_on_its_build_time():
    """A capacity with a memory deeper than the largest engine the 85F holds gets a note on its long export and
    build (rtl-check --engine-top, --engine rtl), said before them; the default and that largest one get none."""
    from golden_model.engine_spec.image import DEFAULT_CAPACITY, LARGEST_85F_CAPACITY, EngineCapacity
    from sim.register_map_export import beyond_the_85f

    assert beyond_the_85f(DEFAULT_CAPACITY) is None and beyond_the_85f(LARGEST_85F_CAPACITY) is None
    for deeper in (EngineCapacity(3073, 18432, 6144), EngineCapacity(1024, 18433, 2048),
                   EngineCapacity(100000, 1000000, 100000)):
        note = beyond_the_85f(deeper)
        assert note.startswith(f"capacity {deeper.as_option()} has a memory deeper than 3072 18432 6144's, the "
                               "largest engine the LFE5U-85F holds in the default formats (docs/synthesis.md): its "
                               "export and simulation build take long")
