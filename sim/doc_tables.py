"""The tables of ``docs/`` that are functions of the code, as markdown (generators of :mod:`sim.docgen`).

Each function returns the body of one generated block; none types a number the code holds. The
format tables read the presets (``golden_model/data/formats``); latencies and stage counts come
from the components (``hdl``), counted from the pipelines they build; DSP blocks are the
``MULT18X18D`` instances of a component elaborated for ECP5 (or the golden model's split rule,
which ``tests/hdl/test_dsp_cost.py`` holds equal to them); flip-flops are the register bits of the
elaborated RTLIL; the measured synthesis tables are rows of ``docs/results/synthesis.csv``
(:mod:`sim.results`).
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

from golden_model.fixed import FORMAT_FIELDS, FormatSet

from .export import quietly

#: The presets the docs tabulate: every one (``golden_model/data/formats``).
PRESETS = tuple(FormatSet.presets())


def _preset(name: str) -> FormatSet:
    return FormatSet.preset(name)


def _table(header: list[str], rows: list[list[object]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _source_comment(path: str, name: str) -> str:
    """The ``# ...`` comment at the end of the line ``"name": ...`` in ``path`` (a dict entry's reason)."""
    text = Path(path).read_text(encoding="utf-8")
    m = re.search(rf'^\s*"{name}":.*?#\s*(.*)$', text, re.M)
    return m.group(1).strip() if m else ""


# ----------------------------------------------------------------------------- docs/fixed-point.md


def format_presets() -> str:
    """Every field of the presets: formats with their widths, then the knobs."""
    sets = [_preset(p) for p in PRESETS]
    rows = [[f"`{f}`", *(x for fs in sets for x in (getattr(fs, f), getattr(fs, f).width))] for f in FORMAT_FIELDS]
    for knob in ("rsqrt_seed_bits", "rsqrt_newton_steps", "lut_index_bits", "lut_interpolate", "max_degree"):
        rows.append([f"`{knob}`", *(x for fs in sets for x in (getattr(fs, knob), ""))])
    rows.append(["`rounding`", *(x for fs in sets for x in (fs.rounding.value, ""))])
    return _table(["signal", *(x for p in PRESETS for x in (p, "bits"))], rows)


def knob_domains() -> str:
    """``KNOB_DOMAINS`` with the reason each bound has (the comment on its line), then the two enumerations."""
    from golden_model.fixed import formats_set
    from golden_model.fixed.format import Rounding

    rows = [[f"{lo}..{hi}", f"`{knob}`", _source_comment(formats_set.__file__, knob)]
            for knob, (lo, hi) in formats_set.KNOB_DOMAINS.items()]
    rows.append(["true, false", "`lut_interpolate`", ""])
    rows.append([", ".join(f"`{r.value}`" for r in Rounding), "`rounding`", ""])
    return _table(["domain", "knob", "why the bound"], rows)


def resolution_scales() -> str:
    """``RESOLUTION_SCALES`` grouped by scale, largest first."""
    from golden_model.fixed.formats_set import RESOLUTION_SCALES

    scales: dict[float, list[str]] = {}
    for name, m in RESOLUTION_SCALES.items():
        scales.setdefault(m, []).append(f"`{name}`")
    return _table(["m", "fields"], [[f"{m:g}", ", ".join(names)] for m, names in sorted(scales.items(), reverse=True)])


def accuracy_bounds() -> str:
    """Each preset's resolution ρ and documented bound ``ACCURACY_FACTOR``·ρ."""
    from golden_model.fixed.formats_set import ACCURACY_FACTOR

    rows = [[f"`{p}`", f"{_preset(p).resolution():.1e}", f"{_preset(p).accuracy_bound():.1e}"] for p in PRESETS]
    return _table(["preset", "ρ(fs)", f"bound: `ACCURACY_FACTOR`·ρ = {ACCURACY_FACTOR:g}·ρ"], rows)


