"""``springflat study``: fixed-point error studies and word-length optimisation.

Sweeps the knobs of a format set one at a time around a base (preset or JSON
file) over a set of cases (meshes × initial layouts × step modes), compares
every run with the float reference, runs the greedy word-length optimiser and
writes ``results.csv``, ``summary.csv``, ``report.md``, ``chosen.json`` and
PNG plots to ``--out``.  The runs are :mod:`.flow`'s, the model :mod:`golden_model.study`.

Wiring (in ``sim/cli.py``)::

    from .study.cli import add_parser as add_study_parser
    add_study_parser(sub)
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import functools
import math
import shlex
import sys
from pathlib import Path
from typing import Any

from golden_model.fixed.formats_set import CONTROLLER_FIELDS, FORMAT_FIELDS, FormatSet
from golden_model.params import ParameterError
from golden_model.study import (
    DATAPATH_FIELDS,
    DEFAULT_BITS,
    GENERATED_PARAMS,
    KNOBS,
    SIGNAL_CLASSES,
    AccuracyTarget,
    class_frac_bits,
    parse_bits,
    parse_knobs,
    preset_configs,
    sweep_configs,
    unexercised_classes,
)

from ..outputs import atomic_directory, atomic_write, check_not_foreign, check_output_directory, print_note, \
    progress_bar, report_owned
from ..run_options import OneOutput, integer_argument, load_format_set, mesh_names, number_argument, path_argument
from ..workers import local_workers
from .cases import STUDY_MESHES, build_cases
from .cost import multipliers
from .flow import ConfigSummary, StudyResult, run_study

__all__ = ["add_parser", "cmd_study", "write_outputs", "PLOT_FILES"]

PLOT_FILES = {"bits": "study-bits.png", "knobs": "study-knobs.png", "pareto": "study-pareto.png"}
#: Every file the report may hold (``chosen.json`` when a format set meets the target).
REPORT_FILES = ("results.csv", "summary.csv", "report.md", "chosen.json", *PLOT_FILES.values())
_BOTH = {"both": ("pca", "tutte"), "pca": ("pca",), "tutte": ("tutte",)}
_STEPS = {"both": ("fixed", "variable"), "fixed": ("fixed",), "variable": ("variable",)}


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``study`` subcommand on an argparse subparsers object."""
    p = subparsers.add_parser(
        "study", help="fixed-point error study and word-length optimisation",
        description="Sweep the fixed-point knobs (fraction bits per signal class, exp-LUT size and "
                    "interpolation, rsqrt seed/Newton steps, rounding) over meshes, compare every run with the "
                    "float reference, and pick the cheapest format set that meets an accuracy target. "
                    f"Generated and file meshes run with density auto, damping {GENERATED_PARAMS.damping}, "
                    f"tol-area = tol-shape = {GENERATED_PARAMS.tol_area}, tol-energy {GENERATED_PARAMS.tol_energy}, "
                    f"max-iter {GENERATED_PARAMS.max_iter}; built-ins with their paper parameters.")
    p.add_argument("meshes", nargs="*", metavar="MESH", default=list(STUDY_MESHES),
                   help=f"built-in or generated mesh ({', '.join(STUDY_MESHES)}) or a mesh file; "
                        "default: all six")
    p.add_argument("--init", choices=tuple(_BOTH), default="both", help="initial layout(s) (default both)")
    p.add_argument("--step", choices=tuple(_STEPS), default="both", help="step mode(s) (default both)")
    p.add_argument("--sweep", default="all", metavar="KNOBS",
                   help="comma list of knobs to sweep one at a time: all (default), none, frac (every signal "
                        f"class) or some of {', '.join(KNOBS)}")
    p.add_argument("--bits", default=None, metavar="MIN:MAX[:STEP]",
                   help="fraction bits tried for each signal class --sweep sweeps (default "
                        f"{':'.join(map(str, DEFAULT_BITS))})")
    p.add_argument("--base", default="default", metavar="PRESET|FILE",
                   help="format set the sweeps and the optimiser start from (default: default)")
    p.add_argument("--target", type=number_argument, default=1e-3,
                   help="accuracy target: max |dE_S|, |dE_C| of the final errors vs float (default 1e-3); "
                        "also required: same status, |d iterations| <= 1, no saturation")
    p.add_argument("--optimise", action=argparse.BooleanOptionalAction, default=True,
                   help="run the greedy word-length optimiser (default on)")
    p.add_argument("--cost", choices=("bits", "dsp"), default="bits",
                   help="what 'cheapest' minimises first: total datapath bits (default) or estimated DSP blocks")
    p.add_argument("--max-iter", type=integer_argument, default=None, help="override every case's iteration limit")
    p.add_argument("--jobs", "--workers", dest="jobs", type=integer_argument, default=None, metavar="N",
                   help="worker processes (default: the CPUs available); alias --workers")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS|local",
                   help="run the fixed-point runs on a Dask cluster: a scheduler address (tcp://host:8786), or "
                        "local for Dask's LocalCluster with --jobs processes")
    p.add_argument("--out", type=path_argument, action=OneOutput, default=Path("study-report"),
                   help="output directory (default study-report)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_study)
    return p


#: The first line of every study's report.md: how a directory shows it holds an earlier study's report.
REPORT_TITLE = "# Fixed-point error study"


def _progress_bars(enabled: bool):
    """``(update(phase, n), close(), totals)``: a :func:`sim.outputs.progress_bar` per phase, labelled with the
    phase, where ``enabled``."""
    bars: dict[str, Any] = {}

    def update(phase: str, n: int) -> None:
        if phase not in bars:
            for bar in bars.values():
                bar.close()
            bars[phase] = progress_bar(totals.get(phase), enabled, unit="run", label=phase)
        bars[phase].update(n)

    def close() -> None:
        for bar in bars.values():
            bar.close()

    totals: dict[str, int | None] = {}
    return update, close, totals


def cmd_study(args: argparse.Namespace) -> int:
    """Run the study described by ``args`` and write the report; returns the exit status."""
    bits = DEFAULT_BITS if args.bits is None else parse_bits(args.bits)
    knobs = parse_knobs(args.sweep)
    classes_swept = any(knob in SIGNAL_CLASSES for knob in knobs)
    if args.bits is not None and not classes_swept:
        remedy = ("give --sweep frac, or a class, instead" if not knobs
                  else "add frac, or a class, to --sweep")  # ('none' is given alone)
        raise ParameterError(f"--bits sets the fraction bits swept for each signal class; --sweep {args.sweep} "
                             f"sweeps no signal class: {remedy}")
    target = AccuracyTarget(args.target)
    if args.max_iter is not None and args.max_iter < 1:
        raise ParameterError(f"--max-iter must be >= 1, got {args.max_iter}")
    workers = local_workers(args.jobs, "--jobs", args.scheduler)
    base = load_format_set(args.base)
    out = args.out
    mesh_names(args.meshes or [])  # (a mesh given twice ran its cases twice)
    inputs = [("--base", None if FormatSet.names_preset(args.base) else Path(args.base)),
              *(("a mesh", Path(m)) for m in args.meshes or ())]
    check_output_directory(out, files=REPORT_FILES, inputs=inputs,  # before the study: the report is its end
                           labels={"chosen.json": "output (written when a format set meets the target)"})
    earlier = report_owned(out, REPORT_TITLE, REPORT_FILES)  # an earlier study's; anything else is the user's
    check_not_foreign(out, REPORT_FILES, earlier)
    cases = build_cases(args.meshes or list(STUDY_MESHES), _BOTH[args.init], _STEPS[args.step], args.max_iter)

    update, close, totals = _progress_bars(not args.quiet and sys.stderr.isatty())  # bars on a terminal only
    n_configs = len({c.key for c in [*preset_configs(base), *sweep_configs(base, knobs, bits)] if c.fs is not None})
    totals["sweep"] = (n_configs + 1) * len(cases)
    try:
        with contextlib.ExitStack() as stack:
            executor = None
            if args.scheduler is not None:
                from ..batch import dask_client

                executor = stack.enter_context(dask_client(args.scheduler, workers)).get_executor(pure=False)
            result = run_study(cases, base, knobs, bits, target, args.cost, args.optimise, workers, progress=update,
                               executor=executor)
    finally:
        close()
    command = " ".join(["springflat study", *map(shlex.quote, args.meshes or STUDY_MESHES),
                        f"--init {args.init} --step {args.step} --sweep {shlex.quote(args.sweep)}",
                        *([f"--bits {':'.join(map(str, bits))}"] if classes_swept else []),
                        f"--base {shlex.quote(str(args.base))} --target {args.target:g} --cost {args.cost}",
                        "--optimise" if args.optimise else "--no-optimise",
                        *([f"--max-iter {args.max_iter}"] if args.max_iter is not None else []),
                        f"--out {shlex.quote(str(out))}"])
    earlier_choice = bool(earlier) and (out / "chosen.json").is_file()
    # all of it or nothing; an earlier run's choice and sweep plots would pass for this report's
    with atomic_directory(out, stale=("chosen.json", PLOT_FILES["bits"], PLOT_FILES["knobs"]) if earlier else (),
                          inputs=inputs, owned=earlier) as build:
        write_outputs(result, build, command=command)
    chosen = result.chosen
    if chosen is None:
        print(f"no configuration meets the target {target.error:g} on the {_count(len(cases), 'case')}; "
              f"wrote {out / 'report.md'}"
              + (f"; removed {out / 'chosen.json'}, an earlier run's choice, which this report does not make"
                 if earlier_choice else ""))
    else:
        base_s = result.summary_of(result.base.label)
        print(f"chosen {chosen.config.label}: {chosen.cost.total_bits} datapath bits, {chosen.cost.dsp} DSP, "
              f"worst |dE| {chosen.worst_deviation:.3g} (base {base.name}: {base_s.cost.total_bits} bits, "
              f"{base_s.cost.dsp} DSP, {'meets' if base_s.meets else 'misses'} the target); "
              f"{result.runs} runs in {_seconds(result.seconds)}; wrote {out / 'report.md'}")
        if (refusal := _rtl_refusal(chosen.config.fs)) is not None:
            print_note(f"the RTL cannot be built with {out / 'chosen.json'} (the golden model runs it): {refusal}; "
                       "docs/study.md#recommendation")
        if (refusal := _file_default_refusal(chosen.config.fs)) is not None:
            print_note(f"{out / 'chosen.json'} runs the paper dynamics it was studied on; a mesh file's default, the "
                       f"momentum dynamics, refuses it ({refusal}): flatten with it and --dynamics paper")
    return 0


def _file_default_refusal(fs: FormatSet) -> str | None:
    """Why a mesh file's default run (the guarded momentum dynamics, :func:`sim.run_options.file_defaults`)
    cannot run on ``fs``, which the study chose on the paper dynamics, or ``None``."""
    from golden_model.fixed.engine import check_fixed_params
    from golden_model.fixed.measures import FixedPointError

    from ..run_options import FILE_PARAMS

    try:
        check_fixed_params(FILE_PARAMS, fs)
    except FixedPointError as exc:
        return str(exc)
    return None


# ----------------------------------------------------------------------------- outputs


def _seconds(seconds: float) -> str:
    """A duration as a person reads it: ``0.4 s`` (not ``0 s``), ``12 s``, ``135 s``."""
    return f"{seconds:.1f} s" if round(seconds, 1) < 10 else f"{seconds:.0f} s"


def _fmt(x: Any, digits: int = 3) -> str:
    if isinstance(x, float):
        if math.isnan(x):
            return "–"
        return f"{x:.{digits}g}"
    return str(x)


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with atomic_write(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        if not rows:
            return
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in row.items()})


