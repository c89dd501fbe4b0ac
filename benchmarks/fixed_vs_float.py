"""Fixed-point golden model against the float reference on the acceptance meshes.

Usage: .venv/bin/python benchmarks/fixed_vs_float.py [--formats default]

Prints a markdown table: status and iterations of both engines, the final
E_S/E_C deviation, the largest position deviation (in mean edge lengths)
and the saturation events, for Surf1/Surf2 (paper parameters) and the
generated meshes (density auto, damping 0.05, tolerances 0.01, 300
iterations), from pca and tutte layouts, with fixed and variable steps.
"""

from __future__ import annotations

import argparse

import numpy as np

from golden_model.builtin import builtin_mesh
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed
from golden_model.fixed.measures import FixedPointError
from sim.generate import generated_meshes
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from golden_model.reference import flatten


def cases():
    for name in ("surf1", "surf2"):
        mesh, paper = builtin_mesh(name)
        yield name, mesh, paper.flatten_params()
    for name, mesh in generated_meshes().items():
        yield name, mesh, FlattenParams(density="auto", damping=0.05, tol_area=0.01, tol_shape=0.01,
                                        tol_energy=0.05, max_iter=300)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--formats", default="default")
    args = parser.parse_args()
    fs = FormatSet.load(args.formats)
    print(f"format set: {fs.name}")
    print("| mesh | init | step | float | fixed | max ΔE_S, ΔE_C | max position error (edges) | saturations |")
    print("|---|---|---|---|---|---|---|---|")
    worst = 0.0
    for name, mesh, params in cases():
        for init in ("pca", "tutte"):
            p0 = initial_layout(mesh, init)
            for step in ("fixed", "variable"):
                p = params.with_(step=step)
                ref = flatten(mesh, p0, p)
                try:
                    fix = flatten_fixed(mesh, p0, p, fs)
                except FixedPointError as exc:
                    print(f"| {name} | {init} | {step} | {ref.status} {ref.iterations} | refused: {exc} | | | |")
                    continue
                dev = max(abs(ref.final.area_error - fix.final.area_error),
                          abs(ref.final.shape_error - fix.final.shape_error))
                worst = max(worst, dev)
                pos = np.abs(ref.positions - fix.positions).max() / mesh.rest_lengths.mean()
                print(f"| {name} | {init} | {step} | {ref.status} {ref.iterations} | {fix.status} {fix.iterations} "
                      f"| {dev:.1e} | {pos:.1e} | {fix.extra['saturations']} |")
    print(f"worst final-error deviation: {worst:.2e}")


if __name__ == "__main__":
    main()
