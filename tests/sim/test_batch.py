"""Batches: every mesh gets its line and files, a corrupt one is reported, Dask writes the same bytes."""

import json
import os
import re
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from sim.generate import dome_grid, grid_faces, grid_uv
from sim.mesh_io import save_obj
from sim.cli import main
from support import PRESETS, SCANS, run_springflat as run

ENDINGS = ["--out", ".dxf", "--out", ".pdf", "--out", ".svg", "--out", ".obj", "--distortion", ".csv"]


def write_meshes(folder: Path, good: int, corrupt_at: int) -> list[Path]:
    """``good`` small domes of different sizes and shapes (OBJ and OFF), a corrupt OBJ at ``corrupt_at``."""
    folder.mkdir()
    paths = []
    for k in range(good):
        mesh = dome_grid(5 + k % 4)
        vertices = mesh.vertices * [100.0 + 10 * k, 80.0 + 5 * k, 30.0]  # millimetres
        if k % 2:
            path = folder / f"dome{k:02d}.off"
            with open(path, "w") as out:
                out.write(f"OFF\n{mesh.n_vertices} {mesh.n_faces} 0\n")
                np.savetxt(out, vertices)
                np.savetxt(out, np.column_stack([np.full(mesh.n_faces, 3), mesh.faces]), fmt="%d")
        else:
            path = folder / f"dome{k:02d}.obj"
            save_obj(path, vertices, mesh.faces)
        paths.append(path)
    corrupt = folder / "corrupt.obj"
    corrupt.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    paths.insert(corrupt_at, corrupt)
    return paths


@pytest.mark.slow
def test_a_corrupt_mesh_is_reported_and_the_other_19_finish(tmp_path):
    meshes = write_meshes(tmp_path / "in", 19, 7)
    out = tmp_path / "out"
    proc = run("flatten", *meshes, "--out-dir", out, *ENDINGS, "--jobs", "2")
    assert proc.returncode == 4, proc.stderr  # (2 is a batch refused before any run)
    lines = proc.stdout.splitlines()
    results = [line for line in lines if line.startswith("[")]
    assert len(results) == 20 and sorted(int(r[1:r.index("/")]) for r in results) == list(range(1, 21))
    failed = [r for r in results if "failed" in r]
    assert len(failed) == 1 and "corrupt.obj" in failed[0] and "vertex 7" in failed[0]
    table = lines[lines.index(next(line for line in lines if line.startswith("mesh "))):]
    assert len(table) == 1 + 20 + 1 and table[-1].startswith("20 meshes: ") and "1 failed" in table[-1]
    rows = {row.split()[0]: row.split()[1] for row in table[1:-1]}
    assert rows.pop("corrupt") == "failed"
    assert len(rows) == 19 and set(rows.values()) <= {"converged", "max-iterations"}
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"{m.stem}{e}" for m in meshes if m.stem != "corrupt" for e in (".dxf", ".pdf", ".svg", ".obj", ".csv"))
    # the reason again under the count, since the progress line that gave it may have scrolled away
    assert proc.stderr.splitlines()[-2] == "springflat: error: 1 of 20 meshes failed:"
    assert proc.stderr.splitlines()[-1].startswith(f"  {meshes[7]}: ") and "vertex 7" in proc.stderr.splitlines()[-1]


def test_batch_json_lines(tmp_path):
    meshes = write_meshes(tmp_path / "in", 3, 1)
    proc = run("flatten", *meshes, "surf1", "--out-dir", tmp_path / "out", "--history", ".history.csv", "--json")
    assert proc.returncode == 4
    records = [json.loads(line) for line in proc.stdout.splitlines()]
    by_mesh = {r["mesh"]: r for r in records[:-1]}
    assert set(by_mesh) == {"dome00", "dome01", "dome02", "corrupt", "surf1"}
    assert by_mesh["corrupt"]["status"] == "failed" and "vertex 7" in by_mesh["corrupt"]["error"]
    assert by_mesh["surf1"]["dynamics"] == "paper" and by_mesh["dome00"]["dynamics"] == "momentum"
    assert by_mesh["dome01"]["files"] == [str(tmp_path / "out" / "dome01.history.csv")]
    assert records[-1]["batch"]["meshes"] == 5 and records[-1]["batch"]["failed"] == 1


@pytest.mark.slow
def test_a_dask_local_cluster_writes_the_same_bytes_as_the_process_pool(tmp_path):
    meshes = write_meshes(tmp_path / "in", 5, 2)
    pool = run("flatten", *meshes, "--out-dir", tmp_path / "pool", *ENDINGS, "--jobs", "2")
    dask = run("flatten", *meshes, "--out-dir", tmp_path / "dask", *ENDINGS, "--scheduler", "local", "--jobs", "2")
    assert pool.returncode == dask.returncode == 4, dask.stderr
    assert "on 2 Dask worker processes" in dask.stdout
    names = sorted(p.name for p in (tmp_path / "pool").iterdir())
    assert len(names) == 5 * 5 and names == sorted(p.name for p in (tmp_path / "dask").iterdir())
    for name in names:
        assert (tmp_path / "pool" / name).read_bytes() == (tmp_path / "dask" / name).read_bytes(), name


