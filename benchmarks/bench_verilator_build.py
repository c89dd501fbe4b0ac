"""What ccache saves on the engine's Verilator builds: two builds into an empty build tree, one after the other.

Usage: .venv/bin/python benchmarks/bench_verilator_build.py [--capacity 256 1536 512]

Every Verilator build compiles Verilator's own runtime (``verilated.cpp``, its VPI, timing and thread
support, cocotb's ``main``) as well as the model. ``sim.cocotb_support.prepare_environment`` sends
those compiles through ccache (``OBJCACHE=ccache``), so the second build of a build tree takes the
runtime from the cache. This script builds ``springflat_engine`` for Verilator twice, for the
``default`` formats and for the same formats with another rounding (another model, the same build
flags), each time running a two-iteration flattening of a 16-vertex dome bit-exact against the golden
model, with the build tree and the ccache store in a fresh temporary directory. It prints each
build's seconds (the whole call less the simulation's own seconds) and ccache's hit count.
The machine is shared: compare the two rows of one run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from golden_model.engine_spec.image import EngineCapacity, build_image
from golden_model.fixed import FormatSet, Rounding
from golden_model.fixed.engine import prepare
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--capacity", type=int, nargs=3, default=(256, 1536, 512), metavar=("V", "E", "T"),
                        help="the engine's capacity (default: 256 1536 512, the tests' size)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="springflat-build-") as scratch:
        # before sim.cocotb_support reads it: the cache starts empty
        os.environ["CCACHE_DIR"] = str(Path(scratch) / "ccache")
        import sim.cocotb_support as cocotb_support
        from sim.engine_run import run_image_on_rtl

        # the build tree in the scratch directory (every build reads it at call time)
        cocotb_support.BUILD_ROOT = Path(scratch) / "cocotb"
        default = FormatSet.preset("default")
        other = Rounding.FLOOR if default.rounding is not Rounding.FLOOR else Rounding.HALF_UP
        capacity = EngineCapacity(*args.capacity)
        mesh = dome_grid(4)
        params = FlattenParams(density="auto", tol_area=0.0, tol_shape=0.0, max_iter=2)
        rows = ["| build | formats | seconds (build) | seconds (simulation) |", "|---|---|---|---|"]
        for k, fs in enumerate((default, default.replace(rounding=other, name=f"default_{other.value}"))):
            image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, fs), capacity)
            started = time.perf_counter()
            run = run_image_on_rtl(image, fs, "verilator")
            total = time.perf_counter() - started
            if not run.passed:
                print(f"build {k + 1}: the run was not bit-exact", file=sys.stderr)
                return 1
            rows.append(f"| {k + 1} | {fs.name} (rounding {fs.rounding.value}) | {total - run.wall_seconds:.1f} | "
                        f"{run.wall_seconds:.1f} |")
        stats = subprocess.run(["ccache", "--print-stats"], capture_output=True, text=True, check=True).stdout
        counts = dict(line.split("\t", 1) for line in stats.splitlines() if "\t" in line)
        print("\n".join(rows))  # after the simulators' own output
        print(f"ccache: {counts.get('direct_cache_hit', '?')} direct hits, "
              f"{counts.get('preprocessed_cache_hit', '?')} preprocessed hits, {counts.get('cache_miss', '?')} misses")
    return 0


if __name__ == "__main__":
    sys.exit(main())
