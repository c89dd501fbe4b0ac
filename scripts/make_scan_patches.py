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
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from golden_model.mesh import Mesh, save_obj  # noqa: E402

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
    import trimesh

    loaded = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(loaded.faces, dtype=np.int64)
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    ok &= np.linalg.norm(np.cross(b - a, c - a), axis=1) > 0
    faces = faces[ok]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    faces = faces[np.sort(first)]
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]


def edge_graph(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    n = len(vertices)
    return sp.coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()


def face_adjacency(faces: np.ndarray) -> sp.csr_matrix:
    """Triangles sharing an (undirected) edge."""
    f = len(faces)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.sort(e, axis=1)
    owner = np.tile(np.arange(f), 3)
    order = np.lexsort((e[:, 1], e[:, 0]))
    e, owner = e[order], owner[order]
    same = np.all(e[1:] == e[:-1], axis=1)
    i, j = owner[:-1][same], owner[1:][same]
    return sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(f, f)).tocsr()


def boundary_edge_counts(faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, inverse, counts = np.unique(np.sort(e, axis=1), axis=0, return_inverse=True, return_counts=True)
    on_boundary = (counts[inverse.reshape(-1)] == 1).reshape(3, -1)
    return on_boundary.sum(axis=0)


def pinched_vertices(faces: np.ndarray, n: int) -> np.ndarray:
    """Vertices whose incident triangles form more than one edge-connected fan."""
    bad = []
    incident = sp.coo_matrix((np.ones(faces.size), (faces.ravel(), np.repeat(np.arange(len(faces)), 3))),
                             shape=(n, len(faces))).tocsr()
    for v in np.unique(faces):
        ring = incident.indices[incident.indptr[v]:incident.indptr[v + 1]]
        if len(ring) < 2:
            continue
        sub = faces[ring]
        # two triangles around v are adjacent when they share v and one more vertex
        others = [set(t) - {v} for t in sub.tolist()]
        rows, cols = [], []
        for a in range(len(ring)):
            for b in range(a + 1, len(ring)):
                if others[a] & others[b]:
                    rows.append(a)
                    cols.append(b)
        g = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(ring),) * 2)
        if connected_components(g, directed=False)[0] > 1:
            bad.append(v)
    return np.asarray(bad, dtype=np.int64)


def nearest(vertices: np.ndarray, point) -> int:
    return int(np.argmin(np.linalg.norm(vertices - np.asarray(point, dtype=np.float64), axis=1)))


def distances(vertices: np.ndarray, faces: np.ndarray, kind: str, points) -> np.ndarray:
    graph = edge_graph(vertices, faces)
    seeds = [nearest(vertices, p) for p in points]
    if kind == "ball":
        return dijkstra(graph, directed=False, indices=seeds[0])
    if kind == "strip":
        d, pred = dijkstra(graph, directed=False, indices=seeds[0], return_predecessors=True)
        path, v = [seeds[1]], seeds[1]
        while v != seeds[0]:
            v = int(pred[v])
            path.append(v)
        return dijkstra(graph, directed=False, indices=path, min_only=True)
    raise ValueError(kind)


def cut_patch(vertices: np.ndarray, faces: np.ndarray, kind: str, points, target: int) -> tuple[np.ndarray, np.ndarray]:
    d = distances(vertices, faces, kind, points)
    radius = np.sort(d)[target - 1]
    keep = np.all(d[faces] <= radius, axis=1)
    adjacency = face_adjacency(faces)
    far = int(np.argmax(d[faces].min(axis=1)))
    for _ in range(100):
        before = keep.copy()
        # largest kept component
        sub = adjacency[keep][:, keep]
        _, label = connected_components(sub, directed=False)
        idx = np.flatnonzero(keep)
        keep[:] = False
        keep[idx[label == np.bincount(label).argmax()]] = True
        # fill enclosed islands of unkept triangles
        out = np.flatnonzero(~keep)
        _, label = connected_components(adjacency[~keep][:, ~keep], directed=False)
        outer = label[np.searchsorted(out, far)]
        keep[out[label != outer]] = True
        # pinched boundary vertices: take their whole source one-ring
        pinched = pinched_vertices(faces[keep], len(vertices))
        if len(pinched):
            keep |= np.isin(faces, pinched).any(axis=1)
        # ears
        idx = np.flatnonzero(keep)
        ears = boundary_edge_counts(faces[keep]) >= 2
        keep[idx[ears]] = False
        if np.array_equal(before, keep):
            break
    else:
        raise RuntimeError("patch clean-up did not settle")
    kept = faces[keep]
    used = np.unique(kept)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept]


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
