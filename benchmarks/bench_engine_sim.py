"""A whole flattening through ``springflat_engine`` on a Verilog simulator: how fast it simulates.

Usage: .venv/bin/python benchmarks/bench_engine_sim.py [--side 45] [--iterations 20] [--simulator verilator]

A generated 45 × 45 grid on a dome (``sim.generate.dome_grid``: 2,025 vertices, 11,792
neighbour entries, 3,872 triangles; a 2,000-point ``delaunay_patch`` is refused by the ``default``
formats, its boundary edges over 8 mean edge lengths), the paper's dynamics with the
variable step from a Tutte layout, tolerances 0 so the run goes to ``N_max``; the engine at
``DEFAULT_CAPACITY``, loaded and read back over Wishbone by the host driver (``sim/engine_run.py``).
The run is bit-exact with ``run_image`` or the script fails. It prints the engine's CYCLES register,
cycles per iteration, simulated cycles per second of wall time from START to done, and the share of
that wall time spent in Python (the rest is inside the simulator, waiting for ``irq``).

With ``--baseline`` (the default) it then runs, on the same simulator and in the same process, the
closed loop that issue 11 measured against: ``springflat_core`` on Surf2 with the Python controller
(``sim/cocotb_benches/closed_loop.py``, as ``bench_rtl_sim.py``), and prints the engine's speed as a
multiple of it. The machine is shared and its speed varies by 2x between hours; the ratio of two runs
a minute apart is what to compare against the issue's 10x.
"""

from __future__ import annotations

import argparse
import sys
import time

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from golden_model.engine_spec.image import DEFAULT_CAPACITY, build_image
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from sim.cocotb_support import SIMULATORS, run_bench
from sim.engine_run import run_image_on_rtl

from bench_rtl_sim import closed_loop_config  # this folder's script, on sys.path when run as a script


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--side", type=int, default=45, help="grid side: side² vertices (default 45)")
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--simulator", choices=SIMULATORS, default="verilator")
    parser.add_argument("--formats", default="default")
    parser.add_argument("--baseline", action=argparse.BooleanOptionalAction, default=True,
                        help="also run the Python-controlled closed loop on Surf2 and print the ratio (default: on)")
    args = parser.parse_args()
    fs = FormatSet.preset(args.formats)
    mesh = dome_grid(args.side)
    params = FlattenParams(density="auto", tol_area=0.0, tol_shape=0.0, max_iter=args.iterations)
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), DEFAULT_CAPACITY)
    c = image.constants
    started = time.perf_counter()
    run = run_image_on_rtl(image, fs, args.simulator)
    total = time.perf_counter() - started
    r = run.result
    if not run.passed:
        print(f"not bit-exact: {r.get('first_mismatches', r)}", file=sys.stderr)
        return 1
    print(f"dome_grid({args.side}): {c['vertices']} vertices, {c['entries']} entries, {c['triangles']} "
          f"triangles; {args.simulator}; {r['status']} after {r['iterations']} iterations, 0 mismatches")
    print("| simulator | cycles | cycles/iteration | run s | simulated cycles/s | Python share | whole bench s |")
    print("|---|---|---|---|---|---|---|")
    print(f"| {args.simulator} | {r['cycles']} | {r['cycles_per_iteration']:.0f} | {r['run_seconds']:.2f} | "
          f"{r['cycles_per_second']:.0f} | {100 * r['python_share']:.1f} % | {total:.0f} |")
    if args.baseline:
        loop = closed_loop_speed(fs, args.simulator)
        print(f"closed loop (springflat_core, Python controller, surf2): {loop['cycles']} cycles, "
              f"{loop['cycles_per_second']:.0f} cycles/s; the engine: "
              f"{r['cycles_per_second'] / loop['cycles_per_second']:.1f}x")
    return 0


def closed_loop_speed(fs: FormatSet, simulator: str) -> dict:
    """The issue's baseline: Surf2 with the paper parameters through ``springflat_core``, the loop in Python."""
    return run_bench(simulator, fs, "springflat_core", "closed_loop", closed_loop_config("surf2", fs)).result


if __name__ == "__main__":
    sys.exit(main())
