"""Mesh loading, validation and topology."""

import numpy as np
import pytest
import trimesh

from golden_model.builtin import builtin_mesh
from golden_model.mesh import (InconsistentOrientation, Mesh, MeshError, boundary_crossings, component_labels,
                               count_components, orient_consistently, oriented_mesh)
from sim.mesh_io import load_mesh, load_mesh_with_notes, save_obj
from sim.generate import grid_faces, grid_uv, rolled_grid

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
    "annulus": (*_annulus(), r"it has 2 boundary loops where a disk has one \(holes, or a tube's ends\)"),
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
    from sim.generate import generated_meshes
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


# --------------------------------------------------------------------------- OBJ reader

from sim.mesh_io import load_mesh_with_notes  # noqa: E402

UNIT_SQUARE_OBJ = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"


def _obj(tmp_path, text, name="m.obj"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_obj_negative_indices_with_texture_and_normals(tmp_path):
    # negative indices count back from the vertices (texture coordinates, normals) read so far
    text = (UNIT_SQUARE_OBJ + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
            "f -4/-4/-1 -3/-3/-1 -2/-2/-1\n"
            "f -4/-4/-1 -2/-2/-1 -1/-1/-1\n"
            "v 2 0 0\nv 2 1 0\nvt 1 0\nvt 1 1\n"
            "f -5/-2/-1 -2/-2/-1 -1/-1/-1\n"
            "f -5/-6/-1 -1/-1/-1 -4/-4/-1\n")
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]]
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]]
    assert notes == []


def test_obj_the_issue_face_with_negative_triples(tmp_path):
    # the issue's "f -18/-9/-6 -17/-8/-5 -16/-7/-4": 18 vertices, 9 texture coordinates, 6 normals before it
    text = ("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + "".join(f"v {i} {i * i % 7} {i % 3}\n" for i in range(15))
            + "vt 0 0\n" * 9 + "vn 0 0 1\n" * 6 + "f -18/-9/-6 -17/-8/-5 -16/-7/-4\n")
    with pytest.raises(MeshError, match=r"vertex 3 is not used by any face \(file line 4\)"):
        load_mesh(_obj(tmp_path, text))  # the face is read; the 15 unused vertices are the validation's business
    from sim.mesh_io import read_obj
    assert read_obj(_obj(tmp_path, text)).faces.tolist() == [[0, 1, 2]]


def test_obj_vertex_and_normal_form(tmp_path):
    text = UNIT_SQUARE_OBJ + "vn 0 0 1\nf 1//1 2//1 3//1\nf 1//1 3//1 -1//-1\n"
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and notes == []


def test_obj_vertex_and_texture_form(tmp_path):
    text = UNIT_SQUARE_OBJ + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and notes == []


def test_obj_mixed_corner_forms_in_one_file(tmp_path):
    text = UNIT_SQUARE_OBJ + "vt 0 0\nvn 0 0 1\nf 1 2/1 3//1\nf 1/1/1 3 4\n"
    assert load_mesh(_obj(tmp_path, text)).faces.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_obj_quads_and_pentagons_are_fan_triangulated(tmp_path):
    text = ("v 0 0 0\nv 2 0 0\nv 3 1.5 0\nv 1 2.5 0\nv -1 1.5 0\nv 4 0 0\nv 4.5 1.5 0\nv 3.5 3 0\n"
            "f 1 2 3 4 5\n"     # pentagon
            "f 2 6 7 3\n"       # quad
            "f 3 7 8\n")        # a triangle stays as it is
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [1, 5, 6], [1, 6, 2], [2, 6, 7]]
    assert notes == ["2 polygons (4 to 5 corners) fan-triangulated into 5 triangles"]
    quad, quad_notes = load_mesh_with_notes(_obj(tmp_path, UNIT_SQUARE_OBJ + "f 1 2 3 4\n", "q.obj"))
    assert quad.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert quad_notes == ["1 polygon (4 corners) fan-triangulated into 2 triangles"]


