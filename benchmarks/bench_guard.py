"""What the step guard costs per iteration: guarded against unguarded momentum steps, in one run.

Usage: .venv/bin/python benchmarks/bench_guard.py [--n 100 300] [--iterations 30] [--repeats 3]

For each size, a dome grid of n×n vertices from Tutte's layout (the barrier on, as the file
defaults): the best of ``--repeats`` runs of ``--iterations`` iterations of the float engine, and of
the fixed-point model, with the guard and without it (``--no-guard``). The energy window is made
longer than the run, so every run does the same number of iterations. Compare the ratios: the
machine is shared.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed
from sim.generate import grid_faces, grid_uv
from sim.layouts import tutte_layout
from golden_model.mesh import Mesh
from golden_model.params import FlattenParams
from golden_model.reference import flatten


def dome(n: int) -> Mesh:
    uv = grid_uv(n, n) - 0.5
    return Mesh(np.column_stack([uv, 0.3 * (1 - 2 * (uv**2).sum(axis=1))]), grid_faces(n, n), name=f"dome{n}")


def per_iteration(run, iterations: int, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        assert result.iterations == iterations, result.status
        best = min(best, time.perf_counter() - start)
    return best / iterations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[100, 300])
    parser.add_argument("--iterations", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    fs = FormatSet.preset("default")
    print("| mesh | V | float guarded | float unguarded | ratio | fixed guarded | fixed unguarded | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    for n in args.n:
        mesh = dome(n)
        p0 = tutte_layout(mesh)
        run = dict(dynamics="momentum", density="auto", tol_area=1.0, tol_shape=1.0, tol_energy=0.0,
                   energy_window=1000, max_iter=args.iterations)
        times = {}
        for guard in (True, False):
            params = FlattenParams(guard=guard, **run)
            times["float", guard] = per_iteration(lambda: flatten(mesh, p0, params), args.iterations, args.repeats)
            times["fixed", guard] = per_iteration(lambda: flatten_fixed(mesh, p0, params, fs), args.iterations,
                                                  args.repeats)
        ms = {key: 1000 * value for key, value in times.items()}
        print(f"| dome {n}×{n} | {mesh.n_vertices} | {ms['float', True]:.1f} ms | {ms['float', False]:.1f} ms | "
              f"{ms['float', True] / ms['float', False]:.2f} | {ms['fixed', True]:.1f} ms | "
              f"{ms['fixed', False]:.1f} ms | {ms['fixed', True] / ms['fixed', False]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
