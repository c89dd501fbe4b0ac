"""Mesh files (``sim/mesh_io``): the OBJ, PLY, OFF and STL readers, the OBJ writer, and their one-line refusals."""

import math

import numpy as np
import pytest
import trimesh

from golden_model.mesh import Holes, Mesh, MeshError
from sim.generate import rolled_grid
from sim.mesh_io import load_mesh, load_mesh_with_notes, save_obj

SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])


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


def test_unparseable_and_unknown_files(tmp_path):
    garbage = tmp_path / "g.ply"
    garbage.write_bytes(b"ply\nformat nonsense\n\x00\x01")
    with pytest.raises(MeshError, match="cannot parse"):
        load_mesh(garbage)
    with pytest.raises(MeshError, match="unknown format"):
        load_mesh(tmp_path / "x.dae") if (tmp_path / "x.dae").write_text("x") else None
    with pytest.raises(MeshError, match="no such file"):
        load_mesh(tmp_path / "missing.obj")
    # a file named only '.OBJ' is a hidden file whose name has no suffix: say so, and how to name it
    (tmp_path / ".OBJ").write_text("v 0 0 0\n")
    with pytest.raises(MeshError, match=r"unknown format '' \(use .*\): the name '\.OBJ' has no stem \(name it, "
                                        r"for example, 'mesh\.obj'\)$"):
        load_mesh(tmp_path / ".OBJ")


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


@pytest.mark.parametrize("text, corners", [
    ("v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 0.2 0\nv 0 1 0\nf 1 2 3 4 5\n", 5),  # reflex at corner 4: the fan from corner 1
    ("v 0 0 0\nv 10 0 0\nv 3 3 0\nv 0 10 0\nf 2 3 4 1\n", 4),              # would fold (1, 3, 4); a concave quad;
    ("v 0 0 0\nv 10 0 0\nv 3 3 0\nv 0 10 0\nf 2 1 4 3\n", 4),              # the same, clockwise;
    ("v 0 0 0\nv 50 0 0\nv 100 0 0\nv 100 50 0\nv 0 50 0\nf 1 2 3 4 5\n", 5),  # a corner on a straight side
])
def test_an_obj_polygon_whose_fan_would_fold_is_ear_clipped(tmp_path, text, corners):
    """They were refused ('cannot be fan-triangulated from its first corner'): a modeller writes them."""
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, text))
    assert notes == [f"1 polygon ({corners} corners) triangulated into {corners - 2} triangles, not as fans from the "
                     f"first corner (line {corners + 1}): that fan would fold, have a sliver or give its corner too many "
                     "neighbours"]
    v = mesh.vertices[:, :2]
    areas = [np.cross(v[b] - v[a], v[c] - v[a]) / 2 for a, b, c in mesh.faces]
    polygon = v[[int(k) - 1 for k in text.split("f ")[1].split()]]
    shoelace = 0.5 * np.sum(polygon[:, 0] * np.roll(polygon[:, 1], -1) - np.roll(polygon[:, 0], -1) * polygon[:, 1])
    assert all(np.sign(a) == np.sign(shoelace) for a in areas) and np.isclose(sum(areas), shoelace)  # as the face


def test_a_polygon_fanned_and_one_ear_clipped_are_told_apart(tmp_path):
    text = ("v 0 0 0\nv 10 0 0\nv 3 3 0\nv 0 10 0\nv 20 0 0\nv 20 10 0\n"
            "f 2 3 4 1\nf 2 5 6 3\n")
    assert load_mesh_with_notes(_obj(tmp_path, text))[1] == [
        "2 polygons (4 corners) triangulated into 4 triangles as fans from the first corner, 1 otherwise (line 7): "
        "that fan would fold, have a sliver or give its corner too many neighbours"]


