"""The mesh: validation, topology, orientation and boundary crossings (the files: tests/sim/test_mesh_io.py)."""

import numpy as np
import pytest

from golden_model.builtin import builtin_mesh
from golden_model.graph import component_labels, count_components
from golden_model.mesh import (HoledMesh, Holes, InconsistentOrientation, Mesh, MeshError, boundary_crossings,
                               fill_holes, folded_faces, hole_triangles, orient_consistently, oriented_mesh,
                               turned_holes)
from sim.generate import grid_faces, grid_uv
from sim.mesh_io import load_mesh_with_notes, save_obj

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


@pytest.mark.parametrize("turned, guessed", [([3], False), (list(range(15)), False), (list(range(1, 31)), True),
                                             (list(range(30)), True), (list(range(1, 50, 2)), True)])
def test_oriented_mesh_turns_the_fewer_faces_and_says_how_many(turned, guessed):
    """Where nearly half the faces (20 or more of 50) face each way, which side is the front is a guess, and
    the pattern's files show the mesh from its front: the note says so."""
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
                     f"{len(faces) - expected} (the pattern's faces keep the turned winding)"
                     + ("; so nearly half face each way that which side is the front, the side the pattern shows, is "
                        "a guess: if it comes out mirrored, wind the faces the other way round" if guessed else "")]


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


def _crossing_pairs_by_hand(positions: np.ndarray, loops: list[np.ndarray]) -> int:
    """Every pair of sides of the closed polygons ``positions[loop]``, one by one: those that share no corner
    and meet."""
    def side(p, q, r):  # > 0: r left of pq
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    def on_segment(p, q, r):  # r, collinear with pq, within its box
        return min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1])

    sides = [(int(loop[k]), int(loop[(k + 1) % len(loop)])) for loop in loops for k in range(len(loop))]
    count = 0
    for i, (p, q) in enumerate(sides):
        for r, t in sides[i + 1:]:
            if {p, q} & {r, t}:
                continue
            a, b, c, d = positions[p], positions[q], positions[r], positions[t]
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
    assert boundary_crossings(bow_tie, [0, 1, 2, 3]) == 1  # one loop as a plain list
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
    assert boundary_crossings(positions, loop) == _crossing_pairs_by_hand(positions, [loop])


@pytest.mark.parametrize("seed", range(30))
def test_boundary_crossings_of_several_loops_count_the_pairs_a_pair_by_pair_test_finds(seed, monkeypatch):
    """An outer edge and holes, drawn at random (on a coarse grid every third seed): every pair of sides that
    meet, within a loop or between two, as a disk with holes has them."""
    import golden_model.mesh

    if seed % 2:
        monkeypatch.setattr(golden_model.mesh, "_CROSSING_CHUNK", 3)
    rng = np.random.default_rng(100 + seed)
    sizes = rng.integers(3, 12, size=int(rng.integers(2, 5)))
    positions = rng.normal(size=(int(sizes.sum()) + 2, 2))
    if seed % 3 == 0:
        positions = np.round(positions * 2) / 2
    order = rng.permutation(len(positions))[:int(sizes.sum())]  # the loops pick their rows out of a layout
    loops = np.split(order, np.cumsum(sizes)[:-1])
    assert boundary_crossings(positions, loops) == _crossing_pairs_by_hand(positions, loops)


def test_holes_inside_the_outer_edge_do_not_cross_it_and_one_moved_across_it_does():
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    hole = np.array([[1.0, 1.0], [1.0, 2.0], [2.0, 2.0], [2.0, 1.0]])  # clockwise, as a hole's edge runs
    positions = np.vstack([square, hole, hole + [1.5, 1.5]])
    outer, first, second = np.arange(4), np.arange(4, 8), np.arange(8, 12)
    assert boundary_crossings(positions, [outer, first]) == 0
    assert boundary_crossings(positions, [outer, first, second]) == 0  # (corner to corner apart: 0.5 gap)
    assert boundary_crossings(np.vstack([square, hole + [2.5, 0.0]]), [outer, first]) == 2  # over the right side
    assert boundary_crossings(np.vstack([square, hole, hole + [0.5, 0.5]]), [outer, first, second]) == 2


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


