"""Fixed point against float under the mesh files' default stop rule, with the step guard.

Usage::

    .venv/bin/python benchmarks/guard_fixed_vs_float.py             # generated patches from Tutte
    .venv/bin/python benchmarks/guard_fixed_vs_float.py --fast-subset [--corpus build/corpus]

Default: from Tutte's layout on generated patches (a mesh file's defaults: the momentum dynamics, the barrier,
the guard with the coarse space, the energy change over 10 iterations <= FILE_TOL_ENERGY, up to 3,000
iterations). ``--fast-subset``: the kinds that broke the
unguarded dynamics (issue 25), as a no-option ``springflat flatten`` runs them (the ``auto`` start,
the mesh file's defaults): ``sim.generate.hard_patches()`` and the corpus's ``taco``,
``cone_tip`` and ``cad_sliver`` patches (docs/corpus.md; a missing corpus is skipped with a note).
Per mesh the status, iterations, rolled-back steps and saturation events of each engine and
|ΔE_S|, |ΔE_C|, and whether the row meets issue 25's bar (same status, iterations within ±1,
|ΔE_S|, |ΔE_C| <= 1e-3); a mesh the formats (``--formats``, a preset or a format-set file: default ``default``) cannot hold is
"refused" with the reason; ``--rsqrt-frac-bits N`` resolves the lengths finer than the set does;
``--coarse-degree D`` runs both with the guarded step's coarse space of degree D (``golden_model.coarse``; 0: the
Jacobi step alone; default: the mesh files', ``DEFAULT_COARSE_DEGREE``).
``--perturbed`` adds the float run from ``P0·(1 + 1e-9)`` beside it: how far the float model's own
stopping point moves under a perturbation far below fixed point's rounding. ``--rounded-start`` adds the
float run from the fixed-point model's start, ``P0`` rounded to [position] and mapped back (a change of
about 1e-8 of the layout's size in the default preset): how far the first rounding the fixed-point model
makes moves the float model's stopping point, all later arithmetic in float. docs/guard.md quotes the tables.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from golden_model.fixed import MAX_PRODUCT_WIDTH, FormatSet  # noqa: E402
from golden_model.fixed.engine import flatten_fixed, prepare  # noqa: E402
from golden_model.fixed.measures import FixedPointError  # noqa: E402
from sim.generate import (delaunay_patch, dome_grid, hard_patches, rolled_grid, saddle_grid,  # noqa: E402
                          spherical_cap)
from sim.layouts import start_layout, tutte_layout  # noqa: E402
from golden_model.mesh import Mesh  # noqa: E402
from sim.mesh_io import load_mesh  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
from golden_model.reference import flatten  # noqa: E402
from sim.run_options import FILE_PARAMS, file_defaults  # noqa: E402

MESHES = {
    "cap, 10 rings": lambda: spherical_cap(10),
    "saddle 15×15": lambda: saddle_grid(15),
    "cylinder strip 12×12": lambda: rolled_grid(12, 12, arc_degrees=180)[0],
    "Delaunay patch, 300 points": lambda: delaunay_patch(300),
    "cap, 15 rings": lambda: spherical_cap(15),
    "saddle 31×31": lambda: saddle_grid(31),
    "dome 31×31": lambda: dome_grid(31),
    "cylinder strip 31×31": lambda: rolled_grid(31, 31, arc_degrees=180)[0],
}
#: The corpus kinds of the fast subset (docs/corpus.md).
FAST_KINDS = ("taco", "cone_tip", "cad_sliver")
MANIFEST = REPO / "benchmarks" / "corpus" / "manifest.json"
#: Issue 25's bar for fixed against float.
MAX_ITERATION_GAP = 1
MAX_ERROR_GAP = 1e-3


def wanted(name: str, only: list[str] | None) -> bool:
    return not only or any(name.startswith(prefix) for prefix in only)


def generated_from_tutte(only: list[str] | None) -> Iterator[tuple[str, Mesh, np.ndarray, FlattenParams]]:
    params = FILE_PARAMS.with_(max_iter=3000)
    for name, make in MESHES.items():
        if not wanted(name, only):
            continue
        mesh = make()
        yield name, mesh, tutte_layout(mesh), params


def fast_subset(corpus: Path, only: list[str] | None) -> Iterator[tuple[str, Mesh, np.ndarray, FlattenParams]]:
    """The no-option run's start and parameters on the hard patches and the corpus's fast kinds."""
    meshes: list[tuple[str, Callable[[], Mesh]]] = [(name, (lambda m=m: m)) for name, m in hard_patches().items()]
    entries = [e for e in json.loads(MANIFEST.read_text())["patches"] if e["kind"] in FAST_KINDS]
    missing = [e["name"] for e in entries if not (corpus / f"{e['name']}.ply").is_file()]
    if missing:
        print(f"note: {len(missing)} corpus patches missing from '{corpus}' (docs/corpus.md builds them): "
              "only the generated ones", file=sys.stderr)
    else:
        meshes += [(f"{e['name']} ({e['kind']})", (lambda p=corpus / f"{e['name']}.ply": load_mesh(p)))
                   for e in entries]
    for name, make in meshes:
        if not wanted(name, only):
            continue
        mesh = make()
        yield name, mesh, start_layout(mesh, "auto").positions, file_defaults(mesh)


#: ``--perturbed``: the float run again from ``P0·(1 + PERTURBATION)``, far below the fixed point's rounding.
PERTURBATION = 1e-9


def float_again(a, mesh: Mesh, start: np.ndarray, params: FlattenParams) -> str:
    """The float model from ``start``: its status, iterations and |ΔE_S|, |ΔE_C| against ``a``, as table cells."""
    c = flatten(mesh, start, params)
    return (f" {c.status}, {c.iterations} | {abs(a.final.area_error - c.final.area_error):.1e} | "
            f"{abs(a.final.shape_error - c.final.shape_error):.1e} |")


def row(name: str, mesh: Mesh, p0: np.ndarray, params: FlattenParams, perturbed: bool, rounded_start: bool,
        formats: FormatSet) -> tuple[str, bool]:
    a = flatten(mesh, p0, params)
    extra = ""
    if perturbed:
        extra += float_again(a, mesh, p0 * (1.0 + PERTURBATION), params)
    try:
        if rounded_start:
            problem = prepare(mesh, p0, params, formats)
            extra += float_again(a, mesh, problem.to_float_positions(problem.initial_positions), params)
        b = flatten_fixed(mesh, p0, params, formats)
    except FixedPointError as exc:  # (the rounded start's cells left empty: the formats hold no start)
        extra += " | | |" if rounded_start else ""
        return f"| {name} | {a.status} / refused: {exc} | {a.iterations} / – | | | | | no |{extra}", False
    ds, dc = abs(a.final.area_error - b.final.area_error), abs(a.final.shape_error - b.final.shape_error)
    ok = a.status == b.status and abs(a.iterations - b.iterations) <= MAX_ITERATION_GAP and max(ds, dc) <= MAX_ERROR_GAP
    return (f"| {name} | {a.status} / {b.status} | {a.iterations} / {b.iterations} | "
            f"{a.extra['rejected_steps']} / {b.extra['rejected_steps']} | {b.extra['saturations']} | "
            f"{ds:.1e} | {dc:.1e} | {'yes' if ok else 'no'} |{extra}"), ok


def finer_lengths(fs: FormatSet, rsqrt_frac_bits: int) -> FormatSet:
    """``fs`` with ``rsqrt_frac_bits`` fraction bits of ``rsqrt`` (lengths resolved finer) and ``length_sq``'s
    fraction bits cut, where needed, so that ``length_sq * rsqrt`` stays within the golden model's
    :data:`~golden_model.fixed.MAX_PRODUCT_WIDTH` bits."""
    r, q = fs.rsqrt, fs.length_sq
    keep = min(q.frac_bits, MAX_PRODUCT_WIDTH - q.int_bits - r.int_bits - rsqrt_frac_bits)
    return fs.replace(rsqrt=f"u{r.int_bits}.{rsqrt_frac_bits}", length_sq=f"u{q.int_bits}.{keep}",
                      name=f"{fs.name}, rsqrt u{r.int_bits}.{rsqrt_frac_bits}, length_sq u{q.int_bits}.{keep}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fast-subset", action="store_true",
                        help="the hard patches and the corpus's taco, cone_tip and cad_sliver patches, no-option runs")
    parser.add_argument("--corpus", type=Path, default=REPO / "build" / "corpus", help="corpus directory (default %(default)s)")
    parser.add_argument("--perturbed", action="store_true",
                        help=f"also run float from P0·(1 + {PERTURBATION:g}): how far float moves from itself")
    parser.add_argument("--rounded-start", action="store_true",
                        help="also run float from the fixed-point model's start (P0 rounded to [position]): how far "
                             "that first rounding alone moves float")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="only rows whose name starts with one of these")
    parser.add_argument("--formats", default="default", metavar="PRESET|PATH",
                        help=f"the fixed-point model's format set: a preset ({', '.join(FormatSet.presets())}) or a "
                             "format-set file (default %(default)s)")
    parser.add_argument("--rsqrt-frac-bits", type=int, metavar="N",
                        help="resolve lengths finer: N fraction bits of rsqrt, length_sq's cut to keep their product "
                             f"in {MAX_PRODUCT_WIDTH} bits (the golden model's int64)")
    parser.add_argument("--coarse-degree", type=int, default=FILE_PARAMS.coarse_degree, metavar="D",
                        help="both models with the coarse space of degree D (0: the Jacobi step alone; default "
                             "%(default)s, the mesh files')")
    args = parser.parse_args()
    try:
        formats = FormatSet.load(args.formats)
        if args.rsqrt_frac_bits is not None:
            formats = finer_lengths(formats, args.rsqrt_frac_bits)
    except (OSError, ValueError) as exc:
        parser.error(str(exc))
    rows = fast_subset(args.corpus, args.only) if args.fast_subset else generated_from_tutte(args.only)
    head = "| mesh | status (float / fixed) | iterations | rolled back | saturations | |ΔE_S| | |ΔE_C| | within the bar |"
    if args.perturbed:
        head += f" float from P0·(1 + {PERTURBATION:g}): status, iterations | its |ΔE_S| | its |ΔE_C| |"
    if args.rounded_start:
        head += " float from P0 rounded to [position]: status, iterations | its |ΔE_S| | its |ΔE_C| |"
    print(head)
    print("|---" * head.count(" | ") + "|---|")
    met = total = 0
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for name, mesh, p0, params in rows:
            params = params.with_(coarse_degree=args.coarse_degree)
            line, ok = row(name, mesh, p0, params, args.perturbed, args.rounded_start, formats)
            met, total = met + ok, total + 1
            print(line, flush=True)
    print(f"\n{met} of {total} within the bar (same status, iterations ±{MAX_ITERATION_GAP}, "
          f"|ΔE_S|, |ΔE_C| <= {MAX_ERROR_GAP:g})")


if __name__ == "__main__":
    main()
