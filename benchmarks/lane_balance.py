"""How evenly K lanes share a mesh's passes: vertex ``i`` in lane ``i mod K`` (``golden_model.engine_spec.image.entry_lanes``).

Usage::

    .venv/bin/python benchmarks/lane_balance.py [--corpus build/corpus] [--lanes 2 4]

Per mesh of the corpus (``docs/corpus.md``; holes kept) and a 2,025-vertex ``saddle_grid(45)``: each lane's
neighbour entries against an even share (``E/K``), and the three passes' items per iteration with K lanes
against one lane: ``max_k E_k + ⌈T/K⌉ + ⌈V/K⌉`` over ``E + T + V`` (the force pass takes an entry a clock,
the area pass a triangle, the integrate pass a node; a lane pass ends with its longest lane). This counts
items, not the RTL's clocks (each pass's latency and the phase changes come on top: about 2.6 % of an
iteration at 1,024 vertices, ``docs/synthesis.md``). docs/engine.md quotes the summary.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from golden_model.engine_spec.image import LANES, entry_lanes  # noqa: E402
from golden_model.mesh import Holes, Mesh  # noqa: E402
from sim.generate import saddle_grid  # noqa: E402
from sim.mesh_io.load import load_mesh_with_notes  # noqa: E402

DEFAULT_CORPUS = REPO / "build" / "corpus"


def lane_shares(mesh: Mesh, lanes: int) -> tuple[float, float]:
    """``(largest lane's entries / (E/K), items per iteration with K lanes / with one)``."""
    indptr = mesh.rings.indptr
    entries, vertices, triangles = int(indptr[-1]), mesh.n_vertices, mesh.n_faces
    counts = entry_lanes(indptr, lanes)[1]
    one = entries + triangles + vertices
    many = counts.max() + -(-triangles // lanes) + -(-vertices // lanes)
    return counts.max() / (entries / lanes), many / one


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--corpus", type=Path, default=DEFAULT_CORPUS, help="directory of the patches (default %(default)s)")
    parser.add_argument("--lanes", type=int, nargs="+", default=[k for k in LANES if k > 1], choices=LANES[1:])
    args = parser.parse_args(argv)
    paths = sorted(args.corpus.glob("*.ply"))
    if not paths:
        raise SystemExit(f"lane_balance: error: no .ply patches in '{args.corpus}'; build the corpus with "
                         "scripts/corpus.py (docs/corpus.md)")
    meshes = {"saddle_grid(45)": saddle_grid(45)}
    meshes.update((path.stem, load_mesh_with_notes(path, Holes.KEEP)[0]) for path in paths)
    header = ["mesh", "V", "E", "T"] + [f"K={k}: {what}" for k in args.lanes for what in ("largest lane / even", "items vs K=1")]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    shares = {k: [] for k in args.lanes}
    for name, mesh in meshes.items():
        cells = [name, mesh.n_vertices, int(mesh.rings.indptr[-1]), mesh.n_faces]
        for k in args.lanes:
            share = lane_shares(mesh, k)
            shares[k].append(share)
            cells += [f"{share[0]:.4f}", f"{share[1]:.4f}"]
        print("| " + " | ".join(map(str, cells)) + " |", flush=True)
    for k, rows in shares.items():
        a = np.array(rows)
        print(f"K={k} over {len(rows)} meshes: largest lane / even share worst {a[:, 0].max():.4f}, median "
              f"{np.median(a[:, 0]):.4f}; items vs K=1 worst {a[:, 1].max():.4f}, median {np.median(a[:, 1]):.4f}")


if __name__ == "__main__":
    main()