def test_obj_polygon_that_cannot_be_fanned_is_refused(tmp_path):
    # reflex at corner 4: the fan from corner 1 would fold triangle (1, 3, 4)
    text = "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 0.2 0\nv 0 1 0\nf 1 2 3 4 5\n"
    with pytest.raises(MeshError, match=r"line 6: polygon with 5 corners cannot be fan-triangulated") as info:
        load_mesh(_obj(tmp_path, text))
    assert "\n" not in str(info.value)


def test_obj_groups_and_objects_make_one_mesh(tmp_path):
    text = ("mtllib scene.mtl\no left\ng part1\nusemtl red\ns 1\n" + UNIT_SQUARE_OBJ + "f 1 2 3\n"
            "g part2\ns off\nf 1 3 4\n"
            "o right\ng part3\nusemtl blue\nv 2 0 0\nv 2 1 0\nf 2 5 6\nf 2 6 3\n")
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert mesh.n_vertices == 6
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]]
    assert notes == ["2 'o' objects and 3 'g' groups read as one mesh (OBJ numbers vertices across the whole file)"]


def test_obj_vertex_i_of_the_file_is_node_i(tmp_path):
    mesh, _ = rolled_grid(5, 4)
    perm = np.random.default_rng(7).permutation(mesh.n_vertices)
    inverse = np.argsort(perm)
    vertices, faces = mesh.vertices[perm], inverse[mesh.faces]
    # faces listed in scrambled order, each with its own texture coordinates (trimesh would split vertices)
    order = np.random.default_rng(8).permutation(len(faces))
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"vt {k / 100} 0" for k in range(3 * len(faces))]
    lines += [f"f {a + 1}/{3 * k + 1} {b + 1}/{3 * k + 2} {c + 1}/{3 * k + 3}"
              for k, (a, b, c) in enumerate(faces[order].tolist())]
    loaded = load_mesh(_obj(tmp_path, "\n".join(lines) + "\n"))
    assert loaded.vertices.tolist() == vertices.tolist()
    assert loaded.faces.tolist() == faces[order].tolist()


def test_obj_ignored_statements_are_noted(tmp_path):
    text = ("# a comment\n" + UNIT_SQUARE_OBJ.replace("v 1 1 0", "v 1 1 0 0.2 0.3 0.4")
            + "vp 0.5\nl 1 2 3\nl 3 4\np 1\nfoo bar\nbaz\nfoo\n"
            + "f 1 2 \\\n  3  # continued\nf 1 3 4\n")
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert mesh.vertices[2].tolist() == [1, 1, 0]
    assert notes == [
        "ignored 1 'vp' parameter-space vertex",
        "ignored 2 'l' line elements",
        "ignored 1 'p' point element",
        "ignored 3 unknown statements: 'foo' (2, first at line 10), 'baz' (1, first at line 11)",
        "ignored the extra values (weight w or colour r g b) of 1 'v' line",
    ]


