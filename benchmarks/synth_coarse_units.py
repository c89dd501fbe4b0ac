"""Place and route the coarse space's units on their own, as the engine builds them at ``DEFAULT_CAPACITY`` with
``--coarse-degree 3``: Fmax after routing and the critical path of each, in minutes rather than the whole
engine's hour.

Usage: .venv/bin/python benchmarks/synth_coarse_units.py [--units coarse_coefficients,coarse_node,coarse_passes]
       [--degree 3] [--freq 125] [--seed 1] [--router auto] [--out build/synth-coarse-units]

Each unit goes through the serial I/O wrapper (``hdl.io_wrapper.SerialWrapper``: every path to and from its
ports register to register), Yosys ``synth_ecp5`` and nextpnr for the ECP5-85F, as ``springflat synth`` does
with its components (``sim.synth``'s tool steps). The units:

``coarse_coefficients``
    ``hdl.CoarseCoefficients`` with the engine's matrix read latency;
``coarse_node``
    ``hdl.CoarseNode(basis_input=True)``, the per-node unit;
``coarse_passes``
    ``hdl.CoarsePasses``, both with the delay line that joins a node's move to the integrator.

It is not a test (a few minutes a unit); ``docs/guard.md`` holds its measured output.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity
from golden_model.fixed import FormatSet
from sim.clock import ENGINE_TARGET_MHZ, write_clock_constraints
from sim.synth import DEFAULT_ROUTER, ROUTERS, TARGETS, TOOL, error_line, nextpnr_argv, parse_nextpnr_log, run_tool, tool_file


def build(unit: str, fs: FormatSet, capacity: EngineCapacity):
    """The unit as :class:`~hdl.engine.SpringflatEngine` builds it at ``capacity``."""
    from hdl.coarse_coefficients import CoarseCoefficients
    from hdl.coarse_node import CoarseNode
    from hdl.coarse_passes import CoarsePasses
    from hdl.memory_windows import matrix_read_latency

    latency = matrix_read_latency()  # the engine builds a coarse space without pin registers or registered select
    return {"coarse_coefficients": lambda: CoarseCoefficients(fs, capacity.coarse_degree, capacity.vertices,
                                                              read_latency=latency),
            "coarse_node": lambda: CoarseNode(fs, capacity.coarse_degree, capacity.vertices, basis_input=True),
            "coarse_passes": lambda: CoarsePasses(fs, capacity, read_latency=latency)}[unit]()


UNITS = ("coarse_coefficients", "coarse_node", "coarse_passes")


def place_and_route(unit: str, fs: FormatSet, capacity: EngineCapacity, freq: float, seed: int, router: str,
                    out: Path) -> dict:
    """Yosys and nextpnr on ``unit`` inside the serial wrapper; its resources, Fmax and critical path."""
    from hdl.dsp import DspPlatform
    from hdl.io_wrapper import SerialWrapper
    from sim.export import verilog_of

    target = TARGETS["ecp5"]
    top = f"{unit}_pnr"
    (out / f"{top}.v").write_text(verilog_of(SerialWrapper(build(unit, fs, capacity)), top,
                                             DspPlatform(target.dsp_primitives)))
    files = {kind: tool_file(top, "ecp5", kind) for kind in ("ys", "stat.json", "yosys.log", "nextpnr.log",
                                                             "nextpnr.stdout")}
    (out / files["ys"]).write_text(f"read_verilog {top}.v\n{target.yosys_synth.format(top=top)}\n"
                                   f"write_json {tool_file(top, 'ecp5', 'json')}\n"
                                   f"tee -q -o {files['stat.json']} stat -json\n")
    t0 = time.monotonic()
    status, log = run_tool(TOOL["yosys"], ["-s", files["ys"]], out, files["yosys.log"])
    if status != 0:
        raise SystemExit(f"yosys failed on {unit}: {error_line(log)}")
    status, text = run_tool(target.nextpnr, nextpnr_argv(target, top, freq, router, seed), out,
                            files["nextpnr.stdout"])
    log_file = out / files["nextpnr.log"]
    log = log_file.read_text() if log_file.exists() else text
    if status != 0:
        raise SystemExit(f"nextpnr failed on {unit}: {error_line(log)}")
    pnr = parse_nextpnr_log(log)
    used = {k: v["used"] for k, v in pnr["utilisation"].items() if k in ("TRELLIS_FF", "TRELLIS_COMB",
                                                                          "MULT18X18D", "DP16KD")}
    return {"unit": unit, "fmax_mhz": pnr["fmax_mhz"], "timing_met": pnr["timing_met"],
            "critical_path": (pnr["critical_path"] or {}).get("summary"), "used_with_wrapper": used,
            "seconds": round(time.monotonic() - t0, 1)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--units", default=",".join(UNITS), help="comma-separated subset of " + ", ".join(UNITS))
    parser.add_argument("--degree", type=int, default=3)
    parser.add_argument("--freq", type=float, default=ENGINE_TARGET_MHZ)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--router", choices=sorted(ROUTERS), default=DEFAULT_ROUTER,
                        help="nextpnr's router (router2 finishes where the timing-driven router1 keeps ripping up)")
    parser.add_argument("--out", type=Path, default=Path("build/synth-coarse-units"))
    args = parser.parse_args()
    units = args.units.split(",")
    if unknown := [u for u in units if u not in UNITS]:
        parser.error(f"unknown unit {unknown[0]!r} (choose from {', '.join(UNITS)})")
    capacity = EngineCapacity(DEFAULT_CAPACITY.vertices, DEFAULT_CAPACITY.entries, DEFAULT_CAPACITY.triangles,
                              coarse_degree=args.degree)
    args.out.mkdir(parents=True, exist_ok=True)
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    write_clock_constraints(args.out, args.freq)
    for unit in units:
        print(f"{unit}: yosys and nextpnr at {args.freq:g} MHz ...", file=sys.stderr, flush=True)
        print(json.dumps(place_and_route(unit, FormatSet.preset("default"), capacity, args.freq, args.seed,
                                         args.router, args.out)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
