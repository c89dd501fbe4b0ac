"""Small combinational helpers shared by the engine's blocks."""

from __future__ import annotations

from amaranth.hdl import Const, Module, Signal, Value

from golden_model.engine_spec.image import ENGINE_RUN_MODES
from golden_model.modes import Step

__all__ = ["or_tree", "mode_runs", "mode_steps", "mode_guarded", "reset_echo"]


def or_tree(values) -> Value:
    """The OR of ``values`` as a balanced tree (an AND-OR multiplexer's second half)."""
    values = [Value.cast(v) for v in values]
    if not values:
        raise ValueError("or_tree needs at least one value")
    while len(values) > 1:
        values = [values[k] | values[k + 1] if k + 1 < len(values) else values[k] for k in range(0, len(values), 2)]
    return values[0]


def mode_runs(code: Value, *, guard: bool = True) -> Value:
    """1 where ``MODE.mode``'s ``code`` is a run mode the engine runs (``ENGINE_RUN_MODES``; without
    ``guard``, the build without the step guard, not the guarded ones)."""
    return or_tree(code == m.code for m in ENGINE_RUN_MODES if guard or not m.guarded)


def mode_steps(code: Value, step: Step) -> Value:
    """1 where ``MODE.mode``'s ``code`` is a run mode the engine runs whose iteration takes ``step``:
    the units' one decode of the mode, from the golden model's table of modes."""
    return or_tree([Const(0), *(code == m.code for m in ENGINE_RUN_MODES if m.step is step)])


def mode_guarded(code: Value) -> Value:
    """1 where ``MODE.mode``'s ``code`` is a run mode the engine runs through the step guard."""
    return or_tree([Const(0), *(code == m.code for m in ENGINE_RUN_MODES if m.guarded)])


def reset_echo(m: Module, name: str) -> Signal:
    """A flip-flop high while the ``sync`` domain is in reset and for the clock after it.

    A register without the domain's reset whose clear is ``reset_echo(...) | clear`` holds, from the clock
    after the reset on, what it would hold with the reset (it is cleared a clock later, while nothing can
    read it yet). The point is placement: the domain's reset is one net across the whole device, and a
    LUT of it and a clear driving a wide register's reset pins is a long path; this flip-flop, read by
    that LUT alone, sits beside it.
    """
    echo = Signal(init=1, name=name)
    m.d.sync += echo.eq(0)
    return echo