OBJ_REFUSALS = {
    "index 0": (UNIT_SQUARE_OBJ + "f 1 2 3\nf 0 3 4\n",
                r"line 6: face vertex index 0 \(OBJ indices start at 1\)"),
    "negative too far back": (UNIT_SQUARE_OBJ + "f -1 -2 -5\n",
                              r"line 5: face refers to vertex -5 but only 4 vertices precede it"),
    "positive beyond the file": (UNIT_SQUARE_OBJ + "f 1 2 9\n",
                                 r"line 5: face refers to vertex 9 but the file has only 4 vertices"),
    "texture index 0": (UNIT_SQUARE_OBJ + "vt 0 0\nf 1/1 2/0 3/1\n",
                        r"line 6: face texture coordinate index 0 \(OBJ indices start at 1\)"),
    "normal out of range": (UNIT_SQUARE_OBJ + "vn 0 0 1\nf 1//1 2//2 3//1\n",
                            r"line 6: face refers to normal 2 but the file has only 1 normal"),
    "free-form type": ("v 0 0 0\nv 1 0 0\ncstype bspline\n",
                       r"line 3: free-form geometry \('cstype'\) is not supported"),
    "curv": ("v 0 0 0\nv 1 0 0\ncurv 0 1 1 2\n", r"line 3: free-form geometry \('curv'\) is not supported"),
    "two-corner face": (UNIT_SQUARE_OBJ + "f 1 2\n", r"line 5: face 'f' with 2 corners \(a face needs at least 3\)"),
    "bad number": ("v 0 0 0\nv 1 0.5.1 0\n", r"line 2: vertex coordinate '0.5.1' is not a number"),
    "two coordinates": ("v 0 0 0\nv 1 0\n", r"line 2: vertex 'v' with 2 coordinates \(needs x y z\)"),
    "bad corner": (UNIT_SQUARE_OBJ + "f 1 2 3/x\n", r"line 5: face corner '3/x' is not i, i/t, i//n or i/t/n"),
    "only lines": (UNIT_SQUARE_OBJ + "l 1 2 3 4 1\n",
                   r"no faces \('f'\), only line \('l'\) or point \('p'\) elements"),
}


@pytest.mark.parametrize("case", OBJ_REFUSALS)
def test_obj_refusals_name_the_construct(tmp_path, case):
    text, message = OBJ_REFUSALS[case]
    path = _obj(tmp_path, text, "x.obj")
    with pytest.raises(MeshError, match=r"^cannot parse mesh '.*x\.obj': " + message) as info:
        load_mesh(path)
    assert "\n" not in str(info.value)


def test_obj_validation_message_points_at_the_file_line(tmp_path):
    # the validation's own message, then the OBJ line it is about
    with pytest.raises(MeshError, match=r"invalid mesh .*: vertex 4 is not used by any face \(file line 5\)$"):
        load_mesh(_obj(tmp_path, UNIT_SQUARE_OBJ + "v 9 9 9\nf 1 2 3 4\n"))
    repeated = r"invalid mesh .*: face 1 repeats a vertex \(degenerate triangle\) \(file line 6\)$"
    with pytest.raises(MeshError, match=repeated):
        load_mesh(_obj(tmp_path, UNIT_SQUARE_OBJ + "f 1 2 3\nf 1 3 3\n"))


# --------------------------------------------------------------------------- PLY and OFF, ranges (issue 14)

PLY_V = np.array([[0, 0, 0], [2, 0, 0], [3, 1.5, 0], [1, 2.5, 0], [-1, 1.5, 0], [4, 0, 0], [4.5, 1.5, 0], [3.5, 3, 0]])


def _ply_binary_mixed(order: str) -> bytes:
    """Big- or little-endian PLY: an extra element before the faces, properties out of x y z order,
    a pentagon, a quad and a triangle with a per-face flag after each list."""
    import struct

    endian = {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    head = (f"ply\nformat {endian} 1.0\ncomment mixed\nelement vertex {len(PLY_V)}\n"
            "property float z\nproperty double x\nproperty uchar red\nproperty double y\n"
            "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
            "element face 3\nproperty list uchar uint vertex_index\nproperty uchar flags\nend_header\n").encode()
    body = b"".join(struct.pack(order + "fdBd", z, x, 7, y) for x, y, z in PLY_V.tolist())
    body += struct.pack(order + "ii", 0, 1)
    for face in ([0, 1, 2, 3, 4], [1, 5, 6, 2], [2, 6, 7]):
        body += struct.pack(f"{order}B{len(face)}IB", len(face), *face, 1)
    return head + body


@pytest.mark.parametrize("order", ["<", ">"])
def test_ply_binary_polygons_are_fanned_in_file_order(tmp_path, order):
    path = tmp_path / "m.ply"
    path.write_bytes(_ply_binary_mixed(order))
    mesh, notes = load_mesh_with_notes(path)
    assert mesh.vertices.tolist() == PLY_V.tolist()
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [1, 5, 6], [1, 6, 2], [2, 6, 7]]
    assert notes == ["2 polygons (4 to 5 corners) fan-triangulated into 5 triangles"]


