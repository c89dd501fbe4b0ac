"""Holes kept as cut-outs (``--keep-holes``, ``keep_holes=True``): the run, its guarantees, the pattern files."""

import json
import re
import subprocess
import warnings

import ezdxf
import numpy as np
import pytest
import shapely

import springflat
from golden_model.mesh import MeshError, folded_faces, loop_signed_area, signed_areas_2d, triangle_areas_3d
from golden_model.params import ParameterError
from sim.generate import holed_dome
from sim.layouts import load_layout
from sim.patterns import SEAM_MARGIN
from sim.mesh_io import save_obj
from support import SPRINGFLAT

#: A 160 mm dome, 16 × 16 vertices, with a 3 × 3-cell and a 4 × 4-cell cut-out.
HOLES = ((2, 2, 3), (8, 8, 4))


def _holed_file(path):
    mesh = holed_dome(16, holes=HOLES)
    save_obj(path, mesh.vertices * 160.0, mesh.faces)
    return mesh


def _dxf_loops(path, layer: str) -> list[np.ndarray]:
    return [np.array([p[:2] for p in e.get_points()]) for e in ezdxf.readfile(path).modelspace()
            if e.dxftype() == "LWPOLYLINE" and e.dxf.layer == layer and e.closed]


def test_the_command_keeps_the_holes_open_fold_free_and_cuts_round_them(tmp_path):
    mesh = _holed_file(tmp_path / "holed.obj")
    outs = [str(tmp_path / name) for name in ("p.flat.obj", "p.dxf", "p.svg", "p.pdf")]
    ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "holed.obj"), "--keep-holes", "--json",
                          "--seam-allowance", "3mm", *(a for out in outs for a in ("--out", out))],
                         capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    assert "springflat: note: holed: 2 holes kept as cut-outs (edges " in ran.stderr
    summary = json.loads(ran.stdout)
    assert (summary["status"], summary["folded"], summary["holes"], summary["faces"]) == ("converged", 0, 2,
                                                                                          mesh.n_faces)
    assert (summary["boundary_crossings"], summary["turned_holes"]) == (0, 0)
    layout = load_layout(tmp_path / "p.flat.obj", mesh.n_vertices, faces=mesh.faces)
    assert not folded_faces(layout, mesh.faces).any()
    # each hole stays open, about the size the surface gives it: its fill's 3D area, within 10 % (a hole's edge
    # is not flat on the dome, and the layout's areas are off by E_S on average, more near the holes)
    outer, *holes = mesh.boundary_loops
    fill = mesh.disk.faces[mesh.n_faces:]
    for hole in holes:
        inside = fill[np.isin(fill, hole).all(axis=1)]
        area_3d = float(triangle_areas_3d(mesh.vertices * 160.0, inside).sum())
        assert -loop_signed_area(layout[hole]) == pytest.approx(area_3d, rel=0.1)  # a hole's edge runs clockwise
    assert loop_signed_area(layout[outer]) > 0
    # the DXF: the sew line is the pattern's edge, outer edge and holes; the cut line 3 mm outside it, into the holes
    sew, cut = _dxf_loops(outs[1], "SEW"), _dxf_loops(outs[1], "CUT")
    assert len(sew) == len(cut) == 3
    for line, loop in zip(sew, mesh.boundary_loops):
        np.testing.assert_allclose(line, layout[loop], atol=1e-9)
    material = shapely.Polygon(sew[0], sew[1:])
    cut_area = shapely.Polygon(cut[0], cut[1:])
    assert cut_area.contains(material)
    for ring in (cut_area.exterior, *cut_area.interiors):  # every cut point 3 mm from the piece, within the buffer's
        distances = [material.distance(shapely.Point(p)) for p in np.asarray(ring.coords)]
        assert min(distances) >= 3.0 * (1 - 1e-9) and max(distances) <= 3.0 * (1 + SEAM_MARGIN) * (1 + 1e-9)
    svg = (tmp_path / "p.svg").read_text()
    assert svg.count('class="cut-hole"') == 2 and svg.count('class="sew-hole"') == 2


