"""The ``springflat`` console command.

Subcommands:

* ``flatten [MESH]``: flatten a mesh (a file or a built-in, default ``surf1``);
* ``paper [--out DIR]``: reproduce the paper's Tables VI–VII and figures.

Bad input never produces a traceback: every user error, an unreadable or
unwritable file included, is one line on stderr (``springflat: error: ...``)
and exit status 2, and leaves no file behind.  A run that diverges exits with
status 3 after writing what was asked for.  ``--json`` prints standard JSON:
a number that is not finite is ``null`` and its key is listed in
``non_finite`` (the status, ``diverged``, says why).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from golden_model.layouts import LAYOUT_METHODS, initial_layout
from golden_model.mesh import Mesh, describe_os_error
from golden_model.fixed.engine import flatten_fixed
from golden_model.reference import FlattenParams, FlattenResult, flatten

from .outputs import (LAYOUT_SUFFIXES, OutputWriteError, all_or_nothing, check_output_path, write_history,
                      write_layout, write_plot)
from .run_options import (EXIT_DIVERGED, EXIT_USAGE, USER_ERRORS, UserError, add_run_options, default_init,
                          load_format_set, params_from_args, resolve_mesh, strict_json)


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error format."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"springflat: error: {message} (see '{self.prog} --help')\n")


def _progress(total: int, enabled: bool):
    """A tqdm bar on stderr that appears only for runs longer than ~2 s."""
    from tqdm import tqdm

    return tqdm(total=total, unit="it", delay=2.0, disable=not enabled, file=sys.stderr, leave=False)


def cmd_flatten(args: argparse.Namespace) -> int:
    mesh, defaults = resolve_mesh(args.mesh)
    params = params_from_args(args, defaults)
    for path, what, suffixes in ((args.out, "--out", LAYOUT_SUFFIXES), (args.history, "--history", None),
                                 (args.plot, "--plot", (".png",))):
        if path is not None:
            check_output_path(path, what, suffixes)
    _check_distinct_files(args)
    args.init = args.init or default_init(args.mesh)
    positions = initial_layout(mesh, args.init)
    show_progress = sys.stderr.isatty() or not args.json
    if args.engine == "fixed":
        formats = load_format_set(args.formats or "default")

        def engine(*run_args, **kw):
            return flatten_fixed(*run_args, fs=formats, **kw)
    elif args.engine == "rtl":
        engine = _rtl_engine(load_format_set(args.formats or "default"))
    elif args.engine == "board":  # the engine on a board, over its UART (sim/board_run.py)
        from .board_run import board_engine

        engine = board_engine(load_format_set(args.formats or "default"), args.port, args.baud)
    elif args.formats is not None:
        raise UserError("--formats applies to --engine fixed and --engine rtl")
    else:
        engine = flatten
    # the engines test every state for finiteness themselves (status "diverged"): no numpy warnings on the way
    with _progress(params.max_iter, show_progress) as bar, np.errstate(over="ignore", invalid="ignore",
                                                                        divide="ignore"):
        result = engine(mesh, positions, params, on_iteration=lambda k, m: bar.update(1))
    _write_outputs(args, mesh, result)
    if args.json:
        print(strict_json({"mesh": mesh.name, "vertices": mesh.n_vertices, "faces": mesh.n_faces, "init": args.init,
                           **result.summary(), "used": _what_was_used(params, args.init, result)[len("springflat: "):]}))
    else:
        final = result.final
        print(f"{mesh.name}: {result.status} after {result.iterations} iterations: "
              f"E_S {result.initial.area_error:.4f} -> {final.area_error:.4f}, "
              f"E_C {result.initial.shape_error:.4f} -> {final.shape_error:.4f}, "
              f"folded {final.folded} (flipped against P0: {final.flipped})"
              + (f", {result.extra['saturations']} saturation events" if result.engine == "fixed"
                 else "")
              + (f"; {result.extra['cycles']} engine cycles on {result.extra['simulator']}"
                 if "simulator" in result.extra else ""))
        print(_what_was_used(params, args.init, result), file=sys.stderr)
    if result.status == "diverged":
        print(f"springflat: the run diverged at iteration {result.iterations + 1} "
              "(try --damping 0.05 or a smaller --dt); outputs hold the last finite state", file=sys.stderr)
        return EXIT_DIVERGED
    return 0


def _rtl_engine(formats):
    """``--engine rtl``: the whole flattening through SpringflatEngine on Verilator (``sim.engine_run``),
    with the engine's default capacity (``SPRINGFLAT_ENGINE_CAPACITY=V,E,T`` overrides it: the tests use a
    small engine); a mesh over capacity is a one-line error."""
    import contextlib
    import os

    from golden_model.fixed.engine import check_fixed_params, prepare
    from golden_model.fixed.engine_image import DEFAULT_CAPACITY, EngineCapacity

    capacity = DEFAULT_CAPACITY
    if os.environ.get("SPRINGFLAT_ENGINE_CAPACITY"):
        try:
            capacity = EngineCapacity(*(int(v) for v in os.environ["SPRINGFLAT_ENGINE_CAPACITY"].split(",")))
        except (TypeError, ValueError) as exc:
            raise UserError(f"SPRINGFLAT_ENGINE_CAPACITY must be V,E,T (three integers >= 2): {exc}") from None

    from .cocotb_support import SimulatorError
    from .engine_run import EngineRunError, flatten_on_rtl

    def engine(mesh, positions, params, on_iteration=None):
        import tempfile

        check_fixed_params(params, formats)
        problem = prepare(mesh, positions, params, formats)
        capacity.check(mesh.n_vertices, len(problem.stream.neighbour), mesh.n_faces)  # before any build
        print(f"springflat: verilator: building springflat_engine for capacity {capacity.vertices}/"
              f"{capacity.entries}/{capacity.triangles} (cached) and running the flattening ...", file=sys.stderr)
        with tempfile.TemporaryDirectory(prefix="springflat-engine-") as tmp:
            try:  # the simulator's own output goes to a log: stdout is for the result
                with contextlib.redirect_stdout(sys.stderr):
                    return flatten_on_rtl(problem, capacity, "verilator", work=Path(tmp) / "run",
                                          log_file=Path(tmp) / "simulation.log")
            except (SimulatorError, EngineRunError) as exc:
                raise UserError(str(exc)) from None

    return engine


def _what_was_used(params: FlattenParams, init: str, result: FlattenResult) -> str:
    """One line: dynamics, initial layout, stop rule, and why the run stopped."""
    if params.dynamics == "momentum":
        dynamics = "momentum dynamics" + (f", fold barrier (kappa {params.barrier_threshold:g}, mu "
                                          f"{params.barrier_gain:g})" if params.barrier else ", no barrier")
    else:
        dynamics = (f"paper dynamics, {params.step} step" + (f", damping {params.damping:g}" if params.damping else "")
                    + (f", fold barrier (kappa {params.barrier_threshold:g}, mu {params.barrier_gain:g})"
                       if params.barrier else ""))
    rule = f"relative energy change <= {params.tol_energy:g}"
    if params.tol_area < 1 or params.tol_shape < 1:
        rule = f"E_S <= {params.tol_area:g}, E_C <= {params.tol_shape:g} and {rule}"
    why = {"converged": "the stop rule held", "max-iterations": f"N_max = {params.max_iter} reached",
           "diverged": "a value stopped being finite"}[result.status]
    return f"springflat: used {dynamics}, initial layout {init}; stop rule: {rule}; stopped: {why}"


def _check_distinct_files(args: argparse.Namespace) -> None:
    """No two outputs may be one file, and no output may overwrite the mesh."""
    seen: dict[Path, str] = {}
    mesh_path = Path(args.mesh)
    if mesh_path.is_file():
        seen[mesh_path.resolve()] = f"the mesh '{args.mesh}'"
    for what, path in (("--out", args.out), ("--history", args.history), ("--plot", args.plot)):
        if path is None:
            continue
        key = Path(path).resolve()
        if key in seen:
            raise UserError(f"{what} '{path}' is the same file as {seen[key]}")
        seen[key] = f"{what} '{path}'"


def _write_outputs(args: argparse.Namespace, mesh: Mesh, result: FlattenResult) -> None:
    """Write the outputs asked for: all of them, or (on an error) none."""
    title = f"{mesh.name} ({result.engine} engine)"
    jobs = ((args.out, "--out", lambda path: write_layout(path, result.positions, mesh.faces, vertices=mesh.vertices)),
            (args.history, "--history", lambda path: write_history(path, result)),
            (args.plot, "--plot", lambda path: write_plot(path, result, mesh.faces, title=title,
                                                          vertices=mesh.vertices)))
    with all_or_nothing():
        for path, what, write in jobs:
            if path is None:
                continue
            try:
                write(path)
            except OutputWriteError as exc:
                raise OutputWriteError(exc.path, exc.error, what) from None
            except OSError as exc:
                raise OutputWriteError(path, exc, what) from None


def cmd_paper(args: argparse.Namespace) -> int:
    from .paper import reproduce_paper

    report = reproduce_paper(Path(args.out), init=args.init, progress=not args.quiet)
    print(f"wrote {report}")
    return 0


def cmd_verilog(args: argparse.Namespace) -> int:
    from .export import engine_capacity, export_engine_bundle, export_verilog

    formats = load_format_set(args.formats)
    capacity = engine_capacity(args.capacity, formats)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out '{out}' exists and is not a directory")
    interface = export_verilog(formats, out)
    for name, c in interface["components"].items():
        print(f"{out / (name + '.v')}: latency {c['latency']}, II {c['initiation_interval']}")
    print(f"{out / 'interface.md'}, {out / 'interface.json'}")
    engine = export_engine_bundle(formats, capacity, out)
    print(f"{out / engine['files'][0]}: capacity {capacity.vertices} vertices, {capacity.entries} entries, "
          f"{capacity.triangles} triangles; {engine['bus']}")
    print(", ".join(str(out / f) for f in engine["files"][1:]))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="springflat",
        description="Flatten triangle-mesh patches with the variable step-size mass-spring method, "
                    "and verify its fixed-point hardware.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    p = sub.add_parser("flatten", help="flatten a mesh", description="Flatten a mesh patch (Algorithm 1).")
    add_run_options(p)
    p.add_argument("--engine", choices=("float", "fixed", "rtl", "board"), default="float",
                   help="float reference (default), the bit-exact fixed-point golden model, rtl: the whole "
                        "flattening through SpringflatEngine's Verilog on Verilator (bit-exact with fixed), or "
                        "board: the engine on a ULX3S over its USB-UART (--port; docs/board.md)")
    from .board_run import add_board_options

    add_board_options(p)
    p.add_argument("--formats", default=None, metavar="PRESET|FILE",
                   help="fixed-point format set: a preset (default, narrow) or a JSON file (default: default)")
    p.add_argument("--out", type=Path, help="flattened layout: .obj (z = 0, same faces) or .svg")
    p.add_argument("--history", type=Path, help="per-iteration CSV")
    p.add_argument("--plot", type=Path, help="PNG of the layouts and error curves")
    p.add_argument("--json", action="store_true", help="print one JSON object with the results")
    p.set_defaults(func=cmd_flatten)

    p = sub.add_parser("paper", help="reproduce the paper's Tables VI-VII and figures",
                       description="Run Surf1 and Surf2 with fixed and variable steps; write a markdown report.")
    p.add_argument("--out", default="paper-report", help="output directory (default paper-report)")
    p.add_argument("--init", choices=LAYOUT_METHODS, default="pca", help="initial layout (default pca)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_paper)

    p = sub.add_parser("verilog", help="export the RTL as Verilog with its interface description",
                       description="Write Verilog of every component, ROM contents and interface.md/json, and the "
                                   "engine (springflat_engine.v) with its register map (register_map.md, "
                                   "register_map.json, springflat_regs.h) and memory_image.md.")
    p.add_argument("--formats", default="default", metavar="PRESET|FILE", help="format set (default: default)")
    p.add_argument("--capacity", nargs=3, type=int, default=None, metavar=("V", "E", "T"),
                   help="the engine's vertices, neighbour entries and triangles (default: "
                        "golden_model.fixed.engine_image.DEFAULT_CAPACITY)")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=cmd_verilog)

    from .rtl_check import add_parser as add_rtl_check_parser
    from .study import add_parser as add_study_parser
    from .synth import add_parser as add_synth_parser

    add_rtl_check_parser(sub, add_run_options)
    add_study_parser(sub)
    add_synth_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except USER_ERRORS + (UserError,) as exc:
        print(f"springflat: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:  # a file operation the commands do not name themselves
        name = f" '{exc.filename}'" if exc.filename else ""
        print(f"springflat: error: cannot access{name}: {describe_os_error(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("springflat: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
