#!/usr/bin/env python3
"""Cut the small scanned disk patches in ``tests/data/scans`` from public scans.

Usage::

    python scripts/make_scan_patches.py ORIGINALS_DIR [OUT_DIR]

``ORIGINALS_DIR`` must hold the unmodified source files named in ``SOURCES``
(see ``tests/data/scans/README.md`` for their repositories and commits);
``OUT_DIR`` defaults to ``tests/data/scans``.  The originals are not part of
this repository.

Every patch is made the same deterministic way (no randomness, no
decimation, vertex positions copied bit for bit from the source):

1. Read the source with trimesh (``process=False``); drop unreferenced
   vertices, triangles with a repeated corner or zero area, and repeated
   triangles.
2. Geodesic distance ``d`` from a seed on the edge graph (Dijkstra, edge
   weight = 3D edge length).  The seed is the vertex nearest to a given 3D
   point; for a *strip* the sources are all vertices on the edge-graph
   shortest path between two such seeds.
3. Radius ``r`` = the ``target``-th smallest distance; keep the triangles
   whose three corners have ``d ≤ r``.
4. Clean up until nothing changes: keep the largest edge-connected set of
   triangles; add back every component of the *unkept* triangles except the
   one containing the farthest triangle (this closes islands the ball left
   out, so only the outer boundary remains); add the whole source one-ring
   of any vertex whose kept triangles form more than one fan (pinched
   boundary vertex); drop triangles with two or three boundary edges
   (ears), which only make spikes.
5. Renumber the kept vertices in source order and check the result with
   :class:`golden_model.mesh.Mesh` (single manifold disk, one boundary loop).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

from corpus import clean, cut_patch, read_original  # noqa: E402  (the cutting method, generalised there)
from golden_model.mesh import Mesh  # noqa: E402
from sim.mesh_io import save_obj  # noqa: E402

#: name -> (source file, kind, seed point(s), target vertex count in the ball)
SOURCES = {
    # Stanford bunny, muzzle and face: a strongly curved cap.
    "bunny_face": ("stanford-bunny.obj", "ball", [(-0.095, 0.123, 0.02)], 3000),
    # Stanford bunny, tip of the taller ear: a finger-like cap, the most curved.
    "bunny_ear": ("stanford-bunny.obj", "ball", [(-0.0175, 0.1873, -0.0198)], 1200),
    # Stanford bunny, top of the back: gently curved.
    "bunny_back": ("stanford-bunny.obj", "ball", [(0.0, 0.135, -0.01)], 2200),
    # Nefertiti (Neues Museum scan), face centred on the nose: strongly curved.
    "nefertiti_face": ("nefertiti.obj", "ball", [(0.0, -181.0, -10.0)], 3000),
    # Stanford armadillo, long strip from the belly down the right leg: long boundary.
    "armadillo_strip": ("armadillo.obj", "strip", [(0.0, 0.0, 0.07), (0.15, -0.45, -0.03)], 2000),
}


def read_clean(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The original after step 1 (the code is ``scripts/corpus.py``'s, which also drops triangles on edges
    shared by more than two triangles: none in these originals)."""
    return clean(*read_original(path))


def main(argv: list[str]) -> int:
    if len(argv) not in (2, 3):
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    src = Path(argv[1])
    out = Path(argv[2]) if len(argv) == 3 else REPO / "tests" / "data" / "scans"
    out.mkdir(parents=True, exist_ok=True)
    cache: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, (file, kind, points, target) in SOURCES.items():
        if file not in cache:
            cache[file] = read_clean(src / file)
        vertices, faces = cut_patch(*cache[file], kind, points, target)
        mesh = Mesh(vertices, faces, name=name)  # raises MeshError if not a single disk
        save_obj(out / f"{name}.obj", mesh.vertices, mesh.faces)
        print(f"{name}: {mesh.n_vertices} vertices, {mesh.n_faces} faces")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
