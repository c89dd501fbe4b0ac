"""Where a whole engine run's Verilator time goes: one workload on several builds of the engine, in one run.

Usage: .venv/bin/python benchmarks/bench_sim_speed.py [--side 45] [--iterations 40] [--repeats 3]
       [--builds gpi-clock,default,x-randomised,cxx-O2,verilator-O3,threads-2,pgo] [--harness] [--guardless]

The workload is ``bench_engine_sim.py``'s: ``dome_grid(45)`` (2,025 vertices, 11,792 entries, 3,872
triangles), the paper's dynamics with the variable step from a Tutte layout, tolerances 0 so the run goes to
``N_max``, the engine at ``DEFAULT_CAPACITY`` behind the host driver (``sim/engine_run.py``). Each build is a
key of ``sim.engine_run.VERILATOR_BUILDS`` (one change against ``gpi-clock`` each, ``default`` the harness's own
clock; ``yosys-opt`` is ``default`` on Yosys's optimisation of the netlist, ``YOSYS_BUILDS``; ``delay-lines``
``default`` on the engine built with the datapaths' delay lines, ``ENGINE_OPTION_BUILDS``); ``pgo`` first
compiles ``gpi-clock`` with ``-fprofile-generate`` and trains it on another mesh (``dome_grid(24)``, 10
iterations), then compiles it again with the profile. Every build is built (and checked bit-exact) once, then the builds
are measured round-robin ``--repeats`` times, so a change in the machine's load hits them alike; the table
has each build's median simulated cycles per second from START to done (the engine's CYCLES register over
the wall time), its spread, and the ratio to the first build. Every run must be bit-exact with ``run_image``.

With ``--guardless`` it also runs the workload on ``default``'s build of the engine without the step guard
(``EngineCapacity(guard=False)``: no guard passes, no proposal memories), round-robin with the others: what the
guard's logic costs the simulator while the paper's dynamics leaves it idle.

With ``--harness`` it also measures the harness alone (``sim.engine_run.harness_ceiling``: a counter under the
bench's clock and wait, 5 million cycles) for ``gpi-clock`` and ``default``, after the engine's runs.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from golden_model.engine_spec.image import DEFAULT_CAPACITY, build_image
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from sim.engine_run import VERILATOR_BUILDS, YOSYS_BUILDS, harness_ceiling, prepare_pgo, run_image_on_rtl


#: The pseudo-build of ``--guardless``: ``default``'s flags on the engine built without the step guard.
GUARDLESS = "default, no guard"


def image_for(side: int, iterations: int, fs: FormatSet, capacity=DEFAULT_CAPACITY):
    mesh = dome_grid(side)
    params = FlattenParams(density="auto", tol_area=0.0, tol_shape=0.0, max_iter=iterations)
    return build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), capacity)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--side", type=int, default=45)
    parser.add_argument("--iterations", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--builds", default="gpi-clock,default,x-randomised,verilator-O3,pgo")
    parser.add_argument("--harness", action="store_true", help="also measure the harness alone")
    parser.add_argument("--guardless", action="store_true",
                        help="also measure the default build of the engine without the step guard (model size)")
    args = parser.parse_args()
    builds = [b.strip() for b in args.builds.split(",") if b.strip()]
    unknown = [b for b in builds if b not in VERILATOR_BUILDS or b == "pgo-generate"]
    if unknown:
        parser.error(f"unknown build {unknown[0]!r} (choose from {', '.join(VERILATOR_BUILDS)})")
    fs = FormatSet.preset("default")
    image = image_for(args.side, args.iterations, fs)
    images = {build: image for build in builds}
    if args.guardless:  # the same run on a smaller model: the paper's dynamics uses none of the guard
        builds.append(GUARDLESS)
        images[GUARDLESS] = image_for(args.side, args.iterations, fs, replace(DEFAULT_CAPACITY, guard=False))

    def run_on(build: str):
        return run_image_on_rtl(images[build], fs, "verilator", build="default" if build == GUARDLESS else build)
    started = time.monotonic()

    def say(msg):
        print(f"[{time.monotonic() - started:7.1f} s] {msg}", file=sys.stderr, flush=True)

    speeds: dict[str, list[float]] = {b: [] for b in builds}
    for build in builds:  # build each (cached), check it bit-exact; the first run's speed is not counted
        if build == "pgo":
            say("pgo: compiling with -fprofile-generate and training on dome_grid(24), 10 iterations")
            training = prepare_pgo(image_for(24, 10, fs), fs)
            if not training.passed:
                print(f"pgo training run not bit-exact: {training.result.get('first_mismatches')}", file=sys.stderr)
                return 1
        say(f"{build}: building and a first run")
        run = run_on(build)
        if not run.passed:
            print(f"{build}: not bit-exact: {run.result.get('first_mismatches', run.result)}", file=sys.stderr)
            return 1
        say(f"{build}: {run.result['cycles_per_second']:.0f} cycles/s (first run, not counted)")
    cycles = None
    for repeat in range(args.repeats):
        for build in builds:
            run = run_on(build)
            if not run.passed:
                print(f"{build}: not bit-exact: {run.result.get('first_mismatches')}", file=sys.stderr)
                return 1
            cycles = run.result["cycles"]
            speeds[build].append(run.result["cycles_per_second"])
            say(f"repeat {repeat + 1} {build}: {speeds[build][-1]:.0f} cycles/s, Python "
                f"{100 * run.result['python_share']:.1f} %")
    c = image.constants
    print(f"dome_grid({args.side}): {c['vertices']} vertices, {c['entries']} entries, {c['triangles']} triangles, "
          f"{args.iterations} iterations, {cycles} cycles per run; every run bit-exact; {args.repeats} runs per "
          f"build, round-robin")
    print(f"| build | Verilator arguments added | make variables | simulated cycles/s (median) | min-max | "
          f"vs {builds[0]} |")
    print("|---|---|---|---|---|---|")
    base = statistics.median(speeds[builds[0]])
    for build in builds:
        flags, make = VERILATOR_BUILDS["default" if build == GUARDLESS else build]
        median = statistics.median(speeds[build])
        ratio = f"{median / base:.2f}x"
        netlist = f" on Yosys's `{YOSYS_BUILDS[build]}`" if build in YOSYS_BUILDS else ""
        print(f"| {build} | `{' '.join(flags)}`{netlist} | `{make.replace(chr(92), '')}` | {median:,.0f} | "
              f"{min(speeds[build]):,.0f}-{max(speeds[build]):,.0f} | {ratio} |")
    if args.harness:
        print("| harness alone (a counter), build | simulated cycles/s |")
        print("|---|---|")
        for build in ("gpi-clock", "default"):
            print(f"| {build} | {harness_ceiling(fs, build=build):,.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
