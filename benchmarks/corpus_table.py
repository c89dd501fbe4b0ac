"""The peer table of the public corpus: springflat's no-option run beside libigl ARAP and SLIM, and the bar of issue 25.

Run: ``.venv/bin/python benchmarks/corpus_table.py`` (build the corpus first: ``scripts/corpus.py``,
see docs/corpus.md).  For every patch of ``benchmarks/corpus/manifest.json`` found in ``--corpus``:

* **springflat**: ``springflat flatten PATCH --json`` (the ``.venv/bin/springflat`` of this tree) in a
  subprocess, with ``--keep-holes`` for the ``holed`` kind's patches (the option they need); the wall time
  of the whole command, its status, iterations, E_S, E_C and folded triangles from its JSON.  A run past
  ``--timeout`` counts as a failure.
* **ARAP**: libigl ARAP from the harmonic layout, iterated in chunks of 10 until no node moves more than
  1e-9 x the boundary length in a chunk, or 1,000 iterations (sim.layouts.arap_layout stops at 100).
* **SLIM**: libigl SLIM (symmetric Dirichlet) from Tutte's embedding, one iteration at a time until the
  energy changes by less than 1e-6 relative, or 200 iterations.

A patch with holes gives both peers the start springflat's computed starts take: the harmonic and Tutte
layouts of the patch with its holes closed (``Mesh.disk``), then ARAP or SLIM on the patch's own triangles.

E_S, E_C and folded are the project's own measures (``golden_model.reference.measure``: spec eqs. 12 and
14, each layout at its own scale; folded against the pattern's own orientation).  The peers depend only on
the patch, so they are cached by the patch's sha256 in ``CORPUS/peers.json``; reruns only rerun springflat.

The bar per mesh (issue 25): not diverged, 0 folded, E_C <= SLIM's and <= ARAP's where ARAP is
fold-free (both with a relative tolerance of ``EC_TOLERANCE``), wall time < 30 s.  Status
``max-iterations`` (capped) is counted but is no failure by itself.

``--barrier-sweep``: from a fold-free start (``--init harmonic`` unless ``--init`` is given), every legal
barrier setting: ``--no-barrier`` and ``--barrier-threshold K --barrier-gain M`` for K in {0.05, 0.5, 1},
M in {0.01, 4, 16}; per mesh and setting the status, folded and E_C, and whether any run folded or diverged.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from sim.layouts import harmonic_layout, tutte_layout  # noqa: E402
from golden_model.mesh import Holes, Mesh, overlap_counts  # noqa: E402
from sim.mesh_io import load_mesh_with_notes  # noqa: E402
from sim.outputs import OutputError, check_output_path, write_text_file  # noqa: E402
from golden_model.reference import SpringModel, measure  # noqa: E402

MANIFEST = REPO / "benchmarks" / "corpus" / "manifest.json"
DEFAULT_CORPUS = REPO / "build" / "corpus"
SPRINGFLAT = REPO / ".venv" / "bin" / "springflat"

#: E_C may exceed a peer's by this fraction and still meet the bar (printed with the table).
EC_TOLERANCE = 0.005
#: The bar's wall-time limit per run, seconds.
TIME_LIMIT = 30.0
ARAP_MAX_ITERATIONS = 1000
ARAP_CHUNK = 10
ARAP_TOLERANCE = 1e-9  # x boundary length, max node move over one chunk
SLIM_MAX_ITERATIONS = 200
SLIM_TOLERANCE = 1e-6  # relative energy change per iteration
#: Every legal barrier setting of the sweep: (label, CLI arguments).
BARRIER_SETTINGS = [("no barrier", ["--no-barrier"])] + [
    (f"kappa {k} mu {m}", ["--barrier-threshold", str(k), "--barrier-gain", str(m)])
    for k in (0.05, 0.5, 1) for m in (0.01, 4, 16)]
#: Version of the peer computation; a change invalidates the cache (2: boundary crossings counted).
PEER_VERSION = 2
_CACHE_LOCK = threading.Lock()


@dataclass
class Layout:
    """One layout's figures."""

    method: str
    seconds: float
    area_error: float
    shape_error: float
    folded: int
    iterations: int
    status: str = "ok"
    #: pairs of the boundary's sides that meet, on a fold-free layout (``None`` on a folded one)
    crossings: int | None = None
    #: holes the layout wraps over, where no sides meet (``None`` without holes)
    turned: int | None = None

    @classmethod
    def of(cls, method: str, mesh: Mesh, positions: np.ndarray, seconds: float, iterations: int) -> "Layout":
        if not np.isfinite(positions).all():
            return cls(method, seconds, math.nan, math.nan, mesh.n_faces, iterations, "non-finite")
        m = measure(SpringModel.build(mesh, positions, 0.5, "auto"), positions)
        crossings, turned = (None, None) if m.folded else overlap_counts(positions, mesh.faces, mesh.boundary_loops)
        return cls(method, seconds, m.area_error, m.shape_error, m.folded, iterations, crossings=crossings,
                   turned=turned)


