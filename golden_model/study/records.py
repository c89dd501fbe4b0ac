"""One fixed-point run of a study compared with the float reference, and the accuracy target."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..fixed.engine import flatten_fixed
from ..fixed.formats_set import FormatSet
from ..fixed.measures import ERROR_MEASURE_EVENTS
from ..params import ParameterError
from ..results import FlattenResult
from .cases import StudyCase

@dataclass(frozen=True)
class AccuracyTarget:
    """What "meets the target" means for one run against the float reference."""

    error: float = 1e-3  # max |ΔE_S| and |ΔE_C| (final values)
    iterations: int = 1  # max |Δ iterations|
    status: bool = True  # the status (converged / max-iterations / diverged) must match
    saturations: int = 0  # max saturation events (beyond the error measures' own clamp: RunRecord.measure_clamps)

    def __post_init__(self) -> None:
        if not (isinstance(self.error, (int, float)) and math.isfinite(self.error) and self.error > 0):
            raise ParameterError(f"--target must be a positive finite number, got {self.error!r}")

    def failures(self, r: "RunRecord") -> list[str]:
        """Why ``r`` misses the target (empty when it meets it)."""
        if r.error:
            return [f"refused: {r.error}"]
        out = []
        if self.status and r.status_fixed != r.status_float:
            out.append(f"status {r.status_fixed} != {r.status_float}")
        if abs(r.d_iterations) > self.iterations:
            out.append(f"iterations {r.iterations_fixed} vs {r.iterations_float}")
        if not r.deviation <= self.error:
            out.append(f"|dE| {r.deviation:.3g} > {self.error:g}")
        if r.saturations - r.measure_clamps > self.saturations:
            out.append(f"{r.saturations - r.measure_clamps} saturations ({r.saturated_signals})")
        return out


@dataclass(frozen=True)
class RunRecord:
    """One configuration on one case, compared with the float reference."""

    config: str
    case: str
    mesh: str
    init: str
    step: str
    status_float: str
    status_fixed: str  # "refused" when error is set
    iterations_float: int
    iterations_fixed: int
    area_error_float: float
    area_error_fixed: float
    shape_error_float: float
    shape_error_fixed: float
    max_position_error: float  # mean-edge units
    rms_position_error: float  # mean-edge units
    saturations: int
    saturated_signals: str  # "name:count;..."
    error: str = ""
    seconds: float = 0.0
    #: of ``saturations``, the error measures' own (``area_error``, ``shape_error``: E of 1 or more held
    #: below 1 by ``error``, u0.F) at measurements where the float reference's E is 1 or more too. The
    #: step is the same (eqs. 18–20 clamp E to [0, 1]); only the reported E is held, so these do not
    #: count against the target.
    measure_clamps: int = 0

    @property
    def d_area(self) -> float:
        """``|ΔE_S|`` of the two runs' E_S as the step sees them, clamped to 1 (eqs. 18–20): an E_S of 1 or more is
        held just below 1 by ``error`` (u0.F), so a float 1.44 against a fixed 0.99999 is no deviation."""
        return abs(min(self.area_error_fixed, 1.0) - min(self.area_error_float, 1.0))

    @property
    def d_shape(self) -> float:
        """``|ΔE_C|``, clamped to 1 as :attr:`d_area`."""
        return abs(min(self.shape_error_fixed, 1.0) - min(self.shape_error_float, 1.0))

    @property
    def deviation(self) -> float:
        """``max(|ΔE_S|, |ΔE_C|)`` (NaN when refused)."""
        return max(self.d_area, self.d_shape) if not self.error else math.nan

    @property
    def d_iterations(self) -> int:
        """Fixed − float iterations; 0 for a refused run (which the target counts as refused, not by this)."""
        return self.iterations_fixed - self.iterations_float if not self.error else 0

    @property
    def status_match(self) -> bool:
        return self.status_fixed == self.status_float

    def row(self, target: AccuracyTarget) -> dict[str, Any]:
        """The ``results.csv`` row."""
        return {
            "config": self.config, "case": self.case, "mesh": self.mesh, "init": self.init, "step": self.step,
            "status_float": self.status_float, "status_fixed": self.status_fixed,
            "status_match": int(self.status_match),
            "iterations_float": self.iterations_float,  # a refused run has no iterations: empty cells
            "iterations_fixed": None if self.error else self.iterations_fixed,
            "d_iterations": None if self.error else self.d_iterations,
            "area_error_float": self.area_error_float, "area_error_fixed": self.area_error_fixed,
            "d_area_error": self.d_area, "shape_error_float": self.shape_error_float,
            "shape_error_fixed": self.shape_error_fixed, "d_shape_error": self.d_shape,
            "max_position_error": self.max_position_error, "rms_position_error": self.rms_position_error,
            "saturations": self.saturations, "saturated_signals": self.saturated_signals,
            "measure_clamps": self.measure_clamps, "meets_target": int(not target.failures(self)), "error": self.error,
            "seconds": round(self.seconds, 4),
        }


RESULT_COLUMNS = tuple(RunRecord("", "", "", "", "", "", "", 0, 0, 0, 0, 0, 0, 0, 0, 0, "").row(AccuracyTarget()))
"""Column names of ``results.csv`` (``kind``, ``knob``, ``value`` are prepended by the writer)."""


@dataclass(frozen=True)
class FixedOutcome:
    status: str
    iterations: int
    area_error: float
    shape_error: float
    positions: np.ndarray | None
    saturations: int
    saturation_events: dict
    error: str
    seconds: float


def run_fixed(case: StudyCase, fs: FormatSet) -> FixedOutcome:
    t0 = time.perf_counter()
    try:
        r = flatten_fixed(case.mesh, case.positions, case.params, fs)
    except ValueError as exc:  # FixedPointError: the mesh/parameters do not fit these formats
        return FixedOutcome("refused", 0, math.nan, math.nan, None, 0, {}, str(exc).splitlines()[0],
                             time.perf_counter() - t0)
    return FixedOutcome(r.status, r.iterations, r.final.area_error, r.final.shape_error, r.positions,
                         int(r.extra.get("saturations", 0)), dict(r.extra.get("saturation_events", {})), "",
                         time.perf_counter() - t0)


def compare(case: StudyCase, ref: FlattenResult, out: FixedOutcome) -> RunRecord:
    if out.error:
        pos_max = pos_rms = math.nan
    else:
        d = np.hypot(*(out.positions - ref.positions).T) / case.mean_edge
        pos_max, pos_rms = float(d.max()), float(np.sqrt(np.mean(d * d)))
    events = ";".join(f"{k}:{v}" for k, v in sorted(out.saturation_events.items()))
    return RunRecord("", case.name, case.mesh_name, case.init, case.step, ref.status, out.status, ref.iterations,
                     out.iterations, ref.final.area_error, out.area_error, ref.final.shape_error, out.shape_error,
                     pos_max, pos_rms, out.saturations, events, out.error, out.seconds,
                     measure_clamps(out.saturation_events, ref))


def measure_clamps(events: dict[str, int], reference: FlattenResult) -> int:
    """The error-measure saturations among ``events`` that the float ``reference`` shares: for E_S and
    E_C, at most as many as the reference has measurements of 1 or more (:attr:`RunRecord.measure_clamps`)."""
    history = (reference.history.area_error, reference.history.shape_error)
    return sum(min(events.get(name, 0), int((np.asarray(values) >= 1).sum()))
               for name, values in zip(ERROR_MEASURE_EVENTS, history))
