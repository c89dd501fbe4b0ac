"""A 20-mesh batch against 20 separate runs of ``springflat flatten`` (issue 28: at most 0.6x).

The meshes are four shipped scans: the three bunny scans, in metres, and ``armadillo_strip``, in model
units read as metres; five copies each, every one written as a DXF and a tiled A4 PDF:

* separate: ``springflat flatten MESH --units m --out DIR/NAME.dxf --out DIR/NAME.pdf``, one after
  the other (what a shell loop does);
* batch: ``springflat flatten MESH ... --units m --out-dir DIR --out .dxf --out .pdf --jobs N``.

Both write the same files; the script checks that they are byte-identical, then prints the wall
times, their ratio and the load average before and after (a busy machine inflates both, the batch
more: it needs the cores free).  ``--large-grid K`` adds one generated dome of K x K vertices (a large scan's
cost, where the workers' memory settings show: Dask's nanny starts its workers with a small malloc trim
threshold, ``sim.workers.undo_dask_malloc_trim``).  Usage::

    .venv/bin/python benchmarks/bench_batch.py [--jobs 2] [--copies 5] [--dask] [--large-grid 150]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANS = ROOT / "tests" / "data" / "scans"
SPRINGFLAT = str(Path(sys.executable).parent / "springflat")
MESHES = ("bunny_face", "bunny_ear", "bunny_back", "armadillo_strip")


def timed(command: list[str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"failed ({done.returncode}): {' '.join(command)}\n{done.stderr}")
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2, help="batch workers (default 2)")
    parser.add_argument("--copies", type=int, default=5, help="copies of each scan (default 5: 20 meshes)")
    parser.add_argument("--dask", action="store_true", help="also time the batch on a Dask LocalCluster")
    parser.add_argument("--large-grid", type=int, default=0, metavar="K",
                        help="add a generated dome of K x K vertices (default: none)")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        tmp = Path(tmp)
        (tmp / "in").mkdir()
        meshes = []
        for copy in range(args.copies):
            for name in MESHES:
                path = tmp / "in" / f"{name}_{copy}.obj"
                shutil.copyfile(SCANS / f"{name}.obj", path)
                meshes.append(path)
        if args.large_grid:
            from sim.generate import dome_grid
            from sim.mesh_io import save_obj

            large = dome_grid(args.large_grid)
            meshes.append(tmp / "in" / f"dome_{args.large_grid}.obj")
            save_obj(meshes[-1], large.vertices, large.faces)
        load_before = os.getloadavg()
        separate_dir = tmp / "separate"
        separate_dir.mkdir()
        separate = sum(timed([SPRINGFLAT, "flatten", str(m), "--units", "m", "--out",
                              str(separate_dir / f"{m.stem}.dxf"), "--out", str(separate_dir / f"{m.stem}.pdf")])
                       for m in meshes)
        batch = timed([SPRINGFLAT, "flatten", *map(str, meshes), "--units", "m", "--out-dir", str(tmp / "batch"),
                       "--out", ".dxf", "--out", ".pdf", "--jobs", str(args.jobs)])
        dask = None
        if args.dask:
            dask = timed([SPRINGFLAT, "flatten", *map(str, meshes), "--units", "m", "--out-dir", str(tmp / "dask"),
                          "--out", ".dxf", "--out", ".pdf", "--jobs", str(args.jobs), "--scheduler", "local"])
        load_after = os.getloadavg()
        for folder in ["batch"] + (["dask"] if args.dask else []):
            for path in sorted(separate_dir.iterdir()):
                if path.read_bytes() != (tmp / folder / path.name).read_bytes():
                    raise SystemExit(f"{folder}/{path.name} differs from the separate run's")
    large = f" and a {args.large_grid} x {args.large_grid} dome" if args.large_grid else ""
    print(f"{len(meshes)} meshes ({', '.join(MESHES)} x {args.copies}{large}), .dxf + .pdf each, on "
          f"{os.cpu_count()} cores")
    print(f"separate runs:            {separate:7.1f} s")
    print(f"batch, {args.jobs} workers:        {batch:7.1f} s   ratio {batch / separate:.2f}")
    if dask is not None:
        print(f"batch, Dask LocalCluster: {dask:7.1f} s   ratio {dask / separate:.2f}")
    print("outputs byte-identical: yes")
    print(f"load average (1, 5, 15 min): before {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}, "
          f"after {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f}")


if __name__ == "__main__":
    main()