def test_without_an_option_a_holed_mesh_is_refused_naming_both_and_both_at_once_are_refused(tmp_path):
    _holed_file(tmp_path / "holed.obj")
    ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "holed.obj")], capture_output=True, text=True,
                         timeout=120)
    assert ran.returncode == 2 and ran.stderr.strip().endswith(
        "--fill-holes closes all but the outer edge, --keep-holes keeps them as cut-outs")
    ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "holed.obj"), "--fill-holes", "--keep-holes"],
                         capture_output=True, text=True, timeout=120)
    assert ran.returncode == 2 and "not allowed with argument" in ran.stderr


def test_the_api_reads_and_flattens_a_mesh_with_its_holes_kept(tmp_path):
    mesh = _holed_file(tmp_path / "holed.obj")
    with pytest.raises(MeshError, match=r"fill_holes=True closes all but the outer edge, keep_holes=True keeps "
                                        r"them as cut-outs$"):
        springflat.read_mesh(tmp_path / "holed.obj")
    with pytest.raises(ParameterError, match=r"^fill_holes=True and keep_holes=True: a hole is closed or kept, give "
                                             r"one of them$"):
        springflat.read_mesh(tmp_path / "holed.obj", fill_holes=True, keep_holes=True)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        V, F = springflat.read_mesh(tmp_path / "holed.obj", keep_holes=True)
    assert F.shape == mesh.faces.shape and "2 holes kept as cut-outs" in str(said[0].message)
    with pytest.raises(ParameterError, match=r"^fill_holes=True and keep_holes=True: "):
        springflat.flatten(V, F, fill_holes=True, keep_holes=True)
    with pytest.warns(springflat.MeshNote, match=r"2 holes kept as cut-outs"):
        pattern = springflat.flatten(V, F, keep_holes=True, name="holed")
    assert pattern.folded == 0 and pattern.boundary_crossings == 0 and pattern.mesh.n_holes == 2
    assert (np.sign(signed_areas_2d(pattern.layout, F)) > 0).all()
    springflat.write_pattern(tmp_path / "api.dxf", pattern)
    assert len(_dxf_loops(tmp_path / "api.dxf", "CUT")) == 3


def _bump_with_a_hole_on_top():
    """A 100 mm grid over a 60 mm high bump, the 2 × 2 cells at its top cut out. The hole's corners hold less
    angle than an open flat hole needs (Gauss–Bonnet: their angles sum to (k + 2)π less the curvature the
    hole enclosed, k its corners), so the energy's minimum wraps the piece over the hole."""
    from sim.generate import grid_uv, grid_with_cut_outs

    n = 21
    uv = grid_uv(n, n, 100.0, 100.0) - 50.0
    vertices = np.column_stack([uv, 60 * np.exp(-(uv**2).sum(axis=1) / (2 * 12.0**2))])
    cut = np.zeros((n - 1, n - 1), dtype=bool)
    cut[9:11, 9:11] = True
    mesh = grid_with_cut_outs(vertices, n, cut)
    return mesh.vertices, mesh.faces