def test_a_local_cluster_beside_another_on_the_dashboards_port_says_nothing(tmp_path):
    """Its scheduler's HTTP server takes a free port: with 8787 taken (another springflat run's cluster, or
    the user's own) a batch printed three lines of Dask's "Port 8787 is already in use" warning."""
    import socket

    meshes = [m for m in write_meshes(tmp_path / "in", 2, 0) if "corrupt" not in m.name]
    with socket.socket() as taken:
        try:
            taken.bind(("127.0.0.1", 8787))
        except OSError:
            pytest.skip("port 8787 is in use here already")
        taken.listen()
        proc = run("flatten", *meshes, "--out-dir", tmp_path / "out", "--out", ".dxf", "--scheduler", "local",
                   "--jobs", "1")
    assert proc.returncode == 0, proc.stderr
    assert "already in use" not in proc.stderr and "Warning" not in proc.stderr, proc.stderr


@pytest.mark.slow
def test_a_scheduler_address_runs_the_batch_on_that_cluster(tmp_path):
    from distributed import LocalCluster

    meshes = write_meshes(tmp_path / "in", 3, 0)
    with LocalCluster(n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None) as cluster:
        proc = run("flatten", *meshes, "--out-dir", tmp_path / "out", "--out", ".dxf", "--scheduler",
                   cluster.scheduler_address)
    assert proc.returncode == 4 and f"on Dask scheduler {cluster.scheduler_address}" in proc.stdout
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["dome00.dxf", "dome01.dxf", "dome02.dxf"]


