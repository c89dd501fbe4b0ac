"""A unit's whole input domain through its exported Verilog on Verilator, with no Python per clock.

:func:`sweep_on_verilator` writes the input beats to a file, and ``stream_sweep`` (Verilog made here)
feeds them to the unit's ``i`` stream on consecutive clocks (``valid`` held while beats remain, ``o``'s
``ready`` high), writes every output beat to a file and raises ``done`` after the last. The harness
makes its own clock (Verilator's ``--timing``, as the engine's default build does: ``sim.engine_run``),
so the cocotb bench (``sim.cocotb_benches.sweep``) only resets and waits for ``done``: millions of beats
in seconds, where a bench that drives each clock from Python takes about 50 us a clock. Stalls and
back-pressure are the cocotb benches' part (``sim.cocotb_benches.units``); this is for the sweeps.
"""

from __future__ import annotations

import hashlib
import os
import time

import numpy as np

from golden_model.fixed import FormatSet

from . import cocotb_support
from .cocotb_support import SimulatorError, build_lock, run_bench, verilog_sources
from .engine_run import CLOCK_HALF_PERIOD_NS, TIMING_MAKE_FLAGS, _make_flags, top_ports

__all__ = ["SWEEP_MODULE", "sweep_on_verilator"]

SWEEP_MODULE = "stream_sweep"
INPUTS, OUTPUTS = "sweep_in.hex", "sweep_out.hex"  # in the run's directory (the simulation's working directory)

HARNESS = """// {toplevel} fed {beats} beats from {inputs}, one a clock while it is ready; its outputs to {outputs}
// (sim/stream_sweep.py).
module {module}(output reg clk, input rst, output reg done);
  initial clk = 1'b0;
  always #{half} clk = ~clk;
  reg [{in_width}-1:0] beats [0:{beats}-1];
  initial $readmemh("{inputs}", beats);
  integer out_file;
  initial out_file = $fopen("{outputs}", "w");
  reg [31:0] taken, given;
  wire in_ready, out_valid;
  wire [{out_width}-1:0] out_payload;
  wire [{in_width}-1:0] in_payload = taken < {beats} ? beats[taken[{index_bits}-1:0]] : {in_width}'d0;
  {toplevel} unit(.clk(clk), .rst(rst), .i__valid(!rst && taken < {beats}), .i__payload(in_payload),
    .i__ready(in_ready), .o__valid(out_valid), .o__payload(out_payload), .o__ready(1'b1));
  always @(posedge clk) begin
    if (rst) begin
      taken <= 0; given <= 0; done <= 1'b0;
    end else begin
      if (taken < {beats} && in_ready) taken <= taken + 1;
      if (out_valid) begin
        $fwrite(out_file, "%h\\n", out_payload);
        given <= given + 1;
      end
      if (given == {beats} && !done) begin
        $fflush(out_file);
        done <= 1'b1;
      end
    end
  end
endmodule
"""


def _port_width(verilog: str, module: str, port: str) -> int:
    for _, width, name in top_ports(verilog, module):
        if name == port:
            return int(width[1:].split(":")[0]) + 1 if width else 1
    raise SimulatorError(f"the exported {module} has no port {port}")


def sweep_on_verilator(toplevel: str, fs: FormatSet, beats: np.ndarray) -> np.ndarray:
    """The raw output payloads of ``toplevel`` (a stream unit exported for ``fs``) for ``beats`` (raw input
    payloads, int64), in order: one beat a clock, no stalls, on Verilator. Built once per unit, format set
    and beat count (under ``build/``)."""
    beats = np.asarray(beats, dtype=np.int64)
    exported = verilog_sources(fs)
    source = (exported / f"{toplevel}.v").read_text()
    in_width, out_width = (_port_width(source, toplevel, port) for port in ("i__payload", "o__payload"))
    if in_width > 63 or out_width > 63:
        raise SimulatorError(f"{toplevel}'s payloads ({in_width}, {out_width} bits) are wider than a sweep's 63")
    n = len(beats)
    key = hashlib.sha256(repr((exported.parent.name, toplevel, n, TIMING_MAKE_FLAGS)).encode())  # the export's key
    directory = cocotb_support.BUILD_ROOT / "sweep" / f"{toplevel}-{key.hexdigest()[:12]}"
    with build_lock(directory):
        if not (directory / f"{SWEEP_MODULE}.v").exists():
            (directory / f"{toplevel}.v").write_text(source)
            (directory / f"{SWEEP_MODULE}.v").write_text(HARNESS.format(
                toplevel=toplevel, module=SWEEP_MODULE, beats=n, inputs=INPUTS, outputs=OUTPUTS,
                half=CLOCK_HALF_PERIOD_NS, in_width=in_width, out_width=out_width,
                index_bits=max(1, (n - 1).bit_length())))
    work = directory / "runs" / f"{os.getpid()}-{time.time_ns()}"
    work.mkdir(parents=True)
    digits = -(-in_width // 4)
    (work / INPUTS).write_text("".join(f"{int(b):0{digits}x}\n" for b in beats))
    with _make_flags(TIMING_MAKE_FLAGS):
        run = run_bench("verilator", fs, SWEEP_MODULE, "sweep", {"beats": n},
                        sources=directory, work=work, extra_build_args=("--timing",))
    if (run.tests, run.failed) != (1, 0):
        raise SimulatorError(f"the sweep of {toplevel} did not finish: {run.result or 'see ' + str(work)}")
    lines = (work / OUTPUTS).read_text().split()
    if len(lines) != n:
        raise SimulatorError(f"the sweep of {toplevel} wrote {len(lines)} outputs for {n} beats")
    return np.array([int(x, 16) for x in lines], dtype=np.int64)