def rsqrt_accuracy() -> str:
    """``measure_rsqrt`` of every preset's rsqrt unit (a few seconds: 13M evaluations)."""
    from golden_model.fixed.rsqrt import measure_rsqrt

    rows = []
    for p in PRESETS:
        cfg = _preset(p).rsqrt_config()
        r = measure_rsqrt(cfg)
        inputs = (f"all {r['n_points']:,}" if r["exhaustive"] else
                  f"{r['n_points']:,}-point sweep + every boundary ({cfg.fmt_in.width}-bit input)")
        rows.append([p, f"{cfg.fmt_in} → {cfg.fmt_out}", f"{cfg.seed_bits} / {cfg.newton_steps}",
                     f"{cfg.seed_table_size} entries", f"**{r['max_ulp_error']:.3f} ulp**", inputs])
    return _table(["preset", "in → out", "seed / steps", "ROM", "max error", "inputs"], rows)


def step_accuracy() -> str:
    """``measure_step_size`` of every preset's step generator (exhaustive over each error's domain)."""
    from golden_model.fixed.steplut import measure_step_size

    rows = []
    for p in PRESETS:
        fs = _preset(p)
        s = measure_step_size(fs)
        table = f"{(1 << fs.lut_index_bits) + 1} entries, {'interpolated' if fs.lut_interpolate else 'nearest'}"
        error = f"**{s['max_dt_ulp_error']:.2f} ulp** ({s['max_dt_ulp_error'] * fs.dt.lsb:.1e} in dt)"
        if not s["separable"]:
            error += ", an upper bound (not separable)"
        rows.append([f"{p} ({fs.error} → {fs.dt})", table, error, f"{s['bound']:.2f}"])
    return _table(["preset", "table", "max dt error (all pairs)", "bound (ulp)"], rows)


# ----------------------------------------------------------------------------- docs/study.md


def preset_costs() -> str:
    """``sim.study.cost.cost`` of every preset."""
    from .study.cost import cost

    return _table(["preset", "total bits", "DSP (18×18)", "ROM bits"],
                  [[f"`{p}`", c.total_bits, c.dsp, f"{c.rom_bits:,}"] for p in PRESETS for c in [cost(_preset(p))]])


def signal_classes() -> str:
    """``golden_model.study.SIGNAL_CLASSES``: each class and the fields that move with it."""
    from golden_model.study import SIGNAL_CLASSES

    return _table(["class", "fields"], [[f"`{k}`", ", ".join(v)] for k, v in SIGNAL_CLASSES.items()])


# ----------------------------------------------------------------------------- DSP blocks and flip-flops


def _fs_dsp(fs: FormatSet) -> dict[str, int]:
    """DSP blocks per RTL unit by the golden model's split rule (``tests/hdl/test_dsp_cost.py`` holds it to the RTL)."""
    from golden_model.fixed.dsp import dsp_blocks

    units = dict.fromkeys(("node_update", "rsqrt", "step_generator"), 0)
    for p in fs.products():
        if p.unit in units:
            units[p.unit] += p.count * dsp_blocks(p.a, p.b)
    return units


def _mult18x18d(component) -> int:
    """``MULT18X18D`` instances of ``component`` elaborated for ECP5."""
    from amaranth.hdl import Fragment, Instance

    from hdl.dsp import ECP5

    def count(fragment) -> int:
        if isinstance(fragment, Instance):
            return int(fragment.type == "MULT18X18D")
        return sum(count(sub) for sub, *_ in fragment.subfragments)

    return count(Fragment.get(component, ECP5))


@cache
def _flip_flops(preset: str) -> int:
    """Register bits of ``NodeUpdate`` elaborated for ECP5 (its RTLIL ``$dff`` cells, before Yosys's optimisations)."""
    from amaranth.back import rtlil

    from hdl import NodeUpdate
    from hdl.dsp import ECP5

    text = rtlil.convert(NodeUpdate(preset), platform=ECP5)
    return sum(int(w) for w in re.findall(r"cell \$\w*dff\w* .*?\n.*?parameter \\WIDTH (\d+)", text, re.S))


# ----------------------------------------------------------------------------- docs/hardware.md


