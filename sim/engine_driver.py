"""Host driver of ``SpringflatEngine``, bus-agnostic, and a pure-Python model of the engine on its bus.

:class:`EngineDriver` turns a :class:`~golden_model.engine_spec.image.EngineImage` (the golden
model's host scaling, packed by :func:`~golden_model.engine_spec.image.build_image`) into bus
writes, starts the engine, waits for it and reads the layout and the result registers back.  The
bus is anything with ``read(word_address) -> int`` and ``write(word_address, value)`` that raises
:class:`BusError` when the engine answers ``err``: :class:`ModelBus` here (the register map, the
memories and :func:`~golden_model.engine_spec.image.run_image` behind it), a cocotb Wishbone
master later.

Every refusal is one line: :class:`DriverError` (a bad call: no engine at the bus, an image for
another capacity or format set, start with no mesh loaded, a wait that never ends) or
:class:`BusError` (the engine's ``err``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import (EngineImage, ImageRunResult, MemoryLayout, constant_fault,
                                            lane_entry_counts, lane_rows, run_constant_fields, run_image)
from golden_model.engine_spec.register_map import MAGIC, STATES, VERSION, BitField, Register, RegisterMap, format_hash

__all__ = ["EngineError", "BusError", "DriverError", "Bus", "EngineReadBack", "EngineDriver", "ModelBus"]

WORD_MASK = 0xFFFF_FFFF
FULL_SEL = 0b1111


class EngineError(Exception):
    """Anything the driver refuses or the engine answers with ``err``; the message is one line."""


class BusError(EngineError):
    """The engine answered ``err``."""


class DriverError(EngineError):
    """A call the driver refuses."""


class Bus(Protocol):
    def read(self, address: int) -> int: ...

    def write(self, address: int, value: int) -> None: ...


def _field(register: Register, name: str) -> BitField:
    return next(f for f in register.fields if f.name == name)


def _get(register: Register, word: int, name: str) -> int:
    f = _field(register, name)
    return (word & f.mask) >> f.lsb


def _put(register: Register, word: int, name: str, value: int) -> int:
    f = _field(register, name)
    return (word & ~f.mask) | ((value << f.lsb) & f.mask)


@dataclass(frozen=True, eq=False)
class EngineReadBack:
    """The engine after a run: STATUS, the result registers and the node memory (raw)."""

    state: str
    result: str
    iterations: int
    saturations: int
    area_error: int  # E_S raw [error]
    shape_error: int  # E_C raw [error]
    energy: int  # energy_raw
    cycles: int
    positions: np.ndarray  # (V, 2) raw [position]
    velocities: np.ndarray  # (V, 2) raw [velocity]


class EngineDriver:
    """Loads, starts, waits for and reads back one engine described by ``register_map``."""

    def __init__(self, bus: Bus, register_map: RegisterMap):
        self.bus, self.map = bus, register_map
        self._status, self._control = register_map.register("STATUS"), register_map.register("CONTROL")

    # ------------------------------------------------------------------ registers
    def read_value(self, value: str) -> int:
        slices = self.map.value_fields(value)
        return self.map.decode_value(value, {r.offset: self.bus.read(r.offset) for r, _ in slices})

    def _status_fields(self) -> tuple[str, str]:
        word = self.bus.read(self._status.offset)
        return STATES[_get(self._status, word, "state")], _field(self._status, "result").codes[
            _get(self._status, word, "result")]

    def identify_engine(self) -> None:
        """Check that the bus holds a springflat engine of this map's major version and format set (the
        registers that say so sit at the same addresses whatever the capacity)."""
        ident = self.read_value("id")
        if ident != MAGIC:
            raise DriverError(f"no springflat engine on this bus: ID reads 0x{ident:08X}, expected 0x{MAGIC:08X}")
        major = self.read_value("version_major")
        if major != VERSION[0]:
            raise DriverError(f"the engine's register map is version {major}.x; this driver speaks {VERSION[0]}.x")
        if (built := self.read_value("format_hash")) != self.map.format_hash:
            preset = next((name for name in FormatSet.presets() if format_hash(FormatSet.preset(name)) == built), None)
            raise DriverError(f"the engine was built for another format set than '{self.map.formats}' (FORMAT_HASH "
                              "differs): " + (f"the '{preset}' preset's: give --formats {preset}" if preset else
                                              "no preset's: give --formats with the file it was built from"))

    def identify(self) -> None:
        """Check that the bus holds this map's engine: magic, major version, format set, capacity."""
        self.identify_engine()
        built = tuple(self.read_value(f"cap_{w}") for w in ("vertices", "entries", "triangles"))
        mapped = (self.map.capacity.vertices, self.map.capacity.entries, self.map.capacity.triangles)
        if built != mapped:
            raise DriverError(f"the engine holds {built[0]} vertices / {built[1]} entries / {built[2]} triangles; "
                              f"the register map says {mapped[0]} / {mapped[1]} / {mapped[2]}")
        guard = bool(self.read_value("feature_guard"))
        if guard != self.map.capacity.guard:
            raise DriverError(f"the engine was built {'with' if guard else 'without'} the step guard; the register "
                              f"map says {'with' if self.map.capacity.guard else 'without'}")
        if (lanes := self.read_value("feature_lanes")) != self.map.capacity.lanes:
            raise DriverError(f"the engine was built with {lanes} lane(s); the register map says {self.map.capacity.lanes}")
        if (degree := self.read_value("feature_coarse")) != self.map.capacity.coarse_degree:
            raise DriverError(f"the engine was built with a coarse space of degree {degree} (0: none); the register map "
                              f"says {self.map.capacity.coarse_degree}")

    # ------------------------------------------------------------------ the run
    def load(self, image: EngineImage, memories: tuple[str, ...] | None = None) -> None:
        """Write the three memories and the run constants (the engine must not be running).

        ``memories`` names the memories to write (default all three: ``nodes``, ``entries``,
        ``triangles``). A run writes only the node memory, so the same image runs again after
        ``load(image, memories=("nodes",))``: on a typical mesh 5 of about 27 words per vertex."""
        self.identify()
        known = image.memories()
        if memories is not None and not set(memories) <= set(known):
            raise DriverError(f"no memory named {sorted(set(memories) - set(known))[0]!r} "
                              f"(the engine has {', '.join(known)})")
        if image.capacity != self.map.capacity:
            c, e = (f"{c.vertices}/{c.entries}/{c.triangles}{'' if c.guard else ' without the guard'}"
                    f"{'' if c.lanes == 1 else f' in {c.lanes} lanes'}"
                    f"{f' with a coarse space of degree {c.coarse_degree}' if c.coarse_degree else ''}"
                    for c in (image.capacity, self.map.capacity))
            raise DriverError(f"the image was built for capacity {c} (vertices/entries/triangles); the engine has {e}")
        if self._status_fields()[0] == "running":
            raise DriverError("the engine is running: abort() or wait() before load()")
        for name, words in known.items():
            if memories is not None and name not in memories:
                continue
            window = self.map.window(name)
            for index, row in zip(image.rows(name), words):
                for k, word in enumerate(row):
                    self.bus.write(window.address(int(index), k), int(word))
        for offset, word in sorted(self.map.encode(image.constants).items()):
            self.bus.write(offset, word)

    def start(self, irq: bool = False) -> None:
        """Start a run on what is loaded (refused when nothing is: VERTICES reads 0)."""
        state, _ = self._status_fields()
        if state == "running":
            raise DriverError("the engine is already running")
        if self.read_value("vertices") == 0:
            raise DriverError("no mesh loaded: call load(image) before start()")
        word = _put(self._control, 0, "irq_enable", int(irq))
        self.bus.write(self._control.offset, _put(self._control, word, "start", 1))

    def abort(self) -> None:
        self.bus.write(self._control.offset, _put(self._control, 0, "abort", 1))

    def state(self) -> str:
        """STATUS.state: ``idle``, ``running`` or ``done``."""
        return self._status_fields()[0]

    def wait(self, poll: Callable[[], None] | None = None, max_polls: int | None = 100_000,
             stall_seconds: float | None = None) -> str:
        """Poll STATUS until the run is done (``poll`` runs between reads, e.g. to advance a simulation);
        returns the result and clears the pending interrupt. :class:`DriverError` after ``max_polls`` reads
        (``None``: no limit), or where ITERATIONS (counted live) has not changed for ``stall_seconds`` of wall
        time (``None``: not watched; a simulation's clock is not the wall's)."""
        polls, watched = 0, None
        changed = checked = time.monotonic()
        while max_polls is None or polls < max_polls:
            polls += 1
            state, result = self._status_fields()
            if state == "done":
                self.bus.write(self._status.offset, _put(self._status, 0, "irq_pending", 1))
                return result
            if state == "idle":
                raise DriverError("the engine is idle: start() it before wait()")
            if stall_seconds is not None and (now := time.monotonic()) - checked >= min(1.0, stall_seconds / 4):
                checked, iterations = now, self.read_value("iterations")
                if iterations != watched:
                    watched, changed = iterations, now
                elif now - changed >= stall_seconds:
                    raise DriverError(f"the engine made no progress for {stall_seconds:g} s: ITERATIONS stays at "
                                      f"{iterations}")
            if poll is not None:
                poll()
        raise DriverError(f"the engine is still running after {max_polls} status polls")

    def read_back(self) -> EngineReadBack:
        """STATUS, the result registers and the node memory's positions and velocities."""
        state, result = self._status_fields()
        if state == "running":
            raise DriverError("the engine is running: wait() before read_back()")
        vertices = self.read_value("vertices")
        window = self.map.window("nodes")
        read_words = getattr(self.bus, "read_words", None)  # a bus that reads a run of words at once (UartBus)
        words = np.array([read_words(window.address(i, 0), window.words) if read_words is not None
                          else [self.bus.read(window.address(i, k)) for k in range(window.words)]
                          for i in range(vertices)], dtype=np.uint32).reshape(vertices, window.words)
        f = MemoryLayout(window.name, window.fields, window.depth).unpack(words)
        positions = np.column_stack([f["position_x"], f["position_y"]])
        velocities = np.column_stack([f["velocity_x"], f["velocity_y"]])
        return EngineReadBack(state, result, *(self.read_value(v) for v in (
            "iterations", "saturations", "area_error", "shape_error", "energy", "cycles")), positions, velocities)


