"""A trial place and route: the guarded engine at ``DEFAULT_CAPACITY`` with every block RAM input in a
register of its own and the banks' select registered (``SpringflatEngine(registered_select=True)``, the
build the engine takes by itself above 2,048 vertices), or with ``--pin-registers`` the block RAM inputs'
registers alone (``SpringflatEngine(pin_registers=True)``).

Usage: .venv/bin/python benchmarks/synth_registered_select_trial.py [--pin-registers] [--seed 1] [--out DIR]

Runs ``springflat synth --target ecp5 --formats default --components springflat_engine --freq 125`` on
that build and prints the engine's Fmax and critical path. It takes 30-40 minutes on this machine, so it
is not a test, and it does not record its row in ``docs/results/synthesis.csv`` (that table is of the
engine as built by default); ``docs/engine-guard.md`` holds its measured output.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from golden_model.fixed import FormatSet
from sim.clock import ENGINE_TARGET_MHZ
from sim.synth import run_synthesis


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("build/synth-registered-select"))
    parser.add_argument("--pin-registers", action="store_true",
                        help="the block RAM inputs' registers alone, without the registered select")
    args = parser.parse_args()
    options = {"pin_registers": True} if args.pin_registers else {"registered_select": True}
    report = run_synthesis(FormatSet.preset("default"), "ecp5", ENGINE_TARGET_MHZ, args.out, components=["springflat_engine"],
                           seed=args.seed, engine_options=options,
                           progress=lambda msg: print(msg, file=sys.stderr, flush=True),
                           command=" ".join(["benchmarks/synth_registered_select_trial.py", *sys.argv[1:]]))
    engine = report["components"]["springflat_engine"]
    print(json.dumps({"seed": args.seed, "fmax_mhz": engine.get("fmax_mhz"), "luts": engine["luts"],
                      "ffs": engine["ffs"], "brams": engine["brams"],
                      "critical_path": (engine.get("critical_path") or {}).get("summary")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