def test_a_piece_that_wraps_over_a_hole_is_said_to_overlap_and_its_start_is_open(tmp_path, monkeypatch):
    from golden_model.mesh import Mesh, boundary_crossings, turned_holes
    from sim.layouts import start_layout
    from sim.patterns import PatternDrawing

    V, F = _bump_with_a_hole_on_top()
    mesh = Mesh(V, F, allow_holes=True)
    # auto: ARAP's folds counted with the fill's, so the hole starts open and the right way round
    start = start_layout(mesh, "auto").positions
    assert not folded_faces(start, mesh.disk.faces).any()
    assert turned_holes(start, F, mesh.boundary_loops) == 0 and boundary_crossings(start, mesh.boundary_loops) == 0
    # harmonic's and LSCM's layouts of the disk fold the fill's triangles, not the piece's: nothing is untangled
    # (untangling a fill, no part of the pattern, can tangle the piece)
    for init in ("harmonic", "lscm"):
        layout = start_layout(mesh, init)
        assert folded_faces(layout.positions, mesh.disk.faces).any() and not folded_faces(layout.positions, F).any()
        assert (layout.method, layout.notes) == (init, [])
    # where ARAP folds the fill, auto takes SLIM's layout of the disk, fold-free with its fill
    import sim.layouts

    monkeypatch.setitem(sim.layouts._METHODS, "arap", sim.layouts.harmonic_layout)
    layout = start_layout(mesh, "auto")
    assert layout.method == "slim" and not folded_faces(layout.positions, mesh.disk.faces).any()
    assert layout.notes == ["the arap layout folds 4 triangles (with the holes closed): starting from SLIM on Tutte's "
                            "layout instead (fold-free by construction)"]
    monkeypatch.undo()
    with pytest.warns(springflat.MeshNote, match=r"the pattern overlaps itself, though no triangle is folded: it "
                                                 r"wraps over 1 of its holes, covering it twice"):
        pattern = springflat.flatten(V, F, keep_holes=True, name="bump")
    assert (pattern.status, pattern.folded, pattern.turned_holes) == ("converged", 0, 1)
    triangles = [shapely.Polygon(pattern.layout[t]) for t in F]
    assert sum(t.area for t in triangles) - shapely.union_all(triangles).area > 1.0  # mm²: covered twice, truly
    with warnings.catch_warnings(record=True) as said:  # its hole is covered: no cut-out to close
        warnings.simplefilter("always")
        springflat.write_pattern(tmp_path / "bump.dxf", pattern, seam_allowance=2.0)
    assert not [w for w in said if "narrower than twice the seam allowance" in str(w.message)]
    assert [str(w.message) for w in said if "covered" in str(w.message)] == [
        "bump: the kept hole is covered by the pattern where it lies on itself: the cut line has no cut-out for it"]
    with pytest.warns(springflat.MeshNote, match=r"^bump: the kept hole is covered by the pattern where it lies on "
                                                 r"itself: the cut line round it runs over the material$"):
        springflat.write_pattern(tmp_path / "bare.dxf", pattern)  # no allowance: the hole's loop is on the cut line
    cut = _dxf_loops(tmp_path / "bump.dxf", "CUT")
    seen = PatternDrawing.of(pattern.mesh, pattern.layout).as_seen().layout  # the files' frame: the mesh's view
    assert shapely.Polygon(cut[0], cut[1:]).buffer(1e-6).contains(shapely.union_all(
        [shapely.Polygon(seen[t]) for t in F]))
    assert "it wraps over 1 of its holes" in str(ezdxf.readfile(tmp_path / "bump.dxf").ezdxf_metadata().get(
        "springflat_run"))


def test_the_grain_line_lies_on_a_ring_not_across_its_hole(tmp_path):
    from sim.patterns import PatternDrawing, material

    mesh = holed_dome(16, holes=((2, 2, 11),))  # a ring two cells wide: its middle is the hole
    pattern = springflat.flatten(mesh.vertices * 160.0, mesh.faces, keep_holes=True)
    drawing = PatternDrawing.of(pattern.mesh, pattern.layout).with_grain("y")
    line = shapely.LineString(drawing.grain_line())
    assert line.length > 0.3 * float(np.ptp(drawing.layout[:, 1]))
    assert material(drawing).buffer(1e-6).covers(line)


def test_a_seam_allowance_that_closes_kept_holes_on_the_cut_line_says_so(tmp_path):
    _holed_file(tmp_path / "holed.obj")
    ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "holed.obj"), "--keep-holes", "--seam-allowance",
                          "18mm", "--out", str(tmp_path / "p.dxf")], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr  # the holes are about 32 and 43 mm across
    assert ("springflat: note: 1 of the 2 kept holes is narrower than twice the seam allowance (18 mm): the cut line "
            "does not go round it; cut it out along the sew line after sewing") in ran.stderr
    assert len(_dxf_loops(tmp_path / "p.dxf", "CUT")) == 2 and len(_dxf_loops(tmp_path / "p.dxf", "SEW")) == 3


