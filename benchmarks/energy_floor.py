"""How exact the guarded run leaves a developable patch, against ``--tol-energy``.

Usage::

    .venv/bin/python benchmarks/energy_floor.py

A developable patch's energy falls to 0 and its relative change stays large, so the stop rule's energy floor
(an rms edge strain of ``min(ε, 1e-3)``, :func:`golden_model.guard.energy_floor_fraction`) is what stops it.
Per ``ε``: status, iterations, E_S, E_C and the worst edge strain of a 90° rolled 8×8 grid from Tutte's
layout (float, the momentum dynamics with the guard and the barrier). docs/guard.md quotes the table.
"""

from __future__ import annotations

import numpy as np

from sim.generate import rolled_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from golden_model.reference import flatten


def main() -> None:
    mesh, _ = rolled_grid(8, 8, arc_degrees=90.0)
    p0 = initial_layout(mesh, "tutte")
    print("| --tol-energy | status | iterations | E_S | E_C | worst edge strain |")
    print("|---|---|---|---|---|---|")
    for tol in (1e-3, 1e-6, 1e-9):
        result = flatten(mesh, p0, FlattenParams(dynamics="momentum", tol_energy=tol, max_iter=3000))
        ends = result.positions[mesh.edges]
        strain = np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1) / mesh.rest_lengths - 1
        print(f"| {tol:g} | {result.status} | {result.iterations} | {result.final.area_error:.1e} | "
              f"{result.final.shape_error:.1e} | {np.abs(strain).max():.1e} |")


if __name__ == "__main__":
    main()
