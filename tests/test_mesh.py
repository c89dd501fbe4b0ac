"""Mesh loading, validation and topology."""

import numpy as np
import pytest
import trimesh

from golden_model.builtin import builtin_mesh
from golden_model.mesh import Mesh, MeshError, load_mesh, save_obj
from golden_model.generate import grid_faces, grid_uv, rolled_grid

SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])


def test_topology_of_square():
    mesh = Mesh(SQUARE_V, SQUARE_F)
    assert mesh.edges.tolist() == [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    assert mesh.rest_lengths == pytest.approx([1, np.sqrt(2), 1, 1, 1])
    assert mesh.face_areas == pytest.approx([0.5, 0.5])
    assert mesh.boundary_loop.tolist() == [0, 1, 2, 3]
    indptr, indices, edge_ids = mesh.neighbours
    assert indptr.tolist() == [0, 3, 5, 8, 10]
    assert indices.tolist() == [1, 2, 3, 0, 2, 0, 1, 3, 0, 2]
    # every CSR entry points at the edge joining the two nodes
    node = np.repeat(np.arange(4), np.diff(indptr))
    assert np.sort(np.column_stack([node, indices]), axis=1).tolist() == mesh.edges[edge_ids].tolist()


def test_masses_hand_computed():
    mesh = Mesh(SQUARE_V, SQUARE_F)
    # rho/3 times the incident areas: nodes 0 and 2 touch both triangles
    assert mesh.masses(2.0) == pytest.approx([2 / 3, 1 / 3, 2 / 3, 1 / 3])
    assert mesh.auto_density() == pytest.approx(6.0)  # 1 / min(m at rho = 1) = 1 / (1/6)


def test_builtins_are_the_papers_meshes():
    surf1, p1 = builtin_mesh("surf1")
    surf2, p2 = builtin_mesh("surf2")
    assert (surf1.n_vertices, surf1.n_faces) == (7, 7)
    assert (surf2.n_vertices, surf2.n_faces) == (15, 24)
    # paper appendix, 1-based: Surf1 face 1 is (6 5 2), Surf2's last is (1 5 9)
    assert surf1.faces[0].tolist() == [5, 4, 1]
    assert surf2.faces[-1].tolist() == [0, 4, 8]
    assert (p1.tol_area, p1.tol_shape, p1.max_iter) == (0.16, 0.40, 100)
    assert (p2.tol_area, p2.tol_shape, p2.max_iter) == (0.30, 0.25, 150)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".off", ".stl"])
def test_load_keeps_vertex_order(tmp_path, suffix):
    mesh, _ = rolled_grid(5, 4)
    # shuffle the vertex numbering so that file order is not sorted in any way
    perm = np.random.default_rng(1).permutation(mesh.n_vertices)
    inverse = np.argsort(perm)
    vertices, faces = mesh.vertices[perm], inverse[mesh.faces]
    path = tmp_path / f"m{suffix}"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    loaded = load_mesh(path)
    if suffix == ".stl":  # STL has no shared vertices: numbered by first appearance
        first = list(dict.fromkeys(faces.ravel().tolist()))
        vertices = vertices[first]
        faces = np.argsort(first)[faces]
    assert np.allclose(loaded.vertices, vertices, atol=1e-6)
    assert loaded.faces.tolist() == faces.tolist()


def test_save_obj_round_trip(tmp_path):
    mesh = Mesh(SQUARE_V, SQUARE_F)
    save_obj(tmp_path / "s.obj", SQUARE_V[:, :2] * 3, SQUARE_F)
    loaded = load_mesh(tmp_path / "s.obj")
    assert loaded.vertices.tolist() == (np.column_stack([SQUARE_V[:, :2] * 3, np.zeros(4)])).tolist()
    assert loaded.faces.tolist() == mesh.faces.tolist()


def _annulus():
    uv = grid_uv(4, 4)
    faces = grid_faces(4, 4)
    centre = {5, 6, 9, 10}
    # drop the middle cell's two triangles: a hole
    keep = [f for f in faces.tolist() if not set(f) <= centre]
    return np.column_stack([uv, np.zeros(16)]), np.array(keep)