def test_ply_ascii_with_tabs_crlf_and_mixed_faces(tmp_path):
    rows = ["ply", "format ascii 1.0", f"element vertex {len(PLY_V)}", "property double x", "property double y",
            "property double z", "element face 3", "property list uchar int vertex_indices", "end_header"]
    rows += ["\t".join(map(repr, v)) for v in PLY_V.tolist()] + ["5\t0 1 2 3 4", "4 1\t5 6 2", "3 2 6 7"]
    path = tmp_path / "m.ply"
    path.write_bytes("\r\n".join(rows).encode() + b"\r\n")
    mesh, notes = load_mesh_with_notes(path)
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [1, 5, 6], [1, 6, 2], [2, 6, 7]]
    assert notes == ["2 polygons (4 to 5 corners) fan-triangulated into 5 triangles"]


@pytest.mark.parametrize("text, message", [
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n",
     r"the file ends inside element 'face'"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
     "end_header\n0 zero 0\n", r"element 'vertex' has a value 'zero' that is not a number"),
    ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
     r"face 0: face refers to vertex 3, outside 0..2"),
    ("ply\nformat binary_middle_endian 1.0\nend_header\n", r"no 'format ascii\|binary"),
    ("ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", r"header line 4 'property quad x'"),
    ("OFF\n3 1\n0 0 0\n1 0 0\n", r"the file ends early"),
    ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", r"line 6: face with 2 corners"),
    ("OFF BINARY\n", r"binary OFF is not supported"),
    ("", r"the file is empty: no 'OFF' header, no vertices, no faces"),
    ("# a comment\n\n", r"the file is empty but for comments and blank lines: no 'OFF' header"),
    ("OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", r"line 4: vertex coordinate 'x' is not a number"),
])
def test_ply_and_off_refusals_are_one_line(tmp_path, text, message):
    path = tmp_path / ("m.ply" if text.startswith("ply") else "m.off")
    path.write_text(text)
    with pytest.raises(MeshError, match=r"^cannot parse mesh '.*': .*" + message) as info:
        load_mesh(path)
    assert "\n" not in str(info.value)


_STL_FACET = ("  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n      vertex 1 0 0\n      vertex 0 1 0\n"
              "    endloop\n  endfacet\n")


@pytest.mark.parametrize("text, message", [
    ("solid s\n" + _STL_FACET.replace("vertex 1 0 0", "vertex 1 abc 0") + "endsolid s\n",
     r"line 5: 'abc' is not a number$"),
    ("solid s\n" + _STL_FACET.replace("      vertex 0 1 0\n", "") + "endsolid s\n",
     r"line 6: expected 'vertex x y z' \(corner 3 of 3\), got 'endloop'$"),
    ("solid s\n" + _STL_FACET.replace("    endloop\n", "      vertex 1 1 0\n    endloop\n") + "endsolid s\n",
     r"line 7: expected 'endloop' after three vertices \(STL holds triangles\), got 'vertex 1 1 0'$"),
    ("solid s\n" + _STL_FACET + _STL_FACET[:47], r"line 11: expected 'vertex x y z' \(corner 1 of 3\), got 'verte', "
     r"the file's last line, cut short: truncated\?$"),
    ("solid s\n" + _STL_FACET + _STL_FACET[:55], r"the file ends inside facet 2 \(after line 11\): truncated\?$"),
    ("solid s\n  facet 0 0 1\n", r"line 2: expected 'facet normal nx ny nz' or 'endsolid', got 'facet 0 0 1'$"),
])
def test_text_stl_refusals_name_the_line(tmp_path, text, message):
    """A text STL is read line by line (sim.mesh_io.load.read_text_stl): a malformed or cut file is
    refused naming the line, not with a parser's internal message."""
    path = tmp_path / "m.stl"
    path.write_text(text)
    with pytest.raises(MeshError, match=r"^cannot parse mesh '.*': " + message) as info:
        load_mesh(path)
    assert "\n" not in str(info.value)