@pytest.mark.parametrize("bump, x", [(-1e-12, 0), (-1e-6, 0), (1e-6, 0), (1e-6, 1e7)])  # (1e7: far from the origin)
def test_a_corner_on_a_nearly_straight_side_is_fanned_from_a_corner_with_no_sliver(tmp_path, bump, x):
    """A CAD exporter's corner a hair off a straight side: the fan from the first corner had a triangle of zero
    area (refused as degenerate) or a sliver (the fixed-point weights then ran out of bits)."""
    text = f"v {x} 0 0\nv {x + 1} {bump} 0\nv {x + 2} 0 0\nv {x + 2} 2 0\nv {x} 2 0\nf 1 2 3 4 5\n"
    mesh = load_mesh(_obj(tmp_path, text))
    v = mesh.vertices[:, :2]
    (ab, ac) = (v[mesh.faces[:, 1]] - v[mesh.faces[:, 0]], v[mesh.faces[:, 2]] - v[mesh.faces[:, 0]])
    areas = (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0]) / 2
    assert np.isclose(areas.sum(), 4.0 - bump) and areas.min() > 0.5  # no sliver:
    assert (mesh.faces == 1).any(axis=1).all()  # the fan from the corner a hair off


def test_a_poor_fan_is_taken_from_the_corner_whose_smallest_triangle_is_largest():
    from sim.mesh_io.polygons import Polygons, poor_fans, refan

    vertices = np.array([[0, 0, 0], [1, 1e-6, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0],  # a hair off a straight side
                         [0, 0, 0], [3, 0, 0], [3, 1, 0], [0, 1, 0]], dtype=float)  # a plain quad
    polygons = Polygons(np.array([0, 1, 2, 3, 4, 5, 6, 7, 8]), np.array([5, 4]), lambda f: f"face {f}")
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [5, 6, 7], [5, 7, 8]])
    triangle_face = np.array([0, 0, 0, 1, 1])
    assert poor_fans(vertices, faces, triangle_face, polygons.sizes).tolist() == [0]  # (0, 1, 2): a sliver
    assert refan(vertices, polygons, np.array([0]), faces).tolist() == []  # nothing left to clip
    assert faces.tolist() == [[1, 2, 3], [1, 3, 4], [1, 4, 0], [5, 6, 7], [5, 7, 8]]


@pytest.mark.parametrize("corners", [12, 40])
def test_a_polygon_of_many_corners_gives_no_corner_many_neighbours(tmp_path, corners):
    """A 40-gon (a cylinder's cap) fanned gave its first corner 39 neighbours, more than the datapath takes."""
    angles = np.arange(corners) * 2 * np.pi / corners
    text = "".join(f"v {math.cos(a)} {math.sin(a)} {0.1 * math.cos(3 * a)}\n" for a in angles)
    mesh = load_mesh(_obj(tmp_path, text + "f " + " ".join(str(k + 1) for k in range(corners)) + "\n"))
    neighbours = np.bincount(mesh.edges.ravel()).max()
    assert len(mesh.faces) == corners - 2 and neighbours <= min(16, corners - 3)  # (the datapath takes 32)


@pytest.mark.parametrize("points, order", [
    ([(0, 0), (1, 0), (0, 1), (1, 1)], [1, 2, 3, 4]),  # a bow tie: no area
    # sides 2-3 and 4-5 cross, and ear clipping finds ears in it
    ([(0.82, 0.33), (-1.3, 0.91), (0.45, -0.54), (0.58, 0.36), (0.29, 0.03), (0.55, -0.74)], [1, 2, 3, 4, 5, 6]),
    ([(math.cos(a), math.sin(a)) for a in np.arange(5) * 2 * np.pi / 5 + 0.3], [1, 3, 5, 2, 4, 1, 3]),  # a pentagram
])
def test_an_obj_polygon_whose_edge_crosses_itself_is_refused(tmp_path, points, order):
    order = order[:len(points)]
    text = "".join(f"v {x} {y} 0\n" for x, y in points) + "f " + " ".join(map(str, order)) + "\n"
    if len(order) == 5:  # the pentagram's fan does not fold: make it one that must be clipped (a reflex corner)
        text = text.replace("f 1 3 5 2 4", "v 0.1 0 0\nf 6 1 3 5 2 4")
    with pytest.raises(MeshError, match=rf"polygon with {len(order) + (len(order) == 5)} corners cannot be "
                                        r"triangulated: its edge crosses itself or encloses no area, seen across it$"):
        load_mesh(_obj(tmp_path, text))


