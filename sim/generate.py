"""Generated test meshes: regular grids bent into shapes, and an irregular Delaunay patch.

Used by the tests, the error studies and the benchmarks; every mesh is a
valid disk (see :mod:`golden_model.mesh`).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from golden_model.mesh import Mesh


def grid_faces(nx: int, ny: int) -> np.ndarray:
    """Triangles of an ``nx × ny`` vertex grid (row-major), two per cell."""
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])


def grid_uv(nx: int, ny: int, width: float = 1.0, height: float = 1.0) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(0, width, nx), np.linspace(0, height, ny))
    return np.column_stack([u.ravel(), v.ravel()])


def rolled_grid(nx: int = 6, ny: int = 6, arc_degrees: float = 60.0, size: float = 1.0) -> tuple[Mesh, np.ndarray]:
    """A ``size × size`` plane grid rolled onto a cylinder arc, and its exact unrolled layout.

    The mesh is made of planar rectangles hinged along the cylinder's
    generators, so it is developable; its isometric layout spaces the
    columns by the 3D chord, not by the arc length.
    """
    uv = grid_uv(nx, ny, size, size)
    radius = size / np.radians(arc_degrees)
    theta = uv[:, 0] / radius
    vertices = np.column_stack([radius * np.sin(theta), uv[:, 1], radius * (1 - np.cos(theta))])
    chord = 2 * radius * np.sin(size / (nx - 1) / radius / 2)
    unrolled = np.column_stack([np.tile(np.arange(nx) * chord, ny), uv[:, 1]])
    return Mesh(vertices, grid_faces(nx, ny), name="rolled"), unrolled


def ring_sector(degrees: float = 180.0, segments: int = 199, rows: int = 2, inner: float = 400.0,
                width: float = 50.0) -> Mesh:
    """A flat ring sector (a waistband, a curved flange) in the plane z = 0: ``segments`` cells along the arc,
    ``rows`` vertices across its ``width``, from radius ``inner``, wound counter-clockwise seen from +z. Its exact
    flattening is itself."""
    uv = grid_uv(segments + 1, rows, np.radians(degrees), width)
    radius = inner + uv[:, 1]
    vertices = np.column_stack([radius * np.cos(uv[:, 0]), radius * np.sin(uv[:, 0]), np.zeros(len(uv))])
    faces = grid_faces(segments + 1, rows)[:, ::-1]  # (the grid's (angle, radius) turns the other way round in xy)
    return Mesh(vertices, faces, name="ring_sector")


def dome_grid(n: int = 8, height: float = 0.3) -> Mesh:
    uv = grid_uv(n, n) - 0.5
    z = height * (1 - 2 * (uv**2).sum(axis=1))
    return Mesh(np.column_stack([uv, z]), grid_faces(n, n), name="dome")


def saddle_grid(n: int = 8, height: float = 0.3) -> Mesh:
    uv = grid_uv(n, n) - 0.5
    z = height * 4 * (uv[:, 0] ** 2 - uv[:, 1] ** 2)
    return Mesh(np.column_stack([uv, z]), grid_faces(n, n), name="saddle")


def delaunay_patch(n_points: int = 150, seed: int = 0, height: float = 0.25) -> Mesh:
    """An irregular Delaunay triangulation of random points in a disk, lifted onto a bump."""
    from scipy.spatial import Delaunay  # scipy is a dependency; only this generator needs it

    rng = np.random.default_rng(seed)
    ring = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    boundary = np.column_stack([np.cos(ring), np.sin(ring)])
    radius = np.sqrt(rng.uniform(0, 0.85**2, n_points - len(ring)))
    angle = rng.uniform(0, 2 * np.pi, n_points - len(ring))
    inner = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    uv = np.vstack([boundary, inner])
    faces = Delaunay(uv).simplices  # the hull is the 24-gon: no slivers
    z = height * np.exp(-2 * (uv**2).sum(axis=1))
    return Mesh(np.column_stack([uv, z]), faces, name="delaunay")


#: How each generated mesh of the fixed-point acceptance checks (and the study's) is made, by name.
GENERATED_MESHES: dict[str, Callable[[], Mesh]] = {
    "developable": lambda: rolled_grid(8, 8, arc_degrees=90)[0],
    "dome": lambda: dome_grid(8, height=0.3),
    "saddle": lambda: saddle_grid(8, height=0.3),
    "delaunay": lambda: delaunay_patch(150),
}


def generated_meshes() -> dict[str, Mesh]:
    """The generated meshes of the fixed-point acceptance checks (:data:`GENERATED_MESHES`), made."""
    return {name: make() for name, make in GENERATED_MESHES.items()}


def spherical_cap(rings: int = 10, half_angle_degrees: float = 60.0, radius: float = 1.0) -> Mesh:
    """A spherical cap meshed in ``rings`` concentric rings around its pole (6k nodes on ring k).

    Ring ``k`` lies at polar angle ``k/rings`` of ``half_angle_degrees``; its
    nodes are evenly spaced in longitude, and neighbouring rings are zipped
    into triangles by longitude order, so the mesh is a disk with nearly
    equilateral triangles and valences around 6.
    """
    vertices = [np.array([[0.0, 0.0, radius]])]
    faces = []
    start = [0]
    offset = 1
    for k in range(1, rings + 1):
        polar = np.radians(half_angle_degrees) * k / rings
        count = 6 * k
        longitude = 2 * np.pi * (np.arange(count) + 0.5 * (k % 2)) / count
        vertices.append(radius * np.column_stack([np.sin(polar) * np.cos(longitude), np.sin(polar) * np.sin(longitude),
                                                  np.full(count, np.cos(polar))]))
        start.append(offset)
        offset += count
    for k in range(1, rings + 1):
        outer = start[k] + np.arange(6 * k)
        if k == 1:  # the pole's fan
            faces += [[0, outer[o], outer[(o + 1) % 6]] for o in range(6)]
            continue
        inner = start[k - 1] + np.arange(6 * (k - 1))
        angle_in = 2 * np.pi * (np.arange(len(inner)) + 0.5 * ((k - 1) % 2)) / len(inner)
        angle_out = 2 * np.pi * (np.arange(len(outer)) + 0.5 * (k % 2)) / len(outer)
        # zip the two rings by longitude: each step advances one ring and makes one triangle
        i = o = 0
        while i < len(inner) or o < len(outer):
            take_outer = i == len(inner) or (o < len(outer) and angle_out[o] <= angle_in[i])
            if take_outer:
                faces.append([inner[i % len(inner)], outer[o], outer[(o + 1) % len(outer)]])
                o += 1
            else:
                faces.append([inner[i], outer[o % len(outer)], inner[(i + 1) % len(inner)]])
                i += 1
    return Mesh(np.vstack(vertices), np.array(faces), name="cap")


def capped_tube(cap_rings: int = 8, rows: int = 24, length: float = 5.0, radius: float = 0.4) -> Mesh:
    """A finger: a hemispherical cap (:func:`spherical_cap` of ``cap_rings`` rings to 90°) continued by
    ``rows`` rings of a cylinder wall of ``length``; a disk whose boundary is the open end."""
    cap = spherical_cap(cap_rings, 90.0, radius)
    n = 6 * cap_rings
    rim = np.arange(cap.n_vertices - n, cap.n_vertices)
    angle = np.arctan2(cap.vertices[rim, 1], cap.vertices[rim, 0])
    order = np.argsort(angle)
    rim, angle = rim[order], angle[order]
    vertices, faces, previous = [cap.vertices], [cap.faces], rim
    for row in range(1, rows + 1):
        ring = cap.n_vertices + (row - 1) * n + np.arange(n)
        vertices.append(np.column_stack([radius * np.cos(angle), radius * np.sin(angle),
                                         np.full(n, cap.vertices[rim[0], 2] - row * length / rows)]))
        nxt = np.roll(np.arange(n), -1)
        faces += [np.column_stack([previous, ring, ring[nxt]]), np.column_stack([previous, ring[nxt], previous[nxt]])]
        previous = ring
    return Mesh(np.vstack(vertices), np.vstack(faces), name="tube")


def cone_tip(rings: int = 20, half_angle_degrees: float = 10.0, height: float = 3.0) -> Mesh:
    """A horn: :func:`spherical_cap`'s rings laid on a cone of ``half_angle_degrees`` around its apex."""
    cap = spherical_cap(rings, 60.0, 1.0)
    x, y = cap.vertices[:, 0], cap.vertices[:, 1]
    slant = np.arcsin(np.clip(np.hypot(x, y), 0.0, 1.0)) / np.radians(60.0) * height / np.cos(
        np.radians(half_angle_degrees))
    theta = np.arctan2(y, x)
    r = slant * np.sin(np.radians(half_angle_degrees))
    return Mesh(np.column_stack([r * np.cos(theta), r * np.sin(theta), -slant * np.cos(np.radians(half_angle_degrees))]),
                cap.faces, name="cone")