@pytest.mark.parametrize("args, message", [
    (["--out-dir", "o", "--out", "sub/.pdf"], "takes a file-name ending such as .pdf"),
    (["--out-dir", "o", "--out", "x.pdf"], "takes a file-name ending that starts with a separator, such as .pdf or "
                                           "_flat.pdf, not 'x.pdf'"),
    (["--out-dir", "o", "--plot", "png"], "--plot takes a file-name ending that starts with a separator, such as .png "
                                          "or _flat.png, not 'png'"),  # the option's own ending, not --out's
    (["--out", ".pdf"], "a batch (several meshes, or --scheduler) writes its outputs to --out-dir DIR"),
    (["--out-dir", "o", "--formats", "narrow"], "--formats applies to the fixed-point engines"),
    (["--out-dir", "o", "--out", ".pdf", "--dxf-edges"], "--dxf-edges draws the mesh's edges into a DXF pattern"),
    (["--out-dir", "o", "--out", ".csv", "--distortion", ".csv"], "given twice"),
    (["--out-dir", "o/sub", "--out", ".png"], "must end in .dxf"),
    (["--out-dir", "o", "--engine", "rtl"], "--engine rtl runs one mesh at a time (the simulator build is shared)"),
    (["--out-dir", "o", "--engine", "board", "--port", "p"], "--engine board runs one mesh at a time (one board answers"),
    (["--init", "layout.txt"], "--init takes a method"),
    (["--jobs", "0"], "--jobs must be >= 1"),
    (["--out-dir", "o", "--out", ".dxf", "--jobs", "2", "--scheduler", "tcp://127.0.0.1:8786"],
     "--jobs sets the local worker processes; the Dask scheduler at 'tcp://127.0.0.1:8786' has its own workers"),
    (["--out-dir", "o", "--max-iter", "3"], "--out-dir holds the batch's files, and none is asked for: add --out "
                                            ".ENDING"),
    (["--out-dir", "o", "--out", ".dxf", "--scheduler", "tcp://127.0.0.1:99999"], "--scheduler "
     "'tcp://127.0.0.1:99999': port 99999 is not in 1-65535 (expected 'local' or PROTOCOL://HOST:PORT"),
    (["--out-dir", "o", "--out", ".dxf", "--scheduler", "tpc://host:8786"], "Dask has no protocol 'tpc'"),
    # Dask's Client takes no address without a port: refused before the batch says where it runs
    (["--out-dir", "o", "--out", ".dxf", "--scheduler", "foo"], "--scheduler 'foo': no port (expected 'local' or "
                                                                 "PROTOCOL://HOST:PORT"),
    (["--out-dir", "o", "--out", ".dxf", "--scheduler", "tcp://foo"], "--scheduler 'tcp://foo': no port"),
])
def test_batch_refusals_are_one_line_before_any_run(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    assert main(["flatten", "in/dome00.obj", "in/dome01.off", *args]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("springflat: error: ") and message in err[0], err
    assert os.listdir(tmp_path) == ["in"]  # an --out-dir the batch made is removed again


@pytest.mark.parametrize("args, message", [
    (["--scheduler", "local", "--out", "x.svg"], "in a batch (--scheduler makes one, of one mesh here), --out takes a "
                                                 "file-name ending that starts with a separator"),
    (["--out-dir", "o", "--out", ".svg", "--init", "layout.txt"], "in a batch (--out-dir makes one, of one mesh "
                                                                  "here), --init takes a method"),
])
def test_a_batch_of_one_mesh_says_what_made_it_a_batch(tmp_path, monkeypatch, capsys, args, message):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 1, 0)
    assert main(["flatten", "in/dome00.obj", *args]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("springflat: error: ") and message in err[0], err
    assert os.listdir(tmp_path) == ["in"]


@pytest.mark.parametrize("out_dir, args, message", [
    ("in", ["--out", ".obj"], "--out 'in/dome00.obj' is the same file as the mesh 'in/dome00.obj'"),
    ("in", ["--history", ".obj"], "--history 'in/dome00.obj' must end in .csv"),
    (".", ["--out", ".flat.obj"], "--out 'dome00.flat.obj' is the same file as the mesh 'in/dome00.obj'"),
    ("linked", ["--out", ".pdf"], "--out 'linked/dome00.pdf' is the same file as the mesh 'in/dome01.off'"),
])
def test_no_output_of_a_batch_replaces_one_of_its_meshes(tmp_path, monkeypatch, capsys, out_dir, args, message):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    os.link("in/dome00.obj", "dome00.flat.obj")  # a mesh that is another's output name, by a hard link
    os.mkdir("linked")
    os.symlink("../in/dome01.off", "linked/dome00.pdf")  # a namesake in --out-dir that links to a mesh
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert main(["flatten", "in/dome00.obj", "in/dome01.off", "dome00.flat.obj", "--max-iter", "3",
                 "--out-dir", out_dir, *args]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"springflat: error: {message}"]
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_a_batch_of_prints_at_a_likely_wrong_scale_gets_the_single_runs_note(tmp_path, monkeypatch, capsys):
    """Meshes in metres printed with the default --units mm: each mesh's note, as a single run prints it."""
    monkeypatch.chdir(tmp_path)
    os.mkdir("in")
    for k in range(2):
        mesh = dome_grid(5)
        save_obj(f"in/part{k}.obj", mesh.vertices * 0.1, mesh.faces)  # 0.1 m
    assert main(["flatten", "in/part0.obj", "in/part1.obj", "--out-dir", "o", "--out", ".pdf", "--out", ".obj",
                 "--max-iter", "3", "--jobs", "1"]) == 0
    err = capsys.readouterr().err
    for k in range(2):
        assert (f"springflat: note: part{k}: the pattern is " in err
                and " mm at 1:1 with --units mm: if the mesh is in metres, centimetres or inches" in err), err
    assert main(["flatten", "in/part0.obj", "in/part1.obj", "--out-dir", "o2", "--out", ".obj", "--max-iter", "3",
                 "--jobs", "1"]) == 0
    assert "the pattern is" not in capsys.readouterr().err  # texture coordinates have no scale


@pytest.mark.parametrize("engine, status", [("float", 0), ("fixed", 4)])
def test_a_batch_names_the_mesh_of_each_start_note(engine, status, tmp_path, monkeypatch, capsys):
    """The start's notes (ARAP failed: SLIM instead) come from workers in any order: each names its mesh. The
    fixed-point formats cannot hold the mesh's 1e-9 edge: that refusal comes before the start, so there is no
    start note then, and each refusal names its mesh."""
    monkeypatch.chdir(tmp_path)
    os.mkdir("in")
    uv = grid_uv(6, 6)
    vertices = np.column_stack([uv, 0.1 * (uv**2).sum(axis=1)])
    vertices[14] = vertices[13] + [1e-9, 0, 0]  # a sliver on which libigl's ARAP returns non-finite coordinates
    for k in range(2):
        save_obj(f"in/sliver{k}.obj", vertices, grid_faces(6, 6))
    assert main(["flatten", "in/sliver0.obj", "in/sliver1.obj", "--out-dir", "o", "--out", ".obj", "--max-iter", "3",
                 "--jobs", "1", "--engine", engine]) == status
    out, err = capsys.readouterr()
    notes = [line for line in err.splitlines() if "arap layout failed" in line]
    if engine == "float":
        assert sorted(line.split(": ")[2] for line in notes) == ["sliver0", "sliver1"], notes
    else:
        refusals = [line for line in out.splitlines() if ": failed: the shortest edge is" in line]
        assert not notes and sorted(line.split()[1] for line in refusals) == ["in/sliver0.obj:", "in/sliver1.obj:"]


def _dies_on_dome01(job):
    """``flatten_one``, whose worker process dies on the mesh ``dome01`` (a crash, or the kernel's OOM killer)."""
    import sim.batch

    if job.name == "dome01":
        os._exit(9)
    return sim.batch.REAL_FLATTEN_ONE(job)


def test_a_worker_that_dies_fails_its_mesh_only(tmp_path, monkeypatch, capsys):
    import sim.batch

    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 6, 0)
    monkeypatch.setattr(sim.batch, "REAL_FLATTEN_ONE", sim.batch.flatten_one, raising=False)
    monkeypatch.setattr(sim.batch, "flatten_one", _dies_on_dome01)  # the workers are forked: they have it too
    meshes = sorted(str(p) for p in (tmp_path / "in").iterdir() if p.name != "corrupt.obj")
    assert main(["flatten", *meshes, "--out-dir", "o", "--out", ".dxf", "--max-iter", "3", "--jobs", "2"]) == 4
    out = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split()[1] for line in out if line.startswith("dome")}
    assert rows.pop("dome01") == "failed" and set(rows.values()) == {"max-iterations"} and len(rows) == 5, out
    assert any(line.endswith("dome01.off: failed: its worker process died (killed by a signal, or out of memory)")
               for line in out), out
    assert sorted(os.listdir("o")) == [f"dome0{k}.dxf" for k in (0, 2, 3, 4, 5)]


