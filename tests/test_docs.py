"""What the docs and docstrings state that a generated block cannot hold, and no history in docs/.

The tables of docs/ that are functions of the code are generated blocks (``sim.docgen``; ``tests/sim/test_docgen.py``
keeps them current). What is left here: numbers stated in the prose of ``hdl/`` docstrings and of the presets'
``notes`` (code and data, not generated), one fact about the code the units' table relied on, that the
design docs carry no commit hashes or session diary, and that the relative links of the README and the docs reach
their files and headings.
"""

import re

import pytest

from golden_model.fixed import FORMAT_FIELDS, FormatSet
from golden_model.fixed.pipeline import accumulator_guard_bits
from support import DOCS, PRESETS

ROOT = DOCS.parent


def flat(text: str) -> str:
    """``text`` with every run of white space one blank (prose wraps anywhere)."""
    return " ".join(text.split())


def elaborated_flip_flops(component) -> int:
    """Register bits of ``component`` elaborated for ECP5 (its RTLIL ``$dff`` cells, before synthesis)."""
    from amaranth.back import rtlil

    from hdl.dsp import ECP5

    text = rtlil.convert(component, platform=ECP5)
    return sum(int(w) for w in re.findall(r"cell \$\w*dff\w* .*?\n.*?parameter \\WIDTH (\d+)", text, re.S))


def test_unit_latencies_in_docstrings():
    """``RsqrtUnit``'s and ``StepGenerator``'s docstrings state their latencies (the docs' tables are
    generated, ``sim.docgen``; a docstring in ``hdl/`` cannot be)."""
    from hdl import RsqrtUnit, StepGenerator

    rsqrt = {RsqrtUnit.latency_of(FormatSet.preset(p).rsqrt_config()) for p in PRESETS}
    step = {StepGenerator.latency_of(FormatSet.preset(p)) for p in PRESETS}
    plain = StepGenerator.latency_of(FormatSet.preset("default").replace(lut_interpolate=False))
    assert len(rsqrt) == len(step) == 1  # "for both presets"
    assert int(re.search(r"latency_of` \((\d+) for both presets\)", flat(RsqrtUnit.__doc__)).group(1)) in rsqrt
    m = re.search(r"latency_of` \((\d+) for both presets, which interpolate; (\d+) without interpolation\)",
                  flat(StepGenerator.__doc__))
    assert (int(m.group(1)), int(m.group(2))) == (*step, plain)


def test_preset_formats_named_in_hdl_docstrings():
    """Every "sI.F in the default preset" in ``hdl/`` names a field's format of that preset."""
    for path in sorted((ROOT / "hdl").glob("*.py")):
        text = flat(path.read_text())
        named = re.findall(r"``(?:fs\.)?(\w+)``[:;,]? ([su]\d+\.\d+) in the (\w+) preset", text)
        assert len(named) == len(re.findall(r"[su]\d+\.\d+ in the \w+ preset", text)), path.name
        for field, fmt, preset in named:
            assert str(getattr(FormatSet.preset(preset), field)) == fmt, (path.name, field)


def test_io_wrapper_states_the_cores_port_bits(unelaborated):
    """``hdl/io_wrapper.py``'s docstring states the core's port bits (a docstring cannot be generated)."""
    from amaranth.hdl import Shape

    from hdl import NodeUpdate
    from hdl import io_wrapper

    ports = sum(Shape.cast(member.shape).width
                for _, member in NodeUpdate("default").signature.members.flatten() if member.is_port)
    assert int(re.search(r"pins \((\d+) port bits for the default preset", flat(io_wrapper.__doc__)).group(1)) \
        == ports


@pytest.mark.slow
def test_flip_flop_count_in_the_node_update_docstring():
    """``NodeUpdate``'s docstring states its flip-flops within 2 % (docs/hardware.md's count is generated;
    a docstring cannot be)."""
    from hdl import NodeUpdate

    m = re.search(r"~([\d,]+) (?:pipeline )?flip-flops", flat(NodeUpdate.__doc__))
    count = elaborated_flip_flops(NodeUpdate("default"))
    assert m and abs(int(m.group(1).replace(",", "")) - count) <= 0.02 * count, (m and m.group(1), count)


# ----------------------------------------------------------------------------- the presets' notes


def _rsqrt_blocks(fs):
    from golden_model.fixed.dsp import dsp_blocks

    return sum(p.count * dsp_blocks(p.a, p.b) for p in fs.products() if p.unit == "rsqrt")


def _measured(fs, seed_bits=None, steps=None):
    from golden_model.fixed.rsqrt import measure_rsqrt

    if seed_bits is not None:
        fs = fs.replace(rsqrt_seed_bits=seed_bits, rsqrt_newton_steps=steps)
    return measure_rsqrt(fs.rsqrt_config())