def test_a_corner_written_twice_in_a_row_is_read_once(tmp_path):
    """Exporters write a triangle as a quad with a corner repeated: it was refused as crossing itself."""
    mesh, notes = load_mesh_with_notes(_obj(tmp_path, UNIT_SQUARE_OBJ + "f 1 2 3 3\nf 1 3 4 1\n"))
    assert mesh.faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert notes == ["2 polygons wrote a corner twice in a row (first line 5), read once"]
    with pytest.raises(MeshError, match=r"line 5: face with 2 distinct corners \(a face needs at least 3\)$"):
        load_mesh(_obj(tmp_path, UNIT_SQUARE_OBJ + "f 1 2 2 1\nf 1 3 4\n"))


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
    # and what a scan's harmless defect needs: the tools that remove it
    with pytest.raises(MeshError, match=r"invalid mesh .*: vertex 4 is not used by any face \(file line 5\); remove "
                                        r"the unused vertices first \(trimesh's remove_unreferenced_vertices\(\), "
                                        r"MeshLab's Remove Unreferenced Vertices\)$"):
        load_mesh(_obj(tmp_path, UNIT_SQUARE_OBJ + "v 9 9 9\nf 1 2 3 4\n"))
    repeated = (r"invalid mesh .*: face 1 repeats a vertex \(degenerate triangle\) \(file line 6\); remove the faces "
                r"of zero area first \(trimesh's update_faces\(nondegenerate_faces\(\)\), MeshLab's Remove Zero Area "
                r"Faces\)$")
    with pytest.raises(MeshError, match=repeated):
        load_mesh(_obj(tmp_path, UNIT_SQUARE_OBJ + "f 1 2 3\nf 1 3 3\n"))
    with pytest.raises(MeshError, match=r"face 0 is duplicated .*; remove the duplicate faces first \(trimesh's "
                                        r"update_faces\(unique_faces\(\)\), MeshLab's Remove Duplicate Faces\)$"):
        load_mesh(_obj(tmp_path, UNIT_SQUARE_OBJ + "f 1 2 3\nf 1 3 4\nf 1 2 3\n"))
    import springflat

    with pytest.raises(MeshError, match=r"; remove the unused vertices first"):  # the API's arrays too
        springflat.flatten(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]]), [[0, 1, 2]])


@pytest.mark.parametrize("text, hint", [
    # two squares meeting at one corner: the validation's vertex 2 is the OBJ's third v, on line 3
    (UNIT_SQUARE_OBJ + "v 2 1 0\nv 2 2 0\nv 1 2 0\nf 1 2 3\nf 1 3 4\nf 3 5 6\nf 3 6 7\n",
     r"non-manifold at vertex 2 \(.*\) \(vertex 2: file line 3\)$"),
    # three faces on the edge from the second v to the third (lines 2, 3)
    (UNIT_SQUARE_OBJ + "v 2 0 0\nv 1 1 1\nf 1 2 3\nf 1 3 4\nf 2 5 3\nf 2 3 6\n",
     r"edge \(1, 2\) is shared by more than two faces \(its vertices: file lines 2 and 3\)$"),
    # two pieces, their faces from lines 5 and 11
    (UNIT_SQUARE_OBJ + "f 1 2 3\nf 1 3 4\no B\nv 5 0 0\nv 6 0 0\nv 5 1 0\nf 5 6 7\n",
     r"it has 2 connected components \(its pieces' faces start at file lines 5, 11: flatten each from a file of its "
     r"own\)$"),
])
def test_obj_validation_names_the_file_lines_of_what_it_refuses(tmp_path, text, hint):
    """A pinched vertex, an edge of three faces and a file of several pieces were named in the validation's
    numbers from 0 (an OBJ has no vertex 0) with no file line."""
    with pytest.raises(MeshError, match=r"^invalid mesh .*" + hint):
        load_mesh(_obj(tmp_path, text))


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


