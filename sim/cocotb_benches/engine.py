"""Whole flattenings through the exported ``springflat_engine``, driven over its Wishbone bus.

The host side is the project's own synchronous :class:`~sim.engine_driver.EngineDriver`, run in a
cocotb *bridge* thread (:func:`cocotb.task.bridge`); its bus is :class:`CocotbWishbone`, whose
``read``/``write`` are coroutines made blocking with :func:`cocotb.task.resume`. While the engine
runs, Python waits on the ``irq`` line (one trigger for the whole run, no per-clock Python), so the
simulator runs at its own speed.

The image (``image.npz``: the three memories; the constants in the config) comes from
:func:`golden_model.engine_spec.image.build_image`; the expected results from
:func:`~golden_model.engine_spec.image.run_image` on the same image, compared bit for bit:
positions, velocities, status, iterations, E_S, E_C, energy. The read-back is written to
``readback.npz`` beside the result.
"""

from __future__ import annotations

import dataclasses

import os
import random
import time
from pathlib import Path

import cocotb
import numpy as np
from cocotb.clock import Clock
from cocotb.task import bridge, resume
from cocotb.triggers import FallingEdge, First, RisingEdge, Timer

from golden_model.engine_spec.image import EngineCapacity, EngineImage, run_image
from golden_model.engine_spec.register_map import RegisterMap
from sim.engine_driver import BusError, DriverError, EngineDriver

from .common import CLOCK_NS, formats, load_config, write_result

#: Clocks a bus cycle may take before the initiator gives up (the engine answers in three or four).
BUS_TIMEOUT = 64


class CocotbWishbone:
    """A Wishbone B4 classic initiator on the DUT's ``bus__*`` ports with the driver's blocking
    ``read``/``write`` (:class:`sim.engine_driver.Bus`), for a driver in a bridge thread.

    Signals are driven and sampled at falling edges: the target's outputs are registers, settled
    there. ``wait_states`` > 0 puts a random 0..``wait_states`` idle clocks (``cyc`` low) before each
    cycle. :meth:`wait_irq` is the driver's ``poll``: it sleeps in the simulator until ``irq`` rises.
    """

    def __init__(self, dut, rng: random.Random, wait_states: int = 0):
        self.dut, self.rng, self.wait_states = dut, rng, wait_states
        self.cycles = 0  # bus cycles run
        self.irq_wait_seconds = 0.0  # wall time spent inside the simulator waiting for irq
        self._at_falling_edge = False
        dut.bus__cyc.value = 0
        dut.bus__stb.value = 0
        dut.bus__we.value = 0
        dut.bus__adr.value = 0
        dut.bus__dat_w.value = 0
        dut.bus__sel.value = 0

    def read(self, address: int) -> int:
        return resume(self._cycle)(address, False, 0, 0b1111)

    def write(self, address: int, value: int, sel: int = 0b1111) -> None:
        resume(self._cycle)(address, True, value, sel)

    def wait_irq(self, max_clocks: int = 1 << 30) -> None:
        resume(self._wait_irq)(max_clocks)

    def clocks(self, n: int) -> None:
        """Let ``n`` clocks pass (the bus idle)."""
        resume(self._clocks)(n)

    def reset(self, clocks: int = 3) -> None:
        """Drive ``rst`` for ``clocks`` clocks (a reset in the middle of whatever runs)."""
        resume(self._reset)(clocks)

    async def _cycle(self, address: int, write: bool, data: int, sel: int) -> int | None:
        bus = self.dut
        if not self._at_falling_edge:
            await FallingEdge(bus.clk)
        for _ in range(self.rng.randint(0, self.wait_states) if self.wait_states else 0):
            bus.bus__cyc.value = 0
            bus.bus__stb.value = 0
            await FallingEdge(bus.clk)
        bus.bus__cyc.value = 1
        bus.bus__stb.value = 1
        bus.bus__we.value = int(write)
        bus.bus__adr.value = address
        bus.bus__dat_w.value = data
        bus.bus__sel.value = sel
        for _ in range(BUS_TIMEOUT):
            await FallingEdge(bus.clk)
            ack, err = int(bus.bus__ack.value), int(bus.bus__err.value)
            if ack or err:
                break
        else:
            raise BusError(f"bus timeout: no ack/err for word 0x{address:X} within {BUS_TIMEOUT} clocks")
        bus.bus__cyc.value = 0
        bus.bus__stb.value = 0
        self._at_falling_edge = True
        self.cycles += 1
        if err:
            raise BusError(f"bus error: {'write' if write else 'read'} at word 0x{address:X} answered err")
        if write:
            return None
        value = bus.bus__dat_r.value
        if not value.is_resolvable:  # Icarus is 4-state: an undefined bit is a bug, not a 0
            raise BusError(f"bus read of word 0x{address:X}: dat_r is {value} (not 0/1)")
        return int(value)

    async def _wait_irq(self, max_clocks: int) -> None:
        self._at_falling_edge = False
        if int(self.dut.irq.value):
            return
        started = time.perf_counter()
        await First(RisingEdge(self.dut.irq), Timer(max_clocks * CLOCK_NS, unit="ns"))
        self.irq_wait_seconds += time.perf_counter() - started

    async def _clocks(self, n: int) -> None:
        self._at_falling_edge = False
        await Timer(n * CLOCK_NS, unit="ns")

    async def _reset(self, clocks: int) -> None:
        self._at_falling_edge = False
        await FallingEdge(self.dut.clk)
        self.dut.rst.value = 1
        await Timer(clocks * CLOCK_NS, unit="ns")
        await FallingEdge(self.dut.clk)
        self.dut.rst.value = 0


