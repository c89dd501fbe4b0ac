"""The run modes: one description that the command line, the engine's MODE register, the docs table
and every engine's step choice derive from.

A run mode fixes how an iteration chooses its step and what it does with it:

========================  ======  =========================================================
mode                      code    the iteration
========================  ======  =========================================================
``paper-variable``        0       the paper's Euler step, Δt from E_S and E_C (eqs. 18–20)
``paper-fixed``           1       the paper's Euler step, a fixed Δt
``momentum``              2       ``V ← β_k·V + w·f``, ``P ← P + V`` (``docs/dynamics.md``)
``momentum-guarded``      3       the momentum step through the step guard (``docs/guard.md``)
========================  ======  =========================================================

The fold barrier is a force term any mode may add (``FlattenParams.barrier``), not a mode.

Adding a mode is a row in :data:`RUN_MODES`; the command line's choices, the engine's ``MODE.mode``
codes (its register map, C header and decode, ``hdl.logic.mode_steps``), the modes the engine runs
(``ENGINE_RUN_MODES``) and the docs' tables (``python -m sim.docgen``) follow from it. A mode with a
step of its own (a new :class:`Step`) also needs the units that compute that step: the float
reference (``golden_model.reference``), the fixed controller (``golden_model.fixed.controller``,
which the engine's image model shares), the closed-loop bench (``sim/cocotb_benches/closed_loop.py``)
and the engine's phase control (``hdl/phase_controller.py``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Step", "RunMode", "RUN_MODES", "DYNAMICS", "STEP_MODES", "run_mode", "mode_named", "MODE_CODE_BITS",
           "modes_table"]


class Step(enum.Enum):
    """How an iteration chooses its step."""

    #: Δt from the errors of the last layout through the exp-LUT step generator (eqs. 18–20)
    VARIABLE = "variable"
    #: the run constant Δt
    FIXED = "fixed"
    #: β_k = k/(k+3) from the controller's iteration counter and gradient restart; Δt = 1
    MOMENTUM = "momentum"


@dataclass(frozen=True)
class RunMode:
    """One run mode: its name, its code in the engine's ``MODE.mode`` field, the dynamics and step it
    takes, whether the step guard acts, and one line for the docs."""

    name: str
    code: int
    dynamics: str
    step: Step
    guarded: bool
    description: str

    @property
    def has_masses(self) -> bool:
        """Whether the mode's nodes have masses from the area density and their velocities a damping (the
        paper's Euler step); the momentum step weighs each node by 2/(C·deg_i) and damps by its restart."""
        return self.step is not Step.MOMENTUM


RUN_MODES: tuple[RunMode, ...] = (
    RunMode("paper-variable", 0, "paper", Step.VARIABLE, False,
            "the paper's Euler step, Δt from E_S and E_C (eqs. 18–20)"),
    RunMode("paper-fixed", 1, "paper", Step.FIXED, False, "the paper's Euler step, a fixed Δt"),
    RunMode("momentum", 2, "momentum", Step.MOMENTUM, False,
            "V ← β_k·V + w·f, P ← P + V, restarted when the forces oppose the velocity"),
    RunMode("momentum-guarded", 3, "momentum", Step.MOMENTUM, True,
            "the momentum step through the step guard: no step raises the energy or inverts a triangle"),
)

#: Bits of the engine's ``MODE.mode`` code field.
MODE_CODE_BITS = max(m.code for m in RUN_MODES).bit_length()

#: The command line's ``--dynamics`` choices and ``--step`` choices, in table order.
DYNAMICS: tuple[str, ...] = tuple(dict.fromkeys(m.dynamics for m in RUN_MODES))
STEP_MODES: tuple[str, ...] = tuple(dict.fromkeys(m.step.value for m in RUN_MODES if m.dynamics == "paper"))


def run_mode(dynamics: str, step: str, guard: bool) -> RunMode:
    """The mode of a run's parameters (``FlattenParams.dynamics``, ``.step``, ``.guard``); the momentum
    dynamics takes no ``step``."""
    for mode in RUN_MODES:
        if mode.dynamics == dynamics and mode.guarded == guard and (mode.step is Step.MOMENTUM
                                                                     or mode.step.value == step):
            return mode
    raise ValueError(f"no run mode has dynamics {dynamics!r}, step {step!r} and guard {guard}")


def mode_named(name: str) -> RunMode:
    for mode in RUN_MODES:
        if mode.name == name:
            return mode
    raise ValueError(f"no run mode {name!r} (modes: {', '.join(m.name for m in RUN_MODES)})")


def modes_table() -> str:
    """The docs' table of the run modes (markdown), generated from :data:`RUN_MODES`."""
    rows = ["| mode | MODE.mode | dynamics | step | guard | the iteration |", "|---|---|---|---|---|---|"]
    for m in RUN_MODES:
        rows.append(f"| `{m.name}` | {m.code} | {m.dynamics} | {m.step.value} | {'yes' if m.guarded else 'no'} | "
                    f"{m.description} |")
    return "\n".join(rows)