@pytest.mark.parametrize("binary", [False, True], ids=["ascii", "binary"])
def test_a_ply_with_other_lists_reads_the_faces_corners(tmp_path, binary):
    """MeshLab writes each face's corners' texture coordinates as a float list: every list was taken for
    indices ('element 'face' has an index 0.1 that is not an integer'), on any element."""
    import struct

    head = ("ply\nformat {} 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
            "property list uchar float weights\nelement face 2\nproperty list uchar int vertex_indices\n"
            "property list uchar float texcoord\nelement material 1\nproperty list uchar float colour\nend_header\n")
    square = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]
    faces = [(0, 1, 2), (0, 2, 3)]
    if binary:
        body = b"".join(struct.pack("<3fBf", *v, 1, 0.5) for v in square)
        body += b"".join(struct.pack("<B3iB6f", 3, *f, 6, .1, .2, .3, .4, .5, .6) for f in faces)
        data = head.format("binary_little_endian").encode() + body + struct.pack("<B2f", 2, 0.25, 0.75)
    else:
        data = (head.format("ascii") + "".join(f"{x} {y} {z} 1 0.5\n" for x, y, z in square)
                + "".join(f"3 {a} {b} {c} 6 0.1 0.2 0.3 0.4 0.5 0.6\n" for a, b, c in faces) + "2 0.25 0.75\n").encode()
    path = tmp_path / "m.ply"
    path.write_bytes(data)
    assert load_mesh(path).faces.tolist() == [[0, 1, 2], [0, 2, 3]]
    path.write_bytes(data.replace(b"3 0 2 3 6", b"3 0 2.5 3 6"))
    if not binary:  # the corners themselves are still checked
        with pytest.raises(MeshError, match=r"element 'face' has an index 2.5 that is not an integer"):
            load_mesh(path)


