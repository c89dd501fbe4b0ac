"""Time per iteration: SpringflatEngine at its ECP5 Fmax against the float and fixed engines on this machine.

Usage: .venv/bin/python benchmarks/bench_engine_iteration.py --fmax MHZ [--iterations 20] [--repeats 3]
       [--formats default] [--capacity V E T] [--side 45] [--rtl verilator|icarus]

For each mesh (``dome45``: ``dome_grid(45)``, a generated 2,025-vertex patch that fits the default
capacity, or ``dome_grid(--side)`` for a smaller one; ``surf1``: the paper's Surf1)
all three engines run the same problem with the stop rule switched off (tolerances 0), so every run
is exactly its ``max_iter`` iterations:

* **float** (``flatten``) and **fixed** (``flatten_fixed``): wall time of a run of ``5 + N``
  iterations minus a run of 5 (best of ``--repeats`` each), divided by ``N``: the set-up (layout
  checks, host scaling, the first measurement) cancels, one iteration is left.
* **engine**: clock cycles per iteration / Fmax. The cycles are
  - with ``--rtl SIM``: measured, the engine's ``CYCLES`` register after a run of ``5 + N``
    iterations minus after a run of 5, divided by ``N`` (``sim.engine_run``, the RTL on a Verilog
    simulator, each run checked bit for bit against ``run_image``);
  - without: the pass structure, ``entries + triangles + vertices`` (one item per clock in the
    force, area and integrate passes) plus the units' latencies the controller waits out
    (:func:`estimated_cycles`); an estimate, stated as such in the output.

``--fmax`` is the engine's Fmax after routing from ``springflat synth --components
springflat_engine`` (docs/synthesis.md).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from golden_model.builtin import builtin_mesh
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed, prepare
from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.mesh import Mesh
from golden_model.params import FlattenParams
from golden_model.reference import flatten

WARMUP_ITERATIONS = 5
"""Iterations of the short run whose time (or cycle count) is subtracted: set-up and the first measurement."""


@dataclass(frozen=True)
class Case:
    name: str
    mesh: Mesh
    params: FlattenParams  # the stop rule off: tolerances 0, max_iter set per run

    @property
    def counts(self) -> tuple[int, int, int]:
        """(vertices, neighbour entries, triangles): an entry per edge end."""
        return self.mesh.n_vertices, 2 * len(self.mesh.edges), len(self.mesh.faces)


def cases(side: int = 45) -> list[Case]:
    off = {"tol_area": 0.0, "tol_shape": 0.0, "tol_energy": 0.0}
    surf1, paper = builtin_mesh("surf1")
    return [
        Case(f"dome{side}", dome_grid(side), FlattenParams(density="auto", damping=0.05, **off)),
        Case("surf1", surf1, FlattenParams(spring=paper.spring, density=paper.density, **off)),
    ]


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def seconds_per_iteration(run, iterations: int, repeats: int) -> float:
    """``run(max_iter)`` timed at ``5 + iterations`` and at 5 iterations; the difference per iteration (s)."""
    for n in (WARMUP_ITERATIONS, WARMUP_ITERATIONS + iterations):
        result = run(n)
        if result.iterations != n:  # the stop rule is off: a run that stops early would time something else
            raise RuntimeError(f"a run stopped after {result.iterations} iterations ({result.status}), not {n}")
    long = best_of(lambda: run(WARMUP_ITERATIONS + iterations), repeats)
    short = best_of(lambda: run(WARMUP_ITERATIONS), repeats)
    return (long - short) / iterations


PHASE_CHANGES = 8
"""Clocks per iteration the controller spends changing phase (check, step, step wait, integrate, start,
force, area, math): one each, as ``hdl/engine.py``'s phase machine is written."""


