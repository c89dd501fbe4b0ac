"""What a flattening run returns: the measurement of a layout, the per-iteration history, the result.

Shared by the float reference and the fixed-point engines (:class:`FlattenResult` is what every
engine returns and the CLI writes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .params import FlattenParams

__all__ = ["Measurement", "History", "FlattenResult", "Status"]

Status = Literal["converged", "max-iterations", "diverged", "stalled"]


@dataclass(frozen=True)
class Measurement:
    """The errors of one layout."""

    area_error: float
    shape_error: float
    energy: float
    flipped: int
    #: faces whose orientation disagrees with the whole pattern's (the honest fold count)
    folded: int = 0

    def finite(self) -> bool:
        return all(math.isfinite(v) for v in (self.area_error, self.shape_error, self.energy))


@dataclass
class History:
    """Per-iteration record; row 0 is the initial layout (``dt`` NaN there)."""

    dt: list[float] = field(default_factory=list)
    area_error: list[float] = field(default_factory=list)
    shape_error: list[float] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    flipped: list[int] = field(default_factory=list)
    folded: list[int] = field(default_factory=list)
    #: whether the iteration's step was taken (the guard rolls back a step that raises the energy); ``None`` for
    #: a row that is no one step (row 0, the start; an engine's end row, after iterations it does not record)
    accepted: list[bool | None] = field(default_factory=list)
    #: each row's iteration number: its index, unless a row skips iterations (an engine's final row)
    iteration: list[int] = field(default_factory=list)

    def append(self, dt: float, m: Measurement, accepted: bool | None, iteration: int | None = None) -> None:
        """Add the row of ``iteration`` (default: the next, ``len(self)``); ``accepted``: whether its step was taken,
        ``None`` for a row that is no one step (no default: a start row given none was written as a step)."""
        self.iteration.append(len(self) if iteration is None else iteration)
        self.accepted.append(accepted)
        self.dt.append(dt)
        self.area_error.append(m.area_error)
        self.shape_error.append(m.shape_error)
        self.energy.append(m.energy)
        self.flipped.append(m.flipped)
        self.folded.append(m.folded)

    def __len__(self) -> int:
        return len(self.dt)

    def rows(self) -> list[tuple]:
        """``(iteration, dt, area_error, shape_error, energy, flipped, folded)`` rows."""
        return [
            (self.iteration[k], self.dt[k], self.area_error[k], self.shape_error[k], self.energy[k], self.flipped[k],
             self.folded[k])
            for k in range(len(self))
        ]


@dataclass
class FlattenResult:
    """Outcome of a flattening run.

    ``positions``/``velocities`` are the last finite state; ``iterations``
    counts the iterations that produced it.  ``status == "diverged"`` means
    iteration ``iterations + 1`` produced a non-finite value.

    ``extra`` holds what one engine or the command adds: the fixed-point engines' ``formats`` (the format set's
    name), ``scale`` (the host's power of two: a mesh length ``x`` is ``x * scale`` in the model's units, so a
    position's raw code is ``positions * scale * 2**fs.position.frac_bits``), ``saturations`` and
    ``saturation_events`` (per source); the step guard's ``rejected_steps``, ``clipped_node_steps``,
    ``frozen_node_steps`` and final ``step_scale`` (``docs/guard.md``); on a fold-free pattern
    ``boundary_crossings`` and, with kept holes, ``turned_holes``.
    """

    positions: np.ndarray
    velocities: np.ndarray
    initial_positions: np.ndarray
    history: History
    status: Status
    iterations: int
    params: FlattenParams
    density: float
    engine: str = "float"
    extra: dict = field(default_factory=dict)

    @property
    def final(self) -> Measurement:
        h = self.history
        return Measurement(h.area_error[-1], h.shape_error[-1], h.energy[-1], h.flipped[-1], h.folded[-1])

    @property
    def initial(self) -> Measurement:
        h = self.history
        return Measurement(h.area_error[0], h.shape_error[0], h.energy[0], h.flipped[0], h.folded[0])

    def summary(self) -> dict:
        """The JSON summary the CLI prints."""
        final, initial = self.final, self.initial
        return {
            "status": self.status,
            "iterations": self.iterations,
            "area_error": final.area_error,
            "shape_error": final.shape_error,
            "energy": final.energy,
            "flipped": final.flipped,
            "folded": final.folded,
            "initial_area_error": initial.area_error,
            "initial_shape_error": initial.shape_error,
            "initial_energy": initial.energy,
            "initial_flipped": initial.flipped,
            "initial_folded": initial.folded,
            "engine": self.engine,
            "mode": self.params.mode.name,
            "dynamics": self.params.dynamics,
            "step": self.params.mode.step.value,  # "momentum": that dynamics has no step of its own to choose
            "guard": self.params.guard,
            **({"coarse_degree": self.params.coarse_degree} if self.params.guard else {}),
            "energy_window": self.params.energy_window,
            "update": self.params.update,
            "penalty": self.params.penalty,
            "barrier": self.params.barrier,
            **({"damping": self.params.damping, "density": self.density} if self.params.mode.has_masses else {}),
            **self.extra,
        }
