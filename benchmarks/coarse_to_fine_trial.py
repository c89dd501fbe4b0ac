"""A trial, not a default: a two-level start for the grid patches of issue 25's 120-iteration bound (float only).

Usage::

    .venv/bin/python benchmarks/coarse_to_fine_trial.py      # about 20 s of CPU

The bumpy patch, the saddle and the cylinder strip are 31×31 vertex grids; the 16×16 grid of the same surface
holds every other row and column of them. The trial flattens the coarse grid from its Tutte layout with the
defaults (guard and barrier) for a number of iterations (or until the mesh files' stop rule), takes its layout
to the fine grid (the shared vertices keep their place, the others go to the middle of the coarse edge they
split, the grid's diagonals included: each fine triangle is a quarter of a coarse one, so a fold-free coarse
layout gives a fold-free fine one), and runs the defaults on the fine grid from there. Printed: the coarse
iterations, the fine iterations to within 1 % of the fine minimum's E_C (``iterations_to_within``; the minimum
as ``tests/golden_model/test_dynamics.py`` measures it, from Tutte), and the work in fine iterations, the
coarse ones weighted by their vertices (256/961).
"""

from __future__ import annotations

import sys
from pathlib import Path

import igl
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sim.generate import bumpy_grid, grid_faces, rolled_grid, saddle_grid  # noqa: E402
from sim.layouts import initial_layout  # noqa: E402
from golden_model.mesh import Mesh, folded_faces  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
from golden_model.reference import flatten, iterations_to_within  # noqa: E402
from sim.run_options import FILE_TOL_ENERGY  # noqa: E402

FINE, COARSE = 31, 16
GRIDS = {
    "bumpy 31×31": bumpy_grid,
    "saddle 31×31": saddle_grid,
    "cylinder strip 31×31, 180°": lambda n: rolled_grid(n, n, arc_degrees=180)[0],
}
RUN = dict(tol_area=1.0, tol_shape=1.0, tol_energy=0.0, energy_window=1000)  # exactly max_iter iterations
#: Coarse runs: a fixed number of iterations, or ``None``: the mesh files' stop rule (cap 400).
COARSE_ITERATIONS = (40, 60, 80, 97, 100, 120, None)


def prolong(coarse: np.ndarray, n: int) -> np.ndarray:
    """A ``(2n−1)²`` grid's layout from an ``n²`` grid's (row-major, ``grid_faces``' diagonals)."""
    c = coarse.reshape(n, n, 2)
    fine = np.zeros((2 * n - 1, 2 * n - 1, 2))
    fine[::2, ::2] = c
    fine[1::2, ::2] = 0.5 * (c[:-1] + c[1:])
    fine[::2, 1::2] = 0.5 * (c[:, :-1] + c[:, 1:])
    fine[1::2, 1::2] = 0.5 * (c[:-1, :-1] + c[1:, 1:])
    return fine.reshape(-1, 2)


def coarse_with_path_lengths(fine: Mesh, n: int) -> Mesh:
    """The ``n²`` grid of every other vertex of the ``(2n−1)²`` grid ``fine``, each edge's rest length the sum of
    the two fine edges it spans (through the fine vertex at its middle)."""
    big = 2 * n - 1
    index = np.arange(big * big).reshape(big, big)
    coarse = Mesh(fine.vertices[index[::2, ::2].ravel()], grid_faces(n, n), name=f"{fine.name}, paths")
    rows, cols = np.divmod(coarse.edges, n)  # each end's coarse row and column
    ends = index[2 * rows, 2 * cols]
    middle = index[rows.sum(axis=1), cols.sum(axis=1)]
    vertices = fine.vertices
    coarse.__dict__["rest_lengths"] = (np.linalg.norm(vertices[ends[:, 0]] - vertices[middle], axis=1)
                                       + np.linalg.norm(vertices[middle] - vertices[ends[:, 1]], axis=1))
    return coarse


def decimated(fine: Mesh) -> Mesh:
    """libigl's ``decimate`` of ``fine`` to a quarter of its faces."""
    vertices, faces, _, _ = igl.decimate(np.asfortranarray(fine.vertices), np.asfortranarray(fine.faces, dtype=np.int32),
                                         len(fine.faces) // 4)
    return Mesh(np.asarray(vertices), np.asarray(faces), name=f"{fine.name}, decimated")


def prolong_by_closest_point(fine: Mesh, coarse: Mesh, layout: np.ndarray) -> np.ndarray:
    """Each fine vertex at its closest point on the coarse 3D mesh, carried to ``layout`` barycentrically."""
    _, face, closest = igl.point_mesh_squared_distance(fine.vertices, coarse.vertices, coarse.faces.astype(np.int64))
    corners = coarse.faces[face]
    v = coarse.vertices
    weights = igl.barycentric_coordinates(closest, v[corners[:, 0]], v[corners[:, 1]], v[corners[:, 2]])
    return np.einsum("ij,ijk->ik", weights, layout[corners])


def main() -> None:
    print("| patch | coarse rest lengths | fine from Tutte | " + " | ".join(
        f"coarse {k if k is not None else 'to the stop rule'}: coarse it, fine it, work" for k in COARSE_ITERATIONS) + " |")
    print("|---" * (3 + len(COARSE_ITERATIONS)) + "|")
    for name, make in GRIDS.items():
        fine = make(FINE)
        p0 = initial_layout(fine, "tutte")
        target = flatten(fine, p0, FlattenParams(dynamics="momentum", max_iter=3000, **RUN)).final.shape_error
        direct = iterations_to_within(flatten(fine, p0, FlattenParams(dynamics="momentum", max_iter=400, **RUN))
                                      .history.shape_error, target)
        def on_grid(layout: np.ndarray, _coarse: Mesh) -> np.ndarray:
            return prolong(layout, COARSE)

        def by_closest_point(layout: np.ndarray, coarse: Mesh) -> np.ndarray:
            return prolong_by_closest_point(fine, coarse, layout)
        variants = (("plain", make(COARSE), on_grid), ("paths", coarse_with_path_lengths(fine, COARSE), on_grid),
                    ("decimated", decimated(fine), by_closest_point))
        for lengths, coarse, to_fine in variants:
            cells = []
            for k in COARSE_ITERATIONS:
                params = (FlattenParams(dynamics="momentum", max_iter=k, **RUN) if k is not None else
                          FlattenParams(dynamics="momentum", tol_area=1.0, tol_shape=1.0, tol_energy=FILE_TOL_ENERGY,
                                        max_iter=400))
                first = flatten(coarse, initial_layout(coarse, "tutte"), params)
                start = to_fine(first.positions, coarse)
                folds = int(folded_faces(start, fine.faces).sum())
                if folds:
                    cells.append(f"{first.iterations}, start folds {folds}")
                    continue
                reached = iterations_to_within(flatten(fine, start, FlattenParams(dynamics="momentum", max_iter=400,
                                                                                  **RUN)).history.shape_error, target)
                work = (f"{reached + first.iterations * coarse.n_vertices / fine.n_vertices:.0f}" if reached is not None
                        else "—")
                cells.append(f"{first.iterations}, {reached if reached is not None else '> 400'}, {work}")
            print(f"| {name} | {lengths} ({coarse.n_vertices} V) | {direct} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
