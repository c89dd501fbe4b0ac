"""The checks of the components' elaboration parameters, one wording for all: a component refuses a
parameter in its ``__init__``, before it builds anything, with a ``ValueError`` naming the parameter."""

from __future__ import annotations


def check_int(name: str, value, minimum: int = 1) -> None:
    """Refuse ``value`` unless it is an ``int`` (not a ``bool``) of at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} must be an int >= {minimum}, not {value!r}")


def check_in_range(name: str, value, low: int, high: int) -> None:
    """Refuse ``value`` unless it is an ``int`` (not a ``bool``) from ``low`` to ``high``."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ValueError(f"{name} must be an int in {low}..{high}, not {value!r}")


def check_power_of_two(name: str, value, minimum: int = 2) -> None:
    """Refuse ``value`` unless it is an ``int`` power of two of at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum or value & (value - 1):
        raise ValueError(f"{name} must be a power of two >= {minimum}, not {value!r}")