@pytest.mark.parametrize("obstacle", ["directory", "fifo", "dangling link into a missing directory"])
def test_an_obstacle_to_a_later_meshs_file_is_refused_before_any_run(tmp_path, monkeypatch, capsys, obstacle):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 3, 0)
    os.mkdir("o")
    {"directory": os.mkdir, "fifo": os.mkfifo,
     "dangling link into a missing directory": lambda path: os.symlink("nowhere/x.dxf", path)}[obstacle]("o/dome02.dxf")
    assert main(["flatten", "in/dome00.obj", "in/dome01.off", "in/dome02.obj", "--out-dir", "o", "--out", ".dxf",
                 "--max-iter", "3"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("springflat: error: ") and "o/dome02.dxf" in err and len(err.splitlines()) == 1
    assert sorted(os.listdir("o")) == ["dome02.dxf"]


def test_a_mesh_whose_files_cannot_be_written_is_failed_in_the_table_and_the_json(tmp_path, monkeypatch, capsys):
    """The run finished but its file could not be put in place (a directory of its name made during the run):
    the mesh is failed everywhere, not only in the count, and the others' files are written; --init auto is a
    method a batch takes."""
    import sim.batch

    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    os.mkdir("o")
    real_write_files = sim.batch._write_files

    def obstacle_during_the_run(out_dir, outcome):
        if outcome.name == "dome01" and not (out_dir / "dome01.dxf").exists():
            os.mkdir(out_dir / "dome01.dxf")
        real_write_files(out_dir, outcome)

    monkeypatch.setattr(sim.batch, "_write_files", obstacle_during_the_run)
    argv = ["flatten", "in/dome00.obj", "in/dome01.off", "--out-dir", "o", "--out", ".dxf", "--init", "auto",
            "--max-iter", "5", "--jobs", "1"]
    assert main(argv) == 4
    out = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split()[1] for line in out if line.startswith("dome")}
    assert rows["dome01"] == "failed" and rows["dome00"] in {"converged", "max-iterations"}
    assert out[-1].startswith("2 meshes: 1 ") and "1 failed" in out[-1]
    os.remove("o/dome00.dxf")
    os.rmdir("o/dome01.dxf")
    assert main([*argv, "--json"]) == 4
    records = {r["mesh"]: r for r in map(json.loads, capsys.readouterr().out.splitlines()) if "mesh" in r}
    assert records["dome01"]["status"] == "failed" and records["dome01"]["error"] == "output 'o/dome01.dxf' is a directory"
    assert records["dome01"]["files"] == [] and records["dome00"]["files"] == ["o/dome00.dxf"]
    assert os.path.isfile("o/dome00.dxf")


@pytest.mark.parametrize("out_dir", ["new/o", "new/../other/o"])
def test_a_batch_that_writes_nothing_leaves_no_out_dir_it_made(tmp_path, monkeypatch, capsys, out_dir):
    """Every run diverged (a diverged run writes no pattern): the --out-dir the batch made, and its missing
    parents, are gone again (with '..': 'new' and 'other')."""
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    assert main(["flatten", "in/dome00.obj", "in/dome01.off", "--out-dir", out_dir, "--out", ".svg", "--step", "fixed",
                 "--dt", "50", "--dynamics", "paper"]) == 3
    err = capsys.readouterr().err
    assert os.listdir(tmp_path) == ["in"]
    for name in ("dome00", "dome01"):  # each diverged mesh says where it ran away and what to try, as a single run
        assert re.search(f"springflat: note: {name}: iteration [0-9]+ ran away: a value stopped being finite, or the "
                         "layout grew .* \\(the paper dynamics has no guard: try --damping 0.05, a smaller --dt, or "
                         "--dynamics momentum \\(it takes none of --step, --dt, --damping, --density\\)\\)", err), err


def test_two_meshes_of_one_name_are_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "a", 1, 0)
    write_meshes(tmp_path / "b", 1, 0)
    assert main(["flatten", "a/dome00.obj", "b/dome00.obj", "--out-dir", "o", "--out", ".dxf"]) == 2
    assert "are both named 'dome00'" in capsys.readouterr().err
    assert main(["flatten", "a/dome00.obj", "a/dome00.obj", "--out-dir", "o", "--out", ".dxf"]) == 2
    assert capsys.readouterr().err == "springflat: error: the mesh 'a/dome00.obj' is given twice\n"
    for other in ("b/../a/dome00.obj", f"{tmp_path}/a/dome00.obj"):
        assert main(["flatten", "a/dome00.obj", other, "--out-dir", "o", "--out", ".dxf"]) == 2
        assert capsys.readouterr().err == (f"springflat: error: the mesh '{other}' is given twice (as 'a/dome00.obj' "
                                           "too: the same file)\n")


def _helical_ribbon(path: Path) -> None:
    """A ribbon wound through 430° and rising as a helix: its fold-free flattening is a ring sector of more than a
    turn, whose end lies on its start (the boundary crosses itself) though no triangle is folded."""
    columns, rows = 61, 3
    u, v = (grid.ravel() for grid in np.meshgrid(np.arange(columns, dtype=float), np.arange(rows, dtype=float)))
    angle, radius = u / (columns - 1) * np.radians(430), 7.0 - v
    faces = [[r * columns + k, r * columns + k + 1, (r + 1) * columns + k + 1] for r in range(rows - 1)
             for k in range(columns - 1)]
    faces += [[r * columns + k, (r + 1) * columns + k + 1, (r + 1) * columns + k] for r in range(rows - 1)
              for k in range(columns - 1)]
    save_obj(path, np.c_[radius * np.cos(angle), radius * np.sin(angle), 0.3 * angle], np.array(faces))