def test_a_text_stl_without_endsolid_is_read_with_a_note(tmp_path):
    path = tmp_path / "m.stl"
    path.write_text("solid s\n" + _STL_FACET + _STL_FACET.replace("vertex 0 0 0", "vertex 1 1 0"))
    mesh, notes = load_mesh_with_notes(path)
    assert (mesh.n_vertices, mesh.n_faces) == (4, 2)
    assert notes[0] == "no 'endsolid' after the last of 2 facets (line 15): the file may be truncated"


def test_off_variants(tmp_path):
    path = tmp_path / "m.off"
    path.write_text("COFF 4 2 0  # counts on the keyword's line\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n"
                    "1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n3 0 1 2 200 10 10\n3\t0 2 3\n")
    mesh, notes = load_mesh_with_notes(path)
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]] and notes == []


def test_coordinates_outside_the_range_are_refused_naming_it():
    with pytest.raises(MeshError, match=r"^vertex 2 has a coordinate of magnitude 1e\+51, outside the supported "
                                        r"range \|x\| <= 1e\+50$"):
        Mesh(np.where(np.arange(4)[:, None] == 2, -1e51, SQUARE_V), SQUARE_F)
    Mesh(SQUARE_V * 1e50, SQUARE_F)  # the limit itself is in range
    # the longest edge is the square's diagonal, 1.41e-150 (not its largest coordinate difference, 1e-150)
    with pytest.raises(MeshError, match=r"^mesh is too small: its longest edge is 1.41e-150 long, below the "
                                        r"supported 1e-50 .*underflow"):
        Mesh(SQUARE_V * 1e-150, SQUARE_F)
    Mesh(SQUARE_V * 1e-50, SQUARE_F)
    # the length decides, as the message says: a diagonal of 1.56e-50 whose coordinates differ by 9e-51
    Mesh(np.array([[0.0, 0.0, 0.0], [9e-51, 9e-51, 9e-51], [9e-51, 0.0, 0.0]]), np.array([[0, 1, 2]]))
    with pytest.raises(MeshError, match="degenerate"):  # all at one point: no size at all
        Mesh(SQUARE_V * 0, SQUARE_F)


def test_a_file_named_with_a_trailing_slash_is_not_read(tmp_path):
    """``scan.obj/`` names no file (the OS says "not a directory"); pathlib drops the slash, and the file was
    read as if it had been named without it."""
    from sim.layouts import LayoutError, load_layout
    from sim.mesh_io import read_obj

    square = tmp_path / "square.obj"
    square.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n")
    load_mesh(str(square))
    with pytest.raises(MeshError, match=r"^cannot read mesh '.*square\.obj/': not a directory$"):
        load_mesh(f"{square}/")
    with pytest.raises(MeshError, match=r"^cannot read mesh '.*square\.obj/': not a directory$"):
        read_obj(f"{square}/")
    with pytest.raises(LayoutError, match=r"^cannot read layout '.*square\.obj/': not a directory$"):
        load_layout(f"{square}/", 4)


def test_an_unreadable_mesh_is_one_line(tmp_path):
    (tmp_path / "d.obj").mkdir()
    with pytest.raises(MeshError, match=r"^cannot read mesh '.*d\.obj': is a directory$"):
        load_mesh(tmp_path / "d.obj")
    with pytest.raises(MeshError, match=r"^cannot read mesh '.*': file name too long$"):
        load_mesh(tmp_path / ("n" * 300 + ".obj"))
    with pytest.raises(MeshError, match=r"^cannot read mesh '.*nope\.ply': no such file$"):
        load_mesh(tmp_path / "nope.ply")


