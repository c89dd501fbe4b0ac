"""The seam allowance (``--seam-allowance``, ``write_pattern(..., seam_allowance=...)``): the cut line outside the
pattern's edge, the edge as the sew line, in every true-scale pattern file. Distances are measured here with
numpy (point to segment) and matplotlib's point-in-polygon test, not with shapely, which draws the line."""

import json
import math
import re
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from matplotlib.path import Path as Outline

from golden_model.mesh import Mesh, boundary_crossings
from sim.generate import grid_faces, grid_uv
from sim.patterns import (PatternDrawing, PatternError, pattern_size_mm, plan_sheets, seam_length, seam_outlines,
                          without_blank_sheets, write_pattern_file)
from support import SCANS, SPRINGFLAT

SVG = "{http://www.w3.org/2000/svg}"
#: How much farther than the allowance the cut line may run from the sew line (the docs' 0.1 %).
MARGIN = 1e-3


def distance_to_loop(points: np.ndarray, loop: np.ndarray) -> np.ndarray:
    """Each point's distance to the closed polyline ``loop`` (to its nearest side)."""
    a, b = loop, np.roll(loop, -1, axis=0)
    ab = b - a
    t = np.clip(((points[:, None, :] - a) * ab).sum(axis=2) / (ab * ab).sum(axis=1), 0.0, 1.0)
    return np.linalg.norm(points[:, None, :] - (a + t[..., None] * ab), axis=2).min(axis=1)


def distance_to_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Each point's distance to the area the closed ``polygon`` encloses (0 inside)."""
    inside = Outline(np.vstack([polygon, polygon[:1]]), closed=True).contains_points(points)
    return np.where(inside, 0.0, distance_to_loop(points, polygon))


def along(ring: np.ndarray, per_side: int = 8) -> np.ndarray:
    """Points along every side of the closed ``ring``, its corners included."""
    t = np.linspace(0.0, 1.0, per_side, endpoint=False)[:, None, None]
    return (ring + t * (np.roll(ring, -1, axis=0) - ring)).reshape(-1, 2)


def rectangle(width: float, height: float) -> tuple[Mesh, np.ndarray]:
    uv = grid_uv(6, 4, width, height)
    return Mesh(np.column_stack([uv, np.zeros(len(uv))]), grid_faces(6, 4)), uv


@pytest.fixture(scope="module")
def bunny():
    """bunny_face.obj (metres), flattened with the file defaults: a scanned boundary's zigzag of short edges."""
    import springflat

    V, F = springflat.read_mesh(SCANS / "bunny_face.obj")
    pattern = springflat.flatten(V, F, name="bunny_face")
    return pattern.mesh, pattern.layout


@pytest.mark.parametrize("case", ["rectangle", "bunny"])
def test_the_cut_line_keeps_the_allowance_from_the_whole_sew_line(case, bunny):
    if case == "rectangle":
        mesh, layout = rectangle(100.0, 60.0)
        allowance = 10.0
    else:
        mesh, layout = bunny
        allowance = 0.01  # 10 mm on a face 90 mm across, whose boundary edges are about 1 mm
    sew = layout[mesh.boundary_loop]
    cut = seam_outlines(PatternDrawing.of(mesh, layout), allowance)[0]
    gap = distance_to_polygon(along(cut), sew)
    assert gap.min() >= allowance, gap.min() / allowance  # no point of the cut line closer than the allowance
    assert gap.max() <= allowance * (1 + MARGIN + 1e-9), gap.max() / allowance  # and none much farther
    # every sew-line point has its full allowance: the cut line is outside it all, at least that far away
    assert Outline(np.vstack([cut, cut[:1]]), closed=True).contains_points(along(sew)).all()
    assert distance_to_polygon(along(sew), cut[::-1]).max() == 0.0
    assert boundary_crossings(cut, np.arange(len(cut))) == 0


