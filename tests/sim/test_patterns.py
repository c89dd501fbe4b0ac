"""Pattern files read back by independent readers: ezdxf's recover and audit, pypdf, ElementTree, trimesh."""

import json
import math
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from sim.generate import dome_grid
from golden_model.mesh import Mesh
from sim.mesh_io import load_mesh, read_obj
from sim.distortion import DISTORTION_HEADER, distortion, worst_summary, write_distortion_csv
from sim.patterns import (MAX_SHEETS, OVERLAP_MM, PatternDrawing, PatternError, plan_sheets, write_pattern_file)
from support import SCANS, SPRINGFLAT

SVG = "{http://www.w3.org/2000/svg}"
INKSCAPE = "{http://www.inkscape.org/namespaces/inkscape}"
#: millimetres per unit: physical facts, not the code's table
MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
PT = 25.4 / 72.0  # mm per PDF point


@pytest.fixture(scope="module")
def bunny():
    """bunny_face.obj (metres) flattened with the file defaults of the command line."""
    import springflat

    V, F = springflat.read_mesh(SCANS / "bunny_face.obj")
    pattern = springflat.flatten(V, F, name="bunny_face")
    assert pattern.status == "converged" and pattern.folded == 0
    return pattern.mesh, pattern.layout


def boundary_length(mesh: Mesh, layout: np.ndarray) -> float:
    """The closed boundary's length, from the mesh's boundary edges (each in exactly one face)."""
    directed = np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]])
    key = np.sort(directed, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = key[counts[inverse.ravel()] == 1]
    return float(np.linalg.norm(layout[boundary[:, 0]] - layout[boundary[:, 1]], axis=1).sum())


# --------------------------------------------------------------------------- DXF


@pytest.mark.slow
@pytest.mark.parametrize("units, insunits", [("m", 6), ("mm", 4), ("cm", 5), ("in", 1)])
def test_dxf_has_a_closed_cut_line_of_the_patterns_length_and_declares_its_units(bunny, tmp_path, units, insunits):
    import ezdxf
    from ezdxf import recover

    mesh, layout = bunny
    path = tmp_path / "bunny.dxf"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, units), dxf_edges=units == "m")
    doc, auditor = recover.readfile(path)
    assert not auditor.has_errors, [str(e) for e in auditor.errors]
    assert not doc.audit().has_errors
    assert doc.header["$INSUNITS"] == insunits
    assert doc.header["$MEASUREMENT"] == (0 if units == "in" else 1)
    assert doc.units == insunits and ezdxf.units.unit_name(doc.units).lower().startswith(
        {"m": "meter", "mm": "milli", "cm": "centi", "in": "inch"}[units])
    cut = doc.modelspace().query('*[layer=="CUT"]')
    assert [e.dxftype() for e in cut] == ["LWPOLYLINE"]
    polyline = cut[0]
    assert polyline.closed
    points = np.array([p[:2] for p in polyline.get_points("xy")])
    length = float(np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1).sum())
    assert length == pytest.approx(boundary_length(mesh, layout), rel=1e-9)
    assert len(points) == len(mesh.boundary_loop)
    lines = doc.modelspace().query('LINE[layer=="MESH"]')
    assert len(lines) == (mesh.n_edges if units == "m" else 0)
    # the extents a viewer zooms to: those of what is drawn (ezdxf's bounding box of the entities)
    box = ezdxf.bbox.extents(doc.modelspace())
    size = float(np.max(box.size))
    assert np.allclose(doc.header["$EXTMIN"], box.extmin, rtol=0, atol=1e-9 * size)
    assert np.allclose(doc.header["$EXTMAX"], box.extmax, rtol=0, atol=1e-9 * size)


def test_dxf_without_edges_has_only_the_cut_line(bunny, tmp_path):
    from ezdxf import recover

    mesh, layout = bunny
    path = tmp_path / "cut.dxf"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m"))
    doc, auditor = recover.readfile(path)
    assert not auditor.has_errors
    assert [e.dxftype() for e in doc.modelspace()] == ["LWPOLYLINE"]
    assert doc.ezdxf_metadata()["springflat_units"] == "m"


# --------------------------------------------------------------------------- PDF


def _matrix(a, b, c, d, e, f) -> np.ndarray:
    return np.array([[a, b, 0.0], [c, d, 0.0], [e, f, 1.0]], dtype=float)


def pdf_page_contents(reader, page):
    """A small PDF interpreter: the page's painted paths and shown text, in mm on the page.

    Returns ``(paths, texts)``: ``paths`` is a list of ``(subpaths, operator)``, each subpath a list of
    ``(x, y)`` mm; ``texts`` a list of ``(text, (x, y) mm of its origin)``.  Handles q/Q/cm, path
    construction (m l h re), painting operators, form XObjects (Do with their /Matrix) and BT/Tm/Td/Tj.
    """
    from pypdf.generic import ContentStream

    paths, texts = [], []

    def point(ctm, x, y):
        p = np.array([float(x), float(y), 1.0]) @ ctm
        return p[0] * PT, p[1] * PT

    def run(content, ctm, resources):
        stack, subpaths, tm = [], [], np.eye(3)
        for operands, op in ContentStream(content, reader).operations:
            op = op.decode() if isinstance(op, bytes) else op
            if op == "q":
                stack.append(ctm)
            elif op == "Q":
                ctm = stack.pop()
            elif op == "cm":
                ctm = _matrix(*map(float, operands)) @ ctm
            elif op == "m":
                subpaths.append([point(ctm, *operands)])
            elif op == "l":
                subpaths[-1].append(point(ctm, *operands))
            elif op == "re":
                x, y, w, h = map(float, operands)
                subpaths.append([point(ctm, x, y), point(ctm, x + w, y), point(ctm, x + w, y + h),
                                 point(ctm, x, y + h)])
            elif op in ("S", "s", "f", "F", "f*", "B", "B*", "b", "b*", "n"):
                if op != "n":
                    paths.append((subpaths, op))
                subpaths = []
            elif op == "BT":
                tm = np.eye(3)
            elif op == "Tm":
                tm = _matrix(*map(float, operands))
            elif op == "Td":
                tm = _matrix(1, 0, 0, 1, *map(float, operands)) @ tm
            elif op == "Tj":
                texts.append((str(operands[0]), point(tm @ ctm, 0, 0)))
            elif op == "Do":
                xobject = resources["/XObject"][operands[0]].get_object()
                matrix = _matrix(*map(float, xobject.get("/Matrix", [1, 0, 0, 1, 0, 0])))
                run(xobject, matrix @ ctm, xobject.get("/Resources", resources))

    run(page.get_contents(), np.eye(3), page["/Resources"])
    return paths, texts


def scale_bar_check(paths, texts) -> tuple[float, float]:
    """``(printed length mm, stated length mm)`` of the scale bar: the label ``<n> <unit>`` and the
    horizontal two-point stroke just under it, spanning the label's origin."""
    stated = [(t, xy) for t, xy in texts if re.fullmatch(r"[\d.]+ (mm|cm|m|in)( \(.*\))?", t)]
    assert len(stated) == 1, texts
    text, (tx, ty) = stated[0]
    number, unit = re.match(r"([\d.]+) (mm|cm|m|in)", text).groups()
    bars = []
    for subpaths, op in paths:
        for sub in subpaths:
            if op == "S" and len(sub) == 2 and abs(sub[0][1] - sub[1][1]) < 1e-6:
                (x1, y), (x2, _) = sub
                if min(x1, x2) <= tx <= max(x1, x2) and 0 < ty - y < 6:
                    bars.append(abs(x2 - x1))
    assert len(bars) == 1, bars
    return bars[0], float(number) * MM[unit]