def test_a_kept_slit_starts_from_pca_or_a_file_and_a_start_that_needs_it_closed_says_so(tmp_path):
    from sim.generate import grid_faces, grid_uv

    n = 11  # a slit: the middle row's three inner vertices doubled, the faces below them on the copies
    uv = grid_uv(n, n, 100.0, 100.0)
    vertices = np.column_stack([uv, 0.002 * ((uv - 50.0)**2).sum(axis=1)])
    faces = grid_faces(n, n)
    slit = [5 * n + k for k in (4, 5, 6)]
    copies = {v: len(vertices) + i for i, v in enumerate(slit)}
    vertices = np.vstack([vertices, vertices[slit]])
    below = (faces // n).max(axis=1) <= 5  # rows 4 to 5: the cells under the middle row
    faces[below] = np.vectorize(lambda v: copies.get(v, v))(faces[below])
    save_obj(tmp_path / "slit.obj", vertices, faces)
    for dynamics in ("momentum", "paper"):  # the guarded start, and the unguarded one, which takes no other
        ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "slit.obj"), "--keep-holes", "--dynamics",
                              dynamics], capture_output=True, text=True, timeout=300)
        assert ran.returncode == 2 and re.fullmatch(
            r"springflat: error: the arap layout, a start computed with the mesh's holes closed, cannot be had: the "
            r"hole whose edge runs through vertices \d+, \d+, \d+, \.\.\. cannot be filled: it encloses no area \(a "
            r"crack or a T-junction's slit\); start from --init pca or from a layout of the mesh's vertices",
            ran.stderr.strip().splitlines()[-1]), ran.stderr
    with pytest.raises(ParameterError, match=r"the arap layout, a start computed with the mesh's holes closed, cannot "
                                             r"be had: .* start from init='pca' or from a layout of the mesh's "
                                             r"vertices$"):
        springflat.flatten(vertices, faces, keep_holes=True)
    np.savetxt(tmp_path / "start.txt", vertices[:, :2])
    for init in ("pca", str(tmp_path / "start.txt")):
        ran = subprocess.run([SPRINGFLAT, "flatten", str(tmp_path / "slit.obj"), "--keep-holes", "--init", init,
                              "--json"], capture_output=True, text=True, timeout=300)
        assert ran.returncode == 0, ran.stderr
        summary = json.loads(ran.stdout)
        # the slit opens where the surface pulls it apart, or the piece wraps over it: either is said
        assert summary["folded"] == 0 and summary["holes"] == 1
        overlapping = summary["boundary_crossings"] or summary.get("turned_holes")
        assert bool(overlapping) == ("the pattern overlaps itself" in ran.stderr)


def test_the_closed_holes_note_counts_a_hole_the_cut_line_goes_round_in_part_as_open():
    """On a flat 100 mm grid of 5 mm cells: an L-shaped hole whose 5 mm arm a 4 mm allowance closes but whose
    15 mm foot it leaves open is cut round (no note); a 5 mm square hole is closed (the note)."""
    from sim.generate import grid_uv, grid_with_cut_outs
    from sim.patterns import PatternDrawing, closed_holes_note

    n = 21
    uv = grid_uv(n, n, 100.0, 100.0)
    cut = np.zeros((n - 1, n - 1), dtype=bool)
    cut[5:8, 5:15] = True  # the foot, 15 x 50 mm
    cut[8:14, 5] = True  # the arm, 5 x 30 mm
    mesh = grid_with_cut_outs(np.column_stack([uv, np.zeros(n * n)]), n, cut)
    drawing = PatternDrawing.of(mesh, mesh.vertices[:, :2]).with_seam(4.0)
    assert len(drawing.cut_loops) == 2 and closed_holes_note(drawing) is None
    cut[16, 16] = True  # and a 5 mm square
    mesh = grid_with_cut_outs(np.column_stack([uv, np.zeros(n * n)]), n, cut)
    drawing = PatternDrawing.of(mesh, mesh.vertices[:, :2]).with_seam(4.0)
    assert closed_holes_note(drawing) == ("1 of the 2 kept holes is narrower than twice the seam allowance (4 mm): "
                                          "the cut line does not go round it; cut it out along the sew line after "
                                          "sewing")