def test_a_pattern_that_overlaps_itself_shows_in_its_line_the_table_and_the_closing_count(tmp_path, monkeypatch,
                                                                                          capsys):
    """Its cut line crosses itself, so a cut along it does not give the piece: the note on stderr scrolls past in a
    batch, so the result line, the table's `overlaps` column and the closing line say it (empty where not counted:
    a folded pattern)."""
    monkeypatch.chdir(tmp_path)
    _helical_ribbon(tmp_path / "ribbon.obj")
    save_obj("dome.obj", dome_grid(5).vertices * 100, dome_grid(5).faces)
    assert main(["flatten", "ribbon.obj", "dome.obj", "surf1", "--out-dir", "o", "--out", ".dxf", "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    ribbon = next(line for line in lines if line.startswith("[") and "ribbon:" in line)
    overlaps = int(re.search(r"folded 0 \(flipped against P0: 0\), overlaps (\d+) ", ribbon)[1])
    assert overlaps > 0
    dome = next(line for line in lines if line.startswith("[") and "dome:" in line)
    assert "folded 0" in dome and "overlaps" not in dome
    header = next(k for k, line in enumerate(lines) if line.startswith("mesh "))
    assert lines[header].split() == ["mesh", "status", "iterations", "E_S", "E_C", "folded", "overlaps", "seconds"]
    rows = {line.split()[0]: line for line in lines[header + 1:header + 4]}
    assert rows["ribbon"].split()[5:7] == ["0", str(overlaps)] and rows["dome"].split()[5:7] == ["0", "0"]
    assert len(rows["surf1"].split()) == 7  # surf1 ends folded under the paper's dynamics: its overlaps not counted
    assert re.fullmatch(r"3 meshes: 3 converged; 1 overlapping itself; .* s on 1 worker process", lines[header + 4])

def test_the_tables_columns_line_up_under_wide_characters(tmp_path, monkeypatch, capsys):
    """A CJK character takes two columns of a terminal, an accent, a Thai vowel mark or a decomposed Hangul
    syllable's vowel none: counted as characters, they shifted their rows' cells."""
    monkeypatch.chdir(tmp_path)
    mesh = dome_grid(5)
    # shown as: 猫耳 (4 columns), plain (5), é (1), กิ (1), 가 (2)
    names = ("猫耳", "plain", "e\u0301", "\u0e01\u0e34", "\u1100\u1161")
    for name in names:
        save_obj(f"{name}.obj", mesh.vertices * 100, mesh.faces)
    assert main(["flatten", *(f"{name}.obj" for name in names), "--out-dir", "o", "--out", ".dxf", "--max-iter", "3",
                 "--jobs", "1"]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(k for k, line in enumerate(lines) if line.startswith("mesh "))
    # each row: the name, then spaces up to the widest name's 5 columns and the two between cells
    padding = {line.split()[0]: len(line) - len(line.split()[0]) - len(line[len(line.split()[0]):].lstrip(" "))
               for line in lines[header + 1:header + 1 + len(names)]}
    assert padding == {"猫耳": 3, "plain": 2, "e\u0301": 6, "\u0e01\u0e34": 6, "\u1100\u1161": 5}


def test_the_table_has_one_row_per_mesh_whatever_its_file_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    mesh = dome_grid(5)
    for name in ("a\nb.obj", "plain.obj", ".hidden.obj"):  # a hidden file's outputs are hidden too
        save_obj(name, mesh.vertices * 100, mesh.faces)
    assert main(["flatten", "a\nb.obj", "plain.obj", ".hidden.obj", "--out-dir", "o", "--out", ".dxf",
                 "--max-iter", "3"]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(k for k, line in enumerate(lines) if line.startswith("mesh "))
    table = lines[header + 1:header + 4]
    assert [row.split()[0] for row in table] == ["a\\nb", "plain", ".hidden"], table
    assert header == 3  # the lines as each mesh finishes: one each
    assert sorted(os.listdir("o")) == [".hidden.dxf", "a\nb.dxf", "plain.dxf"]
    # --json carries the file names as they are (JSON escapes its own), and the mesh's name as the pattern files
    # carry it in their headers and titles, one line of text
    assert main(["flatten", "a\nb.obj", "plain.obj", "--out-dir", "j", "--out", ".dxf", "--max-iter", "3",
                 "--json"]) == 0
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    record = next(r for r in records if r.get("source") == "a\nb.obj")
    assert (record["mesh"], record["files"]) == ("a\\nb", ["j/a\nb.dxf"])


def test_on_a_file_system_that_folds_case_outputs_named_alike_but_for_case_are_one_file(tmp_path, monkeypatch,
                                                                                       capsys):
    """macOS's and Windows's file systems take 'a.svg' and 'A.svg' for one file: there two outputs so named, or
    two meshes 'Ear' and 'ear' of a batch, would replace each other's files. This one tells names apart (the
    probe says so and leaves nothing); where it did not, they are refused before the run."""
    import sim.outputs

    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "a", 2, 0)
    real = sim.outputs.folds_case(tmp_path)
    assert sim.outputs.folds_case(tmp_path / "new" / "dir") == real  # (a directory yet to be made: its parent's)
    assert not real or not sys.platform.startswith("linux")  # (Linux's file systems tell case apart)
    assert sorted(os.listdir(tmp_path)) == ["a"]  # (the probe left nothing)
    os.rename("a/dome01.off", "a/DOME00.off")
    monkeypatch.setattr(sim.outputs, "folds_case", lambda directory: True)
    assert main(["flatten", "a/dome00.obj", "--out", "p.svg", "--out", "P.SVG", "--max-iter", "3"]) == 2
    assert capsys.readouterr().err == "springflat: error: --out 'P.SVG' is the same file as --out 'p.svg'\n"
    assert main(["flatten", "a/dome00.obj", "a/DOME00.off", "--out-dir", "o", "--out", ".svg", "--max-iter", "3"]) == 2
    assert capsys.readouterr().err == ("springflat: error: 'a/dome00.obj' with --out .svg and 'a/DOME00.off' with "
                                       "--out .svg would both write 'o/DOME00.svg' (its file system takes 'dome00.svg' "
                                       "and 'DOME00.svg' for one name)\n")
    assert sorted(os.listdir(tmp_path)) == ["a"]


def test_an_out_dir_that_is_a_dangling_link_is_refused_naming_it(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "a", 2, 0)
    os.symlink("nowhere", "o")
    assert main(["flatten", "a/dome00.obj", "a/dome01.off", "--out-dir", "o", "--out", ".dxf"]) == 2
    assert capsys.readouterr().err == ("springflat: error: --out-dir 'o' is a symbolic link to 'nowhere', which does "
                                       "not exist\n")
    assert sorted(os.listdir()) == ["a", "o"] and os.path.islink("o")
    os.symlink("loop", "loop")  # a link to itself exists, and names nothing
    assert main(["flatten", "a/dome00.obj", "a/dome01.off", "--out-dir", "loop", "--out", ".dxf"]) == 2
    assert capsys.readouterr().err == ("springflat: error: --out-dir 'loop' is a loop of symbolic links: it names no "
                                       "directory\n")
    assert sorted(os.listdir()) == ["a", "loop", "o"]


@pytest.mark.slow
def test_study_on_a_dask_local_cluster_gives_the_pools_results(tmp_path):
    import csv

    args = ["study", "surf2", "--init", "pca", "--step", "variable", "--sweep", "lut_index_bits", "--no-optimise",
            "--quiet", "--workers", "2"]
    pool = run(*args, "--out", tmp_path / "pool")
    dask = run(*args, "--out", tmp_path / "dask", "--scheduler", "local")
    assert pool.returncode == dask.returncode == 0, dask.stderr
    for name in ("summary.csv", "chosen.json"):
        assert (tmp_path / "pool" / name).read_bytes() == (tmp_path / "dask" / name).read_bytes(), name

    def runs(folder):  # every column but the wall time of each run
        with open(tmp_path / folder / "results.csv", newline="") as f:
            return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(f)]
    # the base set, each other preset, lut_index_bits from 5 to 10
    assert runs("pool") == runs("dask") and len(runs("pool")) == 1 + (len(PRESETS) - 1) + 6


def test_a_mesh_name_with_a_dot_gets_the_kind_its_ending_names(tmp_path, monkeypatch, capsys):
    """``ear.flat.obj`` with ``--out .obj`` is the mesh with texture coordinates, ``--out .svg`` the sheets:
    the mesh's name ends in ``.flat``, the endings given do not."""
    monkeypatch.chdir(tmp_path)
    mesh = dome_grid(5)
    save_obj("ear.flat.obj", mesh.vertices * 100, mesh.faces)
    assert main(["flatten", "ear.flat.obj", "--out-dir", "o", "--out", ".obj", "--out", ".svg",
                 "--max-iter", "3"]) == 0
    assert sorted(os.listdir("o")) == ["ear.flat.obj", "ear.flat.svg"]
    obj = Path("o/ear.flat.obj").read_text()
    assert sum(line.startswith("vt ") for line in obj.splitlines()) == mesh.n_vertices and " 1/1 " in obj
    assert 'id="sheet-' in Path("o/ear.flat.svg").read_text()


def test_a_file_name_with_undecodable_bytes_is_written_one_way_in_a_batchs_notes_and_json(tmp_path, monkeypatch,
                                                                                          capsys):
    """As the table prints it (``\\xff``): a lone surrogate in JSON names no file a reader can open (jq reads
    U+FFFD), and the notes said the name one way, the table another."""
    mesh = dome_grid(5)
    odd = os.fsdecode(b"odd\xffname")
    save_obj(tmp_path / f"{odd}.obj", mesh.vertices * 0.5, mesh.faces)  # half a millimetre: a scale note
    save_obj(tmp_path / "plain.obj", mesh.vertices * 100, mesh.faces)
    save_obj(tmp_path / "no\u00a0break.obj", mesh.vertices * 100, mesh.faces)  # valid text: named as it is
    monkeypatch.chdir(tmp_path)
    assert main(["flatten", f"{odd}.obj", "plain.obj", "no\u00a0break.obj", "--out-dir", "out", "--out", ".pdf",
                 "--max-iter", "5", "--json"]) == 0
    out, err = capsys.readouterr()
    records = [json.loads(line) for line in out.splitlines()]
    odd_record = next(r for r in records if r.get("mesh", "").startswith("odd"))
    assert odd_record["mesh"] == "odd\\xffname" and odd_record["source"] == "odd\\xffname.obj"
    assert odd_record["files"] == [os.path.join("out", "odd\\xffname.pdf")]
    spaced = next(r for r in records if r.get("source", "").startswith("no"))
    assert spaced["source"] == "no\u00a0break.obj" and spaced["files"] == [os.path.join("out", "no\u00a0break.pdf")]
    assert Path(spaced["files"][0]).is_file()
    notes = [line for line in err.splitlines() if line.startswith("springflat: note: odd")]
    assert notes and all(line.startswith("springflat: note: odd\\xffname: ") for line in notes), err
    assert (tmp_path / "out" / f"{odd}.pdf").is_file()  # the file itself has the name's own bytes
    assert all("\udcff" not in line for line in [*out.splitlines(), *err.splitlines()])


def test_two_meshes_whose_names_and_endings_make_one_file_name_are_both_named(tmp_path, monkeypatch, capsys):
    mesh = dome_grid(5)
    (tmp_path / "in").mkdir()
    for name in ("a.obj", "a.flat.obj"):
        save_obj(tmp_path / "in" / name, mesh.vertices, mesh.faces)
    monkeypatch.chdir(tmp_path)
    assert main(["flatten", "in/a.obj", "in/a.flat.obj", "--out-dir", "out", "--out", ".obj", "--out",
                 ".flat.obj"]) == 2
    assert capsys.readouterr().err.splitlines() == [
        "springflat: error: 'in/a.obj' with --out .flat.obj and 'in/a.flat.obj' with --out .obj would both write "
        f"'{os.path.join('out', 'a.flat.obj')}'"]
    assert not (tmp_path / "out").exists()


def test_a_mesh_named_with_a_trailing_slash_fails_as_no_file_in_a_batch(tmp_path, monkeypatch, capsys):
    """``dome00.obj/`` names no file ("not a directory"): the batch read the file named without the slash."""
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    assert main(["flatten", "in/dome00.obj/", "in/dome01.off", "--out-dir", "o", "--out", ".flat.obj", "--json",
                 "--max-iter", "2"]) == 4
    records = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    by_mesh = {r["mesh"]: r for r in records[:-1]}
    assert by_mesh["dome00"]["status"] == "failed" and "not a directory" in by_mesh["dome00"]["error"]
    assert by_mesh["dome01"]["status"] != "failed"


def test_skip_existing_goes_on_after_an_interrupted_batch(tmp_path, monkeypatch, capsys):
    """A batch stopped after its first mesh (its files written, the second's not): run again with
    --skip-existing, the first is skipped, its files untouched, and the second runs; a mesh with only some of its
    files runs again."""
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 3, 0)
    argv = ["flatten", "in/dome00.obj", "in/dome01.off", "in/dome02.obj", "--out-dir", "o", "--out", ".dxf",
            "--history", ".csv", "--max-iter", "5", "--jobs", "1"]
    assert main(argv) == 0
    capsys.readouterr()
    first = {name: os.stat(f"o/{name}").st_mtime_ns for name in ("dome00.dxf", "dome00.csv")}
    os.remove("o/dome01.dxf")
    os.remove("o/dome01.csv")  # never written: the batch stopped before dome01 finished
    os.remove("o/dome02.csv")  # only its pattern there
    assert main([*argv, "--skip-existing"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split()[1] for line in out if line.startswith("dome")}
    assert rows == {"dome00": "skipped", "dome01": rows["dome01"], "dome02": rows["dome02"]}
    assert {rows["dome01"], rows["dome02"]} <= {"converged", "max-iterations"}
    assert "[1/3] in/dome00.obj: skipped: its files are in o" in out
    assert out[-1].startswith("3 meshes: 1 skipped, ")
    assert {name: os.stat(f"o/{name}").st_mtime_ns for name in first} == first
    assert sorted(os.listdir("o")) == sorted(f"dome0{k}.{e}" for k in range(3) for e in ("dxf", "csv"))
    os.chmod("o/dome00.dxf", 0o444)  # a finished file made read-only: its mesh is skipped, not refused
    assert main([*argv, "--skip-existing", "--json"]) == 0
    captured = capsys.readouterr()
    records = [json.loads(line) for line in captured.out.splitlines()]
    assert [r["status"] for r in records[:-1]] == ["skipped"] * 3
    assert records[0]["files"] == ["o/dome00.dxf", "o/dome00.csv"]
    assert records[-1]["batch"]["skipped"] == 3
    assert main([*argv, "--skip-existing"]) == 0
    assert capsys.readouterr().err.splitlines()[0] == ("springflat: 3 meshes (3 skipped: their files are in o, newer "
                                                       "than the mesh; the options they were made with are not "
                                                       "compared: remove them to make them again)")


def test_skip_existing_runs_a_mesh_exported_again_since_its_files(tmp_path, monkeypatch, capsys):
    """A mesh re-exported under its name was skipped, its old pattern kept for the cutter: as make would, a mesh
    newer than any of its files runs again; so does one moved into place with its old time kept (mv, cp -p: its
    inode's time is the move's)."""
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 3, 0)
    argv = ["flatten", "in/dome00.obj", "in/dome01.off", "in/dome02.obj", "--out-dir", "o", "--out", ".dxf",
            "--history", ".csv", "--max-iter", "5", "--jobs", "1", "--skip-existing"]
    assert main(argv) == 0
    capsys.readouterr()
    old = os.stat("o/dome01.csv").st_mtime
    os.utime("in/dome01.off", (old + 60, old + 60))  # exported again after the batch
    shutil.copy("in/dome00.obj", "replacement.obj")  # another mesh, dated before the files, moved into place
    os.utime("replacement.obj", (old - 120, old - 120))
    os.replace("replacement.obj", "in/dome02.obj")
    assert os.stat("in/dome02.obj").st_mtime < os.stat("o/dome02.csv").st_mtime
    assert main(argv) == 0
    rows = {line.split()[0]: line.split()[1] for line in capsys.readouterr().out.splitlines() if line.startswith("dome")}
    assert rows["dome00"] == "skipped"
    assert rows["dome01"] in ("converged", "max-iterations") and rows["dome02"] in ("converged", "max-iterations")
    assert os.stat("o/dome01.csv").st_mtime > old


def test_skip_existing_without_an_out_dir_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["flatten", "surf1", "--out", "a.dxf", "--skip-existing"]) == 2
    assert capsys.readouterr().err.strip() == ("springflat: error: --skip-existing skips a batch's meshes whose files "
                                               "are in --out-dir: add --out-dir DIR")
    assert os.listdir(tmp_path) == []


def test_skip_existing_does_not_take_a_mesh_or_a_foreign_obj_for_an_output(tmp_path, monkeypatch, capsys):
    """An output that is one of the batch's meshes, or an OBJ springflat did not write, is no finished output:
    refused as without --skip-existing, not taken for a finished pattern."""
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    assert main(["flatten", "in/dome00.obj", "in/dome01.off", "--out-dir", "in", "--out", ".obj",
                 "--skip-existing"]) == 2
    assert "is the same file as the mesh" in capsys.readouterr().err
    os.mkdir("o")
    save_obj(tmp_path / "o" / "dome00.obj", np.eye(3), np.array([[0, 1, 2]]))  # a user's mesh, no springflat header
    assert main(["flatten", "in/dome00.obj", "in/dome01.off", "--out-dir", "o", "--out", ".obj",
                 "--skip-existing"]) == 2
    assert "springflat did not write" in capsys.readouterr().err


def test_skip_existing_sees_a_mesh_changed_while_it_ran_a_link_pointed_elsewhere_and_a_tie(tmp_path, monkeypatch,
                                                                                            capsys):
    """A mesh exported again while the batch ran got files newer than itself, a link pointed at an older export
    was its target's time, and a file system of whole seconds ties them: each was skipped, its old pattern kept."""
    import sim.batch

    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 2, 0)
    argv = ["flatten", "in/dome00.obj", "in/link.off", "--out-dir", "o", "--out", ".dxf", "--max-iter", "3",
            "--jobs", "1", "--skip-existing"]
    os.symlink("dome01.off", "in/link.off")
    real_job = sim.batch._job

    def job_then_export_again(source, *rest):
        job = real_job(source, *rest)
        if source == "in/dome00.obj":  # exported again the moment after the batch read it
            os.utime(source, ns=(job.read_ns + 1000, job.read_ns + 1000))
        return job

    monkeypatch.setattr(sim.batch, "_job", job_then_export_again)
    assert main(argv) == 0
    assert ("springflat: note: in/dome00.obj changed while the batch ran: its files are of the mesh as it was read, "
            "and --skip-existing runs it again") in capsys.readouterr().err
    monkeypatch.setattr(sim.batch, "_job", real_job)

    def statuses() -> dict[str, str]:
        assert main(argv) == 0
        return {line.split()[0]: line.split()[1] for line in capsys.readouterr().out.splitlines()
                if line.startswith(("dome", "link"))}

    assert statuses() == {"dome00": "max-iterations", "link": "skipped"}  # its files were of the earlier mesh
    assert statuses() == {"dome00": "skipped", "link": "skipped"}  # the run again wrote fresh files
    written = os.stat("o/link.dxf").st_mtime_ns
    (tmp_path / "in" / "older.off").write_bytes((tmp_path / "in" / "dome01.off").read_bytes())
    os.utime("in/older.off", ns=(written - 10**9,) * 2)
    os.remove("in/link.off")
    os.symlink("older.off", "in/link.off")  # the link, not its target, is new
    assert statuses()["link"] != "skipped"
    os.utime("o/dome00.dxf", ns=(os.stat("in/dome00.obj").st_mtime_ns,) * 2)  # a tie: whole seconds
    assert statuses()["dome00"] != "skipped"