def _grid(n: int = 6):
    uv = grid_uv(n, n)
    return np.column_stack([uv, 0.3 * (uv**2).sum(axis=1)]), grid_faces(n, n)


def _each_interior_edge_run_both_ways(faces: np.ndarray) -> bool:
    """Counted here from the directed sides, not with the module's helpers: a consistently wound disk
    has no directed edge twice."""
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    return len(np.unique(directed, axis=0)) == len(directed)


def _mobius(n: int = 12):
    vertices, faces = [], []
    for i in range(n):
        a = 2 * np.pi * i / n
        for w in (-0.3, 0.3):
            vertices.append([(1 + w * np.cos(a / 2)) * np.cos(a), (1 + w * np.cos(a / 2)) * np.sin(a), w * np.sin(a / 2)])
    for i in range(n):
        a0, a1 = 2 * i, 2 * i + 1
        b0, b1 = (2 * i + 2, 2 * i + 3) if i < n - 1 else (1, 0)  # the half twist: the strip's sides swap
        faces += [[a0, b0, b1], [a0, b1, a1]]
    return np.array(vertices), np.array(faces)


def test_faces_wound_against_their_neighbours_are_refused_naming_them():
    vertices, faces = _grid()
    assert _each_interior_edge_run_both_ways(faces)
    faces[3] = faces[3][[0, 2, 1]]
    assert not _each_interior_edge_run_both_ways(faces)
    with pytest.raises(InconsistentOrientation, match=r"faces (3 and \d+|\d+ and 3) run through their shared edge") as info:
        Mesh(vertices, faces)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("turned", [[3], list(range(1, 31)), list(range(30)), list(range(1, 50, 2))])
def test_oriented_mesh_turns_the_fewer_faces_and_says_how_many(turned):
    vertices, faces = _grid()
    given = faces.copy()
    given[turned] = given[turned][:, [0, 2, 1]]
    mesh, notes = oriented_mesh(vertices, given)
    assert _each_interior_edge_run_both_ways(mesh.faces)
    expected = min(len(turned), len(faces) - len(turned))
    assert (mesh.faces != given).any(axis=1).sum() == expected  # the fewer faces turned, the others as given
    assert np.array_equal(np.sort(mesh.faces, axis=1), np.sort(given, axis=1))  # the same triangles
    assert notes == [f"{expected} face{'s' if expected != 1 else ''} wound against "
                     f"{'their' if expected != 1 else 'its'} neighbours: turned to agree with the other "
                     f"{len(faces) - expected} (the pattern's faces keep the turned winding)"]


def test_a_consistent_mesh_is_left_as_it_is():
    vertices, faces = _grid()
    mesh, notes = oriented_mesh(vertices, faces)
    assert notes == [] and np.array_equal(mesh.faces, faces)


def test_a_mobius_strip_is_refused_as_not_orientable():
    vertices, faces = _mobius()
    with pytest.raises(MeshError, match="not orientable"):
        oriented_mesh(vertices, faces)


def test_a_file_with_a_turned_face_loads_wound_consistently_with_a_note(tmp_path):
    vertices, faces = _grid()
    faces[7] = faces[7][[0, 2, 1]]
    save_obj(tmp_path / "turned.obj", vertices, faces)
    mesh, notes = load_mesh_with_notes(tmp_path / "turned.obj")
    assert _each_interior_edge_run_both_ways(mesh.faces)
    assert notes == ["1 face wound against its neighbours: turned to agree with the other 49 (the pattern's faces "
                     "keep the turned winding)"]


# --------------------------------------------------------------------------- boundary crossings


