"""Small combinational helpers shared by the engine's blocks."""

from __future__ import annotations

from amaranth.hdl import Value

__all__ = ["or_tree"]


def or_tree(values) -> Value:
    """The OR of ``values`` as a balanced tree (an AND-OR multiplexer's second half)."""
    values = [Value.cast(v) for v in values]
    if not values:
        raise ValueError("or_tree needs at least one value")
    while len(values) > 1:
        values = [values[k] | values[k + 1] if k + 1 < len(values) else values[k] for k in range(0, len(values), 2)]
    return values[0]
