"""Simulated clock cycles per second of the exported Verilog, on Icarus and Verilator.

Usage: .venv/bin/python benchmarks/bench_rtl_sim.py [--mesh surf2]

For each simulator: the closed-loop flattening (Python controller, a stream
driver that handles every clock) and the simulator alone (the core kept busy
by a constant stream, no Python per clock). The ratio of the two says how much
of the closed loop's time is Python.
"""

from __future__ import annotations

import argparse

from golden_model.builtin import builtin_mesh
from golden_model.fixed import FormatSet
from hdl import SpringflatCore
from sim.cocotb_support import SIMULATORS, run_bench


def closed_loop_config(mesh: str, fs: FormatSet) -> dict:
    """The closed-loop bench's configuration for a built-in mesh with its paper parameters, PCA start."""
    _, p = builtin_mesh(mesh)
    params = dict(spring=p.spring, density=p.density, tol_area=p.tol_area, tol_shape=p.tol_shape,
                  tol_energy=p.tol_energy, max_iter=p.max_iter)
    return {"mesh": mesh, "init": "pca", "params": params, "step_latency": SpringflatCore(fs).step_latency}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mesh", default="surf2")
    parser.add_argument("--formats", default="default")
    args = parser.parse_args()
    fs = FormatSet.load(args.formats)
    config = closed_loop_config(args.mesh, fs)
    rows = {}
    for sim in SIMULATORS:
        loop = run_bench(sim, fs, "springflat_core", "closed_loop", config).result
        raw = run_bench(sim, fs, "springflat_core", "speed", {**config, "cycles": 20000}).result
        rows[sim] = (loop, raw)
    print("| simulator | closed loop: cycles | seconds | cycles/s | simulator alone: cycles/s | Python share |")
    print("|---|---|---|---|---|---|")
    for sim, (loop, raw) in rows.items():
        share = 1 - loop["cycles_per_second"] / raw["cycles_per_second"]
        print(f"| {sim} | {loop['cycles']} | {loop['bench_seconds']:.2f} | {loop['cycles_per_second']:.0f} | "
              f"{raw['cycles_per_second']:.0f} | {100 * share:.0f} % |")
    ratio = rows["verilator"][0]["cycles_per_second"] / rows["icarus"][0]["cycles_per_second"]
    print(f"closed loop, Verilator / Icarus: {ratio:.1f}x")


if __name__ == "__main__":
    main()
