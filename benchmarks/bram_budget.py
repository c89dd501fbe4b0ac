"""The ECP5-85F's block RAMs against the engine's capacity: the largest capacity with and without the guard.

Usage::

    .venv/bin/python benchmarks/bram_budget.py [--start 2048] [--step 256]

Elaborates ``SpringflatEngine`` for ECP5 (``DP16KD`` instances, as ``synth`` maps them; Yosys infers
no other block RAM in it) at ``V / 6V / 2V`` (the entries/vertices ≈ 6, triangles/vertices ≈ 2
ratios of ``DEFAULT_CAPACITY``) in steps of ``--step`` vertices from ``--start``, with the step guard
and without it, up to the first capacity that needs more than the LFE5U-85F's 208. Fitting the block
RAMs is not meeting the clock: that takes a ``synth`` run per seed. docs/synthesis.md quotes the table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity  # noqa: E402
from golden_model.fixed import FormatSet  # noqa: E402
from hdl.dsp import ecp5_instance_count  # noqa: E402
from hdl.engine import SpringflatEngine  # noqa: E402
from sim.synth import TARGETS  # noqa: E402

#: DP16KD block RAMs of the LFE5U-85F.
ECP5_85F_BRAM = TARGETS["ecp5"].capacity["brams"]
ENTRIES_PER_VERTEX = DEFAULT_CAPACITY.entries // DEFAULT_CAPACITY.vertices
TRIANGLES_PER_VERTEX = DEFAULT_CAPACITY.triangles // DEFAULT_CAPACITY.vertices


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--start", type=int, default=DEFAULT_CAPACITY.vertices, help="first vertex capacity")
    parser.add_argument("--step", type=int, default=256, help="vertices from one capacity to the next")
    parser.add_argument("--formats", default="default", help="format set preset")
    args = parser.parse_args(argv)
    if args.start < 2 or args.step < 1:
        parser.error("--start must be at least 2 and --step at least 1")
    fs = FormatSet.preset(args.formats)
    print(f"| build | capacity (V / E / T) | DP16KD | of the 85F's {ECP5_85F_BRAM} |")
    print("|---|---|---|---|")
    for guard in (True, False):
        vertices = args.start
        while True:
            capacity = EngineCapacity(vertices, ENTRIES_PER_VERTEX * vertices, TRIANGLES_PER_VERTEX * vertices, guard)
            brams = ecp5_instance_count(SpringflatEngine(fs, capacity), "DP16KD")
            fits = brams <= ECP5_85F_BRAM
            print(f"| {'with the guard' if guard else 'without the guard'} | {capacity.vertices} / {capacity.entries} / "
                  f"{capacity.triangles} | {brams} | {'fits' if fits else '**does not fit**'} |", flush=True)
            if not fits:
                break
            vertices += args.step


if __name__ == "__main__":
    main()
