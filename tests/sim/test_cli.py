"""The springflat command: round trips and bad input, as a user runs it."""

import csv
import json
import os
import re
from pathlib import Path
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from golden_model.builtin import builtin_mesh
from sim.mesh_io import load_mesh
from sim.generate import dome_grid
from support import SCANS, press_ctrl_c, run_springflat as run


def test_flatten_round_trip(tmp_path):
    out, hist, plot = tmp_path / "flat.flat.obj", tmp_path / "h.csv", tmp_path / "p.png"  # .flat.obj: z = 0
    proc = run("flatten", "surf1", "--out", out, "--history", hist, "--plot", plot, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    for key in ("status", "iterations", "area_error", "shape_error", "energy", "flipped",
                "initial_area_error", "initial_shape_error", "engine", "step", "update"):
        assert key in summary
    assert (summary["engine"], summary["step"], summary["update"]) == ("float", "variable", "jacobi")
    assert (summary["mode"], summary["guard"], summary["density"]) == ("paper-variable", False, 2.0)
    assert summary["status"] == "converged"

    flat = load_mesh(out)
    surf1, _ = builtin_mesh("surf1")
    assert flat.faces.tolist() == surf1.faces.tolist()
    assert (flat.vertices[:, 2] == 0).all()
    assert out.read_text().splitlines()[0] == "# springflat layout of 'surf1': x, y in mm, z = 0"

    with open(hist, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["iteration", "dt", "area_error", "shape_error", "energy", "flipped", "folded", "accepted"]
    assert {row[7] for row in rows[2:]} == {"1"}  # the paper dynamics has no guard: every step taken
    assert len(rows) == summary["iterations"] + 2
    assert rows[1][0] == "0" and rows[1][1] == ""
    assert float(rows[1][2]) == summary["initial_area_error"]
    last = rows[-1]
    assert int(last[0]) == summary["iterations"]
    assert float(last[2]) == summary["area_error"] and float(last[3]) == summary["shape_error"]
    assert int(last[5]) == summary["flipped"] and int(last[6]) == summary["folded"]
    assert 0.01 < float(rows[2][1]) <= 0.21
    # the layout written is the one whose errors were reported
    edges = surf1.edges
    lengths = np.linalg.norm(flat.vertices[edges[:, 0]] - flat.vertices[edges[:, 1]], axis=1)
    shape_error = np.abs(lengths - surf1.rest_lengths).sum() / surf1.rest_lengths.sum()
    assert shape_error == pytest.approx(summary["shape_error"], rel=1e-12)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_flatten_file_mesh_to_svg_with_options(tmp_path):
    mesh = dome_grid(6)
    path = tmp_path / "dome.off"
    with open(path, "w") as f:
        f.write(f"OFF\n{mesh.n_vertices} {mesh.n_faces} 0\n")
        np.savetxt(f, mesh.vertices)
        np.savetxt(f, np.column_stack([np.full(mesh.n_faces, 3), mesh.faces]), fmt="%d")
    svg = tmp_path / "dome.flat.svg"  # the layout in mesh units, a polygon per face (.svg is the print pattern)
    proc = run("flatten", path, "--dynamics", "paper", "--init", "tutte", "--step", "fixed", "--dt", "0.02",
               "--update", "sequential",
               "--damping", "0.1", "--density", "auto", "--max-iter", "5", "--tol-area", "0", "--out", svg, "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert (summary["status"], summary["iterations"], summary["update"], summary["step"]) == \
        ("max-iterations", 5, "sequential", "fixed")
    polygons = ET.parse(svg).getroot().findall(".//{http://www.w3.org/2000/svg}polygon")
    assert len(polygons) == mesh.n_faces


def test_version_is_the_projects():
    """``springflat --version`` and ``springflat.__version__``: the version pyproject.toml gives (the
    command on stdout, exit 0)."""
    import tomllib

    import springflat
    from support import REPO

    want = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["version"]
    proc = run("--version")
    assert (proc.returncode, proc.stdout, proc.stderr) == (0, f"springflat {want}\n", "")
    assert springflat.__version__ == want


def test_human_summary_line():
    proc = run("flatten", "surf2", "--max-iter", "3")
    assert proc.returncode == 0
    assert proc.stdout.startswith("surf2: max-iterations after 3 iterations")


def test_a_run_whose_errors_grow_huge_prints_them_in_a_few_digits():
    from golden_model.results import FlattenResult, History, Measurement
    from sim.flatten_run import human_line

    history = History()
    history.append(float("nan"), Measurement(0.26154, 0.09301, 1.0, 0, 0), None)
    history.append(1.0, Measurement(1.2812e217, 8.5e108, 1e300, 4, 2), True)
    mesh = builtin_mesh("surf1")[0]
    result = FlattenResult(mesh.vertices[:, :2], mesh.vertices[:, :2], mesh.vertices[:, :2], history, "max-iterations",
                           1, None, 1.0)
    assert human_line(mesh, result) == ("surf1: max-iterations after 1 iteration: E_S 0.2615 -> 1.28e+217, "
                                        "E_C 0.0930 -> 8.5e+108, folded 2 (flipped against P0: 4)")


def _bad_files(tmp):
    files = {}
    files["garbage.obj"] = "this is not a mesh\nv 1 2\nf 1 2 3\n"
    files["empty.obj"] = "# nothing\n"
    files["nan.obj"] = "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n"
    files["range.off"] = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n"
    files["degenerate.obj"] = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"
    files["duplicate.obj"] = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\nf 2 3 1\n"
    files["nonmanifold.obj"] = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\n"
                                "f 1 2 3\nf 1 3 4\nf 1 3 5\n")
    files["closed.obj"] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"
    files["twoparts.obj"] = ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 0\nv 6 5 0\nv 5 6 0\nf 1 2 3\nf 4 5 6\n")
    for name, text in files.items():
        (tmp / name).write_text(text)
    return list(files)


BAD_ARGS = [
    (["nope.obj"], "no such file"),
    (["--tol-area", "-1"], "tol-area"),
    (["--tol-shape", "-0.5"], "tol-shape"),
    (["--max-iter", "0"], "max-iter"),
    (["--dt", "0", "--step", "fixed"], "dt"),
    (["--damping", "1.5"], "damping"),
    (["--spring", "-2"], "spring"),
    (["--density", "heavy"], "density"),
    (["--init", "missing-layout.txt"], "no such file"),
    (["--init", "short.txt"], "rows but the mesh has 7"),
    (["--step", "wobbly"], "invalid choice"),
    (["--bogus"], "unrecognized arguments: --bogus (see 'springflat flatten --help')"),
    (["--plot", "p.jpg"], "must end in .png"),
    (["--out", "nodir/x.obj"], "does not exist"),
    (["--out", ""], "argument --out: expected a path, got ''"),
    (["--out", "newdir.dxf/"], "argument --out: expected a file name, got 'newdir.dxf/' (a trailing '/' names a "
                               "directory)"),
    (["--out", "newdir.dxf/."], "argument --out: expected a file name, got 'newdir.dxf/.' (a trailing '.' names a "
                                "directory)"),
    (["--out", "o.obj", "--history", "h.csv/.."], "argument --history: expected a file name, got 'h.csv/..' (a "
                                                  "trailing '..' names a directory)"),
    (["--out", ".dxf"], "--out '.dxf' is a file-name ending, not a file name: name the file (e.g. 'pattern.dxf')"),
    (["--out", ".flat.svg"], "--out '.flat.svg' is a file-name ending, not a file name: name the file (e.g. "
                             "'pattern.flat.svg'), or give --out-dir DIR for a batch"),
    (["--out", "o.obj", "--history", ".history.csv"], "--history '.history.csv' is a file-name ending, not a file name"),
    (["--distortion", "d/.distortion.csv"], "--distortion 'd/.distortion.csv' is a file-name ending, not a file name: "
                                            "name the file (e.g. 'd/pattern.distortion.csv')"),
    ([""], "the mesh path is empty"),
    (["--out", "o.obj", "--history", "h.obj"], "--history 'h.obj' must end in .csv"),
    # options that this run would ignore
    (["--dt", "0.5"], "--dt is the size of the paper dynamics' fixed step: add --step fixed"),
    (["--dynamics", "momentum", "--dt", "0.5"], "the momentum dynamics takes no --dt"),
    (["--barrier-gain", "3"], "--barrier-gain sets the fold barrier, which this run has off: add --barrier"),
    (["--dynamics", "momentum", "--no-barrier", "--barrier-threshold", "0.3"], "--barrier-threshold sets the fold "
                                                                              "barrier, which this run has off"),
    (["--penalty-gain", "5"], "--penalty-gain sets the penalty: add --penalty"),
    (["--penalty-kappa", "2"], "--penalty-kappa sets the penalty: add --penalty"),
    # the fixed-point engines have no penalty: said first, not "add --penalty" and then "drop --penalty"
    (["--engine", "fixed", "--penalty-kappa", "2"], "the penalty is not part of the fixed-point pipeline; drop "
                                                    "--penalty-kappa"),
    (["--engine", "rtl", "--penalty", "--penalty-gain", "2"], "the penalty is not part of the fixed-point pipeline; "
                                                              "drop --penalty and drop --penalty-gain"),
    (["--engine", "fixed", "--penalty-gain", "0"], "the penalty is not part of the fixed-point pipeline; drop "
                                                   "--penalty-gain"),  # (0 is a value given, not none)
    (["--port", "/nowhere"], "--port sets the serial port: add --engine board"),
    (["--baud", "9600"], "--baud sets the serial port's rate: add --engine board"),
    (["--engine", "rtl", "--port", "loop://"], "--port sets the serial port of --engine board, not of --engine rtl: "
                                               "drop --port, or run --engine board"),
    (["surf1", "surf2", "--out-dir", "o", "--out", ".svg", "--baud", "9600"],  # (a batch: the board runs one mesh)
     "--baud sets the serial port's rate of --engine board, which runs one mesh at a time: drop --baud for a batch"),
    (["--dynamics", "momentum", "--step", "fixed"], "--step fixed is a step of the paper dynamics, not of the "
                                                    "momentum dynamics: drop --step, or add --dynamics paper"),
    (["--dynamics", "momentum", "--step", "variable"], "--step variable is a step of the paper dynamics"),
    (["--dynamics", "momentum", "--density", "1e-6"], "--density sets the paper dynamics' node masses; the "
                                                      "momentum dynamics weighs each node by 2/(C deg) instead"),
    (["--dynamics", "momentum", "--damping", "0"], "--damping belongs to the paper dynamics; the momentum "
                                                   "dynamics damps by its restart: drop --damping"),
    (["--dxf-edges"], "--dxf-edges draws the mesh's edges into a DXF pattern: add --out NAME.dxf"),
    (["--paper", "letter"], "--paper is the sheet of a PDF or SVG pattern: add --out NAME.pdf or NAME.svg"),
    (["--paper", "fit", "--out", "l.flat.svg"], "--paper is the sheet of a PDF or SVG pattern"),
    (["--jobs", "0"], "--jobs must be >= 1, got 0"),
    (["--jobs", "1000000"], "--jobs 1000000: at most "),
    (["--jobs", "3"], "--jobs sets a batch's worker processes: give several meshes, or --out-dir DIR"),
    (["--engine", "fixed", "--formats", ""], "the formats '' are empty: name a preset (default, narrow, wide) or a "
                                             "JSON file"),
]


def _assert_clean_failure(proc, message, tmp_path, before):
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("springflat: error")]
    assert len(lines) == 1 and message in lines[0], proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no output file, not even a partial one


@pytest.mark.parametrize("args, message", BAD_ARGS)
def test_bad_arguments(tmp_path, args, message):
    (tmp_path / "short.txt").write_text("0 0\n1 1\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    proc = run("flatten", *args, "--out", "o.obj", "--history", "h.csv", cwd=tmp_path) \
        if "--out" not in args else run("flatten", *args, cwd=tmp_path)
    _assert_clean_failure(proc, message, tmp_path, before)


@pytest.mark.parametrize("command", [["verilog"], ["paper", "--quiet"], ["study", "surf1", "--quiet"], ["synth"],
                                     ["rtl-check"], ["flatten", "surf1", "surf2", "--out", ".obj"]])
def test_an_empty_output_path_is_refused_before_anything_is_written(tmp_path, command):
    option = "--waves" if command[0] == "rtl-check" else "--out-dir" if "--out" in command else "--out"
    proc = run(*command, option, "", cwd=tmp_path)  # '' would be the current directory
    _assert_clean_failure(proc, f"argument {option}: expected a path, got ''", tmp_path, [])


@pytest.mark.parametrize("name, message", [
    ("garbage.obj", "cannot parse"), ("empty.obj", "empty"), ("nan.obj", "non-finite"),
    ("range.off", "range"), ("degenerate.obj", "degenerate"), ("duplicate.obj", "duplicated"),
    ("nonmanifold.obj", "non-manifold"), ("closed.obj", "closed"), ("twoparts.obj", "connected components"),
])
def test_bad_mesh_files(tmp_path, name, message):
    _bad_files(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    proc = run("flatten", name, "--out", "o.obj", "--history", "h.csv", "--plot", "p.png", "--json", cwd=tmp_path)
    _assert_clean_failure(proc, message, tmp_path, before)
    assert proc.stdout == ""


def test_a_diverged_run_exits_nonzero_keeps_an_existing_pattern_and_writes_its_history(tmp_path):
    """Its last finite layout is no pattern: --out and --distortion are not written (an existing file kept),
    --history is, with the finite iterations."""
    (tmp_path / "o.flat.obj").write_text("# springflat layout of 'a good pattern'\n")
    proc = run("flatten", "surf1", "--step", "fixed", "--dt", "1000", "--max-iter", "1000",
               "--out", tmp_path / "o.flat.obj", "--distortion", tmp_path / "d.csv", "--history", tmp_path / "h.csv",
               "--json")
    assert proc.returncode == 3
    assert json.loads(proc.stdout)["status"] == "diverged"
    assert (tmp_path / "o.flat.obj").read_text() == "# springflat layout of 'a good pattern'\n" and not (tmp_path / "d.csv").exists()
    n = json.loads(proc.stdout)["iterations"]  # the iterations whose layouts were finite
    assert len((tmp_path / "h.csv").read_text().splitlines()) == n + 2  # header, P0, n iterations
    assert (f"springflat: iteration {n + 1} ran away: a value stopped being finite, or the layout grew 10000 times "
            "wider than the mesh's edges laid end to end (" in proc.stderr
            and "); the results are of the start, the last finite layout" in proc.stderr and n == 0
            and f"; no pattern written (--out, --distortion), '{tmp_path / 'o.flat.obj'}' kept as it was" in proc.stderr)


def test_a_diverged_runs_note_names_the_last_finite_iteration(tmp_path):
    """'diverged after 5 iterations' and 'iteration 6 ran away': the note says the results are iteration 5's."""
    proc = run("flatten", "surf1", "--step", "fixed", "--dt", "3", "--json")
    n = json.loads(proc.stdout)["iterations"]
    assert proc.returncode == 3 and n > 0
    assert f"springflat: iteration {n + 1} ran away: " in proc.stderr
    assert f"); the results are of iteration {n}, the last finite layout\n" in proc.stderr


def test_a_diverged_runs_plot_is_written_without_warnings(tmp_path):
    proc = run("flatten", "surf1", "--dynamics", "paper", "--step", "fixed", "--dt", "50", "--max-iter", "60",
               "--plot", tmp_path / "p.png")  # errors past 1e300 on the plot's log axis
    assert proc.returncode == 3 and (tmp_path / "p.png").stat().st_size > 0
    assert all(line.startswith("springflat: ") for line in proc.stderr.splitlines()), proc.stderr


@pytest.mark.slow
def test_paper_report(tmp_path):
    proc = run("paper", "--out", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    report = (tmp_path / "rep" / "report.md").read_text()
    assert "36/70" in report and "70/112" in report
    assert "Table VI" in report and "Table VII" in report
    for name in ("surf1.png", "surf2.png", "surf1-fixed.csv", "surf2-variable.csv"):
        assert (tmp_path / "rep" / name).stat().st_size > 0
    from sim.paper import REPORT_FILES  # (the names checked against a user's files before the runs)

    assert sorted(p.name for p in (tmp_path / "rep").iterdir()) == sorted(REPORT_FILES)
    # each run's last iteration is a row of its table: the shorter run's final errors are shown too; the
    # folds the paper's dynamics ends with are said
    for mesh, faces in (("surf1", 7), ("surf2", 24)):
        folded = []
        for step in ("fixed", "variable"):
            with open(tmp_path / "rep" / f"{mesh}-{step}.csv", newline="") as f:
                rows = list(csv.DictReader(f))
            last = rows[-1]
            folded.append(last["folded"])
            assert any(line.startswith(f"| {last['iteration']} | ") and f"E_C = {float(last['shape_error']):.3f}, E_S = "
                       f"{float(last['area_error']):.3f}" in line for line in report.splitlines()), (mesh, step)
        assert any(line.startswith(f"| {mesh} |") and line.endswith(f" | {folded[0]} / {folded[1]} of {faces} |")
                   for line in report.splitlines()), mesh
        assert f" {rows[0]['folded']} of {mesh}'s {faces}" in report  # the start's folds, said


@pytest.mark.slow
def test_variable_step_beats_fixed_on_surf1():
    # the paper's claim, measured on the same initial layout
    fixed = json.loads(run("flatten", "surf1", "--step", "fixed", "--json").stdout)
    variable = json.loads(run("flatten", "surf1", "--step", "variable", "--json").stdout)
    assert fixed["status"] == variable["status"] == "converged"
    assert variable["iterations"] < fixed["iterations"]


@pytest.mark.slow
def test_a_scanned_patch_with_no_options_flattens_without_folds_and_beats_arap():
    """Defaults for files: momentum, the guard with the coarse space of degree 3, fold barrier, ARAP start, stop
    at the energy minimum."""
    from sim.layouts import initial_layout
    from golden_model.reference import SpringModel, measure

    path = SCANS / "bunny_face.obj"
    done = run("flatten", str(path), "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    mesh = load_mesh(path)
    arap = initial_layout(mesh, "arap")
    arap_error = measure(SpringModel.build(mesh, arap, 0.5, "auto"), arap).shape_error
    assert summary["dynamics"] == "momentum" and summary["barrier"] is True
    assert summary["status"] == "converged"
    assert summary["folded"] == 0
    assert summary["shape_error"] <= arap_error
    assert summary["init"] == "arap" and "stopped: the stop rule held" in summary["used"]
    assert (summary["mode"], summary["step"], summary["guard"], summary["energy_window"]) == \
        ("momentum-guarded", "momentum", True, 10) and "density" not in summary and "damping" not in summary
    assert summary["coarse_degree"] == 3
    assert ("relative energy change <= 0.001 over 10 iterations, or an energy below the floor of an rms edge "
            "strain of 0.001;") in summary["used"]
    human = run("flatten", str(path), "--max-iter", "5")
    assert "used momentum dynamics, step guard, coarse space of degree 3, fold barrier" in human.stderr
    assert "N_max = 5 reached" in human.stderr
    unguarded = run("flatten", str(path), "--max-iter", "5", "--no-guard", "--penalty")
    assert "used momentum dynamics, no step guard, fold barrier (kappa 0.5, mu 4), overlap penalty" in unguarded.stderr


@pytest.mark.parametrize("args, message", [
    (["--barrier-threshold", "0"], "--barrier-threshold (kappa) must be in (0, 1]"),
    (["--barrier-gain", "100"], "--barrier-gain (mu) must be in (0, 16]"),
    (["--dynamics", "momentum", "--update", "sequential"], "use --update jacobi"),
    (["--dynamics", "momentum", "--engine", "fixed", "--formats", "FORMATS"], "same fraction bits"),
])
def test_bad_dynamics_parameters_are_one_line(tmp_path, args, message):
    from golden_model.fixed import FormatSet

    odd = tmp_path / "odd.json"
    FormatSet.preset("default").replace(velocity="s3.20", name="odd").save(odd)
    args = [str(odd) if a == "FORMATS" else a for a in args]
    out = tmp_path / "x.obj"
    done = run("flatten", "surf2", "--out", str(out), *args)
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_a_stalled_fixed_point_run_says_why_and_writes_its_layout(tmp_path):
    """With ``floor`` rounding (one-signed errors bias the forces) the guarded fixed-point run on Surf1
    reaches a point where no quantised step lowers the quantised energy: it ends ``stalled``, exit 0,
    with the last accepted layout written, fold-free, and the stop line saying why."""
    from golden_model.fixed import FormatSet

    floor = tmp_path / "floor.json"
    FormatSet.preset("default").replace(rounding="floor", name="default_floor").save(floor)
    proc = run("flatten", "surf1", "--engine", "fixed", "--formats", floor, "--dynamics", "momentum",
               "--out", "stalled.flat.obj", cwd=tmp_path)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stdout.startswith("surf1: stalled after ") and "folded 0" in proc.stdout, proc.stdout
    assert "stopped: no step lowered the energy any more (the guard's step scale fell below 2^-20)" in proc.stderr
    assert (tmp_path / "stalled.flat.obj").stat().st_size > 0


def test_rtl_check_refuses_the_guard_on_the_datapath_bench(tmp_path):
    """The datapath bench (asked for with --stall) has no step guard: a guarded run is one line naming the
    ways out, before any build."""
    proc = run("rtl-check", "surf1", "--dynamics", "momentum", "--stall", "0.2", cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "the datapath bench (--stall) has no step guard: drop --stall" in lines[0], proc.stderr
    assert "building" not in proc.stderr


def test_the_coarse_space_is_an_option_of_the_guarded_float_and_fixed_runs(tmp_path):
    """``--coarse-degree`` shows in the run line and the JSON summary, a mesh file's default of degree 3 too, and 0
    takes the Jacobi step alone; given with an unguarded run, and a degree out of range, it is refused in one line,
    and an unguarded run without it drops the default (the engine's runs with it: ``tests/sim/test_engine_rtl.py``)."""
    path = SCANS / "bunny_face.obj"
    summaries = {}
    for engine in ("float", "fixed"):
        done = run("flatten", str(path), "--engine", engine, "--coarse-degree", "3", "--max-iter", "20", "--json",
                   cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        summaries[engine] = json.loads(done.stdout)
        assert summaries[engine]["coarse_degree"] == 3 and "coarse space of degree 3" in summaries[engine]["used"]
    assert abs(summaries["float"]["shape_error"] - summaries["fixed"]["shape_error"]) <= 1e-3
    default = json.loads(run("flatten", str(path), "--max-iter", "20", "--json", cwd=tmp_path).stdout)
    assert default["coarse_degree"] == 3 and "coarse space of degree 3" in default["used"]
    assert default["shape_error"] == summaries["float"]["shape_error"]
    plain = json.loads(run("flatten", str(path), "--coarse-degree", "0", "--max-iter", "20", "--json",
                           cwd=tmp_path).stdout)
    assert plain["coarse_degree"] == 0 and "coarse" not in plain["used"]
    for options in (("--no-guard",), ("--dynamics", "paper")):
        unguarded = run("flatten", str(path), *options, "--max-iter", "5", "--json", cwd=tmp_path)
        assert unguarded.returncode in (0, 1), unguarded.stderr
        assert "coarse_degree" not in json.loads(unguarded.stdout) and "coarse" not in unguarded.stderr
    for command, options, message in (
            ("flatten", ("--no-guard",), "the coarse space is a step of the guarded momentum dynamics"),
            ("flatten", ("--coarse-degree", "5"), "--coarse-degree must be an integer in [0, 4], got 5")):
        proc = run(command, str(path), "--coarse-degree", "3", *options, cwd=tmp_path)
        lines = proc.stderr.strip().splitlines()
        assert proc.returncode == 2 and len(lines) == 1 and message in lines[0], proc.stderr


@pytest.mark.slow
def test_momentum_on_the_fixed_engine_matches_the_float_engine():
    common = ("flatten", "surf2", "--dynamics", "momentum", "--init", "tutte", "--max-iter", "60",
              "--tol-energy", "0", "--json")
    fixed = json.loads(run(*common, "--engine", "fixed").stdout)
    floating = json.loads(run(*common).stdout)
    assert fixed["iterations"] == floating["iterations"] == 60
    assert fixed["saturations"] == 0 and fixed["barrier"] is True
    assert abs(fixed["shape_error"] - floating["shape_error"]) <= 1e-3
    assert abs(fixed["area_error"] - floating["area_error"]) <= 1e-3


@pytest.mark.parametrize("holding, hint", [([], None), (["wide"], "the preset wide holds it: --formats wide"),
                                           (["narrow", "wide"], "the presets narrow, wide hold it: --formats narrow or wide")])
def test_a_fixed_point_refusal_names_the_presets_that_hold_the_mesh(monkeypatch, holding, hint):
    import sim.flatten_run as flatten_run
    from golden_model.fixed.measures import FixedPointError

    def refuse(*args, **kw):
        raise FixedPointError("too wide for these formats")

    monkeypatch.setattr(flatten_run, "_holds", lambda *args: False)
    monkeypatch.setattr(flatten_run, "presets_holding", lambda *args: holding)
    with pytest.raises(FixedPointError) as info:
        flatten_run._naming_presets_that_hold(refuse, None)("mesh", "P0", "params")
    assert str(info.value) == "too wide for these formats" + (f"; {hint}" if hint else "")


@pytest.mark.parametrize("engine", ["float", "fixed"])
def test_a_face_wound_against_its_neighbours_is_turned_and_the_pattern_has_no_fold(tmp_path, engine):
    """A scan's file with one face written the other way round: the run turns it (a note says so) and the
    pattern, counted with the faces as written to it, has every triangle on one side."""
    from sim.generate import grid_faces, grid_uv
    from sim.mesh_io import read_obj, save_obj

    uv = grid_uv(6, 6)
    faces = grid_faces(6, 6)
    faces[3] = faces[3][[0, 2, 1]]
    save_obj(tmp_path / "turned.obj", np.column_stack([uv, 0.3 * (uv**2).sum(axis=1)]), faces)
    out = tmp_path / "turned.flat.obj"
    proc = run("flatten", tmp_path / "turned.obj", "--engine", engine, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "springflat: note: turned: 1 face wound against its neighbours: turned to agree" in proc.stderr
    written = read_obj(out, out.read_bytes())
    p, f = written.vertices[:, :2], np.asarray(written.faces)
    a, b, c = p[f[:, 0]], p[f[:, 1]], p[f[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    assert (signed > 0).all() or (signed < 0).all()
    assert "folded 0" in proc.stdout


@pytest.mark.parametrize("argv, message", [
    (["--bogus"], "unrecognized arguments: --bogus (see 'springflat --help')"),
    ([], "the following arguments are required: COMMAND (see 'springflat --help')"),
])
def test_no_command_names_the_unknown_option_or_asks_for_one(capsys, argv, message):
    from sim.cli import main

    with pytest.raises(SystemExit) as ended:
        main(argv)
    assert ended.value.code == 2 and capsys.readouterr().err == f"springflat: error: {message}\n"


@pytest.mark.parametrize("command, flag, first, second", [
    (["flatten", "surf1"], "--history", "a.csv", "b.csv"),
    (["flatten", "surf1"], "--plot", "a.png", "b.png"),
    (["flatten", "surf1"], "--distortion", "a.csv", "b.csv"),
    (["flatten", "surf1", "surf2", "--out", ".dxf"], "--out-dir", "a", "b"),
    (["paper"], "--out", "a", "b"),
    (["study"], "--out", "a", "b"),
    (["verilog"], "--out", "a", "b"),
    (["synth"], "--out", "a", "b"),
    (["rtl-check"], "--waves", "a.vcd", "b.vcd"),
])
def test_an_option_that_names_one_output_given_twice_is_refused(tmp_path, monkeypatch, capsys, command, flag, first,
                                                                 second):
    """Kept last, as argparse keeps a repeated option, the first file asked for would silently not be written;
    `--out` of `flatten`, which takes several patterns, is the one output option that repeats."""
    from sim.cli import main

    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as ended:
        main([*command, flag, first, flag, second])
    assert ended.value.code == 2
    assert capsys.readouterr().err.startswith(f"springflat: error: {flag} names one output and was given twice "
                                              f"('{first}' and '{second}'): give it once")
    assert list(tmp_path.iterdir()) == []


def test_a_built_in_name_means_the_built_in_even_beside_a_file_of_that_name(tmp_path, monkeypatch, capsys):
    """A file named ``surf1`` (no mesh format's ending, so it could not be read) made ``flatten surf1`` fail
    with "unknown format ''" in its directory; the built-in runs, with a note, and the file is left alone."""
    from sim.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "surf1").write_text("not a mesh\n")
    assert main(["flatten", "surf1", "--max-iter", "3", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["mesh"] == "surf1"
    assert "note: 'surf1' is the built-in mesh; the file of that name here is not read" in err
    assert (tmp_path / "surf1").read_text() == "not a mesh\n"
    assert main(["flatten", "surf1", "surf2", "--max-iter", "3", "--out-dir", "d", "--out", ".flat.obj"]) == 0
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["surf1.flat.obj", "surf2.flat.obj"]  # a batch too


@pytest.mark.parametrize("terminal", [False, True])
def test_the_notes_on_a_given_start_are_printed_with_progress_lines_or_without(tmp_path, monkeypatch, capsys,
                                                                            terminal):
    """With stderr a terminal the start's long steps are progress lines; a note on reading the start (a
    mirror image mirrored back) is printed all the same, once."""
    import sys

    from sim.mesh_io import save_obj
    from sim.cli import main

    mesh = dome_grid(6)
    monkeypatch.chdir(tmp_path)
    save_obj("dome.obj", mesh.vertices * 100, mesh.faces)
    np.savetxt("uv.txt", mesh.vertices[:, :2] * [100, -100], fmt="%.17g")  # y down: clockwise
    if terminal:
        monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert main(["flatten", "dome.obj", "--init", "uv.txt", "--max-iter", "3"]) == 0
    err = capsys.readouterr().err
    assert err.count("the layout 'uv.txt' is a mirror image of the mesh") == 1, err
    assert ("reading the layout 'uv.txt' ..." in err) == terminal


@pytest.mark.parametrize("mode", [["--dynamics", "paper"], ["--dynamics", "paper", "--step", "fixed"],
                                  ["--dynamics", "momentum"], ["--dynamics", "momentum", "--no-guard"],
                                  ["--dynamics", "momentum", "--no-guard", "--penalty"],
                                  ["--dynamics", "paper", "--penalty", "--damping", "0.2"],
                                  ["--dynamics", "paper", "--penalty", "--penalty-kappa", "1e308"],
                                  ["--dynamics", "paper", "--spring", "1e6"]],
                         ids=["paper", "paper-fixed", "momentum", "momentum-unguarded", "momentum-unguarded-penalty",
                              "paper-penalty-damped", "paper-penalty-raised-kappa", "paper-raised-spring"])
def test_the_divergence_hint_names_only_options_its_mode_takes(mode):
    """Each option the hint tells the user to give is accepted beside the run's own options (one it says to
    drop need not be)."""
    import re

    from golden_model.params import FlattenParams
    from sim.cli import build_parser
    from sim.flatten_run import divergence_hint
    from sim.run_options import params_from_args

    parser = build_parser()
    defaults = FlattenParams(density="auto", dynamics="momentum", tol_area=1.0, tol_shape=1.0, tol_energy=1e-3)
    hint = divergence_hint(params_from_args(parser.parse_args(["flatten", "m.obj", *mode]), defaults))
    values = {"--spring": ["2"], "--damping": ["0.05"], "--dt": ["0.01"], "--step": ["fixed"],
              "--dynamics": ["momentum"], "--penalty-gain": ["0.1"], "--penalty-kappa": ["0.5"]}
    # what it says to drop or leave out ("drop --no-guard, --penalty ...", "without --penalty ...", "(it takes none
    # of --step ...)") need not be accepted: the flags left are the ones it tells the user to give
    kept = re.sub(r"\([^)]*\)|(drop|without) --[a-z-]+(, --[a-z-]+)*((,)? (and|or) --[a-z-]+)?", "", hint)
    named = re.findall(r"--[a-z-]+", kept)
    assert named, hint
    assert ("--penalty-gain" in hint) == ("--penalty" in mode)  # the penalty is what ran away, if given
    if "--damping" in mode:
        assert "a larger --damping than 0.2" in hint
    # the threshold where the user raised it (a kappa of 1e308 ran away, and the hint named only the gain)
    assert ("a smaller --penalty-gain than 1 or --penalty-kappa than 1e+308" in hint) == ("--penalty-kappa" in mode)
    for flag in named:
        given = [*mode, flag, *values[flag]]
        if flag == "--dt" and "fixed" not in mode:
            given += ["--step", "fixed"]  # the hint says "--step fixed with a small --dt"
        if flag == "--dynamics":
            given = [flag, *values[flag]]
        params_from_args(parser.parse_args(["flatten", "m.obj", *given]), defaults)  # refused: ParameterError


@pytest.mark.parametrize("argv, unknown", [
    (["rtl-check", "surf1", "--engine", "fixed"], "--engine fixed"),  # flatten's option, not --engine-top
    (["flatten", "surf1", "--max", "3"], "--max 3"),
])
def test_an_abbreviated_option_is_not_taken_for_a_longer_one(argv, unknown, capsys):
    from sim.cli import main

    with pytest.raises(SystemExit) as stopped:
        main(argv)
    assert stopped.value.code == 2
    assert f"springflat: error: unrecognized arguments: {unknown} (see 'springflat {argv[0]} --help')" in \
        capsys.readouterr().err


def test_a_mesh_file_named_with_a_leading_dash_is_named_with_the_way_to_give_it(capsys):
    """``flatten -dash.obj``: argparse takes the name for an option; the error said the meshes of a batch come
    before the options, for a single mesh."""
    from sim.cli import main

    with pytest.raises(SystemExit) as stopped:
        main(["flatten", "-dash.obj"])
    assert stopped.value.code == 2
    assert capsys.readouterr().err == ("springflat: error: unrecognized arguments: -dash.obj: a file named with a "
                                       "leading '-' is read as an option: write ./-dash.obj (see 'springflat flatten "
                                       "--help')\n")


@pytest.mark.parametrize("argv, hint", [
    (["study", "--bits", "-4:8"], "write --bits=-4:8"),
    (["flatten", "surf1", "--tol-energy", "-1e-3"], "write --tol-energy=-1e-3"),
    (["flatten", "surf1", "--tol-energy", "-inf"], "write --tol-energy=-inf"),
    (["flatten", "surf1", "--tol-energy"], None),  # no value at all: nothing to rewrite
    (["flatten", "surf1", "--out", "-print.pdf"], "write --out=-print.pdf"),  # a file named with a dash
    (["flatten", "surf1", "--out", "--history", "h.csv"], None),  # the value left out before the next option
    (["flatten", "surf1", "--out", "--history=h.csv"], None),
    (["flatten", "surf1", "--history", "--plto", "p.png"], None),  # an option mistyped, the value left out
    (["flatten", "surf1", "--out", "--version"], None),
    (["flatten", "surf1", "--out", "-h"], None),
])
def test_a_value_that_starts_with_a_dash_is_named_with_the_way_to_give_it(argv, hint, capsys):
    """argparse takes ``-4:8`` (not a plain negative number) for an option and says only "expected one
    argument"; the error says how to pass the value."""
    from sim.cli import main

    with pytest.raises(SystemExit) as stopped:
        main(argv)
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    option = next(token for token in argv if token.startswith("--"))
    assert f"springflat: error: argument {option}: expected one argument" in err and err.count("\n") == 1
    if hint:
        assert f"; a value that starts with '-' is read as an option: {hint} (see" in err
    else:
        assert "starts with '-'" not in err


@pytest.mark.parametrize("args", [["--out", "x\ny/z.svg"], ["--out", "z.svg\n"], ["--bogus\tflag"]],
                         ids=["a newline in a missing directory", "a name ending in a newline", "a tab"])
def test_an_error_about_a_name_with_control_characters_is_one_line(tmp_path, args):
    """The name is quoted with its control characters escaped, as in the files' headers: a raw newline made the
    error two lines (and a terminal takes an escape sequence as a command)."""
    proc = run("flatten", "surf1", *args, cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1, proc.stderr
    assert proc.stderr.startswith("springflat: error: ") and "\t" not in proc.stderr
    assert os.listdir(tmp_path) == []


def test_an_error_keeps_a_no_break_space_of_a_name_so_that_it_can_be_copied(tmp_path):
    """Only control characters and line separators are escaped; a no-break space (macOS puts one in its
    screenshots' names) stays itself."""
    proc = run("flatten", "surf1", "--out", "Screen\u00a0Shot/z.svg", cwd=tmp_path)
    assert proc.returncode == 2
    assert "'Screen\u00a0Shot/z.svg'" in proc.stderr and "\\xa0" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("argv, hint", [
    (["flatten", "surf1", "--max-iter", "3", "surf2"], True),  # a mesh after an option
    (["flatten", "surf1", "--max-iter", "3", "ear.OBJ"], True),
    (["flatten", "surf1", "--json", "yes"], False),  # no mesh: no word on meshes
])
def test_a_mesh_given_after_an_option_is_told_where_it_goes(argv, hint, capsys):
    from sim.cli import main

    with pytest.raises(SystemExit) as stopped:
        main(argv)
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and err.startswith(f"springflat: error: unrecognized arguments: {argv[-1]}")
    assert ("the meshes of a batch come together, before the options (flatten MESH MESH ... --option ...)"
            in err) == hint, err


@pytest.mark.parametrize("options", [["--dynamics", "paper"], ["--no-guard"]], ids=["paper", "momentum-unguarded"])
def test_an_unguarded_run_from_a_folded_arap_start_says_so(options, tmp_path):
    """auto falls back to SLIM for a guarded run only; an unguarded one starts from ARAP's folds, with a note."""
    from sim.generate import hard_patches
    from sim.mesh_io import save_obj

    mesh = hard_patches()["slivers"]  # ARAP folds 8 of its triangles
    save_obj(tmp_path / "slivers.obj", mesh.vertices, mesh.faces)
    proc = run("flatten", str(tmp_path / "slivers.obj"), *options, "--max-iter", "1", "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert ("springflat: note: the arap layout folds 8 triangles: without the step guard the run starts from it as "
            "it is") in proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["init"] == "arap" and summary["initial_folded"] == 8
    guarded = run("flatten", str(tmp_path / "slivers.obj"), "--max-iter", "1", "--json", cwd=tmp_path)
    assert json.loads(guarded.stdout)["init"] == "slim" and "without the step guard" not in guarded.stderr
    assert summary["folded"] > 0 and "boundary_crossings" not in summary  # counted on fold-free patterns only


def test_an_unguarded_run_where_arap_fails_names_the_start_to_give(tmp_path):
    from sim.generate import grid_faces, grid_uv
    from sim.mesh_io import save_obj

    uv = grid_uv(6, 6)
    vertices = np.column_stack([uv, 0.1 * (uv**2).sum(axis=1)])
    vertices[14] = vertices[13] + [1e-9, 0, 0]  # libigl's ARAP returns non-finite coordinates here
    save_obj(tmp_path / "sliver.obj", vertices, grid_faces(6, 6))
    proc = run("flatten", str(tmp_path / "sliver.obj"), "--dynamics", "paper", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.endswith("without the step guard --init auto takes no other start: "
                                                         "give --init slim (SLIM on Tutte's layout, where a guarded "
                                                         "run, the default for mesh files, starts)\n"), proc.stderr
    assert run("flatten", str(tmp_path / "sliver.obj"), "--dynamics", "paper", "--init", "slim", "--max-iter", "3",
               cwd=tmp_path).returncode == 0


@pytest.mark.parametrize("engine, capacity, message", [
    ("fixed", None, "a node has 40 neighbours; format set 'default' accumulates at most 32 (max_degree); the preset "
                    "wide holds it: --formats wide"),
    ("rtl", "8,64,32", "the mesh has 41 vertices; the engine holds at most 8 (capacity vertices=8, entries=64, "
                       "triangles=32)"),
    ("rtl", "4,8,2", "SPRINGFLAT_ENGINE_CAPACITY=4,8,2: a disk mesh of 4 vertices has at least 10 neighbour entries "
                     "and 2 triangles; these depths hold at most 3 vertices (give more entries or triangles, or fewer "
                     "vertices)"),  # depths no mesh of that size fills, as --capacity refuses them
    ("rtl", "abc", "SPRINGFLAT_ENGINE_CAPACITY must be V,E,T (three integers >= 2), got 'abc'"),
])
def test_what_the_mesh_alone_cannot_run_is_refused_before_the_start_is_computed(tmp_path, monkeypatch, capsys, engine,
                                                                                 capacity, message):
    """A cone's tip of 40 spokes (a degree the default formats cannot sum), or a mesh over the engine's capacity:
    no layout changes that, so the refusal comes before the start (ARAP on a big scan takes seconds)."""
    import sim.flatten_run as flatten_run
    from sim.mesh_io import save_obj
    from sim.cli import main

    def no_start(*args, **kw):
        raise AssertionError("the start was computed before the refusal")

    angle = 2 * np.pi * np.arange(40) / 40
    save_obj(tmp_path / "wheel.obj", np.vstack([[0.0, 0.0, 0.5], np.column_stack([np.cos(angle), np.sin(angle),
                                                                                   np.zeros(40)])]),
             np.array([[0, 1 + i, 1 + (i + 1) % 40] for i in range(40)]))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(flatten_run, "start_positions", no_start)
    if capacity:
        monkeypatch.setenv("SPRINGFLAT_ENGINE_CAPACITY", capacity)
    formats = ["--formats", "wide"] if capacity else []  # wide holds the mesh: the capacity is what refuses it
    assert main(["flatten", "wheel.obj", "--engine", engine, *formats, "--out", "o.dxf"]) == 2
    assert capsys.readouterr().err == f"springflat: error: {message}\n"
    assert not (tmp_path / "o.dxf").exists()


@pytest.mark.parametrize("option, link, target", [("--out", "pattern.dxf", "scan.ply"), ("--out", "p.pdf", "scan.obj"),
                                                  ("--out", "q.flat.obj", "scan.obj"), ("--history", "h.csv", "m.obj"),
                                                  ("--plot", "p.png", "new.stl")])
def test_an_output_that_links_to_a_file_of_another_kind_is_refused_and_the_file_kept(tmp_path, monkeypatch, capsys,
                                                                                      option, link, target):
    """A symbolic link named like a pattern but pointing at a mesh (existing, or not yet: the link would create it)
    is refused: the link's name passed the suffix check, and the mesh behind it would have become a PDF. A
    ``.pdf`` link to an ``.obj`` passes a suffix check (.obj is a pattern's ending too): the endings must match."""
    from sim.cli import main

    monkeypatch.chdir(tmp_path)
    if target != "new.stl":
        Path(target).write_text("a mesh\n")
    os.symlink(target, link)
    extra = [] if option == "--out" else ["--out", "o.obj"]
    assert main(["flatten", "surf1", "--max-iter", "3", *extra, option, link]) == 2
    ending = ".flat.obj" if link.endswith(".flat.obj") else Path(link).suffix
    kind = Path(target).suffix  # a mesh's ending, or .obj: the uv-mapped pattern's, not the layout's .flat.obj
    assert capsys.readouterr().err == (f"springflat: error: {option} '{link}' is a symbolic link to '{tmp_path / target}'"
                                       f", a file of another kind ({kind}, not {ending}): springflat does not write "
                                       "over it\n")
    assert (Path(target).read_text() == "a mesh\n") if target != "new.stl" else not Path(target).exists()
    assert not Path("o.obj").exists()


def test_an_output_linking_to_a_file_of_its_kind_is_written_through(tmp_path, monkeypatch):
    from sim.cli import main

    monkeypatch.chdir(tmp_path)
    Path("old.pdf").write_text("an old pattern\n")
    os.symlink("old.pdf", "p.pdf")
    assert main(["flatten", "surf1", "--max-iter", "3", "--out", "p.pdf"]) == 0
    assert Path("p.pdf").is_symlink() and Path("old.pdf").read_bytes().startswith(b"%PDF")


def _ended(status="converged", folded=0, area_before=0.3, area_after=0.1):
    from types import SimpleNamespace

    return SimpleNamespace(status=status, iterations=100, extra={},
                           initial=SimpleNamespace(area_error=area_before, folded=0),
                           final=SimpleNamespace(area_error=area_after, folded=folded))


@pytest.mark.parametrize("mode, api, remedy", [
    ([], False, "the step guard adds no fold, but keeps those of its start"),
    (["--no-guard"], False, "the step guard keeps every triangle from folding: drop --no-guard; docs/guard.md"),
    (["--no-guard"], True, "the step guard keeps every triangle from folding: guard=True; docs/guard.md"),
    (["--dynamics", "paper"], False, "the momentum dynamics with its step guard does: --dynamics momentum (it takes "
                                     "none of --step, --dt, --damping, --density); docs/guard.md"),
    (["--dynamics", "paper"], True, "the momentum dynamics with its step guard does: dynamics='momentum' (it takes "
                                    "none of step, dt, damping, density); docs/guard.md"),
    # the guard refuses the penalty and its options, and the momentum dynamics the paper dynamics' own
    (["--dynamics", "paper", "--penalty"], False, "--dynamics momentum without --penalty, --penalty-gain or "
                                                  "--penalty-kappa (it takes none of --step, --dt,"),
    (["--dynamics", "paper", "--penalty"], True, "dynamics='momentum' without penalty, penalty_gain or penalty_kappa "
                                                 "(it takes none of step, dt,"),
    (["--no-guard", "--penalty"], False, "drop --no-guard, --penalty, --penalty-gain and --penalty-kappa;"),
    (["--no-guard", "--penalty"], True, "guard=True, penalty=False and no penalty_gain or penalty_kappa;"),
])
def test_a_folded_pattern_is_said_with_what_keeps_triangles_from_folding(mode, api, remedy):
    from golden_model.params import FlattenParams
    from sim.cli import build_parser
    from sim.flatten_run import fold_note
    from sim.run_options import params_from_args

    defaults = FlattenParams(density="auto", dynamics="momentum", tol_area=1.0, tol_shape=1.0, tol_energy=1e-3)
    params = params_from_args(build_parser().parse_args(["flatten", "m.obj", *mode]), defaults)
    assert fold_note(params, _ended(folded=0), api) is None
    assert fold_note(params, _ended(status="diverged", folded=9), api) is None  # a diverged run says so itself
    one, many = fold_note(params, _ended(folded=1), api), fold_note(params, _ended(folded=246), api)
    assert one.startswith("the pattern has 1 folded triangle, flipped") and remedy in one
    assert many.startswith("the pattern has 246 folded triangles, flipped") and remedy in many


def test_a_layout_grown_away_from_the_mesh_is_said_though_it_did_not_run_away(capsys, tmp_path, monkeypatch):
    """The paper's penalty on Surf1 grows the layout to 1e5–1e7 times the mesh's area in 100 iterations (3.05e5
    and 1.91e7 measured with two releases of the numerics libraries: a runaway's figure follows their last
    bits), under the runaway rule's 1e4 times wider: exit 0 and a pattern, so the note must say that it is
    none."""
    from sim.cli import main
    from sim.flatten_run import growth_note

    assert growth_note(None, _ended(area_before=0.3, area_after=0.9)) is None  # worse, but not grown away
    assert growth_note(None, _ended(area_before=1.5, area_after=1.2)) is None  # a start beyond 1 that improved
    assert growth_note(None, _ended(status="diverged", area_after=5.0)) is None
    monkeypatch.chdir(tmp_path)
    assert main(["flatten", "surf1", "--penalty", "--out", "pen.dxf"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "grew away" in line]
    assert len(notes) == 1, notes
    grown = re.fullmatch(r"springflat: note: the layout grew away from the mesh: E_S 0\.2615 -> (\S+), its area off "
                         r"by \1 times the mesh's: (.*)", notes[0])
    assert grown and 1e5 <= float(grown[1]) <= 1e8, notes
    assert grown[2] == ("no pattern to cut, though it stayed under the runaway rule's 10000 "
                        "times; the overlap penalty pushes nodes apart unchecked: try a smaller --penalty-gain than 1, or "
                        "drop --penalty; the paper dynamics has no guard: try --damping 0.05, --step fixed with a small "
                        "--dt, or --dynamics momentum without --penalty, --penalty-gain or --penalty-kappa (it takes none "
                        "of --step, --dt, --damping, --density)")


def _gently_curved_grid(n: int = 6):
    """An n x n grid on the unit square, bent by 0.3·(x-½)² + 0.2·(y-½)²: nearly developable, so from its PCA
    start the paper's variable step is small (E_S 0.02, E_C 0.01)."""
    x, y = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n)))
    vertices = np.column_stack([x, y, 0.3 * (x - 0.5) ** 2 + 0.2 * (y - 0.5) ** 2])
    a = np.array([j * n + i for j in range(n - 1) for i in range(n - 1)])
    return vertices, np.vstack([np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])])


def test_a_fixed_point_run_whose_steps_round_to_no_move_says_its_pattern_is_its_start(tmp_path, monkeypatch, capsys):
    """From rest the paper dynamics' first moves are ½Δt²·F/m, below the positions' last bit on this grid: the
    energy does not change to the bit and the stop rule holds at iteration 1 ("converged") while the float run
    goes on. The note says so, and its remedies run when followed literally."""
    import warnings

    import springflat
    from sim.mesh_io import save_obj
    from sim.cli import main

    vertices, faces = _gently_curved_grid()
    monkeypatch.chdir(tmp_path)
    save_obj(tmp_path / "grid.obj", vertices, faces)
    argv = ["flatten", "grid.obj", "--dynamics", "paper", "--init", "pca", "--max-iter", "50"]
    assert main([*argv, "--engine", "fixed"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("grid: converged after 1 iteration: E_S 0.0201 -> 0.0201")
    notes = [line for line in err.splitlines() if "without changing" in line]
    assert notes == ["springflat: note: the run stopped without changing the layout's energy: its steps round to no "
                     "move in the 22 fraction bits of the positions (format set 'default'), so the stop rule held at "
                     "once, and the pattern is its start; the float engine, whose steps are not rounded, may move it "
                     "(--engine float), if slowly where E_S and E_C are small; the momentum dynamics does not start "
                     "from rest: --dynamics momentum (it takes none of --step, --dt, --damping, --density)"]
    for remedy in (["--engine", "float"], ["--engine", "fixed", "--dynamics", "momentum"]):  # followed literally
        assert main(["flatten", "grid.obj", "--init", "pca", "--max-iter", "50", *remedy]) == 0
        out, err = capsys.readouterr()
        assert "converged after 1 iteration:" not in out and "without changing" not in err, remedy
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        springflat.flatten(vertices, faces, engine="fixed", dynamics="paper", init="pca", max_iter=50)
    assert any("without changing the layout's energy" in str(w.message) and "(engine='float')" in str(w.message)
               and "dynamics='momentum'" in str(w.message) for w in caught)
    # a flat patch starts exact (energy 0): there is nothing to move, in float either, and no note
    save_obj(tmp_path / "flat.obj", vertices * [1.0, 1.0, 0.0], faces)
    for dynamics in ("paper", "momentum"):
        assert main(["flatten", "flat.obj", "--dynamics", dynamics, "--init", "pca", "--engine", "fixed"]) == 0
        out, err = capsys.readouterr()
        assert "E_S 0.0000 -> 0.0000" in out and "without changing" not in err, dynamics


@pytest.mark.parametrize("options", [["--step", "fixed", "--dt", "1e-4"], ["--density", "1e300"]])
def test_a_float_run_whose_first_step_is_too_small_to_count_says_its_pattern_is_its_start(tmp_path, monkeypatch,
                                                                                           capsys, options):
    """From rest the paper dynamics' first step is its smallest: a tiny --dt or a huge --density changes the energy
    by less than --tol-energy, and the run 'converges' after 1 iteration with the start's errors. The note says
    so, and each of its remedies, followed literally, moves the layout."""
    import warnings

    import springflat
    from sim.mesh_io import save_obj
    from sim.cli import main

    vertices, faces = _gently_curved_grid()
    vertices = vertices * [1.0, 1.0, 4.0]  # curved enough that a step of the default size moves it
    monkeypatch.chdir(tmp_path)
    save_obj(tmp_path / "grid.obj", vertices, faces)
    argv = ["flatten", "grid.obj", "--dynamics", "paper", "--init", "pca", "--max-iter", "50"]
    assert main([*argv, *options]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("grid: converged after 1 iteration: ")
    notes = [line for line in err.splitlines() if "first step" in line]
    assert len(notes) == 1 and notes[0].startswith("springflat: note: the run stopped after its first step, which ")
    heavy = "--density" in options  # its moves are 0 to the bit: no tolerance helps
    remedy = ("a larger --dt with --step fixed and a smaller --density" if heavy else
              "a larger --dt with --step fixed, or a smaller --tol-energy")
    assert notes[0].endswith(f"the pattern is its start, barely moved; larger steps move it: {remedy}; the momentum "
                             "dynamics does not start from rest: --dynamics momentum (it takes none of --step, --dt, "
                             "--damping, --density)")
    remedies = [[*argv, "--step", "fixed", "--dt", "0.05", *(["--density", "1"] if heavy else [])],
                ["flatten", "grid.obj", "--init", "pca", "--max-iter", "50", "--dynamics", "momentum"]]
    if not heavy:
        remedies.append([*argv, *options, "--tol-energy", "1e-15"])
    for remedy in remedies:
        assert main(remedy) == 0
        out, err = capsys.readouterr()
        assert "after 1 iteration:" not in out and "first step" not in err, remedy
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        springflat.flatten(vertices, faces, dynamics="paper", init="pca", max_iter=50, step="fixed", dt=1e-4)
    assert any("first step" in str(w.message) and "a larger dt with step='fixed'" in str(w.message)
               and "dynamics='momentum'" in str(w.message) for w in caught)


def test_rtl_check_with_its_simulator_missing_says_so_before_anything(tmp_path, monkeypatch, capsys):
    """No 'building the model ...' line (nor the start's work) before the one line that the simulator is missing."""
    import shutil

    import sim.cocotb_support
    from sim.cli import main

    real_which = shutil.which
    monkeypatch.setattr(sim.cocotb_support.shutil, "which",
                        lambda tool, *a, **kw: None if tool in ("iverilog", "vvp") else real_which(tool, *a, **kw))
    monkeypatch.chdir(tmp_path)
    for extra in ([], ["--engine-top"]):
        assert main(["rtl-check", "surf1", "--sim", "icarus", *extra]) == 2
        assert capsys.readouterr().err == ("springflat: error: Icarus Verilog is not installed: install it ('sudo "
                                           "apt-get install iverilog'; 'make test' installs it when it runs as root)\n")


def test_rtl_check_engine_top_refuses_stall_whatever_its_value(tmp_path, monkeypatch, capsys):
    """The engine bench has no stall option (it has --wait-states): any --stall, 0 included, is refused."""
    from sim.cli import main

    monkeypatch.chdir(tmp_path)
    for value in ("0", "0.1"):
        assert main(["rtl-check", "surf1", "--engine-top", "--stall", value]) == 2
        assert capsys.readouterr().err == ("springflat: error: --stall applies to the datapath bench; with "
                                           "--engine-top use --wait-states\n")


def test_a_program_that_ran_a_command_in_process_and_saw_it_interrupted_can_write_after_it(tmp_path, monkeypatch):
    """main() notes a Ctrl-C so that nothing of its command is put in place; a program that called it goes on,
    and its own writes afterwards (the API's) are not that command's."""
    import springflat
    import sim.cli
    from golden_model.builtin import builtin_mesh
    from sim.cli import main

    monkeypatch.setattr(sim.cli, "run_flatten", press_ctrl_c)  # as Ctrl-C during the run
    monkeypatch.chdir(tmp_path)
    assert main(["flatten", "surf1", "--out", "p.dxf"]) == 130
    assert not Path("p.dxf").exists()
    mesh, _ = builtin_mesh("surf1")
    pattern = springflat.flatten(mesh.vertices * 100, mesh.faces, max_iter=3)  # (135 mm: no scale note)
    try:
        springflat.write_pattern("after.dxf", pattern)
    except KeyboardInterrupt:  # (not raised on: it would end the test session)
        pytest.fail("the program's own write after the command was refused as the command's interrupt")
    assert Path("after.dxf").stat().st_size > 0


def test_the_run_line_says_when_the_energy_floor_stopped_a_developable_patch(tmp_path):
    """A rolled grid from ARAP stops on the floor (its energy falls to 0 while its relative change stays large),
    which the run line says, with the option that lowers it; a smaller --tol-energy lowers it (an rms strain
    of min(eps, 1e-3)). It said 'the stop rule held' while the energy still fell 6 % an iteration."""
    from sim.generate import rolled_grid
    from sim.mesh_io import save_obj

    mesh, _ = rolled_grid(8, 8, arc_degrees=90.0)
    save_obj(tmp_path / "rolled.obj", mesh.vertices, mesh.faces)
    iterations = []
    for extra, strain in [((), "0.001"), (("--tol-energy", "1e-6"), "1e-06")]:
        done = run("flatten", str(tmp_path / "rolled.obj"), "--init", "tutte", "--json", *extra)  # (ARAP: exact)
        assert done.returncode == 0, done.stderr
        summary = json.loads(done.stdout)
        assert summary["used"].endswith(f"or an energy below the floor of an rms edge strain of {strain}; stopped: "
                                        "the energy fell below the floor (a smaller --tol-energy lowers it)")
        iterations.append(summary["iterations"])
    assert iterations[1] > iterations[0] + 20  # the lower floor: a longer, more exact run
    # with E_S and E_C tolerances the energy's test may have held long before: the line does not blame it
    done = run("flatten", str(tmp_path / "rolled.obj"), "--init", "tutte", "--json", "--tol-area", "1e-9",
               "--tol-shape", "1e-9")
    summary = json.loads(done.stdout)
    assert summary["iterations"] > iterations[0] and summary["used"].endswith(
        "stopped: E_S and E_C within their tolerances, and the energy below the floor"), summary["used"]


@pytest.mark.parametrize("command, written", [(["flatten", "surf1", "--max-iter", "3", "--out", "p.dxf",
                                                "--out", "p.svg"], "p.dxf, p.svg"),
                                               (["paper", "--quiet", "--out", "report"], "report")])
def test_a_signal_after_the_outputs_are_in_place_says_they_were_written(tmp_path, monkeypatch, capsys, command,
                                                                        written):
    """Ctrl-C while the command still prints, after its outputs replaced the old ones: status 130 said
    'interrupted' as if nothing had been written; the line names what was, complete."""
    import sim.cli

    monkeypatch.setattr(sim.cli, "human_line", press_ctrl_c)  # flatten: the result line after its outputs
    monkeypatch.setattr(sim.cli, "print", lambda *a, **k: press_ctrl_c() if a and str(a[0]).startswith("wrote")
                        else print(*a, **k), raising=False)  # paper: its 'wrote' line
    monkeypatch.chdir(tmp_path)
    assert sim.cli.main(command) == 130
    assert capsys.readouterr().err.splitlines()[-1] == f"springflat: interrupted after writing {written}, which are " \
                                                       "complete"
    assert all(Path(name).exists() for name in written.split(", "))


def test_an_obj_output_never_replaces_a_mesh_that_springflat_did_not_write(tmp_path, monkeypatch):
    """`--out scan.obj` (or a link to a scan) replaced an unrelated mesh: only the run's inputs were protected.
    An OBJ springflat wrote (its first line says so) is replaced as before; so in a batch and in the API."""
    import warnings

    import springflat

    monkeypatch.chdir(tmp_path)
    scan = (SCANS / "bunny_ear.obj").read_bytes()
    Path("scan.obj").write_bytes(scan)
    os.symlink("scan.obj", "link.obj")  # (a link to a file of another ending is refused as such)
    for out in ("scan.obj", "link.obj"):
        done = run("flatten", "surf1", "--max-iter", "2", "--out", out, cwd=tmp_path)
        assert done.returncode == 2 and done.stderr.startswith(f"springflat: error: --out '{out}'")
        assert "is an OBJ file springflat did not write (a mesh?)" in done.stderr
    Path("o").mkdir()
    Path("o/bunny_face.obj").write_bytes(scan)
    done = run("flatten", str(SCANS / "bunny_ear.obj"), str(SCANS / "bunny_face.obj"), "--max-iter", "2",
               "--out-dir", "o", "--out", ".obj", cwd=tmp_path)
    assert done.returncode == 2 and "'o/bunny_face.obj' is an OBJ file springflat did not write" in done.stderr
    assert Path("scan.obj").read_bytes() == scan == Path("o/bunny_face.obj").read_bytes()
    assert os.listdir("o") == ["bunny_face.obj"]
    for _ in range(2):  # its own: written, then replaced
        assert run("flatten", "surf1", "--max-iter", "2", "--out", "own.obj", cwd=tmp_path).returncode == 0
    Path("empty.obj").write_bytes(b"")  # no mesh
    assert run("flatten", "surf1", "--max-iter", "2", "--out", "empty.obj", cwd=tmp_path).returncode == 0
    mesh, _ = builtin_mesh("surf1")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pattern = springflat.flatten(mesh.vertices, mesh.faces, max_iter=2)
    with pytest.raises(springflat.OutputError, match="is an OBJ file springflat did not write"):
        springflat.write_pattern("scan.obj", pattern)
    assert Path("scan.obj").read_bytes() == scan


@pytest.mark.parametrize("option, message", [
    (["--max-iter", "5000000000"], "run constant max_iter = 5000000000 does not fit the engine's 32-bit register "
                                   "(max 4294967295)"),
    (["--tol-energy", "300"], "--tol-energy 300 does not fit the engine's TOL_ENERGY register (u8.40: below 256); "
                              "use a smaller value"),
])
def test_a_run_constant_the_engine_cannot_hold_is_refused_before_the_build_line(tmp_path, monkeypatch, capsys,
                                                                                  option, message):
    """--engine rtl with a --max-iter or --tol-energy beyond the engine's register: one line, before the start is
    computed (no layout changes them) and with no 'building springflat_engine' before it (nothing is built)."""
    import sim.flatten_run as flatten_run
    from sim.cli import main

    def no_start(*args, **kw):
        raise AssertionError("the start was computed before the refusal")

    monkeypatch.setattr(flatten_run, "start_positions", no_start)
    monkeypatch.chdir(tmp_path)
    assert main(["flatten", "surf1", "--engine", "rtl", *option]) == 2
    assert capsys.readouterr().err == f"springflat: error: {message}\n"


def test_a_guarded_runs_history_marks_its_rolled_back_steps_and_has_no_time_step(tmp_path):
    """The momentum dynamics has no dt (its step is the weights, scaled by the guard): the column is empty, not
    1.0; a step the guard rolled back is 0 under accepted, as many as --json's rejected_steps, and its row
    repeats the kept layout's energy."""
    import csv
    import json

    from sim.generate import saddle_grid
    from sim.mesh_io import save_obj

    saddle = saddle_grid(15)  # with the Jacobi step alone its run rolls steps back
    save_obj(tmp_path / "saddle.obj", saddle.vertices, saddle.faces)
    proc = run("flatten", "saddle.obj", "--coarse-degree", "0", "--history", "h.csv", "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    with open(tmp_path / "h.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {row["dt"] for row in rows} == {""} and rows[0]["accepted"] == ""
    rolled_back = [k for k, row in enumerate(rows) if row["accepted"] == "0"]
    assert len(rolled_back) == summary["rejected_steps"] > 0
    assert all(rows[k]["energy"] == rows[k - 1]["energy"] for k in rolled_back)


def test_a_name_the_standard_outputs_encoding_lacks_is_escaped_not_a_traceback(tmp_path):
    """A mesh named in Chinese on a standard output that is ASCII (a Windows code page, a C locale, a pipe): the
    result line raised UnicodeEncodeError after the pattern was written; a batch stopped half way."""
    import os
    import shutil
    import subprocess

    from support import SPRINGFLAT

    shutil.copy(SCANS / "bunny_ear.obj", tmp_path / "网格€.obj")
    proc = subprocess.run([SPRINGFLAT, "flatten", "网格€.obj", "--max-iter", "3", "--out", "p.svg"], cwd=tmp_path,
                          capture_output=True, env={**os.environ, "PYTHONIOENCODING": "ascii"})
    assert proc.returncode == 0, proc.stderr.decode("ascii", "replace")
    assert proc.stdout.decode("ascii").startswith("\\u7f51\\u683c\\u20ac: max-iterations after 3 iterations")
    assert (tmp_path / "p.svg").exists()


@pytest.mark.parametrize("given, said", [(["--capacity", "64", "200", "100"], "--capacity applies"),
                                         (["--wait-states", "2"], "--wait-states applies"),
                                         (["--capacity", "64", "200", "100", "--wait-states", "2"],
                                          "--capacity and --wait-states apply"),
                                         (["--lanes", "2", "--no-guard", "--energy-window", "1"], "--lanes applies")])
def test_rtl_check_names_the_engine_top_option_given_without_it(given, said):
    """(It named both options whatever was given.)"""
    proc = run("rtl-check", "surf1", *given)
    assert proc.returncode == 2 and proc.stderr == f"springflat: error: {said} to --engine-top: add it\n"


def test_rtl_check_lanes_need_an_unguarded_mode():
    """Lanes are built without the step guard: the guarded momentum run is refused in one line, before a build."""
    proc = run("rtl-check", "surf1", "--dynamics", "momentum", "--lanes", "2")
    assert proc.returncode == 2 and proc.stderr == ("springflat: error: --lanes 2 builds the engine without the step "
                                                    "guard: add --no-guard --energy-window 1\n")


def test_rtl_check_refuses_the_penalty_as_such_first(tmp_path):
    """rtl-check said "add --penalty" to --penalty-kappa, then "drop --penalty", and on a mesh file "use --no-guard"
    first: the fixed-point pipeline has no penalty, and that is the one line."""
    for args, dropped in ((["--penalty-kappa", "2"], "--penalty-kappa"), (["--penalty"], "--penalty")):
        proc = run("rtl-check", "surf1", *args, cwd=tmp_path)
        assert proc.returncode == 2 and proc.stderr == ("springflat: error: the penalty is not part of the fixed-point "
                                                        f"pipeline; drop {dropped}\n")
    assert not list(tmp_path.iterdir())


def test_a_layout_file_for_an_stl_says_how_its_rows_are_matched(tmp_path):
    """An STL has no shared vertices: a layout's rows are matched to the corners as the reader merges them, which
    the file does not show; the run says so (a layout from another tool's vertex order came out scrambled)."""
    from sim.generate import dome_grid

    mesh = dome_grid(5)
    with open(tmp_path / "dome.stl", "w") as f:
        f.write("solid d\n" + "".join("facet normal 0 0 1\nouter loop\n" + "".join(
            f"vertex {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in mesh.vertices[face]) + "endloop\nendfacet\n"
            for face in mesh.faces) + "endsolid d\n")
    for name, v in (("dome.stl", "stl"), ("dome.obj", "obj")):
        if v == "obj":
            (tmp_path / name).write_text("".join(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in mesh.vertices)
                                         + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in mesh.faces))
        np.savetxt(tmp_path / "uv.txt", mesh.vertices[:, :2])
        proc = run("flatten", name, "--init", "uv.txt", "--max-iter", "2", cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        said = "an STL stores no shared vertices: row i of the layout 'uv.txt' is taken for the mesh's vertex i"
        assert (said in proc.stderr) == (v == "stl"), proc.stderr


def test_a_paper_run_that_ran_away_on_a_raised_spring_constant_is_told_to_lower_it():
    """--spring 1e6 with --damping 0.05: the hint said only 'a larger --damping', though the spring constant,
    which scales every force, made the steps too long."""
    proc = run("flatten", "surf1", "--damping", "0.05", "--spring", "1e6")
    assert proc.returncode == 3 and "try a smaller --spring than 1e+06 (it scales every force), a larger " \
        "--damping than 0.05" in proc.stderr, proc.stderr
    proc = run("flatten", "surf1", "--damping", "0.05", "--spring", "0.4", "--step", "fixed", "--dt", "50")
    assert proc.returncode == 3 and "--spring" not in proc.stderr.split("ran away")[1], proc.stderr


@pytest.mark.parametrize("mode, remedy", [(["--no-guard"], "drop --no-guard"),
                                          (["--dynamics", "paper"], "--dynamics momentum")])
def test_an_unguarded_start_with_an_edge_of_length_zero_is_refused_in_one_line(tmp_path, mode, remedy):
    """Two ends of an edge on one point: an unguarded run 'diverged after 0 iterations', with a hint that did not
    name the start (a guarded run untangles it)."""
    from sim.generate import dome_grid
    from sim.mesh_io import save_obj

    mesh = dome_grid(6)
    save_obj(tmp_path / "dome.obj", mesh.vertices, mesh.faces)
    a, b = (int(v) for v in mesh.edges[len(mesh.edges) // 2])
    layout = mesh.vertices[:, :2].copy()
    layout[a] = layout[b]
    np.savetxt(tmp_path / "uv.txt", layout)
    proc = run("flatten", "dome.obj", "--init", "uv.txt", *mode, "--out", "p.svg", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr == (
        f"springflat: error: the start puts vertices {min(a, b)} and {max(a, b)}, an edge's ends, on one point (rows "
        f"{min(a, b) + 1} and {max(a, b) + 1} of the layout): without the step guard the float run cannot start from "
        f"it; move them apart, or let the guard untangle it ({remedy})\n")
    assert not (tmp_path / "p.svg").exists()
    guarded = run("flatten", "dome.obj", "--init", "uv.txt", "--max-iter", "5", cwd=tmp_path)
    assert guarded.returncode == 0 and "untangling it" in guarded.stderr
    fixed = run("flatten", "dome.obj", "--init", "uv.txt", *mode, "--engine", "fixed", "--max-iter", "5",
                "--energy-window", "1", cwd=tmp_path)  # (its lengths saturate: it runs)
    assert fixed.returncode == 0, fixed.stderr


def test_a_start_methods_name_that_a_file_here_also_has_says_which_is_taken(tmp_path):
    """A file named 'tutte' beside the mesh: --init tutte took the method without a word (a built-in mesh's name
    over a file of that name gets a note)."""
    from sim.generate import dome_grid
    from sim.mesh_io import save_obj

    mesh = dome_grid(5)
    save_obj(tmp_path / "dome.obj", mesh.vertices, mesh.faces)
    np.savetxt(tmp_path / "tutte", mesh.vertices[:, :2])
    said = "--init tutte is the start method; the file 'tutte' here is not read (give ./tutte for the file)"
    method = run("flatten", "dome.obj", "--init", "tutte", "--max-iter", "2", "--json", cwd=tmp_path)
    assert method.returncode == 0 and said in method.stderr and json.loads(method.stdout)["init"] == "tutte"
    given = run("flatten", "dome.obj", "--init", "./tutte", "--max-iter", "2", "--json", cwd=tmp_path)
    assert given.returncode == 0 and said not in given.stderr and json.loads(given.stdout)["init"] == "./tutte"


def test_paper_does_not_replace_a_users_report_in_out(tmp_path):
    """A directory with the user's own report.md: the paper's report replaced it. Refused before the runs; an
    earlier paper report there (its title) is replaced."""
    out = tmp_path / "notes"
    out.mkdir()
    (out / "report.md").write_text("# my report\n")
    proc = run("paper", "--quiet", "--out", out)
    assert proc.returncode == 2 and proc.stderr == (
        f"springflat: error: --out '{out}' holds report.md, which this run would replace and no earlier run of this "
        "command wrote there: move it, or give a new directory\n")
    assert (out / "report.md").read_text() == "# my report\n" and [p.name for p in out.iterdir()] == ["report.md"]