BAD_MESHES = {
    "empty": (np.zeros((0, 3)), np.zeros((0, 3), dtype=int), "empty"),
    "non-finite": (np.array([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]]), np.array([[0, 1, 2]]), "non-finite"),
    "out of range": (SQUARE_V, np.array([[0, 1, 2], [0, 2, 7]]), "out of range"),
    "repeated vertex": (SQUARE_V, np.array([[0, 1, 2], [0, 2, 2]]), "repeats a vertex"),
    "degenerate": (np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float),
                   np.array([[0, 1, 2], [0, 2, 3]]), "degenerate"),
    "duplicate": (SQUARE_V, np.array([[0, 1, 2], [0, 2, 3], [2, 0, 1]]), "duplicated"),
    "unused vertex": (np.vstack([SQUARE_V, [[5, 5, 5]]]), SQUARE_F, "not used"),
    "non-manifold edge": (np.vstack([SQUARE_V, [[0.5, 0.5, 1]]]), np.array([[0, 1, 2], [0, 2, 3], [0, 2, 4]]),
                          "non-manifold"),
    "bowtie": (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float),
               np.array([[0, 1, 2], [0, 3, 4]]), "non-manifold at vertex 0"),
    "two components": (np.vstack([SQUARE_V, SQUARE_V + 5]), np.vstack([SQUARE_F, SQUARE_F + 4]),
                       "2 connected components"),
    "closed": (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float),
               np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]), "closed"),
    "annulus": (*_annulus(), "2 boundary loops"),
}


@pytest.mark.parametrize("case", BAD_MESHES)
def test_bad_meshes_are_refused(case):
    vertices, faces, message = BAD_MESHES[case]
    with pytest.raises(MeshError, match=message) as info:
        Mesh(vertices, faces)
    assert "\n" not in str(info.value)


def test_handle_is_refused():
    # a torus with one hole: one boundary loop but Euler characteristic -1
    n = 6
    idx = np.arange(n * n).reshape(n, n)
    faces = []
    for r in range(n):
        for c in range(n):
            a, b, cc, d = idx[r, c], idx[r, (c + 1) % n], idx[(r + 1) % n, c], idx[(r + 1) % n, (c + 1) % n]
            if (r, c) != (0, 0):
                faces += [[a, b, d], [a, d, cc]]
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, n, endpoint=False), np.linspace(0, 2 * np.pi, n, endpoint=False))
    x = (2 + np.cos(v)) * np.cos(u)
    y = (2 + np.cos(v)) * np.sin(u)
    vertices = np.column_stack([x.ravel(), y.ravel(), np.sin(v).ravel()])
    with pytest.raises(MeshError, match="Euler characteristic -1"):
        Mesh(vertices, np.array(faces))


def test_unparseable_and_unknown_files(tmp_path):
    garbage = tmp_path / "g.ply"
    garbage.write_bytes(b"ply\nformat nonsense\n\x00\x01")
    with pytest.raises(MeshError, match="cannot parse"):
        load_mesh(garbage)
    with pytest.raises(MeshError, match="unknown format"):
        load_mesh(tmp_path / "x.dae") if (tmp_path / "x.dae").write_text("x") else None
    with pytest.raises(MeshError, match="no such file"):
        load_mesh(tmp_path / "missing.obj")


def test_rings_are_cyclic_fans_in_the_mesh_winding():
    from golden_model.generate import generated_meshes
    for mesh in list(generated_meshes().values())[:3]:
        rings = mesh.rings
        indptr, neighbours, _ = mesh.neighbours
        assert np.array_equal(rings.indptr, indptr)
        owner = np.repeat(np.arange(mesh.n_vertices), np.diff(indptr))
        for i in range(mesh.n_vertices):
            lo, hi = indptr[i], indptr[i + 1]
            assert sorted(rings.neighbour[lo:hi]) == sorted(neighbours[lo:hi])
            assert np.array_equal(rings.next_neighbour[lo:hi], np.roll(rings.neighbour[lo:hi], -1))
        tri = rings.face >= 0
        # every face appears once per corner, wound as in the mesh
        assert np.bincount(rings.face[tri], minlength=mesh.n_faces).tolist() == [3] * mesh.n_faces
        wound = np.column_stack([owner[tri], rings.neighbour[tri], rings.next_neighbour[tri]])
        faces = mesh.faces[rings.face[tri]]
        assert all(tuple(w) in {tuple(np.roll(f, k)) for k in range(3)} for w, f in zip(wound, faces))
        boundary = np.zeros(mesh.n_vertices, bool)
        boundary[mesh.boundary_loop] = True
        assert np.array_equal(np.bincount(owner[~tri], minlength=mesh.n_vertices), boundary.astype(int))
        assert np.array_equal(mesh.rest_lengths[rings.edge_id],
                              np.linalg.norm(mesh.vertices[owner] - mesh.vertices[rings.neighbour], axis=1))


def test_folded_faces_counts_against_the_whole_pattern():
    from golden_model.mesh import folded_faces, layout_orientation
    mesh = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float), np.array([[0, 1, 2], [1, 3, 2]]))
    flat = mesh.vertices[:, :2]
    assert layout_orientation(flat, mesh.faces) == 1 and not folded_faces(flat, mesh.faces).any()
    mirrored = flat * [-1, 1]
    assert layout_orientation(mirrored, mesh.faces) == -1 and not folded_faces(mirrored, mesh.faces).any()
    folded = flat.copy()
    folded[3] = [0.2, 0.2]  # vertex 3 pulled across edge (1, 2)
    assert folded_faces(folded, mesh.faces).tolist() == [False, True]
