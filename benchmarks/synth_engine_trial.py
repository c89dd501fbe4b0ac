"""A trial place and route of the guarded engine (at ``DEFAULT_CAPACITY`` unless ``--capacity``) built with one of
its build options:
every block RAM input in a register of its own and the banks' select registered (``--registered-select``:
``SpringflatEngine(registered_select=True)``, the build the engine takes by itself above 2,048 vertices), the
block RAM inputs' registers alone (``--pin-registers``), or the force pass's and the integrator's carried values
in delay lines of distributed RAM (``--delay-lines``: ``SpringflatEngine(delay_lines=True)``).

Usage: .venv/bin/python benchmarks/synth_engine_trial.py (--registered-select | --pin-registers | --delay-lines)
       [--capacity V E T] [--seed 1] [--router auto] [--out DIR]

Runs ``springflat synth --target ecp5 --formats default --components springflat_engine --freq 125`` on
that build and prints the engine's Fmax and critical path. It takes 30-60 minutes on this machine, so it
is not a test, and it does not record its row in ``docs/results/synthesis.csv`` (that table is of the
engine as built by default); ``docs/engine-guard-timing.md`` and ``docs/synthesis.md`` hold its measured output.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity
from golden_model.fixed import FormatSet
from sim.clock import ENGINE_TARGET_MHZ
from sim.synth import DEFAULT_ROUTER, ROUTERS, run_synthesis

#: The build options, each a keyword argument of ``SpringflatEngine``.
OPTIONS = ("registered_select", "pin_registers", "delay_lines")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    chosen = parser.add_mutually_exclusive_group(required=True)
    for option in OPTIONS:
        chosen.add_argument(f"--{option.replace('_', '-')}", dest="option", action="store_const", const=option)
    parser.add_argument("--capacity", nargs=3, type=int, metavar=("V", "E", "T"),
                        default=(DEFAULT_CAPACITY.vertices, DEFAULT_CAPACITY.entries, DEFAULT_CAPACITY.triangles))
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--router", choices=sorted(ROUTERS), default=DEFAULT_ROUTER)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    out = args.out or Path(f"build/synth-{args.option.replace('_', '-')}")
    report = run_synthesis(FormatSet.preset("default"), "ecp5", ENGINE_TARGET_MHZ, out, components=["springflat_engine"],
                           seed=args.seed, router=args.router, engine_options={args.option: True},
                           capacity=EngineCapacity(*args.capacity),
                           progress=lambda msg: print(msg, file=sys.stderr, flush=True),
                           command=" ".join(["benchmarks/synth_engine_trial.py", *sys.argv[1:]]))
    engine = report["components"]["springflat_engine"]
    print(json.dumps({"option": args.option, "seed": args.seed, "fmax_mhz": engine.get("fmax_mhz"),
                      "luts": engine["luts"], "ffs": engine["ffs"], "brams": engine["brams"],
                      "critical_path": (engine.get("critical_path") or {}).get("summary")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
