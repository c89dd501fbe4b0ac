"""The ``springflat`` console command.

Subcommands:

* ``flatten [MESH]``: flatten a mesh (a file or a built-in, default ``surf1``); with several meshes or
  ``--out-dir``, a batch on all cores or a Dask cluster (:mod:`sim.batch`);
* ``paper [--out DIR]``: reproduce the paper's Tables VI–VII and figures;
* ``verilog``: the RTL as Verilog with its interface description (:mod:`sim.export`);
* ``rtl-check``: a flattening through the RTL on a Verilog simulator (:mod:`sim.rtl_check`);
* ``study``: the fixed-point error study and word-length optimiser (:mod:`sim.study`);
* ``synth``: synthesis, placement and routing for ECP5 or iCE40, and the handoff bundle (:mod:`sim.synth`).

Bad input never produces a traceback: every user error, an unreadable or
unwritable file included, is one line on stderr (``springflat: error: ...``)
and exit status 2, and leaves no file behind; Ctrl-C is the one line
``springflat: interrupted`` and exit status 130, with no output left behind
(the policy for output paths: :mod:`sim.outputs`).  A run that diverges exits with
status 3 after writing what was asked for; a batch some of whose meshes failed, with status 4.  ``--json`` prints standard JSON:
a number that is not finite is ``null`` and its key is listed in
``non_finite`` (the status, ``diverged``, says why).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import math
import os
import signal
import sys
import threading
import traceback
import warnings
from pathlib import Path

import numpy as np

from golden_model.builtin import is_builtin
from golden_model.coarse import COARSE_DEGREE_MAX
from golden_model.engine_spec.image import DEFAULT_CAPACITY, LANES
from golden_model.files import describe_os_error
from golden_model.fixed.formats_set import FormatSet, FormatSetNotBuildable
from golden_model.mesh import one_line
from golden_model.params import FlattenParams
from golden_model.results import FlattenResult

from .clock import ENGINE_TARGET_MHZ
from .engines import DEFAULT_ENGINE, ENGINE_NAMES, ENGINES, engine_named
from .exit_codes import EXIT_DIVERGED, EXIT_USAGE, STOP_SIGNALS, answered_signals
from .flatten_run import (PATTERN_OUTPUTS, check_options_used, check_print_size, divergence_note, human_line,
                          json_summary, notes_on_cut_files, output_paths, pattern_drawing, pattern_notes, run_flatten,
                          run_formats, what_was_used, write_outputs)
from .layouts import LAYOUT_METHODS
from .mesh_io import MESH_SUFFIXES
from .outputs import STANDARD_OUTPUT, NamedStandardOutput, OutputError, atomic_directory, check_distinct, \
    check_link_target, check_not_foreign, check_not_interrupted, check_output_path, file_ending, on_interrupt, \
    print_note, received_signal, record_written_outputs, report_owned, reset_interrupted, written_outputs
from .patterns import add_pattern_options, check_not_a_mesh, pattern_ending
from .run_options import (
    USER_ERRORS,
    CommandParser,
    OneOutput,
    UserError,
    add_run_options,
    default_init,
    file_path_argument,
    holes_mode,
    input_files,
    integer_argument,
    load_format_set,
    params_from_args,
    path_argument,
    resolve_mesh,
    strict_json,
)
from .synth import VERILOG_TARGETS
from .version import installed_version


def _written_line(lead: str) -> str:
    """``lead`` and the outputs the command has put in place (three named, and how many more), or ``""``."""
    written = written_outputs()
    if not written:
        return ""
    return lead + ", ".join(written[:3]) + (f" and {len(written) - 3} more" if len(written) > 3 else "")


def cmd_flatten(args: argparse.Namespace) -> int:
    if args.more_meshes or args.out_dir is not None or args.scheduler is not None:
        from .batch import cmd_batch

        return cmd_batch(args)
    mesh, defaults = resolve_mesh(args.mesh, holes_mode(args.fill_holes, args.keep_holes))
    params = params_from_args(args, defaults, fixed_point=engine_named(args.engine).fixed_point)
    check_outputs(args)
    check_print_size(args, mesh)
    result = run_flatten(args, mesh, params, progress=sys.stderr.isatty(),  # progress to a terminal only
                         second_core=True)  # one mesh: SLIM's start may run beside ARAP
    drawing = pattern_drawing(args, mesh, result)  # the files' and their notes' (the seam outline once)
    write_outputs(args, mesh, result, drawing)
    if args.json:
        print(strict_json(json_summary(args, mesh, params, result)))
    else:
        print(human_line(mesh, result))
        print(what_was_used(params, args.init, result, mesh), file=sys.stderr)
    formats = run_formats(args)
    for note in (*pattern_notes(params, mesh, result, formats=formats), *notes_on_cut_files(args, mesh, result, drawing),
                 _energy_rule_note(params, result), _error_resolution_note(formats)):
        if note:
            print_note(note)
    if result.status == "diverged":
        unwritten = [(flag, path) for _, flag, _, path in output_paths(args) if flag in PATTERN_OUTPUTS]
        kept = [f"'{path}'" for _, path in unwritten if os.path.lexists(path)]
        flags = ", ".join(dict.fromkeys(flag for flag, _ in unwritten))
        print(f"springflat: {divergence_note(params, result)}"
              + (f"; no pattern written ({flags})" if unwritten else "")
              + (f", {' and '.join(kept)} kept as {'they were' if len(kept) > 1 else 'it was'}" if kept else ""),
              file=sys.stderr)
        return EXIT_DIVERGED
    return 0


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before the run, an output path that cannot work, two outputs that are one file, and an output
    that links to a file of another kind."""
    for _, flag, endings, path in output_paths(args):
        check_output_path(path, flag, endings, ending_hint=", or give --out-dir DIR for a batch, which takes endings")
    check_options_used(args)
    if args.jobs is not None:
        raise UserError("--jobs sets a batch's worker processes: give several meshes, or --out-dir DIR")
    if args.init is None:
        args.init = default_init(args.mesh)
    _check_distinct_files(args)
    for dest, flag, _, path in output_paths(args):
        check_link_target(path, flag, pattern_ending if dest == "out" else file_ending)
        if dest == "out":
            check_not_a_mesh(path, flag)