def _crossing_pairs_by_hand(polygon: np.ndarray) -> int:
    """Every pair of sides of the closed polygon, one by one: those that are not neighbours and meet."""
    def side(p, q, r):  # > 0: r left of pq
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    def on_segment(p, q, r):  # r, collinear with pq, within its box
        return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])

    n, count = len(polygon), 0
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            a, b, c, d = polygon[i], polygon[(i + 1) % n], polygon[j], polygon[(j + 1) % n]
            d1, d2, d3, d4 = side(a, b, c), side(a, b, d), side(c, d, a), side(c, d, b)
            if ((d1 > 0 > d2 or d1 < 0 < d2) and (d3 > 0 > d4 or d3 < 0 < d4)) \
                    or (d1 == 0 and on_segment(a, b, c)) or (d2 == 0 and on_segment(a, b, d)) \
                    or (d3 == 0 and on_segment(c, d, a)) or (d4 == 0 and on_segment(c, d, b)):
                count += 1
    return count


def test_boundary_crossings_of_simple_and_self_crossing_loops():
    angle = np.linspace(0.0, 2 * np.pi, 2001)[:-1]
    circle = np.c_[np.cos(angle), np.sin(angle)]
    assert boundary_crossings(circle, np.arange(len(circle))) == 0
    bow_tie = np.array([[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]])  # its two long sides cross once
    assert boundary_crossings(bow_tie, np.arange(4)) == 1
    assert boundary_crossings(bow_tie, np.array([0, 2, 1, 3])) == 0  # the same corners, walked round
    # a loop that goes round twice: each side of the first turn crosses the second turn's near sides
    twice = np.c_[np.cos(2 * angle), np.sin(2 * angle)] * (1 + 0.1 * angle)[:, None]
    assert boundary_crossings(twice, np.arange(len(twice))) >= 1


@pytest.mark.parametrize("seed", range(40))
def test_boundary_crossings_count_the_pairs_a_pair_by_pair_test_finds(seed, monkeypatch):
    """Random polygons, on a coarse grid every third seed (collinear sides and shared points); odd seeds
    test the candidate pairs a few at a time, as a long boundary is."""
    import golden_model.mesh

    if seed % 2:
        monkeypatch.setattr(golden_model.mesh, "_CROSSING_CHUNK", 3)
    rng = np.random.default_rng(seed)
    polygon = rng.normal(size=(int(rng.integers(4, 30)), 2))
    if seed % 3 == 0:
        polygon = np.round(polygon * 2) / 2
    positions = np.vstack([rng.normal(size=(3, 2)), polygon])  # the loop picks its rows out of a layout
    loop = np.arange(3, len(positions))
    assert boundary_crossings(positions, loop) == _crossing_pairs_by_hand(polygon)


@pytest.mark.parametrize("seed", range(6))
def test_component_labels_give_scipys_components(seed):
    """The numpy components against scipy's, on random sparse graphs and a randomly numbered chain (the
    longest span for the hooking)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(seed)
    n = 400
    if seed == 0:
        order = rng.permutation(n)
        a, b = order[:-1], order[1:]
    else:
        a, b = rng.integers(0, n, (2, int(rng.integers(0, 500))))
    count, theirs = connected_components(coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)), directed=False)
    labels = component_labels(n, a, b)
    assert count_components(n, a, b) == count == len(np.unique(labels))
    assert len(np.unique(np.column_stack([labels, theirs]), axis=0)) == count  # the same partition
    assert all(labels[i] == np.flatnonzero(labels == labels[i]).min() for i in range(n))  # each part's smallest node


def test_a_long_strip_wound_at_random_is_wound_consistently():
    """A 3 x 10,001 strip (diameter 10,000 faces, where a breadth-first front takes as many steps) with a third
    of its faces turned: every interior edge run both ways after, the fewer faces turned."""
    faces = grid_faces(3, 10001)
    given = faces.copy()
    turned = np.random.default_rng(3).random(len(faces)) < 0.3
    given[turned] = given[turned][:, [0, 2, 1]]
    result, count = orient_consistently(given)
    assert _each_interior_edge_run_both_ways(result)
    assert count == min(turned.sum(), len(faces) - turned.sum())
