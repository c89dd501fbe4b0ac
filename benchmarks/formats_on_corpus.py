"""Which preset format sets hold the corpus, and how close each one's run comes to the float reference's.

Usage::

    .venv/bin/python benchmarks/formats_on_corpus.py [--presets default wide] [--only NAME ...] [--jobs 2]

Per corpus patch (docs/corpus.md; ``scripts/corpus.py`` builds ``build/corpus``), the no-option run's start
(``auto``) and the mesh file's defaults, as ``springflat flatten MESH`` takes them: the float reference's status,
iterations and E_C, then for each preset the fixed-point model's status, iterations, E_C, folded triangles and
saturation events, or the one-line refusal ("refused: ..."). The summary counts, per preset, the patches it
holds, those it runs without a saturation event, and the largest |ΔE_S|, |ΔE_C| against float.
docs/fixed-point.md quotes the table.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from guard_fixed_vs_float import MANIFEST, file_defaults  # noqa: E402

from golden_model.fixed import FormatSet  # noqa: E402
from golden_model.fixed.engine import flatten_fixed  # noqa: E402
from golden_model.fixed.measures import FixedPointError  # noqa: E402
from sim.layouts import start_layout  # noqa: E402
from corpus_table import load_patch  # noqa: E402
from sim.outputs import OutputError, check_output_path, write_text_file  # noqa: E402
from golden_model.reference import flatten  # noqa: E402


def runs(entry: dict, corpus: Path, presets: tuple[str, ...]) -> dict:
    """The float run and one fixed-point run per preset of the manifest's patch ``entry`` (plain values)."""
    mesh = load_patch(entry, corpus)
    params = file_defaults(mesh)
    p0 = start_layout(mesh, "auto").positions
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        ref = flatten(mesh, p0, params)
        out = {"name": entry["name"], "vertices": mesh.n_vertices, "float": _summary(ref)}
        for preset in presets:
            try:
                result = flatten_fixed(mesh, p0, params, FormatSet.preset(preset))
            except FixedPointError as exc:
                out[preset] = {"refused": str(exc)}
                continue
            out[preset] = {**_summary(result), "saturations": result.extra["saturations"],
                           "d_area": abs(result.final.area_error - ref.final.area_error),
                           "d_shape": abs(result.final.shape_error - ref.final.shape_error)}
    return out


def _summary(result) -> dict:
    final = result.final
    return {"status": result.status, "iterations": result.iterations, "area_error": float(final.area_error),
            "shape_error": float(final.shape_error), "folded": int(final.folded)}


def cell(run: dict) -> str:
    if "refused" in run:
        return f"refused: {run['refused']}"
    return (f"{run['status']}, {run['iterations']}, {run['shape_error']:.4f}, {run['folded']}, "
            f"{run['saturations']:,}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", nargs="+", default=FormatSet.presets(), choices=FormatSet.presets())
    parser.add_argument("--corpus", type=Path, default=REPO / "build" / "corpus",
                        help="corpus directory (default %(default)s)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="only these patches")
    parser.add_argument("--jobs", type=int, default=1, help="patches run at once (default 1)")
    parser.add_argument("--json", type=Path, metavar="FILE", help="also write the rows as JSON")
    args = parser.parse_args()
    if args.json is not None:  # before the runs
        try:
            check_output_path(args.json, "--json", typed=False)
        except OutputError as exc:
            parser.error(str(exc))
    entries = [e for e in json.loads(MANIFEST.read_text())["patches"] if not args.only or e["name"] in args.only]
    names = [e["name"] for e in entries]
    missing = [n for n in names if not (args.corpus / f"{n}.ply").is_file()]
    if missing:
        raise SystemExit(f"{len(missing)} corpus patches missing from '{args.corpus}' (docs/corpus.md builds them)")
    presets = tuple(args.presets)
    print("| patch | vertices | float: status, iterations, E_C | "
          + " | ".join(f"`{p}`: status, iterations, E_C, folded, saturations" for p in presets) + " |")
    print("|---|---|---|" + "---|" * len(presets))
    rows = []
    with ProcessPoolExecutor(args.jobs) as pool:
        for row in pool.map(runs, entries, [args.corpus] * len(entries), [presets] * len(entries)):
            rows.append(row)
            f = row["float"]
            print(f"| {row['name']} | {row['vertices']:,} | {f['status']}, {f['iterations']}, {f['shape_error']:.4f} | "
                  + " | ".join(cell(row[p]) for p in presets) + " |", flush=True)
    print()
    for p in presets:
        held = [r[p] for r in rows if "refused" not in r[p]]
        clean = [r for r in held if r["saturations"] == 0]
        folded = sum(r["folded"] > 0 for r in held)
        worst = max((max(r["d_area"], r["d_shape"]) for r in held), default=float("nan"))
        print(f"`{p}`: holds {len(held)} of {len(rows)}; {len(clean)} without a saturation event; "
              f"{folded} end folded; largest |ΔE_S|, |ΔE_C| against float {worst:.1e}")
    if args.json:
        write_text_file(args.json, json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
