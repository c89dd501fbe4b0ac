"""The docs state numbers and tables that must match the code."""

import gc
import re
import warnings
from pathlib import Path

import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.fixed import FORMAT_FIELDS, FormatSet
from golden_model.fixed.pipeline import accumulator_guard_bits

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


# ----------------------------------------------------------------------------- hardware numbers

ROOT = DOCS.parent
PRESETS = ("default", "narrow")


def flat(text: str) -> str:
    """``text`` with every run of white space one blank (prose wraps anywhere)."""
    return " ".join(text.split())


@pytest.fixture
def unelaborated():
    """Components built only for their attributes (latencies) are not reported as unused."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        yield
        gc.collect()


def elaborated_flip_flops(component) -> int:
    """Register bits of ``component`` elaborated for ECP5 (its RTLIL ``$dff`` cells, before synthesis)."""
    from amaranth.back import rtlil

    from hdl.dsp import ECP5

    text = rtlil.convert(component, platform=ECP5)
    return sum(int(w) for w in re.findall(r"cell \$\w*dff\w* .*?\n.*?parameter \\WIDTH (\d+)", text, re.S))


def test_hardware_doc_contract_table(unelaborated):
    """Latencies (front + rsqrt + back + tail + 2) and DSP blocks as the code computes them."""
    from golden_model.fixed.dsp import dsp_blocks
    from hdl import NodeUpdate, RsqrtUnit, StepGenerator

    text = (DOCS / "hardware.md").read_text()
    dsp = {}
    for name in PRESETS:
        fs = FormatSet.preset(name)
        n = NodeUpdate(fs)
        m = re.search(rf"^\| latency, {name} preset \| (\d+) clocks \((\d+) \+ (\d+) \+ (\d+) \+ (\d+) \+ (\d+)\) "
                      r"\| (\d+) \| (\d+) \|", text, re.M)
        assert m, f"docs/hardware.md: no latency row for {name}"
        assert [int(g) for g in m.groups()] == [n.latency, n.front_stages, n.rsqrt_latency, n.back_stages,
                                                n.tail_stages, n.latency - n.pipeline_stages,
                                                RsqrtUnit.latency_of(fs.rsqrt_config()), StepGenerator.latency_of(fs)]
        dsp[name] = units = dict.fromkeys(("node_update", "rsqrt", "step_generator", "controller"), 0)
        for p in fs.products():
            units[p.unit] += p.count * dsp_blocks(p.a, p.b)
    row = flat(re.search(r"^\| multipliers \(18×18 DSP blocks, ECP5\) \|(.*)$", text, re.M).group(1))
    m = re.search(r"default (\d+), narrow (\d+), each incl\. the rsqrt unit's (\d+) \(the core adds the step "
                  r"generator's (\d+): (\d+), (\d+);.*\| (\d+) \| (\d+) \(", row)
    d, n = dsp["default"], dsp["narrow"]
    assert d["rsqrt"] == n["rsqrt"] and d["step_generator"] == n["step_generator"]
    assert [int(g) for g in m.groups()] == [
        d["node_update"] + d["rsqrt"], n["node_update"] + n["rsqrt"], d["rsqrt"], d["step_generator"],
        d["node_update"] + d["rsqrt"] + d["step_generator"], n["node_update"] + n["rsqrt"] + n["step_generator"],
        d["rsqrt"], d["step_generator"]]


def test_synthesis_doc_gives_the_current_latencies(unelaborated):
    from hdl import NodeUpdate

    text = flat((DOCS / "synthesis.md").read_text())
    m = re.search(r"\((?:before|after)[^)]*; (\d+) and (\d+) since\)", text)
    assert m, "docs/synthesis.md no longer says the current latencies"
    assert [int(g) for g in m.groups()] == [NodeUpdate(name).latency for name in PRESETS]


def test_unit_latencies_in_docstrings_and_docs():
    """``RsqrtUnit``'s and ``StepGenerator``'s stated latencies (docstrings, hardware-units.md) are the code's."""
    from hdl import RsqrtUnit, StepGenerator

    rsqrt = {RsqrtUnit.latency_of(FormatSet.preset(p).rsqrt_config()) for p in PRESETS}
    step = {StepGenerator.latency_of(FormatSet.preset(p)) for p in PRESETS}
    plain = StepGenerator.latency_of(FormatSet.preset("default").replace(lut_interpolate=False))
    assert len(rsqrt) == len(step) == 1  # "for both presets"
    units = flat((DOCS / "hardware-units.md").read_text())
    assert [int(v) for v in re.findall(r"\*\*(\d+)\*\* for both presets", units)] == [*rsqrt, *step]
    assert int(re.search(r"\*\*\d+\*\* for both presets, (\d+) without interpolation", units).group(1)) == plain
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
    from amaranth.hdl import Shape

    from hdl import NodeUpdate
    from hdl import io_wrapper

    ports = sum(Shape.cast(member.shape).width
                for _, member in NodeUpdate("default").signature.members.flatten() if member.is_port)
    assert int(re.search(r"pins \((\d+) port bits for the default preset", flat(io_wrapper.__doc__)).group(1)) \
        == ports


