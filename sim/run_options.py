"""What every ``springflat`` command that runs the algorithm shares: the run options, the
mesh's default parameters and initial layout, argument types and the one-line user errors.

``sim/cli.py``, ``sim/rtl_check.py`` and ``sim/study/cli.py`` import from here, not from each other.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import re
import sys
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from golden_model.builtin import BUILTIN_MESHES, builtin_mesh, is_builtin
from golden_model.coarse import COARSE_DEGREE_MAX, DEFAULT_COARSE_DEGREE
from golden_model.files import describe_os_error, same_file_key
from golden_model.mesh import HoledMesh, Holes, Mesh, MeshError, folded_faces, one_line
from golden_model.modes import DYNAMICS, RUN_MODES, STEP_MODES, Step
from golden_model.guard import ENERGY_WINDOW, energy_floor_strain
from golden_model.params import BARRIER_GAIN_MAX, MASS_PARAMETERS, UPDATE_ORDERS, FlattenParams, ParameterError

from .exit_codes import EXIT_USAGE
from .layouts import (AUTO_START, LAYOUT_METHODS, SIZE_TOLERANCE, LayoutError, NoDiskStart, init_name, initial_layout,
                      slim_layout, start_layout)
from .mesh_io import load_mesh_with_notes
from .mesh_io.seams import seams_note
from .mesh_io.polygons import is_float, is_int
from .outputs import OutputError, directory_name_problem, print_note

USER_ERRORS = (MeshError, LayoutError, ParameterError, OutputError)


class CommandParser(argparse.ArgumentParser):
    """argparse with the project's one-line error format (``error_name: error: …``), and no abbreviated
    options: with them ``rtl-check --engine fixed`` (``flatten``'s option) is taken as ``--engine-top`` and
    ``fixed`` refused, and a script's abbreviation changes meaning with the next option added."""

    def __init__(self, *args, error_name: str = "springflat", **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self.error_name = error_name

    def parse_known_args(self, args=None, namespace=None):
        self._argv = list(sys.argv[1:] if args is None else args)  # for error()'s hint
        return super().parse_known_args(args, namespace)

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.error_name}: error: {one_line(message)}{self._dash_value_hint(message)} "
                              f"(see '{self.prog} --help')\n")

    def _dash_value_hint(self, message: str) -> str:
        """argparse reads a value that starts with '-' and is not a plain negative number (``-4:8``, ``-1e-3``,
        a file ``-print.pdf``) as an option, and says only "expected one argument": name the way to give it (where
        the word after the option starts with one dash and is no option of the command)."""
        match = re.fullmatch(r"argument (\S+): expected one argument", message)
        if not match:
            return ""
        argv = getattr(self, "_argv", [])
        for option in match.group(1).split("/"):
            for token, value in zip(argv, argv[1:]):
                if token == option and value.startswith("-") and not value.startswith("--") \
                        and value not in self._option_string_actions:  # (a '--' word is an option mistyped)
                    return f"; a value that starts with '-' is read as an option: write {option}={value}"
        return ""

    def _print_message(self, message: str, file=None) -> None:
        """argparse's, without its silence on a failed write: ``--help`` or ``--version`` into a full disk
        or a closed pipe is the one line on the standard error and status 2, not a lost text and status 0."""
        if not message:
            return
        file = sys.stderr if file is None else file
        try:
            file.write(message)
            file.flush()
        except OSError as exc:
            if file is not sys.stderr:
                try:
                    print(f"{self.error_name}: error: cannot write standard output: {describe_os_error(exc)}",
                          file=sys.stderr)
                except OSError:  # (nowhere left to say it)
                    pass
            raise SystemExit(EXIT_USAGE) from None


class UserError(ValueError):
    """Anything else the user got wrong; one line."""


def load_format_set(spec):
    """:func:`golden_model.fixed.engine.load_formats` (a preset name or a JSON file), with the file errors it
    leaves to the caller made one line: an OS error reading the file, and JSON nested beyond Python's limit; a
    :class:`~golden_model.fixed.FormatSet` (the API's ``formats``) is itself."""
    from golden_model.fixed import FormatSet
    from golden_model.fixed.engine import load_formats

    if isinstance(spec, FormatSet):
        return spec
    if not spec.strip():
        raise UserError(f"the formats '{spec}' are empty: name a preset ({', '.join(FormatSet.presets())}) or a JSON "
                        "file")
    try:
        return load_formats(spec)
    except OSError as exc:
        raise UserError(f"cannot read formats file '{spec}': {describe_os_error(exc)}") from None
    except RecursionError:
        raise UserError(f"formats '{spec}': the JSON is nested too deeply") from None