def node_update_contract() -> str:
    """Initiation interval, latency (with its parts) and DSP blocks of the core's three components."""
    from hdl import NodeUpdate, RsqrtUnit, StepGenerator

    def column(fs: FormatSet):
        n = NodeUpdate(fs)
        parts = (n.front_stages, n.rsqrt_latency, n.back_stages, n.tail_stages, n.latency - n.pipeline_stages)
        return (n.latency, n.credits, parts, RsqrtUnit.latency_of(fs.rsqrt_config()), StepGenerator.latency_of(fs),
                _fs_dsp(fs))

    cols = {p: quietly(lambda: column(_preset(p))) for p in PRESETS}
    rows = [["initiation interval", "1 neighbour entry per clock", 1, 1]]
    for p, (latency, _, parts, rsqrt, step, _) in cols.items():
        rows.append([f"latency, {p} preset", f"{latency} clocks ({' + '.join(map(str, parts))})", rsqrt, step])
    dsp = {p: col[5] for p, col in cols.items()}

    def every(unit: str) -> str:  # one number when the presets agree, else one per preset, in PRESETS' order
        counts = [str(dsp[p][unit]) for p in PRESETS]
        return counts[0] if len(set(counts)) == 1 else " / ".join(counts)

    rows.append(["multipliers (18×18 DSP blocks, ECP5)",
                 ", ".join(f"{p} {dsp[p]['node_update'] + dsp[p]['rsqrt']}" for p in PRESETS) + ", each incl. the "
                 f"rsqrt unit's {every('rsqrt')} (the core adds the step generator's {every('step_generator')}: "
                 f"{', '.join(str(sum(dsp[p].values())) for p in PRESETS)})", every("rsqrt"), every("step_generator")])
    fs = _preset("default")
    from hdl.rsqrt import seed_rom_words

    seeds = fs.rsqrt_config()
    rows.append(["memories", f"seed ROM (block RAM; default {len(seed_rom_words(seeds)):,} words, the "
                 f"{seeds.seed_table_size:,} an input can address filled), header "
                 f"FIFO and result FIFO ({cols['default'][1]} entries), both distributed RAM in "
                 f"{NodeUpdate.FIFO_SLICE_BITS}-bit column slices", "seed ROM",
                 f"exp table ({1 << fs.lut_index_bits} rows)"])
    return _table(["", "`NodeUpdate` / `SpringflatCore`", "`RsqrtUnit`", "`StepGenerator`"], rows)


def node_update_flip_flops() -> str:
    """``NodeUpdate``'s register bits, elaborated for ECP5, per preset (about 5 s)."""
    return _table(["preset", "`NodeUpdate` flip-flops (RTLIL register bits, ECP5, before Yosys)"],
                  [[f"`{p}`", f"{_flip_flops(p):,}"] for p in PRESETS])


# ----------------------------------------------------------------------------- docs/hardware-units.md


