"""The engine's controller, bit for bit: the one Python model of Algorithm 1 on raw integers.

:class:`Controller` runs from a :class:`Setup` (what the engine holds once the host has loaded a
mesh: the stream of neighbour entries, the triangles, the run constants) and a raw layout. Both
``--engine fixed`` (:class:`~golden_model.fixed.engine.FixedEngine`, from the host's
:class:`~golden_model.fixed.engine.FixedProblem`) and the image model of ``SpringflatEngine``
(:func:`~golden_model.engine_spec.image.run_image`, from decoded memories) run this class, so the
two cannot drift apart.

An iteration (``docs/engine.md`` has it pass by pass): the step for the run mode
(:mod:`golden_model.modes`: the step generator on E_S and E_C, the fixed Δt, or β_k), the
integrate pass, the force and area passes on the new layout; with the guard the integrate pass
proposes, the guard certificate picks each node's fraction, and the moved layout is kept only if
its exact energy did not rise (:mod:`golden_model.fixed.guard`). Then the stop rule on raw integers
(:class:`~golden_model.fixed.engine.StopRule` over :class:`~golden_model.guard.EnergyWindow`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..coarse import CoarseSchedule, clipped_deep
from ..guard import EnergyWindow
from ..modes import RunMode, Step
from .coarse import CoarseConstants, coarse_accel
from .format import SaturationCounter
from .formats_set import FormatSet
from .guard import commit, floor_min_raw, guarded_moves_raw, proposal
from .measures import MomentumState, area_error, energy_raw, power_sum, shape_error
from .pipeline import NeighbourStream, NodeConstants, NodeTerms, integrate, integrate_momentum, node_power, node_terms
from .steplut import half_dt_sq, step_size

__all__ = ["Setup", "Controller"]


@dataclass(frozen=True, eq=False)
class Setup:
    """What the controller reads besides the node state, all raw.

    ``faces`` are the triangles (for E_S and the guard) with ``winding`` σ, the pattern's orientation
    (the engine's image writes each triangle in the pattern's winding, so there σ = +1); ``dt`` the
    fixed Δt of ``paper-fixed``; ``saturation_limit`` stops a run as ``diverged`` once that many
    saturation events were counted (0: never); ``coarse`` the guarded step's coarse space
    (:mod:`golden_model.fixed.coarse`; ``None``: the Jacobi step alone, as the engine's).
    """

    fs: FormatSet
    mode: RunMode
    stream: NeighbourStream
    faces: np.ndarray
    face_areas: np.ndarray
    half_spring: int
    damping: int
    dt: int
    area_reciprocal: object  # engine.Reciprocal
    length_reciprocal: object
    rule: object  # engine.StopRule
    max_iter: int
    energy_window: int
    saturation_limit: int = 0
    winding: int = 1
    coarse: CoarseConstants | None = None


class Controller:
    """The raw state of a run and Algorithm 1's loop around it.

    After :meth:`measure` the terms of the current layout's passes are in ``terms``, ``errors``
    (E_S, E_C raw), ``energy_raw`` and, with unguarded momentum, ``power`` (S) and ``node_power``; the
    guarded step forms those in :meth:`choose_step`, from the layout it steps from.
    """

    def __init__(self, setup: Setup, positions: np.ndarray, velocities: np.ndarray, counter: SaturationCounter):
        from ..reference import GuardRecord

        self.setup = setup
        self.counter = counter
        self.raw_positions = positions
        self.raw_velocities = velocities
        self.terms: NodeTerms | None = None
        self.errors = (0, 0)
        self.energy_raw = 0
        self.power = 0
        self.node_power: np.ndarray | None = None
        self.dt = 0  # the step chosen for the coming integrate pass (β with momentum) [dt]
        self.momentum = MomentumState()
        self.guard = GuardRecord() if setup.mode.guarded else None
        self.floor_min = floor_min_raw(setup.fs, setup.face_areas) if self.guard is not None else None
        self.coarse_schedule = CoarseSchedule(active=setup.coarse is not None)
        self.accepted = True
        self.stalled = False
        self._measured: np.ndarray | None = None  # the positions array the pass results belong to

    def measure(self) -> None:
        """The force pass (F, Σe, Σe², Σc·h, S) and the area pass (E_S) of the current layout, once per layout."""
        if self._measured is self.raw_positions:
            return
        s, fs = self.setup, self.setup.fs
        self.terms = node_terms(fs, self.raw_positions, s.stream, s.half_spring, self.counter)
        self.errors = (area_error(fs, s.area_reciprocal, s.faces, s.face_areas, self.raw_positions, self.counter),
                       shape_error(fs, s.length_reciprocal, self.terms.error_sums, self.counter))
        self.energy_raw = energy_raw(fs, s.half_spring, self.terms.error_square_sum, self.terms.barrier_energy_sum)
        if s.mode.step is Step.MOMENTUM and self.guard is None:
            self._form_power()
        self._measured = self.raw_positions

    def _form_power(self) -> None:
        """``S = Σ F·V`` of the current layout's forces and the move that led to it, and its events."""
        fs = self.setup.fs
        self.node_power = node_power(fs, self.terms.force, self.raw_velocities, self.counter)
        self.power = power_sum(fs, self.node_power, self.counter)

    def choose_step(self) -> int:
        """``dt`` for the coming integrate pass, as the run mode chooses it (β_k with momentum) [dt]."""
        s = self.setup
        if s.mode.step is Step.MOMENTUM:
            if self.guard is not None:
                # the guarded step forms S as it proposes (the engine's propose pass reads F and V
                # together), so a trial layout that is rolled back never forms one
                self._form_power()
            self.dt, self.momentum = self.momentum.next(self.power, s.fs)
        elif s.mode.step is Step.FIXED:
            self.dt = s.dt
        else:
            self.dt = int(step_size(np.int64(self.errors[0]), np.int64(self.errors[1]), s.fs, self.counter)[0])
        return self.dt

    def advance(self) -> None:
        """The integrate pass with the chosen step, and the passes of the new layout."""
        s = self.setup
        weights = s.stream.node_weights(self.terms.barrier_active)
        if self.guard is not None:
            self._advance_guarded(weights)
        elif s.mode.step is Step.MOMENTUM:
            self.raw_positions, self.raw_velocities = integrate_momentum(
                s.fs, self.raw_positions, self.raw_velocities, self.terms.force, weights, self.dt, self.counter)
        else:
            constants = NodeConstants(self.dt, int(half_dt_sq(np.int64(self.dt), s.fs)), s.half_spring, s.damping)
            self.raw_positions, self.raw_velocities = integrate(
                s.fs, self.raw_positions, self.raw_velocities, self.terms.force, weights, constants, self.counter)
        self.measure()

    def _advance_guarded(self, weights: np.ndarray) -> None:
        """Propose, guard, commit and measure; keep the step only if the energy did not rise."""
        s, guard = self.setup, self.guard
        accepted = (self.raw_positions, self.terms, self.errors, self.energy_raw, self.power, self.node_power)
        coarse = None
        if self.coarse_schedule.coarse:
            coarse = coarse_accel(s.fs, s.coarse, self.terms.force, self.counter)
        wanted = proposal(s.fs, self.raw_velocities, self.terms.force, weights, self.dt, guard.scale.shift,
                          self.counter, coarse)
        moves, levels = guarded_moves_raw(s.fs, self.raw_positions, wanted, s.faces, s.winding, self.floor_min)
        guard.count_levels(levels)
        # V is the move taken before the moved layout is measured, so that its S = Σ F·V pairs the new
        # forces with the move that led there, as the float guard's (a rejection zeroes both)
        self.raw_positions, self.raw_velocities = commit(self.raw_positions, moves)
        before = self.energy_raw
        self.measure()
        self.accepted = self.energy_raw <= before
        if self.accepted:
            guard.scale = guard.scale.accepted_step()
            self.coarse_schedule = self.coarse_schedule.accepted(clipped_deep(levels))
            return
        self.raw_positions, self.terms, self.errors, self.energy_raw, self.power, self.node_power = accepted
        self._measured = self.raw_positions
        self.raw_velocities = np.zeros_like(self.raw_velocities)
        self.power = 0  # S of a stopped momentum
        self.momentum = MomentumState()
        guard.rejected += 1
        # β = 0: a plain gradient step
        self.coarse_schedule, guard.scale = self.coarse_schedule.rejected(guard.scale, with_momentum=self.dt > 0)
        self.stalled = guard.scale.stalled

    def run(self, on_iteration: Callable[[int], None] | None = None) -> tuple[str, int]:
        """Algorithm 1 from the current layout: ``(status, iterations)``. ``on_iteration(k)`` is called
        after each iteration's passes, before the stop rule."""
        s = self.setup
        self.measure()
        window = EnergyWindow(s.energy_window)
        window.push(self.energy_raw)
        k = 0
        while k < s.max_iter:
            self.choose_step()
            self.advance()
            k += 1
            if on_iteration is not None:
                on_iteration(k)
            if s.saturation_limit and self.counter.total >= s.saturation_limit:
                return "diverged", k
            if self.stalled:
                return "stalled", k
            window.push(self.energy_raw, self.accepted)
            if window.ready and s.rule.converged(window.oldest, self.energy_raw, self.errors):
                return "converged", k
        return "max-iterations", k