def _density(text: str) -> float | str:
    if text == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'auto', got {text!r}") from None


def number_argument(text: str) -> float:
    """A number option's value, written as a number is (``float`` alone also reads ``1_0`` and ``٣``)."""
    if is_float(text.strip()):
        return float(text)
    raise argparse.ArgumentTypeError(f"expected a number, got {text!r}")


def integer_argument(text: str) -> int:
    """An integer option's value, written as an integer is (``int`` alone also reads ``1_0`` and ``٣``)."""
    if is_int(text.strip()):
        return int(text)
    raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")


class TypedPath(type(Path())):
    """A path option's value that formats as the user typed it, so that messages (f-strings) quote it so:
    pathlib drops a leading ``./`` and doubled slashes (``--out ./x.dxf`` would be quoted as ``x.dxf``).
    ``str()``, comparison and hashing stay pathlib's; paths made from it (its parent, a sibling) format as
    pathlib makes them."""

    def __format__(self, spec: str) -> str:
        typed = self.__dict__.get("typed")
        return format(str(self) if typed is None else typed, spec)


def path_argument(text: str) -> Path:
    """A path option's value (a :class:`TypedPath`); an empty one (``--out ''``) would name the current
    directory, so it is refused."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    path = TypedPath(text)
    path.typed = text
    return path


def file_path_argument(text: str) -> Path:
    """A file option's value: a path (:func:`path_argument`) that does not name a directory
    (:func:`~sim.outputs.directory_name_problem`)."""
    path = path_argument(text)
    if (problem := directory_name_problem(text)) is not None:
        raise argparse.ArgumentTypeError(problem)
    return path


class OneOutput(argparse.Action):
    """``store`` for an option that names one output (a file or a directory): given a second time it is refused,
    since keeping the last, as ``store`` does, would silently leave out a file the user asked for."""

    def __call__(self, parser, namespace, values, option_string=None):
        earlier = getattr(namespace, self.dest, None)
        if earlier is not self.default:  # the parser sets the default before it reads the options
            parser.error(f"{option_string} names one output and was given twice ('{earlier}' and '{values}'): "
                         "give it once")
        setattr(namespace, self.dest, values)


#: The parameters' defaults, which the options' help states.
_PARAMS = FlattenParams()


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """The options every command that runs the algorithm shares."""
    builtins = ", ".join(BUILTIN_MESHES)
    parser.add_argument("mesh", nargs="?", default="surf1",
                        help=f"OBJ/PLY/OFF/STL file or a built-in mesh ({builtins}); default surf1")
    holes = parser.add_mutually_exclusive_group()
    holes.add_argument("--fill-holes", action="store_true",
                       help="close the mesh's holes (each boundary loop but the outer edge) with triangles between "
                            "their own vertices before flattening, for a scan's holes: the pattern covers them "
                            "(default: a mesh with holes is refused)")
    holes.add_argument("--keep-holes", action="store_true",
                       help="keep the mesh's holes as cut-outs in the pattern (its start layout is computed with "
                            "them closed)")
    parser.add_argument("--init", default=None, metavar="|".join((AUTO_START,) + LAYOUT_METHODS) + "|PATH",
                        help="initial layout: auto (arap; for a guarded run slim from tutte where arap folds or "
                             "fails, and lscm where that is exact: a developable patch), tutte, pca, "
                             "harmonic, lscm, arap, slim (libigl) or a file of V rows 'x y' / an OBJ (default: "
                             "pca for built-ins, auto for files; a file is one mesh's, not a batch's); a file that "
                             "is a mirror image of the mesh (clockwise) is mirrored back in y, one more than "
                             f"{SIZE_TOLERANCE:g} times off the mesh's size is scaled to it; with the guarded "
                             "dynamics any other start with folds is untangled")
    parser.add_argument("--dynamics", choices=DYNAMICS, default=None,
                        help="paper (eqs. 7-9) or momentum (docs/dynamics.md); default: paper for built-ins, "
                             "momentum for files")
    parser.add_argument("--barrier", action=argparse.BooleanOptionalAction, default=None,
                        help="the fold barrier (default: on with momentum, off with paper)")
    parser.add_argument("--barrier-threshold", type=number_argument, default=None,
                        help="barrier threshold kappa in (0, 1]: the fraction of its 3D area below which a "
                             f"triangle is pushed back (default {_PARAMS.barrier_threshold:g})")
    parser.add_argument("--barrier-gain", type=number_argument, default=None,
                        help=f"barrier stiffness mu in (0, {BARRIER_GAIN_MAX:g}], relative to the springs' C (default "
                             f"{_PARAMS.barrier_gain:g})")
    parser.add_argument("--guard", action=argparse.BooleanOptionalAction, default=None,
                        help="the momentum dynamics' step guard: no accepted step raises the energy or inverts a "
                             "triangle (default: on with momentum; docs/guard.md)")
    parser.add_argument("--energy-window", type=integer_argument, default=None, metavar="W",
                        help="iterations over which the stop rule measures the relative energy change "
                             f"(default: 1 with paper, as Algorithm 1; {ENERGY_WINDOW} with momentum)")
    parser.add_argument("--coarse-degree", type=integer_argument, default=None, metavar="D",
                        help="the guarded momentum step's coarse space: add the best move in the span of the start "
                             f"layout's monomials up to degree D (0 to {COARSE_DEGREE_MAX}, 0: the Jacobi step alone; "
                             f"with {DEFAULT_COARSE_DEGREE} smooth patches come within 1 percent of the minimum in at "
                             "most 120 iterations; default: "
                             f"{DEFAULT_COARSE_DEGREE} for a mesh file's guarded run, else 0; docs/guard.md)")
    parser.add_argument("--step", choices=STEP_MODES, default=None,
                        help=f"the paper dynamics' step-size mode (default {_PARAMS.step}, eqs. 18-20)")
    parser.add_argument("--dt", type=number_argument, default=None, help=f"fixed step size (default {_PARAMS.dt:g})")
    parser.add_argument("--update", choices=UPDATE_ORDERS, default=_PARAMS.update,
                        help="update order: jacobi (synchronous) or sequential (Algorithm 1); default "
                             f"{_PARAMS.update}")
    parser.add_argument("--damping", type=number_argument, default=None,
                        help=f"the paper dynamics' velocity damping gamma in [0, 1) (default {_PARAMS.damping:g})")
    parser.add_argument("--penalty", action="store_true", help="apply the overlap penalty (eqs. 10-11)")
    parser.add_argument("--penalty-kappa", type=number_argument, default=None,
                        help=f"penalty threshold kappa (default {_PARAMS.penalty_kappa:g})")
    parser.add_argument("--penalty-gain", type=number_argument, default=None,
                        help=f"penalty gain lambda (default {_PARAMS.penalty_gain:g})")
    parser.add_argument("--spring", type=number_argument, default=None,
                        help=f"spring constant C (default {_PARAMS.spring:g})")
    parser.add_argument("--density", type=_density, default=None,
                        help="the paper dynamics' area density rho or 'auto' = 1/min m_i (default: 2 for built-ins, "
                             "auto for files; the momentum dynamics weighs each node by 2/(C deg) instead)")
    parser.add_argument("--tol-area", type=number_argument, default=None,
                        help="area error tolerance phi_S (default: the paper's for built-ins, Tables II and IV; "
                             "1, off, for files)")
    parser.add_argument("--tol-shape", type=number_argument, default=None,
                        help="shape error tolerance phi_C (default: the paper's for built-ins; 1, off, for files)")
    parser.add_argument("--tol-energy", type=number_argument, default=None,
                        help="relative energy change tolerance epsilon over the --energy-window (0: only an energy "
                             "that no longer changes at all stops the run; default: the paper's for built-ins; for "
                             f"files {FILE_TOL_ENERGY:g}, {FILE_TOL_ENERGY_PAPER:g} with --dynamics paper)")
    parser.add_argument("--max-iter", type=integer_argument, default=None,
                        help="iteration limit N_max (default: the paper's for built-ins; for files "
                             f"max({FILE_MIN_ITER}, {FILE_ITER_PER_EDGE} x the mesh's radius in edges))")


#: The stop rule for mesh files: the energy minimum, not the paper's Surf1 tolerances; the energy
#: change over the momentum dynamics' window of 10 iterations (docs/guard.md has the measurements).
FILE_TOL_ENERGY = 1e-3
#: ... and per iteration (Algorithm 1's rule) for a mesh file run with ``--dynamics paper``, whose
#: oscillating energy changes by more than this until it has settled.
FILE_TOL_ENERGY_PAPER = 1e-7
#: N_max for files: this many iterations per edge from the boundary to the deepest node (the
#: momentum dynamics needs about 6), and never fewer than FILE_MIN_ITER.
FILE_ITER_PER_EDGE = 40
FILE_MIN_ITER = 1000


def edge_radius(mesh: Mesh) -> int:
    """Edges from the boundary to the node farthest from it (breadth-first, all boundary nodes at 0)."""
    import scipy.sparse as sp

    i, j = mesh.edges.T
    adjacency = sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])),
                              shape=(mesh.n_vertices, mesh.n_vertices)).tocsr()
    reached = np.zeros(mesh.n_vertices, dtype=bool)
    reached[np.concatenate(mesh.boundary_loops)] = True
    frontier, depth = reached.copy(), 0
    while not reached.all():
        frontier = (adjacency @ frontier.astype(float) > 0) & ~reached
        reached |= frontier
        depth += 1
    return depth


def holes_mode(fill_holes: bool, keep_holes: bool) -> Holes:
    """What ``--fill-holes`` / ``--keep-holes`` ask done with a mesh's holes (one or neither)."""
    if fill_holes and keep_holes:
        raise UserError("--fill-holes and --keep-holes: a hole is closed or kept, give one of them")
    return Holes.FILL if fill_holes else Holes.KEEP if keep_holes else Holes.REFUSE