def unit_figures() -> str:
    """Latency and ``MULT18X18D`` blocks of every unit in ``hdl/``, every preset."""
    from golden_model.coarse import DEFAULT_COARSE_DEGREE
    from golden_model.engine_spec.image import DEFAULT_CAPACITY
    from hdl import (AreaError, BetaDivider, CoarseCoefficients, CoarseNode, EnergyCheck, ForcePass, Integrator, Normaliser,
                     RsqrtUnit, StepGenerator)

    entries = 8192

    def column(fs: FormatSet) -> list[list[str]]:
        plain = fs.replace(lut_interpolate=False)
        fp, fpe, integ, area = ForcePass(fs), ForcePass(fs, energy=True), Integrator(fs), AreaError(fs)
        norm, energy, beta = Normaliser(fs), EnergyCheck(fs, entries), BetaDivider(fs)
        coarse = CoarseNode(fs, DEFAULT_COARSE_DEGREE, DEFAULT_CAPACITY.vertices)
        coarse_basis = CoarseNode(fs, DEFAULT_COARSE_DEGREE, DEFAULT_CAPACITY.vertices, basis_input=True)
        coefficients = CoarseCoefficients(fs, DEFAULT_COARSE_DEGREE, DEFAULT_CAPACITY.vertices)
        s = fp.stages
        return [
            [str(RsqrtUnit.latency_of(fs.rsqrt_config())), str(_mult18x18d(RsqrtUnit(fs)))],
            [str(StepGenerator.latency_of(fs)), str(_mult18x18d(StepGenerator(fs)))],
            [str(StepGenerator.latency_of(plain)), str(_mult18x18d(StepGenerator(plain)))],
            [f"{s.front} + {s.rsqrt} + {s.back} = {fp.latency}", str(_mult18x18d(fp))],
            [f"{fpe.latency}", str(_mult18x18d(fpe))],
            [str(integ.latency), str(_mult18x18d(integ))],
            [str(AreaError.latency_of(fs)), str(_mult18x18d(area))],
            [str(coarse.latency), str(_mult18x18d(coarse))],
            [str(coarse_basis.latency), str(_mult18x18d(coarse_basis))],
            [f"{norm.cycles(fs.error.frac_bits + 2)} to {norm.cycles(10 ** 6)}", "none"],
            [f"{energy.square_bits} + {energy.energy_bits} + {energy.latency - energy.square_bits - energy.energy_bits}"
             f" = {energy.latency}", "none"],
            [str(beta.latency), "none"],
            [f"{coefficients.cycles:,}", "none"],
        ]

    rows = {p: quietly(lambda: column(_preset(p))) for p in PRESETS}
    names = ["`RsqrtUnit`", "`StepGenerator`", "`StepGenerator`, `lut_interpolate` off", "`ForcePass`",
             "`ForcePass(energy=True)`", "`Integrator`", "`AreaError`",
             f"`CoarseNode`, degree {DEFAULT_COARSE_DEGREE}",
             f"`CoarseNode`, degree {DEFAULT_COARSE_DEGREE}, `basis_input`", "`Normaliser`: `cycles(shift)`, shift from "
             "F + 2 up", f"`EnergyCheck` at {entries:,} entries", "`BetaDivider`",
             f"`CoarseCoefficients`, degree {DEFAULT_COARSE_DEGREE}"]
    return _table(["unit", *(f"latency, {p}" for p in PRESETS), *(f"`MULT18X18D`, {p}" for p in PRESETS)],
                  [[name, *(rows[p][i][0] for p in PRESETS), *(rows[p][i][1] for p in PRESETS)]
                   for i, name in enumerate(names)])


# ----------------------------------------------------------------------------- docs/synthesis.md


def synth_components() -> str:
    """The streaming components ``springflat synth`` builds: latency, II and port bits (as ``synth --json``
    reports them)."""
    from sim.export import COMPONENTS, describe

    rows = []
    for spec in COMPONENTS:
        info = {p: quietly(lambda: describe(spec.build(_preset(p)), _preset(p), spec.module)) for p in PRESETS}
        rows.append([f"`{spec.module}`", info["default"]["initiation_interval"],
                     *(info[p]["latency"] for p in PRESETS), sum(port["width"] for port in info["default"]["ports"])])
    return _table(["component", "II", *(f"latency, {p}" for p in PRESETS), "port bits, default"], rows)


def _current_latency(row: dict[str, str]) -> int | None:
    """The latency the component has in today's RTL, for the row's preset (None for the engine)."""
    from hdl import GuardCertificate, NodeUpdate, RsqrtUnit, StepGenerator

    if not row["latency"] or row["preset"] not in PRESETS:
        return None
    fs = _preset(row["preset"])
    return quietly({"rsqrt_unit": lambda: RsqrtUnit.latency_of(fs.rsqrt_config()),
                     "step_generator": lambda: StepGenerator.latency_of(fs),
                     "node_update": lambda: NodeUpdate(fs).latency,
                     "springflat_core": lambda: NodeUpdate(fs).latency,
                     "guard_certificate": lambda: GuardCertificate.latency_of(fs),
                     "guard_certificate_ii2": lambda: GuardCertificate.latency_of(fs, 2)}[row["component"]])


class _Runs:
    """Footnote numbers for the commands and dates of a table's rows, in order of first use."""

    def __init__(self):
        self.runs: dict[tuple[str, str], int] = {}

    def __call__(self, row: dict[str, str]) -> str:
        return f"[{self.runs.setdefault((row['command'], row['date']), len(self.runs) + 1)}]"

    def notes(self) -> str:
        return "\n".join(f"- [{i}] `{command}`, {date}" for (command, date), i in self.runs.items())


