"""SpringflatEngine in K lanes: clocks per iteration against one lane (measured on Verilator, each run bit-exact),
and the multipliers and block RAMs each K takes (counted by elaborating the engine for ECP5).

Usage::

    .venv/bin/python benchmarks/lane_cycles.py [--side 45] [--iterations 12] [--lanes 1 2 4] [--capacity V E T]

Runs the unguarded momentum dynamics (``--no-guard --energy-window 1``: lanes are built without the step guard)
from the Tutte layout of ``saddle_grid(--side)`` (2,025 vertices at 45) on the engine of each K at
``--capacity`` (default ``DEFAULT_CAPACITY``), one lane built without the guard too, so that the builds differ
only in their lanes; each run is compared bit for bit with the golden model's ``run_image`` by the bench.
CYCLES covers START to done: the first measurement and ``--iterations`` iterations. Then counts
``MULT18X18D`` and ``DP16KD`` of each K at that capacity in the ``default`` and ``narrow`` presets.
docs/engine.md quotes both tables. A first run builds a Verilator model per K (about a minute each).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from golden_model.engine_spec.image import DEFAULT_CAPACITY, LANES, UNGUARDED, EngineCapacity, build_image  # noqa: E402
from golden_model.fixed import FormatSet  # noqa: E402
from golden_model.fixed.engine import prepare  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
from hdl.dsp import ecp5_instance_count  # noqa: E402
from hdl.engine import SpringflatEngine  # noqa: E402
from sim.engine_run import run_image_on_rtl  # noqa: E402
from sim.generate import saddle_grid  # noqa: E402
from sim.layouts import initial_layout  # noqa: E402
from sim.synth import TARGETS  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--side", type=int, default=45, help="saddle_grid's side (default 45: 2,025 vertices)")
    parser.add_argument("--iterations", type=int, default=12)
    parser.add_argument("--lanes", type=int, nargs="+", default=list(LANES), choices=LANES)
    parser.add_argument("--capacity", type=int, nargs=3, metavar=("V", "E", "T"),
                        default=(DEFAULT_CAPACITY.vertices, DEFAULT_CAPACITY.entries, DEFAULT_CAPACITY.triangles))
    args = parser.parse_args(argv)
    fs = FormatSet.preset("default")
    mesh = saddle_grid(args.side)
    params = FlattenParams(dynamics="momentum", **UNGUARDED, max_iter=args.iterations)
    problem = prepare(mesh, initial_layout(mesh, "tutte"), params, fs)
    print(f"saddle_grid({args.side}): {mesh.n_vertices} vertices, {len(problem.stream.neighbour)} entries, "
          f"{mesh.n_faces} triangles; capacity {' '.join(map(str, args.capacity))}, without the guard", flush=True)
    print("\n| lanes | result | iterations | mismatches | CYCLES | clocks per iteration | against one lane |")
    print("|---|---|---|---|---|---|---|")
    first = None
    for lanes in args.lanes:
        capacity = EngineCapacity(*args.capacity, guard=False, lanes=lanes)
        with contextlib.redirect_stdout(sys.stderr):  # (the simulator's build log)
            run = run_image_on_rtl(build_image(problem, capacity), fs, "verilator")
        r = run.result
        cycles = int(r["cycles"])
        first = first or cycles
        print(f"| {lanes} | {r['status']} | {r['iterations']} | {run.mismatches} | {cycles:,} | "
              f"{cycles / r['iterations']:,.0f} | {cycles / first:.3f} |", flush=True)
    ecp5 = TARGETS["ecp5"].capacity
    print(f"\n| preset | lanes | MULT18X18D (of {ecp5['dsps']}) | DP16KD (of {ecp5['brams']}) | the 85F |")
    print("|---|---|---|---|---|")
    for preset in ("default", "narrow"):
        for lanes in args.lanes:
            engine = SpringflatEngine(preset, EngineCapacity(*args.capacity, guard=False, lanes=lanes))
            dsps, brams = (ecp5_instance_count(engine, cell) for cell in ("MULT18X18D", "DP16KD"))
            fits = dsps <= ecp5["dsps"] and brams <= ecp5["brams"]
            print(f"| {preset} | {lanes} | {dsps} | {brams} | {'fits' if fits else '**does not fit**'} |", flush=True)


if __name__ == "__main__":
    main()