#: The refusal's hint for a mesh with holes, naming the options that take it.
HOLES_HINT = "--fill-holes closes all but the outer edge, --keep-holes keeps them as cut-outs"


def resolve_mesh(name: str, holes: Holes = Holes.REFUSE, notes: list[str] | None = None,
                 label: str | None = None) -> tuple[Mesh, FlattenParams]:
    """The mesh (a file's holes refused, closed or kept as ``holes`` says) and its default parameters; what
    the reader changed or found (``label: note``, ``label`` by default the mesh's name) goes to ``notes``, or to
    stderr where that is ``None``.

    Built-ins: the paper's sets (paper dynamics, Table II/IV tolerances).  Files: the momentum
    dynamics with the fold barrier, stopped at the energy minimum (relative energy change
    ``FILE_TOL_ENERGY``, no E_S/E_C thresholds) with ``N_max`` sized to the mesh's radius in edges.
    """
    def note(text: str) -> None:
        if notes is None:
            print_note(text)
        else:
            notes.append(text)

    if is_builtin(name):  # a file of that name has no mesh format's ending: it could not be read
        if Path(name).is_file():
            note(f"'{name}' is the built-in mesh; the file of that name here is not read "
                 "(a mesh file's name ends in its format: .obj, .ply, .off, .stl)")
        mesh, paper = builtin_mesh(name)
        return mesh, paper.flatten_params()
    if name.strip() and not Path(name).suffix and not os.path.lexists(name):  # a built-in's name mistyped?
        raise MeshError(f"cannot read mesh '{name}': no such file, and no built-in mesh of that name (built-in: "
                        f"{', '.join(BUILTIN_MESHES)}; a mesh file's name ends in its format: .obj, .ply, .off, .stl)")
    try:
        mesh, found = load_mesh_with_notes(name, holes=holes)
    except HoledMesh as exc:
        raise MeshError(f"{exc}; {HOLES_HINT}") from None
    for text in [*found, *filter(None, [seams_note(mesh.vertices, mesh.faces)])]:  # (as the API's flatten says it)
        note(f"{mesh.name if label is None else label}: {text}")
    return mesh, file_defaults(mesh)