#: Iterations :func:`_energy_rule_note` looks back over.
ENERGY_NOTE_WINDOW = 50


def _energy_rule_note(params: FlattenParams, result: FlattenResult) -> str | None:
    """Why a fixed-point run ended at N_max under the energy rule, when its energy never settled below ε.

    The fixed-point energy changes by its own rounding from one iteration to the next; near the
    minimum that floor can be above ``--tol-energy`` (docs/dynamics.md), so the rule cannot hold.
    """
    energy = np.asarray(result.history.energy[-ENERGY_NOTE_WINDOW - 1:], dtype=float)
    if (not engine_named(result.engine).fixed_point or result.status != "max-iterations" or not params.tol_energy > 0
            or len(energy) <= ENERGY_NOTE_WINDOW or not np.isfinite(energy).all()
            or result.extra.get("saturations")):  # clamped values, not rounding, move that energy
        return None
    steps = np.diff(energy)
    if np.count_nonzero(steps > 0) < ENERGY_NOTE_WINDOW // 4:  # still descending, not at the floor
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        change = np.abs(steps) / energy[:-1]
    smallest = float(np.nanmin(change)) if np.isfinite(change).any() else math.inf
    if not smallest > params.tol_energy:
        return None
    return (f"over the last {len(change)} iterations the relative energy change never fell below {smallest:.2g}, "
            f"above --tol-energy {params.tol_energy:g}: the fixed-point energy moves by its rounding at that level "
            "near the minimum, so the rule could not hold (a larger --tol-energy stops there; docs/dynamics.md)")


#: The resolution of E_S and E_C as printed (four decimals): a coarser error format gets a note.
PRINTED_ERROR_RESOLUTION = 5e-5


def _error_resolution_note(formats: FormatSet | None) -> str | None:
    """E_S and E_C of the fixed-point engine are values of the ``error`` format: say so when it is coarser
    than the printed digits (an error of 0.0053 reads 0.0000 in u0.1)."""
    if formats is None or formats.error.lsb <= PRINTED_ERROR_RESOLUTION:
        return None
    return (f"format set '{formats.name}' holds E_S and E_C in error {formats.error}: they are multiples of "
            f"{formats.error.lsb:.3g}, the values above are rounded to that")


def _check_distinct_files(args: argparse.Namespace) -> None:
    """No two outputs may be one file, and no output may be an input (the mesh, the --init or --formats
    file), compared by device and inode."""
    check_distinct([(flag, path) for _, flag, _, path in output_paths(args)], input_files(args))


def cmd_paper(args: argparse.Namespace) -> int:
    from .paper import REPORT_FILES, REPORT_TITLE, reproduce_paper

    out = args.out
    owned = report_owned(out, REPORT_TITLE, REPORT_FILES)  # an earlier report's files; any other is the user's
    check_not_foreign(out, REPORT_FILES, owned)  # (before the runs)
    with atomic_directory(out, owned=owned) as build:  # all of the report or nothing, also on Ctrl-C
        report = reproduce_paper(build, init=args.init, progress=not args.quiet and sys.stderr.isatty())
    print(f"wrote {out / report.name}")
    return 0


