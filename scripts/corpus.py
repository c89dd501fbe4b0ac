#!/usr/bin/env python3
"""The public disk-patch corpus: fetch the originals, cut the patches, check both against the manifest.

The corpus is ``benchmarks/corpus/manifest.json``: one entry per patch naming the public original
(repository, commit, path, sha256, licence), the cut recipe, and the sha256, size and quality
figures of the patch it gives.  Neither the originals nor the patches are part of this repository;
this script makes them, by default in ``build/corpus`` (``build/`` is ignored by git)::

    python scripts/corpus.py download    --out build/corpus   # needs internet (raw.githubusercontent.com)
    python scripts/corpus.py from-mirror --mirror-root /work/.mirror --out build/corpus
    python scripts/corpus.py build       --originals DIR --out build/corpus

``download`` and ``from-mirror`` put the originals in ``OUT/originals`` and then run ``build``;
``build`` checks every original's sha256, cuts it and checks the patch's sha256.  The patches are
binary little-endian PLY files ``OUT/<name>.ply`` (double coordinates, copied bit for bit from the
original; int32 triangles), which :func:`sim.mesh_io.load_mesh` reads.

Every patch is cut the same deterministic way (no randomness, no decimation, no smoothing):

1. Read the original (trimesh, ``process=False``; STL corners that are bit-identical are merged,
   as :func:`sim.mesh_io.load_mesh` does; triangle strips of a PLY are unrolled).  Drop
   unreferenced vertices, triangles with a repeated corner or zero area, repeated triangles and
   every triangle on an edge that more than two triangles share.
2. Geodesic distance ``d`` on the edge graph (Dijkstra, weight = 3D edge length) from the vertex
   nearest a seed point (*ball*), or from the edge-graph shortest path between two seed points
   (*strip*).
3. Keep the triangles whose three corners have ``d <= r``, ``r`` the ``target``-th smallest ``d``.
4. Until nothing changes: keep the largest edge-connected set of kept triangles; add back every
   set of unkept triangles that the kept ones enclose (all but the one holding the triangle
   farthest from the seed); add the whole one-ring of every vertex whose kept triangles form more
   than one fan (pinched vertex); drop ears (triangles with two or three boundary edges).
5. A recipe's ``cut_outs`` (the ``holed`` kind, for ``--keep-holes``), each a seed point and a
   target: drop the patch's triangles whose corners all lie within the target-th smallest
   edge-graph distance from the vertex nearest the seed, then repeat step 4 without adding back
   enclosed triangles (the cut-outs are holes).
6. Renumber the kept vertices in original order; the result must be a single manifold disk with
   one boundary loop, or with ``cut_outs`` a disk with holes (:class:`golden_model.mesh.Mesh`), and
   reading the written file back must give the same arrays.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from golden_model.mesh import Holes, Mesh, MeshError  # noqa: E402
from sim.mesh_io import load_mesh_with_notes  # noqa: E402
from sim.outputs import write_text_file  # noqa: E402

MANIFEST = REPO / "benchmarks" / "corpus" / "manifest.json"
DEFAULT_OUT = REPO / "build" / "corpus"
RAW_URL = "https://raw.githubusercontent.com/{repo}/{commit}/{path}"

#: The kinds of patch the corpus covers (the kinds that broke the flattener in issue 25, and cut-outs).
KINDS = {
    "dense_scan": "dense scanned surface (faces, statues), many small triangles",
    "cad_crease": "CAD panel with sharp feature lines (creases)",
    "cone_tip": "patch around a cone apex (horn, spike, CAD cone tip)",
    "tube": "thin tube, finger, leg or tentacle cut as a disk (a capped tube)",
    "taco": "strongly curved cap folded like a taco (ears, fins)",
    "cad_sliver": "CAD tessellation with slivers (min angle < 1 deg, area ratio > 1e4)",
    "gentle": "gently curved patch",
    "holed": "a patch with cut-outs (holes kept with --keep-holes)",
}


class CorpusError(RuntimeError):
    """A corpus step that failed; the message is one line for the user."""


# --------------------------------------------------------------------------- reading originals


def sha256_of(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _ply_tristrips(data: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """Vertices and triangles of a binary little-endian PLY whose faces are ``tristrips`` (None if it is not one).

    Only the layout of such files is read: ``vertex`` with float x, y, z and one ``tristrips``
    element holding a list of int indices, ``-1`` ending each strip.  Triangle k of a strip is
    ``(s_k, s_k+1, s_k+2)``, odd k with its first two corners swapped, as the strip's winding alternates.
    """
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply") or end < 0 or b"element tristrips" not in data[:end]:
        return None
    header = data[:end].decode("ascii").split("\n")
    if "format binary_little_endian 1.0" not in header:
        raise CorpusError("tristrips PLY: only binary_little_endian is read")
    n = int(next(line.split()[2] for line in header if line.startswith("element vertex")))
    body = data[end + len(b"end_header\n"):]
    vertices = np.frombuffer(body, dtype="<f4", count=3 * n).reshape(n, 3).astype(np.float64)
    pos = 12 * n
    (length,) = np.frombuffer(body, dtype="<i4", count=1, offset=pos)
    strip = np.frombuffer(body, dtype="<i4", count=int(length), offset=pos + 4).astype(np.int64)
    breaks = np.flatnonzero(strip < 0)
    starts = np.r_[0, breaks + 1]
    stops = np.r_[breaks, len(strip)]
    faces = []
    for a, b in zip(starts, stops):
        s = strip[a:b]
        if len(s) < 3:
            continue
        tri = np.column_stack([s[:-2], s[1:-1], s[2:]])
        odd = np.arange(len(tri)) % 2 == 1
        tri[odd] = tri[odd][:, [1, 0, 2]]
        faces.append(tri)
    return vertices, np.concatenate(faces)


def _merge_exact_duplicates(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge bit-identical vertices, numbered by first appearance (as the project's STL reader does)."""
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return vertices[np.sort(first)], rank[inverse.reshape(-1)][faces]


