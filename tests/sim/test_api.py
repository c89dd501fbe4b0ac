"""The springflat package: the README's example as written, the command line's options and defaults."""

import json
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest
import trimesh

import springflat
from golden_model.fixed import FormatSet
from golden_model.mesh import MeshError
from sim.mesh_io import load_mesh
from golden_model.params import ParameterError
from sim.cli import main
from support import REPO, SPRINGFLAT

ROOT = REPO
SCANS = ROOT / "tests" / "data" / "scans"


def readme_first_code_block() -> tuple[str, str]:
    blocks = re.findall(r"^```(\w*)\n(.*?)^```", (ROOT / "README.md").read_text(), re.S | re.M)
    return blocks[0]


@pytest.mark.slow
def test_the_readme_opens_with_the_api_in_three_lines_and_it_runs_as_written(monkeypatch):
    language, code = readme_first_code_block()
    assert language == "python"
    lines = [line for line in code.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    assert len(lines) == 3
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    layout = namespace["pattern"].layout  # the name the README's next lines write to a file
    mesh = load_mesh(SCANS / "bunny_face.obj")
    assert isinstance(layout, np.ndarray) and layout.shape == (mesh.n_vertices, 2) == (2993, 2)
    assert layout.dtype == np.float64 and np.isfinite(layout).all()
    # the layout the command gives the same file with no options
    done = subprocess.run([SPRINGFLAT, "flatten", str(SCANS / "bunny_face.obj"), "--json"], capture_output=True,
                          text=True, timeout=300)
    summary = json.loads(done.stdout)
    lengths = np.linalg.norm(layout[mesh.edges[:, 0]] - layout[mesh.edges[:, 1]], axis=1)
    shape_error = np.abs(lengths - mesh.rest_lengths).sum() / mesh.rest_lengths.sum()
    assert shape_error == pytest.approx(summary["shape_error"], rel=1e-12)


@pytest.fixture(scope="module")
def ear():
    return springflat.read_mesh(SCANS / "bunny_ear.obj")


def test_the_options_are_the_command_lines_run_and_engine_options():
    from sim.cli import build_parser

    flatten_parser = build_parser()._subparsers._group_actions[0].choices["flatten"]
    flags = {flag for action in flatten_parser._actions for flag in action.option_strings if flag.startswith("--")}
    not_run_options = {"--help", "--out", "--history", "--plot", "--json", "--units", "--paper", "--dxf-edges",
                       "--grain", "--seam-allowance", "--distortion", "--out-dir", "--jobs", "--skip-existing",
                       "--scheduler", "--port", "--baud"}
    negations = {flag for flag in flags if flag.startswith("--no-") and "--" + flag[5:] in flags}  # --[no-]barrier
    assert {spec.flag for spec in springflat.OPTIONS.values()} == flags - not_run_options - negations
    for spec in springflat.OPTIONS.values():
        assert spec.keyword == spec.flag[2:].replace("-", "_") and spec.help
        assert f"``{spec.keyword}`` (``{spec.flag}``)" in springflat.flatten.__doc__


def test_keywords_change_the_run_as_the_flags_do(ear, capsys):
    V, F = ear
    # numpy scalars are taken as their text would be on the command line
    pattern = springflat.flatten(V, F, dynamics="paper", step="fixed", dt=np.float32(0.02), max_iter=np.int64(7),
                                 init="tutte", name="ear")
    assert (pattern.status, pattern.iterations, pattern.init) == ("max-iterations", 7, "tutte")
    assert (pattern.params.dynamics, pattern.params.step, pattern.params.dt) == ("paper", "fixed", 0.02)
    assert main(["flatten", str(SCANS / "bunny_ear.obj"), "--dynamics", "paper", "--step", "fixed", "--dt", "0.02",
                 "--max-iter", "7", "--init", "tutte", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["area_error"] == pattern.area_error and summary["shape_error"] == pattern.shape_error
    np.testing.assert_array_equal(pattern.area_ratio, pattern.distortion().area_ratio)
    assert pattern.layout.shape == (len(V), 2) and pattern.area_ratio.shape == (len(F),)
    assert pattern.edge_strain.shape == (pattern.mesh.n_edges,)


@pytest.mark.parametrize("options, flags", [
    ({"max_iter": 2.5}, ["--max-iter", "2.5"]),
    ({"damping": "lots"}, ["--damping", "lots"]),
    ({"dynamics": "brownian"}, ["--dynamics", "brownian"]),
    ({"damping": 0.2}, ["--damping", "0.2"]),            # a domain rule: damping is the paper dynamics'
    ({"barrier_threshold": 0}, ["--barrier-threshold", "0"]),
    ({"engine": "quantum"}, ["--engine", "quantum"]),
    ({"step": "fixed"}, ["--step", "fixed"]),             # the momentum dynamics has no step to choose
    ({"density": 1e-6}, ["--density", "1e-6"]),           # nor node masses (its weights are 2/(C deg))
    ({"damping": 0}, ["--damping", "0"]),                 # nor damping, even none
])
def test_a_value_the_command_refuses_the_api_refuses(ear, capsys, options, flags):
    V, F = ear
    with pytest.raises(ParameterError) as refused:
        springflat.flatten(V, F, **options)
    try:
        code = main(["flatten", str(SCANS / "bunny_ear.obj"), *flags])
    except SystemExit as exc:  # argparse's own refusals
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    if "argument --" in err:  # argparse refused the text: both name the value
        assert flags[1] in str(refused.value) and flags[1] in err
    else:  # a domain rule: the very same message, the API's in its keywords
        from springflat.api import _in_api_words

        said = err.strip().removeprefix("springflat: error: ")
        assert "--" in said and str(refused.value) == _in_api_words(said) and "--" not in str(refused.value)


def test_unknown_keywords_and_wrong_types_are_type_errors(ear):
    V, F = ear
    with pytest.raises(TypeError, match="unexpected keyword.*max_iters"):
        springflat.flatten(V, F, max_iters=3)
    with pytest.raises(ParameterError, match="barrier must be True or False"):
        springflat.flatten(V, F, barrier="yes")
    for vertices_alone in (V, V.tolist()):  # the faces forgotten: said to be missing
        with pytest.raises(TypeError, match=r"^flatten\(V, F\) takes the faces F too: F, the \(F, 3\) vertex indices, "
                                            r"is missing$"):
            springflat.flatten(vertices_alone)
    with pytest.raises(TypeError, match=r"one trimesh.Trimesh, or a mesh file's path or a built-in mesh's name \(str "
                                        r"or pathlib.Path\), not bytes"):
        springflat.flatten(b"ear.obj")
    with pytest.raises(TypeError, match="flatten takes a Trimesh alone \\(its faces are its own\\), or two arrays"):
        springflat.flatten(trimesh.Trimesh(V, F, process=False), F)
    with pytest.raises(TypeError, match="read_mesh takes a file path \\(str or pathlib.Path\\), not NoneType"):
        springflat.read_mesh(None)


def test_trimesh_and_an_initial_array(ear):
    import trimesh

    V, F = ear
    from_arrays = springflat.flatten(V, F, max_iter=20)
    from_trimesh = springflat.flatten(trimesh.Trimesh(V, F, process=False), max_iter=20)
    np.testing.assert_array_equal(from_arrays.layout, from_trimesh.layout)
    again = springflat.flatten(V, F, init=from_arrays.result.initial_positions, max_iter=20)
    assert again.init == "array"
    np.testing.assert_array_equal(again.layout, from_arrays.layout)


@pytest.mark.parametrize("layout, message", [
    (lambda P: np.full_like(P, np.nan), "the init array has a non-finite coordinate"),
    (lambda P: P * 1e300, "the init array: row 1 has a coordinate of magnitude"),
    (lambda P: P[:-1], "the init array has {m} rows but the mesh has {n} vertices"),
    (lambda P: np.column_stack([P, P[:, :1]]), r"the init array has shape \({n}, 3\), expected \({n}, 2\)"),
    (lambda P: P.astype(complex), "the init array holds complex128 values, not real numbers"),
    (lambda P: [list(P[0][:1])] + P[1:].tolist(), r"the init array's rows are not all of one length: expected "
                                                  r"\({n}, 2\)"),
])
def test_an_initial_array_is_checked_as_a_layout_file_is(ear, layout, message):
    V, F = ear
    with pytest.raises(ParameterError, match=message.format(n=len(V), m=len(V) - 1)):
        springflat.flatten(V, F, init=layout(springflat.flatten(V, F, max_iter=1).result.initial_positions))


def test_a_folded_initial_array_is_untangled_as_a_layout_file_is(ear, tmp_path):
    V, F = ear
    folded = springflat.flatten(V, F, init="tutte", max_iter=1).result.initial_positions.copy()
    folded[: len(folded) // 3, 0] *= -1  # a third of the nodes mirrored: triangles across the cut fold
    path = tmp_path / "folded.txt"
    np.savetxt(path, folded, fmt="%.17g")
    with pytest.warns(springflat.MeshNote) as notes:
        from_array = springflat.flatten(V, F, init=folded, max_iter=5)
    assert any("folds" in str(note.message) and "untangling it" in str(note.message) for note in notes), notes.list
    with pytest.warns(springflat.MeshNote) as file_notes:  # the untangled layout overlaps itself too, and says so
        from_file = springflat.flatten(V, F, init=path, max_iter=5)
    assert any("folds 773 triangles: untangling it" in str(note.message) for note in file_notes), file_notes.list
    assert from_array.init == "array, untangled" and from_file.init == f"{path}, untangled"
    assert from_array.result.initial.folded == 0
    np.testing.assert_array_equal(from_array.layout, from_file.layout)


def test_a_mirror_image_start_is_mirrored_so_that_the_pattern_shows_the_meshs_front(ear, tmp_path):
    """A layout given clockwise (y-down texture coordinates, say) would be cut the wrong way round."""
    from golden_model.mesh import layout_orientation

    V, F = ear
    start = springflat.flatten(V, F, max_iter=1).result.initial_positions
    assert layout_orientation(start, F) > 0  # the computed start faces the front
    mirrored = start * [1.0, -1.0]
    path = tmp_path / "uv.txt"
    np.savetxt(path, mirrored, fmt="%.17g")
    for init, what in ((mirrored, "the init array"), (path, f"the layout '{path}'")):
        with pytest.warns(springflat.MeshNote, match=f"{what} is a mirror image of the mesh .*: mirrored in y"):
            pattern = springflat.flatten(V, F, init=init, max_iter=20)
        assert layout_orientation(pattern.layout, F) > 0 and pattern.folded == 0
        # mirrored back in y, the way y-down texture coordinates come out upright: the computed start itself
        np.testing.assert_array_equal(pattern.result.initial_positions, start)


def test_the_board_engine_is_refused_by_the_api_with_what_to_run_instead(ear):
    V, F = ear
    with pytest.raises(ParameterError, match=r"engine 'board', the engine on a ULX3S over its USB-UART \(--port; docs/board.md\), runs from the command "
                       r"line: springflat flatten MESH --engine board; the API runs the float, fixed, rtl engines"):
        springflat.flatten(V, F, engine="board")


@pytest.mark.parametrize("name, shown", [("evil\nv 9 9 9\nf 1 2 3", "evil\\nv 9 9 9\\nf 1 2 3"),
                                         ("bad\udcff", "bad\\xff"), ("tab\tstop", "tab\\tstop"),
                                         ("Kopf ü", "Kopf ü")],
                         ids=["newline", "undecodable byte", "tab", "not ascii"])
def test_a_name_with_control_characters_or_undecodable_bytes_is_one_line_of_text_in_every_file(ear, tmp_path, name,
                                                                                                 shown):
    V, F = ear
    pattern = springflat.flatten(V, F, name=name, max_iter=2)
    assert pattern.name == shown
    for suffix in (".obj", ".flat.obj", ".svg", ".pdf", ".dxf"):
        springflat.write_pattern(tmp_path / f"p{suffix}", pattern, units="m")  # (a scan in metres)
    obj = (tmp_path / "p.obj").read_text(encoding="utf-8").splitlines()
    assert obj[0] == f"# springflat pattern of '{shown}': v = the 3D mesh in m, vt = the flattened pattern"
    assert sum(line.startswith("v ") for line in obj) == len(V) and sum(line.startswith("f ") for line in obj) == len(F)
    assert shown in (tmp_path / "p.svg").read_text(encoding="utf-8")
    assert (tmp_path / "p.flat.obj").read_text(encoding="utf-8").splitlines()[0] == \
        f"# springflat layout of '{shown}': x, y in m, z = 0"


@pytest.mark.parametrize("make, message", [
    (lambda V, F: ([[0, 0, 0], [1, 0]], F),
     r"^V must be an array of \(V, 3\) vertex positions: its rows are not all of one length$"),
    (lambda V, F: (V.astype(complex), F), r"V must be an array of \(V, 3\) vertex positions, got complex128 values"),
    (lambda V, F: (V.astype(str), F), r"V must be an array of \(V, 3\) vertex positions, got <U\d+ values"),
    (lambda V, F: (V, F.astype(str)), r"F must be an array of \(F, 3\) vertex indices, got <U\d+ values"),
    (lambda V, F: (V > 0, F), r"^V must be an array of \(V, 3\) vertex positions, got bool values$"),
    (lambda V, F: (V, F > 0), r"^F must be an array of \(F, 3\) vertex indices, got bool values$"),
    (lambda V, F: (np.ma.masked_greater(V, V.max() - 1e-9), F),
     r"^V has masked entries: a mesh has no missing vertex positions; fill or drop them$"),
    (lambda V, F: (V, F + 0.5), r"face indices must be integers"),  # whole numbers as floats are taken (below)
    (lambda V, F: (V, np.vstack([F, [0.0, 1.0, np.nan]])), r"face indices must be integers"),  # (no cast warning)
])
def test_arrays_that_are_no_arrays_of_numbers_are_mesh_errors(ear, make, message):
    with pytest.raises(MeshError, match=message):
        springflat.flatten(*make(*ear), max_iter=1)


def test_none_is_an_option_left_out_whichever_option_it_is(ear):
    """``engine=None`` raised a bare ValueError and ``update=None``, ``penalty=None`` a ParameterError, where
    ``dynamics=None`` meant the default: ``None`` is now the default for every option."""
    V, F = ear
    reference = springflat.flatten(V, F)
    for keyword in springflat.OPTIONS:
        pattern = springflat.flatten(V, F, **{keyword: None})
        assert pattern.params == reference.params, keyword
        np.testing.assert_array_equal(pattern.layout, reference.layout)


def test_write_pattern_does_not_write_a_pattern_through_a_link_to_a_mesh(ear, tmp_path):
    """A link named like a pattern that points at a mesh: the mesh would have become a DXF."""
    V, F = ear
    (tmp_path / "scan.obj").write_text("a mesh\n")
    (tmp_path / "link.dxf").symlink_to("scan.obj")
    with pytest.raises(springflat.OutputError, match="write_pattern: the path '.*link.dxf' is a symbolic link to "
                                                    "'.*scan.obj', a file of another kind \\(.obj, not .dxf\\)"):
        springflat.write_pattern(tmp_path / "link.dxf", springflat.flatten(V, F, max_iter=1))
    assert (tmp_path / "scan.obj").read_text() == "a mesh\n"


def test_write_pattern_does_not_write_over_the_files_the_run_read(tmp_path, monkeypatch):
    """A mesh that is a springflat pattern .obj (its own kind of file, which write_pattern replaces) and a start
    layout that is a .flat.obj: written over by the pattern of their own run, directly or through a link, they
    would be gone, as the command refuses (`--out` the same file as the mesh)."""
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        springflat.write_pattern("mesh.obj", springflat.flatten("surf1", max_iter=2))
        springflat.write_pattern("start.flat.obj", springflat.flatten("surf1", max_iter=2))
        pattern = springflat.flatten("mesh.obj", init="start.flat.obj", max_iter=2)
    assert pattern.read_files == (tmp_path / "mesh.obj", tmp_path / "start.flat.obj")
    (tmp_path / "link.obj").symlink_to("mesh.obj")
    before = {name: (tmp_path / name).read_bytes() for name in ("mesh.obj", "start.flat.obj")}
    for path, read in [("mesh.obj", "mesh.obj"), (tmp_path / "link.obj", "mesh.obj"),
                       ("start.flat.obj", "start.flat.obj")]:
        with pytest.raises(springflat.OutputError, match=f"write_pattern: the path '.*' is the same file as the "
                                                        f"run's input '{tmp_path}/{read}'"):
            springflat.write_pattern(path, pattern)
    assert {name: (tmp_path / name).read_bytes() for name in before} == before
    springflat.write_pattern("other.obj", pattern)  # any other file is written
    assert springflat.flatten(np.asarray(pattern.vertices), np.asarray(pattern.faces), max_iter=1).read_files == ()
    for name in ("surf1", "slim"):  # a built-in's name and a method's, though files of those names are here
        (tmp_path / name).write_text("")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert springflat.flatten("surf1", init="slim", max_iter=1).read_files == ()
        (tmp_path / "f.json").write_text(json.dumps(FormatSet.load("default").to_dict()))
        assert springflat.flatten("surf1", engine="fixed", formats="f.json", max_iter=1).read_files == (
            tmp_path / "f.json",)


def test_write_pattern_takes_a_pattern_and_a_real_bool(ear, tmp_path):
    V, F = ear
    with pytest.raises(TypeError, match="write_pattern takes a file path \\(str or pathlib.Path\\), not NoneType"):
        springflat.write_pattern(None, springflat.flatten(V, F, max_iter=1))
    with pytest.raises(TypeError, match="write_pattern takes the Pattern that flatten returns, not tuple"):
        springflat.write_pattern(tmp_path / "x.dxf", (V, F))
    with pytest.raises(TypeError, match="dxf_edges must be True or False, got 'no'"):
        springflat.write_pattern(tmp_path / "x.dxf", springflat.flatten(V, F, max_iter=1), dxf_edges="no")
    with pytest.raises(springflat.OutputError, match="expected a file name, got '.*x.dxf/' \\(a trailing '/' names a "
                                                    "directory"):
        springflat.write_pattern(f"{tmp_path}/x.dxf/", springflat.flatten(V, F, max_iter=1))
    with pytest.raises(springflat.OutputError, match="expected a file name, got '.*x.dxf/.' \\(a trailing '.' names a "
                                                    "directory"):
        springflat.write_pattern(f"{tmp_path}/x.dxf/.", springflat.flatten(V, F, max_iter=1))
    for path, message in [("", "write_pattern: expected a file name, got ''"),
                          (tmp_path / ".dxf", "write_pattern: the path '.*/.dxf' is a file-name ending, not a file "
                                              "name: name the file \\(e.g. '.*/pattern.dxf'\\)")]:
        with pytest.raises(springflat.OutputError, match=message):
            springflat.write_pattern(path, springflat.flatten(V, F, max_iter=1))
    assert list(tmp_path.iterdir()) == []


def test_the_api_s_errors_are_importable_from_the_package():
    assert (springflat.MeshError, springflat.ParameterError) == (MeshError, ParameterError)
    assert all(issubclass(e, ValueError) for e in (springflat.MeshError, springflat.ParameterError,
                                                   springflat.OutputError))


def test_bad_arrays_are_one_line_mesh_errors_without_a_temporary_path():
    V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float)
    with pytest.raises(MeshError) as refused:
        springflat.flatten(V, np.array([[0, 1, 2], [0, 2, 3]]))
    assert "degenerate" in str(refused.value) and "tmp" not in str(refused.value)
    with pytest.raises(MeshError, match="no such file"):
        springflat.read_mesh("nope.obj")


def test_write_pattern_and_read_mesh(ear, tmp_path):
    from ezdxf import recover

    V, F = ear
    mesh = load_mesh(SCANS / "bunny_ear.obj")
    np.testing.assert_array_equal(V, mesh.vertices)
    np.testing.assert_array_equal(F, mesh.faces)
    pattern = springflat.flatten(V, F, max_iter=10, name="ear")
    springflat.write_pattern(tmp_path / "ear.dxf", pattern, units="m")
    doc, auditor = recover.readfile(tmp_path / "ear.dxf")
    assert not auditor.has_errors and doc.header["$INSUNITS"] == 6
    assert doc.ezdxf_metadata()["springflat_mesh"] == "ear"


def test_arrays_with_a_face_wound_against_its_neighbours_are_turned_with_a_note():
    from sim.generate import grid_faces, grid_uv

    uv = grid_uv(6, 6)
    faces = grid_faces(6, 6)
    faces[3] = faces[3][[0, 2, 1]]
    with pytest.warns(springflat.MeshNote, match="1 face wound against its neighbours: turned"):
        pattern = springflat.flatten(np.column_stack([uv, 0.3 * (uv**2).sum(axis=1)]), faces, max_iter=20)
    assert pattern.folded == 0 and pattern.faces[3].tolist() == faces[3][[0, 2, 1]].tolist()


def test_write_pattern_refuses_a_diverged_pattern_and_options_the_format_would_ignore(ear, tmp_path):
    V, F = ear
    with pytest.warns(springflat.MeshNote, match=r"mesh: iteration \d+ ran away: .* \(the paper dynamics has no guard: "
                                                 r"try damping=0\.05, a smaller dt, or dynamics='momentum'"):
        diverged = springflat.flatten(V, F, dynamics="paper", step="fixed", dt=1e6, max_iter=100)
    assert diverged.status == "diverged"  # (it came back with no word)
    for path in ("d.dxf", "d.obj", "d.flat.obj", "d.flat.svg"):
        with pytest.raises(springflat.OutputError, match=r"^write_pattern: the run diverged after \d+ iterations: its "
                                                         r"last finite layout is no pattern$"):
            springflat.write_pattern(tmp_path / path, diverged)
    pattern = springflat.flatten(V, F, max_iter=1)
    with pytest.raises(springflat.OutputError, match="dxf_edges draws the mesh's edges into a DXF pattern, not "):
        springflat.write_pattern(tmp_path / "p.pdf", pattern, dxf_edges=True)
    with pytest.raises(springflat.OutputError, match="paper is the sheet of a PDF or SVG pattern, not "):
        springflat.write_pattern(tmp_path / "p.dxf", pattern, paper="letter")
    assert list(tmp_path.iterdir()) == []


def test_write_pattern_notes_a_true_scale_pattern_too_small_for_its_units(ear, tmp_path):
    V, F = ear  # a scan in metres: a few centimetres across
    pattern = springflat.flatten(V, F, max_iter=1)
    with pytest.warns(springflat.MeshNote, match=r"mm at 1:1 with units='mm': if the mesh is in metres, centimetres "
                                                 r"or inches, say so with units='m', units='cm' or units='in'"):
        springflat.write_pattern(tmp_path / "ear.dxf", pattern)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no note at the right units, nor for a texture
        springflat.write_pattern(tmp_path / "ear.pdf", pattern, units="m")
        springflat.write_pattern(tmp_path / "ear.obj", pattern)


def test_a_pattern_keeps_its_own_arrays_and_prints_short(ear):
    V, F = (array.copy() for array in ear)
    pattern = springflat.flatten(V, F, max_iter=1, name="ear")
    V *= 1000
    F[:] = 0
    np.testing.assert_array_equal(pattern.vertices, ear[0])
    np.testing.assert_array_equal(pattern.faces, ear[1])
    assert re.fullmatch(rf"Pattern\(name='ear', status='max-iterations', iterations=1, area_error=\S+, "
                        rf"shape_error=\S+, folded=0, {len(V)} vertices, {len(F)} faces\)", repr(pattern))


def test_the_api_raises_only_its_documented_errors_on_paths_and_options(ear):
    V, F = ear
    with pytest.raises(MeshError, match=r"^cannot read mesh 'a\\x00b.obj': a file name cannot hold a NUL character"):
        springflat.read_mesh("a\0b.obj")
    with pytest.raises(ParameterError, match="^init 'a\\\\x00b.txt': a file name cannot hold a NUL character"):
        springflat.flatten(V, F, init="a\0b.txt")
    with pytest.raises(springflat.OutputError, match="a file name cannot hold a NUL character"):
        springflat.write_pattern("a\0b.svg", springflat.flatten(V, F, max_iter=1))
    with pytest.raises(ParameterError, match="^formats applies to the fixed-point engines: engine='fixed' or "
                                             "engine='rtl'$"):  # the API's words: no --formats, no board
        springflat.flatten(V, F, formats="wide")
    with pytest.raises(ParameterError, match=r"^cannot read layout 'ARAP': no such file, nor a start method \(auto, "
                                             r"tutte, pca, harmonic, lscm, arap, slim\)$"):
        springflat.flatten(V, F, init="ARAP")
    with pytest.raises(TypeError, match="name must be a string"):
        springflat.flatten(V, F, name=3)
    with pytest.raises(MeshError, match=r"^cannot read mesh 'a\\x00b.obj': a file name cannot hold a NUL character"):
        springflat.flatten("a\0b.obj")
    with pytest.raises(springflat.OutputError, match="paper must be one of a4, a3, letter, fit, got ''"):
        springflat.write_pattern("p.pdf", springflat.flatten(V, F, max_iter=1), paper="")
    with pytest.raises(springflat.OutputError, match=r"^write_pattern: the path 'no/where/p.dxf': directory "
                                                     r"'no/where' does not exist$"):  # not "no such file"
        springflat.write_pattern("no/where/p.dxf", springflat.flatten(V, F, max_iter=1))
    with pytest.raises(springflat.OutputError, match=r"^write_pattern: cannot write the path 'x{300}\.dxf': file "
                                                     r"name too long$"):
        springflat.write_pattern("x" * 300 + ".dxf", springflat.flatten(V, F, max_iter=1))


def test_a_format_set_the_rtl_cannot_build_is_a_parameter_error(ear, tmp_path):
    import json

    from golden_model.fixed import FormatSet

    V, F = ear
    formats = FormatSet.preset("default").to_dict()
    formats["formats"]["delta"] = "s3.23"  # finer than position's 22 fraction bits: the force pass refuses it
    formats["name"] = "fine_delta"  # (a set of a preset's name must be that preset)
    (tmp_path / "f.json").write_text(json.dumps(formats))
    with pytest.raises(ParameterError, match="delta s3.23 cannot have more fraction bits than position"):
        springflat.flatten(V, F, engine="rtl", formats=str(tmp_path / "f.json"), max_iter=1)


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_a_signal_while_write_pattern_commits_goes_to_the_programs_own_handler_and_leaves_no_trace(
        ear, tmp_path, monkeypatch, signum):
    """The signal is held while the file is put in place, then answered by the handler the program had; the
    next write works (a Jupyter session that survives a Ctrl-C can go on writing patterns)."""
    import os
    import signal as signals

    pattern = springflat.flatten(*ear, max_iter=3)
    calls = []
    number = getattr(signals, signum)
    before = signals.signal(number, lambda n, frame: calls.append(n))
    real = os.replace

    def replace_as_the_signal_arrives(src, dst):
        os.kill(os.getpid(), number)
        return real(src, dst)

    try:
        monkeypatch.setattr(os, "replace", replace_as_the_signal_arrives)
        springflat.write_pattern(tmp_path / "first.dxf", pattern, units="m")
        monkeypatch.setattr(os, "replace", real)
        assert calls == [number]  # the program's own handler, once, after the commit
        springflat.write_pattern(tmp_path / "second.dxf", pattern, units="m")
    finally:
        signals.signal(number, before)
    assert (tmp_path / "first.dxf").read_bytes() == (tmp_path / "second.dxf").read_bytes()


def test_faces_given_as_whole_floats_are_their_indices(ear):
    """np.loadtxt reads a CSV of indices as floats: they are the same faces, the same pattern."""
    V, F = ear
    as_floats = springflat.flatten(V, F.astype(float), max_iter=3)
    assert np.array_equal(as_floats.layout, springflat.flatten(V, F, max_iter=3).layout)
    assert as_floats.faces.dtype.kind == "i"


def _strip_wound_past_a_turn() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat 40 × 1 strip (V, F) and a fold-free layout of it wound through 430°: its end lies on its start."""
    columns = 41
    u, v = np.meshgrid(np.arange(columns, dtype=float), np.arange(2, dtype=float))
    vertices = np.c_[u.ravel(), v.ravel(), np.zeros(u.size)]
    faces = np.array([[k, k + 1, k + columns + 1] for k in range(columns - 1)]
                     + [[k, k + columns + 1, k + columns] for k in range(columns - 1)])
    angle, radius = u.ravel() / (columns - 1) * np.radians(430), 7.0 - v.ravel()  # counter-clockwise, as the mesh
    return vertices, faces, np.c_[radius * np.cos(angle), radius * np.sin(angle)]


def test_a_pattern_that_overlaps_itself_says_so_though_no_triangle_is_folded():
    """Fold-free is not one to one: a pattern whose boundary crosses itself has parts lying on each other."""
    vertices, faces, wound = _strip_wound_past_a_turn()
    with pytest.warns(springflat.MeshNote,
                      match=r"overlaps itself, though no triangle is folded: \d+ pairs of its boundary's sides meet"):
        pattern = springflat.flatten(vertices, faces, init=wound, max_iter=1)
    assert pattern.folded == 0 and pattern.boundary_crossings > 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flat = springflat.flatten(vertices, faces, init=vertices[:, :2], max_iter=1)  # the strip as it is
    assert flat.boundary_crossings == 0


def test_the_json_counts_the_boundary_crossings(tmp_path, capsys):
    vertices, faces, wound = _strip_wound_past_a_turn()
    trimesh.Trimesh(vertices, faces, process=False).export(tmp_path / "strip.obj")
    np.savetxt(tmp_path / "wound.txt", wound)
    assert main(["flatten", str(tmp_path / "strip.obj"), "--init", str(tmp_path / "wound.txt"), "--max-iter", "1",
                 "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["folded"] == 0 and summary["boundary_crossings"] > 0
    assert "the pattern overlaps itself" in captured.err


def test_a_folded_pattern_warns_in_the_apis_words():
    """Surf1 under the paper's dynamics from PCA ends with 3 folded triangles: a MeshNote says so, naming the
    keyword that keeps triangles from folding (not the command line's --dynamics)."""
    from golden_model.builtin import builtin_mesh

    mesh, _ = builtin_mesh("surf1")
    with pytest.warns(springflat.MeshNote) as caught:
        pattern = springflat.flatten(mesh.vertices, mesh.faces, dynamics="paper", init="pca", name="surf1")
    notes = [str(w.message) for w in caught if "folded" in str(w.message)]
    assert pattern.folded == 3 and notes == [
        "surf1: the pattern has 3 folded triangles, flipped over their neighbours: cut along its boundary it is not "
        "the mesh's piece; the paper dynamics does not keep triangles from folding; the momentum dynamics with its "
        "step guard does: dynamics='momentum' (it takes none of step, dt, damping, density); docs/guard.md"]
    with pytest.warns(springflat.MeshNote) as caught:  # with the paper dynamics' barrier on: it did not hold either
        pattern = springflat.flatten(mesh.vertices, mesh.faces, dynamics="paper", init="pca", name="surf1",
                                     barrier=True)
    notes = [str(w.message) for w in caught if "folded" in str(w.message)]
    assert pattern.folded > 0 and len(notes) == 1 and ("the paper dynamics does not keep triangles from folding, nor "
                                                       "does its fold barrier, a force that only pushes back; the "
                                                       "momentum dynamics") in notes[0]


def test_write_patterns_refusals_speak_the_apis_keywords(tmp_path):
    """The print-size refusals name units= and paper=, not the command line's --units and --paper, and every
    refusal of write_pattern starts with its name."""
    from golden_model.builtin import builtin_mesh

    mesh, _ = builtin_mesh("surf1")
    big = springflat.flatten(mesh.vertices * 1000, mesh.faces, max_iter=3)
    with pytest.raises(springflat.OutputError) as info:
        springflat.write_pattern(tmp_path / "huge.pdf", big, units="m")
    assert re.fullmatch(r"write_pattern: the pattern is .* m at 1:1 with units='m': .* a4 sheets \(at most 400\); "
                        r"check units, or write \.dxf", str(info.value)), str(info.value)
    x, y = np.meshgrid(np.linspace(0.0, 5.5, 12), np.linspace(0.0, 1.0, 3))  # a 5.5 x 1 m strip, slightly bent
    strip_v = np.column_stack([x.ravel(), y.ravel(), 0.01 * np.sin(x.ravel())])
    strip_f = np.array([[r * 12 + c, r * 12 + c + 1, (r + 1) * 12 + c + 1] for r in range(2) for c in range(11)]
                       + [[r * 12 + c, (r + 1) * 12 + c + 1, (r + 1) * 12 + c] for r in range(2) for c in range(11)])
    with pytest.raises(springflat.OutputError) as info:
        springflat.write_pattern(tmp_path / "fit.svg", springflat.flatten(strip_v, strip_f, max_iter=3), units="m",
                                 paper="fit")
    assert str(info.value).endswith("check units, print it tiled (paper='a4', 'a3' or 'letter'), or write .dxf")
    assert "--" not in str(info.value)
    with pytest.raises(springflat.OutputError, match="^write_pattern: units must be one of mm, cm, m, in, got 'ft'$"):
        springflat.write_pattern(tmp_path / "p.dxf", big, units="ft")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_fixed_point_run_that_ran_away_into_its_range_warns_in_the_api_too():
    """The fixed-point engine holds a runaway at the top of its formats (E_S just below 1) instead of diverging: the
    API says so as the command does, where the grown-away note (E_S above 1) cannot see it."""
    from golden_model.builtin import builtin_mesh

    mesh, _ = builtin_mesh("surf1")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pattern = springflat.flatten(mesh.vertices, mesh.faces, engine="fixed", dynamics="paper", step="fixed", dt=0.9,
                                     max_iter=200, init="pca", name="surf1", tol_area=0, tol_shape=0, tol_energy=0,
                                     density=2.0, spring=0.5)  # the command's Surf1: its paper parameters
    notes = [str(w.message) for w in caught if issubclass(w.category, springflat.MeshNote)]
    assert pattern.status == "max-iterations" and pattern.area_error < 1
    assert any(note.startswith("surf1: format set 'default' clamped") and "E_S or E_C is at the top of its format: "
               "the run ran away" in note for note in notes), notes


def test_a_mesh_the_formats_cannot_hold_names_the_preset_by_its_keyword():
    """A cone's tip of 40 spokes: the default formats sum at most 32 neighbours; the API names formats='wide'."""
    angle = 2 * np.pi * np.arange(40) / 40
    V = np.vstack([[0.0, 0.0, 0.5], np.column_stack([np.cos(angle), np.sin(angle), np.zeros(40)])])
    F = np.array([[0, 1 + i, 1 + (i + 1) % 40] for i in range(40)])
    with pytest.raises(ParameterError) as info:  # a FixedPointError, which is a ParameterError
        springflat.flatten(V, F, engine="fixed")
    assert str(info.value) == ("a node has 40 neighbours; format set 'default' accumulates at most 32 (max_degree); "
                               "the preset wide holds it: formats='wide'")


def test_the_commands_option_words_become_the_apis_keywords():
    from springflat.api import _in_api_words

    assert _in_api_words("the presets default, narrow, wide hold it: --formats default or narrow or wide") == \
        "the presets default, narrow, wide hold it: formats='default' or 'narrow' or 'wide'"
    assert _in_api_words("check --units, print it tiled (--paper a4 or letter), or with --units m") == \
        "check units, print it tiled (paper='a4' or 'letter'), or with units='m'"


def test_the_commands_switches_and_drops_become_keyword_values():
    from springflat.api import _in_api_words

    assert _in_api_words("the paper dynamics has none (drop --guard); drop --damping, or use --no-guard") == \
        "the paper dynamics has none (guard=False); drop damping, or use guard=False"
    assert _in_api_words("--tol-energy 1e-30 is below; --damping belongs to it; --formats applies") == \
        "tol_energy=1e-30 is below; damping belongs to it; formats applies"
    # a method is quoted as an init, a file name never taken for a value, a full stop not part of one
    assert _in_api_words("give --init slim; --distortion writes a CSV; at most --max-iter 10.") == \
        "give init='slim'; distortion writes a CSV; at most max_iter=10."


@pytest.mark.parametrize("options", [dict(spring=-1), dict(dynamics="paper", guard=True), dict(damping=0.5),
                                     dict(engine="fixed", tol_energy=1e-30), dict(penalty=True),
                                     dict(barrier_gain=1e9), dict(max_iter=True), dict(spring=1e-320)])
def test_a_refused_keyword_is_named_as_a_keyword_not_a_flag(ear, options):
    V, F = ear
    with pytest.raises(ValueError) as info:
        springflat.flatten(V, F, **options)
    assert "--" not in str(info.value) and any(keyword in str(info.value) for keyword in options), str(info.value)

def test_a_call_leaves_no_thread_behind():
    """The first call started tqdm's monitor thread, for the process's life, though it shows no bar."""
    code = ("import threading, springflat; from golden_model.builtin import builtin_mesh; "
            "m, _ = builtin_mesh('surf1'); springflat.flatten(m.vertices * 100, m.faces, max_iter=3); "
            "print(sorted(t.name for t in threading.enumerate()))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "['MainThread']"


def test_write_pattern_takes_a_grain(ear, tmp_path):
    import ezdxf

    V, F = ear
    pattern = springflat.flatten(V * 1000, F, max_iter=5)
    springflat.write_pattern(tmp_path / "g.dxf", pattern, grain="z")
    assert len(ezdxf.readfile(tmp_path / "g.dxf").modelspace().query('LWPOLYLINE[layer=="GRAIN"]')) == 3
    with pytest.raises(springflat.OutputError, match=r"^write_pattern: grain 'q': expected x, y or z"):
        springflat.write_pattern(tmp_path / "h.dxf", pattern, grain="q")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.dxf"]


def test_a_patterns_arrays_are_read_only(ear):
    """A frozen Pattern whose arrays could be edited in place (p.layout *= 1000) went stale: its errors, area
    ratios and distortion were of the old values."""
    V, F = ear
    pattern = springflat.flatten(V, F, max_iter=2)
    for array in (pattern.layout, pattern.area_ratio, pattern.vertices, pattern.faces, pattern.result.velocities,
                  pattern.result.initial_positions):
        with pytest.raises(ValueError, match="read-only"):
            array[...] = 0
    assert np.array_equal(pattern.layout.copy() * 2, pattern.layout * 2)  # a copy is the caller's to change


def test_write_pattern_takes_a_grain_as_three_numbers(ear, tmp_path):
    """The docs give grain=(1, 0, 1): it was passed on as the text '(1, 0, 1)', which no grain reads."""
    import ezdxf

    V, F = ear
    pattern = springflat.flatten(V * 1000, F, max_iter=5)
    springflat.write_pattern(tmp_path / "g.dxf", pattern, grain=(0, 0, 2))
    doc = ezdxf.readfile(tmp_path / "g.dxf")
    assert doc.ezdxf_metadata()["springflat_grain"] == "0,0,2"
    assert len(doc.modelspace().query('LWPOLYLINE[layer=="GRAIN"]')) == 3


def test_a_pattern_below_half_its_surface_area_says_so_one_at_its_size_does_not():
    """E_S cannot tell a pattern shrunk to a tenth (E_S at most 1) from a good one; the note gives the area's share.
    A flat grid started from its own layout squeezed to a quarter across and stretched by 1.6 along (40 % of its
    area, near the mesh's size by its edge lengths: taken as it is) and stopped after one Jacobi step (the coarse
    space's affine move would restore most of the area at once): every triangle still smaller than its own, so the
    share is 1 - E_S; started from its own layout, the pattern is the grid."""
    from sim.generate import grid_faces, grid_uv

    uv = grid_uv(6, 6, 10.0, 10.0)
    vertices, faces = np.column_stack([uv, np.zeros(len(uv))]), grid_faces(6, 6)
    with pytest.warns(springflat.MeshNote, match=r"the pattern's area is \d+% of the surface's") as notes:
        pattern = springflat.flatten(vertices, faces, init=uv * [0.25, 1.6], max_iter=1, coarse_degree=0)
    said = next(str(n.message) for n in notes if "the pattern's area is" in str(n.message))
    share = int(re.search(r"area is (\d+)%", said).group(1))
    assert np.all(pattern.area_ratio < 1) and share == round(100 * (1 - pattern.area_error)) and share < 50
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        springflat.flatten(vertices, faces, init=uv, max_iter=1)
    assert not [w for w in caught if "area is" in str(w.message)]


def test_arrays_with_a_seam_left_open_get_the_files_note_and_hint():
    """The API reads arrays as the command reads files: an open seam is a MeshNote; a heap of triangles is refused
    with the hint that welding may make it one disk."""
    from sim.generate import grid_faces, grid_uv

    grid = np.column_stack([grid_uv(4, 4, 10.0, 10.0), np.zeros(16)])
    faces = grid_faces(4, 4)
    with pytest.raises(MeshError, match=r"connected components; \d+ vertices lie on one another in \d+ places with "
                                        r"no edge between them \(an exporter's seam\?\): weld them first \(trimesh's "
                                        r"merge_vertices, MeshLab's Merge Close Vertices\), and it may be one disk$"):
        springflat.flatten(grid[faces].reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3))
    right = grid[faces].mean(axis=1)[:, 0] > grid[1, 0]  # vertex 1, on the edge, copied for the faces right of it
    faces[right] = np.where(faces[right] == 1, 16, faces[right])
    with pytest.warns(springflat.MeshNote, match=r"mesh: 2 vertices lie on one another in 1 place with no edge "):
        springflat.flatten(np.vstack([grid, grid[1]]), faces, max_iter=2)


def test_a_seam_left_open_in_a_file_is_said_once_by_read_mesh_then_flatten(tmp_path):
    """read_mesh gives its reader's notes, flatten the seam's: once, not from both."""
    from sim.generate import grid_faces, grid_uv
    from sim.mesh_io import save_obj

    grid = np.column_stack([grid_uv(4, 4, 10.0, 10.0), np.zeros(16)])
    faces = grid_faces(4, 4)
    right = grid[faces].mean(axis=1)[:, 0] > grid[1, 0]
    faces[right] = np.where(faces[right] == 1, 16, faces[right])
    save_obj(tmp_path / "seam.obj", np.vstack([grid, grid[1]]), faces)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        springflat.flatten(*springflat.read_mesh(tmp_path / "seam.obj"), max_iter=2)
    assert len([w for w in said if "lie on one another" in str(w.message)]) == 1


def test_the_options_help_speaks_keywords():
    """help(flatten) listed the command's help texts as they are ('drop --damping, or add --dynamics paper');
    a flag the API has no keyword for (the board's --port) is the command line's to speak of."""
    flag = re.compile(r"--(?:no-)?([a-z][a-z0-9-]*)")
    for spec in springflat.OPTIONS.values():
        line = next(line for line in springflat.flatten.__doc__.splitlines() if f"``{spec.keyword}`` (" in line)
        spoken = {name.replace("-", "_") for name in flag.findall(line.split(":", 1)[1])}
        assert not spoken & set(springflat.OPTIONS), line


def test_formats_takes_a_format_set_or_its_dict(ear):
    """A researcher sweeping word lengths had to write a JSON file for every set."""
    from golden_model.fixed.formats_set import FormatSet

    V, F = ear
    by_name = springflat.flatten(V, F, engine="fixed", formats="wide", max_iter=5)
    narrower = FormatSet.preset("default")
    for formats in (FormatSet.preset("wide"), FormatSet.preset("wide").to_dict()):
        assert np.array_equal(springflat.flatten(V, F, engine="fixed", formats=formats, max_iter=5).layout,
                              by_name.layout)
    assert not np.array_equal(springflat.flatten(V, F, engine="fixed", formats=narrower, max_iter=5).layout,
                              by_name.layout)
    with pytest.raises(ParameterError, match="^formats: FormatSet 'custom': missing 'formats' object$"):
        springflat.flatten(V, F, engine="fixed", formats={"position": "s8.20"})


def test_a_mesh_named_is_read_and_run_as_the_command_runs_it(tmp_path, capsys):
    """flatten('surf1') was a TypeError and read_mesh('surf1') 'no such file', though the command takes it; a
    built-in runs with the paper's parameters and start, a file with its defaults and its name."""
    from golden_model.builtin import builtin_mesh

    with pytest.warns(springflat.MeshNote, match="folded"):  # (the paper's dynamics, as the command's)
        pattern = springflat.flatten("surf1")
    assert (pattern.name, pattern.init, pattern.params) == ("surf1", "pca", builtin_mesh("surf1")[1].flatten_params())
    assert main(["flatten", "surf1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert (summary["status"], summary["iterations"], summary["area_error"], summary["shape_error"]) == \
        (pattern.status, pattern.iterations, pattern.area_error, pattern.shape_error)
    V, F = springflat.read_mesh("SURF1")
    assert np.array_equal(V, pattern.vertices) and np.array_equal(F, pattern.faces)

    path = SCANS / "bunny_ear.obj"
    from_file = springflat.flatten(path, max_iter=3)
    from_arrays = springflat.flatten(*springflat.read_mesh(path), max_iter=3)
    assert from_file.name == "bunny_ear" and from_arrays.name == "mesh"
    assert np.array_equal(from_file.layout, from_arrays.layout) and from_file.params == from_arrays.params
    assert springflat.flatten(str(path), name="ear", max_iter=3).name == "ear"
    with pytest.raises(MeshError, match="no built-in mesh of that name"):
        springflat.flatten("surf3")
    with pytest.raises(TypeError, match="alone, or two arrays"):
        springflat.flatten(path, F)


def test_a_files_notes_are_warnings_and_its_holes_hint_speaks_keywords(tmp_path):
    quad = tmp_path / "quad.obj"
    quad.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0.1\nv 0 1 0\nf 1 2 3 4\n")
    with pytest.warns(springflat.MeshNote, match="^quad: .*triangulated"):
        springflat.flatten(quad, max_iter=2)
    with warnings.catch_warnings(record=True) as said:  # one name for the file's notes and the run's
        warnings.simplefilter("always")
        springflat.flatten(quad, max_iter=2, name="panel")
    assert said and all(str(w.message).startswith("panel: ") for w in said), [str(w.message) for w in said]
    ring = tmp_path / "ring.obj"
    ring.write_text("".join(f"v {np.cos(a):.6f} {np.sin(a):.6f} 0\nv {2 * np.cos(a):.6f} {2 * np.sin(a):.6f} 0\n"
                            for a in np.arange(8) * np.pi / 4)
                    + "".join(f"f {2 * k + 1} {2 * k + 2} {(2 * k + 2) % 16 + 2}\nf {2 * k + 1} {(2 * k + 2) % 16 + 2} "
                              f"{(2 * k + 2) % 16 + 1}\n" for k in range(8)))
    with pytest.raises(MeshError) as refused:
        springflat.flatten(ring)
    assert "keep_holes=True" in str(refused.value) and "--" not in str(refused.value)
    assert springflat.flatten(ring, keep_holes=True, max_iter=2).faces.shape == (16, 3)


def test_a_refused_mesh_file_says_what_it_refuses_to_an_api_caller(tmp_path):
    """MeshError's faces, vertices and defect (what a program can act on) came through as a plain message."""
    from golden_model.mesh import MeshDefect

    path = tmp_path / "extra.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\n")
    with pytest.raises(MeshError) as refused:
        springflat.flatten(path)
    assert (refused.value.vertices, refused.value.defect) == ((3,), MeshDefect.UNUSED_VERTEX)
    with pytest.raises(MeshError) as refused:
        springflat.flatten(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]]), [[0, 1, 2]])
    assert (refused.value.vertices, refused.value.defect) == ((3,), MeshDefect.UNUSED_VERTEX)


@pytest.mark.parametrize("value", [5, [1], b"default"])
def test_formats_of_another_type_is_refused_as_such(value):
    """formats=5 was looked up as a preset named '5'."""
    with pytest.raises(ParameterError, match=r"^formats takes a preset's name, a JSON file's path, a FormatSet or its "
                                             rf"to_dict\(\), not a {type(value).__name__}$"):
        springflat.flatten("surf1", engine="fixed", formats=value)


@pytest.mark.parametrize("power", [-30, 30])
@pytest.mark.parametrize("init", [None, "slim"])  # the no-option start (ARAP's, here) and the one where ARAP folds
def test_a_run_gives_the_same_pattern_at_any_size(ear, power, init):
    """A mesh in metres, millimetres or microns is the same patch: made 2^±30 times as large (a factor that rounds
    nothing), the start, every step and stop of the guarded run are the same, and the pattern is the same,
    scaled, to the last bit. An absolute threshold anywhere (libigl's SLIM had some) shows here."""
    V, F = ear
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (the units note: a pattern 1e-9 mm across)
        reference, scaled = springflat.flatten(V, F, init=init), springflat.flatten(V * 2.0 ** power, F, init=init)
    assert (scaled.status, scaled.iterations, scaled.folded) == (reference.status, reference.iterations, 0)
    np.testing.assert_array_equal(scaled.layout, reference.layout * 2.0 ** power)
    assert (scaled.area_error, scaled.shape_error) == (reference.area_error, reference.shape_error)


@pytest.mark.parametrize("options, said", [
    ({"penalty": True, "penalty_gain": 2.0}, "penalty=False and drop penalty_gain"),
    ({"penalty_kappa": 0.0}, "drop penalty_kappa"),  # (0 is a value given)
])
def test_the_fixed_point_engine_refuses_the_penalty_in_the_apis_words(options, said):
    with pytest.raises(ParameterError, match=rf"^the penalty is not part of the fixed-point pipeline; {said}$"):
        springflat.flatten("surf1", engine="fixed", **options)
