"""A flattening through the engine on a board (or anything behind :class:`~sim.uart_bus.UartBus`): the flow of
``springflat flatten --engine board``.

The same pieces as ``--engine rtl`` (``sim/engine_run.py``): the golden model's host scaling
(``prepare``), the image (``build_image``), the register map and :class:`~sim.engine_driver.EngineDriver`;
only the transport differs. The capacity is the board's own: read from its CAP_* registers (whose
addresses do not depend on the capacity) before the map is built. The read-back is compared bit for bit
with :func:`~golden_model.engine_spec.image.run_image` (a mismatch is an :class:`EngineRunError`), and
becomes the :class:`~golden_model.results.FlattenResult` that ``flatten`` writes.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import FixedProblem
from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity, build_image, run_image
from golden_model.engine_spec.register_map import RegisterMap

from .engine_driver import DriverError, EngineDriver, EngineReadBack
from .engine_run import EngineRunError, engine_flatten_result
from .outputs import print_note

__all__ = ["board_capacity", "BoardRun", "run_on_board", "flatten_on_board", "add_board_options", "board_engine"]


def board_capacity(bus, fs: FormatSet) -> EngineCapacity:
    """The capacity the engine behind ``bus`` was built with (its CAP_* registers and FEATURES), once its
    ID, version and format set say it is an engine this driver speaks to (:class:`DriverError` if not)."""
    probe = EngineDriver(bus, RegisterMap.build(fs, DEFAULT_CAPACITY))
    probe.identify_engine()
    values = [probe.read_value(f"cap_{what}") for what in ("vertices", "entries", "triangles")]
    try:
        capacity = EngineCapacity(*values, guard=bool(probe.read_value("feature_guard")),
                                  lanes=probe.read_value("feature_lanes"),
                                  coarse_degree=probe.read_value("feature_coarse"))
        RegisterMap.build(fs, capacity)  # (its address map must fit the bus)
    except ValueError as exc:
        raise DriverError(f"the engine reports a capacity it cannot have ({exc})") from None
    return capacity


#: ``flatten --engine board`` gives up on a run whose ITERATIONS has not moved for this long (wall time). An
#: iteration of a 3,025-vertex patch took 58,376 clocks in simulation (docs/synthesis.md), under a millisecond
#: at the board's engine clock (``uart_protocol.ENGINE_CLOCK_HZ``).
BOARD_STALL_SECONDS = 20.0


@dataclass(frozen=True, eq=False)
class BoardRun:
    readback: EngineReadBack
    capacity: EngineCapacity
    mismatches: list[str]
    load_seconds: float
    run_seconds: float
    readback_seconds: float
    #: the engine was found running (a run cut off before it could abort it) and was aborted first
    aborted_earlier_run: bool = False


def _abort(driver: EngineDriver) -> None:
    """ABORT, then STATUS polled until the engine has drained what was in flight (a few clocks)."""
    driver.abort()
    for _ in range(100):
        if driver.state() != "running":
            return
    raise DriverError("the engine is still running after ABORT")


def run_on_board(problem: FixedProblem, bus, *, poll=None, max_polls: int | None = 10_000_000,
                 stall_seconds: float | None = None) -> BoardRun:
    """Load ``problem``'s image, run it, read it back and compare it with ``run_image``. ``poll`` runs between
    STATUS reads (default: none; the link's round trip paces the polls); ``max_polls`` and ``stall_seconds``
    limit the wait (:meth:`EngineDriver.wait`). The host owns the engine: one found running (a run cut off by
    a lost link or a killed process) is aborted first, and a run that is interrupted or fails here is aborted
    before the exception goes on, so that the next run finds the engine idle."""
    fs = problem.fs
    capacity = board_capacity(bus, fs)
    driver = EngineDriver(bus, RegisterMap.build(fs, capacity))
    image = build_image(problem, capacity)  # refuses a mesh over the board's capacity in one line
    aborted_earlier_run = driver.state() == "running"
    if aborted_earlier_run:
        _abort(driver)
    started = time.perf_counter()
    batched = getattr(bus, "batched", None)
    if batched is not None:
        with batched():
            driver.load(image)
    else:
        driver.load(image)
    loaded = time.perf_counter()
    driver.start(irq=True)
    try:
        driver.wait(poll=poll, max_polls=max_polls, stall_seconds=stall_seconds)
    except BaseException:  # (KeyboardInterrupt too: the command's signals)
        for pause in (0.0, 0.2):  # again after a pause: an interrupted frame's answer may still be arriving
            time.sleep(pause)
            try:
                _abort(driver)
                break
            except Exception:  # the link itself failed: the next run aborts what it finds running
                continue
        raise
    ran = time.perf_counter()
    readback = driver.read_back()
    done = time.perf_counter()
    want = run_image(image, fs)
    mismatches = [f"{name}: engine {getattr(readback, attr)} golden model {getattr(want, name)}"
                  for name, attr in (("status", "result"), ("iterations", "iterations"),
                                     ("area_error", "area_error"), ("shape_error", "shape_error"),
                                     ("energy", "energy"), ("saturations", "saturations"))
                  if getattr(readback, attr) != getattr(want, name)]
    for name in ("positions", "velocities"):
        got, golden = getattr(readback, name), getattr(want, name)
        if got.shape != golden.shape or not np.array_equal(got, golden):
            bad = np.argwhere(got != golden) if got.shape == golden.shape else [[0, 0]]
            node, axis = (int(v) for v in bad[0])
            mismatches.append(f"{name}: {len(bad)} values differ, the first node {node} {'xy'[axis]}")
    return BoardRun(readback, capacity, mismatches, loaded - started, ran - loaded, done - ran, aborted_earlier_run)


def flatten_on_board(problem: FixedProblem, bus, *, poll=None, transport: str = "board",
                     stall_seconds: float | None = None):
    """``springflat flatten --engine board``: ``problem`` through the engine behind ``bus``, as a
    :class:`~golden_model.results.FlattenResult`; :class:`EngineRunError` when the read-back differs
    from the golden model's."""
    run = run_on_board(problem, bus, poll=poll, stall_seconds=stall_seconds)
    if run.aborted_earlier_run:
        print_note(f"the engine on {transport} was still running a run cut off earlier: aborted it first")
    if run.mismatches:
        raise EngineRunError(f"the engine on {transport} does not match the golden model: {run.mismatches[0]}")
    r = run.readback
    return engine_flatten_result(problem, r.positions, r.velocities, r.result, r.iterations, "board", {
        "saturations": r.saturations, "simulator": transport, "cycles": r.cycles,
        "cycles_per_iteration": r.cycles / max(r.iterations, 1), "load_seconds": round(run.load_seconds, 3),
        "run_seconds": round(run.run_seconds, 3), "readback_seconds": round(run.readback_seconds, 3)})


def add_board_options(parser) -> None:
    """``--port`` and ``--baud`` of ``flatten --engine board``."""
    from golden_model.engine_spec.uart_protocol import DEFAULT_BAUD

    from .run_options import integer_argument

    parser.add_argument("--port", default=None, metavar="DEVICE|URL",
                        help="--engine board: the board's serial port (/dev/ttyUSB0, COM3, or a pyserial URL "
                             "such as socket://host:port)")
    parser.add_argument("--baud", type=integer_argument, default=None,  # None: not given (DEFAULT_BAUD)
                        help=f"--engine board: the UART's rate in bit/s, as the bitstream was built (default "
                             f"{DEFAULT_BAUD})")


#: pyserial URLs whose link has no line rate: ``--baud`` does nothing there (``rfc2217://`` sets the far port's).
UNTIMED_LINKS = ("socket://", "loop://")


def board_engine(formats: FormatSet, port: str | None, baud: int | None):
    """``--engine board``: the engine function ``cmd_flatten`` calls; every failure is one line (``UserError``).
    ``baud``: ``None`` for :data:`~golden_model.engine_spec.uart_protocol.DEFAULT_BAUD`."""

    from golden_model.engine_spec.uart_protocol import DEFAULT_BAUD

    from golden_model.fixed.engine import prepare

    from .engine_driver import EngineError
    from .run_options import UserError
    from .uart_bus import UartBus, open_port

    if not port:
        raise UserError("--engine board needs --port DEVICE (the board's serial port, e.g. /dev/ttyUSB0)")
    if baud is not None and baud <= 0:  # (before the note on a link that ignores it)
        raise UserError(f"--baud must be a positive number of bits per second, not {baud}")
    if baud is not None and port.startswith(UNTIMED_LINKS):
        print_note(f"--baud {baud} has no effect on a {port.split('://')[0]}:// link, which carries bytes at no line "
                   "rate; the board's UART runs at the rate its bitstream was built for")
    baud = DEFAULT_BAUD if baud is None else baud

    def engine(mesh, positions, params, on_iteration=None):  # the parameters checked by choose_engine
        problem = prepare(mesh, positions, params, formats)
        try:
            link = open_port(port, baud)
        except EngineError as exc:
            raise UserError(str(exc)) from None
        speed = "" if port.startswith(UNTIMED_LINKS) else f" at {baud} baud"
        print(f"springflat: board: loading the mesh over {port}{speed} and running the flattening ...",
              file=sys.stderr)
        try:
            with link:
                return flatten_on_board(problem, UartBus(link, name=f"the board on {port}"),
                                        transport=f"the board on {port}", stall_seconds=BOARD_STALL_SECONDS)
        except (EngineError, EngineRunError) as exc:
            raise UserError(str(exc)) from None

    return engine