def cmd_verilog(args: argparse.Namespace) -> int:
    from .export import BUNDLE_FILES, bundle_readme, export_engine_bundle, export_verilog
    from .top_names import COMPONENT_SUMMARIES
    from .register_map_export import engine_capacity
    from .clock import clock_sdc
    from .synth import bundle_owned, earlier_bundle_files, ecp5_overflow, record_bundle_files
    from .outputs import check_build_so_far
    from hdl.dsp import DspPlatform

    formats = load_format_set(args.formats)
    capacity = engine_capacity(args.capacity, formats, guard=args.build_guard, lanes=args.lanes,
                               coarse_degree=args.coarse_degree)
    dsp = VERILOG_TARGETS[args.target]
    platform = DspPlatform(dsp) if dsp else None
    out = args.out
    inputs = [("--formats", None if FormatSet.names_preset(args.formats) else Path(args.formats))]
    earlier, owned = earlier_bundle_files(out), bundle_owned(out)
    check_not_foreign(out, [*(f"{module}.v" for module in COMPONENT_SUMMARIES),  # before the half minute's work
                            *(name for name in BUNDLE_FILES if not name.endswith("/"))], owned)
    with atomic_directory(out, inputs=inputs, stale=earlier,  # all of the bundle or nothing, also on Ctrl-C
                          owned=owned) as build:  # (a file of the user's in --out is not replaced)
        print(f"springflat verilog: exporting every component and springflat_engine (capacity "
              f"{capacity.as_option()}, {args.target}) to {out} ...", file=sys.stderr)  # half a minute of silence
        # the build that met 125 MHz fits; any other is counted (seconds), since the bundle's clock says 125
        if (formats, capacity) != (FormatSet.preset("default"), DEFAULT_CAPACITY) and \
                (over := ecp5_overflow(formats, capacity)):
            print_note(f"this engine does not fit the largest ECP5: it needs {over} (docs/synthesis.md: the "
                       "capacities that fit)")
        interface = export_verilog(formats, build, platform=platform)
        check_build_so_far()  # a --formats file named interface.json: refused before the engine's export
        engine = export_engine_bundle(formats, capacity, build, platform=platform)
        (Path(build) / "clock.sdc").write_text(clock_sdc(ENGINE_TARGET_MHZ))
        files = sorted([path.name + ("" if path.is_file() else "/") for path in Path(build).iterdir()]
                       + ["README.md"])
        (Path(build) / "README.md").write_text(bundle_readme(formats, capacity, files, installed_version(),
                                                             platform))
        record_bundle_files(Path(build))
    for name, c in interface["components"].items():
        print(f"{out / (name + '.v')}: latency {c['latency']}, II {c['initiation_interval']}")
    print(f"{out / 'interface.md'}, {out / 'interface.json'}; ROM contents {out / 'rsqrt_seed.hex'}, "
          f"{out / 'exp_table.hex'}")
    print(f"{out / engine['files'][0]}: capacity {capacity.vertices} vertices, {capacity.entries} entries, "
          f"{capacity.triangles} triangles{'' if capacity.guard else ', no step guard'}"
          f"{f', coarse space of degree {capacity.coarse_degree}' if capacity.coarse_degree else ''}; {engine['bus']}")
    print(", ".join(str(out / f) for f in engine["files"][1:]))
    print(f"{out / 'clock.sdc'}: clk at {ENGINE_TARGET_MHZ:g} MHz")
    if platform is not None:
        print(f"{out / 'sim_models'}/: the ECP5 primitives' simulation models")
    print(f"{out / 'README.md'}: which file is which")
    return 0


def add_engine_options(parser: argparse.ArgumentParser) -> None:
    """``--engine`` and ``--formats`` of ``flatten`` (also the keywords of ``springflat.flatten``)."""
    parser.add_argument("--engine", choices=ENGINE_NAMES, default=DEFAULT_ENGINE,
                        help="; ".join(f"{e.name}: {e.help}" for e in ENGINES))
    parser.add_argument("--formats", default=None, metavar="PRESET|FILE",
                        help=f"fixed-point format set: a preset ({', '.join(FormatSet.presets())}; "
                             "docs/fixed-point.md) or a JSON file (default: default)")