@pytest.mark.parametrize("name, text", [
    ("m.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
    ("m.stl", "solid s\n" + "  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n      vertex 1 0 0\n"
              "      vertex 0 1 0\n    endloop\n  endfacet\n" * 1 + "endsolid s\n"),
    ("M.STL", "SOLID S\n  FACET NORMAL 0 0 1\n    OUTER LOOP\n      VERTEX 0 0 0\n      VERTEX 1 0 0\n"
              "      VERTEX 0 1 0\n    ENDLOOP\n  ENDFACET\nENDSOLID S\n"),
])
def test_a_byte_order_mark_and_capitals_are_read_past(tmp_path, name, text):
    """OBJ and OFF read past a UTF-8 BOM; a text STL or PLY with one was 'not a PLY file' or, as a binary STL,
    a billion triangles; so was a text STL in capitals, which its grammar takes."""
    path = tmp_path / name
    path.write_bytes(b"\xef\xbb\xbf" + text.encode() + b" " * 80 * (name != "m.ply"))  # over 84 bytes, as any is
    assert load_mesh(path).faces.tolist() == [[0, 1, 2]]


def test_a_ply_without_faces_names_what_it_has(tmp_path):
    text = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            "element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    path = tmp_path / "m.ply"
    path.write_text(text)
    with pytest.raises(MeshError, match=r"no 'face' element, 3 vertices alone \(its 'tristrips' are not read: save "
                                        r"the faces as a 'face' element\)$"):
        load_mesh(path)


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
    ("OFF\n3 1 0\n0 0 0\n", r"declares 3 vertices and 1 face, the file has 1 line of them$"),
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


def _holed_obj(path):
    """A gently curved 100 mm square grid, 21 x 21 vertices, with two cells taken out: two holes."""
    from sim.generate import grid_faces, grid_uv

    n = 21
    uv = grid_uv(n, n, 100.0, 100.0)
    vertices = np.column_stack([uv, 10 * np.sin(uv[:, 0] / 30)])
    faces = grid_faces(n, n)
    holes = [{i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1} for i, j in ((5, 5), (12, 14))]
    save_obj(path, vertices, faces[[not any(set(f) <= h for h in holes) for f in faces.tolist()]])
    return len(vertices)


def test_a_mesh_file_with_holes_is_refused_as_holed_and_read_with_the_fill(tmp_path):
    from golden_model.mesh import HoledMesh

    n = _holed_obj(tmp_path / "holed.obj")
    with pytest.raises(HoledMesh, match=r"^invalid mesh '.*holed\.obj': mesh is not a disk: it has 3 boundary "
                                        r"loops where a disk has one \(holes, or a tube's ends\)$"):
        load_mesh(tmp_path / "holed.obj")  # (the command and the API add how to fill it: a study cannot)
    mesh, notes = load_mesh_with_notes(tmp_path / "holed.obj", holes=Holes.FILL)
    assert mesh.n_vertices == n and len(notes) == 1 and notes[0].startswith("2 holes closed by 4 triangles (")


def test_the_command_flattens_a_holed_scan_with_fill_holes_and_the_api_too(tmp_path):
    import subprocess
    import warnings

    import springflat
    from golden_model.mesh import folded_faces
    from support import SPRINGFLAT

    _holed_obj(tmp_path / "holed.obj")
    ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "holed.obj"), "--out", str(tmp_path / "p.flat.obj")],
                         capture_output=True, text=True)
    assert ran.returncode == 2 and ran.stderr.strip().endswith(
        "--fill-holes closes all but the outer edge, --keep-holes keeps them as cut-outs")
    ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "holed.obj"), "--fill-holes", "--json",
                          "--out", str(tmp_path / "p.flat.obj")], capture_output=True, text=True)
    assert ran.returncode == 0, ran.stderr
    assert "springflat: note: holed: 2 holes closed by 4 triangles (" in ran.stderr
    layout = load_mesh(tmp_path / "p.flat.obj")
    assert layout.n_vertices == 441 and not folded_faces(layout.vertices[:, :2], layout.faces).any()
    with pytest.raises(MeshError, match=r"fill_holes=True closes all but the outer edge, keep_holes=True keeps them as cut-outs$"):
        springflat.read_mesh(tmp_path / "holed.obj")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        V, F = springflat.read_mesh(tmp_path / "holed.obj", fill_holes=True)
    assert V.shape == (441, 3) and "2 holes closed" in str(said[0].message)
    V0, F0 = V, F[:-4]  # the file's own faces: its holes open again
    with pytest.raises(MeshError, match=r"fill_holes=True closes all but the outer edge, keep_holes=True keeps them as cut-outs$"):
        springflat.flatten(V0, F0)
    with pytest.warns(springflat.MeshNote, match=r"^mesh: 2 holes closed by 4 triangles \("):
        pattern = springflat.flatten(V0, F0, fill_holes=True, init=V0[:, :2])  # a layout of the file's vertices
    assert pattern.layout.shape == (441, 2) and pattern.folded == 0


