"""``springflat rtl-check``: a whole flattening through the exported Verilog, on Icarus or Verilator.

The RTL (``springflat_core``) computes every node update and every step size;
the Python side plays the hardware-side controller (``sim/cocotb_benches/closed_loop.py``).
Every iteration is compared bit for bit with the golden model, and the result
with the float reference.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import shutil
import sys
import tempfile
from pathlib import Path

from golden_model.fixed.engine import check_fixed_params, prepare, scale_mesh
from golden_model.engine_spec.image import DEFAULT_CAPACITY, LANES, check_engine_params

from .cocotb_support import SIMULATORS, WAVE_SUFFIX, SimulatorError, missing_simulator, run_bench
from .layouts import AUTO_START, LAYOUT_METHODS, initial_layout
from .run_options import OneOutput, file_path_argument, integer_argument
from .top_names import CORE_MODULE, ENGINE_MODULE

__all__ = ["add_parser", "cmd_rtl_check"]


def add_parser(sub, add_run_options) -> None:
    p = sub.add_parser("rtl-check", help="run a flattening through the RTL on a Verilog simulator",
                       description="Closed-loop flattening through the exported Verilog, checked bit for bit "
                                   "against the golden model and compared with the float reference. The Verilog "
                                   "and the simulator builds are cached under build/ in the checkout (or "
                                   "~/.cache/springflat outside one); SPRINGFLAT_BUILD_DIR=DIR puts them in DIR "
                                   "(a CI cache, a build per job).")
    add_run_options(p)
    p.add_argument("--formats", default="default", metavar="PRESET|FILE", help="format set (default: default)")
    p.add_argument("--sim", "--simulator", dest="sim", choices=SIMULATORS, default="verilator",
                   help="simulator (default verilator)")
    p.add_argument("--engine-top", action="store_true",
                   help="run the whole flattening through SpringflatEngine (springflat_engine.v, driven over "
                        "its Wishbone bus) and compare it bit for bit with the golden model's run_image (what a "
                        "guarded run, a mesh file's default, always does)")
    p.add_argument("--capacity", type=integer_argument, nargs=3, default=None, metavar=("V", "E", "T"),
                   help="with --engine-top: the engine's vertices, neighbour entries and triangles "
                        f"(default: {DEFAULT_CAPACITY.as_option()})")
    p.add_argument("--lanes", type=integer_argument, default=1, choices=LANES, metavar="K",
                   help="with --engine-top: an engine of K datapaths (1, 2 or 4), built without the step guard, so "
                        "with --no-guard --energy-window 1 (default 1)")
    p.add_argument("--wait-states", type=integer_argument, default=0, metavar="N",
                   help="with --engine-top: up to N random idle clocks before each bus cycle (default 0)")
    p.add_argument("--iterations", type=integer_argument, default=None, metavar="N", help="stop after at most N iterations")
    p.add_argument("--waves", type=file_path_argument, action=OneOutput, default=None, metavar="PATH",
                   help="write the waveform here: FILE.fst with icarus, FILE.vcd with verilator")
    p.add_argument("--stall", type=float, default=None, metavar="P",
                   help="the datapath bench's probability of a random stall on each side per clock (default 0; "
                        "not with --engine-top, which has --wait-states, nor the guarded dynamics, which only the "
                        "engine runs)")
    p.add_argument("--json", action="store_true", help="print one JSON object with the results")
    p.set_defaults(func=cmd_rtl_check)


def cmd_rtl_check(args: argparse.Namespace) -> int:
    from hdl import SpringflatCore

    from .outputs import check_distinct, check_link_target, check_output_path, print_note
    from .run_options import (UserError, default_init, holes_mode, input_files, load_format_set, params_from_args,
                              resolve_mesh, strict_json)

    holes = holes_mode(args.fill_holes, args.keep_holes)
    mesh, defaults = resolve_mesh(args.mesh, holes)
    params = params_from_args(args, defaults, fixed_point=True)
    if args.init is None:
        args.init = default_init(args.mesh)
    if (missing := missing_simulator(args.sim)) is not None:  # before the start and the "building" line
        raise UserError(missing)
    if args.waves is not None:  # before any build or run: a path that cannot take the waveform is one line
        check_output_path(args.waves, "--waves", (WAVE_SUFFIX[args.sim],))  # the format the simulator writes
        check_distinct([("--waves", args.waves)], input_files(args))
        check_link_target(args.waves, "--waves")
    load_format_set(args.formats)  # a formats file that cannot work is refused before the run mode
    check_engine_params(params)
    if args.lanes > 1 and params.guard:
        raise UserError(f"--lanes {args.lanes} builds the engine without the step guard: add --no-guard --energy-window 1")
    if params.guard and not args.engine_top:
        if args.stall is not None:  # asked for the datapath bench, which has no guard
            raise UserError("the datapath bench (--stall) has no step guard: drop --stall for the whole engine "
                            "(--engine-top, with --wait-states), or add --no-guard --energy-window 1")
        print_note("the guarded momentum dynamics (the default for mesh files) runs on the whole engine only: "
                   "checking SpringflatEngine (--engine-top); the datapath bench takes --no-guard --energy-window 1")
        args.engine_top = True
    if args.engine_top:
        return cmd_rtl_check_engine(args, mesh, params)
    if given := [flag for flag, value in (("--capacity", args.capacity is not None), ("--lanes", args.lanes != 1),
                                          ("--wait-states", bool(args.wait_states))) if value]:
        raise UserError(f"{' and '.join(given)} appl{'y' if len(given) > 1 else 'ies'} to --engine-top: add it")
    if args.iterations is not None and args.iterations < 1:
        raise UserError(f"--iterations must be >= 1, got {args.iterations}")
    stall = 0.0 if args.stall is None else args.stall
    if not 0 <= stall < 1:
        raise UserError(f"--stall must be in [0, 1), got {stall}")
    formats = load_format_set(args.formats)
    check_fixed_params(params, formats)
    scale_mesh(mesh, params, formats)  # what no layout changes, before the start is computed
    prepare(mesh, _initial_layout(mesh, args.init), params, formats)  # refuses what the formats cannot hold
    mesh_spec = args.mesh if not Path(args.mesh).is_file() else str(Path(args.mesh).resolve())
    init_spec = args.init if args.init in LAYOUT_METHODS + (AUTO_START,) else str(Path(args.init).resolve())
    config = {"mesh": mesh_spec, "holes": holes.value, "init": init_spec, "params": params.as_dict(),
              "iterations": args.iterations,
              "step_latency": SpringflatCore.step_latency_of(formats), "p_valid": 1 - stall,
              "p_ready": 1 - stall}
    first = "; the first Verilator build takes about a minute" if args.sim == "verilator" else ""
    print(f"springflat: {args.sim}: building the model (once per format set, then reused{first}) "
          "and running the closed loop ...", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="springflat-rtl-") as tmp:
        log = Path(tmp) / "simulation.log"
        try:
            with contextlib.redirect_stdout(sys.stderr):  # keep stdout for the result (--json)
                run = run_bench(args.sim, formats, CORE_MODULE, "closed_loop", config,
                                waves=args.waves is not None, work=Path(tmp) / "run", log_file=log)
        except SimulatorError as exc:
            raise UserError(str(exc)) from None
        result = run.result
        if not result:
            tail = log.read_text(errors="replace").splitlines()[-5:] if log.exists() else []
            raise UserError(f"the {args.sim} simulation produced no result: {' / '.join(tail)}")
        if args.waves is not None and run.waves is not None:
            _save_waves(run.waves, args.waves)
    summary = {"mesh": mesh.name, "simulator": args.sim, "formats": formats.name, **result}
    summary["wall_seconds"] = run.wall_seconds
    if args.waves is not None:
        summary["waves"] = str(args.waves) if run.waves is not None else None
    if args.json:
        print(strict_json(summary))
    else:
        print(f"{mesh.name} on {args.sim}: {result['mismatches']} mismatches over {result['iterations']} iterations "
              f"({result['status']}); E_S {result['area_error']:.5f} (float {result['float_area_error']:.5f}), "
              f"E_C {result['shape_error']:.5f} (float {result['float_shape_error']:.5f}); "
              f"{result['cycles']} cycles at {result['cycles_per_second']:.0f} cycles/s")
    for line in result.get("first_mismatches", []):
        print(f"springflat: mismatch: {line}", file=sys.stderr)
    return 0 if result["mismatches"] == 0 and run.failed == 0 else 1


def _initial_layout(mesh, init: str):
    """:func:`initial_layout`, its notes (an OBJ layout's unused faces or z) printed as ``springflat: note:``."""
    from .outputs import print_note

    notes: list[str] = []
    positions = initial_layout(mesh, init, notes)
    for note in notes:
        print_note(note)
    return positions


def _save_waves(source: Path, waves: Path) -> None:
    """Copy the simulator's waveform to ``--waves`` as every output is written (:func:`sim.outputs.atomic_write`)."""
    from .outputs import OutputWriteError, atomic_write

    try:
        with atomic_write(waves) as tmp:
            shutil.copyfile(source, tmp)
    except OutputWriteError as exc:
        raise OutputWriteError(exc.path, exc.error, "--waves") from None


def _engine_measures(result: dict, problem) -> dict:
    """The engine's read-back E_S, E_C and energy as the datapath check and ``flatten --json`` give them (float,
    mesh units), and as read (``*_raw``: [error] and :func:`energy_raw` integers)."""
    from golden_model.fixed.engine import energy_to_float
    from golden_model.fixed.format import to_float

    if "area_error" not in result:  # a bench that failed before its read-back
        return {}
    error = problem.fs.error
    return {"area_error": float(to_float(result["area_error"], error)),
            "shape_error": float(to_float(result["shape_error"], error)),
            "energy": energy_to_float(problem, result["energy"]), "area_error_raw": result["area_error"],
            "shape_error_raw": result["shape_error"], "energy_raw": result["energy"]}


def cmd_rtl_check_engine(args: argparse.Namespace, mesh, params) -> int:
    """The whole flattening through ``springflat_engine``: exit 0 when bit-exact, 1 (one line) if not."""
    from golden_model.engine_spec.image import build_image

    from .engine_run import run_image_on_rtl, summary_line
    from .outputs import print_note
    from .register_map_export import beyond_the_85f, engine_capacity
    from .run_options import UserError, load_format_set, start_positions, strict_json

    if args.stall is not None:
        raise UserError("--stall applies to the datapath bench; with --engine-top use --wait-states")
    if args.wait_states < 0:
        raise UserError(f"--wait-states must be >= 0, got {args.wait_states}")
    if args.iterations is not None:
        if args.iterations < 1:
            raise UserError(f"--iterations must be >= 1, got {args.iterations}")
        params = dataclasses.replace(params, max_iter=min(params.max_iter, args.iterations))
    formats = load_format_set(args.formats)
    # one line for what the register map cannot hold; lanes are built without the guard
    capacity = engine_capacity(args.capacity, formats, guard=args.lanes == 1, lanes=args.lanes,
                               coarse_degree=params.coarse_degree)
    if beyond := beyond_the_85f(capacity):  # (before the start's seconds, and the export's minutes)
        print_note(beyond)
    check_fixed_params(params, formats)
    scale_mesh(mesh, params, formats)  # what no layout changes is refused before the start is computed
    capacity.check_mesh(mesh)
    # the start flatten takes: a guarded run's folded start untangled (the datapath bench has no guard)
    problem = prepare(mesh, start_positions(mesh, args.init, params, progress=False)[0], params, formats)
    image = build_image(problem, capacity)  # FixedPointError (one line) for a mesh over capacity
    lanes = "" if capacity.lanes == 1 else f" in {capacity.lanes} lanes"
    print(f"springflat: {args.sim}: exporting and building springflat_engine for capacity {capacity.vertices}/"
          f"{capacity.entries}/{capacity.triangles}{lanes} (once per format set and capacity, then reused) and running "
          "the whole flattening ...", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="springflat-engine-") as tmp:
        log = Path(tmp) / "simulation.log"
        try:
            with contextlib.redirect_stdout(sys.stderr):
                run = run_image_on_rtl(image, formats, args.sim, wait_states=args.wait_states,
                                       work=Path(tmp) / "run", log_file=log, waves=args.waves is not None)
        except SimulatorError as exc:
            raise UserError(str(exc)) from None
        if not run.result or "status" not in run.result:
            tail = log.read_text(errors="replace").splitlines()[-5:] if log.exists() else []
            raise UserError(f"the {args.sim} simulation of the engine produced no result: {' / '.join(tail)}")
        if args.waves is not None and run.waves is not None:
            _save_waves(run.waves, args.waves)
    summary = {"mesh": mesh.name, "simulator": args.sim, "formats": formats.name, "top": ENGINE_MODULE,
               "capacity": list(args.capacity or (capacity.vertices, capacity.entries, capacity.triangles)),
               "lanes": capacity.lanes,
               "vertices": mesh.n_vertices, **run.result, **_engine_measures(run.result, problem),
               "wall_seconds": run.wall_seconds}
    if args.json:
        print(strict_json(summary))
    else:
        print(summary_line(mesh.name, args.sim, run))
    if not run.passed:
        first = run.result.get("first_mismatches") or ["the bench failed (see the simulator log)"]
        print(f"springflat: mismatch: {first[0]} ({run.mismatches} in all)", file=sys.stderr)
        return 1
    return 0
