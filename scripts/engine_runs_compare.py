"""Whole runs on the engine before and after a change meant to keep its behaviour: same clocks, same results.

Runs ``tests/hdl/test_engine.py``'s three runs (paper dynamics with the variable step, the fixed step with barrier
and damping, the momentum dynamics with restarts), each with the entry memory in one bank and in banks of 32
words, on Amaranth's simulator: once on ``hdl/`` and ``golden_model/`` of a git ref (``git archive``), once on
the working tree. Compares per run STATUS.result, ITERATIONS, CYCLES (the clocks from START to done: the
control's timing), SATURATIONS, AREA_ERROR, SHAPE_ERROR, ENERGY and the positions and velocities read back.

A complement to ``scripts/engine_equivalence.py``: it checks reachable behaviour on real runs, not every state.
Run from the repository root (a few minutes per side on a 2-core machine)::

    .venv/bin/python scripts/engine_runs_compare.py --before main

Exit status 0 when every run is identical, 1 if not (the differing runs on stdout).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RUNS = """
import json, sys
sys.path.insert(0, sys.argv[1])
sys.path.insert(1, sys.argv[2])
sys.path.insert(1, sys.argv[2] + "/tests")
sys.path.insert(1, sys.argv[2] + "/tests/hdl")
import hdl.engine
assert hdl.engine.__file__.startswith(sys.argv[1]), hdl.engine.__file__
import test_engine as T
out = {}
for run in T.RUNS:
    image = T.image_of(T.RUNS[run], init=T.INIT.get(run, "tutte"))
    for bank_depth in (T.CAPACITY.entries, 32):
        dut = hdl.engine.SpringflatEngine(T.FS, T.CAPACITY, entry_bank_depth=bank_depth)
        result, rb = T.run_on_engine(dut, image)
        out[f"{run}, entry banks of {bank_depth}"] = {
            "result": result, "iterations": rb.iterations, "cycles": rb.cycles, "saturations": rb.saturations,
            "area_error": rb.area_error, "shape_error": rb.shape_error, "energy": rb.energy,
            "positions": rb.positions.tolist(), "velocities": rb.velocities.tolist()}
json.dump(out, open(sys.argv[3], "w"))
"""


def runs(source: Path, out: Path) -> dict:
    subprocess.run([sys.executable, "-c", RUNS, str(source), str(ROOT), str(out)], check=True, cwd=ROOT)
    return json.loads(out.read_text())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", default="HEAD", help="git ref of the before design (default HEAD)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="engine-runs-") as tmp:
        work = Path(tmp)
        before_src = work / "before_src"
        before_src.mkdir()
        archive = subprocess.run(["git", "archive", args.before, "hdl", "golden_model"], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(before_src)], input=archive, check=True)
        before, after = runs(before_src, work / "before.json"), runs(ROOT, work / "after.json")
    same = True
    for name in before:
        differing = [k for k in before[name] if before[name][k] != after[name][k]]
        same &= not differing
        print(f"{name}: {before[name]['result']} after {before[name]['iterations']} iterations, "
              f"{before[name]['cycles']} cycles before, {after[name]['cycles']} after; "
              + (f"DIFFER: {', '.join(differing)}" if differing else "identical"))
    print("engine_runs_compare:", "PASS" if same else "FAIL")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
