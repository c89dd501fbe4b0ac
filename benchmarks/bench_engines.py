"""Per-iteration time of the float and fixed-point engines on a generated ~90k-vertex mesh.

Usage: .venv/bin/python benchmarks/bench_engines.py [--n 300] [--iterations 20] [--formats default]

Measures, in one run (ratios are what to compare on a shared machine):
  * Tutte and PCA initial layouts (one sparse LU solve; SVD);
  * one `jacobi` iteration of the float engine (forces, Euler step and the
    measurement the stopping rule needs), as edge updates per second;
  * the same step written as plain vectorised numpy (np.add.at scatter,
    edge vectors recomputed for the measurement): the baseline the engine
    must at least match;
  * one iteration of the bit-exact fixed-point golden model (`--engine
    fixed`: force pass, E_S/E_C, step generator, integrate pass);
  * the SpringflatEngine's memory images of that problem (`build_image`:
    what the host driver loads over the bus).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from golden_model.fixed import FormatSet, SaturationCounter
from golden_model.fixed.engine import FixedEngine, prepare
from golden_model.engine_spec.image import EngineCapacity, build_image
from sim.layouts import pca_layout, tutte_layout
from golden_model.mesh import Mesh, signed_areas_2d
from golden_model.params import FlattenParams
from golden_model.reference import SpringModel, _Jacobi, variable_step
from sim.generate import grid_faces, grid_uv


def dome(n: int) -> Mesh:
    uv = grid_uv(n, n) - 0.5
    return Mesh(np.column_stack([uv, 0.3 * (1 - 2 * (uv**2).sum(axis=1))]), grid_faces(n, n), name=f"dome{n}")


def best_of(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


class PlainNumpyStep:
    """The same jacobi iteration, written the obvious vectorised way."""

    def __init__(self, mesh: Mesh, model: SpringModel, positions: np.ndarray, spring: float):
        self.mesh, self.model, self.spring = mesh, model, spring
        self.positions = positions.copy()
        self.velocities = np.zeros_like(positions)

    def iteration(self, dt: float) -> None:
        mesh, p = self.mesh, self.positions
        i, j = mesh.edges.T
        delta = p[j] - p[i]
        length = np.linalg.norm(delta, axis=1)
        term = (0.5 * self.spring * (1 - mesh.rest_lengths / length))[:, None] * delta
        forces = np.zeros_like(p)
        np.add.at(forces, i, term)
        np.add.at(forces, j, -term)
        a = forces / self.model.masses[:, None]
        p += dt * self.velocities + 0.5 * dt * dt * a
        self.velocities += dt * a
        # measurement for the stopping rule
        delta = p[j] - p[i]
        length = np.linalg.norm(delta, axis=1)
        area = np.abs(signed_areas_2d(p, mesh.faces))
        e_s = np.abs(mesh.face_areas - area).sum() / mesh.face_areas.sum()
        e_c = np.abs(mesh.rest_lengths - length).sum() / mesh.rest_lengths.sum()
        energy = self.spring * ((length - mesh.rest_lengths) ** 2).sum()
        return e_s, e_c, energy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=300, help="grid side (n² vertices; default 300 → 90,000)")
    parser.add_argument("--iterations", type=int, default=20, help="timed iterations (best of)")
    parser.add_argument("--formats", default="default", help="fixed-point format set (default: default)")
    args = parser.parse_args()

    t = time.perf_counter()
    mesh = dome(args.n)
    _ = mesh.edges, mesh.rest_lengths, mesh.face_areas, mesh.neighbours
    build = time.perf_counter() - t
    tutte = best_of(lambda: tutte_layout(mesh), 2)
    pca = best_of(lambda: pca_layout(mesh), 2)
    p0 = pca_layout(mesh)
    params = FlattenParams(density="auto")
    model = SpringModel.build(mesh, p0, params.spring, params.density)
    engine = _Jacobi(model, params, p0)
    dt = variable_step(0.5, 0.5)

    def engine_iteration():
        engine.advance(dt)
        engine.measure()

    plain = PlainNumpyStep(mesh, model, p0, params.spring)
    problem = prepare(mesh, p0, params, FormatSet.load(args.formats))
    fixed = FixedEngine(problem, SaturationCounter())
    capacity = EngineCapacity(mesh.n_vertices, len(problem.stream.neighbour), mesh.n_faces)
    t_image = best_of(lambda: build_image(problem, capacity), 3)

    def fixed_iteration():
        fixed.advance(fixed.step_size(fixed.measure()))

    engine_iteration(), plain.iteration(dt), fixed_iteration()  # warm-up
    t_engine = best_of(engine_iteration, args.iterations)
    t_plain = best_of(lambda: plain.iteration(dt), args.iterations)
    t_fixed = best_of(fixed_iteration, args.iterations)
    e = mesh.n_edges
    print(f"mesh: {mesh.n_vertices} vertices, {mesh.n_faces} faces, {e} edges (built and validated in {build:.2f} s)")
    print(f"| what | time | edge updates/s |")
    print(f"|---|---|---|")
    print(f"| tutte layout | {tutte:.2f} s | |")
    print(f"| pca layout | {pca:.3f} s | |")
    print(f"| float engine, jacobi iteration | {1e3 * t_engine:.1f} ms | {e / t_engine / 1e6:.1f} M |")
    print(f"| plain numpy (np.add.at) iteration | {1e3 * t_plain:.1f} ms | {e / t_plain / 1e6:.1f} M |")
    print(f"| fixed-point engine ({args.formats}) iteration | {1e3 * t_fixed:.1f} ms | {e / t_fixed / 1e6:.1f} M |")
    print(f"| SpringflatEngine memory images (build_image) | {1e3 * t_image:.1f} ms | |")
    print(f"float engine / plain numpy time: {t_engine / t_plain:.2f}; fixed / float engine time: {t_fixed / t_engine:.2f}")


if __name__ == "__main__":
    main()