def test_a_rectangles_cut_line_is_its_allowance_larger_each_way():
    mesh, layout = rectangle(100.0, 60.0)
    cut = seam_outlines(PatternDrawing.of(mesh, layout), 10.0)[0]
    assert ([120.0, 80.0] <= np.ptp(cut, axis=0)).all() and (np.ptp(cut, axis=0) <= [120.02, 80.02]).all()


def test_a_sew_line_that_crosses_itself_gets_one_simple_cut_line_around_it():
    """A strip bent round until its end lies over its start: the boundary crosses itself."""
    uv = grid_uv(30, 3, 1.0, 0.1)
    mesh = Mesh(np.column_stack([uv, np.zeros(len(uv))]), grid_faces(30, 3))
    angle = uv[:, 0] * 2.4 * math.pi
    radius = 0.3 + uv[:, 1]
    layout = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    assert boundary_crossings(layout, mesh.boundary_loop) > 0
    cut = seam_outlines(PatternDrawing.of(mesh, layout), 0.02)[0]
    assert boundary_crossings(cut, np.arange(len(cut))) == 0
    outline = Outline(np.vstack([cut, cut[:1]]), closed=True)
    assert outline.contains_points(layout).all()
    assert distance_to_loop(layout, cut).min() >= 0.02


@pytest.mark.parametrize("value, units, expected", [
    ("10", "mm", 10.0), (10, "mm", 10.0), ("10mm", "m", 0.01), ("1.5 cm", "mm", 15.0), ("0.375in", "mm", 9.525),
    ("0.01m", "cm", 1.0), (np.float32(2.5), "cm", 2.5), ("0", "mm", 0.0), (" +.5in ", "in", 0.5),
    ("1e1mm", "mm", 10.0)])
def test_an_allowance_is_read_in_the_pattern_units_or_its_own(value, units, expected):
    assert seam_length(value, units) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("value", ["-1", "abc", "nan", "inf", "1e400", "mm", "10 ft", "1_0", "10M", "1.5 CM",
                                   "\u0663", "0x10", "1,5cm", -0.5, float("nan"), float("inf"), 10**400, True, None])
def test_an_allowance_that_is_not_a_length_of_0_or_more_is_refused(value):
    with pytest.raises(PatternError, match=r"^a seam allowance is a length"):
        seam_length(value, "mm")


def test_minus_zero_is_no_allowance():
    assert math.copysign(1.0, seam_length("-0", "mm")) == 1.0


def test_the_dxf_has_the_cut_line_on_cut_and_the_pattern_edge_on_sew(bunny, tmp_path):
    import ezdxf
    from ezdxf import recover

    mesh, layout = bunny
    path = tmp_path / "bunny.dxf"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m").with_seam(0.01))
    doc, auditor = recover.readfile(path)
    assert not auditor.has_errors
    lines = {e.dxf.layer: np.array([p[:2] for p in e.get_points("xy")]) for e in doc.modelspace()}
    assert sorted(lines) == ["CUT", "SEW"]
    assert all(e.closed for e in doc.modelspace())
    sew = layout[mesh.boundary_loop]
    np.testing.assert_allclose(lines["SEW"], sew, rtol=0, atol=1e-12)
    gap = distance_to_polygon(along(lines["CUT"]), sew)
    assert 0.01 <= gap.min() and gap.max() <= 0.01 * (1 + MARGIN + 1e-9)
    assert doc.layers.get("SEW").dxf.linetype == "SEW" and "SEW" in doc.linetypes
    drawn = np.vstack(list(lines.values()))
    np.testing.assert_allclose(doc.header["$EXTMIN"][:2], drawn.min(axis=0), atol=1e-12)
    np.testing.assert_allclose(doc.header["$EXTMAX"][:2], drawn.max(axis=0), atol=1e-12)
    assert ezdxf.readfile(path).ezdxf_metadata()["springflat_seam_allowance"] == "0.01 m"


