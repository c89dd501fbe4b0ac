"""``springflat synth``: the command line of :mod:`sim.synth` (components on a target) and of the board build
(:mod:`sim.board_build`, ``--board``)."""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from pathlib import Path

from golden_model.engine_spec import uart_protocol as protocol
from golden_model.coarse import COARSE_DEGREE_MAX
from golden_model.engine_spec.image import DEFAULT_CAPACITY, LANES

from .clock import ENGINE_TARGET_MHZ
from .run_options import OneOutput, integer_argument, path_argument
from .top_names import COMPONENT_SUMMARIES
from .synth import (DEFAULT_FREQ, DEFAULT_PLACER_TIMING, DEFAULT_ROUTER, ENGINE, PLACER_TIMING, REPORT_FILES, ROUTERS,
                    TARGETS, DoesNotFit, SynthError, build_in_place, report_markdown, run_synthesis)

__all__ = ["add_parser", "cmd_synth"]


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of MHz, got {text!r}") from None
    if not (0 < value <= 1000):
        raise argparse.ArgumentTypeError(f"expected a frequency in (0, 1000] MHz, got {text!r}")
    return value


def _seed(text: str) -> int:
    """nextpnr's ``--seed``: a C ``int``; a value it would refuse after synthesis is refused here."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not -2**31 <= seed < 2**31:
        raise argparse.ArgumentTypeError(f"nextpnr takes a 32-bit seed, -2147483648 to 2147483647, not {seed}")
    return seed


def _component_list(text: str) -> list[str]:
    names = [*COMPONENT_SUMMARIES, ENGINE]
    chosen = [c.strip() for c in text.split(",") if c.strip()]
    for c in chosen:
        if c not in names:
            raise argparse.ArgumentTypeError(f"unknown component {c!r} (choose from {', '.join(names)})")
    if not chosen:
        raise argparse.ArgumentTypeError("expected at least one component")
    return chosen


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``springflat synth`` on an ``add_subparsers()`` object."""
    p = subparsers.add_parser(
        "synth", help="synthesise, place and route the RTL for ECP5 or iCE40 and write a handoff bundle",
        description="Export the Verilog, run Yosys and nextpnr (YoWASP) for ECP5-85F CABGA381 or iCE40 UP5K SG48, "
                    "and report LUT4, flip-flops, DSPs, block RAM, Fmax after routing and the critical path per "
                    "component of --components (by default every component, springflat_core the datapath's "
                    "top among them). springflat_engine (the whole engine behind "
                    "its Wishbone bus, --capacity) is opt-in. Writes the handoff bundle to --out.")
    p.add_argument("--target", choices=tuple(TARGETS),
                   help="ecp5 (LFE5U-85F) or ice40 (UP5K); one of --target and --board is needed")
    p.add_argument("--board", choices=("ulx3s-85f",), default=None,
                   help="instead of --target: the board top (PLL, UART bridge, LEDs, the engine at --capacity) "
                        "to a bitstream with its timing report and pin list (docs/board.md)")
    p.add_argument("--baud", type=integer_argument, default=None,
                   help=f"--board: the UART's rate in bit/s (default {protocol.DEFAULT_BAUD})")
    p.add_argument("--formats", default="default", metavar="PRESET|FILE", help="format set (default: default)")
    p.add_argument("--freq", type=_positive, default=None, metavar="MHZ",
                   help="clock constraint for nextpnr (default "
                        + ", ".join(f"{mhz:g} for {target}" for target, mhz in DEFAULT_FREQ.items())
                        + f"; {ENGINE_TARGET_MHZ:g}, the engine's target, where the components include {ENGINE} on "
                          f"ecp5); with --board the engine's clock from the PLL (default {protocol.ENGINE_CLOCK_HZ / 1e6:g})")
    p.add_argument("--out", type=path_argument, action=OneOutput, default=None,
                   help="bundle directory (default synth-TARGET-PRESET; with --board board-BOARD-PRESET)")
    p.add_argument("--components", type=_component_list, default=None, metavar="LIST",
                   help=f"comma-separated subset of {', '.join([*COMPONENT_SUMMARIES, ENGINE])} (default: all but "
                        f"{ENGINE})")
    p.add_argument("--capacity", nargs=3, type=integer_argument, default=None, metavar=("V", "E", "T"),
                   help="springflat_engine's vertices, neighbour entries and triangles (default: "
                        f"{DEFAULT_CAPACITY.as_option()})")
    p.add_argument("--no-guard", dest="build_guard", action="store_false",
                   help="springflat_engine without the step guard: no guarded mode and fewer block RAMs "
                        "(docs/engine-guard.md)")
    p.add_argument("--lanes", type=integer_argument, choices=LANES, default=1, metavar="K",
                   help="springflat_engine with K datapaths (1, 2 or 4), each on a share of the nodes; built without "
                        "the step guard, so with --no-guard (docs/engine.md, 'Lanes'; default 1)")
    p.add_argument("--coarse-degree", type=integer_argument, choices=range(COARSE_DEGREE_MAX + 1), default=0,
                   metavar="D", help="springflat_engine with the guarded step's coarse space of degree D (its basis "
                                     "and matrix memories and passes, docs/guard.md; default 0: none)")
    p.add_argument("--router", choices=tuple(ROUTERS), default=DEFAULT_ROUTER,
                   help="nextpnr router (default auto: the timing-driven router1; router1-ripup: router1 with its "
                        "timing-driven rip-up, --tmg-ripup; router2 is not timing-driven)")
    p.add_argument("--placer-timing", choices=tuple(PLACER_TIMING), default=DEFAULT_PLACER_TIMING,
                   help="nextpnr's placer: default, or strong (the heap placer's criticality exponent and timing "
                        "weight 4 and 20 instead of 2 and 10: more weight on long routes)")
    p.add_argument("--seed", type=_seed, default=1, help="nextpnr placer seed, a 32-bit integer (default 1)")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cmd_synth)
    return p