#: Claims a note may make about the formats, in the forms a note writes them: (pattern, the
#: ``(stated, actual)`` pairs of a match ``m`` in the note of key ``k`` of preset ``fs``, or None
#: when the match is no claim). Tried in this order; text a claim matched is not read again.
NOTE_CLAIMS = [
    (r"(\d+)-bit seed ROM \((\d+) entries\) \+ (\d+) Newton step",
     lambda fs, k, m: zip(m.groups(), (fs.rsqrt_seed_bits, fs.rsqrt_config().seed_table_size,
                                       fs.rsqrt_newton_steps))),
    (r"over the (\d+)-bit input", lambda fs, k, m: [(m[1], fs.length_sq.width)]),
    (r"max ([\d.]+) ulp on a ([\d.]+)M-point sweep",
     lambda fs, k, m: zip(m.groups(), (round(_measured(fs)["max_ulp_error"], 2),
                                       round(_measured(fs)["n_points"] / 1e6, 1)))),
    (r"(\d+) bits \+ (\d+) steps is also faithful \(([\d.]+) ulp\) but doubles the multipliers \((\d+) DSP "
     r"blocks instead of (\d+)\)",
     lambda fs, k, m: [(m[3], round(_measured(fs, int(m[1]), int(m[2]))["max_ulp_error"], 2)),
                       (m[4], _rsqrt_blocks(fs.replace(rsqrt_seed_bits=int(m[1]), rsqrt_newton_steps=int(m[2])))),
                       (m[5], _rsqrt_blocks(fs)), (m[4], 2 * int(m[5]))]),
    (r"(\d+)-entry table", lambda fs, k, m: [(m[1], (1 << fs.lut_index_bits) + 1)]),
    (r"(\d+) guard bits", lambda fs, k, m: [(m[1], accumulator_guard_bits(fs.max_degree))]),
    (r"(\d+) bits, (\d+) more than (\w+)'s (\d+) fraction bits",
     lambda fs, k, m: [(m[1], getattr(fs, k).width), (m[4], getattr(fs, m[3]).frac_bits),
                       (m[2], getattr(fs, k).width - getattr(fs, m[3]).frac_bits)]),
    (r"\b(\w+) \((\d+) bits", lambda fs, k, m: [(m[2], getattr(fs, m[1]).width)] if m[1] in FORMAT_FIELDS else None),
    (r"\b([su]\d+\.\d+)\b", lambda fs, k, m: [(m[1], str(getattr(fs, k)))]),
    (r"(\d+) fraction bits", lambda fs, k, m: [(m[1], getattr(fs, k).frac_bits)]),
    (r"\b(\d+|one) integer bits?", lambda fs, k, m: [("1" if m[1] == "one" else m[1], getattr(fs, k).int_bits)]),
    (r"2\^-(\d+)", lambda fs, k, m: [(m[1], getattr(fs, k).frac_bits)]),
    (r"lsb ([\d.]+e-\d+)", lambda fs, k, m: [(m[1], float(f"{getattr(fs, k).lsb:.2g}"))]),
    (r"\((\d+) bits", lambda fs, k, m: [(m[1], getattr(fs, k).width)]),
]


@pytest.mark.slow
@pytest.mark.parametrize("preset", PRESETS)
def test_preset_notes_state_the_formats_numbers(preset):
    """The numbers a preset's notes derive from its formats (fraction/integer bits, widths, formats,
    the rsqrt measurement, table sizes) are the formats' own: a note that drifts fails here."""
    import json

    from golden_model.fixed import PRESET_DIR

    fs = FormatSet.preset(preset)
    notes = json.loads((PRESET_DIR / f"{preset}.json").read_text())["notes"]
    checked = 0
    for key, text in notes.items():
        for pattern, claims in NOTE_CLAIMS:
            read = []
            for m in re.finditer(pattern, text):
                pairs = claims(fs, key, m)
                if pairs is None:
                    continue
                for stated, actual in pairs:
                    assert type(actual)(stated) == actual, (preset, key, m.group(0), actual)
                    checked += 1
                read.append(m.span())
            for lo, hi in read:
                text = text[:lo] + " " * (hi - lo) + text[hi:]
    assert checked >= (25 if preset == "default" else 3), checked


# ----------------------------------------------------------------------------- no history in the design docs

#: Tokens of 7–40 hex digits in docs/ that are not commit hashes, each with the reason.
NOT_HASHES = {
    "123456789": "the ASCII string a CRC's check value is computed over (docs/board.md)",
    "1175269": "a raw fixed-point value in an example mismatch message (docs/verification.md)",
    "1175268": "a raw fixed-point value in an example mismatch message (docs/verification.md)",
    "0099983": "the fraction digits of 0.0099983 (docs/study.md)",
}
HASH_LIKE = re.compile(r"\b[0-9a-fA-F]{7,40}\b")
DIARY = re.compile(r"\b(?:this|previous|last|next|earlier|later|same|first|second|third|fourth|fifth|sixth|seventh|"
                   r"eighth|ninth|tenth|eleventh|twelfth|\d+(?:st|nd|rd|th)) session\b|\bat the time of writing\b",
                   re.IGNORECASE)


