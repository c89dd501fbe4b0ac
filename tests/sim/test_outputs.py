"""The plot and SVG colour each face by its area distortion |A'|/A and mark folded faces."""

import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from matplotlib.colors import to_rgba

from sim.generate import dome_grid
from sim.layouts import tutte_layout
from golden_model.mesh import folded_faces, triangle_areas_3d
from golden_model.params import FlattenParams
from golden_model.reference import flatten
from sim.outputs import (
    FOLD_COLOUR,
    MAX_SCALE,
    MIN_SCALE,
    PLAIN_COLOUR,
    distortion_cmap,
    distortion_scale,
    face_colours,
    show_edges,
    write_layout,
    write_plot,
)

SVG = "{http://www.w3.org/2000/svg}"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _hex(rgba) -> str:
    r, g, b = (int(round(c * 255)) for c in rgba[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def _four_triangles():
    """Separate triangles, each of 3D area 1/2: undistorted, area ×2, area ×1/2, and folded (clockwise)."""
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    positions = np.vstack([tri, tri * np.sqrt(2) + 3, tri * np.sqrt(0.5) + 6, tri[[0, 2, 1]] + 9])
    faces = np.arange(12).reshape(4, 3)  # the last: same winding over a mirrored triangle, clockwise
    return positions, faces, np.full(4, 0.5)


def test_face_colours_centre_stretched_shrunk_folded():
    positions, faces, areas = _four_triangles()
    colours = face_colours(positions, faces, areas, scale=2.0)
    np.testing.assert_allclose(colours.ratio, [1.0, 2.0, 0.5, 1.0])
    assert colours.folded.tolist() == [False, False, False, True] and colours.n_folded == 1
    cmap = distortion_cmap()
    # undistorted: the map's centre, nearly white
    np.testing.assert_allclose(colours.rgba[0], cmap(0.5), atol=1e-2)
    assert min(colours.rgba[0][:3]) > 0.9
    # area ×2 at scale 2: the stretched (red) end; ×1/2: the shrunk (blue) end
    np.testing.assert_allclose(colours.rgba[1], cmap(1.0))
    np.testing.assert_allclose(colours.rgba[2], cmap(0.0))
    assert colours.rgba[1][0] > 0.5 > colours.rgba[1][2]
    assert colours.rgba[2][2] > 0.5 > colours.rgba[2][0]
    # folded: the contrast colour, far from every colour of the map
    np.testing.assert_allclose(colours.rgba[3], to_rgba(FOLD_COLOUR))
    ramp = cmap(np.linspace(0, 1, 256))[:, :3]
    assert np.min(np.linalg.norm(ramp - np.array(to_rgba(FOLD_COLOUR)[:3]), axis=1)) > 0.3
    # a ratio of 2 on a wider scale lands on the upper side, short of the end
    wide = face_colours(positions, faces, areas, scale=4.0)
    assert 0.5 < wide.rgba[1][0] and wide.rgba[1][2] < wide.rgba[0][2]
    assert not np.allclose(wide.rgba[1], cmap(1.0))


def test_face_colours_without_3d_areas_is_plain_with_folds():
    positions, faces, _ = _four_triangles()
    colours = face_colours(positions, faces)
    assert not colours.has_ratio
    for k in range(3):
        np.testing.assert_allclose(colours.rgba[k], to_rgba(PLAIN_COLOUR))
    np.testing.assert_allclose(colours.rgba[3], to_rgba(FOLD_COLOUR))


def test_distortion_scale_is_robust_and_clipped():
    assert distortion_scale(np.ones(100)) == MIN_SCALE
    assert distortion_scale(np.full(100, 10.0)) == MAX_SCALE
    ratio = np.full(1000, 1.3)
    ratio[:500] = 1 / 1.3
    assert distortion_scale(ratio) == pytest.approx(1.3)
    # a few outliers (under 2 %) and folded faces do not set the scale
    ratio[:10] = 50.0
    folded = np.zeros(1000, bool)
    folded[10:200] = True
    ratio[10:200] = 1e-6
    assert distortion_scale(ratio, folded) == pytest.approx(1.3)
    ticks = face_colours(*_four_triangles(), scale=2.0).ticks()
    np.testing.assert_allclose(ticks, [0.5, 2**-0.5, 1, 2**0.5, 2])


def _folded_layout(n: int):
    """A dome's plane projection with one interior vertex pushed across its neighbours (some faces fold)."""
    mesh = dome_grid(n, height=0.3)
    positions = mesh.vertices[:, :2].copy()
    centre = (n // 2) * n + n // 2
    positions[centre, 0] += 2.5 / (n - 1)
    folded = folded_faces(positions, mesh.faces)
    assert 0 < folded.sum() < mesh.n_faces // 2
    return mesh, positions, folded


def test_svg_fills_each_face_and_marks_folds(tmp_path):
    mesh, positions, folded = _folded_layout(7)
    path = tmp_path / "pattern.svg"
    write_layout(path, positions, mesh.faces, vertices=mesh.vertices)
    root = ET.parse(path).getroot()
    polygons = root.findall(f".//{SVG}polygon")
    assert len(polygons) == mesh.n_faces
    assert all(p.get("fill", "").startswith("#") for p in polygons)
    groups = {g.get("id"): g for g in root.iter(f"{SVG}g")}
    fold_fills = [p.get("fill") for p in groups["folded"].findall(f"{SVG}polygon")]
    assert fold_fills == [FOLD_COLOUR] * int(folded.sum())
    # the unfolded faces, in face order, with the colours of face_colours
    colours = face_colours(positions, mesh.faces, triangle_areas_3d(mesh.vertices, mesh.faces))
    expected = [_hex(c) for c in colours.rgba[~folded]]
    assert [p.get("fill") for p in groups["pattern"].findall(f"{SVG}polygon")] == expected
    assert FOLD_COLOUR not in expected
    # a small mesh keeps thin strokes; the legend has the colour bar and the fold count
    assert groups["pattern"].get("stroke") not in (None, "none")
    assert len(groups["colourbar"].findall(f"{SVG}rect")) >= 16
    legend_text = " ".join(t.text for t in groups["legend"].iter(f"{SVG}text"))
    assert f"folded: {int(folded.sum())}" in legend_text and "|A'|/A" in legend_text
    # the first face's corners, y flipped, in the viewBox's mesh units
    first = np.array([xy.split(",") for xy in groups["pattern"][0].get("points").split()], dtype=float)
    face0 = np.flatnonzero(~folded)[0]
    np.testing.assert_allclose(first, positions[mesh.faces[face0]] * [1, -1], atol=1e-4)
    # deterministic
    again = tmp_path / "again.svg"
    write_layout(again, positions, mesh.faces, vertices=mesh.vertices)
    assert again.read_bytes() == path.read_bytes()


def test_svg_units_and_plain_fallback(tmp_path):
    mesh, positions, folded = _folded_layout(5)
    path = tmp_path / "plain.svg"
    write_layout(path, positions, mesh.faces, units="cm")
    root = ET.parse(path).getroot()
    assert root.get("width").endswith("cm") and root.get("height").endswith("cm")
    view = [float(v) for v in root.get("viewBox").split()]
    assert float(root.get("width")[:-2]) == pytest.approx(view[2], rel=1e-5)
    fills = [p.get("fill") for p in root.iter(f"{SVG}polygon")]
    assert sorted(set(fills)) == sorted({PLAIN_COLOUR, FOLD_COLOUR}) and fills.count(FOLD_COLOUR) == folded.sum()
    assert not [g for g in root.iter(f"{SVG}g") if g.get("id") == "colourbar"]


def test_svg_of_a_large_mesh_has_no_strokes(tmp_path):
    mesh = dome_grid(101)  # 20 000 triangles
    path = tmp_path / "big.svg"
    write_layout(path, mesh.vertices[:, :2], mesh.faces, vertices=mesh.vertices)
    root = ET.parse(path).getroot()
    assert len(root.findall(f".//{SVG}polygon")) == mesh.n_faces == 20000
    pattern = next(g for g in root.iter(f"{SVG}g") if g.get("id") == "pattern")
    assert pattern.get("stroke") == "none"
    assert path.stat().st_size < 120 * mesh.n_faces  # compact: rounded coordinates


def test_edges_only_when_they_stay_apart():
    small, big = dome_grid(8), dome_grid(101)
    pixels_per_unit = 500.0  # a 1-unit pattern in a 500-pixel panel
    assert show_edges(small.vertices[:, :2], small.faces, pixels_per_unit)
    assert not show_edges(big.vertices[:, :2], big.faces, pixels_per_unit)


@pytest.mark.slow
@pytest.mark.parametrize("n", [8, 101])  # 98 and 20 000 triangles
def test_plot_is_a_coloured_png(tmp_path, n):
    import matplotlib.image

    mesh = dome_grid(n, height=0.4)
    result = flatten(mesh, tutte_layout(mesh), FlattenParams(dynamics="momentum", max_iter=5))
    path = tmp_path / "plot.png"
    write_plot(path, result, mesh.faces, title="dome", vertices=mesh.vertices)
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    image = matplotlib.image.imread(path)[..., :3]
    assert image.shape[0] > 500 and image.shape[1] > 1000
    # the distortion map's both sides are on the picture (Tutte's initial layout is far from true area)
    reds = (image[..., 0] > 0.6) & (image[..., 2] < 0.35)
    blues = (image[..., 2] > 0.6) & (image[..., 0] < 0.35)
    assert reds.sum() > 500 and blues.sum() > 500
    # and the plot without 3D areas (plain faces) still works
    write_plot(tmp_path / "plain.png", result, mesh.faces)
    assert (tmp_path / "plain.png").read_bytes()[:8] == PNG_SIGNATURE


def test_plot_marks_folded_faces(tmp_path):
    import dataclasses

    import matplotlib.image

    mesh, positions, folded = _folded_layout(9)
    result = flatten(mesh, mesh.vertices[:, :2], FlattenParams(max_iter=1))
    result = dataclasses.replace(result, positions=positions)
    path = tmp_path / "folded.png"
    write_plot(path, result, mesh.faces, vertices=mesh.vertices)
    image = matplotlib.image.imread(path)[..., :3]
    main = image[:, : image.shape[1] // 2]  # the final pattern's panel
    black = (main.max(axis=2) < 0.08).sum()
    assert black > 200  # the folds (not just text and frame)
    plain = tmp_path / "unfolded.png"
    write_plot(plain, dataclasses.replace(result, positions=mesh.vertices[:, :2]), mesh.faces, vertices=mesh.vertices)
    unfolded = matplotlib.image.imread(plain)[..., :3][:, : image.shape[1] // 2]
    assert black > (unfolded.max(axis=2) < 0.08).sum() + 200


def _build(out, files: dict[str, str], **kw) -> None:
    from sim.outputs import atomic_directory

    with atomic_directory(out, stale=("chosen.json",), **kw) as build:
        for name, text in files.items():
            (build / name).write_text(text)


def test_a_file_a_directory_output_replaces_keeps_its_mode(tmp_path):
    """As a single output file does (README): a report made private stays private when the command runs again."""
    import stat

    from sim.outputs import atomic_directory

    out = tmp_path / "report"
    _build(out, {"report.md": "1", "figure.png": "1"})
    os.chmod(out / "report.md", 0o600)
    os.chmod(out / "figure.png", 0o640)
    _build(out, {"report.md": "2", "figure.png": "2", "new.csv": "2"})
    modes = {name: stat.S_IMODE(os.stat(out / name).st_mode) for name in ("report.md", "figure.png", "new.csv")}
    assert (modes["report.md"], modes["figure.png"]) == (0o600, 0o640)
    if os.geteuid() == 0:  # a user's report rewritten under sudo stays theirs (only root may give a file away)
        os.chown(out / "report.md", 1234, 5678)
        _build(out, {"report.md": "2"})
        assert (os.stat(out / "report.md").st_uid, os.stat(out / "report.md").st_gid) == (1234, 5678)
        assert os.stat(out / "figure.png").st_uid == os.geteuid()
    # a script the command makes runnable stays runnable over an old copy that lost its execute bits
    with atomic_directory(out) as build:
        (build / "reproduce.sh").write_text("#!/bin/sh\n")
        (build / "reproduce.sh").chmod(0o755)
    os.chmod(out / "reproduce.sh", 0o644)
    with atomic_directory(out) as build:
        (build / "reproduce.sh").write_text("#!/bin/sh\n")
        (build / "reproduce.sh").chmod(0o755)
    assert stat.S_IMODE(os.stat(out / "reproduce.sh").st_mode) == 0o755
    assert (out / "report.md").read_text() == "2"
    umask = os.umask(0)
    os.umask(umask)
    assert modes["new.csv"] == 0o666 & ~umask  # a new file: the umask's


def test_an_os_error_of_a_directory_commands_work_is_not_called_an_output_error(tmp_path):
    """A tool that cannot be started (its file not executable) is named as what failed, not --out."""
    import subprocess

    from sim.outputs import OutputWriteError, atomic_directory

    tool = tmp_path / "tool"
    tool.write_text("#!/bin/sh\n")
    tool.chmod(0o644)
    with pytest.raises(PermissionError) as raised:
        with atomic_directory(tmp_path / "out"):
            subprocess.run([str(tool)])
    assert raised.value.filename == str(tool) and not (tmp_path / "out").exists()
    with pytest.raises(OutputWriteError, match="cannot write --out '.*out': .*"):  # a write into the build is one
        with atomic_directory(tmp_path / "out") as build:
            (build / "sub").write_text("")
            open(build / "sub" / "x", "w")
    # a copy into the build that fails names the source first and the build second (a full disk): the output's
    with pytest.raises(OutputWriteError, match="no space left on device"):
        with atomic_directory(tmp_path / "out") as build:
            raise OSError(28, "No space left on device", str(tool), None, str(build / "copy.v"))
    with pytest.raises(OutputWriteError):  # a descriptor, not a path: the output's (no traceback)
        with atomic_directory(tmp_path / "out"):
            os.stat(987654)


def test_a_directory_output_keeps_what_this_run_wrote_and_drops_a_stale_result(tmp_path):
    """``stale``: an earlier run's result this run did not write again is removed; one it did write is its
    new one; one that is an input of this run (study's --base) is never removed."""
    out = tmp_path / "study"
    _build(out, {"report.md": "1", "chosen.json": "first"})
    _build(out, {"report.md": "2", "chosen.json": "second"})  # over an existing --out
    assert (out / "chosen.json").read_text() == "second" and (out / "report.md").read_text() == "2"
    _build(out, {"report.md": "3"}, inputs=[("--base", out / "chosen.json")])  # no pick, from its own choice
    assert (out / "chosen.json").read_text() == "second"
    _build(out, {"report.md": "4"})  # no pick: the old one would mislead
    assert sorted(os.listdir(out)) == ["report.md"]


def test_an_engines_history_numbers_its_final_row_by_the_iterations_run(tmp_path):
    """The engine keeps no per-iteration record: its history is the initial row and the final one, which is
    iteration N (the CSV and the plot's axis said 1)."""
    import csv

    import numpy as np

    from golden_model.builtin import builtin_mesh
    from golden_model.fixed.engine import prepare
    from golden_model.fixed.formats_set import FormatSet
    from sim.layouts import initial_layout
    from golden_model.params import FlattenParams
    from sim.engine_run import engine_flatten_result
    from sim.outputs import write_history

    mesh, _ = builtin_mesh("surf2")
    problem = prepare(mesh, initial_layout(mesh, "pca"), FlattenParams(), FormatSet.preset("default"))
    raw = problem.initial_positions
    result = engine_flatten_result(problem, raw, np.zeros_like(raw), "max-iterations", 150, "rtl", {})
    write_history(tmp_path / "h.csv", result)
    with open(tmp_path / "h.csv", newline="") as f:
        assert [row["iteration"] for row in csv.DictReader(f)] == ["0", "150"]


def test_a_stop_signal_turns_logging_off_in_a_dask_block_and_the_callers_level_comes_back(monkeypatch):
    """sim.outputs.on_interrupt runs the block's hook at once (Dask's loop thread logs the abandon from then on);
    after the block, logging.disable is what the caller had."""
    import logging
    import signal

    from sim.batch import _quiet_when_abandoned
    from sim.outputs import on_interrupt, reset_interrupted

    before = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        with pytest.raises(KeyboardInterrupt):
            with _quiet_when_abandoned():
                assert logging.root.manager.disable == logging.WARNING
                on_interrupt(signal.SIGINT, None)
        assert logging.root.manager.disable == logging.WARNING
        with pytest.raises(KeyboardInterrupt):
            with _quiet_when_abandoned():
                try:
                    on_interrupt(signal.SIGINT, None)
                finally:
                    assert logging.root.manager.disable == logging.CRITICAL  # off the moment the signal came
    finally:
        reset_interrupted()
        logging.disable(before)


def test_a_history_of_the_start_and_the_end_leaves_dt_and_accepted_empty(tmp_path):
    """The RTL and board engines keep no per-iteration record: their history is the start and the end (iteration
    0 and N). That last row is no one step: no dt (even for the paper dynamics) and no accepted; a float run's rows
    each have theirs."""
    import csv
    import dataclasses

    from golden_model.results import History
    from sim.outputs import write_history

    mesh = dome_grid(6)
    result = flatten(mesh, tutte_layout(mesh), FlattenParams(dynamics="paper", step="fixed", dt=0.01, max_iter=5))
    write_history(tmp_path / "float.csv", result)
    assert result.history.accepted[0] is None  # the start is no step, and says so
    ends = History()
    ends.append(math.nan, result.initial, accepted=None)  # (as every engine marks its start)
    ends.append(result.history.dt[-1], result.final, accepted=None, iteration=len(result.history) - 1)
    write_history(tmp_path / "ends.csv", dataclasses.replace(result, history=ends))
    with open(tmp_path / "float.csv", newline="") as f:
        every = list(csv.DictReader(f))
    with open(tmp_path / "ends.csv", newline="") as f:
        start, end = csv.DictReader(f)
    assert [row["dt"] for row in every[1:]] == ["0.01"] * 5 and {row["accepted"] for row in every[1:]} == {"1"}
    assert (end["iteration"], end["dt"], end["accepted"]) == ("5", "", "") and start["accepted"] == ""
    from sim.engine_run import engine_flatten_result  # the engines' own end row, after one iteration too
    from golden_model.fixed import FormatSet
    from golden_model.fixed.engine import prepare

    problem = prepare(mesh, tutte_layout(mesh), FlattenParams(dynamics="momentum", max_iter=1),
                      FormatSet.preset("default"))
    one = engine_flatten_result(problem, problem.initial_positions, 0 * problem.initial_positions, "max-iterations",
                                1, "rtl", {})
    write_history(tmp_path / "one.csv", one)
    with open(tmp_path / "one.csv", newline="") as f:
        assert [(row["iteration"], row["dt"], row["accepted"]) for row in csv.DictReader(f)] == [("0", "", ""),
                                                                                                 ("1", "", "")]