def test_the_sheets_grow_by_the_allowance_and_say_it(tmp_path):
    """A 185 x 100 mm piece fits one A4 portrait window (190 x 255 mm); with 10 mm all round, 205 x 120 mm, it
    takes one landscape sheet; the SVG's cut line is the larger outline and its sew line the piece's edge."""
    mesh, layout = rectangle(185.0, 100.0)
    plain, seamed = PatternDrawing.of(mesh, layout, "mm"), PatternDrawing.of(mesh, layout, "mm").with_seam(10.0)
    assert pattern_size_mm(plain) == pytest.approx((185.0, 100.0)) and pattern_size_mm(seamed) == pytest.approx(
        (205.0, 120.0), abs=0.02)
    for drawing, name in ((plain, "plain.svg"), (seamed, "seamed.svg")):
        write_pattern_file(tmp_path / name, drawing)
    roots = {name: ET.parse(tmp_path / name).getroot() for name in ("plain.svg", "seamed.svg")}
    assert (roots["plain.svg"].get("width"), roots["seamed.svg"].get("width")) == ("210mm", "297mm")

    def polygon(root, ident):
        found = root.find(f".//{SVG}polygon[@id='{ident}']")
        return None if found is None else np.array([p.split(",") for p in found.get("points").split()], float)

    assert polygon(roots["plain.svg"], "sew") is None
    np.testing.assert_allclose(np.ptp(polygon(roots["seamed.svg"], "cut"), axis=0), [205.01, 120.01], atol=0.011)
    np.testing.assert_allclose(np.ptp(polygon(roots["seamed.svg"], "sew"), axis=0), [185.0, 100.0], atol=1e-3)
    assert "seam allowance 10 mm included" in roots["seamed.svg"].find(f"{SVG}title").text
    assert "seam allowance" not in roots["plain.svg"].find(f"{SVG}title").text


def test_a_sheet_that_holds_only_seam_allowance_is_printed():
    """A diagonal strip over a 3 x 3 grid with 40 mm all round: every sheet the cut line's area reaches is kept,
    also one that no triangle reaches (the check: there is such a sheet)."""
    t = np.linspace(0.0, 1.0, 40)
    spine = np.column_stack([t * 480.0, t * 660.0])
    across = np.array([-12.0, 12.0]) / math.sqrt(2)
    layout = np.vstack([spine + across, spine - across])
    n = len(t)
    faces = np.array([f for k in range(n - 1) for f in ((k, n + k, k + 1), (k + 1, n + k, n + k + 1))])
    mesh = Mesh(np.column_stack([layout, np.zeros(2 * n)]), faces)
    drawing = PatternDrawing.of(mesh, layout, "mm").with_seam(40.0)
    grid_plan = plan_sheets(pattern_size_mm(drawing), "a4")
    kept = {s.label for s in without_blank_sheets(grid_plan, drawing).sheets}
    cut = drawing.cut_points
    low = np.vstack([cut, layout]).min(axis=0)
    w, h = grid_plan.window[2:]

    def sheets_reached(points: np.ndarray) -> set[str]:  # in the grid's mm, the drawing's box corner at the shift
        placed = points - low + grid_plan.shift
        return {s.label for s in grid_plan.sheets
                if np.any(np.all((placed >= s.offset) & (placed <= np.add(s.offset, (w, h))), axis=1))}

    box = np.stack(np.meshgrid(*(np.linspace(a, b, 400) for a, b in zip(cut.min(axis=0), cut.max(axis=0)))), -1)
    box = box.reshape(-1, 2)
    allowance_area = box[Outline(np.vstack([cut, cut[:1]]), closed=True).contains_points(box)]
    a, b = np.meshgrid(np.linspace(0, 1, 40), np.linspace(0, 1, 40))
    weights = np.column_stack([a[a + b <= 1], b[a + b <= 1], 1 - a[a + b <= 1] - b[a + b <= 1]])
    triangles = np.vstack([weights @ layout[f] for f in faces])
    reached = sheets_reached(allowance_area)
    assert reached - sheets_reached(triangles), "no sheet holds allowance alone: the case is not tested"
    assert reached <= kept and len(kept) < len(grid_plan.sheets), (reached, kept)