def chosen_formats(result: StudyResult) -> FormatSet | None:
    """The chosen configuration as a FormatSet named for the study, with notes."""
    chosen = result.chosen
    if chosen is None:
        return None
    meshes = sorted({c.mesh_name for c in result.cases})
    how = (f"greedy word-length optimiser, cost metric {result.metric}" if chosen.config.kind == "optimiser" else
           f"cost metric {result.metric}, among the base, the presets and the sweeps"
           + ("" if _optimised(result) else ": the optimiser did not run"))
    refusal = _rtl_refusal(chosen.config.fs)
    notes = {"_": (f"Chosen by 'springflat study' ({how}) "
                   f"as the cheapest configuration meeting max |dE_S|, |dE_C| <= {result.target.error:g} vs the "
                   f"float engine, same status, |d iterations| <= {result.target.iterations}, no saturation, on "
                   f"{_count(len(result.cases), 'case')}: {', '.join(meshes)}; started from '{result.base.fs.name}'. "
                   f"Source configuration: {chosen.config.label}."
                   + (f" The RTL cannot be built with it (the golden model runs it): {refusal}." if refusal else ""))}
    return chosen.config.fs.replace(name=f"study-{result.target.error:g}", notes=notes)


def _count(n: int, noun: str) -> str:
    """``1 case``, ``3 cases``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


@functools.lru_cache(maxsize=4)
def _rtl_refusal(fs: FormatSet) -> str | None:
    """:func:`sim.export.rtl_refusal`, once per format set (the report, ``chosen.json`` and stdout say it)."""
    from ..export import rtl_refusal

    return rtl_refusal(fs)


def _swept(result: StudyResult) -> bool:
    """Whether any knob was swept (not ``--sweep none``): the sweep plots and their report section."""
    return any(s.config.kind == "sweep" for s in result.summaries)


def _swept_bits(result: StudyResult) -> bool:
    """Whether a signal class's fraction bits were swept (not only other knobs, such as ``--sweep rounding``):
    the deviation-against-bits plot and its table."""
    return any(s.config.kind == "sweep" and s.config.knob in SIGNAL_CLASSES for s in result.summaries)


def _optimised(result: StudyResult) -> bool:
    """Whether the greedy optimiser ran (``--optimise``, and a base that meets the target)."""
    return result.optimisation is not None and result.optimisation.best is not None


def write_outputs(result: StudyResult, out: Path, command: str = "springflat study") -> dict[str, Path]:
    """results.csv, summary.csv, chosen.json, the plots and report.md."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {name: out / name for name in ("results.csv", "summary.csv", "report.md")}
    by_label = {s.config.label: s.config for s in result.summaries}
    rows = []
    for r in result.records:
        c = by_label[r.config]
        rows.append({"config": r.config, "kind": c.kind, "knob": c.knob, "value": c.value,
                     **{k: v for k, v in r.row(result.target).items() if k != "config"}})
    _write_csv(paths["results.csv"], rows)
    _write_csv(paths["summary.csv"], [s.row(result.metric) for s in result.summaries])
    fs = chosen_formats(result)
    if fs is not None:
        paths["chosen.json"] = out / "chosen.json"
        with atomic_write(paths["chosen.json"]) as tmp:
            fs.save(tmp)
    elif (out / "chosen.json").exists():
        (out / "chosen.json").unlink()  # a stale choice from an earlier run would mislead
    plots = {PLOT_FILES["pareto"]: _plot_pareto}
    if _swept(result):  # else empty axes, which the report does not link
        plots |= {PLOT_FILES["knobs"]: _plot_knobs}
    if _swept_bits(result):
        plots |= {PLOT_FILES["bits"]: _plot_bits}
    for name, plot in plots.items():
        paths[name] = out / name
        plot(result, paths[name])
    with atomic_write(paths["report.md"]) as tmp:
        Path(tmp).write_text(report_markdown(result, fs, command), encoding="utf-8")
    return paths