#: A mesh file's parameters but ``N_max`` (:func:`file_defaults`): the momentum dynamics with the fold barrier and
#: the guard with the coarse space (:data:`~golden_model.coarse.DEFAULT_COARSE_DEGREE`; dropped with the guard
#: unless given), stopped at the energy minimum (``FILE_TOL_ENERGY``, no E_S/E_C thresholds).
FILE_PARAMS = FlattenParams(density="auto", dynamics="momentum", tol_area=1.0, tol_shape=1.0,
                            tol_energy=FILE_TOL_ENERGY, coarse_degree=DEFAULT_COARSE_DEGREE)


def file_defaults(mesh: Mesh) -> FlattenParams:
    """A mesh file's parameters (the API's arrays take them too): :data:`FILE_PARAMS` with ``N_max`` sized to
    the mesh's radius in edges."""
    return dataclasses.replace(FILE_PARAMS, max_iter=max(FILE_MIN_ITER, FILE_ITER_PER_EDGE * edge_radius(mesh)))


def init_notes(mesh_name: str, init) -> list[str]:
    """What ``--init`` needs said before the run: a start method's name that a file here also has (the method is
    taken, as a built-in's name is over a file), and a layout file given for an STL mesh, whose file has no shared
    vertices, so that the layout's rows follow the vertices as the reader numbers them (:func:`sim.mesh_io.load_mesh`),
    which the file does not show."""
    if not isinstance(init, str) or init == AUTO_START:
        return []
    if init in LAYOUT_METHODS:
        return ([f"--init {init} is the start method; the file '{init}' here is not read (give ./{init} for the file)"]
                if Path(init).is_file() else [])
    if Path(mesh_name).suffix.lower() != ".stl":
        return []
    return [f"an STL stores no shared vertices: row i of the layout '{init}' is taken for the mesh's vertex i, its "
            "i-th distinct corner in the file's order (as a pattern .obj written from this STL numbers them)"]


