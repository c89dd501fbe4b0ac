"""The engine's register map (golden_model.engine_spec.register_map) and its exports (sim/register_map_export.py)."""

import dataclasses
import json
import re
import shutil
import subprocess

import pytest

from golden_model.modes import RUN_MODES, mode_named
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from golden_model.engine_spec.image import (RESULTS, EngineCapacity, build_image, energy_width, memory_layouts,
                                            run_constant_fields)
from golden_model.engine_spec.register_map import MAGIC, STATES, VERSION, BitField, Register, RegisterMap, format_hash
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.engine_spec.image import UNGUARDED
from golden_model.params import FlattenParams
from sim.register_map_export import EXPORT_FILES, c_header, markdown, to_json, write_exports
from support import DOCS, PRESETS, press_ctrl_c

SMALL = EngineCapacity(vertices=100, entries=600, triangles=200)


@pytest.fixture(scope="module", params=PRESETS)
def fs(request):
    return FormatSet.preset(request.param)


@pytest.fixture(scope="module")
def regmap(fs):
    return RegisterMap.build(fs, SMALL)


def test_identification_and_capacity_read_back_as_reset_values(regmap, fs):
    assert regmap.register("ID").reset == MAGIC == int.from_bytes(b"SPFL", "big")
    assert regmap.register("FORMAT_HASH").reset == format_hash(fs)
    for what in ("vertices", "entries", "triangles"):
        r = regmap.register(f"CAP_{what.upper()}")
        assert (r.access, r.reset) == ("ro", getattr(SMALL, what))
    features = regmap.register("FEATURES")
    # bit 0 the guard, bits 3:1 the lanes (K = 1)
    assert (features.access, features.reset, features.block) == ("ro", 0b0011, regmap.register("ID").block)
    guardless = RegisterMap.build(fs, dataclasses.replace(SMALL, guard=False))
    assert guardless.register("FEATURES").reset == 0b0010
    # FEATURES took the identification block's free word: no other register moved
    assert [(r.name, r.offset) for r in guardless.registers] == [(r.name, r.offset) for r in regmap.registers]
    assert features.offset < regmap.register("CONTROL").offset


def test_the_format_hash_tells_format_sets_apart_but_not_their_names():
    default = FormatSet.preset("default")
    assert format_hash(default) == format_hash(default.replace(name="renamed"))
    assert format_hash(default) != format_hash(default.replace(position="s11.22"))


def test_control_and_status_fields(regmap):
    control = {f.name: f for f in regmap.register("CONTROL").fields}
    assert {n: (f.access, f.width) for n, f in control.items()} == {
        "start": ("w1p", 1), "abort": ("w1p", 1), "irq_enable": ("rw", 1)}
    status = {f.name: f for f in regmap.register("STATUS").fields}
    assert status["state"].codes == ("idle", "running", "done") and status["state"].width == 2
    assert status["result"].codes == ("none", "converged", "max-iterations", "diverged", "no-mesh", "bad-constants",
                                     "stalled")
    assert 2 ** status["result"].width >= len(RESULTS)
    assert status["irq_pending"].access == "w1c"


