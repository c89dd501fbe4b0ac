"""The board simulated whole (``springflat_board_sim``: BoardCore with the host's UART, ``sim/board_sim.py``): the
host driver speaks frames over the serial line.

The host runs in a cocotb *bridge* thread: :class:`~sim.uart_bus.UartBus` on :class:`SimulatedSerial`, a byte
stream whose ``write``/``read`` are coroutines made blocking with :func:`cocotb.task.resume` (``read`` waits in
simulated time, and returns what arrived when its timeout passes, as pyserial does). In order:

1. the self-test a person with a board runs first: ID (MAGIC) and VERSION read over the link;
2. bad frames: a wrong checksum, an overlong length, a truncated frame, a bad command, each answered with its
   error status and with no bus access (the top's ``accesses`` count does not move, and the register the
   frame would have written keeps its value);
3. the flattening (``problem.pkl``) through :func:`sim.board_run.run_on_board`: load (batched frames), START,
   STATUS polls, read-back, compared bit for bit with ``run_image``; the LEDs then show ``done``.

Findings go to the result JSON, the read-back to ``readback.npz``.
"""

from __future__ import annotations

import os
import pickle
import time
from pathlib import Path

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.task import bridge, resume
from cocotb.triggers import Event, FallingEdge, First, RisingEdge, Timer

from golden_model.engine_spec import uart_protocol as protocol
from golden_model.engine_spec.register_map import MAGIC, VERSION, RegisterMap
from golden_model.engine_spec.image import EngineCapacity
from sim.board_run import run_on_board
from sim.uart_bus import UartBus

from .common import CLOCK_NS, load_config, write_result


class SimulatedSerial:
    """pyserial's ``write``/``read`` (with a read timeout in clocks) on the top's ``send_*``/``recv_*``."""

    def __init__(self, dut, timeout_clocks: int):
        self.dut, self.timeout_clocks = dut, timeout_clocks
        self.received = bytearray()
        self.arrived = Event()
        self.bytes_sent = 0
        dut.send_valid.value = 0
        dut.send_data.value = 0

    async def receiver(self) -> None:
        while True:
            await RisingEdge(self.dut.recv_valid)
            await FallingEdge(self.dut.clk)
            self.received.append(int(self.dut.recv_data.value))
            self.arrived.set()

    # ------------------------------------------------------------------ the thread's calls
    def write(self, data: bytes) -> int:
        resume(self._send)(bytes(data))
        return len(data)

    def read(self, n: int) -> bytes:
        return resume(self._receive)(n)

    def reset_input_buffer(self) -> None:
        self.received.clear()

    def clocks(self, n: int) -> None:
        resume(self._clocks)(n)

    def get(self, name: str) -> int:
        return resume(self._get)(name)

    # ------------------------------------------------------------------ coroutines
    async def _send(self, data: bytes) -> None:
        dut = self.dut
        for byte in data:
            await FallingEdge(dut.clk)
            if not int(dut.send_ready.value):
                await RisingEdge(dut.send_ready)
                await FallingEdge(dut.clk)
            dut.send_data.value = byte
            dut.send_valid.value = 1
            await FallingEdge(dut.clk)  # taken at the rising edge between
            dut.send_valid.value = 0
            self.bytes_sent += 1

    async def _receive(self, n: int) -> bytes:
        deadline = cocotb.utils.get_sim_time("ns") + self.timeout_clocks * CLOCK_NS
        while len(self.received) < n:
            left = deadline - cocotb.utils.get_sim_time("ns")
            if left <= 0:
                break
            self.arrived.clear()
            await First(self.arrived.wait(), Timer(left, unit="ns"))
        data = bytes(self.received[:n])
        del self.received[:n]
        return data

    async def _clocks(self, n: int) -> None:
        await Timer(n * CLOCK_NS, unit="ns")

    async def _get(self, name: str) -> int:
        await FallingEdge(self.dut.clk)
        return int(getattr(self.dut, name).value)