def test_pdf_page_size_and_scale_bar_are_true_to_a_tenth_of_a_millimetre(bunny, tmp_path):
    from pypdf import PdfReader

    mesh, layout = bunny
    path = tmp_path / "bunny.pdf"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m", "converged"), paper="a4")
    reader = PdfReader(path)
    assert len(reader.pages) == 1
    page = reader.pages[0]
    width, height = float(page.mediabox.width) * PT, float(page.mediabox.height) * PT
    assert abs(width - 210.0) < 0.1 and abs(height - 297.0) < 0.1
    paths, texts = pdf_page_contents(reader, page)
    printed, stated = scale_bar_check(paths, texts)
    assert abs(printed - stated) < 0.1
    words = " ".join(t for t, _ in texts)
    assert "bunny_face" in words and "units m" in words and "scale 1:1" in words
    # the cut line: the closed path with one corner per boundary vertex, at 1:1 (metres on paper)
    cut = [np.array(sub) for subpaths, op in paths for sub in subpaths if len(sub) == len(mesh.boundary_loop)]
    assert len(cut) == 1
    extent_mm = cut[0].max(axis=0) - cut[0].min(axis=0)
    expected = (layout[mesh.boundary_loop].max(axis=0) - layout[mesh.boundary_loop].min(axis=0)) * 1000.0
    np.testing.assert_allclose(extent_mm, expected, atol=0.01)
    printed_length = float(np.linalg.norm(np.roll(cut[0], -1, axis=0) - cut[0], axis=1).sum())
    assert printed_length == pytest.approx(boundary_length(mesh, layout) * 1000.0, abs=0.1)
    assert reader.metadata.title.startswith("bunny_face")
    assert reader.trailer["/Root"]["/ViewerPreferences"]["/PrintScaling"] == "/None"  # the dialog's default: 100 %
    assert reader.pdf_header == "%PDF-1.6"  # the version that has /PrintScaling


@pytest.mark.slow
def test_pdf_of_a_large_pattern_is_tiled_with_overlap_marks_on_letter(tmp_path):
    from pypdf import PdfReader

    mesh = load_mesh(SCANS / "armadillo_strip.obj")  # about 0.27 x 0.62 of a unit flat: metres here
    layout = mesh.vertices[:, [0, 1]]  # the projection: a stand-in layout, no run needed
    drawing = PatternDrawing.of(mesh, layout, "m")
    path = tmp_path / "armadillo.pdf"
    write_pattern_file(path, drawing, paper="letter", turn=False)  # the tiling as laid (turning: its own tests)
    reader = PdfReader(path)
    size = (np.ptp(layout, axis=0) * 1000.0).tolist()
    plan = plan_sheets(tuple(size), "letter")
    assert 1 < len(reader.pages) <= len(plan.sheets)
    page_mm = sorted((215.9, 279.4), reverse=plan.landscape)
    labels = []
    cut_points = len(mesh.boundary_loop)
    shown = np.zeros(cut_points, bool)
    for page in reader.pages:
        assert abs(float(page.mediabox.width) * PT - page_mm[0]) < 0.1
        assert abs(float(page.mediabox.height) * PT - page_mm[1]) < 0.1
        paths, texts = pdf_page_contents(reader, page)
        # the page shows part of the pattern, and together the pages show all of it: the cut line in page
        # mm (the form placed; the clip to the window not applied) against the window
        cut = np.array(next(sub for subpaths, op in paths for sub in subpaths if len(sub) == cut_points))
        x, y, w, h = plan.window
        inside = (cut[:, 0] >= x) & (cut[:, 0] <= x + w) & (cut[:, 1] >= y) & (cut[:, 1] <= y + h)
        assert inside.any()
        shown |= inside
        printed, stated = scale_bar_check(paths, texts)
        assert abs(printed - stated) < 0.1
        words = " ".join(t for t, _ in texts)
        labels.append(re.search(r"sheet (\w+) of (\d+)", words).groups())
        assert "overlaps here" in words
        dashed = [sub for subpaths, op in paths for sub in subpaths if op == "S"]
        assert dashed
    assert shown.all()
    assert [int(n) for _, n in labels] == [len(reader.pages)] * len(reader.pages)
    assert len({label for label, _ in labels}) == len(reader.pages)


def test_a_sheet_that_would_be_blank_is_left_out_and_said(tmp_path):
    """A diagonal strip on a 3 x 3 grid of sheets: the corners away from the diagonal hold nothing."""
    from pypdf import PdfReader

    t = np.linspace(0.0, 1.0, 60)
    along = np.column_stack([t * 520.0, t * 700.0])  # mm, corner to corner of 3 x 3 portrait A4 windows
    across = np.array([-12.0, 12.0]) / math.sqrt(2)
    vertices = np.vstack([along + across, along - across])
    n = len(t)
    faces = np.array([f for k in range(n - 1) for f in ((k, n + k, k + 1), (k + 1, n + k, n + k + 1))])
    mesh = Mesh(np.column_stack([vertices, np.zeros(2 * n)]), faces)
    path = tmp_path / "strip.pdf"
    write_pattern_file(path, PatternDrawing.of(mesh, vertices, "mm"), paper="a4", turn=False)  # (as laid)
    plan = plan_sheets(tuple(np.ptp(vertices, axis=0).tolist()), "a4")
    assert (plan.rows, plan.cols) == (3, 3)
    reader = PdfReader(path)
    words = [" ".join(t for t, _ in pdf_page_contents(reader, page)[1]) for page in reader.pages]
    labels = sorted(re.search(r"sheet (\w+) of", w).group(1) for w in words)
    # from the bottom left (C1) to the top right (A3): the other two corners hold nothing of it
    assert {"C1", "B2", "A3"} <= set(labels) and not {"A1", "C3"} & set(labels)
    said = f"{len(labels)} A4 portrait sheets (3 columns x 3 rows, {9 - len(labels)} blank left out, overlap 10 mm)"
    assert all(said in w for w in words)


def test_a_sheet_crossed_only_by_folded_triangles_is_printed(tmp_path):
    """A square fan whose centre node lies far outside it: four long folded triangles cross windows that
    hold no node and lie outside the cut line, and they are drawn there."""
    from pypdf import PdfReader

    vertices = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 300.0], [0.0, 300.0], [150.0, 150.0]])
    faces = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    mesh = Mesh(np.column_stack([vertices, np.zeros(5)]), faces)
    layout = vertices.copy()
    layout[4] = (1500.0, 150.0)
    path = tmp_path / "fan.pdf"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "mm"), paper="a4")
    plan = plan_sheets(tuple(np.ptp(layout, axis=0).tolist()), "a4")
    reader = PdfReader(path)
    printed = {re.search(r"sheet (\w+) of", " ".join(t for t, _ in pdf_page_contents(reader, page)[1])).group(1)
               for page in reader.pages}
    # where the triangles are, by dense sampling, in the grid's frame (the layout's box corner at plan.shift)
    a, b = np.meshgrid(np.linspace(0, 1, 300), np.linspace(0, 1, 300))
    inside = (a + b) <= 1
    weights = np.column_stack([a[inside], b[inside], 1 - a[inside] - b[inside]])
    samples = np.vstack([weights @ layout[f] for f in faces]) - layout.min(axis=0) + plan.shift
    w, h = plan.window[2:]
    hit = {s.label for s in plan.sheets
           if np.any(np.all((samples >= s.offset) & (samples <= np.add(s.offset, (w, h))), axis=1))}
    assert len(hit) > 4 and hit <= printed, (hit, printed)


# --------------------------------------------------------------------------- SVG


def test_svg_sheet_scale_bar_and_cut_line_at_true_scale(bunny, tmp_path):
    mesh, layout = bunny
    path = tmp_path / "bunny.svg"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m"), paper="a4")
    root = ET.parse(path).getroot()
    assert (root.get("width"), root.get("height"), root.get("viewBox")) == ("210mm", "297mm", "0 0 210 297")
    bar = root.find(f".//{SVG}polyline[@class='scale-bar']")
    (x1, y1), (x2, y2) = [tuple(map(float, p.split(","))) for p in bar.get("points").split()]
    label = root.find(f".//{SVG}text[@class='scale-label']").text
    number, unit = re.match(r"([\d.]+) (mm|cm|m|in)", label).groups()
    assert y1 == y2 and abs(abs(x2 - x1) - float(number) * MM[unit]) < 0.1
    cut = np.array([p.split(",") for p in root.find(f".//{SVG}polygon[@id='cut']").get("points").split()], float)
    np.testing.assert_allclose(np.ptp(cut, axis=0), np.ptp(layout[mesh.boundary_loop], axis=0) * 1000, atol=1e-3)
    title = root.find(f"{SVG}title").text
    assert "bunny_face" in title and "units m" in title


