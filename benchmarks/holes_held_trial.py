"""Kept holes left free or held open by their fill: the design choice of ``--keep-holes``, measured.

Run: ``.venv/bin/python benchmarks/holes_held_trial.py [--corpus DIR]``: the corpus's ``holed`` patches
(``scripts/corpus.py``; docs/corpus.md; left out where the corpus is not built) and generated domes with a
slot, a comb-shaped hole and a ring's middle cut out.  Float engine, each patch's mesh-file defaults, from
one start: the ``auto`` start of the patch with its holes closed (``Mesh.disk``), fold-free.

* **free** (what ``--keep-holes`` runs): the dynamics on the patch's own triangles alone;
* **held** (a trial, not adopted): the dynamics on the patch with its holes' fill (``fill_holes``), whose
  springs and guarded triangles hold each hole open; the pattern is the patch's own triangles.

Per patch: iterations, E_S and E_C of the patch's own triangles, and the overlaps of the pattern (pairs of
boundary sides that meet, holes wrapped over: ``golden_model.mesh.overlap_counts``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from corpus_table import DEFAULT_CORPUS, MANIFEST, holed, load_patch  # noqa: E402
from golden_model.mesh import Mesh, folded_faces, overlap_counts  # noqa: E402
from sim.generate import dome_grid, grid_with_cut_outs  # noqa: E402
from golden_model.reference import SpringModel, flatten, measure  # noqa: E402
from sim.layouts import start_layout  # noqa: E402
from sim.run_options import file_defaults  # noqa: E402


def cells(mesh: Mesh, run_on: Mesh, start: np.ndarray) -> str:
    """``iterations, E_S, E_C, overlaps`` of the run on ``run_on`` from ``start``, measured on ``mesh``."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        result = flatten(run_on, start, file_defaults(mesh))
    layout = result.positions
    piece = measure(SpringModel.build(mesh, layout, 0.5, "auto"), layout)
    if folded_faces(layout, mesh.faces).any():
        overlaps = f"{int(folded_faces(layout, mesh.faces).sum())} folded"
    else:
        crossings, turned = overlap_counts(layout, mesh.faces, mesh.boundary_loops)
        overlaps = ", ".join([f"{crossings} pairs"] * bool(crossings) + [f"{turned} wrapped"] * bool(turned)) or "none"
    return f"{result.status}, {result.iterations} | {piece.area_error:.4f} | {piece.shape_error:.4f} | {overlaps}"


def generated() -> dict[str, Mesh]:
    """Domes 160 mm across, 16 x 16 vertices (10.7 mm cells), with holes of the shapes a fill distorts."""
    n = 16
    vertices = dome_grid(n).vertices * 160.0
    shapes = {"dome with a slot (1 x 9 cells)": [(7, slice(3, 12))],
              "dome with a comb-shaped hole": [(5, slice(3, 12))] + [(slice(6, 10), c) for c in (3, 6, 9, 11)],
              "dome ring (its 11 x 11-cell middle cut out)": [(slice(2, 13), slice(2, 13))]}
    meshes = {}
    for name, cells in shapes.items():
        cut = np.zeros((n - 1, n - 1), dtype=bool)
        for rows, columns in cells:
            cut[rows, columns] = True
        meshes[name] = grid_with_cut_outs(vertices, n, cut, name=name)
    return meshes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--corpus", type=Path, default=DEFAULT_CORPUS, help="directory of the patches (default %(default)s)")
    args = parser.parse_args(argv)
    meshes = dict(generated())
    for entry in json.loads(MANIFEST.read_text())["patches"]:
        if holed(entry) and (args.corpus / f"{entry['name']}.ply").is_file():
            meshes[entry["name"]] = load_patch(entry, args.corpus)
    print("| patch | holes | free: status, it | E_S | E_C | overlaps | held: status, it | E_S | E_C | overlaps |")
    print("|---|--:|---|--:|--:|---|---|--:|--:|---|")
    for name, mesh in meshes.items():
        start = start_layout(mesh.disk, "auto").positions
        print(f"| {name} | {mesh.n_holes} | {cells(mesh, mesh, start)} | {cells(mesh, mesh.disk, start)} |",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
