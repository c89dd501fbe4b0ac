"""The measured tables of docs/dynamics.md: paper vs momentum dynamics, with and without the fold barrier.

For each mesh and start (Tutte, ARAP): iterations until E_C stays within 1 % of the converged E_C
(or 1e-4 absolute, for developable meshes whose E_C* is 0), and the final E_S, E_C and folded
triangles next to libigl's ARAP and LSCM layouts.  Run: ``.venv/bin/python benchmarks/dynamics_table.py``
(about 15 minutes on 2 cores; prints markdown).
"""

from __future__ import annotations

import sys
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.generate import rolled_grid, saddle_grid, spherical_cap  # noqa: E402
from sim.layouts import initial_layout  # noqa: E402
from sim.mesh_io import load_mesh  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
from golden_model.reference import SpringModel, flatten, measure  # noqa: E402
from golden_model.reference import iterations_to_within as within  # noqa: E402

SCANS = Path(__file__).resolve().parents[1] / "tests" / "data" / "scans"
RUN = dict(tol_area=1.0, tol_shape=1.0, tol_energy=0.0)


def main() -> None:
    meshes = {"cap (10 rings)": spherical_cap(10), "saddle 15×15": saddle_grid(15),
              "cylinder strip 12×12": rolled_grid(12, 12, arc_degrees=180)[0]}
    meshes.update({p.stem: load_mesh(p) for p in sorted(SCANS.glob("*.obj"))})
    print("| mesh | V | start | paper (γ 0.001) | momentum | momentum + barrier |")
    print("|---|---|---|---|---|---|")
    finals = []
    for name, mesh in meshes.items():
        paper_cap = 30000 if mesh.n_vertices < 1000 else 10000
        for start in ("tutte", "arap"):
            p0 = initial_layout(mesh, start)
            counts = []
            for dynamics, barrier, cap in (("paper", False, paper_cap), ("momentum", False, 1500),
                                           ("momentum", True, 1500)):
                target = flatten(mesh, p0, FlattenParams(dynamics="momentum", barrier=barrier, max_iter=3000,
                                                         **RUN)).final.shape_error
                extra = dict(density="auto", damping=0.001) if dynamics == "paper" else {}
                result = flatten(mesh, p0, FlattenParams(dynamics=dynamics, barrier=barrier, max_iter=cap,
                                                         **extra, **RUN))
                k = within(result.history.shape_error, target)
                counts.append(f">{cap}" if k is None else str(k))
                if dynamics == "momentum" and barrier:
                    finals.append((name, start, result.final))
            print(f"| {name} | {mesh.n_vertices} | {start} | " + " | ".join(counts) + " |", flush=True)
    print()
    print("| mesh | start | momentum + barrier: E_S / E_C / folded | libigl ARAP | libigl LSCM |")
    print("|---|---|---|---|---|")
    for name, start, final in finals:
        mesh = meshes[name]
        cells = []
        for method in ("arap", "lscm"):
            layout = initial_layout(mesh, method)
            m = measure(SpringModel.build(mesh, layout, 0.5, "auto"), layout)
            cells.append(f"{m.area_error:.4f} / {m.shape_error:.4f} / {m.folded}")
        print(f"| {name} | {start} | {final.area_error:.4f} / {final.shape_error:.4f} / {final.folded} | "
              + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
