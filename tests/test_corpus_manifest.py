"""The public corpus's manifest and its cutting script (fast: no corpus file is needed).

The manifest (``benchmarks/corpus/manifest.json``) must describe at least 40 patches spanning every
kind, each with its licence, the sha256 of its original and of its patch, and a recipe; and
``scripts/corpus.py build`` must turn an original into a disk that the project's reader accepts,
refusing originals and patches whose sha256 differs from the manifest's.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from sim.mesh_io import load_mesh, save_obj
from support import REPO

MANIFEST = REPO / "benchmarks" / "corpus" / "manifest.json"
SHA256 = re.compile(r"^[0-9a-f]{64}$")


def _corpus_module():
    spec = importlib.util.spec_from_file_location("corpus_script", REPO / "scripts" / "corpus.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the class is built
    spec.loader.exec_module(module)
    return module


corpus = _corpus_module()


@pytest.fixture(scope="module")
def manifest() -> dict:
    return json.loads(MANIFEST.read_text())


def test_manifest_has_40_patches_spanning_every_kind(manifest):
    patches = manifest["patches"]
    assert len(patches) >= 40
    assert {p["kind"] for p in patches} == set(corpus.KINDS)
    assert len({p["name"] for p in patches}) == len(patches)
    assert len({p["repo"] for p in patches}) >= 4  # several public sources, not one collection


def test_every_patch_has_licence_checksums_recipe_and_size(manifest):
    for p in manifest["patches"]:
        where = p["name"]
        assert p["kind"] in corpus.KINDS, where
        assert p["licence"]["name"], where
        assert p["licence"].get("spdx") or p["licence"]["name"], where
        assert SHA256.match(p["original_sha256"]), where
        assert SHA256.match(p["patch"]["sha256"]), where
        assert re.match(r"^[0-9a-f]{40}$", p["commit"]), where
        assert p["original"] == f"{p['repo'].replace('/', '+')}/{p['path']}", where
        recipe = p["recipe"]
        assert recipe["method"] in ("ball", "strip"), where
        assert len(recipe["seeds"]) == (1 if recipe["method"] == "ball" else 2), where
        assert all(len(s) == 3 for s in recipe["seeds"]), where
        assert 500 <= p["patch"]["vertices"] <= 100_000, where
        holes = p["patch"].get("holes", 0)  # Euler: V - E + F = 1 - holes, and 2E = 3F + B
        assert p["patch"]["faces"] == 2 * p["patch"]["vertices"] - p["patch"]["boundary_vertices"] - 2 + 2 * holes, where
        if p["kind"] == "holed":  # each cut-out one hole
            assert recipe["cut_outs"] and holes == len(recipe["cut_outs"]), where
            assert all(len(c["seed"]) == 3 and c["target"] > 0 for c in recipe["cut_outs"]), where
        else:
            assert "cut_outs" not in recipe and "holes" not in p["patch"], where


def test_sizes_reach_the_large_end(manifest):
    sizes = [p["patch"]["vertices"] for p in manifest["patches"]]
    assert sum(v > 20_000 for v in sizes) >= 3
    assert max(sizes) >= 90_000


def test_sliver_patches_meet_their_definition(manifest):
    slivers = [p["patch"] for p in manifest["patches"] if p["kind"] == "cad_sliver"]
    assert slivers
    assert all(s["min_angle_deg"] < 1 and s["area_ratio"] > 1e4 for s in slivers)


def _uv_sphere(n_lat: int = 12, n_lon: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A closed sphere: two poles and ``n_lat - 1`` rings of ``n_lon`` vertices."""
    theta = np.linspace(0, np.pi, n_lat + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, n_lon, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    rings = np.column_stack([np.sin(t).ravel() * np.cos(p).ravel(), np.sin(t).ravel() * np.sin(p).ravel(),
                             np.cos(t).ravel()])
    vertices = np.vstack([[0.0, 0.0, 1.0], rings, [0.0, 0.0, -1.0]])
    south = len(vertices) - 1
    faces = []
    for j in range(n_lon):
        k = (j + 1) % n_lon
        faces.append([0, 1 + j, 1 + k])
        last = 1 + (n_lat - 2) * n_lon
        faces.append([south, last + k, last + j])
        for i in range(n_lat - 2):
            a, b = 1 + i * n_lon + j, 1 + i * n_lon + k
            faces += [[a, a + n_lon, b], [b, a + n_lon, b + n_lon]]
    return vertices, np.asarray(faces)


@pytest.fixture
def synthetic(tmp_path) -> tuple[Path, Path, Path]:
    """``(manifest, originals dir, out dir)`` with one made-up entry cutting a cap from a closed sphere."""
    originals = tmp_path / "originals"
    (originals / "someone+meshes").mkdir(parents=True)
    original = originals / "someone+meshes" / "sphere.obj"
    save_obj(original, *_uv_sphere())
    entry = {"name": "sphere_cap", "kind": "gentle", "original": "someone+meshes/sphere.obj",
             "repo": "someone/meshes", "commit": "0" * 40, "path": "sphere.obj",
             "original_sha256": hashlib.sha256(original.read_bytes()).hexdigest(),
             "licence": {"spdx": "CC0-1.0", "name": "CC0 1.0", "url": None},
             "recipe": {"method": "ball", "seeds": [[0.0, 0.0, 1.0]], "target": 60}}
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps({"format": 1, "patches": [entry]}))
    return path, originals, tmp_path / "out"