def estimated_cycles(case: Case, fs: FormatSet, capacity: EngineCapacity, p0: np.ndarray) -> int:
    """Clocks per iteration from the pass structure of ``hdl/engine.py`` (an estimate, not a measurement):

    * integrate pass: one node per clock, its fetch's latency, the integrator's latency;
    * force pass: one entry per clock, its fetch's latency, the force pass's latency;
    * area pass: one triangle per clock, its fetch's latency, the area unit's latency, then the area
      normaliser (its cycles for this mesh's shift); the energy check, started at the force pass's end,
      runs beside it: the longer of the two;
    * the step generator's latency, and :data:`PHASE_CHANGES`.
    """
    from golden_model.engine_spec.image import build_image
    from hdl.area_error import AreaError
    from hdl.controller_units import EnergyCheck, Normaliser
    from hdl.force_pass import ForcePass
    from hdl.integrator import Integrator
    from hdl.pass_sequencer import AREA_FETCH_LATENCY, FORCE_FETCH_LATENCY, NODE_FETCH_LATENCY
    from hdl.stepgen import StepGenerator

    c = build_image(prepare(case.mesh, p0, case.params.with_(max_iter=1), fs), capacity).constants
    integrate = c["vertices"] + NODE_FETCH_LATENCY + Integrator(fs).latency
    force = c["entries"] + FORCE_FETCH_LATENCY + ForcePass(fs, energy=True).latency
    area = c["triangles"] + AREA_FETCH_LATENCY + AreaError(fs).latency + Normaliser(fs).cycles(c["area_shift"])
    energy = EnergyCheck(fs, capacity.entries).latency
    return integrate + force + max(area, energy) + StepGenerator(fs).latency + PHASE_CHANGES


def rtl_cycles_per_iteration(case: Case, fs: FormatSet, capacity: EngineCapacity, simulator: str,
                             iterations: int, p0: np.ndarray) -> float:
    """Cycles per iteration measured on the RTL (``CYCLES`` after 5 + N iterations minus after 5, / N)."""
    from sim.engine_run import run_engine

    cycles = {}
    for n in (WARMUP_ITERATIONS, WARMUP_ITERATIONS + iterations):
        run = run_engine(prepare(case.mesh, p0, case.params.with_(max_iter=n), fs), capacity, simulator)
        if not run.passed:
            raise RuntimeError(f"{case.name}: the RTL run did not match run_image ({run.result})")
        if run.result["iterations"] != n:
            raise RuntimeError(f"{case.name}: the RTL stopped after {run.result['iterations']} iterations, not {n}")
        cycles[n] = run.result["cycles"]
    return (cycles[WARMUP_ITERATIONS + iterations] - cycles[WARMUP_ITERATIONS]) / iterations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fmax", type=float, required=True, help="the engine's Fmax after routing (MHz)")
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--side", type=int, default=45,
                        help="the generated patch: dome_grid(SIDE), SIDE² vertices (default 45; it must fit --capacity)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--formats", default="default")
    parser.add_argument("--capacity", nargs=3, type=int, metavar=("V", "E", "T"), default=None,
                        help="the engine's capacity (default DEFAULT_CAPACITY)")
    parser.add_argument("--rtl", choices=("verilator", "icarus"), default=None,
                        help="measure the cycles on the RTL with this simulator instead of the pass-structure estimate")
    args = parser.parse_args()
    fs = FormatSet.load(args.formats)
    capacity = EngineCapacity(*args.capacity) if args.capacity else DEFAULT_CAPACITY
    source = (f"measured on the RTL ({args.rtl})" if args.rtl else
              "estimated from the pass structure (entries + triangles + vertices + the units' latencies)")
    print(f"format set {fs.name}; engine at {args.fmax:g} MHz, capacity {capacity.vertices}/{capacity.entries}/"
          f"{capacity.triangles}; cycles per iteration: {source}; CPU times: ({WARMUP_ITERATIONS} + "
          f"{args.iterations}) − {WARMUP_ITERATIONS} iterations, best of {args.repeats}")
    print()
    print("| mesh | vertices | entries | triangles | engine cycles/iteration | engine (µs/iteration) | "
          "float (µs/iteration) | fixed (µs/iteration) | engine vs float | engine vs fixed |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for case in cases(args.side):
        vertices, entries, triangles = case.counts
        p0 = initial_layout(case.mesh, "pca")
        float_s = seconds_per_iteration(lambda n: flatten(case.mesh, p0, case.params.with_(max_iter=n)),
                                        args.iterations, args.repeats)
        fixed_s = seconds_per_iteration(lambda n: flatten_fixed(case.mesh, p0, case.params.with_(max_iter=n), fs),
                                        args.iterations, args.repeats)
        if args.rtl:
            cycles = rtl_cycles_per_iteration(case, fs, capacity, args.rtl, args.iterations, p0)
        else:
            cycles = estimated_cycles(case, fs, capacity, p0)
        engine_s = cycles / (args.fmax * 1e6)
        print(f"| {case.name} | {vertices} | {entries} | {triangles} | {cycles:.0f} | {engine_s * 1e6:.2f} | "
              f"{float_s * 1e6:.1f} | {fixed_s * 1e6:.1f} | {float_s / engine_s:.0f}× | {fixed_s / engine_s:.0f}× |")


if __name__ == "__main__":
    main()