def default_init(mesh_name: str) -> str:
    """The initial layout when ``--init`` is not given: pca for built-ins (the paper runs), ``auto`` for files
    (ARAP; SLIM from Tutte where ARAP folds or fails; LSCM where that is exact to the stop rule's floor and more so
    than ARAP's: sim.layouts.start_layout)."""
    return "pca" if is_builtin(mesh_name) else AUTO_START


#: From this many vertices ARAP takes seconds here, and a guarded ``--init auto`` run with a second core
#: computes SLIM's start there while ARAP runs (:func:`slim_beside_arap`).
SLIM_BESIDE_ARAP_VERTICES = 5000


@contextlib.contextmanager
def slim_beside_arap(mesh: Mesh, enabled: bool) -> Iterator[Callable[[], np.ndarray] | None]:
    """``slim`` for :func:`~sim.layouts.start_layout`: where ``enabled``, the mesh has
    :data:`SLIM_BESIDE_ARAP_VERTICES` or more and this process may use two cores, SLIM's layout computed
    in a worker process from the start, so that where ARAP folds its layout is ready sooner (the same
    bytes: the same function on the same mesh); ``None`` (SLIM after ARAP, where needed) otherwise.
    Leaving the block ends the worker, whether its layout was used or not. Not in a daemonic process (a
    caller's ``multiprocessing.Pool`` worker), which may not have children."""
    import multiprocessing

    if not (enabled and mesh.n_vertices >= SLIM_BESIDE_ARAP_VERTICES and len(os.sched_getaffinity(0)) > 1
            and not multiprocessing.current_process().daemon):
        yield None
        return
    from .workers import WorkerPool, result_of

    try:
        disk = mesh.disk
    except MeshError:  # (a kept slit: the start refuses it, saying why)
        yield None
        return
    with WorkerPool(1) as pool:
        try:
            future = pool.submit(slim_layout, disk)
            yield lambda: result_of(future)
        finally:
            pool.stop()  # ARAP did not fold, or SLIM's layout has arrived: nothing left to wait for


