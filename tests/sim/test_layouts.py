"""Initial layouts: tutte, pca, the libigl maps (harmonic, lscm, arap) and user files."""

import math
import re

import igl
import numpy as np
import pytest

from golden_model.builtin import builtin_mesh
from golden_model.mesh import Mesh, folded_faces, signed_areas_2d
from sim.generate import delaunay_patch, dome_grid, grid_faces, grid_uv, rolled_grid, saddle_grid, spherical_cap
from sim.layouts import (
    LAYOUT_METHODS,
    LayoutError,
    arap_layout,
    harmonic_layout,
    initial_layout,
    load_layout,
    lscm_layout,
    pca_layout,
    slim_layout,
    start_layout,
    tutte_layout,
)
from support import SCANS


def test_tutte_boundary_circle_and_barycentric_interior():
    mesh = dome_grid(7)
    p = tutte_layout(mesh)
    loop = mesh.boundary_loop
    chords = np.linalg.norm(mesh.vertices[np.roll(loop, -1)] - mesh.vertices[loop], axis=1)
    radius = np.linalg.norm(p[loop], axis=1)
    assert radius == pytest.approx(np.full(len(loop), chords.sum() / (2 * math.pi)))
    # arc-length placement: consecutive boundary angles proportional to 3D chords
    angles = np.unwrap(np.arctan2(p[loop, 1], p[loop, 0]))
    steps = np.abs(np.diff(np.r_[angles, angles[0] + np.sign(angles[1] - angles[0]) * 2 * math.pi]))
    assert steps == pytest.approx(2 * math.pi * chords / chords.sum())
    interior = np.setdiff1d(np.arange(mesh.n_vertices), loop)
    indptr, nbr, _ = mesh.neighbours
    for i in interior:
        assert p[i] == pytest.approx(p[nbr[indptr[i]:indptr[i + 1]]].mean(axis=0))
    assert (signed_areas_2d(p, mesh.faces) > 0).all()  # Tutte: an embedding, counter-clockwise


