"""Where the engine's flip-flops are: flip-flop bits per unit of ``SpringflatEngine``, with and without the guard.

Usage::

    .venv/bin/python benchmarks/ff_budget.py [--capacity V E T] [--formats default] [--delay-lines]

Elaborates the engine for ECP5 (``DP16KD``, ``MULT18X18D`` and the ``keep`` pin registers as ``synth`` makes
them), converts it to RTLIL and has Yosys count every flip-flop bit per module after ``proc`` and
``opt_clean``, before ``synth_ecp5``'s optimisation, which merges and removes about a tenth (at 3072 /
18432 / 6144: 63,012 and 42,339 flip-flops after it, against 68,532 and 46,937 here). Units are the
engine's submodules with their own submodules folded in. About twenty seconds per build. The last row
adds a second lane's units (:data:`LANE_UNITS`) to the total: a sum of the measured units, not a build.
``--delay-lines`` builds the force pass and the integrator with their delay lines (``SpringflatEngine(delay_lines=True)``,
a build option).
docs/synthesis.md quotes the table: the guarded engine above ``DEFAULT_CAPACITY`` is placed short of
its clock with three-quarters of the 85F's flip-flops in use, and with three-fifths with the delay lines.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity  # noqa: E402
from golden_model.fixed import FormatSet  # noqa: E402
from hdl.dsp import ECP5  # noqa: E402
from hdl.engine import SpringflatEngine  # noqa: E402
from sim.synth import TARGETS, TOOL  # noqa: E402
from sim.synth import error_line, run_tool  # noqa: E402

TOP = "springflat_engine"
#: The units a second lane (issue 29's ``lanes = 2``) would hold again: its force pass, area unit and
#: integrator, and with the guard its certificate, scatters and commit (each lane certifies its share of
#: the triangles and commits its share of the nodes).
LANE_UNITS = ("force", "area", "integrator", "guard")
#: Flip-flops (TRELLIS_FF) of the LFE5U-85F.
ECP5_85F_FF = TARGETS["ecp5"].capacity["ffs"]
#: A flip-flop cell of Yosys's ``stat -width`` (``$dff_66``, ``$sdffe_1``, …) or a kept ``TRELLIS_FF``.
FF_CELL = re.compile(r"^\s+(\d+)\s+(?:\$\w*dff\w*_(\d+)|(TRELLIS_FF))\s*$", re.M)


def ff_bits_per_module(stat: str) -> dict[str, int]:
    """Flip-flop bits of each module in the text of Yosys's ``stat -width`` (the module's own cells)."""
    bits = {}
    for name, body in re.findall(r"^=== (\S+) ===$(.*?)(?=^=== )", stat + "\n=== end ===", re.M | re.S):
        bits[name] = sum(int(count) * (int(width) if width else 1) for count, width, _ in FF_CELL.findall(body))
    return bits


def ff_bits_per_unit(fs: FormatSet, capacity: EngineCapacity, delay_lines: bool = False) -> dict[str, int]:
    """Flip-flop bits per unit (the engine's first level of submodules, ``(engine)`` for its own)."""
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    from amaranth.back import rtlil

    with tempfile.TemporaryDirectory() as tmp:
        il, stat = Path(tmp) / "engine.il", Path(tmp) / "stat.txt"
        engine = SpringflatEngine(fs, capacity, delay_lines=delay_lines)
        il.write_text(rtlil.convert(engine, name=TOP, platform=ECP5))
        # YoWASP's Yosys sees the working directory, not absolute paths
        status, log = run_tool(TOOL["yosys"], ["-q", "-p", f"read_rtlil {il.name}; hierarchy -top {TOP}; proc; "
                                               f"opt_clean; tee -q -o {stat.name} stat -width"], Path(tmp), "yosys.log")
        if status:
            sys.exit(f"ff_budget: yosys failed: {error_line(log)}")
        modules = ff_bits_per_module(stat.read_text())
    units: dict[str, int] = defaultdict(int)
    for name, bits in modules.items():
        path = name.split(".")
        units[path[1].split("$")[0] if len(path) > 1 else "(engine)"] += bits
    return dict(units)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--capacity", nargs=3, type=int, metavar=("V", "E", "T"),
                        default=(DEFAULT_CAPACITY.vertices, DEFAULT_CAPACITY.entries, DEFAULT_CAPACITY.triangles))
    parser.add_argument("--formats", default="default", help="format set preset")
    parser.add_argument("--delay-lines", action="store_true", help="the datapaths' delay lines (a build option)")
    args = parser.parse_args(argv)
    fs = FormatSet.preset(args.formats)
    builds = {guard: ff_bits_per_unit(fs, EngineCapacity(*args.capacity, guard), args.delay_lines)
              for guard in (True, False)}
    units = sorted(builds[True], key=lambda u: -builds[True][u])
    print(f"| unit | with the guard | without the guard |  (capacity {' / '.join(map(str, args.capacity))})")
    print("|---|---|---|")
    for unit in units:
        print(f"| `{unit}` | {builds[True][unit]:,} | {builds[False].get(unit, 0):,} |")
    totals = {guard: sum(bits.values()) for guard, bits in builds.items()}
    print(f"| total | {totals[True]:,} ({totals[True] / ECP5_85F_FF:.0%} of the 85F's {ECP5_85F_FF:,}) | "
          f"{totals[False]:,} ({totals[False] / ECP5_85F_FF:.0%}) |")
    lanes = {guard: totals[guard] + sum(bits.get(unit, 0) for unit in LANE_UNITS) for guard, bits in builds.items()}
    print(f"| two lanes (the total and the lane's units again) | {lanes[True]:,} ({lanes[True] / ECP5_85F_FF:.0%}) | "
          f"{lanes[False]:,} ({lanes[False] / ECP5_85F_FF:.0%}) |")


if __name__ == "__main__":
    main()