def bent(mesh: Mesh, angle: float) -> Mesh:
    """``mesh`` bent about the y axis by ``angle`` radians over its z extent (a bent finger)."""
    x, y, z = mesh.vertices.T
    phi = angle * (z.max() - z) / (np.ptp(z) or 1.0)
    return Mesh(np.column_stack([x * np.cos(phi) - z * np.sin(phi), y, x * np.sin(phi) + z * np.cos(phi)]),
                mesh.faces, name=f"bent {mesh.name}")


def jittered(mesh: Mesh, amount: float, seed: int = 0) -> Mesh:
    """``mesh`` with each vertex moved by a normal deviate of ``amount`` × the median edge length (a scan's noise)."""
    rng = np.random.default_rng(seed)
    step = amount * float(np.median(mesh.rest_lengths))
    return Mesh(mesh.vertices + rng.normal(0.0, step, mesh.vertices.shape), mesh.faces, name=f"noisy {mesh.name}")


def hard_patches() -> dict[str, Mesh]:
    """Generated patches of the kinds that broke the unguarded dynamics on public scans (docs/corpus.md):
    fingers and horn tips whose ARAP layout folds, and a sliver-strewn Delaunay patch."""
    return {
        "bent finger": bent(capped_tube(), 2.5),
        "noisy finger": jittered(capped_tube(), 0.25),
        "noisy horn": jittered(cone_tip(), 0.3),
        "slivers": sliver_patch(),
    }