@dataclass
class Run:
    """One springflat command."""

    args: list[str]
    seconds: float
    status: str
    iterations: int | None = None
    area_error: float | None = None
    shape_error: float | None = None
    folded: int | None = None
    message: str = ""
    #: folded triangles of the run's start layout (from its JSON)
    initial_folded: int | None = None
    #: pairs of the pattern's boundary sides that meet, on a fold-free pattern (its JSON's boundary_crossings)
    crossings: int | None = None
    #: kept holes the pattern wraps over (its JSON's turned_holes)
    turned: int | None = None


@dataclass
class Row:
    name: str
    kind: str
    vertices: int
    faces: int
    springflat: Run
    arap: Layout
    slim: Layout
    failures: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- peers


def arap_converged(mesh: Mesh) -> tuple[np.ndarray, int]:
    """libigl ARAP from the harmonic layout to convergence: ``(positions, iterations)``.

    As ``sim.layouts.arap_layout`` (one boundary vertex pinned, ``with_dynamics`` off) but
    up to :data:`ARAP_MAX_ITERATIONS`, stopping after a chunk of :data:`ARAP_CHUNK` iterations that
    moved no node more than :data:`ARAP_TOLERANCE` x the boundary length.
    """
    import igl

    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    positions = harmonic_layout(mesh.disk)
    loop = mesh.boundary_loop
    pinned = np.array([loop[0]], dtype=np.int32)
    targets = np.ascontiguousarray(positions[pinned.astype(np.int64)])
    perimeter = float(np.linalg.norm(vertices[np.roll(loop, -1)] - vertices[loop], axis=1).sum())
    data = igl.ARAPData()
    data.with_dynamics = False
    data.max_iter = ARAP_CHUNK
    igl.arap_precomputation(vertices, faces, 2, pinned, data)
    iterations = 0
    while iterations < ARAP_MAX_ITERATIONS:
        moved = np.asarray(igl.arap_solve(targets, data, positions), dtype=np.float64)
        iterations += ARAP_CHUNK
        change = float(np.abs(moved - positions).max()) if np.isfinite(moved).all() else math.inf
        positions = moved
        if not change > ARAP_TOLERANCE * perimeter:
            break
    return positions - positions.mean(axis=0), iterations


def symmetric_dirichlet(mesh: Mesh, positions: np.ndarray) -> float:
    """``Σ_t A_t (|J_t|²_F + |J_t⁻¹|²_F)``, J_t the map of triangle t from 3D to the layout (inf if any J_t is not orientation-preserving)."""
    p = mesh.vertices[mesh.faces]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    l1 = np.linalg.norm(e1, axis=1)
    x = np.zeros((len(p), 2, 2))
    x[:, 0, 0] = l1
    x[:, 0, 1] = np.sum(e1 * e2, axis=1) / l1
    x[:, 1, 1] = np.linalg.norm(np.cross(e1, e2), axis=1) / l1
    u = positions[mesh.faces]
    du = np.stack([u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]], axis=2)  # columns are the edges
    j = du @ np.linalg.inv(x)
    det = np.linalg.det(j)
    if not (det > 0).all() and not (det < 0).all():
        return math.inf
    frob = np.sum(j * j, axis=(1, 2))
    return float(np.sum(mesh.face_areas * (frob + frob / det ** 2)))