def test_flip_flop_counts_in_the_hardware_doc():
    """``~N`` flip-flops in docs/hardware.md within 2 % of the elaborated ``NodeUpdate``'s."""
    from hdl import NodeUpdate

    text = flat((DOCS / "hardware.md").read_text())
    m = re.search(r"elaborates to ~([\d,]+) flip-flops for ECP5 in the default preset and ~([\d,]+) in `narrow`",
                  text)
    assert m, "docs/hardware.md no longer states NodeUpdate's flip-flops"
    for stated, name in zip(m.groups(), PRESETS):
        count = elaborated_flip_flops(NodeUpdate(name))
        assert abs(int(stated.replace(",", "")) - count) <= 0.02 * count, (name, stated, count)


def test_flip_flop_count_in_the_node_update_docstring():
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


# ---------------------------------------------------------------- docs/hardware-units.md: the engine's units


def _units_doc() -> str:
    return " ".join((DOCS / "hardware-units.md").read_text().split())


def _dsp_blocks(component) -> int:
    """MULT18X18D cells in ``component`` elaborated for ECP5."""
    from amaranth.back import rtlil
    from amaranth.hdl import Const, Value

    from hdl.dsp import ECP5

    ports = [Value.cast(v) for _, _, v in component.signature.flatten(component) if not isinstance(v, Const)]
    return len(re.findall(r"^\s*cell \\MULT18X18D ", rtlil.convert(component, platform=ECP5, ports=ports), re.M))


def test_engine_unit_pipelines_in_the_units_doc(unelaborated):
    from hdl import AreaError, ForcePass, Integrator

    doc, dsp = _units_doc(), _dsp_blocks
    D, N = FormatSet.preset("default"), FormatSet.preset("narrow")
    fd, fn = ForcePass(D), ForcePass(N)
    sd, sn = fd.stages, fn.stages
    assert (f"default {sd.front} + {sd.rsqrt} + {sd.back} = {fd.latency}, narrow "
            f"{sn.front} + {sn.rsqrt} + {sn.back} = {fn.latency}") in doc
    assert f"default {dsp(fd)}, narrow {dsp(fn)}, each including the rsqrt unit's 12" in doc
    assert f"(default {dsp(ForcePass(D, energy=True))}, narrow {dsp(ForcePass(N, energy=True))})" in doc
    assert f"{Integrator(D).latency} (default), {Integrator(N).latency} (narrow)" in doc
    assert f"default {dsp(Integrator(D))}, narrow {dsp(Integrator(N))}" in doc
    assert {AreaError.latency_of(D), AreaError.latency_of(N)} == {int(re.search(r"adder levels: (\d+) in both", doc)[1])}
    assert {dsp(AreaError(D)), dsp(AreaError(N))} == {int(re.search(r"(\d+) `MULT18X18D` each: (\d+) in both", doc)[2])}


def test_controller_unit_numbers_in_the_units_doc(unelaborated):
    from golden_model.fixed.engine_image import EngineCapacity, energy_width
    from hdl import BetaDivider, EnergyCheck, Normaliser

    doc = _units_doc()
    D, N = FormatSet.preset("default"), FormatSet.preset("narrow")
    nd, nn = Normaliser(D), Normaliser(N)
    lo = lambda n: n.cycles(n.fs.error.frac_bits + 2)  # noqa: E731
    hi = lambda n: n.cycles(10**6)  # noqa: E731
    assert f"{lo(nd)} to {hi(nd)} edges, narrow" in doc and f"{lo(nn)} to {hi(nn)};" in doc
    ed, en = EnergyCheck(D, 8192), EnergyCheck(N, 8192)
    cap = EngineCapacity(1024, 8192, 2048)
    assert ed.energy_bits == energy_width(D, cap) and en.energy_bits == energy_width(N, cap)
    assert (f"default {ed.square_bits} + {ed.energy_bits} + 5 = {ed.latency}, narrow "
            f"{en.square_bits} + {en.energy_bits} + 5 = {en.latency}") in doc
    assert {BetaDivider(D).latency, BetaDivider(N).latency} == {
        int(re.search(r"output transfer\): (\d+) in both presets", doc)[1])}


def test_fixed_point_doc_states_the_domains_and_the_resolution_scales():
    from golden_model.fixed.formats_set import ACCURACY_FACTOR, KNOB_DOMAINS, RESOLUTION_SCALES

    text = (DOCS / "fixed-point.md").read_text()
    domains = {m.group(3): (int(m.group(1)), int(m.group(2)))
               for m in re.finditer(r"^\| (\d+)\.\.(\d+) \| `(\w+)` \|", text, re.M)}
    assert domains == KNOB_DOMAINS
    scales = {}
    for m in re.finditer(r"^\| ([\d.]+) \| ((?:`\w+`(?:, )?)+) \|$", text, re.M):
        scales.update({name: float(m.group(1)) for name in re.findall(r"`(\w+)`", m.group(2))})
    assert scales == RESOLUTION_SCALES
    assert f"≤ {ACCURACY_FACTOR:g}·ρ(fs)" in text
    def short(x: float) -> str:  # 4.8e-3
        mantissa, exponent = f"{x:.1e}".split("e")
        return f"{mantissa}e{int(exponent)}"

    for name in ("default", "narrow"):  # the stated resolutions and bounds
        fs = FormatSet.preset(name)
        assert f"`{name}` ρ = {short(fs.resolution())} (bound {short(fs.accuracy_bound())})" in flat(text), name