def sliver_patch(n_points: int = 400, seed: int = 1, squash: float = 0.02) -> Mesh:
    """A bump triangulated by Delaunay in a squashed parameter domain, then unsquashed: thin slivers."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    ring = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    boundary = np.column_stack([np.cos(ring), np.sin(ring)])
    radius = np.sqrt(rng.uniform(0, 0.85**2, n_points))
    angle = rng.uniform(0, 2 * np.pi, n_points)
    uv = np.vstack([boundary, np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])])
    faces = Delaunay(uv * [1.0, squash]).simplices
    z = 0.4 * np.exp(-3.0 * (uv**2).sum(axis=1))
    return Mesh(np.column_stack([uv, z]), faces, name="slivers")


def bumpy_grid(n: int = 31, height: float = 0.08, bumps: int = 3) -> Mesh:
    """An ``n × n`` grid over the unit square lifted by ``bumps × bumps`` sine bumps of ``height``."""
    uv = grid_uv(n, n) - 0.5
    z = height * np.sin(2 * np.pi * bumps * uv[:, 0]) * np.sin(2 * np.pi * bumps * uv[:, 1])
    return Mesh(np.column_stack([uv, z]), grid_faces(n, n), name="bumpy")


def holed_dome(n: int = 16, height: float = 0.3, holes: tuple[tuple[int, int, int], ...] = ((5, 5, 3),)) -> Mesh:
    """:func:`dome_grid` with square cut-outs: each ``(row, column, size)`` removes the grid's cells of rows and
    columns ``row .. row + size − 1``, ``column .. column + size − 1`` (holes must not touch the edge or each
    other; :func:`grid_with_cut_outs`)."""
    cut = np.zeros((n - 1, n - 1), dtype=bool)
    for row, column, size in holes:
        cut[row:row + size, column:column + size] = True
    return grid_with_cut_outs(dome_grid(n, height).vertices, n, cut, name="holed dome")


def grid_with_cut_outs(vertices: np.ndarray, n: int, cut: np.ndarray, name: str = "grid") -> Mesh:
    """The ``n × n`` vertex grid ``vertices`` (row-major, :func:`grid_faces`) without the cells where ``cut``
    ``(n − 1, n − 1)`` is true, its unused vertices dropped (the rest in order): a disk with holes,
    ``Mesh(..., allow_holes=True)``."""
    keep = ~np.asarray(cut, dtype=bool).ravel()
    faces = grid_faces(n, n)[np.concatenate([keep, keep])]  # two triangles a cell, in two runs
    used = np.unique(faces)
    renumber = np.full(n * n, -1)
    renumber[used] = np.arange(len(used))
    return Mesh(np.asarray(vertices)[used], renumber[faces], name=name, allow_holes=True)