def _command_line(args: argparse.Namespace, out: Path) -> str:
    parts = ["springflat", "synth", "--target", args.target, "--formats", args.formats]
    if args.freq is not None:
        parts += ["--freq", f"{args.freq:g}"]
    if args.components:
        parts += ["--components", ",".join(args.components)]
    if args.capacity:
        parts += ["--capacity", *(str(n) for n in args.capacity)]
    if args.coarse_degree:
        parts += ["--coarse-degree", str(args.coarse_degree)]
    if not args.build_guard:
        parts.append("--no-guard")
    if args.lanes != 1:
        parts += ["--lanes", str(args.lanes)]
    if args.router != DEFAULT_ROUTER:
        parts += ["--router", args.router]
    if args.placer_timing != DEFAULT_PLACER_TIMING:
        parts += ["--placer-timing", args.placer_timing]
    if args.seed != 1:
        parts += ["--seed", str(args.seed)]
    parts += ["--out", str(out)]
    return shlex.join(parts)


def cmd_synth(args: argparse.Namespace) -> int:
    from .run_options import load_format_set, strict_json

    from .register_map_export import engine_capacity

    fs = load_format_set(args.formats)
    board = args.board is not None or args.target is None
    if board and args.lanes > 1:  # (before engine_capacity's hint to add --no-guard, which would not help)
        raise SynthError("--lanes applies to --target ecp5 builds of springflat_engine, not yet to --board")
    capacity = engine_capacity(args.capacity, fs, guard=args.build_guard, lanes=args.lanes,
                               coarse_degree=args.coarse_degree)
    if board:
        if args.coarse_degree:
            raise SynthError("--coarse-degree builds springflat_engine with --target ecp5; the board top does not "
                             "take it yet: drop --coarse-degree")
        from .board_build import cmd_board

        return cmd_board(args, fs, capacity)
    if args.baud is not None:
        raise SynthError("--baud sets the board's UART: add --board ulx3s-85f (and drop --target)")
    for given, option in ((args.capacity, "--capacity sizes"), (not args.build_guard, "--no-guard builds"),
                          (args.lanes > 1, "--lanes builds"), (args.coarse_degree, "--coarse-degree builds")):
        if given and ENGINE not in (args.components or ()):
            raise SynthError(f"{option} {ENGINE}: add it to --components")
    out = args.out if args.out else Path(f"synth-{args.target}-{fs.name}")
    start = time.monotonic()

    def progress(msg: str) -> None:
        if not args.quiet:
            print(f"springflat synth [{time.monotonic() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    report = build_in_place(out, args.formats, lambda build, shown: run_synthesis(
        fs, args.target, args.freq, build, components=args.components, progress=lambda msg: progress(shown(msg)),
        router=args.router, seed=args.seed, command=_command_line(args, out), capacity=capacity,
        placer_timing=args.placer_timing), late=REPORT_FILES)
    if args.json:
        print(strict_json(report))
    else:
        print(report_markdown(report), end="")
        print(f"bundle: {Path(out)}/ (synth_report.md, synth_report.json, interface.md, reproduce.sh)")
    if report["does_not_fit"]:
        what = "; ".join(f"{n}: {', '.join(p)}" for n, p in report["does_not_fit"].items())
        raise DoesNotFit(f"does not fit {report['device']}: {what} (synthesis numbers are in {out / 'synth_report.md'})")
    return 0
