"""The parameters of a flattening run and their domains (the float reference's and every engine's).

See :class:`FlattenParams`; a value outside its domain raises :class:`ParameterError` with a
one-line message for the user.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from .coarse import COARSE_DEGREE_MAX
from .guard import ENERGY_WINDOW
from .modes import DYNAMICS, STEP_MODES, RunMode, run_mode

__all__ = ["FlattenParams", "ParameterError", "UPDATE_ORDERS", "BARRIER_GAIN_MAX"]

UPDATE_ORDERS = ("jacobi", "sequential")
#: The fold barrier's largest stiffness μ, relative to the springs' C.
BARRIER_GAIN_MAX = 16.0


class ParameterError(ValueError):
    """A parameter outside its domain; the message is one line for the user."""


#: The parameters of a mode with masses alone (:attr:`RunMode.has_masses`), each with why another mode
#: refuses it.
MASS_PARAMETERS = {
    "density": "--density sets the paper dynamics' node masses; the momentum dynamics weighs each node by "
               "2/(C deg) instead: drop --density, or add --dynamics paper",
    "damping": "--damping belongs to the paper dynamics; the momentum dynamics damps by its restart: drop "
               "--damping, or add --dynamics paper",
}


@dataclass(frozen=True)
class FlattenParams:
    """Parameters of one flattening run (defaults: the paper's Table II).

    Attributes:
        spring: spring constant ``C`` (> 0).
        density: area density ``rho`` (> 0), or ``"auto"`` for ``1/min m_i``
            with masses computed at ``rho = 1``.
        step: ``"variable"`` (eqs. 18–20) or ``"fixed"``.
        dt: the fixed step ``Δt`` (> 0), used when ``step == "fixed"``.
        update: ``"jacobi"`` (synchronous, what the hardware computes) or
            ``"sequential"`` (Algorithm 1, index order).
        damping: velocity damping ``γ`` in [0, 1); 0 is the paper.
        penalty: apply the overlap penalty (eqs. 10–11).
        penalty_kappa: ``κ`` ≥ 0, the fraction of the 3D altitude below which
            the penalty fires.
        penalty_gain: ``λ`` ≥ 0, the fraction of the shortfall moved per step.
        tol_area, tol_shape, tol_energy: ``φ_S``, ``φ_C``, ``ε`` (≥ 0).
        max_iter: ``N_max`` (≥ 1).
        dynamics: ``"paper"`` (eqs. 7–9, the default) or ``"momentum"``:
            per-node weights ``w_i = 2/(C·deg_i)``, ``V ← β_k·V + w_i·f_i``,
            ``P ← P + V`` with ``β_k = k/(k+3)`` and a gradient restart
            (``docs/dynamics.md``).  ``step``, ``dt`` and ``density`` do not
            apply to it.
        barrier: the fold barrier (``docs/dynamics.md``); ``None`` means on
            with ``momentum`` and off with ``paper``.
        barrier_threshold: ``κ`` in (0, 1]: a triangle whose signed 2D area
            falls below ``κ`` times its 3D area is pushed back.
        barrier_gain: ``μ`` > 0: the barrier's stiffness relative to the
            springs' ``C``.
        guard: the step guard of the momentum dynamics (:mod:`golden_model.guard`): no
            accepted step raises the energy or inverts a triangle; ``None`` means on with
            ``momentum``; the paper dynamics has none.
        energy_window: ``W``, the iterations over which the stop rule measures the relative
            energy change, ``|E_k − E_k−W| ≤ ε·E_k−W`` (counting accepted steps only);
            ``None`` means 1 with ``paper`` (Algorithm 1's rule) and
            :data:`~golden_model.guard.ENERGY_WINDOW` with ``momentum``.
        coarse_degree: the guarded momentum step's coarse space (:mod:`golden_model.coarse`): the
            monomials up to this degree of the start layout's coordinates; 0 (the default here) takes the
            Jacobi step alone. A mesh file's defaults take
            :data:`~golden_model.coarse.DEFAULT_COARSE_DEGREE` with the guard
            (``sim.run_options.FILE_PARAMS``).
    """

    spring: float = 0.5
    density: float | str = 2.0
    step: str = "variable"
    dt: float = 0.01
    update: str = "jacobi"
    damping: float = 0.0
    penalty: bool = False
    penalty_kappa: float = 1.0
    penalty_gain: float = 1.0
    tol_area: float = 0.16
    tol_shape: float = 0.40
    tol_energy: float = 0.05
    max_iter: int = 100
    dynamics: str = "paper"
    barrier: bool | None = None
    barrier_threshold: float = 0.5
    barrier_gain: float = 4.0
    guard: bool | None = None
    energy_window: int | None = None
    coarse_degree: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):  # a numpy scalar as its Python value (np.float32(0.5) is 0.5, np.int64(500) 500)
            if isinstance(value := getattr(self, f.name), np.generic):
                object.__setattr__(self, f.name, value.item())

        def finite(name: str, value: float) -> float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(f"{name} must be a finite number, got {value!r}")
            return float(value)

        if finite("--spring (the spring constant C)", self.spring) <= 0:
            raise ParameterError(f"--spring (the spring constant C) must be > 0, got {self.spring}")
        if self.density != "auto" and finite("--density", self.density) <= 0:
            raise ParameterError(f"--density must be > 0 or 'auto', got {self.density}")
        if self.step not in STEP_MODES:
            raise ParameterError(f"step must be one of {STEP_MODES}, got {self.step!r}")
        if finite("--dt", self.dt) <= 0:
            raise ParameterError(f"--dt must be > 0, got {self.dt}")
        if self.update not in UPDATE_ORDERS:
            raise ParameterError(f"update must be one of {UPDATE_ORDERS}, got {self.update!r}")
        if not 0 <= finite("--damping", self.damping) < 1:
            raise ParameterError(f"--damping must be in [0, 1), got {self.damping}")
        for name in ("penalty_kappa", "penalty_gain", "tol_area", "tol_shape", "tol_energy"):
            flag = "--" + name.replace("_", "-")  # as the option is spelled, in every message about it
            if finite(flag, getattr(self, name)) < 0:
                raise ParameterError(f"{flag} must be >= 0, got {getattr(self, name)}")
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, int) or self.max_iter < 1:
            raise ParameterError(f"--max-iter must be an integer >= 1, got {self.max_iter!r}")
        if self.dynamics not in DYNAMICS:
            raise ParameterError(f"dynamics must be one of {DYNAMICS}, got {self.dynamics!r}")
        if self.barrier is None:
            object.__setattr__(self, "barrier", self.dynamics == "momentum")
        if not isinstance(self.barrier, bool):
            raise ParameterError(f"barrier must be true or false, got {self.barrier!r}")
        if not 0 < finite("--barrier-threshold", self.barrier_threshold) <= 1:
            raise ParameterError(f"--barrier-threshold (kappa) must be in (0, 1], got {self.barrier_threshold}")
        if not 0 < finite("--barrier-gain", self.barrier_gain) <= BARRIER_GAIN_MAX:
            raise ParameterError(f"--barrier-gain (mu) must be in (0, {BARRIER_GAIN_MAX:g}], got {self.barrier_gain}")
        if self.guard is None:
            object.__setattr__(self, "guard", self.dynamics == "momentum")
        if not isinstance(self.guard, bool):
            raise ParameterError(f"guard must be true or false, got {self.guard!r}")
        if self.energy_window is None:
            object.__setattr__(self, "energy_window", ENERGY_WINDOW if self.dynamics == "momentum" else 1)
        if (isinstance(self.energy_window, bool) or not isinstance(self.energy_window, int)
                or not 1 <= self.energy_window <= 1000):
            raise ParameterError(f"--energy-window must be an integer in [1, 1000], got {self.energy_window!r}")
        if self.guard and self.dynamics != "momentum":
            raise ParameterError("the step guard belongs to the momentum dynamics (--dynamics momentum); "
                                 "the paper dynamics has none (drop --guard)")
        if (isinstance(self.coarse_degree, bool) or not isinstance(self.coarse_degree, int)
                or not 0 <= self.coarse_degree <= COARSE_DEGREE_MAX):
            raise ParameterError(f"--coarse-degree must be an integer in [0, {COARSE_DEGREE_MAX}], "
                                 f"got {self.coarse_degree!r}")
        if self.coarse_degree and not self.guard:
            raise ParameterError("the coarse space is a step of the guarded momentum dynamics: drop --coarse-degree"
                                 + (", or drop --no-guard" if self.dynamics == "momentum" else
                                    ", or add --dynamics momentum"))
        if self.guard and self.penalty:
            raise ParameterError("the penalty moves nodes after the guarded step and would void its "
                                 "guarantees: drop --penalty, or use --no-guard")
        if self.dynamics == "momentum":
            if self.update != "jacobi":
                raise ParameterError("the momentum dynamics updates all nodes together: use --update jacobi")
            if self.damping:
                raise ParameterError(MASS_PARAMETERS["damping"])

    @property
    def mode(self) -> RunMode:
        """The run mode (:mod:`golden_model.modes`) these parameters select."""
        return run_mode(self.dynamics, self.step, self.guard)

    def with_(self, **changes) -> "FlattenParams":
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def as_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}