# ----------------------------------------------------------------------------- plots


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


_FLOOR = 1e-8  # deviations of exactly 0 on a log axis


def _y(dev: float) -> float:
    return max(dev, _FLOOR)


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    with atomic_write(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    _pyplot().close(fig)


def _plot_bits(result: StudyResult, path: Path) -> None:
    plt = _pyplot()
    base = result.base
    base_s = result.summary_of(base.label)
    fig, ax = plt.subplots(figsize=(9.5, 5.6))
    colours = plt.get_cmap("tab20").colors
    markers = "osD^v<>ph*XP8"
    for k, (cls, fields) in enumerate(SIGNAL_CLASSES.items()):
        pts = [(s.config.value, s) for s in result.summaries
               if s.config.kind == "sweep" and s.config.knob == cls and s.config.fs is not None
               and not math.isnan(s.worst_deviation)]
        if not pts:
            continue
        pts.append((class_frac_bits(base.fs, cls), base_s))
        pts.sort(key=lambda t: t[0])
        x = [p[0] for p in pts]
        y = [_y(p[1].worst_deviation) for p in pts]
        colour, marker = colours[(2 * k) % 20 if k < 10 else (2 * k + 1) % 20], markers[k % len(markers)]
        ax.plot(x, y, "-", color=colour, lw=1.2, label="+".join(fields))
        ok = [(a, b) for (a, s), b in zip(pts, y) if s.meets]
        bad = [(a, b) for (a, s), b in zip(pts, y) if not s.meets]
        if ok:
            ax.plot(*zip(*ok), marker, color=colour, ms=5, ls="none")
        if bad:
            ax.plot(*zip(*bad), marker, color=colour, ms=6, ls="none", mfc="none")
    ax.axhline(result.target.error, color="k", ls="--", lw=1, label=f"target {result.target.error:g}")
    ax.set_yscale("log")
    ax.set_xlabel("fraction bits of the signal class (others at the base)")
    ax.set_ylabel("worst max(|ΔE_S|, |ΔE_C|) over the cases")
    ax.set_title(f"Final-error deviation from float vs fraction bits (base '{base.fs.name}', "
                 f"{_count(len(result.cases), 'case')}); hollow = misses the target")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2, loc="upper right")
    _save(fig, path)