def test_the_command_takes_an_allowance_with_its_unit_and_refuses_what_ignores_it(tmp_path):
    mesh = SCANS / "bunny_face.obj"
    ran = subprocess.run([SPRINGFLAT, "flatten", str(mesh), "--units", "m", "--seam-allowance", "10mm",
                          "--out", str(tmp_path / "a.dxf")], capture_output=True, text=True)
    assert ran.returncode == 0, ran.stderr
    ran = subprocess.run([SPRINGFLAT, "flatten", str(mesh), "--units", "m", "--seam-allowance", "0.01",
                          "--out", str(tmp_path / "b.dxf")], capture_output=True, text=True)
    assert ran.returncode == 0, ran.stderr
    assert (tmp_path / "a.dxf").read_bytes() == (tmp_path / "b.dxf").read_bytes()
    ran = subprocess.run([SPRINGFLAT, "flatten", str(mesh), "--units", "m", "--seam-allowance", "0.007m",
                          "--out", str(tmp_path / "c.svg"), "--json"], capture_output=True, text=True)
    assert ran.returncode == 0 and json.loads(ran.stdout)["seam_allowance"] == 0.007  # as given: no round trip
    (tmp_path / "c.svg").unlink()
    for args, message in (
            (["--seam-allowance", "10", "--out", str(tmp_path / "c.obj")],
             r"--seam-allowance draws the cut line outside the pattern's edge: add a \.dxf, \.pdf or \.svg --out"),
            (["--seam-allowance", "10"], r"--seam-allowance draws the cut line"),
            (["--seam-allowance=-2", "--out", str(tmp_path / "c.dxf")],
             r"argument --seam-allowance: expected a length of 0 or more, got '-2'"),
            (["--seam-allowance", "1 foot", "--out", str(tmp_path / "c.dxf")],
             r"argument --seam-allowance: expected a length such as 10, 10mm or 0\.375in, got '1 foot'"),
            (["--units", "m", "--seam-allowance", "10", "--out", str(tmp_path / "c.pdf")],  # 10 m, meant as mm
             r"^springflat: error: a seam allowance of 10 m \(10000 mm\) is more than half the length of the "
             r"pattern's edge, 0\.\d+ m \(\d+\.\d+ mm\): check its length and unit"),
            (["--seam-allowance", "1e200", "--out", str(tmp_path / "c.dxf")], r"is more than half the length")):
        ran = subprocess.run([SPRINGFLAT, "flatten", str(mesh), *args], capture_output=True, text=True)
        assert ran.returncode == 2 and len(ran.stderr.strip().splitlines()) == 1, ran.stderr
        assert re.search(message, ran.stderr), ran.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.dxf", "b.dxf"]