def bad_frames(rmap: RegisterMap) -> list[tuple[str, bytes, int]]:
    """(name, bytes, the status expected): each would write MAX_ITER = 0x5A5A if the bridge accepted it."""
    address = rmap.register("MAX_ITER").offset
    good = protocol.encode_write(address, [0x5A5A])
    over = protocol.MAX_WORDS + 1
    body = bytes([protocol.WRITE]) + address.to_bytes(4, "big") + bytes([over]) + bytes(4 * over)
    return [("wrong checksum", good[:-1] + bytes([good[-1] ^ 0x01]), protocol.BAD_CHECKSUM),
            ("overlong length", body + bytes([protocol.crc8(body)]), protocol.BAD_LENGTH),
            ("truncated frame", good[:-3], protocol.TIMEOUT),
            ("bad command", bytes([0x00]) + good[1:], protocol.BAD_COMMAND)]


@cocotb.test()
async def board_run(dut):
    config = load_config()
    work = Path(os.environ["SPRINGFLAT_BENCH_RESULT"]).parent
    problem = pickle.loads((work / "problem.pkl").read_bytes())
    capacity = EngineCapacity(*config["capacity"])
    rmap = RegisterMap.build(problem.fs, capacity)
    Clock(dut.clk, CLOCK_NS, unit="ns", impl="gpi").start()
    dut.rst.value = 1
    port = SimulatedSerial(dut, timeout_clocks=4 * config["timeout"] + 400 * 10 * config["divisor"])
    await Timer(5 * CLOCK_NS, unit="ns")
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    cocotb.start_soon(port.receiver())
    result: dict = {"mismatches": [], "bad_frames": {}}
    problems = result["mismatches"]

    def host() -> None:
        bus = UartBus(port, name="the simulated board")
        ident, version = bus.read(rmap.register("ID").offset), bus.read(rmap.register("VERSION").offset)
        result["self_test"] = {"id": ident, "version_major": version >> 16}
        if (ident, version >> 16) != (MAGIC, VERSION[0]):
            problems.append(f"self-test: ID 0x{ident:08X}, VERSION 0x{version:08X}")
        if config.get("bad_frames"):
            address = rmap.register("MAX_ITER").offset
            for name, frame, want in bad_frames(rmap):
                before_value = bus.read(address)
                before = port.get("accesses")
                port.write(frame)
                answer = port.read(3)
                after = port.get("accesses")
                value = bus.read(address)
                got = protocol.decode_answer(answer).status if len(answer) == 3 else None
                result["bad_frames"][name] = {"answer": answer.hex(), "status": got, "bus_accesses": after - before}
                if got != want:
                    problems.append(f"{name}: answered {answer.hex()} (status {got}), expected status {want}")
                if after != before or value != before_value:
                    problems.append(f"{name}: {after - before} bus accesses, MAX_ITER {before_value} -> {value}")
        started = time.perf_counter()
        run = run_on_board(problem, bus, poll=lambda: port.clocks(2000))
        problems.extend(run.mismatches)
        r = run.readback
        leds = port.get("leds")
        result.update({"status": r.result, "iterations": r.iterations, "cycles": r.cycles,
                       "saturations": r.saturations, "frames": bus.frames, "bytes_sent": port.bytes_sent,
                       "leds": leds, "wall_seconds": time.perf_counter() - started})
        if leds & 0b1110 != 0b1000:  # LEDs 1-3: idle, running, done
            problems.append(f"LEDs read 0b{leds:07b} after the run: expected done (LED 3) alone of idle/running/done")
        np.savez(work / "readback.npz", positions=r.positions, velocities=r.velocities)

    try:
        await bridge(host)()
    except Exception as exc:
        problems.append(f"the host stopped: {type(exc).__name__}: {exc}")
        raise
    finally:
        write_result(result)
    assert not problems, problems[0]
