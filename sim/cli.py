"""The ``springflat`` console command.

Subcommands:

* ``flatten [MESH]``: flatten a mesh (a file or a built-in, default ``surf1``);
* ``paper [--out DIR]``: reproduce the paper's Tables VI–VII and figures.

Bad input never produces a traceback: every user error is one line on
stderr (``springflat: error: ...``) and exit status 2.  A run that diverges
exits with status 3 after writing what was asked for.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from golden_model.builtin import BUILTIN_MESHES, builtin_mesh, is_builtin
from golden_model.layouts import LAYOUT_METHODS, LayoutError, initial_layout
from golden_model.mesh import Mesh, MeshError, load_mesh_with_notes
from golden_model.fixed.engine import FixedPointError, flatten_fixed, load_formats
from golden_model.reference import DYNAMICS, FlattenParams, FlattenResult, ParameterError, flatten

from .outputs import LAYOUT_SUFFIXES, OutputError, check_output_path, write_history, write_layout, write_plot

EXIT_USAGE = 2
EXIT_DIVERGED = 3
USER_ERRORS = (MeshError, LayoutError, ParameterError, OutputError)


class UserError(ValueError):
    """Anything else the user got wrong; one line."""


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error format."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"springflat: error: {message} (see '{self.prog} --help')\n")


def _density(text: str) -> float | str:
    if text == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'auto', got {text!r}") from None


def number_argument(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def integer_argument(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """The options every command that runs the algorithm shares."""
    builtins = ", ".join(BUILTIN_MESHES)
    parser.add_argument("mesh", nargs="?", default="surf1",
                        help=f"OBJ/PLY/OFF/STL file or a built-in mesh ({builtins}); default surf1")
    parser.add_argument("--init", default=None, metavar="|".join(LAYOUT_METHODS) + "|PATH",
                        help="initial layout: tutte, pca, harmonic, lscm, arap (libigl) or a file of V rows "
                             "'x y' / an OBJ (default: pca for built-ins, arap for files)")
    parser.add_argument("--dynamics", choices=DYNAMICS, default=None,
                        help="paper (eqs. 7-9) or momentum (docs/dynamics.md); default: paper for built-ins, "
                             "momentum for files")
    parser.add_argument("--barrier", action=argparse.BooleanOptionalAction, default=None,
                        help="the fold barrier (default: on with momentum, off with paper)")
    parser.add_argument("--barrier-threshold", type=number_argument, default=None,
                        help="barrier threshold kappa in (0, 1]: the fraction of its 3D area below which a "
                             "triangle is pushed back (default 0.5)")
    parser.add_argument("--barrier-gain", type=number_argument, default=None,
                        help="barrier stiffness mu in (0, 16], relative to the springs' C (default 4)")
    parser.add_argument("--step", choices=("variable", "fixed"), default="variable",
                        help="step-size mode (default variable, eqs. 18-20)")
    parser.add_argument("--dt", type=number_argument, default=None, help="fixed step size (default 0.01)")
    parser.add_argument("--update", choices=("jacobi", "sequential"), default="jacobi",
                        help="update order: jacobi (synchronous, default) or sequential (Algorithm 1)")
    parser.add_argument("--damping", type=number_argument, default=None, help="velocity damping gamma in [0, 1) (default 0)")
    parser.add_argument("--penalty", action="store_true", help="apply the overlap penalty (eqs. 10-11)")
    parser.add_argument("--penalty-kappa", type=number_argument, default=None, help="penalty threshold kappa (default 1)")
    parser.add_argument("--penalty-gain", type=number_argument, default=None, help="penalty gain lambda (default 1)")
    parser.add_argument("--spring", type=number_argument, default=None, help="spring constant C (default 0.5)")
    parser.add_argument("--density", type=_density, default=None,
                        help="area density rho or 'auto' = 1/min m_i (default: 2 for built-ins, auto for files)")
    parser.add_argument("--tol-area", type=number_argument, default=None, help="area error tolerance phi_S")
    parser.add_argument("--tol-shape", type=number_argument, default=None, help="shape error tolerance phi_C")
    parser.add_argument("--tol-energy", type=number_argument, default=None, help="relative energy change tolerance epsilon")
    parser.add_argument("--max-iter", type=integer_argument, default=None, help="iteration limit N_max")


#: The stop rule for mesh files: the energy minimum, not the paper's Surf1 tolerances.
FILE_TOL_ENERGY = 1e-7
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
    reached[mesh.boundary_loop] = True
    frontier, depth = reached.copy(), 0
    while not reached.all():
        frontier = (adjacency @ frontier.astype(float) > 0) & ~reached
        reached |= frontier
        depth += 1
    return depth


def resolve_mesh(name: str) -> tuple[Mesh, FlattenParams]:
    """The mesh and its default parameters.

    Built-ins: the paper's sets (paper dynamics, Table II/IV tolerances).  Files: the momentum
    dynamics with the fold barrier, stopped at the energy minimum (relative energy change
    ``FILE_TOL_ENERGY``, no E_S/E_C thresholds) with ``N_max`` sized to the mesh's radius in edges.
    """
    if is_builtin(name) and not Path(name).is_file():
        mesh, paper = builtin_mesh(name)
        return mesh, FlattenParams(spring=paper.spring, density=paper.density, tol_area=paper.tol_area,
                                   tol_shape=paper.tol_shape, tol_energy=paper.tol_energy,
                                   max_iter=paper.max_iter)
    mesh, notes = load_mesh_with_notes(name)
    for note in notes:
        print(f"springflat: note: {mesh.name}: {note}", file=sys.stderr)
    return mesh, FlattenParams(density="auto", dynamics="momentum", tol_area=1.0, tol_shape=1.0,
                               tol_energy=FILE_TOL_ENERGY,
                               max_iter=max(FILE_MIN_ITER, FILE_ITER_PER_EDGE * edge_radius(mesh)))


def default_init(mesh_name: str) -> str:
    """The initial layout when ``--init`` is not given: pca for built-ins (the paper runs), arap for files
    (measured best: the lowest E_C of the five methods and no folds on every shipped scan, docs/dynamics.md)."""
    return "pca" if is_builtin(mesh_name) and not Path(mesh_name).is_file() else "arap"


def params_from_args(args: argparse.Namespace, defaults: FlattenParams) -> FlattenParams:
    """Apply the command-line overrides to ``defaults`` (validated)."""
    changes = {"step": args.step, "update": args.update, "penalty": args.penalty or defaults.penalty}
    if args.dynamics is not None and args.dynamics != defaults.dynamics:
        changes["dynamics"] = args.dynamics
        changes["barrier"] = None  # follows the dynamics unless given
    for option in ("dt", "damping", "penalty_kappa", "penalty_gain", "spring", "density",
                   "tol_area", "tol_shape", "tol_energy", "max_iter", "barrier", "barrier_threshold",
                   "barrier_gain"):
        value = getattr(args, option)
        if value is not None:
            changes[option] = value
    return defaults.with_(**changes)


def _progress(total: int, enabled: bool):
    """A tqdm bar on stderr that appears only for runs longer than ~2 s."""
    from tqdm import tqdm

    return tqdm(total=total, unit="it", delay=2.0, disable=not enabled, file=sys.stderr, leave=False)


def cmd_flatten(args: argparse.Namespace) -> int:
    mesh, defaults = resolve_mesh(args.mesh)
    params = params_from_args(args, defaults)
    for path, what, suffixes in ((args.out, "--out", LAYOUT_SUFFIXES), (args.history, "--history", None),
                                 (args.plot, "--plot", (".png",))):
        if path is not None:
            check_output_path(path, what, suffixes)
    args.init = args.init or default_init(args.mesh)
    positions = initial_layout(mesh, args.init)
    show_progress = sys.stderr.isatty() or not args.json
    if args.engine == "fixed":
        formats = load_formats(args.formats or "default")

        def engine(*run_args, **kw):
            return flatten_fixed(*run_args, fs=formats, **kw)
    elif args.formats is not None:
        raise UserError("--formats applies to --engine fixed")
    else:
        engine = flatten
    with _progress(params.max_iter, show_progress) as bar:
        result = engine(mesh, positions, params, on_iteration=lambda k, m: bar.update(1))
    _write_outputs(args, mesh, result)
    if args.json:
        print(json.dumps({"mesh": mesh.name, "vertices": mesh.n_vertices, "faces": mesh.n_faces, "init": args.init,
                          **result.summary(), "used": _what_was_used(params, args.init, result)[len("springflat: "):]}))
    else:
        final = result.final
        print(f"{mesh.name}: {result.status} after {result.iterations} iterations: "
              f"E_S {result.initial.area_error:.4f} -> {final.area_error:.4f}, "
              f"E_C {result.initial.shape_error:.4f} -> {final.shape_error:.4f}, "
              f"folded {final.folded} (flipped against P0: {final.flipped})"
              + (f", {result.extra['saturations']} saturation events" if result.engine == "fixed" else ""))
        print(_what_was_used(params, args.init, result), file=sys.stderr)
    if result.status == "diverged":
        print(f"springflat: the run diverged at iteration {result.iterations + 1} "
              "(try --damping 0.05 or a smaller --dt); outputs hold the last finite state", file=sys.stderr)
        return EXIT_DIVERGED
    return 0


def _what_was_used(params: FlattenParams, init: str, result: FlattenResult) -> str:
    """One line: dynamics, initial layout, stop rule, and why the run stopped."""
    if params.dynamics == "momentum":
        dynamics = "momentum dynamics" + (f", fold barrier (kappa {params.barrier_threshold:g}, mu "
                                          f"{params.barrier_gain:g})" if params.barrier else ", no barrier")
    else:
        dynamics = (f"paper dynamics, {params.step} step" + (f", damping {params.damping:g}" if params.damping else "")
                    + (f", fold barrier (kappa {params.barrier_threshold:g}, mu {params.barrier_gain:g})"
                       if params.barrier else ""))
    rule = f"relative energy change <= {params.tol_energy:g}"
    if params.tol_area < 1 or params.tol_shape < 1:
        rule = f"E_S <= {params.tol_area:g}, E_C <= {params.tol_shape:g} and {rule}"
    why = {"converged": "the stop rule held", "max-iterations": f"N_max = {params.max_iter} reached",
           "diverged": "a value stopped being finite"}[result.status]
    return f"springflat: used {dynamics}, initial layout {init}; stop rule: {rule}; stopped: {why}"


def _write_outputs(args: argparse.Namespace, mesh: Mesh, result: FlattenResult) -> None:
    if args.out is not None:
        write_layout(args.out, result.positions, mesh.faces, vertices=mesh.vertices)
    if args.history is not None:
        write_history(args.history, result)
    if args.plot is not None:
        write_plot(args.plot, result, mesh.faces, title=f"{mesh.name} ({result.engine} engine)",
                   vertices=mesh.vertices)


def cmd_paper(args: argparse.Namespace) -> int:
    from .paper import reproduce_paper

    report = reproduce_paper(Path(args.out), init=args.init, progress=not args.quiet)
    print(f"wrote {report}")
    return 0


def cmd_verilog(args: argparse.Namespace) -> int:
    from .export import export_verilog

    formats = load_formats(args.formats)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out '{out}' exists and is not a directory")
    interface = export_verilog(formats, out)
    for name, c in interface["components"].items():
        print(f"{out / (name + '.v')}: latency {c['latency']}, II {c['initiation_interval']}")
    print(f"{out / 'interface.md'}, {out / 'interface.json'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="springflat",
        description="Flatten triangle-mesh patches with the variable step-size mass-spring method, "
                    "and verify its fixed-point hardware.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=_Parser)

    p = sub.add_parser("flatten", help="flatten a mesh", description="Flatten a mesh patch (Algorithm 1).")
    add_run_options(p)
    p.add_argument("--engine", choices=("float", "fixed"), default="float",
                   help="float reference (default) or the bit-exact fixed-point golden model")
    p.add_argument("--formats", default=None, metavar="PRESET|FILE",
                   help="fixed-point format set: a preset (default, narrow) or a JSON file (default: default)")
    p.add_argument("--out", type=Path, help="flattened layout: .obj (z = 0, same faces) or .svg")
    p.add_argument("--history", type=Path, help="per-iteration CSV")
    p.add_argument("--plot", type=Path, help="PNG of the layouts and error curves")
    p.add_argument("--json", action="store_true", help="print one JSON object with the results")
    p.set_defaults(func=cmd_flatten)

    p = sub.add_parser("paper", help="reproduce the paper's Tables VI-VII and figures",
                       description="Run Surf1 and Surf2 with fixed and variable steps; write a markdown report.")
    p.add_argument("--out", default="paper-report", help="output directory (default paper-report)")
    p.add_argument("--init", choices=LAYOUT_METHODS, default="pca", help="initial layout (default pca)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=cmd_paper)

    p = sub.add_parser("verilog", help="export the RTL as Verilog with its interface description",
                       description="Write Verilog of every component, ROM contents and interface.md/json.")
    p.add_argument("--formats", default="default", metavar="PRESET|FILE", help="format set (default: default)")
    p.add_argument("--out", required=True, help="output directory")
    p.set_defaults(func=cmd_verilog)

    from .rtl_check import add_parser as add_rtl_check_parser
    from .study import add_parser as add_study_parser
    from .synth import add_parser as add_synth_parser

    add_rtl_check_parser(sub, add_run_options)
    add_study_parser(sub)
    add_synth_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except USER_ERRORS + (UserError,) as exc:
        print(f"springflat: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("springflat: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
