"""The engines ``springflat flatten --engine`` runs: one description that the command line's choices and
help, the checks before a run, what a batch and the Python API refuse, and each result's ``engine`` label
derive from.

Each :class:`Engine` says whether it runs fixed-point formats, runs ``SpringflatEngine`` (its parameter
checks), may run in a batch's workers and in the Python API, and how its run is made (``float``: the float
reference, ``fixed``: the golden model, ``rtl``: the Verilog on Verilator, ``board``: a ULX3S over its UART).

Adding an engine is a row in :data:`ENGINES` and the function that makes its run.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Callable

__all__ = ["Engine", "ENGINES", "ENGINE_NAMES", "DEFAULT_ENGINE", "SERIAL_ENGINE_NAMES", "engine_named"]

#: ``run(mesh, P0, params, on_iteration=None) -> FlattenResult``
RunFunction = Callable[..., object]


@dataclass(frozen=True)
class Engine:
    """One engine of ``flatten --engine``.

    Attributes:
        name: the ``--engine`` value, and the ``engine`` of its results (the JSON summary's ``"engine"``).
        fixed_point: runs a fixed-point format set (``--formats``, saturation counts, the formats' checks).
        hardware: runs ``SpringflatEngine`` (its parameter checks, ``check_engine_params``, apply).
        single: why it runs one mesh at a time, in the command (``None``: a batch may run it in its workers).
        api: the Python API (``springflat.flatten``) can run it (no port or other device to name).
        serial: it talks to a device over a serial port (``--port``, ``--baud``).
        help: the ``--help`` text.
        make: ``make(args, formats) -> run``: the run function for ``args`` (``--port``, ...) and the loaded
            format set (``None`` for float).
        check_mesh: ``check_mesh(mesh)`` refuses a mesh the engine cannot hold whatever its layout, before the
            layout is computed (``None``: no such limit is known before the run).
    """

    name: str
    fixed_point: bool
    hardware: bool
    single: str | None
    api: bool
    serial: bool
    help: str
    make: Callable[[argparse.Namespace, object], RunFunction]
    check_mesh: Callable[[object], None] | None = None


def _float(args: argparse.Namespace, formats) -> RunFunction:
    from golden_model.reference import flatten

    return flatten


def _fixed(args: argparse.Namespace, formats) -> RunFunction:
    from golden_model.fixed.engine import flatten_fixed

    def run(*run_args, **kw):
        return flatten_fixed(*run_args, fs=formats, **kw)
    return run


def _rtl(args: argparse.Namespace, formats) -> RunFunction:
    from .engine_run import rtl_engine

    return rtl_engine(formats)


def _rtl_holds(mesh) -> None:
    from .engine_run import rtl_capacity

    rtl_capacity().check_mesh(mesh)


def _board(args: argparse.Namespace, formats) -> RunFunction:
    from .board_run import board_engine

    return board_engine(formats, args.port, args.baud)


ENGINES: tuple[Engine, ...] = (
    Engine("float", False, False, None, True, False, "the float reference (the default)", _float),
    Engine("fixed", True, False, None, True, False, "the bit-exact fixed-point golden model", _fixed),
    Engine("rtl", True, True, "the simulator build is shared", True, False,
           "the whole flattening through SpringflatEngine's Verilog on Verilator (bit-exact with fixed)", _rtl,
           _rtl_holds),
    Engine("board", True, True, "one board answers on one port", False, True,
           "the engine on a ULX3S over its USB-UART (--port; docs/board.md)", _board),
)

#: The ``--engine`` choices, in table order.
ENGINE_NAMES: tuple[str, ...] = tuple(e.name for e in ENGINES)
DEFAULT_ENGINE = "float"
#: The engines that take ``--port``.
SERIAL_ENGINE_NAMES: tuple[str, ...] = tuple(e.name for e in ENGINES if e.serial)


def engine_named(name: str) -> Engine:
    """The engine ``--engine name`` chooses (``ValueError`` for a name no engine has)."""
    for engine in ENGINES:
        if engine.name == name:
            return engine
    raise ValueError(f"no engine {name!r} (engines: {', '.join(ENGINE_NAMES)})")