def slim_converged(mesh: Mesh) -> tuple[np.ndarray, int]:
    """libigl SLIM (symmetric Dirichlet) from Tutte's embedding to convergence: ``(positions, iterations)``."""
    import igl

    vertices = np.asfortranarray(mesh.vertices, dtype=np.float64)
    faces = np.asfortranarray(mesh.faces, dtype=np.int32)
    start = np.asfortranarray(tutte_layout(mesh.disk))
    data = igl.slim_precompute(vertices, faces, start, igl.MappingEnergyType.SYMMETRIC_DIRICHLET,
                               np.zeros(0, dtype=np.int32), np.zeros((0, 2), order="F"), 0.0)
    energy = symmetric_dirichlet(mesh, start)
    positions, iterations = start, 0
    while iterations < SLIM_MAX_ITERATIONS:
        positions = np.asarray(igl.slim_solve(data, 1), dtype=np.float64)
        iterations += 1
        new = symmetric_dirichlet(mesh, positions)
        if not math.isfinite(new) or abs(energy - new) <= SLIM_TOLERANCE * abs(new):
            break
        energy = new
    return positions, iterations


def timed(function, mesh: Mesh, method: str) -> Layout:
    start = time.perf_counter()
    try:
        positions, iterations = function(mesh)
    except Exception as exc:  # a libigl failure is a result of the peer, not of the benchmark
        return Layout(method, time.perf_counter() - start, math.nan, math.nan, mesh.n_faces, 0,
                      f"failed: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
    return Layout.of(method, mesh, positions, time.perf_counter() - start, iterations)


def peers_for(mesh: Mesh, sha: str, cache_path: Path, cache: dict) -> tuple[Layout, Layout]:
    hit = cache.get(sha)
    if hit and hit.get("version") == PEER_VERSION:
        return Layout(**hit["arap"]), Layout(**hit["slim"])
    arap = timed(arap_converged, mesh, "arap")
    slim = timed(slim_converged, mesh, "slim")
    with _CACHE_LOCK:  # --jobs N: one writer at a time
        cache[sha] = {"version": PEER_VERSION, "name": mesh.name, "arap": asdict(arap), "slim": asdict(slim)}
        partial = cache_path.with_suffix(".json.part")
        partial.write_text(json.dumps(cache, indent=1, allow_nan=True))
        partial.replace(cache_path)
    return arap, slim


# --------------------------------------------------------------------------- springflat runs


def springflat(patch: Path, extra: list[str], timeout: float) -> Run:
    """``springflat flatten PATCH --json EXTRA`` in a subprocess; the wall time of the whole command."""
    args = ["flatten", str(patch), "--json", *extra]
    start = time.perf_counter()
    try:
        done = subprocess.run([str(SPRINGFLAT), *args], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return Run(args, time.perf_counter() - start, "timeout", message=f"no result within {timeout:g} s")
    seconds = time.perf_counter() - start
    try:
        result = json.loads(done.stdout)
    except ValueError:
        lines = done.stderr.strip().splitlines()
        return Run(args, seconds, "error", message=lines[-1] if lines else f"exit status {done.returncode}")
    return Run(args, seconds, str(result["status"]), int(result["iterations"]), float(result["area_error"]),
               float(result["shape_error"]), int(result["folded"]), initial_folded=int(result["initial_folded"]),
               crossings=result.get("boundary_crossings"), turned=result.get("turned_holes"))


def bar_failures(run: Run, arap: Layout, slim: Layout) -> list[str]:
    """What of issue 25's bar the run misses (empty: it passes)."""
    if run.status in ("timeout", "error"):
        return [run.status]
    out = []
    if run.status == "diverged":
        out.append("diverged")
    if run.folded:
        out.append(f"folded {run.folded}")
    ec = run.shape_error if run.shape_error is not None and math.isfinite(run.shape_error) else math.inf
    if math.isfinite(slim.shape_error) and slim.folded == 0 and ec > slim.shape_error * (1 + EC_TOLERANCE):
        out.append("E_C > SLIM")
    if math.isfinite(arap.shape_error) and arap.folded == 0 and ec > arap.shape_error * (1 + EC_TOLERANCE):
        out.append("E_C > ARAP")
    if run.seconds >= TIME_LIMIT:
        out.append("slow")
    return out


# --------------------------------------------------------------------------- tables


def _f(x: float | None, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:.{digits}f}" if abs(x) < 1e3 else f"{x:.1e}"


def peer_cell(layout: Layout) -> str:
    if layout.status != "ok":
        return f"{layout.status} | - | - | - | -"
    return f"{layout.seconds:.1f} | {_f(layout.area_error)} | {_f(layout.shape_error)} | {layout.folded} | {layout.iterations}"


def markdown(rows: list[Row], command: str) -> str:
    lines = [f"Command: `{command}`", "",
             f"Bar: not diverged, 0 folded, E_C <= SLIM's and <= ARAP's where ARAP is fold-free "
             f"(relative tolerance {EC_TOLERANCE:.1%}), wall time < {TIME_LIMIT:g} s.", "",
             "| mesh | kind | V | start folded | status | it | time s | E_S | E_C | folded | ARAP s | E_S | E_C "
             "| folded | it | SLIM s | E_S | E_C | folded | it | bar |",
             "|---|---|--:|--:|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|--:|---|"]
    for r in rows:
        s = r.springflat
        verdict = "PASS" if not r.failures else "FAIL: " + ", ".join(r.failures)
        start = "-" if s.initial_folded is None else str(s.initial_folded)
        lines.append(f"| {r.name} | {r.kind} | {r.vertices} | {start} | {s.status} | {s.iterations if s.iterations is not None else '-'} "
                     f"| {s.seconds:.1f} | {_f(s.area_error)} | {_f(s.shape_error)} | "
                     f"{s.folded if s.folded is not None else '-'} | {peer_cell(r.arap)} | {peer_cell(r.slim)} | {verdict} |")
    lines += ["", summary(rows), "", overlaps(rows), "", *kind_table(rows)]
    return "\n".join(lines) + "\n"


def kind_table(rows: list[Row]) -> list[str]:
    """The bar's outcome per kind of patch (markdown lines)."""
    lines = ["| kind | meshes | pass | diverged | folded | slow or timeout | E_C miss | capped | start had folds |",
             "|---|--:|--:|--:|--:|--:|--:|--:|--:|"]
    for kind in dict.fromkeys(r.kind for r in rows):
        group = [r for r in rows if r.kind == kind]

        def count(*tags: str) -> int:
            return sum(any(f.startswith(tags) for f in r.failures) for r in group)

        lines.append(f"| `{kind}` | {len(group)} | {sum(not r.failures for r in group)} | {count('diverged')} | "
                     f"{count('folded')} | {count('slow', 'timeout')} | {count('E_C')} | "
                     f"{sum(r.springflat.status == 'max-iterations' for r in group)} | "
                     f"{sum(bool(r.springflat.initial_folded) for r in group)} |")
    return lines


def overlaps(rows: list[Row]) -> str:
    """Which fold-free layouts overlap themselves, per method: their boundary's sides meet (pairs of sides), or
    they wrap over kept holes (holes). Not in the bar."""
    def what(layout: Layout | Run) -> str:
        parts = [f"{layout.crossings} pair{'s' if layout.crossings > 1 else ''}"] if layout.crossings else []
        parts += [f"{layout.turned} hole{'s' if layout.turned > 1 else ''} wrapped over"] if layout.turned else []
        return ", ".join(parts)

    def listed(layouts: list[tuple[str, Layout | Run]]) -> str:
        found = [f"{name} ({what(layout)})" for name, layout in layouts if what(layout)]
        fold_free = sum(layout.crossings is not None for _, layout in layouts)
        return f"{len(found)} of {fold_free} fold-free" + (f": {', '.join(found)}" if found else "")

    return ("Overlaps (fold-free layouts whose boundary's sides meet, or that wrap over a kept hole), not part of the "
            f"bar: springflat {listed([(r.name, r.springflat) for r in rows])}; "
            f"ARAP {listed([(r.name, r.arap) for r in rows])}; "
            f"SLIM {listed([(r.name, r.slim) for r in rows])}.")


def summary(rows: list[Row]) -> str:
    def count(tag: str) -> int:
        return sum(any(f.startswith(tag) for f in r.failures) for r in rows)

    passed = sum(not r.failures for r in rows)
    capped = sum(r.springflat.status == "max-iterations" for r in rows)
    return (f"{passed} of {len(rows)} pass; diverged {count('diverged')}, folded {count('folded')}, "
            f"capped {capped}, slow {count('slow')}, E_C misses {sum(any(f.startswith('E_C') for f in r.failures) for r in rows)} "
            f"(E_C > SLIM {count('E_C > SLIM')}, E_C > ARAP {count('E_C > ARAP')}), "
            f"timeouts {count('timeout')}, errors {count('error')}")


# --------------------------------------------------------------------------- driver


def patches(corpus: Path, only: list[str] | None, kinds: list[str] | None) -> list[dict]:
    manifest = json.loads(MANIFEST.read_text())
    entries = manifest["patches"]
    if only:
        unknown = set(only) - {e["name"] for e in entries}
        if unknown:
            raise SystemExit(f"corpus_table: error: no patch named {', '.join(sorted(unknown))} in the manifest")
        entries = [e for e in entries if e["name"] in only]
    if kinds:
        unknown = set(kinds) - set(manifest["kinds"])
        if unknown:
            raise SystemExit(f"corpus_table: error: unknown kind {', '.join(sorted(unknown))} "
                             f"(kinds: {', '.join(manifest['kinds'])})")
        entries = [e for e in entries if e["kind"] in kinds]
    missing = [e["name"] for e in entries if not (corpus / f"{e['name']}.ply").is_file()]
    if missing:
        raise SystemExit(f"corpus_table: error: {len(missing)} patches missing from '{corpus}' (first: {missing[0]}); "
                         "build the corpus with scripts/corpus.py (docs/corpus.md)")
    return entries


def holed(entry: dict) -> bool:
    """A patch with cut-outs (the ``holed`` kind): springflat runs it with ``--keep-holes``."""
    return bool(entry["recipe"].get("cut_outs"))


def holes_options(entry: dict) -> list[str]:
    """The command-line options a patch's runs need: ``--keep-holes`` for a ``holed`` one."""
    return ["--keep-holes"] if holed(entry) else []


def load_patch(entry: dict, corpus: Path) -> Mesh:
    """The patch of ``entry`` in ``corpus``, a ``holed`` one with its holes kept."""
    return load_mesh_with_notes(corpus / f"{entry['name']}.ply", holes=Holes.KEEP if holed(entry) else Holes.REFUSE)[0]


def table_row(entry: dict, corpus: Path, extra: list[str], timeout: float, cache_path: Path, cache: dict) -> Row:
    patch = corpus / f"{entry['name']}.ply"
    mesh = load_patch(entry, corpus)
    arap, slim = peers_for(mesh, entry["patch"]["sha256"], cache_path, cache)
    run = springflat(patch, [*extra, *holes_options(entry)], timeout)
    row = Row(entry["name"], entry["kind"], mesh.n_vertices, mesh.n_faces, run, arap, slim)
    row.failures = bar_failures(run, arap, slim)
    return row


def sweep_rows(entry: dict, corpus: Path, extra: list[str], timeout: float) -> list[dict]:
    patch = corpus / f"{entry['name']}.ply"
    out = []
    for label, setting in BARRIER_SETTINGS:
        run = springflat(patch, [*extra, *setting, *holes_options(entry)], timeout)
        out.append({"name": entry["name"], "kind": entry["kind"], "setting": label, **asdict(run)})
    return out


def sweep_markdown(results: list[dict], command: str) -> str:
    """The sweep's table: every run, the totals, and the totals per barrier setting."""
    lines = [f"Command: `{command}`", "", "| mesh | kind | setting | status | it | folded | E_C |",
             "|---|---|---|---|--:|--:|--:|"]
    for r in results:
        lines.append(f"| {r['name']} | {r['kind']} | {r['setting']} | {r['status']} | {r['iterations'] or '-'} | "
                     f"{r['folded'] if r['folded'] is not None else '-'} | {_f(r['shape_error'])} |")

    def totals(runs: list[dict]) -> tuple[int, int, int, int, int]:
        return (len(runs), sum(r["status"] == "diverged" for r in runs), sum(bool(r["folded"]) for r in runs),
                sum(r["status"] == "timeout" for r in runs), sum(r["status"] == "error" for r in runs))

    runs, diverged, folded, timeouts, errors = totals(results)
    meshes = len(dict.fromkeys(r["name"] for r in results))
    lines += ["", f"{runs} runs on {meshes} meshes; folded {folded}, diverged {diverged}, timeouts {timeouts}, "
                  f"errors {errors}" + ("" if diverged or folded or timeouts or errors else "; no folds and no divergence"),
              "", "| setting | runs | diverged | ended with folds | timeouts | errors |", "|---|--:|--:|--:|--:|--:|"]
    for setting in dict.fromkeys(r["setting"] for r in results):
        n, d, f, t, e = totals([r for r in results if r["setting"] == setting])
        lines.append(f"| {setting} | {n} | {d} | {f} | {t} | {e} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="Timings are honest only with --jobs 1 on an otherwise idle machine: with N > 1 on this 2-core "
               "machine the runs share the cores, and their times are not the bar's.")
    parser.add_argument("--corpus", type=Path, default=DEFAULT_CORPUS, help="directory of the patches (default %(default)s)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="only these patches")
    parser.add_argument("--kinds", nargs="+", metavar="KIND", help="only patches of these kinds")
    parser.add_argument("--json", type=Path, metavar="OUT", help="write every result as JSON")
    parser.add_argument("--markdown", type=Path, metavar="OUT", help="write the table as markdown")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per springflat run (default %(default)s)")
    parser.add_argument("--springflat-args", default="", metavar="ARGS", help="extra springflat flatten arguments, quoted")
    parser.add_argument("--init", help="springflat's --init (default: none, i.e. the no-option run; harmonic in --barrier-sweep)")
    parser.add_argument("--jobs", type=int, default=1, help="meshes at once (default 1; see below)")
    parser.add_argument("--barrier-sweep", action="store_true", help="run every legal barrier setting from a fold-free start")
    parser.add_argument("--peers", type=Path, help="peer cache (default CORPUS/peers.json)")
    parser.add_argument("--render", type=Path, metavar="JSON", help="run nothing: print (and --markdown) the table "
                                                                      "of a --json file written before")
    args = parser.parse_args(argv)
    for what, path in (("--markdown", args.markdown), ("--json", args.json)):  # before the hour of runs
        if path is not None:
            try:
                check_output_path(path, what, typed=False)
            except OutputError as exc:
                parser.error(str(exc))
    if args.render:
        saved = json.loads(args.render.read_text())
        if "runs" in saved:  # a --barrier-sweep's
            text = sweep_markdown(saved["runs"], saved["command"])
            print(text)
            if args.markdown:
                write_text_file(args.markdown, text)
            return 0
        rows = [Row(**{**r, "springflat": Run(**r["springflat"]), "arap": Layout(**r["arap"]),
                       "slim": Layout(**r["slim"])}) for r in saved["rows"]]
        text = markdown(rows, saved["command"])
        print(text)
        if args.markdown:
            write_text_file(args.markdown, text)
        return 0
    entries = patches(args.corpus, args.only, args.kinds)
    extra = shlex.split(args.springflat_args)
    command = "benchmarks/corpus_table.py " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    jobs = max(1, args.jobs)

    if args.barrier_sweep:
        extra += ["--init", args.init or "harmonic"]
        with ThreadPoolExecutor(jobs) as pool:
            results = [r for rows in pool.map(lambda e: sweep_rows(e, args.corpus, extra, args.timeout), entries)
                       for r in rows]
        text = sweep_markdown(results, command)
        print(text)
        if args.markdown:
            write_text_file(args.markdown, text)
        if args.json:
            write_text_file(args.json, json.dumps({"command": command, "runs": results}, indent=1))
        return 0

    if args.init:
        extra += ["--init", args.init]
    cache_path = args.peers or args.corpus / "peers.json"
    cache = json.loads(cache_path.read_text()) if cache_path.is_file() else {}
    print(f"springflat: {SPRINGFLAT} flatten PATCH --json {' '.join(extra)}; E_C tolerance {EC_TOLERANCE:.1%}; "
          f"{len(entries)} meshes, {jobs} at once", file=sys.stderr, flush=True)

    def one(entry: dict) -> Row:
        row = table_row(entry, args.corpus, extra, args.timeout, cache_path, cache)
        s = row.springflat
        print(f"{row.name}: {s.status} it {s.iterations} {s.seconds:.1f} s E_C {_f(s.shape_error)} folded {s.folded} | "
              f"ARAP E_C {_f(row.arap.shape_error)} folded {row.arap.folded} | SLIM E_C {_f(row.slim.shape_error)} "
              f"folded {row.slim.folded} | {'PASS' if not row.failures else 'FAIL: ' + ', '.join(row.failures)}",
              file=sys.stderr, flush=True)
        return row

    with ThreadPoolExecutor(jobs) as pool:
        rows = list(pool.map(one, entries))
    text = markdown(rows, command)
    print(text)
    if args.markdown:
        write_text_file(args.markdown, text)
    if args.json:
        write_text_file(args.json, json.dumps({"command": command, "ec_tolerance": EC_TOLERANCE,
                                               "time_limit": TIME_LIMIT, "summary": summary(rows),
                                               "rows": [asdict(r) for r in rows]}, indent=1, allow_nan=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
