"""A folded start untangled against SLIM from Tutte: which start the guarded run does better from.

Usage::

    .venv/bin/python benchmarks/untangled_start.py [--corpus DIR] [--only NAME,...] [--max-vertices 10000]

``--init auto`` starts from SLIM on Tutte's layout where ARAP's layout folds; any other start that folds (``--init
arap``, a layout file) is untangled (:func:`sim.untangle.untangle_layout`). Per corpus disk patch whose ARAP layout
folds (by default every one up to ``--max-vertices``), the whole no-option run (``springflat.flatten``) from each:
``init="arap"`` (ARAP's layout untangled) and ``init="slim"``, with its E_C, folded triangles, iterations and
seconds (start and run). docs/guard.md quotes the table.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from corpus_table import DEFAULT_CORPUS, holed, load_patch, patches  # noqa: E402


def main(argv: list[str] | None = None) -> None:
    import springflat
    from golden_model.mesh import folded_faces
    from sim.layouts import initial_layout

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--corpus", type=Path, default=DEFAULT_CORPUS, help="the built corpus (scripts/corpus.py)")
    parser.add_argument("--only", default=None, help="comma-separated patch names (default: every disk patch)")
    parser.add_argument("--max-vertices", type=int, default=10_000, help="skip larger patches (default 10000)")
    args = parser.parse_args(argv)
    print("| mesh | untangled ARAP: E_C, folded, iterations, seconds | SLIM from Tutte: E_C, folded, iterations, "
          "seconds |")
    print("|---|---|---|")
    for entry in patches(args.corpus, args.only.split(",") if args.only else None, None):
        if holed(entry):
            continue
        mesh = load_patch(entry, args.corpus)
        if mesh.n_vertices > args.max_vertices or not folded_faces(initial_layout(mesh, "arap"), mesh.faces).any():
            continue
        cells = []
        for init in ("arap", "slim"):
            started = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # (the notes: the table says what matters)
                pattern = springflat.flatten(args.corpus / f"{entry['name']}.ply", init=init)
            seconds = time.perf_counter() - started
            cells.append(f"{pattern.shape_error:.3f}, {pattern.folded}, {pattern.iterations}, {seconds:.1f} s")
        print(f"| {entry['name']} | {cells[0]} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