def _holed_grid(n: int = 9, cells=((2, 2), (5, 4))):
    """A bumpy n x n grid with the cells at ``cells`` (row, column) taken out: one hole each."""
    uv = grid_uv(n, n)
    vertices = np.column_stack([uv, 0.2 * (uv**2).sum(axis=1)])
    faces = grid_faces(n, n)
    holes = [{i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1} for i, j in cells]
    return vertices, faces[[not any(set(f) <= h for h in holes) for f in faces.tolist()]]


def test_a_mesh_with_holes_is_refused_as_one_the_fill_can_close():
    vertices, faces = _holed_grid()
    with pytest.raises(HoledMesh, match=r"^mesh is not a disk: it has 3 boundary loops where a disk has one"):
        Mesh(vertices, faces)


def _flat_area(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed areas of ``faces`` seen from above (x, y), counter-clockwise positive."""
    a, b, c = (points[faces[:, k], :2] for k in range(3))
    return ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0]) / 2


def test_filling_closes_each_hole_with_triangles_of_its_own_corners_after_the_meshs_faces():
    vertices, faces = _holed_grid()
    mesh, notes = oriented_mesh(vertices, faces, holes=Holes.FILL)
    m = len(faces)
    assert mesh.n_vertices == len(vertices) and mesh.n_faces == m + 4  # a square hole: two triangles
    np.testing.assert_array_equal(mesh.faces[:m], faces)
    assert _each_interior_edge_run_both_ways(mesh.faces)
    corners = {i * 9 + j + d for i, j in ((2, 2), (5, 4)) for d in (0, 1, 9, 10)}
    assert set(mesh.faces[m:].ravel().tolist()) == corners
    # seen from above the grid is flat and wound counter-clockwise: the fill covers the two cells, once
    fill = _flat_area(vertices, mesh.faces[m:])
    assert (fill > 0).all() and fill.sum() == pytest.approx(2 / 64)
    rounds = sorted(np.linalg.norm(np.diff(vertices[[a, a + 1, a + 10, a + 9, a]], axis=0), axis=1).sum()
                    for a in (2 * 9 + 2, 5 * 9 + 4))
    edge = np.linalg.norm(np.diff(vertices[np.r_[mesh.boundary_loop, mesh.boundary_loop[0]]], axis=0), axis=1).sum()
    assert notes == [f"2 holes closed by 4 triangles (edges {rounds[0]:.4g} to {rounds[1]:.4g} long, the piece's outer "
                     f"edge {edge:.4g}, in the mesh's units): the pattern covers them"]


def _grid_without(n: int, cells) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n grid (0 to 1) less the cells (row, column) given: one hole of their shape."""
    uv = grid_uv(n, n)
    faces = grid_faces(n, n)
    gone = [{i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1} for i, j in cells]
    return np.column_stack([uv, np.zeros(len(uv))]), faces[[not any(set(f) <= g for g in gone) for f in faces.tolist()]]


@pytest.mark.parametrize("shape, cells", [
    ("C", [(3, 3), (3, 4), (3, 5), (4, 3), (5, 3), (5, 4), (5, 5)]),
    ("L", [(2, 2), (3, 2), (4, 2), (5, 2), (5, 3), (5, 4)]),
    ("comb", [(1, c) for c in range(1, 8)] + [(r, c) for r in range(2, 7) for c in (1, 3, 5, 7)]),
])
def test_a_hole_of_any_shape_is_covered_once_and_the_outer_edge_kept(shape, cells):
    """The fill's triangles, seen from above, all turn the mesh's way and add up to the hole's area (a C or an L
    is no star about its centre); the comb's hole is longer than the piece's edge, which must stay open."""
    vertices, faces = _grid_without(10, cells)
    mesh, notes = oriented_mesh(vertices, faces, holes=Holes.FILL)
    fill = _flat_area(vertices, mesh.faces[len(faces):])
    assert (fill > 0).all() and fill.sum() == pytest.approx(len(cells) / 81)
    assert len(mesh.boundary_loop) == 36  # the square's edge, 4 x 9 sides
    assert (_flat_area(vertices, mesh.faces) > 0).all()


def test_holes_over_a_tenth_of_the_piece_are_said_to_be_maybe_cut_outs():
    cells = [(2, c) for c in range(1, 8)] + [(r, 1) for r in range(3, 8)]  # an L of 12 of the 81 cells
    vertices, faces = _grid_without(10, cells)
    notes = oriented_mesh(vertices, faces, holes=Holes.FILL)[1]
    assert notes[0].endswith(f"; it is {12 / 69:.0%} of the piece's area: a cut-out the piece must keep is no hole "
                             "to fill")  # of the 69 cells left


def test_filling_follows_the_turning_of_faces_wound_against_their_neighbours():
    vertices, faces = _holed_grid()
    given = faces.copy()
    given[::7] = given[::7][:, [0, 2, 1]]
    mesh, notes = oriented_mesh(vertices, given, holes=Holes.FILL)
    assert _each_interior_edge_run_both_ways(mesh.faces) and len(notes) == 2
    assert notes[0].endswith("(the pattern's faces keep the turned winding)") and "holes closed" in notes[1]


def test_a_tubes_narrower_end_is_the_hole():
    """A cone frustum open at both ends: two loops; the narrower end is filled, a cup."""
    k, rings = 16, 5
    angle = np.linspace(0, 2 * np.pi, k, endpoint=False)
    radius = np.linspace(1.0, 0.5, rings)
    vertices = np.array([[r * np.cos(a), r * np.sin(a), z] for z, r in enumerate(radius) for a in angle])
    faces = np.array([f for z in range(rings - 1) for i in range(k)
                      for f in ((z * k + i, z * k + (i + 1) % k, (z + 1) * k + i),
                                ((z + 1) * k + i, z * k + (i + 1) % k, (z + 1) * k + (i + 1) % k))])
    mesh, _ = oriented_mesh(vertices, faces, holes=Holes.FILL)
    assert set(mesh.faces[len(faces):].ravel().tolist()) == set(range((rings - 1) * k, rings * k))  # narrow end
    assert set(mesh.boundary_loop.tolist()) == set(range(k))  # the wide end is the edge


@pytest.mark.parametrize("holes", [Holes.FILL, Holes.KEEP])
def test_holes_in_a_mesh_with_a_handle_are_refused_as_handles_not_as_holes_to_fill(holes):
    """A torus with two cells taken out: two boundary loops, but closing them leaves a torus, no disk; the
    refusal says so at once instead of naming the fill."""
    k = 8
    angle = 2 * np.pi * np.arange(k) / k
    vertices = np.array([[(2 + np.cos(b)) * np.cos(a), (2 + np.cos(b)) * np.sin(a), np.sin(b)]
                         for a in angle for b in angle])
    cells = [(i, j) for i in range(k) for j in range(k) if (i, j) not in ((1, 1), (5, 4))]
    faces = np.array([f for i, j in cells for a, b, c, d in [(i * k + j, ((i + 1) % k) * k + j,
                                                                ((i + 1) % k) * k + (j + 1) % k, i * k + (j + 1) % k)]
                      for f in ((a, b, c), (a, c, d))])
    with pytest.raises(MeshError, match=r"^mesh is not a disk: it has 2 boundary loops where a disk has one "
                                        r"\(holes, or a tube's ends\), and handles \(Euler characteristic -2, "
                                        r"expected 0\)$") as info:
        oriented_mesh(vertices, faces, holes=holes)
    assert not isinstance(info.value, HoledMesh)



def test_a_sheet_rolled_nearly_shut_keeps_its_outer_edge_open():
    """A 10 x 10 grid rolled 330 degrees round with a slot of 5 cells: the rolled edge spans less vector area
    than a hole might, but its corners lie farther apart; the slot is filled."""
    vertices, faces = _grid_without(10, [(4, c) for c in range(2, 7)])
    angle = vertices[:, 0] * np.radians(330)
    rolled = np.column_stack([0.3 * np.cos(angle), 0.3 * np.sin(angle), vertices[:, 1]])
    mesh, _ = oriented_mesh(rolled, faces, holes=Holes.FILL)
    assert len(mesh.boundary_loop) == 36 and mesh.n_faces == len(faces) + 10  # a 12-corner slot: 10 triangles


def test_a_hole_that_encloses_no_area_is_refused_as_a_crack():
    """Three vertices of a slit (a T-junction's): no triangle can cover it."""
    vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [1, 1, 0], [1.5, 1, 0], [0.5, 1, 0]], float)
    loop = np.array([4, 5, 6])
    with pytest.raises(MeshError, match=r"^the hole whose edge runs through vertices .* cannot be filled: it "
                                        r"encloses no area \(a crack or a T-junction's slit\)$"):
        hole_triangles(vertices, loop)