def test_a_touched_mesh_whose_finished_files_are_read_only_says_why_it_is_not_skipped(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_meshes(tmp_path / "in", 1, 0)
    argv = ["flatten", "in/dome00.obj", "surf1", "--out-dir", "o", "--out", ".dxf", "--max-iter", "3", "--jobs", "1",
            "--skip-existing"]
    assert main(argv) == 0
    capsys.readouterr()
    os.chmod("o/dome00.dxf", 0o444)
    future = os.stat("o/dome00.dxf").st_mtime_ns + 10**9
    os.utime("in/dome00.obj", ns=(future, future))  # touched: a checkout, a copy without -p
    assert main(argv) == 2
    assert capsys.readouterr().err.strip().endswith("(in/dome00.obj is newer than its files, so --skip-existing runs "
                                                    "it again)")


def test_a_worker_that_cannot_write_its_copy_of_the_mesh_fails_it_in_one_line(tmp_path, monkeypatch):
    """A full temporary directory: the mesh failed with the worker's whole traceback as one escaped string."""
    import errno
    import pathlib
    from concurrent.futures.process import _RemoteTraceback

    import sim.batch

    def full(self, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(pathlib.Path, "write_bytes", full)
    job = sim.batch.BatchJob(str(SCANS / "bunny_ear.obj"), "bunny_ear", b"v 0 0 0\n", {}, (("out", ".dxf"),),
                             scratch=str(tmp_path))
    outcome = sim.batch.flatten_one(job)
    assert outcome.failed and outcome.line == (f"cannot write the worker's files in '{tmp_path}': no space left on "
                                               "device (TMPDIR chooses the directory)")
    assert list(tmp_path.iterdir()) == []
    raised = OSError(errno.ENOSPC, "No space left on device")  # as a pool hands back a worker's exception
    raised.__cause__ = _RemoteTraceback('\n"""\nTraceback (most recent call last):\n  File "x.py"\n"""')
    assert sim.batch._died(job, raised).line == "the worker failed: OSError: [Errno 28] No space left on device"
