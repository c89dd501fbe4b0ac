"""The board simulated whole on Verilator: :class:`hdl.board.BoardCore` (the UART bridge, the engine, the LEDs:
the board top without its PLL and pins) with the host's end of the serial line, driven by the host driver in
frames (``sim/cocotb_benches/board.py``).

:class:`BoardSimTop` puts a host-side :class:`~hdl.uart_bridge.UartTx` and :class:`~hdl.uart_bridge.UartRx`
(the same divisor) on BoardCore's ``rx``/``tx`` pins, so the bench hands over whole bytes (a few triggers
per byte instead of one per bit) while the line between them is serial, bit by bit; the UARTs themselves are
tested bit by bit against Python in ``tests/hdl/test_uart_bridge.py``. It also counts the engine bus's answers
(``accesses``), so the bench sees that a bad frame makes no bus access.
"""

from __future__ import annotations

import os
import pickle
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from amaranth.hdl import Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import FixedProblem
from golden_model.engine_spec.image import EngineCapacity

from . import cocotb_support
from .cocotb_support import _formats_key, build_lock, run_bench

__all__ = ["BOARD_SIM_MODULE", "SIM_DIVISOR", "SIM_TIMEOUT", "BoardSimTop", "board_sources", "BoardSimRun",
           "run_board_sim"]

BOARD_SIM_MODULE = "springflat_board_sim"
#: Clocks per UART bit in simulation (the board: 100 at 1 Mbaud and 100 MHz); small, so a frame takes few clocks.
SIM_DIVISOR = 4
#: The bridge's inter-byte timeout in simulation (clocks): 20 byte times.
SIM_TIMEOUT = 20 * 10 * SIM_DIVISOR


class BoardSimTop(wiring.Component):
    """BoardCore with the host's UART on its pins and a count of the engine bus's answers.

    Members
    -------
    send_valid, send_data : ``In``; send_ready : ``Out``: a byte to send to the board (host → board).
    recv_valid, recv_data : ``Out``: a byte received from the board, ``recv_valid`` high for one clock.
    accesses : ``Out(32)``: bus cycles answered (``ack`` or ``err``) since reset.
    bridge_busy : ``Out(1)``; leds : the core's LEDs but the PLL's lock (:data:`hdl.board.LEDS`)
    """

    def __init__(self, fs: FormatSet, capacity: EngineCapacity, *, divisor: int = SIM_DIVISOR,
                 timeout: int = SIM_TIMEOUT):
        from hdl.board import BoardCore
        from hdl.uart_bridge import UartRx, UartTx

        self.core = BoardCore(fs, capacity, divisor=divisor, timeout=timeout, heartbeat_bits=8, blink_bits=4)
        self.host_tx, self.host_rx = UartTx(divisor), UartRx(divisor)
        super().__init__({"send_valid": In(1), "send_data": In(8), "send_ready": Out(1), "recv_valid": Out(1),
                          "recv_data": Out(8), "accesses": Out(32), "bridge_busy": Out(1),
                          "leds": Out(len(self.core.leds))})

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = core = self.core
        m.submodules.host_tx = host_tx = self.host_tx
        m.submodules.host_rx = host_rx = self.host_rx
        bus = core.bridge.bus
        m.d.comb += [host_tx.sink.valid.eq(self.send_valid), host_tx.sink.payload.eq(self.send_data),
                     self.send_ready.eq(host_tx.sink.ready), core.rx.eq(host_tx.tx), host_rx.rx.eq(core.tx),
                     host_rx.source.ready.eq(1), self.recv_valid.eq(host_rx.source.valid),
                     self.recv_data.eq(host_rx.source.payload), self.bridge_busy.eq(core.bridge.frames.busy),
                     self.leds.eq(core.leds)]
        count = Signal(32)
        with m.If(bus.cyc & (bus.ack | bus.err)):
            m.d.sync += count.eq(count + 1)
        m.d.comb += self.accesses.eq(count)
        return m


def board_sources(fs: FormatSet, capacity: EngineCapacity) -> Path:
    """Export ``springflat_board_sim.v`` once per format set, capacity and RTL; return its directory."""
    from .export import verilog_of

    here = Path(__file__).resolve()
    key = _formats_key(fs) + "-" + __import__("hashlib").sha256(here.read_bytes()).hexdigest()[:8]
    from .engine_run import capacity_key

    directory = cocotb_support.BUILD_ROOT / key / "board" / capacity_key(capacity)
    target = directory / f"{BOARD_SIM_MODULE}.v"
    with build_lock(directory):
        if not target.exists():
            text = verilog_of(BoardSimTop(fs, capacity), BOARD_SIM_MODULE)
            partial = target.with_suffix(".v.partial")
            partial.write_text(text)
            partial.rename(target)
    return directory


@dataclass(frozen=True, eq=False)
class BoardSimRun:
    result: dict
    positions: np.ndarray | None
    velocities: np.ndarray | None
    passed: bool
    wall_seconds: float


def run_board_sim(problem: FixedProblem, capacity: EngineCapacity, *, work: Path | None = None,
                  log_file: Path | None = None, bad_frames: bool = True) -> BoardSimRun:
    """Build (cached) and run the board bench on Verilator: the self-test read, the bad frames (with
    ``bad_frames``), then ``problem`` through :func:`sim.board_run.run_on_board` over the simulated UART."""
    from .engine_run import _make_flags, build_flags, read_back

    fs = problem.fs
    sources = board_sources(fs, capacity)
    work = Path(work) if work is not None else sources / "runs" / f"{os.getpid()}-{time.time_ns()}"
    work.mkdir(parents=True, exist_ok=True)
    (work / "problem.pkl").write_bytes(pickle.dumps(problem))
    config = {"capacity": [capacity.vertices, capacity.entries, capacity.triangles, capacity.guard],
              "divisor": SIM_DIVISOR, "timeout": SIM_TIMEOUT, "bad_frames": bad_frames}
    flags, make_flags = build_flags("verilator", "gpi-clock")  # the bench starts cocotb's clock
    with _make_flags(make_flags):
        run = run_bench("verilator", fs, BOARD_SIM_MODULE, "board", config, work=work, log_file=log_file,
                        sources=sources, extra_build_args=flags)
    positions, velocities = read_back(work)
    passed = run.tests == 1 and run.failed == 0 and run.result.get("mismatches") == []
    return BoardSimRun(run.result, positions, velocities, passed, run.wall_seconds)