def test_every_run_constant_and_result_has_its_width(regmap, fs):
    for c in run_constant_fields(fs, SMALL):
        assert regmap.value_width(c.name) == c.width, c.name
        assert all(r.access == "rw" for r, _ in regmap.value_fields(c.name))
    assert regmap.value_width("area_error") == regmap.value_width("shape_error") == fs.error.width
    assert regmap.value_width("cycles") == 64
    assert [r.name for r, _ in regmap.value_fields("cycles")] == ["CYCLES_LO", "CYCLES_HI"]
    width = energy_width(fs, SMALL.entries)
    names = [r.name for r, _ in regmap.value_fields("energy")]
    assert names == [f"ENERGY_{k}" for k in range(-(-width // 32))] and regmap.value_width("energy") == width
    assert len(names) >= 3  # a wide value spans as many registers as it needs


def test_multi_word_values_are_aligned(regmap):
    for value in ("cycles", "energy", "tol_energy"):
        regs = [r for r, _ in regmap.value_fields(value)]
        span = 1 << (len(regs) - 1).bit_length()
        assert regs[0].offset % span == 0, value
        assert [r.offset for r in regs] == list(range(regs[0].offset, regs[0].offset + len(regs)))


def test_windows_follow_the_memory_layouts(regmap, fs):
    layouts = memory_layouts(fs, SMALL)
    last_register = max(r.offset for r in regmap.registers)
    for w in regmap.windows:
        layout = layouts[w.name]
        assert (w.depth, w.words, w.stride, w.fields) == (layout.depth, layout.words, layout.stride, layout.fields)
        assert w.base > last_register and w.base % w.size == 0 and w.size >= w.depth * w.stride


def test_decode_selects_exactly_the_mapped_words(regmap):
    """Every address up to past the last window: a register, a memory word, or None (bus error)."""
    expected = {r.offset: r for r in regmap.registers}
    for w in regmap.windows:
        for i in range(w.depth):
            for k in range(w.words):
                expected[w.base + i * w.stride + k] = (w, i, k)
    end = max(w.base + w.size for w in regmap.windows)
    for address in range(end + 64):
        assert regmap.decode(address) == expected.get(address), hex(address)


def test_encode_and_decode_values_round_trip(regmap, fs):
    mesh = dome_grid(6)
    params = FlattenParams(dynamics="momentum", **UNGUARDED, tol_energy=3.5)
    constants = build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), SMALL).constants
    words = regmap.encode(constants)
    assert set(words) <= {r.offset for r in regmap.registers if r.access == "rw"}
    assert {n: regmap.decode_value(n, words) for n in constants} == constants
    mode = {f.name: f.lsb for f in regmap.register("MODE").fields}
    assert words[regmap.register("MODE").offset] == (mode_named("momentum").code << mode["mode"]) | (1 << mode["barrier"])
    # tol_energy = 3.5 · 2^40 is wider than a word: the high word holds its bits 63:32
    assert words[regmap.register("TOL_ENERGY_HI").offset] == (7 << 39) >> 32


def test_signed_values_are_twos_complement_over_their_width(regmap, fs):
    width = fs.spring.width
    words = regmap.encode({"half_spring": -3})
    assert words[regmap.register("HALF_SPRING").offset] == (1 << width) - 3
    assert regmap.decode_value("half_spring", words) == -3
    with pytest.raises(ValueError, match=f"half_spring = {1 << (width - 1)} does not fit its {width}-bit register"):
        regmap.encode({"half_spring": 1 << (width - 1)})


def _rebuilt(regmap, **changes):
    return dataclasses.replace(regmap, **changes)


def test_the_checks_refuse_a_broken_map(regmap):
    regs = list(regmap.registers)
    with pytest.raises(ValueError, match=r"register map: X and ID overlap at word 0"):
        _rebuilt(regmap, registers=tuple(regs + [dataclasses.replace(regmap.register("ITERATIONS"), name="X",
                                                                     offset=0)]))
    with pytest.raises(ValueError, match="duplicate register names"):
        _rebuilt(regmap, registers=tuple(regs + [dataclasses.replace(regs[1], offset=0x7)]))
    clash = Register("X", 0x7, "rw", "", (BitField("a", 0, 4, "rw", ""), BitField("b", 3, 2, "rw", "")), "control")
    with pytest.raises(ValueError, match=r"register map: X\.b overlaps another field"):
        _rebuilt(regmap, registers=tuple(regs + [clash]))
    wide = Register("X", 0x7, "rw", "", (BitField("a", 20, 13, "rw", ""),), "control")
    with pytest.raises(ValueError, match=r"X\.a .* does not fit a 32-bit register"):
        _rebuilt(regmap, registers=tuple(regs + [wide]))
    stray = Register("X", 0x7, "rw", "", (BitField("a", 0, 4, "rw", ""),), "control", reset=0x10)
    with pytest.raises(ValueError, match="reset 0x10 sets bits outside its fields"):
        _rebuilt(regmap, registers=tuple(regs + [stray]))
    first = regmap.windows[0]
    with pytest.raises(ValueError, match=f"window {first.name} at 0x0 overlaps"):
        _rebuilt(regmap, windows=(dataclasses.replace(first, base=0),) + regmap.windows[1:])
    with pytest.raises(ValueError, match=f"window {first.name} at .* is not aligned to its size"):
        _rebuilt(regmap, windows=(dataclasses.replace(first, base=first.base + first.size // 2),)
                 + regmap.windows[1:])


# ---------------------------------------------------------------------------------------- exports

def test_json_round_trips_the_map(regmap):
    text = to_json(regmap)
    assert RegisterMap.from_dict(json.loads(text)) == regmap
    changed = json.loads(text)
    changed["registers"][0]["reset"] ^= 1
    assert RegisterMap.from_dict(changed) != regmap  # the comparison sees a change


def test_markdown_lists_every_register_field_and_window(regmap):
    text = markdown(regmap)
    for r in regmap.registers:
        for f in r.fields:
            assert re.search(rf"\| `0x{r.offset:04X}` \| `{r.name}` \| [0-9:]+ \| `{f.name}` \| {f.access} \|", text), \
                (r.name, f.name)
    for w in regmap.windows:
        assert f"| `{w.name}` | `0x{w.base:05X}` | {w.depth} | {w.words} | {w.stride} |" in text
        for f in w.fields:
            assert f"| `{f.name}` | {f.width} |" in text
    assert "0 idle, 1 running, 2 done" in text
    version = regmap.register("VERSION").offset
    assert f"| `0x{version:04X}` | `VERSION` | 31:16 | `major` | ro | `0x{VERSION[0]:X}` |" in text
    assert f"| `0x{version:04X}` | `VERSION` | 15:0 | `minor` | ro | `0x{VERSION[1]:X}` |" in text
    assert f"| `CAP_ENTRIES` | 31:0 | `value` | ro | `0x{SMALL.entries:X}` |" in text


def _expected_defines(regmap):
    """Every number the header must define, from the map."""
    want = {"SPRINGFLAT_MAGIC": MAGIC, "SPRINGFLAT_FORMAT_HASH": regmap.format_hash}
    for r in regmap.registers:
        want[f"SPRINGFLAT_{r.name}_ADDR"] = r.offset
        want[f"SPRINGFLAT_{r.name}_RESET"] = r.reset
        for f in r.fields:
            key = f"SPRINGFLAT_{r.name}_{f.name.upper()}"
            want[key + "_SHIFT"], want[key + "_MASK"], want[key + "_WIDTH"] = f.lsb, f.mask, f.width
            if f.signed:  # (a driver sign-extends those)
                want[key + "_SIGNED"] = 1
    for i, s in enumerate(STATES):
        want[f"SPRINGFLAT_STATE_{s.upper()}"] = i
    for i, s in enumerate(RESULTS):
        want[f"SPRINGFLAT_RESULT_{s.upper().replace('-', '_')}"] = i
    for mode in RUN_MODES:
        want[f"SPRINGFLAT_MODE_{mode.name.upper().replace('-', '_')}"] = mode.code
    for w in regmap.windows:
        for what in ("base", "depth", "words", "stride", "size"):
            want[f"SPRINGFLAT_WINDOW_{w.name.upper()}_{what.upper()}"] = getattr(w, what)
        lsb = 0
        for f in w.fields:
            want[f"SPRINGFLAT_WINDOW_{w.name.upper()}_{f.name.upper()}_LSB"] = lsb
            if f.signed:
                want[f"SPRINGFLAT_WINDOW_{w.name.upper()}_{f.name.upper()}_SIGNED"] = 1
            lsb += f.width
    assert {"SPRINGFLAT_WINDOW_NODES_POSITION_X_SIGNED", "SPRINGFLAT_HALF_SPRING_VALUE_SIGNED"} <= set(want)  # (known)
    assert "SPRINGFLAT_WINDOW_NODES_INV_MASS_SIGNED" not in want
    # a window's names apart from its register's: the entries window's base is not the ENTRIES register's address
    assert {"SPRINGFLAT_ENTRIES_ADDR", "SPRINGFLAT_WINDOW_ENTRIES_BASE"} <= set(want)
    return want


def test_the_c_header_says_each_fields_access_where_it_is_not_its_registers(regmap):
    """CONTROL is rw but its start and abort are w1p, STATUS w1c but its state ro: a header that said only
    'CONTROL (rw)' told a driver writer to read back a pulse."""
    comments = {line.split(" ")[1]: line for line in c_header(regmap).splitlines() if line.startswith("/* ")}
    for register in regmap.registers:
        line = comments[register.name]
        for f in register.fields:
            assert (f"{f.name} {f.access}" in line) == (f.access != register.access), line
    assert comments["CONTROL"].startswith("/* CONTROL (rw; start w1p, abort w1p): ")


def test_the_c_header_compiles_and_holds_the_map(regmap, tmp_path):
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler on this machine")
    (tmp_path / "springflat_regs.h").write_text(c_header(regmap))
    want = _expected_defines(regmap)
    prints = "\n".join(f'    printf("{k} %llu\\n", (unsigned long long)({k}));' for k in want)
    (tmp_path / "check.c").write_text(f'#include <stdio.h>\n#include "springflat_regs.h"\n'
                                      f'#include "springflat_regs.h"\nint main(void) {{\n{prints}\n    return 0;\n}}\n')
    subprocess.run([compiler, "-std=c99", "-Wall", "-Werror", "-o", str(tmp_path / "check"), str(tmp_path / "check.c")],
                   check=True, capture_output=True)
    output = subprocess.run([str(tmp_path / "check")], check=True, capture_output=True, text=True).stdout
    got = {name: int(value) for name, value in (line.split() for line in output.splitlines())}
    assert got == want


def test_the_jsons_field_positions_unpack_the_images_words(regmap, fs):
    """register_map.json gives each memory field its ``lsb`` (the C header's ``_LSB``): with it and the width, a
    host's script reads every field of a real image's words as the golden model packed it."""
    mesh = dome_grid(6)
    params = FlattenParams(dynamics="momentum", barrier=True, max_iter=5)
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), SMALL)
    windows = json.loads(to_json(regmap))["windows"]
    layouts = memory_layouts(fs, SMALL)
    header = c_header(regmap)
    for window in windows:
        words = image.memories()[window["name"]]
        whole = [sum(int(w) << (32 * k) for k, w in enumerate(row)) for row in words]
        unpacked = layouts[window["name"]].unpack(words)
        for field in window["fields"]:
            raw = [(value >> field["lsb"]) & ((1 << field["width"]) - 1) for value in whole]
            if field["signed"]:
                raw = [r - (1 << field["width"]) if r >> (field["width"] - 1) else r for r in raw]
            assert raw == [int(v) for v in unpacked[field["name"]]], (window["name"], field["name"])
            name = f"SPRINGFLAT_WINDOW_{window['name']}_{field['name']}_LSB".upper()
            assert re.search(rf"#define {name} +0x{field['lsb']:X}u", header), name


def test_the_c_header_is_ascii(regmap):
    """A compiler that reads the header in its code page warns on any other character, in a comment too (MSVC's
    C4819): the map's ½, Σ, φ, ε, −, · are spelled out."""
    header = c_header(regmap)
    assert header.isascii()
    assert "/* HALF_SPRING (rw): 1/2 C raw [spring] */" in header and "E_S = sum*mantissa*2^-shift" in header
    assert all(line.count("*/") == line.count("/*") for line in header.splitlines())


def test_write_exports_writes_all_three(regmap, tmp_path):
    paths = write_exports(regmap, tmp_path / "out")
    assert [p.name for p in paths] == list(EXPORT_FILES)
    assert RegisterMap.from_dict(json.loads(paths[1].read_text())) == regmap
    assert paths[2].read_text() == c_header(regmap) and paths[0].read_text() == markdown(regmap)


@pytest.mark.parametrize("case", ["a file", "under a file", "a directory in the way"])
def test_the_export_command_refuses_an_output_it_cannot_write_in_one_line_and_writes_nothing(tmp_path, capsys, case):
    """``python -m sim.register_map_export --out DIR``: a DIR that is a file, lies under one, or holds a
    directory where a file goes was a traceback, the last after register_map.md had been written."""
    from sim.register_map_export import main

    (tmp_path / "afile").write_text("mine\n")
    (tmp_path / "e5" / "register_map.json").mkdir(parents=True)
    out = {"a file": "afile", "under a file": "afile/sub", "a directory in the way": "e5"}[case]
    with pytest.raises(SystemExit) as stopped:
        main(["--out", str(tmp_path / out)])
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m sim.register_map_export: error: ") and err.count("\n") == 1
    assert (tmp_path / "afile").read_text() == "mine\n"
    assert sorted(p.name for p in (tmp_path / "e5").iterdir()) == ["register_map.json"]
    assert main(["--out", str(tmp_path / "new")]) == 0
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == sorted(EXPORT_FILES)
    # a --formats file the export would replace is refused, as verilog's and synth's are
    formats = tmp_path / "new" / "register_map.json"
    FormatSet.preset("default").save(formats)
    before = formats.read_text()
    with pytest.raises(SystemExit) as stopped:
        main(["--formats", str(formats), "--out", str(tmp_path / "new")])
    assert stopped.value.code == 2 and "is the same file as --formats" in capsys.readouterr().err
    assert formats.read_text() == before


def test_the_engine_doc_holds_the_generated_map():
    """docs/engine.md's register-map block is the export's markdown of sim.docgen's DOC_MAP: it cannot drift."""
    from sim.docgen import BLOCK, DOC_MAP

    blocks = {m.group("name"): m.group("body") for m in BLOCK.finditer((DOCS / "engine.md").read_text())}
    assert "register-map" in blocks, "docs/engine.md lost its generated register map"
    formats, capacity = DOC_MAP
    regmap = RegisterMap.build(FormatSet.preset(formats), capacity)
    assert blocks["register-map"].rstrip() == markdown(regmap, level=3).rstrip()

def test_the_export_command_writes_the_map_of_k_lanes(tmp_path, capsys):
    from sim.register_map_export import main

    assert main(["--lanes", "2", "--out", str(tmp_path / "two")]) == 0
    header = (tmp_path / "two" / "springflat_regs.h").read_text()
    assert header.splitlines()[0].endswith("4096 triangles, in 2 lanes. */")
    assert "#define SPRINGFLAT_LANE1_ENTRIES_ADDR" in header and "SPRINGFLAT_LANE2_ENTRIES" not in header
    exported = json.loads((tmp_path / "two" / "register_map.json").read_text())
    # the map of the engine that lanes build: without the guard (FEATURES.guard 0)
    assert exported["capacity"]["lanes"] == 2 and exported["capacity"]["guard"] is False
    with pytest.raises(SystemExit) as stopped:
        main(["--lanes", "4", "--capacity", "64", "402", "128", "--out", str(tmp_path / "four")])
    assert stopped.value.code == 2
    assert capsys.readouterr().err.splitlines()[-1] == ("python -m sim.register_map_export: error: --capacity V E T: "
                                                        "entries = 402 is not a multiple of lanes = 4 (each lane holds "
                                                        "an equal share of every memory)")
    assert not (tmp_path / "four").exists()


def test_the_export_command_says_in_one_line_what_is_wrong_with_its_inputs(tmp_path, capsys):
    """A --formats FIFO was a NotRegularFileError traceback; --out '' wrote into the current directory; an
    argument error came after argparse's usage block. Each is one line, the command's name first."""
    import os

    from sim.register_map_export import main

    os.mkfifo(tmp_path / "f.json")
    for args, said in [(["--formats", str(tmp_path / "f.json"), "--out", str(tmp_path / "o")],
                        f"cannot read --formats '{tmp_path / 'f.json'}': is a named pipe (FIFO), not a regular file"),
                       (["--out", ""], "argument --out: expected a path, got ''"),
                       (["--out", str(tmp_path / "o"), "--bogus"], "unrecognized arguments: --bogus")]:
        with pytest.raises(SystemExit) as stopped:
            main(args)
        assert stopped.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"python -m sim.register_map_export: error: {said}"), err
    assert os.listdir(tmp_path) == ["f.json"]