def history_in(text: str) -> list[str]:
    """Commit-hash-like tokens (but the ones ``NOT_HASHES`` explains) and diary phrases in ``text``."""
    return [m.group(0) for m in HASH_LIKE.finditer(text) if m.group(0) not in NOT_HASHES] + \
        [m.group(0) for m in DIARY.finditer(flat(text))]


def test_history_is_found():
    assert history_in("measured at 02ffc8f (the eleventh session), ac1ece3's netlist; this\nsession too") == [
        "02ffc8f", "ac1ece3", "eleventh session", "this session"]
    assert history_in("0x1F, 150 MHz, 2048 words, 0.0099983, dome_grid(45), a cafe, 0.0012345") == ["0012345"]
    assert history_in("CRC over 123456789; at the time of writing") == ["at the time of writing"]


@pytest.mark.parametrize("path", sorted(DOCS.rglob("*.md")), ids=lambda p: str(p.relative_to(DOCS)))
def test_design_docs_keep_no_history(path):
    """The docs state the design and the current figures; the history is git's (and docs/results/ keeps
    the measured rows, each with its date and command)."""
    assert history_in(path.read_text(encoding="utf-8")) == []


LINK = re.compile(r"\]\(([^)\s]+)\)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def heading_anchors(text: str) -> set[str]:
    """The anchors GitHub gives a Markdown file's headings: lower case, the text of links and code kept,
    other punctuation dropped, blanks as ``-``, and ``-1``, ``-2`` ... on repeats."""
    anchors: set[str] = set()
    for heading in re.findall(r"^#+ +(.+?) *$", FENCE.sub("", text), re.M):
        slug = re.sub(r"[^\w\- ]", "", re.sub(r"\[([^]]*)\]\([^)]*\)", r"\1", heading).lower()).replace(" ", "-")
        anchor, repeat = slug, 0
        while anchor in anchors:
            repeat += 1
            anchor = f"{slug}-{repeat}"
        anchors.add(anchor)
    return anchors


def broken_links(path) -> list[str]:
    """The relative links of a Markdown file whose file, or heading after ``#``, does not exist."""
    text = path.read_text(encoding="utf-8")
    broken = []
    for target in LINK.findall(FENCE.sub("", text)):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        linked = (path.parent / file).resolve() if file else path
        if not linked.exists():
            broken.append(target)
        elif anchor and linked.suffix == ".md" and anchor not in heading_anchors(linked.read_text(encoding="utf-8")):
            broken.append(target)
    return broken


def test_heading_anchors_follow_github():
    assert heading_anchors("# The per-node pipeline (`golden_model/fixed/pipeline.py`)\n## A, b\n## A, b\n") == {
        "the-per-node-pipeline-golden_modelfixedpipelinepy", "a-b", "a-b-1"}


@pytest.mark.parametrize("path", [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))], ids=lambda p: p.name)
def test_relative_links_reach_a_file_and_its_heading(path):
    assert broken_links(path) == []


def test_the_board_self_test_expects_the_register_maps_id_and_version():
    """docs/board.md's bring-up reads ID and VERSION: the values it tells a bench to expect are the map's."""
    from golden_model.engine_spec.register_map import MAGIC, VERSION

    expected = re.search(r"# expect (0x[0-9a-f]+) (0x[0-9a-f]+)", (DOCS / "board.md").read_text())
    assert expected, "docs/board.md no longer says what the self-test reads"
    assert (int(expected[1], 16), int(expected[2], 16)) == (MAGIC, VERSION[0] << 16 | VERSION[1])


def test_the_readmes_repository_layout_names_every_module():
    """The README's layout of the repository had fallen behind the files (the guard's blocks, graph.py, the
    batch's workers): every module of the three layers is named in it, a top-level one as ``name.py`` (or a
    ``prefix_*.py``), one in a sub-package by its name in that package's parentheses."""
    readme = (ROOT / "README.md").read_text()
    layout = readme[readme.index("## Layout of the repository"):]
    named = set(re.findall(r"[\w*]+\.py", layout))
    patterns = [re.compile(name.replace("*", r"\w*") + "$") for name in named if "*" in name]
    missing = []
    for package in ("golden_model", "hdl", "sim", "springflat"):
        for path in sorted((ROOT / package).rglob("*.py")):
            inner = path.relative_to(ROOT / package).parts[:-1]
            if path.name == "__init__.py" or inner in (("cocotb_benches",), ("models",)):
                continue  # a package is named by its folder; the benches and models by theirs
            if inner:  # a sub-package's modules, in the parentheses after its folder's name in its package's part
                part = re.search(rf"^{package}/ (.*?)(?=^\S)", layout, re.S | re.M)[1]
                said = re.search(re.escape(inner[-1]) + r"/ \(([^()]*(?:\([^()]*\)[^()]*)*)\)", part)
                found = said is not None and re.search(rf"\b{path.stem}\b", said[1])
            else:
                found = path.name in named or any(p.match(path.name) for p in patterns)
            if not found:
                missing.append(str(path.relative_to(ROOT)))
    assert not missing, f"the README's layout does not name {missing}"
