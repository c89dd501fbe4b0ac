"""Where the time of a whole engine run goes inside the simulator process: ``perf`` over START .. done.

Usage: perf record -k CLOCK_MONOTONIC -F 499 -o build/engine.perf -- \
           .venv/bin/python benchmarks/profile_engine_sim.py [--side 45] [--iterations 40] [--build default]
       then the script prints the ``perf report`` command for the run's window (START to done).

Runs ``bench_sim_speed.py``'s workload once on one build and prints the run's CLOCK_MONOTONIC window; perf's
samples inside it are the simulator running the engine (loading and reading back, Python at every bus clock,
are outside it). ``perf report --sort dso`` then splits the window between the model's code (the
executable ``springflat_engine_sim``), Verilator's runtime and VPI (``verilated_vpi``, in the executable
too: use ``--sort sym``), cocotb's GPI (``libgpi``, ``libcocotbvpi_verilator``) and Python.
"""

from __future__ import annotations

import argparse
import sys

from golden_model.fixed import FormatSet
from sim.engine_run import VERILATOR_BUILDS, run_image_on_rtl

from bench_sim_speed import image_for  # this folder's script


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--side", type=int, default=45)
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--build", default="default", choices=tuple(VERILATOR_BUILDS))
    parser.add_argument("--perf-data", default="build/engine.perf")
    args = parser.parse_args()
    fs = FormatSet.preset("default")
    run = run_image_on_rtl(image_for(args.side, args.iterations, fs), fs, "verilator", build=args.build)
    if not run.passed:
        print(f"not bit-exact: {run.result.get('first_mismatches')}", file=sys.stderr)
        return 1
    start, end = run.result["run_window_monotonic"]
    print(f"{run.result['cycles']} cycles in {run.result['run_seconds']:.2f} s = {run.result['cycles_per_second']:.0f} "
          f"cycles/s; window {start:.6f},{end:.6f}")
    print(f"perf report -i {args.perf_data} --time {start:.6f},{end:.6f} --sort dso --stdio")
    print(f"perf report -i {args.perf_data} --time {start:.6f},{end:.6f} --sort sym --stdio")
    return 0


if __name__ == "__main__":
    sys.exit(main())