def _plot_knobs(result: StudyResult, path: Path) -> None:
    plt = _pyplot()
    base_s = result.summary_of(result.base.label)
    rows = [base_s] + [s for s in result.summaries
                       if s.config.kind in ("sweep", "preset") and s.config.knob not in SIGNAL_CLASSES]
    fig, ax = plt.subplots(figsize=(8.5, max(2.5, 0.32 * len(rows) + 1.2)))
    labels, values, colours = [], [], []
    for s in rows:
        labels.append(s.config.label + ("" if s.config.fs is not None else " (invalid)"))
        dev = s.worst_deviation
        values.append(_y(dev) if not math.isnan(dev) else _FLOOR)
        colours.append("tab:blue" if s.meets else ("tab:gray" if math.isnan(dev) else "tab:red"))
    y = range(len(rows))
    ax.barh(list(y), values, color=colours)
    ax.set_yticks(list(y), labels, fontsize=8)
    ax.invert_yaxis()
    ax.axvline(result.target.error, color="k", ls="--", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("worst max(|ΔE_S|, |ΔE_C|) over the cases (red: misses the target, grey: refused)")
    ax.set_title("Other knobs, one at a time around the base")
    ax.grid(alpha=0.3, axis="x", which="both")
    _save(fig, path)


def _pareto(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    front, best = [], math.inf
    for c, d in sorted(points):
        if d < best:
            front.append((c, d))
            best = d
    return front


def _plot_pareto(result: StudyResult, path: Path) -> None:
    plt = _pyplot()
    metric = result.metric
    fig, ax = plt.subplots(figsize=(9, 5.6))
    valid = [s for s in result.summaries if s.cost is not None and not math.isnan(s.worst_deviation)]
    for meets, colour, label in ((False, "tab:red", "misses the target"), (True, "tab:blue", "meets the target")):
        pts = [(s.cost.value(metric), _y(s.worst_deviation)) for s in valid
               if s.meets == meets and s.config.kind != "optimiser"]
        if pts:
            ax.scatter(*zip(*pts), s=14, color=colour, alpha=0.6, label=f"sweep/presets: {label}")
    opt = [s for s in result.summaries if s.config.kind in ("base", "optimiser") and s.cost is not None]
    if result.optimisation is not None and len(opt) > 1:
        ax.plot([s.cost.value(metric) for s in opt], [_y(s.worst_deviation) for s in opt], ".-", color="tab:green",
                lw=1, ms=5, label="optimiser path")
    front = _pareto([(s.cost.value(metric), _y(s.worst_deviation)) for s in valid])
    if front:
        ax.step(*zip(*front), where="post", color="k", lw=0.8, alpha=0.6, label="Pareto front")
    for s in valid:
        if s.config.kind in ("base", "preset") or (result.chosen is not None and s is result.chosen):
            name = "chosen" if result.chosen is not None and s is result.chosen else s.config.label
            ax.annotate(name, (s.cost.value(metric), _y(s.worst_deviation)), fontsize=8,
                        xytext=(4, 4), textcoords="offset points")
            ax.plot(s.cost.value(metric), _y(s.worst_deviation), "k*", ms=9)
    ax.axhline(result.target.error, color="k", ls="--", lw=1, label=f"target {result.target.error:g}")
    ax.set_yscale("log")
    ax.set_xlabel("total datapath bits" if metric == "bits" else "estimated 18×18 DSP blocks")
    ax.set_ylabel("worst max(|ΔE_S|, |ΔE_C|) over the cases")
    ax.set_title("Cost vs accuracy")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    _save(fig, path)


# ----------------------------------------------------------------------------- report


def _cost_cells(s: ConfigSummary) -> str:
    if s.cost is None:
        return "– | – | –"
    return f"{s.cost.total_bits} | {s.cost.dsp} | {s.cost.rom_bits}"


def _runs_count(value: int | None) -> str:
    """A count over the runs, or '–' where none ran."""
    return "–" if value is None else str(value)


def _text_cell(text: str) -> str:
    """Free text as one markdown table cell: its pipes (``|dE| 3.8e-05 > 1e-07``) would split it."""
    return text.replace("|", "\\|")


def _summary_row(s: ConfigSummary) -> str:
    return (f"| {_text_cell(s.config.label)} | {_cost_cells(s)} | {_fmt(s.worst_deviation)} | "
            f"{_fmt(s.worst_max_position)} | {_runs_count(s.max_abs_d_iterations)} | "
            f"{_runs_count(s.status_mismatches)} | {_runs_count(s.saturations)} | "
            f"{s.refused} | {'yes' if s.meets else 'no'} | {_text_cell(s.first_failure or s.config.error or '')} |")


_SUMMARY_HEAD = ["| config | total bits | DSP | ROM bits | worst \\|ΔE\\| | worst max pos. err. | max \\|Δit\\| | "
                 "status mism. | saturations | refused | meets | first failure |",
                 "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|"]


def _knob_line(fs: FormatSet) -> str:
    return (f"rsqrt_seed_bits {fs.rsqrt_seed_bits}, rsqrt_newton_steps {fs.rsqrt_newton_steps}, lut_index_bits "
            f"{fs.lut_index_bits}, lut_interpolate {str(fs.lut_interpolate).lower()}, rounding {fs.rounding.value}")


def report_markdown(result: StudyResult, chosen_fs: FormatSet | None, command: str = "springflat study") -> str:
    t, metric = result.target, result.metric
    base = result.base
    base_s = result.summary_of(base.label)
    cpu = sum(r.seconds for r in result.records)
    lines = [
        REPORT_TITLE,
        "",
        f"Generated by `{command}`: {_count(len(result.cases), 'case')}, "
        f"{_count(len(result.summaries), 'configuration')} evaluated "
        f"on every case, {result.runs} fixed-point runs in {_seconds(result.seconds)}.",
        "",
        f"**Target**: on every case, the final E_S and E_C within {t.error:g} (absolute) of the float reference, "
        f"the same status, at most {t.iterations} iteration(s) difference and "
        f"{'no' if t.saturations == 0 else f'at most {t.saturations}'} saturation events. "
        f"**Cost**: `{metric}` (compared as {'(total bits, DSP, ROM bits)' if metric == 'bits' else '(DSP, total bits, ROM bits)'}; "
        "see `docs/study.md`).",
        "",
        "## Cases (float reference)",
        "",
        "| case | V | F | status | iterations | E_S | E_C | φ_S / φ_C / ε | N_max |",
        "|---|---:|---:|---|---:|---:|---:|---|---:|",
    ]
    for c in result.cases:
        f = result.floats[c.name]
        p = c.params
        lines.append(f"| {c.name} | {c.mesh.n_vertices} | {c.mesh.n_faces} | {f.status} | {f.iterations} | "
                     f"{f.final.area_error:.4g} | {f.final.shape_error:.4g} | {p.tol_area:g} / {p.tol_shape:g} / "
                     f"{p.tol_energy:g} | {p.max_iter} |")

    lines += ["", "## Result", ""]
    chosen = result.chosen
    if chosen is None:
        lines.append(f"No evaluated configuration meets the target on every case.")
    else:
        lines.append(f"The cheapest configuration that meets the target is **{chosen.config.label}**: "
                     f"{chosen.cost.total_bits} datapath bits, {chosen.cost.dsp} DSP blocks, "
                     f"{chosen.cost.rom_bits} ROM bits, worst |ΔE| {chosen.worst_deviation:.3g}.")
        if (refusal := _rtl_refusal(chosen.config.fs)) is not None:
            lines.append(f"**The RTL cannot be built with it** (`verilog`, `rtl-check` and `synth` refuse it; the "
                         f"golden model runs it, so it bounds what a narrower datapath could reach): {refusal}. Its "
                         "DSP count below is the split rule's estimate for a datapath that does not exist.")
    lines.append(f"The base `{base.fs.name}` {'meets' if base_s.meets else 'misses'} the target "
                 f"(worst |ΔE| {_fmt(base_s.worst_deviation)}{'' if base_s.meets else '; ' + base_s.first_failure}).")
    lines += ["", *_SUMMARY_HEAD, _summary_row(base_s)]
    lines += [_summary_row(s) for s in result.summaries if s.config.kind == "preset"]
    if chosen is not None and chosen is not base_s:
        lines.append(_summary_row(chosen).replace(f"| {chosen.config.label} |",
                                                  f"| **chosen** ({chosen.config.label}) |", 1))

    if chosen_fs is not None:
        lines += ["", "### Chosen formats", "",
                  f"| field | {base.fs.name} | chosen | Δ width |", "|---|---|---|---:|"]
        for f in FORMAT_FIELDS:
            a, b = getattr(base.fs, f), getattr(chosen_fs, f)
            mark = "" if f in DATAPATH_FIELDS else " (controller)" if f in CONTROLLER_FIELDS else " (step generator)"
            lines.append(f"| {f}{mark} | {a} | {'**' + str(b) + '**' if a != b else str(b)} | "
                         f"{b.width - a.width:+d} |")
        lines += ["", f"Knobs: {base.fs.name}: {_knob_line(base.fs)}; chosen: {_knob_line(chosen_fs)}.", "",
                  "Multipliers of the chosen configuration (18×18 DSP blocks by the RTL's split rule):", "",
                  "| product | width a | width b | count | DSP each |", "|---|---:|---:|---:|---:|"]
        lines += [f"| {n} | {a} | {b} | {c} | {d} |" for n, a, b, c, d in multipliers(chosen_fs)]
        lines += ["", "The chosen configuration as a format-set file (`chosen.json`; "
                  "`springflat flatten --engine fixed --formats chosen.json` loads it):", "", "```json",
                  chosen_fs.to_json().rstrip(), "```"]

    unexercised = unexercised_classes(c.params for c in result.cases)
    opt = result.optimisation
    if opt is not None:
        lines += ["", "## Optimiser", ""]
        if unexercised:
            lines += [f"Not moved: {', '.join(unexercised)}, which no case reads (their widths change no result "
                      "here: the cases run no fold barrier, no momentum dynamics, or no damping), so they keep "
                      f"`{base.fs.name}`'s widths.", ""]
        if opt.best is None:
            lines.append(f"Not run: {opt.reason}.")
        else:
            lines += [f"Greedy from `{base.fs.name}` ({opt.candidates} candidate configurations tried, "
                      f"{opt.runs} fixed-point runs). Accepted moves:", "",
                      "| step | move | total bits | DSP | ROM bits | worst \\|ΔE\\| | moves rejected first |",
                      "|---:|---|---:|---:|---:|---:|---:|"]
            for k, st in enumerate(opt.steps, 1):
                lines.append(f"| {k} | {_text_cell(st.move)} | {st.cost.total_bits} | {st.cost.dsp} | {st.cost.rom_bits} | "
                             f"{st.worst_deviation:.3g} | {st.rejected} |")
            lines += ["", "Why no further single move is acceptable from the result:", "",
                      "| move | reason |", "|---|---|"]
            lines += [f"| {_text_cell(m)} | {_text_cell(why)} |" for m, why in opt.rejected]

    if _swept(result):
        lines += ["", "## One-knob sweeps", ""]
    if _swept_bits(result):
        sweep = [s for s in result.summaries if s.config.kind == "sweep"]
        lines += [f"Each signal class's fraction bits, everything else at `{base.fs.name}`: the fewest swept bits "
                  "that still meet the target (in isolation — combined reductions add up).", "",
                  "| class | fields | base bits | fewest swept bits meeting the target | its worst \\|ΔE\\| |",
                  "|---|---|---:|---:|---:|"]
        for cls, fields in SIGNAL_CLASSES.items():
            runs = [s for s in sweep if s.config.knob == cls]
            if not runs:
                continue
            if cls in unexercised:  # any width "meets": no finding
                lines.append(f"| {cls} | {'+'.join(fields)} | {class_frac_bits(base.fs, cls)} | – (no case reads "
                             "it) | – |")
                continue
            ok = [s for s in runs if s.meets and s.config.value < class_frac_bits(base.fs, cls)]
            best = min(ok, key=lambda s: s.config.value) if ok else None
            lines.append(f"| {cls} | {'+'.join(fields)} | {class_frac_bits(base.fs, cls)} | "
                         f"{best.config.value if best else '–'} | {_fmt(best.worst_deviation) if best else '–'} |")
        lines += ["", f"![deviation vs fraction bits]({PLOT_FILES['bits']})", ""]
    if _swept(result):
        lines += [f"![other knobs]({PLOT_FILES['knobs']})", ""]
    lines += [f"![cost vs accuracy]({PLOT_FILES['pareto']})", ""]

    meeting = sorted((s for s in result.summaries if s.meets), key=lambda s: (s.cost.key(metric), s.worst_deviation))
    lines += ["## Cheapest configurations meeting the target", "", *_SUMMARY_HEAD]
    lines += [_summary_row(s) for s in meeting[:15]]
    lines += ["", "## Every configuration", "", *_SUMMARY_HEAD]
    lines += [_summary_row(s) for s in result.summaries]
    lines += ["", f"Per-run details: `results.csv` (one row per configuration × case); per configuration: "
              f"`summary.csv`. Fixed-point run time: {_seconds(cpu)} summed over the runs kept.", ""]
    return "\n".join(lines)