def test_build_cuts_a_disk_the_reader_accepts_and_checks_its_sha256(synthetic, capsys):
    manifest_path, originals, out = synthetic
    # first run records the patch's figures, as a maintainer does for a new recipe
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out), "--record"]) == 0
    mesh = load_mesh(out / "sphere_cap.ply")
    assert 60 <= mesh.n_vertices < 12 * 16  # a cap, not the sphere: the ball kept ~60 vertices
    assert len(mesh.boundary_loop) >= 8
    recorded = json.loads(manifest_path.read_text())["patches"][0]["patch"]
    assert recorded["sha256"] == hashlib.sha256((out / "sphere_cap.ply").read_bytes()).hexdigest()
    assert recorded["vertices"] == mesh.n_vertices
    # vertex coordinates are copied, not recomputed
    source = load_mesh_like_obj(originals / "someone+meshes" / "sphere.obj")
    assert all(any(np.array_equal(v, s) for s in source) for v in mesh.vertices[:20])
    # a plain build checks the recorded sha256 and passes
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out)]) == 0


def test_a_recipes_cut_outs_are_holes_of_the_patch(synthetic):
    from golden_model.mesh import Holes, MeshError
    from sim.mesh_io import load_mesh_with_notes

    manifest_path, originals, out = synthetic
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out), "--record"]) == 0
    plain = load_mesh(out / "sphere_cap.ply")
    data = json.loads(manifest_path.read_text())
    seed = _uv_sphere()[0][1 + 2 * 16 + 4].tolist()  # a vertex of the cap's third ring
    data["patches"][0]["recipe"]["cut_outs"] = [{"seed": seed, "target": 4}]
    manifest_path.write_text(json.dumps(data))
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out), "--record"]) == 0
    with pytest.raises(MeshError, match="boundary loops"):
        load_mesh(out / "sphere_cap.ply")
    mesh = load_mesh_with_notes(out / "sphere_cap.ply", holes=Holes.KEEP)[0]
    assert mesh.n_holes == 1 and mesh.n_faces < plain.n_faces and seed in mesh.vertices[mesh.boundary_loops[1]].tolist()
    assert json.loads(manifest_path.read_text())["patches"][0]["patch"]["holes"] == 1
    data["patches"][0]["recipe"]["cut_outs"] *= 2  # the same cut-out twice: one hole, not two
    manifest_path.write_text(json.dumps(data))
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out), "--record"]) == 1


def load_mesh_like_obj(path: Path) -> np.ndarray:
    return np.array([[float(x) for x in line.split()[1:4]] for line in path.read_text().splitlines()
                     if line.startswith("v ")])


def test_build_refuses_a_changed_original_and_a_changed_recipe(synthetic, capsys):
    manifest_path, originals, out = synthetic
    corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals), "--out", str(out),
                 "--record"])
    capsys.readouterr()
    data = json.loads(manifest_path.read_text())
    data["patches"][0]["recipe"]["target"] = 40  # another cut: its sha256 no longer matches
    manifest_path.write_text(json.dumps(data))
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "sphere_cap: FAILED: patch sha256" in err
    assert err.strip().splitlines()[-1].startswith("corpus: error: 1 of 1 patches failed")
    assert not (out / "sphere_cap.partial.ply").exists()
    original = originals / "someone+meshes" / "sphere.obj"
    original.write_text(original.read_text() + "# changed\n")
    assert corpus.main(["--manifest", str(manifest_path), "build", "--originals", str(originals),
                        "--out", str(out)]) == 1
    assert "has sha256" in capsys.readouterr().err


def test_download_offline_fails_with_one_line(synthetic, capsys, monkeypatch):
    manifest_path, _, out = synthetic
    # port 9 on loopback refuses the connection: the same path as a machine without internet
    monkeypatch.setattr(corpus, "RAW_URL", "http://127.0.0.1:9/{repo}/{commit}/{path}")
    assert corpus.main(["--manifest", str(manifest_path), "download", "--out", str(out), "--timeout", "5"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("corpus: error: cannot download http://127.0.0.1:9/")
    assert "this needs internet" in err[0]


@pytest.mark.parametrize("script, option", [("corpus_table.py", "--markdown"), ("corpus_table.py", "--json"),
                                            ("formats_on_corpus.py", "--json")])
def test_a_benchmark_refuses_an_output_it_cannot_write_before_its_runs(tmp_path, script, option):
    """A FIFO as the table's file: refused in one error line before any run (else the table would go into it after
    the runs), nothing written."""
    import os
    import subprocess

    os.mkfifo(tmp_path / "fifo")
    args = ["--render", str(tmp_path / "none.json")] if script == "corpus_table.py" else []
    ran = subprocess.run([sys.executable, str(REPO / "benchmarks" / script), *args, option, str(tmp_path / "fifo")],
                         capture_output=True, text=True, timeout=120)
    assert ran.returncode == 2, ran.stderr
    assert ran.stderr.strip().splitlines()[-1] == (f"{script}: error: {option} '{tmp_path / 'fifo'}' is a named pipe "
                                                   "(FIFO), not a regular file: springflat writes regular files only")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo"]