def test_svg_tiles_each_sheet_as_a_page(tmp_path):
    mesh = load_mesh(SCANS / "armadillo_strip.obj")
    layout = mesh.vertices[:, [0, 1]]
    path = tmp_path / "armadillo.svg"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m"), paper="a4", turn=False)  # (as laid)
    root = ET.parse(path).getroot()
    pages = root.findall(f".//{INKSCAPE}page")
    plan = plan_sheets(tuple((np.ptp(layout, axis=0) * 1000.0).tolist()), "a4")
    assert len(pages) == len(plan.sheets) == len(root.findall(f"{SVG}g")) > 1
    assert {(float(p.get("width")), float(p.get("height"))) for p in pages} == {plan.page}
    assert len(root.findall(f".//{SVG}polyline[@class='scale-bar']")) == len(plan.sheets)


# --------------------------------------------------------------------------- OBJ


def _similarity_residual(source: np.ndarray, target: np.ndarray) -> float:
    """Largest distance after the best similarity (scale, rotation, shift; no mirror) of source onto target."""
    a, b = source - source.mean(axis=0), target - target.mean(axis=0)
    u, s, vt = np.linalg.svd(a.T @ b)
    sign = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])  # Kabsch: a proper rotation only
    rotation = u @ sign @ vt
    scale = (s * np.diag(sign)).sum() / (a ** 2).sum()
    return float(np.abs(scale * a @ rotation - b).max())


def test_obj_is_the_3d_mesh_with_the_pattern_as_vt(bunny, tmp_path):
    import trimesh

    mesh, layout = bunny
    path = tmp_path / "bunny.obj"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m"))
    loaded = trimesh.load(path, process=False, maintain_order=True)
    np.testing.assert_array_equal(loaded.vertices, mesh.vertices)
    np.testing.assert_array_equal(loaded.faces, mesh.faces)
    uv = np.asarray(loaded.visual.uv)
    assert uv.shape == (mesh.n_vertices, 2) and uv.min() >= 0 and uv.max() <= 1
    size = float(np.ptp(layout, axis=0).max())
    assert _similarity_residual(uv, layout) < 1e-9 * size
    assert "in m" in path.read_text().splitlines()[0]


def test_flat_obj_keeps_the_layout_with_z_0(bunny, tmp_path):
    mesh, layout = bunny
    path = tmp_path / "bunny.flat.obj"
    write_pattern_file(path, PatternDrawing.of(mesh, layout, "m"))
    obj = read_obj(path)
    np.testing.assert_array_equal(obj.vertices[:, :2], layout)
    assert (obj.vertices[:, 2] == 0).all() and obj.faces.tolist() == mesh.faces.tolist()


# --------------------------------------------------------------------------- sheets and refusals


@pytest.mark.parametrize("size", [(50.0, 60.0), (189.9, 244.9), (400.0, 100.0), (1000.0, 700.0), (190.0, 1200.0)])
def test_sheet_windows_cover_the_pattern_and_overlap_by_the_stated_strip(size):
    plan = plan_sheets(size, "a4")
    x, y, w, h = plan.window
    assert x >= 10 and y >= 10 and x + w <= plan.page[0] - 10 + 1e-9 and y + h <= plan.page[1] - 10 + 1e-9
    assert sorted(plan.page) == [210.0, 297.0]
    # every point of the pattern (shifted onto the grid) falls in some sheet's window
    grid = np.stack(np.meshgrid(np.linspace(0, size[0], 41), np.linspace(0, size[1], 41)), -1).reshape(-1, 2)
    grid += plan.shift
    inside = np.zeros(len(grid), bool)
    for sheet in plan.sheets:
        ox, oy = sheet.offset
        inside |= (grid[:, 0] >= ox - 1e-9) & (grid[:, 0] <= ox + w + 1e-9) & \
                  (grid[:, 1] >= oy - 1e-9) & (grid[:, 1] <= oy + h + 1e-9)
    assert inside.all()
    if plan.cols > 1:
        a = next(s for s in plan.sheets if (s.row, s.col) == (0, 0))
        b = next(s for s in plan.sheets if (s.row, s.col) == (0, 1))
        assert (a.offset[0] + w) - b.offset[0] == pytest.approx(OVERLAP_MM)
    # one sheet fewer in either direction would not cover it
    assert plan.cols == 1 or w + (plan.cols - 2) * (w - OVERLAP_MM) < size[0]
    assert plan.rows == 1 or h + (plan.rows - 2) * (h - OVERLAP_MM) < size[1]
    assert len({s.label for s in plan.sheets}) == len(plan.sheets) == plan.rows * plan.cols


def test_landscape_when_it_needs_fewer_sheets_and_fit_is_one_page():
    assert not plan_sheets((100.0, 200.0), "a4").landscape
    assert plan_sheets((260.0, 150.0), "a4").landscape and len(plan_sheets((260.0, 150.0), "a4").sheets) == 1
    fit = plan_sheets((1500.0, 900.0), "fit")
    assert len(fit.sheets) == 1 and fit.window[2] >= 1500.0 and fit.window[3] >= 900.0
    assert plan_sheets((1.0, 1.0), "letter").page == (215.9, 279.4)


def test_refusals_leave_no_file(tmp_path):
    mesh = dome_grid(5)
    drawing = PatternDrawing.of(mesh, mesh.vertices[:, :2] * 1e4, "m")  # tens of kilometres at 1:1
    with pytest.raises(PatternError, match=f"at most {MAX_SHEETS}"):
        write_pattern_file(tmp_path / "huge.pdf", drawing)
    xy = mesh.vertices[:, :2] - mesh.vertices[:, :2].min(axis=0)
    strip = PatternDrawing.of(mesh, xy / xy.max(axis=0) * (5.5, 1.0), "m")  # 5.5 x 1 m: 147 a4 sheets, 150 letter
    for suffix in (".pdf", ".svg"):  # one page of tens of kilometres is none a viewer opens, nor are 10^6 sheets
        with pytest.raises(PatternError, match=r"a page larger than a PDF's 5.08 m a side \(an SVG's pages are the "
                                               r"PDF's\); check --units, or write \.dxf$"):
            write_pattern_file(tmp_path / f"huge{suffix}", drawing, paper="fit")
        with pytest.raises(PatternError, match=r"the pattern is 5.5 x 1 m .*; check --units, print it tiled "
                                               r"\(--paper a4, a3 or letter\), or write \.dxf$"):
            write_pattern_file(tmp_path / f"strip{suffix}", strip, paper="fit", turn=False)
    write_pattern_file(tmp_path / "strip.pdf", strip, paper="letter")  # as suggested
    assert (tmp_path / "strip.pdf").stat().st_size > 0
    (tmp_path / "strip.pdf").unlink()
    astronomical = PatternDrawing.of(mesh, mesh.vertices[:, :2] * 1e150, "m")
    # (1e153 mm)² over a window of about 270 x 170 mm: some 2e301 sheets, as a count, not 302 digits
    with pytest.raises(PatternError, match=r": 2\.\de\+301 a4 sheets \(at most"):
        write_pattern_file(tmp_path / "huge.pdf", astronomical)
    with pytest.raises(PatternError, match="must end in"):
        write_pattern_file(tmp_path / "x.txt", drawing)
    with pytest.raises(PatternError, match="units must be one of"):
        PatternDrawing.of(mesh, mesh.vertices[:, :2], "ft")
    assert list(tmp_path.iterdir()) == []