def test_a_saddle_shaped_hole_is_filled_seen_along_its_normal():
    """A round hole whose edge rises and falls twice as much as it is wide: from the plane of largest spread it
    crosses itself; seen along its vector area's normal it is a circle."""
    theta = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    vertices = np.column_stack([np.cos(theta), np.sin(theta), 1.2 * np.cos(2 * theta)])
    triangles = hole_triangles(vertices, np.arange(40))
    assert triangles.shape == (38, 3) and _flat_area(vertices, triangles).sum() == pytest.approx(
        -0.5 * 40 * np.sin(2 * np.pi / 40))  # the loop run back: clockwise seen from above
    assert np.bincount(triangles.ravel()).max() < 15  # not a fan from one corner


def test_a_mesh_without_holes_is_left_as_it_is_by_the_fill():
    vertices, faces = _grid_without(5, [])
    filled_vertices, filled_faces, note = fill_holes(vertices, faces)
    assert note == "" and np.array_equal(filled_faces, faces) and np.array_equal(filled_vertices, vertices)


def test_a_disk_with_holes_is_a_mesh_where_asked_its_outer_edge_first_and_its_disk_closed():
    vertices, faces = _holed_grid()
    mesh = Mesh(vertices, faces, allow_holes=True)
    assert mesh.n_holes == 2 and [len(loop) for loop in mesh.boundary_loops] == [32, 4, 4]
    np.testing.assert_array_equal(mesh.boundary_loop, mesh.boundary_loops[0])
    outer, *holes = mesh.boundary_loops
    assert set(outer.tolist()) == {k for k in range(81) if k // 9 in (0, 8) or k % 9 in (0, 8)}
    flat = vertices[:, :2]  # seen from above, the faces counter-clockwise: the outer edge too, each hole's not
    twice_area = [np.sum(flat[loop, 0] * np.roll(flat[loop, 1], -1) - np.roll(flat[loop, 0], -1) * flat[loop, 1])
                  for loop in mesh.boundary_loops]
    assert twice_area[0] > 0 and all(area < 0 for area in twice_area[1:])
    assert {frozenset(hole.tolist()) for hole in holes} == {frozenset({20, 21, 29, 30}), frozenset({49, 50, 58, 59})}
    disk = mesh.disk
    assert disk.n_holes == 0 and disk.n_faces == len(faces) + 4 and disk.vertices is mesh.vertices
    np.testing.assert_array_equal(disk.faces[:len(faces)], faces)
    assert disk.disk is disk
    mesh_of_disk = Mesh(vertices, disk.faces, allow_holes=True)  # holes allowed, none there
    assert mesh_of_disk.n_holes == 0 and mesh_of_disk.disk is mesh_of_disk
    swap = np.arange(81)
    swap[[0, 20]] = [20, 0]  # a hole's corner is vertex 0: its loop is still not the outer edge
    renumbered = Mesh(vertices[swap], swap[faces], allow_holes=True)
    assert [len(loop) for loop in renumbered.boundary_loops] == [32, 4, 4] and 0 in renumbered.boundary_loops[1]


def test_kept_holes_are_said_with_their_edges_lengths():
    vertices, faces = _holed_grid()  # a hole a cell of 1/8 on a gentle bowl: a little over 0.5 round, the piece 4
    mesh, notes = oriented_mesh(vertices, faces, holes=Holes.KEEP)
    assert mesh.n_holes == 2 and mesh.n_faces == len(faces)
    assert notes == ["2 holes kept as cut-outs (edges 0.5039 to 0.5155 long, the piece's outer edge 4.104, in the "
                     "mesh's units); a computed start layout closes them first"]
    one = oriented_mesh(*_holed_grid(cells=((2, 2),)), holes=Holes.KEEP)[1]
    assert one == ["1 hole kept as cut-out (edge 0.5039 long, the piece's outer edge 4.104, in the mesh's units); a "
                   "computed start layout closes it first"]
    assert oriented_mesh(*_holed_grid(cells=()), holes=Holes.KEEP)[1] == []  # no hole, no note
    with pytest.raises(HoledMesh):
        oriented_mesh(vertices, faces)


def test_a_hole_whose_edge_runs_the_patterns_way_round_is_turned():
    vertices, faces = _holed_grid()
    mesh = Mesh(vertices, faces, allow_holes=True)
    flat = vertices[:, :2].copy()
    assert turned_holes(flat, faces, mesh.boundary_loops) == 0
    assert turned_holes(flat * [-1.0, 1.0], faces, mesh.boundary_loops) == 0  # mirrored: both the other way round
    hole = mesh.boundary_loops[1]
    flat[hole] = flat[hole][[1, 0, 3, 2]]  # the hole's corners swapped in pairs: its square walked the other way
    assert turned_holes(flat, faces, mesh.boundary_loops) == 1
    assert turned_holes(flat, faces, mesh.boundary_loops[:1]) == 0  # (the outer edge alone: no hole)


def test_a_layout_whose_hole_became_its_outer_edge_is_not_turned():
    """A flat ring laid out by z -> 1/z (orientation-preserving, one to one): its inner edge is the layout's
    outer edge and its outer edge a hole, the mesh's loops the other way round, and nothing overlaps."""
    rings, sectors = 6, 48
    radius = np.linspace(1.0, 2.0, rings)
    angle = 2 * np.pi * np.arange(sectors) / sectors
    z = (radius[:, None] * np.exp(1j * angle[None, :])).ravel()
    vertices = np.column_stack([z.real, z.imag, np.zeros(len(z))])
    faces = []
    for r in range(rings - 1):
        for k in range(sectors):
            a, b = r * sectors + k, r * sectors + (k + 1) % sectors
            faces += [(a, b, b + sectors), (a, b + sectors, a + sectors)]
    mesh = Mesh(vertices, np.array(faces), allow_holes=True)
    assert len(mesh.boundary_loop) == sectors and np.allclose(np.abs(z[mesh.boundary_loop]), 2.0)  # outer in 3D
    inverted = 1.0 / z
    layout = np.column_stack([inverted.real, inverted.imag])
    assert not folded_faces(layout, mesh.faces).any()
    assert boundary_crossings(layout, mesh.boundary_loops) == 0
    assert turned_holes(layout, mesh.faces, mesh.boundary_loops) == 0
    assert turned_holes(vertices[:, :2], mesh.faces, mesh.boundary_loops) == 0


def test_holes_meeting_at_a_corner_are_refused_saying_so():
    vertices, faces = _holed_grid(cells=((2, 2), (3, 3)))  # two cells out, corner to corner: vertex 30 pinched
    with pytest.raises(MeshError, match=r"^mesh is non-manifold at vertex 30 \(its triangles form more than one fan: "
                                        r"a pinch, or holes or the outer edge meeting at a corner\)$"):
        Mesh(vertices, faces, allow_holes=True)