def test_pca_is_isometric_for_a_planar_mesh():
    rng = np.random.default_rng(3)
    uv = grid_uv(5, 4, 2.0, 1.0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    vertices = np.column_stack([uv, np.zeros(len(uv))]) @ q.T + [1, 2, 3]
    mesh = Mesh(vertices, grid_faces(5, 4))
    p = pca_layout(mesh)
    assert p.mean(axis=0) == pytest.approx([0, 0], abs=1e-12)
    i, j = mesh.edges.T
    assert np.linalg.norm(p[i] - p[j], axis=1) == pytest.approx(mesh.rest_lengths)


def test_pca_is_deterministic_and_counter_clockwise():
    mesh, _ = builtin_mesh("surf2")
    p = pca_layout(mesh)
    assert np.array_equal(p, pca_layout(Mesh(mesh.vertices.copy(), mesh.faces.copy())))
    assert np.sum(signed_areas_2d(p, mesh.faces) > 0) > mesh.n_faces / 2


def test_layout_files(tmp_path):
    mesh, _ = builtin_mesh("surf1")
    expected = np.arange(14, dtype=float).reshape(7, 2) / 10
    (tmp_path / "a.txt").write_text("\n".join(f"{x} {y}" for x, y in expected) + "\n")
    (tmp_path / "b.csv").write_text("# x,y\n" + "\n".join(f"{x},{y}" for x, y in expected))
    (tmp_path / "c.obj").write_text("".join(f"v {x} {y} 0\n" for x, y in expected) + "f 1 2 3\n")
    for name in ("a.txt", "b.csv", "c.obj"):
        assert np.array_equal(load_layout(tmp_path / name, 7), expected)


def test_a_given_start_is_brought_to_the_meshs_size_with_a_note_where_that_scales_it_much(tmp_path):
    """A texture layout in [0, 1] of a mesh in millimetres: the guarded dynamics never grows a triangle through
    zero area and its steps are local, so from 1/100 of the size it stalled with a star-shaped pattern, said
    'converged'. A given start that far off is scaled to the mesh's size (its edge lengths fitted to the 3D
    ones); a pattern from an earlier run is at that size, and one within SIZE_TOLERANCE is taken as it is."""
    import springflat
    from sim.layouts import SIZE_TOLERANCE

    mesh = dome_grid(8)
    finished = springflat.flatten(mesh.vertices, mesh.faces, init="tutte")
    for scale, said in ((0.01, "is 0.01 times the mesh's size (another length unit?): scaled by 100 to it"),
                        (1e16, "is 1e+16 times the mesh's size"), (0.97 * SIZE_TOLERANCE, None), (1.0, None)):
        notes: list[str] = []
        start = initial_layout(mesh, finished.layout * scale, notes)
        if said is None:
            assert np.array_equal(start, finished.layout * scale) and notes == []
        else:  # back at the size of the pattern, a minimum of the springs' energy
            np.testing.assert_allclose(start, finished.layout, rtol=1e-3, atol=1e-9)
            assert notes == [AnyStringWith(said)], notes
    for scale in (0.01, 1e16):
        again = springflat.flatten(mesh.vertices, mesh.faces, init=finished.layout * scale)
        assert again.folded == 0 and again.shape_error <= finished.shape_error * 1.01


class AnyStringWith(str):
    def __eq__(self, other):
        return isinstance(other, str) and str(self) in other

    __hash__ = str.__hash__


def test_an_obj_layout_of_texture_coordinates_alone_says_vt_is_not_read(tmp_path):
    """(It said the layout had 0 rows.)"""
    (tmp_path / "uv.obj").write_text("".join(f"vt {k / 10} {k / 20}\n" for k in range(7)))
    with pytest.raises(LayoutError, match=r"holds texture coordinates \(vt\) but no vertices \(v\): --init reads an "
                                          r"OBJ's v lines"):
        load_layout(tmp_path / "uv.obj", 7)


@pytest.mark.parametrize("text, message", [
    ("0 0\n1 1\n", "has 2 rows but the mesh has 7"),
    ("0 0 0\n" * 7, "expected 2"),
    ("0 0\n" * 6 + "nan 0\n", "non-finite"),
    ("0 0\n" * 6 + "x y\n", "cannot parse"),
])
def test_bad_layout_files(tmp_path, text, message):
    (tmp_path / "l.txt").write_text(text)
    with pytest.raises(LayoutError, match=message):
        load_layout(tmp_path / "l.txt", 7)


def test_missing_layout_file(tmp_path):
    with pytest.raises(LayoutError, match="no such file"):
        load_layout(tmp_path / "nope.txt", 7)


# --------------------------------------------------------------------------- libigl layouts


def _shape_error(mesh, p):
    """E_C = Σ|d_e − L_e| / Σ d_e."""
    i, j = mesh.edges.T
    return np.abs(mesh.rest_lengths - np.linalg.norm(p[i] - p[j], axis=1)).sum() / mesh.rest_lengths.sum()


def _reversed(mesh):
    """The same surface with every face's winding reversed (the mirror image's layouts)."""
    return Mesh(mesh.vertices, mesh.faces[:, ::-1].copy())


def test_layout_methods_are_the_init_choices():
    assert LAYOUT_METHODS == ("tutte", "pca", "harmonic", "lscm", "arap", "slim")
    mesh = dome_grid(6)
    expected = {"tutte": tutte_layout, "pca": pca_layout, "harmonic": harmonic_layout, "lscm": lscm_layout,
                "arap": arap_layout}
    for name, function in expected.items():
        assert np.array_equal(initial_layout(mesh, name), function(mesh))


@pytest.mark.parametrize("method", LAYOUT_METHODS)
@pytest.mark.parametrize("make", [lambda: dome_grid(12, height=0.3), lambda: saddle_grid(12, height=0.3),
                                  lambda: _reversed(saddle_grid(12, height=0.3))],
                         ids=["dome", "saddle", "saddle-reversed-winding"])
def test_every_method_gives_a_fold_free_counter_clockwise_layout(method, make):
    mesh = make()
    p = initial_layout(mesh, method)
    assert p.shape == (mesh.n_vertices, 2) and p.dtype == np.float64
    assert np.isfinite(p).all()
    assert np.sum(signed_areas_2d(p, mesh.faces) > 0) > mesh.n_faces / 2
    assert not folded_faces(p, mesh.faces).any()
    # deterministic, also from fresh copies of the arrays
    assert np.array_equal(p, initial_layout(Mesh(mesh.vertices.copy(), mesh.faces.copy()), method))


def test_harmonic_keeps_tuttes_boundary_and_differs_inside():
    mesh = delaunay_patch(150)  # irregular: cotangent and uniform weights differ
    h, t = harmonic_layout(mesh), tutte_layout(mesh)
    loop = mesh.boundary_loop
    assert h[loop] == pytest.approx(t[loop], abs=1e-12)
    interior = np.setdiff1d(np.arange(mesh.n_vertices), loop)
    radius = np.linalg.norm(t[loop], axis=1).max()
    assert np.abs(h[interior] - t[interior]).max() > 1e-2 * radius


def test_harmonic_reproduces_a_flat_disk_up_to_scale():
    """Linear precision of the cotangent Laplacian, which the uniform (Tutte) weights lack.

    The flat Delaunay patch's boundary is a regular 24-gon starting at vertex
    0 on the x axis, so Tutte's circle is that polygon scaled by
    perimeter / (2π); the cotangent-harmonic interior is then the same
    scaling of the flat mesh, mirrored or not.
    """
    mesh = delaunay_patch(150, height=0.0)
    uv = mesh.vertices[:, :2]
    loop = mesh.boundary_loop
    perimeter = np.linalg.norm(uv[np.roll(loop, -1)] - uv[loop], axis=1).sum()
    scaled = uv * perimeter / (2 * math.pi)
    candidates = (scaled, scaled * [1.0, -1.0], scaled * [-1.0, 1.0])
    h = harmonic_layout(mesh)
    assert min(np.abs(h - c).max() for c in candidates) < 1e-10
    t = tutte_layout(mesh)
    assert min(np.abs(t - c).max() for c in candidates) > 1e-3


def test_lscm_area_equals_3d_area_and_is_centred():
    for mesh in (dome_grid(12, height=0.3), saddle_grid(12, height=0.3), delaunay_patch(150)):
        p = lscm_layout(mesh)
        assert np.abs(signed_areas_2d(p, mesh.faces)).sum() == pytest.approx(mesh.face_areas.sum(), rel=1e-9)
        assert p.mean(axis=0) == pytest.approx([0, 0], abs=1e-12)


@pytest.mark.parametrize("method", ["lscm", "arap"])
def test_lscm_and_arap_unroll_a_developable_grid(method):
    mesh, unrolled = rolled_grid(8, 8, arc_degrees=90)
    p = initial_layout(mesh, method)
    assert _shape_error(mesh, p) < 1e-6
    # the exact unrolled layout up to a rigid motion (orthogonal Procrustes, mirror allowed)
    a, b = p - p.mean(axis=0), unrolled - unrolled.mean(axis=0)
    u, _, vt = np.linalg.svd(b.T @ a)
    assert np.abs(b @ (u @ vt) - a).max() < 1e-6


def test_arap_keeps_the_3d_scale():
    mesh = dome_grid(12, height=0.3)
    p = arap_layout(mesh)
    assert _shape_error(mesh, p) < 0.05
    big = arap_layout(Mesh(mesh.vertices * 10.0, mesh.faces))
    assert big == pytest.approx(10.0 * p, abs=1e-9 * 10.0)


def _nan_like(result):
    if isinstance(result, tuple):
        return (np.full_like(result[0], np.nan),) + tuple(result[1:])
    return np.full_like(result, np.nan)


@pytest.mark.parametrize("method, function", [("harmonic", "harmonic"), ("lscm", "lscm"), ("arap", "arap_solve"),
                                              ("arap", "harmonic")])
def test_non_finite_libigl_output_is_a_layout_error(monkeypatch, method, function):
    original = getattr(igl, function)
    monkeypatch.setattr(igl, function, lambda *args: _nan_like(original(*args)))
    with pytest.raises(LayoutError, match=rf"^{method} layout failed: igl.{function} returned non-finite "
                                          r"coordinates for 36 of 36 vertices$") as info:
        initial_layout(dome_grid(6), method)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("method, function", [("harmonic", "harmonic"), ("lscm", "lscm"), ("arap", "arap_solve"),
                                              ("arap", "arap_precomputation")])
def test_libigl_exception_is_a_layout_error(monkeypatch, method, function):
    def fail(*args):
        raise RuntimeError("solver exploded\nsecond line")

    monkeypatch.setattr(igl, function, fail)
    with pytest.raises(LayoutError, match=rf"^{method} layout failed: igl.{function} raised RuntimeError: "
                                          r"solver exploded$"):
        initial_layout(dome_grid(6), method)


def test_auto_starts_from_slim_where_arap_fails():
    """A 1e-9 sliver makes libigl's ARAP return non-finite coordinates: ``auto`` (which the user did not ask
    to be ARAP) then starts from SLIM on Tutte's layout, with a note; ``arap`` asked for by name fails."""
    from sim.layouts import start_layout

    uv = grid_uv(6, 6)
    vertices = np.column_stack([uv, 0.1 * (uv**2).sum(axis=1)])
    vertices[14] = vertices[13] + [1e-9, 0, 0]
    mesh = Mesh(vertices, grid_faces(6, 6))
    with pytest.raises(LayoutError, match="arap layout failed"):
        start_layout(mesh, "arap")
    start = start_layout(mesh, "auto")
    assert start.method == "slim" and start.folded == 0 and np.isfinite(start.positions).all()
    assert start.notes == ["arap layout failed: igl.arap_solve returned non-finite coordinates for 35 of 36 vertices: "
                           "starting from SLIM on Tutte's layout instead (fold-free by construction)"]
    assert not folded_faces(start.positions, mesh.faces).any()


@pytest.mark.parametrize("power", [-12, -30, 12])
def test_slims_layout_is_the_same_at_any_size(power):
    """libigl's SLIM has absolute thresholds: the shipped ear scan (in metres) made 2^-12 times as large, edges
    of 0.4 µm, came back with 38 folded triangles, against a start the note calls fold-free by construction.
    Run at a size near 1 set by a power of two, its layout is the unscaled one's, scaled, to the last bit."""
    from sim.mesh_io import load_mesh

    ear = load_mesh(SCANS / "bunny_ear.obj")
    scaled = Mesh(ear.vertices * 2.0 ** power, ear.faces)
    positions = slim_layout(scaled)
    assert not folded_faces(positions, scaled.faces).any()
    np.testing.assert_array_equal(positions, slim_layout(ear) * 2.0 ** power)


def test_auto_starts_from_lscm_where_it_is_exact_and_a_fold_free_arap_is_not():
    """A flat half ring: ARAP stops after its 100 iterations bent and strained (5 %), which the dynamics's local
    steps do not undo; LSCM is exact on a developable patch, so ``auto`` starts from it, with a note. On a curved
    dome no layout is exact: ``auto`` keeps ARAP's, with no note."""
    from sim.generate import ring_sector

    ring = ring_sector()
    arap = initial_layout(ring, "arap")
    assert _shape_error(ring, arap) > 1e-3  # the case: ARAP far from the exact layout (E_C 0.005, 5 % at worst)
    start = start_layout(ring, "auto")
    assert start.method == "lscm" and start.folded == 0 and _shape_error(ring, start.positions) < 1e-9
    assert len(start.notes) == 1 and re.fullmatch(r"the arap layout is not as exact as the stop rule asks \(an rms "
                                                  r"edge strain of 0\.0\d+\), the lscm layout is \(\S+: a "
                                                  r"developable patch\): starting from it", start.notes[0]), start.notes
    assert start_layout(ring, "auto", floor_strain=0.0).method == "arap"  # --tol-energy 0: no floor, none exact
    dome = dome_grid(12, height=0.3)
    start = start_layout(dome, "auto")
    assert (start.method, start.notes) == ("arap", [])
    np.testing.assert_array_equal(start.positions, initial_layout(dome, "arap"))


@pytest.mark.parametrize("content, message", [
    (b"\x89PNG\r\n\x1a\n", r"^cannot parse layout '.*l.txt': not a text file \(byte 0 is not UTF-8 text\): a layout "
                           r"is a text file of 'x y' rows or an OBJ$"),
    (b"0 0\n# a comment\n\n1 x\n", r"^cannot parse layout '.*l.txt': row 2 has 'x', not a number$"),
])
def test_an_unreadable_layout_file_is_one_line_naming_what(tmp_path, content, message):
    (tmp_path / "l.txt").write_bytes(content)
    with pytest.raises(LayoutError, match=message):
        load_layout(tmp_path / "l.txt", 2)


def test_a_computed_start_is_oriented_by_its_area_as_folds_are_counted():
    """A folded start whose faces are mostly clockwise by count but whose bulk (its total signed area)
    is counter-clockwise is left as it is: the rule is the one its folds are counted against, so the
    few large faces stay the pattern and the many slivers are its folds."""
    from sim.layouts import _counter_clockwise
    from golden_model.mesh import layout_orientation

    angles = np.radians([0.0, 170.0, 169.0, 168.0, 167.0])  # an open fan: one wide face, three slivers back
    positions = np.vstack([[0.0, 0.0], 10.0 * np.column_stack([np.cos(angles), np.sin(angles)])])
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    vertices = np.column_stack([positions, np.zeros(6)])
    vertices[2:, 2] = [0.1, 0.2, 0.3, 0.4]  # the 3D fan is not flat
    mesh = Mesh(vertices, faces)
    assert np.sum(signed_areas_2d(positions, faces) < 0) == 3 and layout_orientation(positions, faces) > 0
    kept = _counter_clockwise(positions, mesh)
    assert np.array_equal(kept, positions)
    assert folded_faces(kept, faces).sum() == 3
    mirrored = positions * np.array([1.0, -1.0])
    assert np.array_equal(_counter_clockwise(mirrored, mesh), mirrored * np.array([-1.0, 1.0]))


def test_a_folded_start_is_untangled_before_the_guarded_dynamics(tmp_path):
    mesh = spherical_cap(6)
    folded = initial_layout(mesh, "tutte")
    folded[0] = folded[mesh.boundary_loop[0]] * 1.3  # the pole dragged past the rim: its fan folds
    assert folded_faces(folded, mesh.faces).sum() > 0
    path = tmp_path / "folded.txt"
    np.savetxt(path, folded)
    start = start_layout(mesh, str(path))
    assert start.folded == 0 and folded_faces(start.positions, mesh.faces).sum() == 0
    assert "untangl" in start.method and start.notes[-1].endswith("folds 3 triangles: untangling it")


def test_untangling_keeps_a_nearly_right_start_and_its_size():
    """A start with one vertex out of place (a fold): untangled at the mesh's size, the run from it ends as the run
    from the right start does. At the paper's weights (ε = 1, θ = 1/128), which assume a fixed boundary, the
    untangler shrank the layout, and the run here ended at E_C 0.19 against 0.013."""
    import springflat

    mesh = dome_grid(8)
    right = initial_layout(mesh, "tutte")
    moved = right.copy()
    inner = int(np.setdiff1d(np.arange(mesh.n_vertices), mesh.boundary_loop)[20])
    neighbour = int(mesh.edges[mesh.edges[:, 0] == inner][0, 1])
    moved[inner] = 1.5 * right[neighbour] - 0.5 * right[inner]  # past a neighbour: its fan folds
    assert folded_faces(moved, mesh.faces).sum() > 0
    start = start_layout(mesh, moved)
    assert start.folded == 0 and "untangled" in start.method
    area = np.abs(signed_areas_2d(start.positions, mesh.faces)).sum()
    assert 0.8 < area / mesh.face_areas.sum() < 1.25  # at the mesh's size
    from_right = springflat.flatten(mesh.vertices, mesh.faces, init=right)
    from_moved = springflat.flatten(mesh.vertices, mesh.faces, init=moved)
    assert from_moved.folded == 0 and from_moved.shape_error <= 1.05 * from_right.shape_error


def test_an_obj_that_holds_the_curved_mesh_itself_is_no_layout_a_flat_one_is(tmp_path):
    """springflat's pattern .obj keeps the 3D mesh in its v (the pattern in vt): given to --init, its x, y were
    taken as a start with a 'z dropped' note. Refused in one line; a flat mesh's own file is its exact layout."""
    from sim.generate import ring_sector
    from sim.mesh_io import save_obj

    dome = dome_grid(6)
    save_obj(tmp_path / "dome.obj", dome.vertices, dome.faces)
    with pytest.raises(LayoutError, match=r"^layout '.*dome.obj' holds the 3D mesh itself, not a layout \(a "
                                          r"springflat pattern .obj keeps the pattern in its vt, which --init does not "
                                          r"read\): give the pattern written as .flat.obj, or a text file of 'x y' "
                                          r"rows$"):
        initial_layout(dome, str(tmp_path / "dome.obj"))
    ring = ring_sector(90.0, 20)
    save_obj(tmp_path / "ring.obj", ring.vertices, ring.faces)
    np.testing.assert_allclose(initial_layout(ring, str(tmp_path / "ring.obj")), ring.vertices[:, :2], rtol=1e-12)


def test_lscm_pins_the_farthest_pair_among_the_hull_and_a_far_pair_on_a_long_strip():
    """The pins: every pair measured among the convex hull's vertices gives the brute force's pair (3D, planar and
    nearly planar sets, a grid's tied diagonals); past FARTHEST_PAIR_EXACT hull vertices (a half ring's outer arc)
    a double sweep's pair, at least half the greatest distance apart."""
    from sim.generate import ring_sector
    from sim.layouts import FARTHEST_PAIR_EXACT, _farthest_pair

    def brute(points):
        d2 = ((points[:, None] - points[None]) ** 2).sum(axis=2)
        r, c = divmod(int(np.argmax(d2)), len(points))
        return min(r, c), max(r, c)

    rng = np.random.default_rng(5)
    for k in range(60):
        points = rng.normal(size=(int(rng.integers(4, 300)), 3))
        points[:, 2] *= (1.0, 0.0, 1e-9)[k % 3]  # 3D, flat (no 3D hull), nearly flat
        assert _farthest_pair(points) == brute(points)
    vertices = np.column_stack([grid_uv(9, 9), np.zeros(81)])
    grid = vertices[Mesh(vertices, grid_faces(9, 9)).boundary_loop]
    assert _farthest_pair(grid) == brute(grid)
    ring = ring_sector(180.0, 2 * FARTHEST_PAIR_EXACT, 2)
    points = ring.vertices[ring.boundary_loop]
    a, b = _farthest_pair(points)
    assert np.linalg.norm(points[a] - points[b]) >= 0.5 * 900.0  # the outer arc's ends are 900 apart


def test_a_computed_start_given_back_is_taken_as_it_is():
    """Every start method's layout of the built-ins and of generated patches is within SIZE_TOLERANCE of the mesh's
    size (Tutte's of Surf1 is 2.07 times it, LSCM's of Surf2 0.75), so given back as a file or an array it starts
    the same run again; at 1.1 Tutte's, PCA's and ARAP's were scaled."""
    from sim.layouts import SIZE_TOLERANCE
    from sim.untangle import size_factor

    for mesh in (builtin_mesh("surf1")[0], builtin_mesh("surf2")[0], dome_grid(10), spherical_cap(8), saddle_grid(9)):
        for method in LAYOUT_METHODS:
            layout = initial_layout(mesh, method)
            assert 1 / SIZE_TOLERANCE <= size_factor(mesh, layout) <= SIZE_TOLERANCE, (mesh.name, method)
            assert np.array_equal(initial_layout(mesh, layout), layout), (mesh.name, method)