def test_the_api_writes_an_allowance_and_refuses_it_where_it_would_be_ignored(tmp_path):
    import springflat
    from sim.outputs import OutputError

    V, F = springflat.read_mesh(SCANS / "bunny_face.obj")
    pattern = springflat.flatten(V, F, name="bunny_face")
    springflat.write_pattern(tmp_path / "p.svg", pattern, units="m", seam_allowance="10mm")
    assert ET.parse(tmp_path / "p.svg").getroot().find(f".//{SVG}polygon[@id='sew']") is not None
    with pytest.raises(OutputError, match=r"^write_pattern: seam_allowance draws the cut line of a DXF, PDF or SVG"):
        springflat.write_pattern(tmp_path / "p.obj", pattern, units="m", seam_allowance=0.01)
    with pytest.raises(PatternError, match=r"^write_pattern: a seam allowance is a length of 0 or more, got -1"):
        springflat.write_pattern(tmp_path / "q.pdf", pattern, units="m", seam_allowance=-1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.svg"]


def test_the_pdf_draws_the_sew_line_dashed(tmp_path):
    from pypdf import PdfReader

    mesh, layout = rectangle(185.0, 100.0)
    forms = {}
    for name, drawing in (("plain", PatternDrawing.of(mesh, layout, "mm")),
                          ("seamed", PatternDrawing.of(mesh, layout, "mm").with_seam(10.0))):
        write_pattern_file(tmp_path / f"{name}.pdf", drawing)
        page = PdfReader(tmp_path / f"{name}.pdf").pages[0]
        forms[name] = b"".join(x.get_object().get_data() for x in page["/Resources"]["/XObject"].values())
    assert b"[3 1.5] 0 d" in forms["seamed"] and b"[3 1.5] 0 d" not in forms["plain"]


def test_tiled_sheets_overlap_guides_are_not_drawn_like_the_sew_line(tmp_path):
    """On a pattern tiled over several sheets with an allowance, the guides where a neighbour's sheet overlaps
    are a grey chain line, the sew line even black dashes: one is not taken for the other."""
    mesh, layout = rectangle(400.0, 100.0)
    write_pattern_file(tmp_path / "p.svg", PatternDrawing.of(mesh, layout, "mm").with_seam(10.0))
    root = ET.parse(tmp_path / "p.svg").getroot()
    sew = root.find(f".//{SVG}polygon[@id='sew']")
    guides = [line for line in root.iter(f"{SVG}polyline") if line.get("class", "").startswith("overlap-")]
    assert sew is not None and guides
    for guide in guides:
        assert guide.get("stroke-dasharray") != sew.get("stroke-dasharray")
        assert guide.get("stroke") != sew.get("stroke") and len(guide.get("stroke-dasharray").split()) == 4


def _folded_back_strip():
    """A 100 x 20 mm strip whose last 30 mm are folded back over the strip (a fold along x = 70): folded
    triangles, and material (the flap's edge) that the boundary's own polygon does not hold as inside."""
    uv = grid_uv(11, 3, 100.0, 20.0)
    mesh = Mesh(np.column_stack([uv, np.zeros(len(uv))]), grid_faces(11, 3))
    layout = uv.copy()
    beyond = layout[:, 0] > 70.0
    layout[beyond, 0] = 140.0 - layout[beyond, 0]
    layout[beyond, 1] += 5.0  # the flap a little off the strip: it sticks out across its top edge
    return mesh, layout


def test_a_folded_patterns_cut_line_holds_all_its_material():
    from golden_model.mesh import folded_faces

    mesh, layout = _folded_back_strip()
    assert folded_faces(layout, mesh.faces).any()
    cut = seam_outlines(PatternDrawing.of(mesh, layout), 5.0)[0]
    outline = Outline(np.vstack([cut, cut[:1]]), closed=True)
    a, b = np.meshgrid(np.linspace(0, 1, 12), np.linspace(0, 1, 12))
    inside = a + b <= 1
    weights = np.column_stack([a[inside], b[inside], 1 - a[inside] - b[inside]])
    material = np.vstack([weights @ layout[f] for f in mesh.faces])  # points of every triangle, folded or not
    assert outline.contains_points(material).all()
    assert distance_to_loop(material, cut).min() >= 5.0  # the full allowance round it all


def test_a_c_shaped_piece_whose_slit_the_allowances_close_keeps_its_middle_cut_out():
    """A flat ring 100 to 200 mm round with a slit 6 mm wide at its inner edge, and 10 mm of allowance: the
    allowances close the slit, and the ring's empty middle is a hole of the cut line, not material."""
    rings, steps = 6, 120
    gap = 6.0 / 100.0  # the slit's angle at the inner radius
    angle = np.linspace(gap / 2, 2 * np.pi - gap / 2, steps)
    radius = np.linspace(100.0, 200.0, rings)
    layout = np.array([[r * np.cos(a), r * np.sin(a)] for r in radius for a in angle])
    faces = grid_faces(steps, rings)
    mesh = Mesh(np.column_stack([layout, np.zeros(len(layout))]), faces)
    loops = seam_outlines(PatternDrawing.of(mesh, layout), 10.0)
    assert len(loops) == 2
    outer, hole = (Outline(np.vstack([loop, loop[:1]]), closed=True) for loop in loops)
    assert hole.contains_point((0.0, 0.0))  # the middle is cut out
    assert outer.contains_points(layout).all() and not hole.contains_points(layout).any()
    assert min(distance_to_loop(layout, loop).min() for loop in loops) >= 10.0
