"""Fixed point against float under the mesh files' default stop rule, with the step guard.

Usage: .venv/bin/python benchmarks/guard_fixed_vs_float.py

From Tutte's layout on generated patches (the momentum dynamics, the barrier, the guard, the energy
change over 10 iterations <= FILE_TOL_ENERGY): per mesh the status, iterations, rolled-back steps
and saturation events of each engine and |ΔE_S|, |ΔE_C|. docs/guard.md quotes the table.
"""

from __future__ import annotations

from golden_model.fixed.engine import flatten_fixed
from golden_model.generate import delaunay_patch, dome_grid, rolled_grid, saddle_grid, spherical_cap
from golden_model.layouts import tutte_layout
from golden_model.params import FlattenParams
from golden_model.reference import flatten
from sim.run_options import FILE_TOL_ENERGY

MESHES = {
    "cap, 10 rings": lambda: spherical_cap(10),
    "saddle 15×15": lambda: saddle_grid(15),
    "cylinder strip 12×12": lambda: rolled_grid(12, 12, arc_degrees=180)[0],
    "Delaunay patch, 300 points": lambda: delaunay_patch(300),
    "cap, 15 rings": lambda: spherical_cap(15),
    "saddle 31×31": lambda: saddle_grid(31),
    "dome 31×31": lambda: dome_grid(31),
    "cylinder strip 31×31": lambda: rolled_grid(31, 31, arc_degrees=180)[0],
}


def main() -> None:
    params = FlattenParams(dynamics="momentum", density="auto", tol_area=1.0, tol_shape=1.0,
                           tol_energy=FILE_TOL_ENERGY, max_iter=3000)
    print("| mesh | status (float / fixed) | iterations | rolled back | saturations | |ΔE_S| | |ΔE_C| |")
    print("|---|---|---|---|---|---|---|")
    for name, make in MESHES.items():
        mesh = make()
        p0 = tutte_layout(mesh)
        a, b = flatten(mesh, p0, params), flatten_fixed(mesh, p0, params)
        print(f"| {name} | {a.status} / {b.status} | {a.iterations} / {b.iterations} | "
              f"{a.extra['rejected_steps']} / {b.extra['rejected_steps']} | {b.extra['saturations']} | "
              f"{abs(a.final.area_error - b.final.area_error):.1e} | "
              f"{abs(a.final.shape_error - b.final.shape_error):.1e} |", flush=True)


if __name__ == "__main__":
    main()