def test_every_format_is_reproducible_byte_for_byte(tmp_path):
    mesh = dome_grid(7)
    drawing = PatternDrawing.of(mesh, mesh.vertices[:, :2] * 100, "mm", "a caption")
    for ending in ("dxf", "pdf", "svg", "obj", "flat.obj"):
        write_pattern_file(tmp_path / f"a.{ending}", drawing, dxf_edges=True)
        write_pattern_file(tmp_path / f"b.{ending}", drawing, dxf_edges=True)
        assert (tmp_path / f"a.{ending}").read_bytes() == (tmp_path / f"b.{ending}").read_bytes(), ending
    for ending in ("dxf", "pdf", "svg"):  # a seam allowance's cut line, outlined anew for each drawing
        for name in ("c", "d"):
            write_pattern_file(tmp_path / f"{name}.{ending}", PatternDrawing.of(
                mesh, mesh.vertices[:, :2] * 100, "mm", "a caption").with_seam(5.0).with_grain("x"))
        assert (tmp_path / f"c.{ending}").read_bytes() == (tmp_path / f"d.{ending}").read_bytes(), ending


# --------------------------------------------------------------------------- distortion


def test_distortion_of_a_uniformly_scaled_flat_mesh():
    """A flat mesh laid out at twice its size: every area ratio 4, every strain 1 (by geometry)."""
    mesh = dome_grid(6)
    flat = Mesh(np.column_stack([mesh.vertices[:, :2], np.zeros(mesh.n_vertices)]), mesh.faces)
    d = distortion(flat, 2.0 * mesh.vertices[:, :2])
    np.testing.assert_allclose(d.area_ratio, 4.0, rtol=1e-12)
    np.testing.assert_allclose(d.strain, 1.0, rtol=1e-12)
    assert not d.folded.any()


def test_worst_one_percent_finds_the_moved_vertex(tmp_path):
    mesh = dome_grid(21)  # 800 faces: the worst 1 % is 8 faces
    flat = Mesh(np.column_stack([mesh.vertices[:, :2], np.zeros(mesh.n_vertices)]), mesh.faces)
    layout = mesh.vertices[:, :2].copy()
    centre = 10 * 21 + 10
    layout[centre] += [0.3 / 20, 0.0]
    d = distortion(flat, layout)
    summary = worst_summary(d)
    around = set(np.flatnonzero((mesh.faces == centre).any(axis=1)).tolist())
    assert summary["area_ratio"]["worst_count"] == math.ceil(0.01 * mesh.n_faces) == 8
    assert summary["area_ratio"]["worst_face"] in around
    assert set(summary["edge_strain"]["worst_edge"]) & {centre}
    low, high = summary["area_ratio"]["worst_band"]
    outside = (d.area_ratio < low - 1e-12) | (d.area_ratio > high + 1e-12)
    assert outside.sum() < 8 and set(np.flatnonzero(outside).tolist()) <= around
    path = tmp_path / "d.csv"
    write_distortion_csv(path, d, "cm")
    rows = path.read_text().splitlines()
    assert rows[0].split(",") == list(DISTORTION_HEADER)
    assert len(rows) == 1 + mesh.n_faces + mesh.n_edges
    face = rows[1].split(",")
    assert face[0] == "face" and face[5] == "cm^2" and float(face[8]) == d.area_ratio[0]
    edge = rows[1 + mesh.n_faces].split(",")
    assert edge[0] == "edge" and edge[5] == "cm" and float(edge[9]) == d.strain[0]


# --------------------------------------------------------------------------- the command