def build_parser() -> argparse.ArgumentParser:
    parser = CommandParser(
        prog="springflat",
        description="Flatten triangle-mesh patches with the variable step-size mass-spring method, "
                    "and verify its fixed-point hardware.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {installed_version()}")
    # not required here: main() names an unknown option before it asks for the command
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=CommandParser)

    p = sub.add_parser("flatten", help="flatten a mesh", description="Flatten a mesh patch (Algorithm 1).")
    add_run_options(p)
    add_engine_options(p)
    from .board_run import add_board_options

    add_board_options(p)
    p.add_argument("--out", type=file_path_argument, action="append", metavar="FILE",
                   help="the pattern, by its ending (repeat for several): .dxf (cut line on layer CUT), .pdf or "
                        ".svg (true scale on --paper sheets), .obj (the 3D mesh with the pattern as vt), "
                        ".flat.obj (the layout, z = 0), .flat.svg (the layout coloured by distortion)")
    p.add_argument("--history", type=file_path_argument, action=OneOutput, metavar="FILE.csv", help="per-iteration CSV")
    p.add_argument("--plot", type=file_path_argument, action=OneOutput, metavar="FILE.png",
                   help="PNG of the layouts and error curves")
    p.add_argument("--json", action="store_true", help="print one JSON object with the results (a batch: one "
                   "line per mesh, then one with the batch's counts)")
    add_pattern_options(p)
    from .batch import add_batch_options

    add_batch_options(p)
    p.set_defaults(func=cmd_flatten)

    p = sub.add_parser("paper", help="reproduce the paper's Tables VI-VII and figures",
                       description="Run Surf1 and Surf2 with fixed and variable steps; write a markdown report.")
    p.add_argument("--out", type=path_argument, action=OneOutput, default="paper-report",
                   help="output directory (default paper-report)")
    p.add_argument("--init", choices=LAYOUT_METHODS, default="pca", help="initial layout (default pca)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_paper)

    p = sub.add_parser("verilog", help="export the RTL as Verilog with its interface description",
                       description="Write Verilog of every component, ROM contents and interface.md/json, and the "
                                   "engine (springflat_engine.v) with its register map (register_map.md, "
                                   "register_map.json, springflat_regs.h), memory_image.md, and "
                                   "verilator_waivers.vlt (the lint rules the generated Verilog breaks by "
                                   f"construction), clock.sdc (clk at the engine's {ENGINE_TARGET_MHZ:g} MHz); "
                                   "README.md says which file is which.")
    p.add_argument("--formats", default="default", metavar="PRESET|FILE", help="format set (default: default)")
    p.add_argument("--capacity", nargs=3, type=integer_argument, default=None, metavar=("V", "E", "T"),
                   help="the engine's vertices, neighbour entries and triangles (default: "
                        f"{DEFAULT_CAPACITY.as_option()})")
    p.add_argument("--no-guard", dest="build_guard", action="store_false",
                   help="the engine without the step guard (no guarded mode; its block RAMs free for depth)")
    p.add_argument("--lanes", type=integer_argument, choices=LANES, default=1, metavar="K",
                   help="the engine with K datapaths (1, 2 or 4), each on a share of the nodes; built without the "
                        "step guard, so with --no-guard (docs/engine.md, 'Lanes'; default 1)")
    p.add_argument("--coarse-degree", type=integer_argument, choices=range(COARSE_DEGREE_MAX + 1), default=0,
                   metavar="D", help="the engine with the guarded step's coarse space of degree D (its basis and "
                                     "matrix memories and passes, docs/engine.md; default 0: none)")
    p.add_argument("--target", choices=tuple(VERILOG_TARGETS), default="generic",
                   help="generic (the default): no vendor primitives, for any tool or simulator; ecp5: the netlist "
                        "'springflat synth --target ecp5' places (MULT18X18D, DP16KD and TRELLIS_FF instances, their "
                        "simulation models in sim_models/), the one clock.sdc's clock was met with")
    p.add_argument("--out", type=path_argument, action=OneOutput, required=True, help="output directory")
    p.set_defaults(func=cmd_verilog)

    from .rtl_check import add_parser as add_rtl_check_parser
    from .study.cli import add_parser as add_study_parser
    from .synth_cli import add_parser as add_synth_parser

    add_rtl_check_parser(sub, add_run_options)
    add_study_parser(sub)
    add_synth_parser(sub)
    parser.commands = sub.choices  # each command's parser by name (main's errors point at its --help)
    return parser


def _quiet_after_interrupt() -> None:
    """After Ctrl-C, the objects a half-done step leaves are collected: their finalisers' warnings (such as
    amaranth's UnusedElaboratable for a half-elaborated design) and errors are noise, not for the user."""
    warnings.simplefilter("ignore")
    sys.unraisablehook = lambda unraisable: None


def forget_half_built_components(exc: FormatSetNotBuildable) -> None:
    """Collect, quietly, the RTL components built before ``exc`` refused the format set: each would warn
    "created but never used" (Amaranth's ``UnusedElaboratable``), noise after the one line that says why."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        traceback.clear_frames(exc.__traceback__)
        gc.collect()


def _say(line: str) -> None:
    """An error's line on stderr, if stderr takes it (a full disk or a closed terminal: the status says it)."""
    with contextlib.suppress(OSError):
        print(line, file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extras = parser.parse_known_args(argv)
    if args.command is None:
        parser.error(f"unrecognized arguments: {' '.join(extras)}" if extras else
                     "the following arguments are required: COMMAND")
    if extras:  # refused by the command's own parser, so that the message points at its --help
        meshes = [extra for extra in extras if is_builtin(extra) or Path(extra).suffix.lower() in MESH_SUFFIXES]
        dashed = [extra for extra in meshes if extra.startswith("-")]
        if dashed:  # a file's name that argparse took for an option
            hint = f": a file named with a leading '-' is read as an option: write ./{dashed[0]}"
        else:
            hint = (f": the meshes of a batch come together, before the options ({args.command} MESH "
                    "MESH ... --option ...)" if args.command == "flatten" and meshes else "")
        parser.commands[args.command].error(f"unrecognized arguments: {' '.join(extras)}{hint}")
    reset_interrupted()
    record_written_outputs(True)
    handler = threading.current_thread() is threading.main_thread()
    # Ctrl-C, kill or a hang-up: one line, status 130, 143 or 129 (sim.exit_codes.STOP_SIGNALS), unless ignored
    previous = ({name: signal.signal(getattr(signal, name), on_interrupt) for name in answered_signals()}
                if handler else {})
    stdout = sys.stdout
    if stdout is not None:  # (closed: print() skips it)
        sys.stdout = NamedStandardOutput(stdout)
    try:
        try:
            if getattr(args, "json", False) and getattr(sys.stdout, "closed_at_start", False):
                # (sim.entry.ClosedStandardOutput) --json asks for the standard output alone: refused before the work
                raise UserError("--json writes the results to the standard output, which is closed: drop --json, or "
                                "give the standard output a file")
            status = args.func(args)
            if sys.stdout is not None:
                sys.stdout.flush()  # a full disk or a closed pipe is one line here, not a message at exit
            check_not_interrupted()  # a Ctrl-C a finaliser swallowed still ends the command as interrupted
            return status
        except Exception:
            # A Ctrl-C can come back as another exception: an import it cut short is an ImportError (numpy's,
            # libigl's), which a command may turn into a one-line error of its own. It is still Ctrl-C.
            check_not_interrupted()
            raise
    except USER_ERRORS + (UserError,) as exc:
        _say(f"springflat: error: {one_line(str(exc))}")  # a newline in a path: one line
        return EXIT_USAGE
    except FormatSetNotBuildable as exc:
        _say(one_line(f"springflat: error: the RTL cannot be built with format set "
                      f"'{getattr(args, 'formats', None)}': {exc}"))
        forget_half_built_components(exc)
        return EXIT_USAGE
    except OSError as exc:  # a file operation the commands do not name themselves
        what = ("write standard output" if exc.filename == STANDARD_OUTPUT else
                f"access '{exc.filename}'" if exc.filename else "access")
        written = _written_line("; written before it, complete: ")  # (a --json line after the pattern files)
        _say(f"springflat: error: {one_line(f'cannot {what}: {describe_os_error(exc)}{written}')}")
        return EXIT_USAGE
    except KeyboardInterrupt:
        if argv is None:  # the program itself, which ends now (not a caller running it in-process)
            _quiet_after_interrupt()
        line, status = STOP_SIGNALS[received_signal().name]
        if written := _written_line(" after writing "):  # put in place before the signal, while it still printed
            line += f"{written}, which are complete"
        with contextlib.suppress(OSError):  # after SIGHUP the terminal may be gone (EIO)
            print(f"springflat: {line}", file=sys.stderr)
        return status
    finally:
        record_written_outputs(False)
        sys.stdout = stdout
        for name, before in previous.items():
            signal.signal(getattr(signal, name), before)
        if argv is not None:  # a caller running it in-process goes on: its own writes are not this command's
            reset_interrupted()


if __name__ == "__main__":
    sys.exit(main())