def start_positions(mesh: Mesh, init: str | np.ndarray, params: FlattenParams, progress: bool,
                    second_core: bool = False, notes: list[str] | None = None) -> tuple[np.ndarray, str]:
    """``(P0, what it is)``. A guarded run starts fold-free where that can be had (``start_layout``: folds are
    untangled, and what was done is one note each on stderr, or appended to ``notes`` when it is given);
    an unguarded run takes the layout as it is (``auto``: ARAP's, with a note where it folds).
    ``second_core``: ``--init auto`` may compute SLIM's start beside ARAP (:func:`slim_beside_arap`)."""
    def tell(told: list[str]) -> None:
        if notes is not None:
            notes.extend(told)
        else:
            for note in told:
                print_note(note)

    if not params.guard:
        read: list[str] = []
        try:
            positions = initial_layout(mesh, init, read)
        except LayoutError as exc:
            if init_name(init) != AUTO_START or isinstance(exc, NoDiskStart):
                raise
            raise LayoutError(f"{exc}; without the step guard --init auto takes no other start: give --init slim "
                              "(SLIM on Tutte's layout, where a guarded run, the default for mesh files, starts)"
                              ) from None
        if init_name(init) == AUTO_START and (folds := int(np.count_nonzero(folded_faces(positions, mesh.faces)))):
            read.append(f"the arap layout folds {folds} triangle{'s' if folds > 1 else ''}: without the step guard "
                        "the run starts from it as it is (the guarded dynamics, the default for mesh files, would "
                        "start from SLIM on Tutte's layout, fold-free)")
        tell(read)
        return positions, "arap" if init_name(init) == AUTO_START else init_name(init)
    said: list[str] = []  # the notes a progress line has given

    def say(text: str) -> None:
        said.append(text)
        print(f"springflat: {text} ...", file=sys.stderr)

    with slim_beside_arap(mesh, second_core and init_name(init) == AUTO_START) as slim:
        start = start_layout(mesh, init, progress=say if progress else None, slim=slim,
                             floor_strain=energy_floor_strain(params.tol_energy))
    tell([note for note in start.notes if note not in said])  # what the progress lines have not said
    return start.positions, start.method


def check_float_start(mesh: Mesh, positions: np.ndarray, params: FlattenParams, init) -> None:
    """Refuse, in one line, an unguarded float run's start with an edge of length zero: a spring's direction is
    undefined there, and the float reference's first step is not finite (a guarded start is untangled first, and
    the fixed-point engines' lengths saturate instead)."""
    if params.guard:
        return
    lengths = mesh.layout_lengths(positions)
    if lengths.all():
        return
    a, b = (int(v) for v in mesh.edges[np.flatnonzero(lengths == 0)[0]])
    given = init_name(init) not in (AUTO_START, *LAYOUT_METHODS)
    raise LayoutError(f"the start puts vertices {a} and {b}, an edge's ends, on one point"
                      + (f" (rows {a + 1} and {b + 1} of the layout)" if given else f" (the {init_name(init)} layout)")
                      + ": without the step guard the float run cannot start from it; move them apart, or let the "
                      "guard untangle it (" + ("drop --no-guard)" if params.mode.step is Step.MOMENTUM
                                               else "--dynamics momentum)"))


def mesh_names(meshes: list[str]) -> list[str]:
    """Each mesh's name (file stem or built-in name), for the commands that take several (a batch, a study): a
    mesh given twice, or two meshes of one name, whose outputs would share files, are refused in one line."""
    names = [m if is_builtin(m) else Path(m).stem for m in meshes]
    seen: dict[str, str] = {}
    for mesh, name in zip(meshes, names):
        if name in seen and seen[name] == mesh:
            raise UserError(f"the mesh '{mesh}' is given twice")
        if name in seen and not is_builtin(mesh) and (key := same_file_key(mesh)) is not None \
                and key == same_file_key(seen[name]):
            raise UserError(f"the mesh '{mesh}' is given twice (as '{seen[name]}' too: the same file)")
        if name in seen:
            raise UserError(f"'{seen[name]}' and '{mesh}' are both named '{name}': their outputs would collide")
        seen[name] = mesh
    return names