def load_image(config: dict, work: Path) -> EngineImage:
    capacity = EngineCapacity(**config["capacity"])
    arrays = np.load(work / "image.npz")
    coarse = [arrays["basis"], arrays["matrix"]] if capacity.coarse_degree else []
    return EngineImage(capacity, arrays["nodes"], arrays["entries"], arrays["triangles"],
                       {k: int(v) for k, v in config["constants"].items()}, *coarse)


def compare(got, want, what: str) -> list[str]:
    """Every difference between a read-back and ``run_image``'s result, as readable lines."""
    problems = [f"{what}: {name}: rtl {getattr(got, attr)} golden {getattr(want, name)}"
                for name, attr in (("status", "result"), ("iterations", "iterations"), ("area_error", "area_error"),
                                   ("shape_error", "shape_error"), ("energy", "energy"),
                                   ("saturations", "saturations"))
                if getattr(got, attr) != getattr(want, name)]
    for name in ("positions", "velocities"):
        rtl, golden = getattr(got, name), getattr(want, name)
        if rtl.shape != golden.shape:
            problems.append(f"{what}: {name}: rtl shape {rtl.shape} golden {golden.shape}")
            continue
        for node, axis in np.argwhere(rtl != golden):
            problems.append(f"{what}: node {int(node)} {name[:-1]}.{'xy'[axis]}: rtl {int(rtl[node, axis])} "
                            f"golden {int(golden[node, axis])}")
    return problems


def with_constants(image: EngineImage, **changes: int) -> EngineImage:
    return dataclasses.replace(image, constants={**image.constants, **changes})


