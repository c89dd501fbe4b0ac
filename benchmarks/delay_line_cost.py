"""What the delay lines trade: the force pass and the integrator mapped for ECP5 with and without them.

Usage::

    .venv/bin/python benchmarks/delay_line_cost.py [--formats default]

Maps each unit as the engine builds it (``ForcePass(energy=True, saturations=True)``,
``Integrator(saturations=True)``) with Yosys's ``synth_ecp5``, once with a register per stage and once with
``delay_lines=True`` (``hdl.pipeline.Pipeline.delayed``), and prints the cells that differ: flip-flops
(``TRELLIS_FF``), LUT4 (carry cells apart), the distributed RAM's ``TRELLIS_DPR16X4`` and the multipliers (which
must not change). About a minute. docs/engine.md quotes the table.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from amaranth.hdl import Elaboratable, Module, Signal, Value  # noqa: E402

from golden_model.fixed import FormatSet  # noqa: E402
from hdl import ForcePass, Integrator  # noqa: E402
from hdl.dsp import ECP5  # noqa: E402
from sim.synth import TOOL, error_line, run_tool  # noqa: E402

CELLS = ("TRELLIS_FF", "LUT4", "CCU2C", "TRELLIS_DPR16X4", "MULT18X18D")


class _Top(Elaboratable):
    """The unit as a submodule, so that its constant stream members (always-ready) are not ports."""

    def __init__(self, unit):
        self.unit = unit

    def elaborate(self, platform):
        m = Module()
        m.submodules.unit = self.unit
        return m


def mapped_cells(unit) -> dict[str, int]:
    """``synth_ecp5``'s cell counts for ``unit``, every signal member a port."""
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    from amaranth.back import rtlil

    ports = [Value.cast(v) for _, _, v in unit.signature.flatten(unit) if isinstance(Value.cast(v), Signal)]
    with tempfile.TemporaryDirectory() as tmp:
        Path(tmp, "unit.il").write_text(rtlil.convert(_Top(unit), name="unit", platform=ECP5, ports=ports))
        # YoWASP's Yosys sees the working directory, not absolute paths
        status, log = run_tool(TOOL["yosys"], ["-q", "-p", "read_rtlil unit.il; synth_ecp5 -top unit; "
                                               "tee -q -o stat.txt stat"], Path(tmp), "yosys.log")
        if status:
            sys.exit(f"delay_line_cost: yosys failed: {error_line(log)}")
        stat = Path(tmp, "stat.txt").read_text()
    counts = {name: int(count) for count, name in re.findall(r"^\s+(\d+)\s+(\w+)\s*$", stat, re.M)}
    return {cell: counts.get(cell, 0) for cell in CELLS}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--formats", default="default", help="format set preset")
    args = parser.parse_args(argv)
    fs = FormatSet.preset(args.formats)
    units = {"force pass": lambda lines: ForcePass(fs, energy=True, saturations=True, delay_lines=lines),
             "integrator": lambda lines: Integrator(fs, saturations=True, delay_lines=lines)}
    print(f"| unit ({args.formats}) | build | " + " | ".join(CELLS) + " |")
    print("|---|---|" + "---|" * len(CELLS))
    for name, build in units.items():
        for lines in (False, True):
            cells = mapped_cells(build(lines))
            label = "delay lines" if lines else "registers"
            print(f"| {name} | {label} | " + " | ".join(f"{cells[c]:,}" for c in CELLS) + " |", flush=True)


if __name__ == "__main__":
    main()
