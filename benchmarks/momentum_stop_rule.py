"""Fixed point against float under the relative-energy stop rule, momentum dynamics (docs/dynamics.md).

For {cap, saddle, cylinder, Surf1, Surf2} × {tutte, pca} × {barrier on, off} and ε in {1e-6, 1e-7}:
both engines' status and iterations (N_max 3,000) and the larger of |ΔE_S|, |ΔE_C| at the end.
Run: ``.venv/bin/python benchmarks/momentum_stop_rule.py`` (a few minutes; prints markdown).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from golden_model.builtin import builtin_mesh  # noqa: E402
from golden_model.fixed import FormatSet  # noqa: E402
from golden_model.fixed.engine import flatten_fixed  # noqa: E402
from sim.generate import rolled_grid, saddle_grid, spherical_cap  # noqa: E402
from sim.layouts import initial_layout  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
from golden_model.reference import flatten  # noqa: E402


def main() -> None:
    fs = FormatSet.preset("default")
    meshes = {"cap": spherical_cap(10), "saddle": saddle_grid(15), "cylinder": rolled_grid(12, 12, arc_degrees=180)[0],
              "surf1": builtin_mesh("surf1")[0], "surf2": builtin_mesh("surf2")[0]}
    print("| ε | mesh | start | barrier | float | fixed | max abs ΔE |")
    print("|---|---|---|---|---|---|---|")
    summary = []
    for eps in (1e-6, 1e-7):
        apart = worst = runs = 0
        for name, mesh in meshes.items():
            for start in ("tutte", "pca"):
                p0 = initial_layout(mesh, start)
                for barrier in (True, False):
                    params = FlattenParams(dynamics="momentum", barrier=barrier, tol_area=1.0, tol_shape=1.0,
                                           tol_energy=eps, max_iter=3000)
                    a, b = flatten(mesh, p0, params), flatten_fixed(mesh, p0, params, fs)
                    delta = max(abs(a.final.shape_error - b.final.shape_error),
                                abs(a.final.area_error - b.final.area_error))
                    runs += 1
                    apart += abs(a.iterations - b.iterations) > 1
                    worst = max(worst, delta)
                    print(f"| {eps:g} | {name} | {start} | {'on' if barrier else 'off'} | {a.status} {a.iterations} "
                          f"| {b.status} {b.iterations} | {delta:.1e} |", flush=True)
        summary.append(f"ε = {eps:g}: {apart} of {runs} pairs more than one iteration apart; worst |ΔE| {worst:.1e}")
    print()
    print("\n".join(summary))


if __name__ == "__main__":
    main()
