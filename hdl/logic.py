"""Small combinational helpers shared by the engine's blocks."""

from __future__ import annotations

from amaranth.hdl import Const, Value

from golden_model.engine_spec.image import ENGINE_RUN_MODES
from golden_model.modes import Step

__all__ = ["or_tree", "mode_runs", "mode_steps", "mode_guarded"]


def or_tree(values) -> Value:
    """The OR of ``values`` as a balanced tree (an AND-OR multiplexer's second half)."""
    values = [Value.cast(v) for v in values]
    if not values:
        raise ValueError("or_tree needs at least one value")
    while len(values) > 1:
        values = [values[k] | values[k + 1] if k + 1 < len(values) else values[k] for k in range(0, len(values), 2)]
    return values[0]


def mode_runs(code: Value) -> Value:
    """1 where ``MODE.mode``'s ``code`` is a run mode the engine runs (``ENGINE_RUN_MODES``)."""
    return or_tree(code == m.code for m in ENGINE_RUN_MODES)


def mode_steps(code: Value, step: Step) -> Value:
    """1 where ``MODE.mode``'s ``code`` is a run mode the engine runs whose iteration takes ``step``:
    the units' one decode of the mode, from the golden model's table of modes."""
    return or_tree([Const(0), *(code == m.code for m in ENGINE_RUN_MODES if m.step is step)])


def mode_guarded(code: Value) -> Value:
    """1 where ``MODE.mode``'s ``code`` is a run mode the engine runs through the step guard."""
    return or_tree([Const(0), *(code == m.code for m in ENGINE_RUN_MODES if m.guarded)])