class ModelBus:
    """The engine on its bus, in Python: the register map's registers and windows, ``err`` where the map
    says, and :func:`run_image` when START is written.  A run stays ``running`` for ``run_polls`` reads of
    STATUS (so a host waits, and memory accesses meanwhile answer ``err``); CYCLES reads 0 (no timing)."""

    def __init__(self, register_map: RegisterMap, fs: FormatSet, run_polls: int = 2):
        if format_hash(fs) != register_map.format_hash:
            raise ValueError(f"ModelBus: format set '{fs.name}' is not the register map's ('{register_map.formats}')")
        self.map, self.fs, self.run_polls = register_map, fs, run_polls
        self.registers = register_map.reset_words()
        self.memories = {w.name: np.zeros((w.depth, w.words), dtype=np.uint32) for w in register_map.windows}
        self._status, self._control = register_map.register("STATUS"), register_map.register("CONTROL")
        self._pending: ImageRunResult | None = None
        self._polls_left = 0

    # ------------------------------------------------------------------ bus
    def read(self, address: int) -> int:
        target = self._decode(address, "read")
        if isinstance(target, Register):
            if target is self._status and self._state == "running":
                self._tick()
            word = self.registers[target.offset]
            return word & ~sum(f.mask for f in target.fields if f.access == "w1p")
        window, index, k = target
        return int(self.memories[window.name][index, k])

    def write(self, address: int, value: int, sel: int = FULL_SEL) -> None:
        if sel != FULL_SEL:
            raise BusError(f"bus error: write to word 0x{address:X} with sel 0b{sel:04b} (partial writes are refused)")
        target = self._decode(address, "write")
        value &= WORD_MASK
        if not isinstance(target, Register):
            window, index, k = target
            self.memories[window.name][index, k] = value
            return
        if target.access == "ro":
            raise BusError(f"bus error: write to read-only register {target.name} (word 0x{address:X})")
        if target is self._control:
            self._write_control(value)
        elif target is self._status:
            if _get(target, value, "irq_pending"):
                self.registers[target.offset] = _put(target, self.registers[target.offset], "irq_pending", 0)
        else:
            self.registers[target.offset] = value & sum(f.mask for f in target.fields)

    @property
    def irq(self) -> bool:
        """The interrupt line: irq_pending and irq_enable."""
        return bool(_get(self._status, self.registers[self._status.offset], "irq_pending")
                    and _get(self._control, self.registers[self._control.offset], "irq_enable"))

    def _decode(self, address: int, what: str) -> Register | tuple:
        target = self.map.decode(address)
        if target is None:
            raise BusError(f"bus error: {what} at unmapped word 0x{address:X}")
        if not isinstance(target, Register) and self._state == "running":
            raise BusError(f"bus error: {what} of the {target[0].name} memory (word 0x{address:X}) while the "
                           "engine is running")
        return target

    # ------------------------------------------------------------------ controller
    @property
    def _state(self) -> str:
        return STATES[_get(self._status, self.registers[self._status.offset], "state")]

    def _set_status(self, state: str, result: str, irq_pending: int, saturated: int = 0) -> None:
        word = _put(self._status, 0, "state", STATES.index(state))
        word = _put(self._status, word, "result", _field(self._status, "result").codes.index(result))
        word = _put(self._status, word, "irq_pending", irq_pending)
        self.registers[self._status.offset] = _put(self._status, word, "saturated", saturated)

    def _write_control(self, value: int) -> None:
        offset = self._control.offset
        self.registers[offset] = _put(self._control, self.registers[offset], "irq_enable",
                                      _get(self._control, value, "irq_enable"))
        if _get(self._control, value, "abort"):
            self._pending = None
            self._set_status("idle", "none", 0)
        elif _get(self._control, value, "start") and self._state != "running":
            self._start()

    def _constants(self) -> dict[str, int]:
        return {c.name: self.map.decode_value(c.name, self.registers)
                for c in run_constant_fields(self.fs, self.map.capacity)}

    def _start(self) -> None:
        constants = self._constants()
        fault = constant_fault(constants, self.fs, self.map.capacity)
        if fault is not None:
            self._set_status("done", fault, 1)
            return
        entries = self.memories["entries"][lane_rows(lane_entry_counts(constants, self.map.capacity), self.map.capacity)]
        coarse = ([self.memories["basis"], self.memories["matrix"]] if self.map.capacity.coarse_degree else [])
        image = EngineImage(self.map.capacity, self.memories["nodes"][:constants["vertices"]], entries,
                            self.memories["triangles"][:constants["triangles"]], constants, *coarse)
        self._pending = run_image(image, self.fs)
        self._polls_left = self.run_polls
        self._set_status("running", "none", 0)

    def _tick(self) -> None:
        self._polls_left -= 1
        if self._polls_left > 0:
            return
        result, self._pending = self._pending, None
        self.memories["nodes"][:len(result.nodes)] = result.nodes
        values = {"iterations": result.iterations, "saturations": result.saturations, "energy": result.energy,
                  "area_error": result.area_error, "shape_error": result.shape_error, "cycles": 0}
        self.registers.update(self.map.encode(values))
        self._set_status("done", result.status, 1, int(result.saturations > 0))