def test_a_grain_line_through_a_c_shaped_pieces_gap_moves_onto_the_piece():
    """A C-shaped piece (no hole): the vertical through the vertex nearest its centroid crosses the C's gap;
    the grain line moves to the piece's longest vertical stretch, the back of the C."""
    from sim.generate import grid_uv, grid_with_cut_outs
    from sim.patterns import PatternDrawing

    n = 21
    uv = grid_uv(n, n, 100.0, 100.0)
    cut = np.zeros((n - 1, n - 1), dtype=bool)
    cut[4:14, 4:] = True  # the gap, y 20 to 70, from the right edge in to x = 20: the outer edge goes round it
    mesh = grid_with_cut_outs(np.column_stack([uv, np.zeros(n * n)]), n, cut)
    assert mesh.n_holes == 0
    drawing = PatternDrawing.of(mesh, mesh.vertices[:, :2]).with_grain("y")
    (x0, y0), (x1, y1) = drawing.grain_line()
    assert x0 == x1 and x0 < 20.0 and y1 - y0 == pytest.approx(50.0)  # on the back, half the height long
    assert drawing.covered.covers(shapely.LineString([(x0, y0), (x1, y1)]))


def test_the_dxf_loops_run_one_way_with_or_without_a_seam_allowance(tmp_path):
    """Outer loops counter-clockwise, holes clockwise, on CUT and SEW alike (a cutter offsets by direction)."""
    mesh = holed_dome(16, holes=((2, 2, 3), (8, 8, 4)))
    pattern = springflat.flatten(mesh.vertices * 160.0, mesh.faces, keep_holes=True)
    for name, seam in (("plain.dxf", None), ("seamed.dxf", 3.0)):
        springflat.write_pattern(tmp_path / name, pattern, seam_allowance=seam)
        for layer in ("CUT", "SEW") if seam else ("CUT",):
            loops = _dxf_loops(tmp_path / name, layer)
            signs = [np.sign(loop_signed_area(loop)) for loop in loops]
            assert len(loops) == 3 and signs == [1.0, -1.0, -1.0], (name, layer, signs)


def test_a_flap_over_a_kept_hole_is_said_where_the_cut_line_has_no_cut_out_for_it():
    """A 110 mm flat grid with two 30 mm holes side by side in y, the strip x < c folded over onto [c, 2c]: at
    c = 36 mm the flap covers both holes (the covered note, both, with and without an allowance); at 30 mm it
    covers two thirds of each and the cut line still goes round the rest (no note); at 26 mm with a 10 mm
    allowance the rest is too narrow and the cut line goes round none of it (the closed note, not the covered)."""
    from sim.generate import grid_uv, grid_with_cut_outs
    from sim.patterns import PatternDrawing, closed_holes_note, covered_holes_note

    n = 12
    uv = grid_uv(n, n, 110.0, 110.0)
    cut = np.zeros((n - 1, n - 1), dtype=bool)
    cut[1:4, 4:7] = True  # x 40-70, y 10-40
    cut[6:9, 4:7] = True  # x 40-70, y 60-90
    mesh = grid_with_cut_outs(np.column_stack([uv, np.zeros(n * n)]), n, cut)

    def folded_at(c: float, seam: float) -> PatternDrawing:
        layout = mesh.vertices[:, :2].copy()
        layout[layout[:, 0] < c, 0] = 2 * c - layout[layout[:, 0] < c, 0]
        drawing = PatternDrawing.of(mesh, layout)
        return drawing.with_seam(seam) if seam else drawing

    covers = folded_at(36.0, 1.0)
    assert len(covers.cut_loops) == 1 and closed_holes_note(covers) is None
    assert covered_holes_note(covers) == ("both kept holes are covered by the pattern where it lies on itself: the "
                                          "cut line has no cut-out for them")
    assert covered_holes_note(folded_at(36.0, 0.0)) == ("both kept holes are covered by the pattern where it lies on "
                                                        "itself: the cut line round them runs over the material")
    two_thirds = folded_at(30.0, 1.0)
    assert len(two_thirds.cut_loops) == 3 and covered_holes_note(two_thirds) is None
    assert closed_holes_note(two_thirds) is None
    narrow = folded_at(26.0, 10.0)
    assert len(narrow.cut_loops) == 1 and covered_holes_note(narrow) is None
    assert closed_holes_note(narrow) == ("both kept holes are narrower than twice the seam allowance (10 mm): the cut "
                                         "line does not go round them; cut them out along the sew line after sewing")