def _split_at(rows: range, column: int = 3, n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """An ``n × n`` grid whose vertices ``(row, column)`` for ``rows`` are copied for the faces right of that
    column, as an exporter's seam leaves them: the same points, no edge between the copies."""
    from sim.generate import grid_faces, grid_uv

    vertices, faces = np.column_stack([grid_uv(n, n), np.zeros(n * n)]), grid_faces(n, n)
    right = vertices[faces].mean(axis=1)[:, 0] > vertices[column, 0]
    for row in rows:
        old = row * n + column
        copied = right & (faces == old).any(axis=1)
        faces[copied] = np.where(faces[copied] == old, len(vertices), faces[copied])
        vertices = np.vstack([vertices, vertices[old]])
    return vertices, faces


def test_a_seam_left_open_is_named_where_it_cuts_the_surface_and_where_it_breaks_the_disk(tmp_path, capsys):
    """A seam from the edge inwards is a slit: read, with a note naming the copies and how to weld them; an inner
    seam makes a hole, and a face-by-face file a heap of triangles: their refusals say that welding may help."""
    from sim.run_options import resolve_mesh

    vertices, faces = _split_at(range(0, 2))  # from the boundary row in: a slit, still a disk
    save_obj(tmp_path / "edge_seam.obj", vertices, faces)
    mesh, _ = resolve_mesh(str(tmp_path / "edge_seam.obj"), Holes.REFUSE)  # the commands' reader, with its notes
    said = capsys.readouterr().err.splitlines()
    assert mesh.n_vertices == 38 and [line for line in said if "on one another" in line] == [
        "springflat: note: edge_seam: 4 vertices lie on one another in 2 places with no edge between them: the surface "
        "is cut there (an exporter's seam, where texture coordinates or normals differ, leaves it so), and so is the "
        "pattern; if it is one piece there, weld them first (trimesh's merge_vertices, MeshLab's Merge Close Vertices)"]
    vertices, faces = _split_at(range(2, 4))  # rows 1 and 4 stay shared: a hole
    save_obj(tmp_path / "inner_seam.obj", vertices, faces)
    with pytest.raises(MeshError, match=r"2 boundary loops .*; 4 vertices lie on one another in 2 places with no "
                                        r"edge between them \(an exporter's seam\?\): weld them first \(trimesh's "
                                        r"merge_vertices, MeshLab's Merge Close Vertices\), and it may be one disk$"):
        load_mesh_with_notes(tmp_path / "inner_seam.obj")
    from sim.generate import grid_faces, grid_uv

    grid = np.column_stack([grid_uv(3, 3), np.zeros(9)])
    soup = grid[grid_faces(3, 3)].reshape(-1, 3)  # every triangle its own three corners: 24 at 9 points, of
    save_obj(tmp_path / "soup.obj", soup, np.arange(len(soup)).reshape(-1, 3))  # which two corners have one
    with pytest.raises(MeshError, match=r"8 connected components; 22 vertices lie on one another in 7 places"):
        load_mesh_with_notes(tmp_path / "soup.obj")
    noisy = soup + np.random.default_rng(1).normal(size=soup.shape) * 1e-6  # (a float32 file's rounding, say)
    save_obj(tmp_path / "noisy.obj", noisy, np.arange(len(soup)).reshape(-1, 3))  # each point's copies one place,
    with pytest.raises(MeshError, match=r"22 vertices lie on one another in 7 places"):  # not its nearest pairs
        load_mesh_with_notes(tmp_path / "noisy.obj")
    save_obj(tmp_path / "grid.obj", grid, grid_faces(3, 3))
    assert not [note for note in load_mesh_with_notes(tmp_path / "grid.obj")[1] if "on one another" in note]
    # two copies of a point joined by an edge (of a face of zero area) are no seam, and a point is no copy of
    # itself, wherever the KD-tree lists it among its neighbours at distance 0
    (tmp_path / "joined.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.2\nv 1 0 0\nf 1 2 3\nf 2 4 3\nf 1 5 2\n")
    with pytest.raises(MeshError, match=r"joined.obj': face 2 is degenerate \(zero area\) \(file line 8\); remove "
                                        r"the faces of zero area first \(trimesh's update_faces\(nondegenerate_faces"
                                        r"\(\)\), MeshLab's Remove Zero Area Faces\)$"):
        load_mesh_with_notes(tmp_path / "joined.obj")