def test_the_export_command_answers_ctrl_c_in_one_line_with_nothing_written(tmp_path, capsys, monkeypatch):
    import sim.register_map_export as export

    monkeypatch.setattr(export, "write_exports", press_ctrl_c)
    assert export.main(["--out", str(tmp_path / "o")]) == 130
    assert capsys.readouterr().err == "python -m sim.register_map_export: interrupted\n"
    assert list(tmp_path.iterdir()) == []


def test_the_export_refuses_to_replace_a_file_of_the_users_and_replaces_its_own(tmp_path, capsys):
    """A directory holding the user's own register_map.md (or a link of that name) was overwritten: the export
    replaces only what an earlier export of its own (or a bundle's) wrote there, as verilog does."""
    from sim.register_map_export import main

    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "register_map.md").write_text("my own register notes\n")
    (tmp_path / "mine.md").write_text("linked\n")
    (notes / "springflat_regs.h").symlink_to(tmp_path / "mine.md")
    with pytest.raises(SystemExit) as stopped:
        main(["--out", str(notes)])
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "which this run would replace and no earlier run of this command wrote" in err
    assert (notes / "register_map.md").read_text() == "my own register notes\n"
    assert (notes / "springflat_regs.h").is_symlink() and (tmp_path / "mine.md").read_text() == "linked\n"
    assert sorted(p.name for p in notes.iterdir()) == ["register_map.md", "springflat_regs.h"]
    # a map of the user's own with a format_hash, or a link named as the map (springflat writes no links), is
    # no earlier export: the directory's files stay the user's
    for name, make in (("own", lambda p: p.write_text('{"format_hash": "mine"}')),
                       ("linked", lambda p: p.symlink_to(tmp_path / "maps" / "register_map.json"))):
        (tmp_path / name).mkdir()
        (tmp_path / name / "register_map.md").write_text("mine\n")
        make(tmp_path / name / "register_map.json")
    assert main(["--out", str(tmp_path / "maps")]) == 0
    for name in ("own", "linked"):
        with pytest.raises(SystemExit):
            main(["--out", str(tmp_path / name)])
        assert "which this run would replace" in capsys.readouterr().err
        assert (tmp_path / name / "register_map.md").read_text() == "mine\n"
    assert (tmp_path / "linked" / "register_map.json").is_symlink()
    assert main(["--out", str(tmp_path / "maps")]) == 0  # its own export, again: replaced
    assert main(["--lanes", "2", "--out", str(tmp_path / "maps")]) == 0
    assert "in 2 lanes" in (tmp_path / "maps" / "springflat_regs.h").read_text()