@pytest.mark.slow
def test_flatten_writes_every_format_at_once_with_distortion_and_units(tmp_path):
    outs = [tmp_path / f"b.{e}" for e in ("dxf", "pdf", "svg", "obj", "flat.obj")]
    args = [a for out in outs for a in ("--out", out)]
    proc = subprocess.run([SPRINGFLAT, "flatten", str(SCANS / "bunny_ear.obj"), "--units", "m", *map(str, args),
                           "--distortion", str(tmp_path / "d.csv"), "--json"], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["units"] == "m"
    worst = summary["distortion"]
    assert worst["faces"] == summary["faces"]
    assert worst["area_ratio"]["worst_count"] == math.ceil(0.01 * summary["faces"])
    assert all(out.stat().st_size > 0 for out in outs)
    assert "note" not in proc.stderr


def test_a_pattern_too_small_for_its_units_gets_a_note(tmp_path):
    proc = subprocess.run([SPRINGFLAT, "flatten", str(SCANS / "bunny_ear.obj"), "--max-iter", "3",
                           "--out", str(tmp_path / "b.pdf")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"note: the pattern is [\d.]+ x [\d.]+ mm at 1:1 with --units mm", proc.stderr)


@pytest.mark.parametrize("units, suggested", [
    ("mm", "if the mesh is in metres, centimetres or inches, say so with --units m, --units cm or --units in"),
    ("cm", "if the mesh is in metres or inches, say so with --units m or --units in"),
    ("in", "if the mesh is in metres, say so with --units m"),
    ("m", None),
])
def test_the_small_pattern_note_suggests_only_larger_units_than_the_one_given(units, suggested):
    """A pattern under 10 mm at 1:1: the unit given is not suggested back, nor a smaller one."""
    from sim.patterns import scale_note

    mesh = dome_grid(5)
    drawing = PatternDrawing.of(mesh, mesh.vertices[:, :2] * 0.05 / MM[units], units)  # 0.05 mm wide
    note = scale_note(drawing)
    assert note.startswith("the pattern is 0.05 x 0.05 mm at 1:1 with --units " + units)
    assert (note.split(": ", 1)[1] if ": " in note else None) == suggested


def test_a_fit_page_beyond_a_pdfs_largest_is_refused_before_the_run(tmp_path):
    proc = subprocess.run([SPRINGFLAT, "flatten", str(SCANS / "nefertiti_face.obj"), "--units", "m", "--paper", "fit",
                           "--out", str(tmp_path / "n.pdf")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.splitlines() == ["springflat: error: the mesh's area is about 189 x 189 m at 1:1 with --units m: "
                                        "a page larger than a PDF's 5.08 m a side (an SVG's pages are the PDF's); "
                                        "check --units, or write .dxf"]  # (no paper prints that area in 400 sheets)
    assert list(tmp_path.iterdir()) == []


def test_a_print_of_too_many_sheets_is_refused_before_the_run(tmp_path):
    """nefertiti_face is in millimetres: read as metres it would be about 190 m across."""
    proc = subprocess.run([SPRINGFLAT, "flatten", str(SCANS / "nefertiti_face.obj"), "--units", "m",
                           "--out", str(tmp_path / "n.dxf"), "--out", str(tmp_path / "n.pdf")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.splitlines() == [f"springflat: error: the mesh's area is about 189 x 189 m at 1:1 with "
                                        f"--units m: more than {MAX_SHEETS} a4 sheets; check --units, or write .dxf"]
    assert list(tmp_path.iterdir()) == []


def _svg_boxes(path):
    """Per sheet of an SVG: ``(texts, strokes)``, each a list of ``(x0, y0, x1, y1)`` boxes in page mm
    (y down). A text's box from reportlab's Helvetica widths (Arial's are the same), a character beyond
    Latin-1 (drawn in a fallback font) 1 em wide, and its font size: 0.22 em below the baseline to 0.75 em
    above it."""
    from reportlab.pdfbase.pdfmetrics import stringWidth

    root = ET.parse(path).getroot()
    sheets = []
    for group in root.findall(f"{SVG}g"):
        texts, strokes = [], []
        for text in group.findall(f"{SVG}text"):
            size = float(text.get("font-size"))
            latin = "".join(c for c in text.text if ord(c) < 256)
            width = stringWidth(latin, "Helvetica-Bold" if text.get("font-weight") == "bold" else "Helvetica",
                                size) + (len(text.text) - len(latin)) * size
            x = float(text.get("x")) - {"start": 0, "middle": width / 2, "end": width}[text.get("text-anchor", "start")]
            y = float(text.get("y"))
            texts.append((text.text, (x, y - 0.75 * size, x + width, y + 0.22 * size)))
        for line in group.findall(f"{SVG}polyline"):
            points = np.array([p.split(",") for p in line.get("points").split()], float)
            strokes.append((line.get("class"), (*points.min(axis=0), *points.max(axis=0))))
        sheets.append((texts, strokes))
    return sheets


def _overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


@pytest.mark.parametrize("size, paper, units, name", [
    ((300.0, 350.0), "a4", "m", "armadillo_strip"),                   # tiled portrait: 2 x 2 sheets
    ((120.0, 40.0), "fit", "cm", "a_rather_long_mesh_name_from_a_scanner_export_2026-12-04_left_shoe_upper_v2"),
    ((100.0, 150.0), "letter", "in", "ear"),
    ((2000.0, 900.0), "fit", "mm", "panel"),
    ((120.0, 40.0), "fit", "mm", "日本語のメッシュ" * 10),
    ((120.0, 40.0), "fit", "mm", "x" * 20000),  # an API name of any length: set small and shortened, at once
], ids=["tiled-portrait", "fit-long-name", "letter", "fit-wide", "fit-cjk-name", "fit-20000-characters"])
def test_title_block_lines_stay_on_the_page_and_clear_of_each_other_and_the_scale_bar(tmp_path, size, paper, units,
                                                                                     name):
    mesh = dome_grid(6)
    layout = (mesh.vertices[:, :2] - mesh.vertices[:, :2].min(axis=0)) / np.ptp(mesh.vertices[:, :2], axis=0)
    layout = layout * np.array(size) / MM[units]
    drawing = PatternDrawing.of(mesh, layout, units, "converged after 1234 iterations: E_S 0.0123, E_C 0.0456, "
                                                     "0 folded")
    drawing = PatternDrawing(**{**drawing.__dict__, "name": name})
    path = tmp_path / "p.svg"
    write_pattern_file(path, drawing, paper=paper, turn=False)  # (the page as laid)
    plan = plan_sheets(size, paper)
    assert paper != "a4" or (plan.cols, plan.rows, plan.landscape) == (2, 2, False)
    for texts, strokes in _svg_boxes(path):
        scale = [box for kind, box in strokes if kind == "scale-bar"]
        assert len(scale) == 1
        title = [text for text, _ in texts if "springflat cutting pattern" in text]
        assert len(title) == 1 and title[0].endswith(f"scale 1:1, units {units}") and title[0][:3] == name[:3]
        for k, (text, box) in enumerate(texts):
            assert 10 - 1e-6 <= box[0] and box[2] <= plan.page[0] - 10 + 1e-6, (text, box)
            assert 10 - 1e-6 <= box[1] and box[3] <= plan.page[1] - 10 + 1e-6, (text, box)
            assert not _overlap(box, scale[0]), text
            for other, other_box in texts[k + 1:]:
                assert not _overlap(box, other_box), (text, other)


def _diagonal_strip(angle_degrees: float, length: float = 1500.0, width: float = 150.0):
    """A flat strip ``length`` x ``width`` mm laid at ``angle_degrees``: its mesh and layout."""
    t = np.linspace(0.0, 1.0, 40)
    a = math.radians(angle_degrees)
    along = np.column_stack([t * length * math.cos(a), t * length * math.sin(a)])
    across = np.array([-math.sin(a), math.cos(a)]) * width
    layout = np.vstack([along, along + across])
    n = len(t)
    faces = np.array([f for k in range(n - 1) for f in ((k, k + 1, n + k), (k + 1, n + k + 1, n + k))])
    return Mesh(np.column_stack([layout, np.zeros(2 * n)]), faces), layout


@pytest.mark.parametrize("kind", ["pdf", "svg"])
def test_a_diagonal_pattern_is_turned_on_the_sheets_to_take_fewer(tmp_path, kind):
    """A 1.5 m x 15 cm strip laid at 35 degrees: its box as laid is 1.31 x 0.98 m, an 8 x 4 grid of A4 sheets
    (14 printed, the blank ones left out); turned along its length it takes one row of 6 landscape ones. The
    DXF keeps the layout's frame; the turn is a rotation (lengths kept, the front still up), never a mirror."""
    from pypdf import PdfReader

    from sim.patterns import pattern_size_mm, turned_to_fit

    mesh, layout = _diagonal_strip(35.0)
    drawing = PatternDrawing.of(mesh, layout, "mm")
    turned = turned_to_fit(drawing, "a4")
    width, height = sorted(pattern_size_mm(turned))
    assert width == pytest.approx(150.0, abs=1e-6) and height == pytest.approx(1500.0, abs=1e-6)
    edges = mesh.edges
    assert np.allclose(np.linalg.norm(np.diff(turned.layout[edges], axis=1), axis=2),
                       np.linalg.norm(np.diff(layout[edges], axis=1), axis=2), rtol=0, atol=1e-9)

    def signed_areas(xy):
        a, b, c = (xy[mesh.faces[:, k]] for k in range(3))
        (ux, uy), (vx, vy) = (b - a).T, (c - a).T
        return ux * vy - uy * vx

    assert np.allclose(signed_areas(turned.layout), signed_areas(layout))  # turned, not mirrored
    counts = {}
    for turn in (True, False):
        path = tmp_path / f"strip-{turn}.{kind}"
        write_pattern_file(path, drawing, paper="a4", turn=turn)
        counts[turn] = (len(PdfReader(path).pages) if kind == "pdf"
                        else len(ET.parse(path).getroot().findall(f".//{INKSCAPE}page")))
    assert counts == {True: 6, False: 14}, counts
    write_pattern_file(tmp_path / "strip.dxf", drawing)
    import ezdxf

    cut = ezdxf.readfile(tmp_path / "strip.dxf").modelspace().query("LWPOLYLINE")[0]
    assert np.allclose(np.array(cut.get_points("xy")), layout[mesh.boundary_loop], atol=1e-9)


@pytest.mark.parametrize("angle, written", [(35.0, "turned"), (0.0, "as laid")])
def test_the_sheets_a_turn_was_chosen_on_are_the_ones_written(tmp_path, monkeypatch, angle, written):
    """Finding a large pattern's blank sheets takes as long as the rest of the turn's choice: the plan that
    decided it is the one printed, not found a second time (a strip at 35 degrees: as laid and turned,
    two; along x already, the grid's sheets decide and the laid one is found once)."""
    import sim.patterns

    found = []
    counted = sim.patterns.without_blank_sheets
    monkeypatch.setattr(sim.patterns, "without_blank_sheets", lambda plan, d: found.append(d) or counted(plan, d))
    mesh, layout = _diagonal_strip(angle)
    write_pattern_file(tmp_path / "strip.pdf", PatternDrawing.of(mesh, layout, "mm"), paper="a4")
    assert len(found) == (2 if written == "turned" else 1)


def test_a_pattern_that_turning_would_not_save_a_sheet_is_left_as_laid():
    from sim.patterns import turned_to_fit

    mesh, layout = _diagonal_strip(0.0)  # along x already: as few sheets as any turn gives
    drawing = PatternDrawing.of(mesh, layout, "mm")
    assert turned_to_fit(drawing, "a4") is drawing and turned_to_fit(drawing, "letter") is drawing
    small_mesh, small = _diagonal_strip(35.0, length=150.0, width=20.0)  # one sheet either way
    small_drawing = PatternDrawing.of(small_mesh, small, "mm")
    assert turned_to_fit(small_drawing, "a4") is small_drawing
    fit = turned_to_fit(PatternDrawing.of(mesh, _diagonal_strip(35.0)[1], "mm"), "fit")  # a smaller page
    assert sorted(np.ptp(fit.layout, axis=0)) == pytest.approx([150.0, 1500.0], abs=1e-6)


def _l_shape(arm: float, width: float, step: float = 10.0):
    """An L of two arms ``arm`` mm long and ``width`` mm wide on a ``step`` grid: its mesh and layout."""
    xs = np.arange(0.0, arm + step / 2, step)
    index = {}
    for i, x in enumerate(xs):
        for j, y in enumerate(xs):
            if x <= width or y <= width:
                index[i, j] = len(index)
    faces = []
    for i in range(len(xs) - 1):
        for j in range(len(xs) - 1):
            corners = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
            if all(c in index for c in corners) and (xs[i + 1] <= width or xs[j + 1] <= width):
                a, b, c, d = (index[c] for c in corners)
                faces += [(a, b, c), (a, c, d)]
    layout = np.array([(xs[i], xs[j]) for (i, j) in index], dtype=float)
    return Mesh(np.column_stack([layout, np.zeros(len(layout))]), np.array(faces)), layout


def test_a_turn_whose_grid_is_smaller_but_prints_more_sheets_is_not_taken(tmp_path):
    """An L of two 1 m arms, 4 cm wide: turned along its hull's diagonal side its grid has 24 A4 sheets
    against 28, but 14 of them hold some of it against 10 as laid (its empty corner is left out)."""
    from pypdf import PdfReader

    from sim.patterns import turned_to_fit

    mesh, layout = _l_shape(1000.0, 40.0)
    drawing = PatternDrawing.of(mesh, layout, "mm")
    assert turned_to_fit(drawing, "a4") is drawing
    write_pattern_file(tmp_path / "l.pdf", drawing, paper="a4")
    assert len(PdfReader(tmp_path / "l.pdf").pages) == 10


def test_a_fit_page_is_not_turned_past_the_largest_a_pdf_has(tmp_path):
    """A 5.2 m x 10 cm strip at 45 degrees fits a 3.8 m page as laid; its smallest page, turned, would be
    5.2 m long, past the 5.08 m a PDF can have: it is printed as laid, not refused."""
    from pypdf import PdfReader

    mesh, layout = _diagonal_strip(45.0, length=5200.0, width=100.0)
    write_pattern_file(tmp_path / "s.pdf", PatternDrawing.of(mesh, layout, "mm"), paper="fit")
    assert len(PdfReader(tmp_path / "s.pdf").pages) == 1


def _rectangle(width: float, height: float, angle_degrees: float = 0.0) -> tuple[Mesh, np.ndarray]:
    """A flat width × height grid (mesh units) and its layout turned by ``angle_degrees``."""
    from sim.generate import grid_faces, grid_uv

    uv = grid_uv(5, 5, width, height)
    a = math.radians(angle_degrees)
    return Mesh(np.column_stack([uv, np.zeros(len(uv))]), grid_faces(5, 5)), uv @ np.array(
        [[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])


def test_a_print_refused_for_its_sheets_names_the_turned_patterns_size(tmp_path):
    """6 x 4 m laid at 30°: more than MAX_SHEETS A4 sheets either way; the refusal named the slanted box
    (7.2 x 6.46 m, 1,000-odd sheets) while the docs promise the turned pattern's size."""
    mesh, layout = _rectangle(6.0, 4.0, 30.0)
    with pytest.raises(PatternError, match=r"^the pattern is (6 x 4|4 x 6) m at 1:1 with --units m: \d+ a4 sheets"):
        write_pattern_file(tmp_path / "big.pdf", PatternDrawing.of(mesh, layout, "m"))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("units, suggested", [
    ("m", "if the mesh is in centimetres, inches or millimetres, say so with --units cm, --units in or --units mm"),
    ("in", "if the mesh is in centimetres or millimetres, say so with --units cm or --units mm"),
    ("mm", None),
])
def test_the_large_pattern_note_suggests_only_smaller_units_than_the_one_given(units, suggested):
    """A pattern over 5 m at 1:1 (a DXF has no sheet limit to refuse it): the mirror of the small note."""
    from sim.patterns import scale_note

    mesh, layout = _rectangle(6000.0 / MM[units], 4000.0 / MM[units])
    note = scale_note(PatternDrawing.of(mesh, layout, units))
    assert note.startswith(f"the pattern is 6 x 4 m at 1:1 with --units {units}")
    assert (note.split(": ", 1)[1] if ": " in note else None) == suggested
    assert scale_note(PatternDrawing.of(mesh, layout * 0.8, units)) is None  # 4.8 m: no note


def test_paper_names_are_case_blind_and_a3_tiles(tmp_path):
    """--paper A4 was refused as an invalid choice; A3 is a common pattern printer's sheet."""
    from sim.patterns import PAPER_MM, plan_sheets

    proc = subprocess.run([SPRINGFLAT, "flatten", str(SCANS / "bunny_ear.obj"), "--max-iter", "3", "--paper", "A3",
                           "--out", str(tmp_path / "d.pdf")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert PAPER_MM["a3"] == (297.0, 420.0) and len(plan_sheets((600.0, 400.0), "a3").sheets) < len(
        plan_sheets((600.0, 400.0), "a4").sheets)


def test_the_sheets_caption_says_the_boundary_crosses_itself():
    from sim.patterns import run_caption

    assert run_caption("converged", 12, 0.01, 0.02, 0, 10) == ("converged after 12 iterations: E_S 0.0100, E_C "
                                                               "0.0200, 0 folded, its boundary crosses itself 10 times")
    assert run_caption("converged", 12, 0.01, 0.02, 0, 0).endswith("0 folded")
    assert run_caption("converged", 12, 0.01, 0.02, 0, 1).endswith("0 folded, its boundary crosses itself once")


def test_the_apis_words_quote_each_value_of_a_list():
    from springflat.api import _in_api_words

    assert _in_api_words("print it tiled (--paper a4, a3 or letter); say so with --units cm or --units mm") == \
        "print it tiled (paper='a4', 'a3' or 'letter'); say so with units='cm' or units='mm'"


def test_grain_turns_a_developable_pattern_so_that_the_direction_points_up():
    """The rolled grid's generators (3D y) unroll to parallel lines: laid at 30°, --grain y turns them
    vertical; -y turns them the other way up; a flat square laid as a diamond comes back square."""
    from sim.generate import rolled_grid
    from sim.patterns import _turned, grain_axis, grain_direction

    mesh, unrolled = rolled_grid(8, 8, arc_degrees=90.0)
    laid = _turned(unrolled, math.radians(30.0), np.zeros(2))
    angle, agreement = grain_axis(mesh.vertices, mesh.faces, laid, grain_direction("y"))
    assert math.degrees(angle) == pytest.approx(120.0) and agreement == pytest.approx(1.0)  # one line: all agree
    for grain, up in (("y", 1.0), ("-y", -1.0), ("0,2,0", 1.0)):
        turned = PatternDrawing.of(mesh, laid).with_grain(grain).layout
        generator = turned[8:] - turned[:-8]  # vertex k to k + 8: one row up, along 3D y
        assert np.allclose(generator[:, 0], 0.0, atol=1e-12) and np.all(np.sign(generator[:, 1]) == up)
    square, uv = _rectangle(100.0, 100.0, 45.0)
    drawing = PatternDrawing.of(square, uv).with_grain("x")
    assert np.allclose(np.ptp(drawing.layout, axis=0), [100.0, 100.0])
    (x0, y0), (x1, y1) = drawing.grain_line()
    assert x0 == x1 and y1 - y0 == pytest.approx(50.0)


@pytest.mark.parametrize("grain, message", [
    ("z", "the direction is normal to the surface"),  # a flat patch: z lies in none of its triangles
    ("0,0,0", "that is not zero"), ("1,2", "a 3D direction X,Y,Z"), ("w", "expected x, y or z")])
def test_a_grain_the_pattern_cannot_have_is_refused(grain, message):
    square, uv = _rectangle(100.0, 100.0)
    with pytest.raises(PatternError, match=message):
        PatternDrawing.of(square, uv).with_grain(grain)


def test_the_grain_line_is_in_every_pattern_file_and_the_sheets_keep_the_turn(tmp_path):
    """--grain: the DXF's GRAIN layer (a vertical line, an arrowhead at each end), the PDF and SVG draw it too,
    and the sheets are not turned again to fit (the grain fixes the turn)."""
    import ezdxf

    from sim.mesh_io import save_obj

    strip, _ = _rectangle(400.0, 40.0)  # across 3D y when --grain y: 400 mm wide, which the sheets would turn upright
    save_obj(tmp_path / "sq.obj", strip.vertices, strip.faces)
    proc = subprocess.run([SPRINGFLAT, "flatten", "sq.obj", "--tol-energy", "1e-9", "--grain", "y", "--out", "sq.dxf",
                           "--out", "sq.svg", "--out", "sq.pdf"], capture_output=True, text=True, cwd=tmp_path,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    doc = ezdxf.readfile(tmp_path / "sq.dxf")
    strokes = [[tuple(p[:2]) for p in e.get_points()] for e in doc.modelspace().query('LWPOLYLINE[layer=="GRAIN"]')]
    assert len(strokes) == 3 and strokes[0][0][0] == pytest.approx(strokes[0][1][0])
    cut = np.array([p[:2] for p in doc.modelspace().query('LWPOLYLINE[layer=="CUT"]')[0].get_points()])
    assert np.ptp(cut, axis=0) == pytest.approx([400.0, 40.0], abs=1e-3)  # 3D y (40 mm) up the page
    assert doc.ezdxf_metadata()["springflat_grain"] == "y"
    ns = {"s": "http://www.w3.org/2000/svg"}
    assert len(ET.parse(tmp_path / "sq.svg").getroot().findall(".//s:g[@id='grain']/s:polyline", ns)) == 3
    # a grain at 45° to the strip leaves it slanted on the sheets, which would have turned it straight
    assert subprocess.run([SPRINGFLAT, "flatten", "sq.obj", "--tol-energy", "1e-9", "--grain", "1,1,0", "--out",
                           "slant.svg"], capture_output=True, cwd=tmp_path, timeout=300).returncode == 0
    cut_svg = np.array([[float(v) for v in point.split(",")] for point in ET.parse(tmp_path / "slant.svg").getroot().find(
        ".//s:polygon[@id='cut']", ns).get("points").split()])
    assert np.ptp(cut_svg, axis=0) == pytest.approx([440.0 / math.sqrt(2)] * 2, abs=1e-3)
    from pypdf import PdfReader

    forms = PdfReader(tmp_path / "sq.pdf").pages[0]["/Resources"]["/XObject"]
    assert any(b"\n.35 G\n" in form.get_object().get_data() for form in forms.values())  # the grain line's grey
    refused = subprocess.run([SPRINGFLAT, "flatten", "sq.obj", "--grain", "x"], capture_output=True, text=True,
                             cwd=tmp_path, timeout=300)
    assert refused.returncode == 2 and "--grain turns the pattern files" in refused.stderr


def test_a_grain_across_a_half_pipe_is_an_axis_not_cancelling_pieces():
    """Across a half-pipe (0° to 180°) the direction x runs one way on one side and back on the other: summed
    with their signs its pieces cancelled and --grain x was refused; as an axis it lies along the unrolled arc.
    Components of any size are a direction (1e308 overflowed the norm, 1e-320 was 'zero')."""
    import warnings

    from sim.generate import rolled_grid

    mesh, unrolled = rolled_grid(13, 5, arc_degrees=180.0)
    for grain in ("x", "1e308,0,0", "1e-320,0,0", (2.0, 0.0, 0.0)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            turned = PatternDrawing.of(mesh, unrolled).with_grain(grain).layout
        across = turned[1:13] - turned[:12]  # along the arc, one row
        assert np.allclose(across[:, 0], 0.0, atol=1e-9) and np.all(across[:, 1] > 0), grain


def test_a_grain_normal_to_the_surface_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    from sim.mesh_io import save_obj
    import sim.cli

    square, _ = _rectangle(100.0, 100.0)
    save_obj(tmp_path / "sq.obj", square.vertices, square.faces)
    monkeypatch.setattr(sim.cli, "run_flatten", lambda *a, **k: pytest.fail("the run started"))
    monkeypatch.chdir(tmp_path)
    assert sim.cli.main(["flatten", "sq.obj", "--grain", "z", "--out", "sq.dxf"]) == 2
    assert "--grain: the direction is normal to the surface" in capsys.readouterr().err
    assert sorted(os.listdir()) == ["sq.obj"]


def _label_box_inside(root, ident: str) -> tuple[str, bool]:
    """The piece label's text, and whether its box (reportlab's Helvetica widths, cap height from its font size)
    lies inside the pattern's polygon ``ident`` of the SVG's pattern group (both in the group's y-down frame)."""
    from matplotlib.path import Path as Outline
    from reportlab.pdfbase.pdfmetrics import stringWidth

    label = root.find(f".//{SVG}g[@id='pattern']/{SVG}text[@class='piece-label']")
    polygon = np.array([p.split(",") for p in root.find(f".//{SVG}polygon[@id='{ident}']").get("points").split()],
                       float)
    em = float(label.get("font-size"))
    width, cap = stringWidth(label.text, "Helvetica", em), 0.718 * em  # Helvetica's cap height, from its metrics
    x, baseline = float(label.get("x")), float(label.get("y"))
    corners = [(x - width / 2, baseline), (x + width / 2, baseline), (x - width / 2, baseline - cap),
               (x + width / 2, baseline - cap)]
    return label.text, bool(Outline(polygon).contains_points(corners).all())


@pytest.mark.parametrize("seam", [0.0, 0.005])
def test_the_piece_carries_its_name_inside_its_edge(bunny, tmp_path, seam):
    """Trimmed out of its sheet, a piece keeps its name: the label lies inside the sew line (the edge)."""
    mesh, layout = bunny
    drawing = PatternDrawing.of(mesh, layout, "m").with_seam(seam)
    write_pattern_file(tmp_path / "bunny.svg", drawing)
    text, inside = _label_box_inside(ET.parse(tmp_path / "bunny.svg").getroot(), "sew" if seam else "cut")
    assert text == "bunny_face" and inside


def test_a_piece_too_small_for_its_name_has_none_on_it(tmp_path):
    from sim.patterns import PIECE_LABEL_MIN_MM

    mesh, layout = _rectangle(20.0, 1.5)  # mm: room for 1.35 mm of cap height at most, under the least size
    assert 0.9 * 1.5 < PIECE_LABEL_MIN_MM
    write_pattern_file(tmp_path / "sliver.svg", PatternDrawing.of(mesh, layout, "mm"))
    root = ET.parse(tmp_path / "sliver.svg").getroot()
    assert root.find(f".//{SVG}text[@class='piece-label']") is None
    write_pattern_file(tmp_path / "piece.svg", PatternDrawing.of(*_rectangle(120.0, 60.0), "mm"))
    assert _label_box_inside(ET.parse(tmp_path / "piece.svg").getroot(), "cut")[1]


def test_the_pdfs_piece_label_is_drawn_with_the_pattern(bunny, tmp_path):
    from pypdf import PdfReader

    mesh, layout = bunny
    write_pattern_file(tmp_path / "bunny.pdf", PatternDrawing.of(mesh, layout, "m"))
    reader = PdfReader(tmp_path / "bunny.pdf")
    texts = [text for text, _ in pdf_page_contents(reader, reader.pages[0])[1]]
    assert texts.count("bunny_face") == 1  # the piece's own label, beside the title block's longer line


def test_the_piece_label_keeps_clear_of_the_grain_line(bunny, tmp_path):
    """The grain line runs through the vertex nearest the centroid, where the label would be centred: the
    name goes beside it, not struck through."""
    from reportlab.pdfbase.pdfmetrics import stringWidth

    mesh, layout = bunny
    write_pattern_file(tmp_path / "grain.svg", PatternDrawing.of(mesh, layout, "m").with_grain("y"))
    root = ET.parse(tmp_path / "grain.svg").getroot()
    strokes = [np.array([p.split(",") for p in line.get("points").split()], float)
               for line in root.findall(f".//{SVG}g[@id='grain']/{SVG}polyline")]
    shaft = max(strokes, key=lambda stroke: np.ptp(stroke[:, 1]))  # the line itself, not an arrowhead
    label = root.find(f".//{SVG}text[@class='piece-label']")
    em = float(label.get("font-size"))
    x, baseline, half = float(label.get("x")), float(label.get("y")), stringWidth(label.text, "Helvetica", em) / 2
    top, bottom = baseline - 0.718 * em, baseline + 0.21 * em  # (y down in the SVG)
    assert np.ptp(shaft[:, 0]) < 1e-6  # vertical
    crosses = x - half <= shaft[0, 0] <= x + half and shaft[:, 1].min() <= bottom and top <= shaft[:, 1].max()
    assert not crosses, (x - half, x + half, shaft[0, 0])


def test_lengths_on_the_sheets_and_in_messages_give_their_millimetres():
    from sim.patterns import length_text

    assert [length_text(2.0, "in"), length_text(0.01, "m"), length_text(5.0, "cm"), length_text(10.0, "mm")] == [
        "2 in (50.8 mm)", "0.01 m (10 mm)", "5 cm (50 mm)", "10 mm"]


def test_a_piece_narrower_than_the_grain_lines_clearance_gets_no_label_and_no_error(tmp_path):
    """The label keeps clear of the grain line; on a piece a few mm wide nothing is left beside it."""
    square, uv = _rectangle(1.6, 1.7)
    write_pattern_file(tmp_path / "p.svg", PatternDrawing.of(square, uv).with_grain("y"))
    svg = (tmp_path / "p.svg").read_text()
    assert 'class="piece-label"' not in svg and 'id="grain"' in svg


def test_a_grain_close_to_the_surfaces_normal_gets_a_note_one_along_it_none():
    """The bunny's muzzle faces -x: its x maps onto the pattern in pieces that point every way where the surface
    faces x, and the grain line drawn is their average (a probe: 50° off the pieces' area-weighted mean); its y
    runs along the surface, and its pieces agree."""
    from sim.layouts import initial_layout
    from sim.mesh_io import load_mesh
    from sim.patterns import GRAIN_AGREEMENT, grain_note

    mesh = load_mesh(SCANS / "bunny_face.obj")
    layout = initial_layout(mesh, "arap")
    across, along = (PatternDrawing.of(mesh, layout).with_grain(grain) for grain in ("x", "y"))
    assert across.grain_agreement < GRAIN_AGREEMENT <= along.grain_agreement
    assert re.fullmatch(r"the grain direction x lies on the pattern in pieces that point many ways \(agreement "
                        r"0\.\d\d of 1\): the grain line drawn is their average, which much of the piece does not "
                        r"follow; a direction that runs along the surface, not across it, gives a truer line",
                        grain_note(across))
    assert grain_note(along) is None and grain_note(PatternDrawing.of(mesh, layout)) is None


def _flat_square_grid(n: int = 11, size: float = 200.0, clockwise: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A ``size`` mm square in x, y as an ``n`` x ``n`` grid, its faces wound anticlockwise seen from +z."""
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    a = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
    F = np.concatenate([np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])])
    return V, (F[:, ::-1] if clockwise else F)


@pytest.mark.parametrize("clockwise", [False, True], ids=["front +z", "front -z"])
def test_a_piece_modelled_flat_comes_back_in_its_own_x_y_not_as_the_start_laid_it(tmp_path, clockwise):
    """A 200 mm square laid as a diamond by its start came out a 283 mm diamond in every pattern file: the files
    show the piece as the mesh is seen from its front (the side its faces' winding faces)."""
    import ezdxf
    import springflat

    V, F = _flat_square_grid(clockwise=clockwise)
    diamond = (V[:, :2] - 100) @ np.array([[1, 1], [-1, 1]]) / math.sqrt(2)
    pattern = springflat.flatten(V, F, init=diamond * ([1, -1] if clockwise else [1, 1]))  # (a mirror fits them)
    assert np.ptp(pattern.layout, axis=0) == pytest.approx([200 * math.sqrt(2)] * 2, rel=1e-6)  # the run's frame
    springflat.write_pattern(tmp_path / "p.dxf", pattern)
    cut = np.array([p[:2] for p in ezdxf.readfile(tmp_path / "p.dxf").modelspace().query("LWPOLYLINE")[0]
                   .get_points()])
    seen = V[:, :2] * ([-1, 1] if clockwise else [1, 1])  # from below, x runs the other way
    layout = PatternDrawing.of(pattern.mesh, pattern.layout).as_seen().layout
    assert np.ptp(cut, axis=0) == pytest.approx([200, 200], rel=1e-6)
    assert np.allclose(layout - layout.mean(axis=0), seen - seen.mean(axis=0), atol=1e-6)


@pytest.mark.parametrize("facing", ["-y", "+y", "+x", "-z"])
def test_a_wall_comes_up_the_right_way(facing):
    """A wall (or a piece facing down) came upside down where the view kept x across: up is z, or y where z lies
    along the normal; the view is from the front, so across is up x normal."""
    from golden_model.mesh import signed_areas_2d

    V, F = _flat_square_grid(n=5, size=2.0)  # in x, y, facing +z
    V = V[:, {"-y": [0, 2, 1], "+y": [0, 2, 1], "+x": [2, 0, 1], "-z": [0, 1, 2]}[facing]]
    wound = {"-y": F, "+y": F[:, ::-1], "+x": F, "-z": F[:, ::-1]}[facing]
    normal = np.cross(V[wound[0, 1]] - V[wound[0, 0]], V[wound[0, 2]] - V[wound[0, 0]])
    assert facing == ("+" if normal[abs(normal).argmax()] > 0 else "-") + "xyz"[abs(normal).argmax()]
    mesh = Mesh(V, wound)
    up_axis = 2 if facing != "-z" else 1
    across = np.cross(np.eye(3)[up_axis], normal / np.linalg.norm(normal))
    for angle in (0.4, 2.5):  # the piece's own shape, positively wound, at some angle
        flat = np.column_stack([V @ across, V[:, up_axis]])
        c, s = math.cos(angle), math.sin(angle)
        laid = flat @ np.array([[c, s], [-s, c]])
        assert (signed_areas_2d(laid, wound) > 0).all()
        seen = PatternDrawing.of(mesh, laid).as_seen().layout
        top, bottom = V[:, up_axis].argmax(), V[:, up_axis].argmin()
        assert seen[top, 1] > seen[bottom, 1] and np.allclose(seen - seen.mean(0), flat - flat.mean(0), atol=1e-9)


def test_the_view_turn_follows_the_mesh_round_its_normal():
    """Turned about its normal by an angle, a curved piece's files turn with it by that angle."""
    from sim.patterns import view_turn

    mesh = dome_grid(9)
    layout = np.random.default_rng(5).normal(size=(mesh.n_vertices, 2)) * 0.01 + mesh.vertices[:, :2] @ [[0, -1],
                                                                                                          [1, 0]]
    angle = view_turn(mesh.vertices, mesh.faces, layout)
    assert abs(angle - math.pi / 2) < 0.05  # the layout is the mesh's view turned a quarter clockwise
    drawing = PatternDrawing.of(mesh, layout).as_seen().with_grain("x")  # the turn --plot shows: both, summed
    c, s = math.cos(drawing.turn), math.sin(drawing.turn)
    turned = layout @ np.array([[c, s], [-s, c]])
    assert np.allclose(turned - turned.mean(axis=0), drawing.layout - drawing.layout.mean(axis=0), atol=1e-12)
    for theta in (0.3, 2.0, -1.2):
        c, s = math.cos(theta), math.sin(theta)
        turned = mesh.vertices @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        assert math.remainder(view_turn(turned, mesh.faces, layout) - angle - theta, 2 * math.pi) == \
            pytest.approx(0, abs=1e-9)


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one core: BLAS runs one thread whatever it is told")
def test_the_view_turn_does_not_depend_on_the_blas_threads(tmp_path):
    """A Dask worker has one BLAS thread, the command as many as cores: a dot product split by threads gave the
    angle another last bit, and a large pattern's files other bytes than the command's."""
    code = ("import sys; import numpy as np; from sim.generate import dome_grid; from sim.patterns import view_turn; "
            "m = dome_grid(150); rng = np.random.default_rng(3); "
            "layout = m.vertices[:, :2] @ np.array([[0.6, 0.8], [-0.8, 0.6]]) + rng.normal(size=(m.n_vertices, 2)) * 1e-3; "
            "print(repr(view_turn(m.vertices, m.faces, layout)))")
    angles = set()
    for threads in ("1", str(os.cpu_count())):
        env = {**os.environ, "OPENBLAS_NUM_THREADS": threads, "OMP_NUM_THREADS": threads}
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
        assert done.returncode == 0, done.stderr
        angles.add(done.stdout.strip())
    assert len(angles) == 1, angles
