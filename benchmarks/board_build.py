"""The ULX3S-85F bitstream at ``DEFAULT_CAPACITY``: ``springflat synth --board ulx3s-85f``, timed.

Usage: .venv/bin/python benchmarks/board_build.py [--seed 1] [--out build/board-ulx3s-85f]

Runs Yosys, nextpnr-ecp5 and ecppack (YoWASP) on :class:`hdl.board.Ulx3sTop` (the PLL to 100 MHz, the
UART bridge at 1 Mbaud, the LEDs, the engine at ``DEFAULT_CAPACITY``) and prints the report: per clock
the Fmax after routing and the critical path, the device utilisation, the bitstream's size and each
tool's time. It takes tens of minutes on this machine, so it is not a test; ``docs/board.md`` holds its
measured output.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import DEFAULT_CAPACITY
from sim.board_build import board_markdown, run_board_build


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--formats", default="default")
    parser.add_argument("--out", type=Path, default=Path("build/board-ulx3s-85f"))
    args = parser.parse_args()
    fs = FormatSet.preset(args.formats)
    started = time.monotonic()
    command = (f".venv/bin/springflat synth --board ulx3s-85f --formats {args.formats} --seed {args.seed} "
               f"--out {args.out}")
    report = run_board_build(fs, DEFAULT_CAPACITY, args.out, seed=args.seed, command=command,
                             progress=lambda msg: print(f"[{time.monotonic() - started:7.1f} s] {msg}",
                                                        file=sys.stderr, flush=True))
    print(board_markdown(report), end="")
    print(f"whole build {time.monotonic() - started:.0f} s; bitstream {report['bitstream']['bytes']} bytes")
    return 0 if report["timing_met"] else 1


if __name__ == "__main__":
    sys.exit(main())