def test_a_coarse_build_adds_its_windows_and_constants_after_the_others_moving_none(fs):
    """A build with a coarse space keeps every address of the build without one, and adds the basis and matrix
    windows after the triangles' and COARSE and MATRIX_EXPONENT after the other run constants; FEATURES.coarse
    reads its degree; a host's image for it round-trips through the windows' field positions."""
    coarse = dataclasses.replace(SMALL, coarse_degree=3)
    plain, built = RegisterMap.build(fs, SMALL), RegisterMap.build(fs, coarse)
    for register in plain.registers:
        assert built.register(register.name).offset == register.offset, register.name
    for window in plain.windows:
        assert built.window(window.name).base == window.base, window.name
    assert [w.name for w in built.windows] == ["nodes", "entries", "triangles", "basis", "matrix"]
    assert built.window("basis").depth == SMALL.vertices and built.window("matrix").depth == 100
    assert min(built.window(n).base for n in ("basis", "matrix")) > built.window("triangles").base
    last_plain = max(r.offset for r in plain.registers)
    assert all(built.register(n).offset > last_plain for n in ("COARSE", "MATRIX_EXPONENT"))
    assert built.value_fields("matrix_exponent")[0][1].signed
    features = built.register("FEATURES")
    field = next(f for f in features.fields if f.name == "coarse")
    assert (features.reset & field.mask) >> field.lsb == 3
    assert (plain.register("FEATURES").reset & field.mask) == 0
    mesh = dome_grid(6)
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), FlattenParams(dynamics="momentum", coarse_degree=3,
                                                                                   max_iter=5), fs), coarse)
    words = built.encode(image.constants)
    assert built.decode_value("matrix_exponent", words) == image.constants["matrix_exponent"] != 0
    assert built.decode_value("coarse", words) == 1