def params_from_args(args: argparse.Namespace, defaults: FlattenParams, fixed_point: bool = False) -> FlattenParams:
    """Apply the command-line overrides to ``defaults`` (validated). ``fixed_point``: the run goes to the
    fixed-point pipeline (``--engine fixed|rtl|board``, ``rtl-check``), which has no penalty: a penalty option
    is refused as such first, before a hint that would ask for another."""
    from golden_model.fixed.engine import NO_PENALTY

    given = {"penalty": args.penalty, "penalty_kappa": args.penalty_kappa is not None,  # (a value of 0 is given)
             "penalty_gain": args.penalty_gain is not None}
    if fixed_point and any(given.values()):
        raise ParameterError(f"{NO_PENALTY}; " + " and ".join(f"drop --{name.replace('_', '-')}"
                                                                for name, set_ in given.items() if set_))
    changes = {"update": args.update, "penalty": args.penalty or defaults.penalty}
    if args.dynamics is not None and args.dynamics != defaults.dynamics:
        changes["dynamics"] = args.dynamics
        for follower in ("barrier", "guard", "energy_window"):
            changes[follower] = None  # follows the dynamics unless given
        if defaults.tol_energy == FILE_TOL_ENERGY and args.dynamics == "paper":  # a mesh file's defaults
            changes["tol_energy"] = FILE_TOL_ENERGY_PAPER
    for option in ("step", "dt", "damping", "penalty_kappa", "penalty_gain", "spring", "density",
                   "tol_area", "tol_shape", "tol_energy", "max_iter", "barrier", "barrier_threshold",
                   "barrier_gain", "guard", "energy_window", "coarse_degree"):
        value = getattr(args, option)
        if value is not None:
            changes[option] = value
    if args.coarse_degree is None and defaults.coarse_degree \
            and not defaults.with_(**{**changes, "coarse_degree": 0}).guard:
        changes["coarse_degree"] = 0  # the defaults' coarse space follows the guard unless given
    params = defaults.with_(**changes)
    _check_options_apply(args, params)
    return params


def _check_options_apply(args: argparse.Namespace, params: FlattenParams) -> None:
    """Refuse an option given for a part of the run that these parameters leave out (it would be ignored)."""
    if args.step is not None and args.step not in {m.step.value for m in RUN_MODES if m.dynamics == params.dynamics}:
        owner = next(m.dynamics for m in RUN_MODES if m.step.value == args.step)
        raise ParameterError(f"--step {args.step} is a step of the {owner} dynamics, not of the {params.dynamics} "
                             f"dynamics: drop --step, or add --dynamics {owner}")
    if args.dt is not None and params.mode.step is not Step.FIXED:
        has_fixed_step = any(m.dynamics == params.dynamics and m.step is Step.FIXED for m in RUN_MODES)
        raise ParameterError(f"--dt is the size of the {params.dynamics} dynamics' fixed step: add --step "
                             f"{Step.FIXED.value}" if has_fixed_step else
                             f"the {params.dynamics} dynamics takes no --dt (it has no fixed step): drop --dt")
    for option, why in MASS_PARAMETERS.items():  # given at all, even as the default's value
        if getattr(args, option) is not None and not params.mode.has_masses:
            raise ParameterError(why)
    for option in ("penalty_kappa", "penalty_gain"):
        if getattr(args, option) is not None and not params.penalty:
            raise ParameterError(f"--{option.replace('_', '-')} sets the penalty: add --penalty")
    for option in ("barrier_threshold", "barrier_gain"):
        if getattr(args, option) is not None and not params.barrier:
            flag = f"--{option.replace('_', '-')}"
            raise ParameterError(f"{flag} sets the fold barrier, which this run has off: add --barrier (or drop "
                                 f"{flag})")


def strict_json(summary: dict) -> str:
    """One line of standard JSON: each number that is not finite becomes ``null`` and its key (dotted
    for nested objects) is listed under ``non_finite``."""
    non_finite: list[str] = []

    def finite(value, key):
        if isinstance(value, float) and not math.isfinite(value):
            non_finite.append(key)
            return None
        if isinstance(value, dict):
            return {k: finite(v, f"{key}.{k}" if key else str(k)) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [finite(v, f"{key}[{i}]") for i, v in enumerate(value)]
        return value

    cleaned = finite(summary, "")
    if non_finite:
        cleaned["non_finite"] = non_finite
    return json.dumps(cleaned, allow_nan=False)


def input_files(args: argparse.Namespace) -> list[tuple[str, Path | None]]:
    """The files a run reads, as ``(what, path)`` for :func:`sim.outputs.check_distinct`: the mesh, and the
    ``--init`` and ``--formats`` arguments when they name files (not a built-in, a method or a preset)."""
    from golden_model.fixed.formats_set import FormatSet

    init = getattr(args, "init", None)
    formats = getattr(args, "formats", None)
    return [("the mesh", Path(args.mesh)),
            ("--init", Path(init) if init and init not in LAYOUT_METHODS + (AUTO_START,) else None),
            ("--formats", Path(formats) if formats and not FormatSet.names_preset(formats) else None)]
