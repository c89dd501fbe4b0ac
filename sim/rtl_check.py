"""``springflat rtl-check``: a whole flattening through the exported Verilog, on Icarus or Verilator.

The RTL (``springflat_core``) computes every node update and every step size;
the Python side plays the hardware-side controller (``sim/cocotb_benches/closed_loop.py``).
Every iteration is compared bit for bit with the golden model, and the result
with the float reference.
"""

from __future__ import annotations

import argparse
import contextlib
import shutil
import sys
import tempfile
from pathlib import Path

from golden_model.fixed.engine import check_fixed_params, prepare
from golden_model.layouts import LAYOUT_METHODS, initial_layout

from .cocotb_support import SIMULATORS, SimulatorError, run_bench

__all__ = ["add_parser", "cmd_rtl_check"]


def add_parser(sub, add_run_options) -> None:
    p = sub.add_parser("rtl-check", help="run a flattening through the RTL on a Verilog simulator",
                       description="Closed-loop flattening through the exported Verilog, checked bit for bit "
                                   "against the golden model and compared with the float reference.")
    add_run_options(p)
    p.add_argument("--formats", default="default", metavar="PRESET|FILE", help="format set (default: default)")
    p.add_argument("--sim", choices=SIMULATORS, default="verilator", help="simulator (default verilator)")
    p.add_argument("--iterations", type=int, default=None, metavar="N", help="stop after at most N iterations")
    p.add_argument("--waves", type=Path, default=None, metavar="PATH", help="write the waveform (FST/VCD) here")
    p.add_argument("--stall", type=float, default=0.0, metavar="P",
                   help="probability of a random stall on each side per clock (default 0)")
    p.add_argument("--json", action="store_true", help="print one JSON object with the results")
    p.set_defaults(func=cmd_rtl_check)


def cmd_rtl_check(args: argparse.Namespace) -> int:
    from hdl import SpringflatCore

    from .run_options import UserError, default_init, load_format_set, params_from_args, resolve_mesh, strict_json

    mesh, defaults = resolve_mesh(args.mesh)
    params = params_from_args(args, defaults)
    args.init = args.init or default_init(args.mesh)
    if args.iterations is not None and args.iterations < 1:
        raise UserError(f"--iterations must be >= 1, got {args.iterations}")
    if not 0 <= args.stall < 1:
        raise UserError(f"--stall must be in [0, 1), got {args.stall}")
    if args.waves is not None and not (args.waves.parent if str(args.waves.parent) else Path(".")).is_dir():
        raise UserError(f"--waves '{args.waves}': directory '{args.waves.parent}' does not exist")
    formats = load_format_set(args.formats)
    check_fixed_params(params, formats)
    prepare(mesh, initial_layout(mesh, args.init), params, formats)  # refuses what the formats cannot hold
    mesh_spec = args.mesh if not Path(args.mesh).is_file() else str(Path(args.mesh).resolve())
    init_spec = args.init if args.init in LAYOUT_METHODS else str(Path(args.init).resolve())
    config = {"mesh": mesh_spec, "init": init_spec, "params": params.as_dict(), "iterations": args.iterations,
              "step_latency": SpringflatCore(formats).step_latency, "p_valid": 1 - args.stall,
              "p_ready": 1 - args.stall}
    print(f"springflat: {args.sim}: building the model (cached; the first Verilator build takes ~1 min) "
          "and running the closed loop ...", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="springflat-rtl-") as tmp:
        log = Path(tmp) / "simulation.log"
        try:
            with contextlib.redirect_stdout(sys.stderr):  # keep stdout for the result (--json)
                run = run_bench(args.sim, formats, "springflat_core", "closed_loop", config,
                                waves=args.waves is not None, work=Path(tmp) / "run", log_file=log)
        except SimulatorError as exc:
            raise UserError(str(exc)) from None
        result = run.result
        if not result:
            tail = log.read_text(errors="replace").splitlines()[-5:] if log.exists() else []
            raise UserError(f"the {args.sim} simulation produced no result: {' / '.join(tail)}")
        if args.waves is not None and run.waves is not None:
            shutil.copyfile(run.waves, args.waves)
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