def read_original(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(V, 3)`` float64 vertices and ``(F, 3)`` int64 triangles of an original file, as stored."""
    data = path.read_bytes()
    strips = _ply_tristrips(data) if path.suffix.lower() == ".ply" else None
    if strips is not None:
        return strips
    import trimesh

    loaded = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(loaded.faces, dtype=np.int64)
    if path.suffix.lower() == ".stl":
        vertices, faces = _merge_exact_duplicates(vertices, faces)
    return vertices, faces


def _edge_keys(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each directed corner edge (3F, face-major order k = corner) as an undirected edge id, with the id counts."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, inverse, counts = np.unique(np.sort(e, axis=1), axis=0, return_inverse=True, return_counts=True)
    return e, inverse.reshape(-1), counts


def clean(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop repeated-corner, zero-area and repeated triangles, triangles on non-manifold edges, unused vertices."""
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    ok &= np.linalg.norm(np.cross(b - a, c - a), axis=1) > 0
    faces = faces[ok]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    faces = faces[np.sort(first)]
    _, edge_id, counts = _edge_keys(faces)
    shared = (counts[edge_id] > 2).reshape(3, -1).any(axis=0)
    faces = faces[~shared]
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]


# --------------------------------------------------------------------------- cutting


def edge_graph(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    w = np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)
    n = len(vertices)
    return sp.coo_matrix((np.r_[w, w], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()


def face_adjacency(faces: np.ndarray) -> sp.csr_matrix:
    """Triangles sharing an (undirected) edge."""
    f = len(faces)
    _, edge_id, _ = _edge_keys(faces)
    owner = np.tile(np.arange(f), 3)
    order = np.argsort(edge_id, kind="stable")
    eid, own = edge_id[order], owner[order]
    same = eid[1:] == eid[:-1]
    i, j = own[:-1][same], own[1:][same]
    return sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(f, f)).tocsr()


def boundary_edge_counts(faces: np.ndarray) -> np.ndarray:
    """``(F,)`` how many of each triangle's edges no other triangle shares."""
    _, edge_id, counts = _edge_keys(faces)
    return (counts[edge_id] == 1).reshape(3, -1).sum(axis=0)


def pinched_vertices(faces: np.ndarray) -> np.ndarray:
    """Vertices whose incident triangles form more than one edge-connected fan.

    Vectorised: the nodes of a graph are the corners ``(face, k)``; two corners at the same vertex
    are joined when their triangles share an edge through that vertex.  A vertex is pinched when
    its corners fall into more than one component.
    """
    _, edge_id, _ = _edge_keys(faces)
    f = len(faces)
    # directed edge j of face t runs corner (t, j) -> corner (t, j+1 mod 3)
    corner_a = np.concatenate([np.arange(f) * 3 + 0, np.arange(f) * 3 + 1, np.arange(f) * 3 + 2])
    corner_b = np.concatenate([np.arange(f) * 3 + 1, np.arange(f) * 3 + 2, np.arange(f) * 3 + 0])
    order = np.argsort(edge_id, kind="stable")
    eid = edge_id[order]
    same = np.flatnonzero(eid[1:] == eid[:-1])
    p, q = order[same], order[same + 1]
    # the two directed copies of a shared edge: join the corners that sit at the same vertex
    rows, cols = [], []
    for x in (corner_a, corner_b):
        for y in (corner_a, corner_b):
            vx = faces.ravel()[x[p]]
            vy = faces.ravel()[y[q]]
            hit = vx == vy
            rows.append(x[p][hit])
            cols.append(y[q][hit])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    n = 3 * f
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    vertex = faces.ravel()
    pairs = np.unique(np.column_stack([vertex, label]), axis=0)
    fans = np.bincount(pairs[:, 0])
    return np.flatnonzero(fans > 1)


def nearest(vertices: np.ndarray, point) -> int:
    return int(np.argmin(np.linalg.norm(vertices - np.asarray(point, dtype=np.float64), axis=1)))


def distances(vertices: np.ndarray, faces: np.ndarray, method: str, points) -> np.ndarray:
    graph = edge_graph(vertices, faces)
    seeds = [nearest(vertices, p) for p in points]
    if method == "ball":
        return dijkstra(graph, directed=False, indices=seeds[0])
    if method == "strip":
        _, pred = dijkstra(graph, directed=False, indices=seeds[0], return_predecessors=True)
        path, v = [seeds[1]], seeds[1]
        while v != seeds[0]:
            if v < 0:
                raise CorpusError("strip seeds are not connected")
            v = int(pred[v])
            path.append(v)
        return dijkstra(graph, directed=False, indices=path, min_only=True)
    raise CorpusError(f"unknown cut method {method!r} (use ball or strip)")


def _within(faces: np.ndarray, d: np.ndarray, target: int) -> np.ndarray:
    """``(F,)`` bool: the triangles whose corners all lie within the ``target``-th smallest of the distances
    ``d`` ``(V,)`` (infinite: not reached)."""
    finite = np.sort(d[np.isfinite(d)])
    if target > len(finite):
        raise CorpusError(f"target {target} exceeds the {len(finite)} vertices reachable from the seed")
    return np.all(d[faces] <= finite[target - 1], axis=1)


def cut_patch(vertices: np.ndarray, faces: np.ndarray, method: str, points, target: int,
              cut_outs: tuple[dict, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """The patch of the recipe (module docstring, steps 2-6 without the check)."""
    d = distances(vertices, faces, method, points)
    faces = faces[np.isfinite(d[faces]).all(axis=1)]  # the seed's connected part of the original only
    far = int(np.argmax(d[faces].min(axis=1)))
    keep = _settled(faces, _within(faces, d, target), far)
    for cut in cut_outs:  # distances on the patch, from each cut-out's seed
        inside = np.flatnonzero(keep)
        on_patch = distances(vertices, faces[inside], "ball", [cut["seed"]])
        keep[inside[_within(faces[inside], on_patch, int(cut["target"]))]] = False
    if cut_outs:
        keep = _settled(faces, keep, None)
    kept = faces[keep]
    used = np.unique(kept)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[kept]


def _settled(faces: np.ndarray, keep: np.ndarray, far: int | None) -> np.ndarray:
    """Step 4 on ``keep`` until nothing changes; with ``far`` None, enclosed triangles are not added back."""
    keep = keep.copy()
    adjacency = face_adjacency(faces)
    for _ in range(200):
        before = keep.copy()
        idx = np.flatnonzero(keep)
        _, label = connected_components(adjacency[keep][:, keep], directed=False)
        keep[:] = False
        keep[idx[label == np.bincount(label).argmax()]] = True
        out = np.flatnonzero(~keep)
        if len(out) and far is not None:
            _, label = connected_components(adjacency[~keep][:, ~keep], directed=False)
            outer = label[np.searchsorted(out, far)] if not keep[far] else -1
            keep[out[label != outer]] = True
        pinched = pinched_vertices(faces[keep])
        if len(pinched):
            keep |= np.isin(faces, pinched).any(axis=1)
        idx = np.flatnonzero(keep)
        keep[idx[boundary_edge_counts(faces[keep]) >= 2]] = False
        if np.array_equal(before, keep):
            return keep
    raise CorpusError("patch clean-up did not settle")


# --------------------------------------------------------------------------- patch files and figures


def ply_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A binary little-endian PLY: double x, y, z and ``uchar int`` triangle lists."""
    header = ("ply\nformat binary_little_endian 1.0\ncomment springflat corpus patch\n"
              f"element vertex {len(vertices)}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    records = np.zeros(len(faces), dtype=np.dtype([("n", "u1"), ("v", "<i4", (3,))]))
    records["n"] = 3
    records["v"] = faces
    return header.encode("ascii") + np.ascontiguousarray(vertices, dtype="<f8").tobytes() + records.tobytes()


@dataclass(frozen=True)
class PatchFigures:
    """Size and triangle quality of a patch."""

    vertices: int
    faces: int
    boundary_vertices: int
    min_angle_deg: float
    area_ratio: float  # largest / smallest triangle area
    total_curvature: float  # interior angle defect / 2π (a hemisphere is 1)
    holes: int = 0  # cut-outs (the holed kind)

    def as_dict(self) -> dict:
        return {"vertices": self.vertices, "faces": self.faces, "boundary_vertices": self.boundary_vertices,
                "min_angle_deg": round(self.min_angle_deg, 4), "area_ratio": float(f"{self.area_ratio:.4g}"),
                "total_curvature": round(self.total_curvature, 4), **({"holes": self.holes} if self.holes else {})}


def figures(mesh: Mesh) -> PatchFigures:
    v, f = mesh.vertices, mesh.faces
    corners = v[f]
    angles = []
    for k in range(3):
        a = corners[:, (k + 1) % 3] - corners[:, k]
        b = corners[:, (k + 2) % 3] - corners[:, k]
        cos = np.sum(a * b, axis=1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
        angles.append(np.arccos(np.clip(cos, -1.0, 1.0)))
    angles = np.column_stack(angles)
    angle_sum = np.bincount(f.ravel(), weights=angles.ravel(), minlength=len(v))
    interior = np.ones(len(v), dtype=bool)
    interior[np.concatenate(mesh.boundary_loops)] = False
    defect = float(np.sum(2 * np.pi - angle_sum[interior]))
    area = mesh.face_areas
    return PatchFigures(mesh.n_vertices, mesh.n_faces, int(interior.size - interior.sum()),
                        float(np.degrees(angles.min())), float(area.max() / area.min()), defect / (2 * np.pi),
                        mesh.n_holes)


# --------------------------------------------------------------------------- manifest


def load_manifest(path: Path = MANIFEST) -> dict:
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise CorpusError(f"cannot read manifest '{path}': {exc}") from None
    for entry in manifest.get("patches", []):
        for key in ("name", "kind", "original", "repo", "commit", "path", "original_sha256", "licence", "recipe"):
            if key not in entry:
                raise CorpusError(f"manifest '{path}': patch {entry.get('name', '?')!r} has no {key!r}")
    return manifest


def select(manifest: dict, names: list[str] | None) -> list[dict]:
    entries = manifest["patches"]
    if not names:
        return entries
    known = {e["name"] for e in entries}
    unknown = [n for n in names if n not in known]
    if unknown:
        raise CorpusError(f"no patch named {', '.join(unknown)} in the manifest")
    return [e for e in entries if e["name"] in names]


def originals_of(entries: list[dict]) -> dict[str, dict]:
    """``original file name -> one entry naming it`` (the first)."""
    out: dict[str, dict] = {}
    for entry in entries:
        out.setdefault(entry["original"], entry)
    return out


# --------------------------------------------------------------------------- commands


def cut_entry(entry: dict, source: tuple[np.ndarray, np.ndarray]) -> tuple[bytes, Mesh]:
    recipe = entry["recipe"]
    cut_outs = tuple(recipe.get("cut_outs", ()))
    vertices, faces = cut_patch(*source, recipe["method"], recipe["seeds"], int(recipe["target"]), cut_outs)
    mesh = Mesh(vertices, faces, name=entry["name"], allow_holes=bool(cut_outs))
    if mesh.n_holes != len(cut_outs):  # (cut-outs that merged, or that reached the patch's edge)
        raise CorpusError(f"{entry['name']}: the recipe cuts {len(cut_outs)} out, the patch has "
                          f"{mesh.n_holes} hole{'s' if mesh.n_holes != 1 else ''}")
    return ply_bytes(vertices, faces), mesh


def build(manifest_path: Path, originals: Path, out: Path, names: list[str] | None, record: bool) -> int:
    """Check the originals, cut every patch, check (or, with ``record``, store) the patch figures."""
    manifest = load_manifest(manifest_path)
    entries = select(manifest, names)
    out.mkdir(parents=True, exist_ok=True)
    for file, entry in originals_of(entries).items():
        path = originals / file
        if not path.is_file():
            raise CorpusError(f"original '{path}' is missing (run download or from-mirror first)")
        got = sha256_of(path)
        if got != entry["original_sha256"]:
            raise CorpusError(f"original '{path}' has sha256 {got}, the manifest says {entry['original_sha256']}")
    cache: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    failures = 0
    for entry in entries:
        name = entry["name"]
        if entry["original"] not in cache:
            cache.clear()  # originals are used in manifest order: keep one in memory
            cache[entry["original"]] = clean(*read_original(originals / entry["original"]))
        try:
            data, mesh = cut_entry(entry, cache[entry["original"]])
        except (MeshError, CorpusError) as exc:
            print(f"{name}: FAILED: {str(exc).splitlines()[0]}", file=sys.stderr)
            failures += 1
            continue
        target = out / f"{name}.ply"
        partial = out / f"{name}.partial.ply"  # load_mesh reads by suffix
        partial.write_bytes(data)
        back = load_mesh_with_notes(partial, holes=Holes.KEEP if mesh.n_holes else Holes.REFUSE)[0]
        if not (np.array_equal(back.vertices, mesh.vertices) and np.array_equal(back.faces, mesh.faces)):
            partial.unlink()
            raise CorpusError(f"{name}: the written PLY does not read back to the same mesh")
        digest = hashlib.sha256(data).hexdigest()
        stats = figures(mesh)
        if record:
            entry["patch"] = {"file": target.name, "sha256": digest, **stats.as_dict()}
        elif entry.get("patch", {}).get("sha256") != digest:
            partial.unlink()
            print(f"{name}: FAILED: patch sha256 {digest} differs from the manifest's "
                  f"{entry.get('patch', {}).get('sha256')}", file=sys.stderr)
            failures += 1
            continue
        partial.replace(target)
        print(f"{name}: {stats.vertices} vertices, {stats.faces} faces, min angle {stats.min_angle_deg:.3g} deg, "
              f"area ratio {stats.area_ratio:.3g}", flush=True)
    if record:
        write_text_file(manifest_path, json.dumps(manifest, indent=1) + "\n")
    if failures:
        raise CorpusError(f"{failures} of {len(entries)} patches failed")
    return 0


def _mirror_git_dir(mirror_root: Path, repo: str) -> Path:
    base = mirror_root / repo.replace("/", "+") / "repo"
    for candidate in (base / ".git", base):
        if (candidate / "objects").is_dir() or (candidate / "HEAD").is_file():
            return candidate
    raise CorpusError(f"no fetched mirror of {repo} under '{mirror_root}' (expected '{base}')")


def from_mirror(manifest_path: Path, mirror_root: Path, out: Path, names: list[str] | None, record: bool) -> int:
    """Read every original with ``git show COMMIT:PATH`` from the fetched bare repositories, then build."""
    entries = select(load_manifest(manifest_path), names)
    originals = out / "originals"
    originals.mkdir(parents=True, exist_ok=True)
    for file, entry in originals_of(entries).items():
        git_dir = _mirror_git_dir(mirror_root, entry["repo"])
        done = subprocess.run(["git", f"--git-dir={git_dir}", "show", f"{entry['commit']}:{entry['path']}"],
                              capture_output=True)
        if done.returncode != 0:
            raise CorpusError(f"git show {entry['commit'][:12]}:{entry['path']} in {git_dir} failed: "
                              f"{done.stderr.decode(errors='replace').strip().splitlines()[0]}")
        (originals / file).parent.mkdir(parents=True, exist_ok=True)
        (originals / file).write_bytes(done.stdout)
    return build(manifest_path, originals, out, names, record)


def download(manifest_path: Path, out: Path, names: list[str] | None, timeout: float) -> int:
    """Fetch every original from raw.githubusercontent.com at its pinned commit, then build."""
    entries = select(load_manifest(manifest_path), names)
    originals = out / "originals"
    originals.mkdir(parents=True, exist_ok=True)
    for file, entry in originals_of(entries).items():
        target = originals / file
        if target.is_file() and sha256_of(target) == entry["original_sha256"]:
            continue
        url = RAW_URL.format(repo=entry["repo"], commit=entry["commit"], path=entry["path"])
        try:
            with urllib.request.urlopen(url, timeout=timeout) as response:
                data = response.read()
        except (urllib.error.URLError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            raise CorpusError(f"cannot download {url}: {reason} (this needs internet; offline, use from-mirror)") from None
        got = hashlib.sha256(data).hexdigest()
        if got != entry["original_sha256"]:
            raise CorpusError(f"{url} has sha256 {got}, the manifest says {entry['original_sha256']}")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(data)
    return build(manifest_path, originals, out, names, record=False)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="corpus.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--manifest", type=Path, default=MANIFEST, help="the manifest (default %(default)s)")
    sub = parser.add_subparsers(dest="command", required=True)
    about = "cut the patches from a directory of originals (checks both sha256s)"
    b = sub.add_parser("build", help=about, description=about)
    b.add_argument("--originals", type=Path, required=True, help="directory holding the originals, named as the manifest's 'original'")
    about = "read the originals from fetched bare git repositories (git show COMMIT:PATH), then build"
    m = sub.add_parser("from-mirror", help=about, description=about)
    m.add_argument("--mirror-root", type=Path, default=Path("/work/.mirror"),
                   help="directory of fetched repositories OWNER+NAME/repo (default %(default)s)")
    about = ("fetch the originals from raw.githubusercontent.com at the pinned commits (sha256-checked), then "
             "build; needs internet: the project's development machines have none, and there this fails with "
             "one line (use from-mirror or build there)")
    d = sub.add_parser("download", help=about, description=about)
    d.add_argument("--timeout", type=float, default=60.0, help="seconds per file (default %(default)s)")
    for p in (b, m, d):
        p.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output directory (default %(default)s)")
        p.add_argument("--only", nargs="+", metavar="NAME", help="only these patches")
    for p in (b, m):
        p.add_argument("--record", action="store_true",
                       help="store each patch's sha256 and figures in the manifest instead of checking them "
                            "(for a maintainer changing a recipe)")
    args = parser.parse_args(argv)
    try:
        if args.command == "build":
            return build(args.manifest, args.originals, args.out, args.only, args.record)
        if args.command == "from-mirror":
            return from_mirror(args.manifest, args.mirror_root, args.out, args.only, args.record)
        return download(args.manifest, args.out, args.only, args.timeout)
    except CorpusError as exc:
        print(f"corpus: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
