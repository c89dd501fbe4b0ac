"""Initial layouts: tutte, pca and user files."""

import math

import numpy as np
import pytest

from golden_model.builtin import builtin_mesh
from golden_model.layouts import LayoutError, initial_layout, load_layout, pca_layout, tutte_layout
from golden_model.mesh import Mesh, signed_areas_2d
from golden_model.generate import dome_grid, grid_faces, grid_uv


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
        assert np.array_equal(initial_layout(mesh, tmp_path / name), expected)


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