@cocotb.test()
async def engine_run(dut):
    """Load, start, wait on irq, read back; compare with run_image bit for bit (and the checks the
    config asks for: every iteration's state by N_max = 1..K runs, a reset mid-run then a clean
    rerun, START with no mesh, a memory access while running, an unmapped access)."""
    config = load_config()
    work = Path(os.environ["SPRINGFLAT_BENCH_RESULT"]).parent
    fs = formats(config)
    image = load_image(config, work)
    rmap = RegisterMap.build(fs, image.capacity)
    rng = random.Random(config.get("seed", 0))
    if not config.get("internal_clock"):  # else the harness makes its own (sim.engine_run.simulation_harness)
        Clock(dut.clk, CLOCK_NS, unit="ns", impl="gpi").start()
    dut.rst.value = 1
    bus = CocotbWishbone(dut, rng, config.get("wait_states", 0))
    await Timer(3 * CLOCK_NS, unit="ns")
    await FallingEdge(dut.clk)
    dut.rst.value = 0
    result: dict = {"checks": {}}
    problems: list[str] = []

    def expected(img: EngineImage):
        want = run_image(img, fs)
        if config.get("broken_expectation"):  # one wrong golden bit: the bench must fail
            want.positions[len(want.positions) // 2, 1] ^= 1
        return want

    def run_once(img: EngineImage, driver: EngineDriver) -> dict:
        driver.load(img)
        waited_before = bus.irq_wait_seconds
        started, window = time.perf_counter(), [time.monotonic()]
        driver.start(irq=True)
        status = driver.wait(poll=bus.wait_irq)
        run_seconds = time.perf_counter() - started
        window.append(time.monotonic())
        readback = driver.read_back()
        irq_seconds = bus.irq_wait_seconds - waited_before
        return {"readback": readback, "status": status, "run_seconds": run_seconds,
                "python_seconds": run_seconds - irq_seconds, "window": window}

    def host() -> None:
        driver = EngineDriver(bus, rmap)
        checks = result["checks"]
        if config.get("no_mesh_check"):
            try:
                driver.start()
                checks["driver_start_without_mesh"] = "accepted"
            except DriverError as exc:
                checks["driver_start_without_mesh"] = str(exc)
            control = rmap.register("CONTROL")
            bus.write(control.offset, next(f for f in control.fields if f.name == "start").mask)
            checks["hardware_start_without_mesh"] = driver.wait(poll=bus.wait_irq)
        if config.get("unmapped_check"):
            end = max(w.base + w.size for w in rmap.windows)
            unused = next(a for a in range(end) if rmap.decode(a) is None)
            try:
                bus.read(unused)
                checks["unmapped_read"] = "answered ack"
            except BusError as exc:
                checks["unmapped_read"] = str(exc)
        for k in range(1, config.get("iteration_checks", 0) + 1):
            step = with_constants(image, max_iter=k)
            got = run_once(step, driver)["readback"]
            problems.extend(compare(got, expected(step), f"N_max {k}"))
        if config.get("reset_after") is not None or config.get("busy_check"):
            driver.load(image)
            driver.start(irq=True)
            if config.get("busy_check"):
                try:
                    bus.read(rmap.window("nodes").address(0))
                    checks["memory_read_while_running"] = "answered ack"
                except BusError as exc:
                    checks["memory_read_while_running"] = str(exc)
            if config.get("reset_after") is not None:
                bus.clocks(config["reset_after"])
                checks["running_before_reset"] = driver._status_fields()[0]
                bus.reset()
                checks["state_after_reset"] = driver._status_fields()[0]
                checks["vertices_after_reset"] = driver.read_value("vertices")
            else:
                driver.wait(poll=bus.wait_irq)
        final = run_once(image, driver)
        readback = final["readback"]
        problems.extend(compare(readback, expected(image), "whole run"))
        iterations = max(readback.iterations, 1)
        result.update({
            "status": final["status"], "iterations": readback.iterations, "cycles": readback.cycles,
            "cycles_per_iteration": readback.cycles / iterations, "area_error": readback.area_error,
            "shape_error": readback.shape_error, "energy": readback.energy, "saturations": readback.saturations,
            "run_seconds": final["run_seconds"], "cycles_per_second": readback.cycles / final["run_seconds"],
            "python_share": final["python_seconds"] / final["run_seconds"],
            "run_window_monotonic": final["window"],  # START .. done, CLOCK_MONOTONIC s (for perf --time)
            "bus_cycles": bus.cycles})
        np.savez(work / "readback.npz", positions=readback.positions, velocities=readback.velocities)

    started = time.perf_counter()
    try:
        await bridge(host)()
    except Exception as exc:  # a refusal or bus error where none was expected: reported, then raised
        problems.append(f"the host stopped: {type(exc).__name__}: {exc}")
        raise
    finally:
        result.update({"mismatches": len(problems), "first_mismatches": problems[:10],
                       "bench_seconds": time.perf_counter() - started})
        write_result(result)
    assert not problems, f"{len(problems)} mismatches; first: {problems[0]}"

