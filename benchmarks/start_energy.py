"""Which layout ``--init auto`` starts from where ARAP's is fold-free: ARAP's, or LSCM's where that is exact.

Usage::

    .venv/bin/python benchmarks/start_energy.py [--corpus DIR]

Per patch: ARAP's folds and springs' energy as an rms edge strain ``√(Σ(L_e − d_e)² / Σd_e²)``
(:func:`sim.layouts.rms_strain`), LSCM's, SLIM's (from Tutte) where ARAP folds, and the start ``auto`` takes (:func:`sim.layouts.start_layout`: LSCM where ARAP is fold-free and LSCM is
fold-free, below the stop rule's floor of 1e-3 and below ARAP's strain; SLIM from Tutte where ARAP folds). First generated developable strips (a flat half ring, a half cone
frustum: their exact layout holds no energy), then every disk patch of the public corpus that is built in
``--corpus`` (docs/corpus.md). docs/guard.md quotes the table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from corpus_table import DEFAULT_CORPUS, holed, load_patch, patches  # noqa: E402
from golden_model.mesh import Mesh, folded_faces  # noqa: E402
from sim.generate import grid_faces, ring_sector  # noqa: E402
from sim.layouts import initial_layout, rms_strain, start_layout  # noqa: E402


def half_frustum(segments: int = 79, rows: int = 12) -> Mesh:
    """Half a cone frustum (a sheet-metal reducer), radius 100 to 150 over a height of 100: developable."""
    theta, s = np.meshgrid(np.linspace(0, np.pi, segments + 1), np.linspace(0, 1, rows))
    radius = 100.0 + 50.0 * s
    vertices = np.column_stack([(radius * np.cos(theta)).ravel(), (radius * np.sin(theta)).ravel(),
                                100.0 * s.ravel()])
    return Mesh(vertices, grid_faces(segments + 1, rows), name="half_frustum")


def row(mesh: Mesh) -> str:
    cells = []
    for method in ("arap", "lscm"):
        positions = initial_layout(mesh, method)
        cells += [str(int(np.count_nonzero(folded_faces(positions, mesh.faces)))), f"{rms_strain(mesh, positions):.2g}"]
    start = start_layout(mesh, "auto")
    slim = f"{rms_strain(mesh, start.positions):.2g}" if start.method == "slim" else "-"
    return f"| {mesh.name} | {mesh.n_vertices} | {' | '.join(cells)} | {slim} | {start.method} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--corpus", type=Path, default=DEFAULT_CORPUS, help="directory of the built corpus")
    args = parser.parse_args()
    print("| patch | V | ARAP folds | ARAP rms strain | LSCM folds | LSCM rms strain | SLIM's rms strain (where ARAP "
          "folds) | auto starts from |")
    print("|---|--:|--:|--:|--:|--:|--:|---|")
    print(row(ring_sector()), flush=True)
    print(row(half_frustum()), flush=True)
    built = [e for e in patches(args.corpus, None, None) if not holed(e)] if args.corpus.is_dir() else []
    for entry in built:
        mesh = load_patch(entry, args.corpus)
        print(row(Mesh(mesh.vertices, mesh.faces, name=entry["name"])), flush=True)


if __name__ == "__main__":
    main()