def _fmax(row: dict[str, str]) -> str:
    return f"**{row['fmax_mhz']}**" if row["fmax_mhz"] else "—"


def _cell(value: str) -> str:
    return value.replace("|", "\\|") if value else "—"


def _latency(row: dict[str, str]) -> str:
    now = _current_latency(row)
    return row["latency"] if now is None or str(now) == row["latency"] else f"{row['latency']} (now {now})"


def _synthesis_rows(target: str, engine: bool) -> list[dict[str, str]]:
    from sim.results import read_rows

    return [r for r in read_rows() if r["target"] == target and (r["component"] == "springflat_engine") == engine]


def synthesis_components(target: str) -> str:
    """The measured rows of the streaming components for ``target``, with their runs."""
    runs = _Runs()
    rows = [[r["preset"], f"`{r['component']}`", _cell(r["seed"]), _cell(r["lut4"]), _cell(r["ff"]), _cell(r["dsp"]),
             _cell(r["bram"]), _cell(r["lutram"]), _latency(r), _fmax(r), _cell(r["critical_path"]), runs(r)]
            for r in _synthesis_rows(target, engine=False)]
    table = _table(["preset", "component", "seed", "LUT4", "FF", "DSP", "BRAM", "LUT RAM", "latency", "Fmax (MHz)",
                    "critical path (nextpnr, after routing) or why not placed", "run"], rows)
    return f"{table}\n\n{runs.notes()}"


def synthesis_engine(target: str = "ecp5") -> str:
    """The measured rows of ``springflat_engine`` (by capacity and seed), with their runs."""
    runs = _Runs()
    rows = [[r["preset"], r["capacity"].replace("/", " / "), _cell(r["seed"]),
             f"{r['lut4']} / {r['ff']} / {r['dsp']} / {r['bram']}", _fmax(r), _cell(r["critical_path"]), runs(r)]
            for r in _synthesis_rows(target, engine=True)]
    table = _table(["preset", "capacity (V / E / T)", "seed", "LUT4 / FF / DSP / BRAM (Yosys)", "Fmax (MHz)",
                    "critical path (nextpnr, after routing) or why not placed", "run"], rows)
    return f"{table}\n\n{runs.notes()}"


def datapath_throughput(target: str = "ecp5") -> str:
    """Per preset: DSP blocks per datapath, how many datapaths the device's DSP blocks hold, and what
    one datapath moves at the measured Fmax of ``springflat_core`` (seed 1, its latest run)."""
    from hdl import NodeUpdate
    from sim.export import describe
    from sim.synth import TARGETS

    capacity = TARGETS[target].capacity["dsps"]
    measured = {r["preset"]: r for r in _synthesis_rows(target, engine=False)
                if r["component"] == "springflat_core" and r["seed"] == "1" and r["fmax_mhz"]}
    rows = []
    for p in PRESETS:
        fs = _preset(p)
        dsp = _fs_dsp(fs)
        per_datapath = dsp["node_update"] + dsp["rsqrt"]
        ports = quietly(lambda: describe(NodeUpdate(fs), fs, "node_update"))["ports"]
        entry_bits = next(port["width"] for port in ports if port["name"] == "i__payload")
        row = measured.get(p)
        if row:
            f = float(row["fmax_mhz"]) * 1e6
            then = f", latency {row['latency']} then" if _latency(row) != row["latency"] else ""
            rate = (f"{row['fmax_mhz']} MHz ({row['date']}{then}): {f / 2 / 1e6:.1f} M edge updates/s, "
                    f"{entry_bits * f / 1e9:.1f} Gbit/s of entries")
        else:
            rate = "not measured"
        datapaths = (capacity - dsp["step_generator"]) // per_datapath
        rows.append([f"`{p}`", f"{per_datapath} + {dsp['step_generator']}", datapaths, entry_bits, rate])
    return _table(["preset", "DSP blocks: datapath + shared step generator",
                   f"datapaths per {TARGETS[target].device} ({capacity} DSP blocks)", "entry bits",
                   "one datapath at the core's measured Fmax (seed 1)"], rows)
