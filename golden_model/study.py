"""Error studies and word-length optimisation of the fixed-point golden model.

A *study* runs the bit-exact fixed-point engine (:func:`~golden_model.fixed.engine.flatten_fixed`)
with many :class:`~golden_model.fixed.FormatSet` configurations over a set of
*cases* (mesh × initial layout × step mode) and compares every run with the
float reference (:func:`~golden_model.reference.flatten`), which is computed
once per case and cached.

Per run (:class:`RunRecord`): final ``E_S`` and ``E_C`` absolute deviation from
the float run, max and RMS vertex position error in mean-edge units, iteration
difference, status match, saturation events, or the reason the configuration
or the mesh was refused.

**Knobs** (:data:`KNOBS`): the fraction bits of each *signal class*
(:data:`SIGNAL_CLASSES`; tied formats move together so that the design
invariants of the presets hold: ``position``/``delta``/``face_edge`` share fraction bits so
narrowing only saturates, ``force``/``force_acc`` so accumulation is exact,
``rest_length``/``error_acc``/``face_area`` so error sums are exact, ``dt``/``lut_entry`` so
``dt = C + T(E_S) + T(E_C)`` is an exact sum, ``error``/``reciprocal`` so the reciprocals
keep their guard bits), ``lut_index_bits``,
``lut_interpolate``, ``rsqrt_seed_bits``, ``rsqrt_newton_steps`` and
``rounding``.  :func:`sweep_configs` makes one-knob-at-a-time sweeps around a
base set; combinations that :class:`FormatSet` refuses are kept with the
``ValueError`` message.  Integer bits are never changed (their need depends on
the meshes, not on accuracy; saturation events show when they are short).

**Cost model** (:func:`cost`): ``total_bits`` = sum of the widths of the node
datapath formats (:data:`DATAPATH_FIELDS`: every format but the step
generator's ``error`` and ``lut_entry`` and the controller's); ``dsp`` = the 18×18 DSP
blocks of the RTL (:func:`multipliers`): every multiplication of ``fs.products()`` in the
node datapath, its rsqrt unit and the step generator, times its instances, split into
partial products by the rule the RTL uses (:mod:`golden_model.fixed.dsp`);
``rom_bits`` = rsqrt seed ROM + exp-LUT bits.  Costs compare
lexicographically: ``(total_bits, dsp, rom_bits)`` for the ``bits`` metric,
``(dsp, total_bits, rom_bits)`` for ``dsp``.

**Optimiser** (:meth:`Study.optimise`): greedy word-length reduction from a
base set that meets the :class:`AccuracyTarget`: each round lists the
cost-reducing moves (1, 2, 4 or 8 fraction bits less in a signal class, one
LUT index or seed bit less, one Newton step less, interpolation off), tries
them from the largest cost reduction down (ties: the least sensitive knob in
the sweep first) and keeps the first one with which every case still meets
the target — i.e. the acceptable move that reduces the cost most.  A move
that fails is not retried in later rounds until every remaining move has
failed; then every single-bit move is retried once against the current
configuration, so the result is a configuration from which no single move
is acceptable.  Moves to values the one-knob sweep already showed to miss the
target are skipped (``prune``).  Candidates are evaluated case by case (the
case most likely to fail first) and abandoned at the first failing case.

Runs are spread over worker processes (``workers``); no plotting, progress
bars or file output here (see ``sim/study.py``).
"""

from __future__ import annotations

import json
import math
import signal
import time
from concurrent.futures import FIRST_COMPLETED, Executor, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .builtin import builtin_mesh, is_builtin
from .fixed.dsp import dsp_blocks as _dsp_blocks
from .fixed.engine import flatten_fixed
from .fixed.format import Rounding
from .fixed.formats_set import CONTROLLER_FIELDS, FORMAT_FIELDS, FormatSet
from .layouts import initial_layout
from .mesh import Mesh
from .mesh_io import load_mesh
from .reference import FlattenParams, FlattenResult, ParameterError, flatten

__all__ = [
    "GENERATED_PARAMS", "STUDY_MESHES", "GENERATED_MESH_NAMES", "SIGNAL_CLASSES", "DATAPATH_FIELDS", "KNOBS",
    "OTHER_KNOB_VALUES", "DEFAULT_BITS", "DEFAULT_STRIDES", "RTL_UNITS",
    "StudyCase", "Config", "RunRecord", "AccuracyTarget", "Cost", "ConfigSummary", "OptimiseStep",
    "OptimiseResult", "StudyResult", "Study",
    "resolve_study_mesh", "build_cases", "parse_bits", "parse_knobs", "make_config", "class_frac_bits",
    "class_changes", "sweep_configs", "preset_configs", "multipliers", "dsp_blocks", "datapath_bits",
    "rom_bits", "cost", "fs_key", "summarise", "run_study",
]

# ----------------------------------------------------------------------------- cases

GENERATED_PARAMS = FlattenParams(density="auto", damping=0.05, tol_area=0.01, tol_shape=0.01, tol_energy=0.05,
                                 max_iter=300)
"""Parameters of generated and file meshes in a study (built-ins use their paper sets)."""

GENERATED_MESH_NAMES = ("developable", "dome", "saddle", "delaunay")
STUDY_MESHES = ("surf1", "surf2") + GENERATED_MESH_NAMES
"""The default meshes of a study."""


@dataclass(frozen=True, eq=False)
class StudyCase:
    """One flattening problem: a mesh, an initial layout ``P0`` and parameters."""

    name: str  # "<mesh>/<init>/<step>"
    mesh_name: str
    mesh: Mesh
    init: str
    positions: np.ndarray  # P0, (V, 2)
    params: FlattenParams

    @property
    def step(self) -> str:
        return self.params.step

    @property
    def mean_edge(self) -> float:
        return float(self.mesh.rest_lengths.mean())

    @property
    def work(self) -> int:
        """A run-time estimate (entries × iteration budget), for scheduling."""
        return (2 * self.mesh.n_edges + self.mesh.n_vertices) * self.params.max_iter


_GENERATED: dict[str, Mesh] | None = None


def resolve_study_mesh(name: str) -> tuple[str, Mesh, FlattenParams]:
    """``(display name, mesh, default parameters)`` for a built-in, generated or file mesh.

    Built-ins take their paper parameter sets (jacobi, no damping); generated
    and file meshes take :data:`GENERATED_PARAMS`.
    """
    global _GENERATED
    path = Path(name)
    if is_builtin(name) and not path.is_file():
        mesh, paper = builtin_mesh(name)
        return name.lower(), mesh, FlattenParams(spring=paper.spring, density=paper.density,
                                                 tol_area=paper.tol_area, tol_shape=paper.tol_shape,
                                                 tol_energy=paper.tol_energy, max_iter=paper.max_iter)
    if name.lower() in GENERATED_MESH_NAMES and not path.is_file():
        if _GENERATED is None:
            from .generate import generated_meshes

            _GENERATED = generated_meshes()
        return name.lower(), _GENERATED[name.lower()], GENERATED_PARAMS
    if path.is_file():
        return path.stem, load_mesh(path), GENERATED_PARAMS
    raise ParameterError(f"unknown mesh '{name}': expected one of {', '.join(STUDY_MESHES)} or a mesh file")


def build_cases(meshes: Sequence[str] = STUDY_MESHES, inits: Sequence[str] = ("pca", "tutte"),
                steps: Sequence[str] = ("fixed", "variable"), max_iter: int | None = None) -> list[StudyCase]:
    """Every combination mesh × init × step (meshes in the given order, duplicates dropped)."""
    if not meshes:
        raise ParameterError("no meshes to study")
    for init in inits:
        if init not in ("pca", "tutte"):
            raise ParameterError(f"unknown initial layout '{init}': expected pca or tutte")
    cases: list[StudyCase] = []
    seen: set[str] = set()
    for spec in meshes:
        label, mesh, params = resolve_study_mesh(spec)
        if label in seen:
            if spec.lower() in seen:
                continue  # the same mesh twice
            k = 2
            while f"{label}-{k}" in seen:
                k += 1
            label = f"{label}-{k}"
        seen.add(label)
        if max_iter is not None:
            params = params.with_(max_iter=max_iter)
        for init in inits:
            p0 = initial_layout(mesh, init)
            for step in steps:
                cases.append(StudyCase(f"{label}/{init}/{step}", label, mesh, init, p0, params.with_(step=step)))
    return cases


# ----------------------------------------------------------------------------- knobs

SIGNAL_CLASSES: dict[str, tuple[str, ...]] = {
    "position": ("position", "delta", "face_edge"),
    "velocity": ("velocity",),
    "length_sq": ("length_sq",),
    "rsqrt": ("rsqrt",),
    "rest_length": ("rest_length", "error_acc", "face_area"),
    "spring": ("spring",),
    "force": ("force", "force_acc"),
    "inv_mass": ("inv_mass",),
    "accel": ("accel",),
    "dt": ("dt", "lut_entry"),
    "half_dt_sq": ("half_dt_sq",),
    "error": ("error", "reciprocal"),
    "damping": ("damping",),
    "area": ("area",),
    "barrier": ("barrier_gain", "barrier_coeff"),
    "power": ("power", "power_acc"),
}
"""Signal classes whose fraction bits are swept: name -> tied format fields.

All fields of a class shift by the same number of fraction bits (their offsets
in the base set are kept); the class's value is the first field's fraction bits.
"""
assert sorted(f for fs in SIGNAL_CLASSES.values() for f in fs) == sorted(FORMAT_FIELDS)

DATAPATH_FIELDS: tuple[str, ...] = tuple(f for f in FORMAT_FIELDS
                                         if f not in ("error", "lut_entry") + CONTROLLER_FIELDS)
"""Formats of the node datapath counted by ``total_bits`` (the step generator's and the controller's are not)."""

OTHER_KNOB_VALUES: dict[str, tuple[Any, ...]] = {
    "lut_index_bits": (4, 5, 6, 7, 10, 12),
    "lut_interpolate": (True, False),
    "rsqrt_seed_bits": (4, 6, 8, 10, 12, 14),
    "rsqrt_newton_steps": (0, 1, 2),
    "rounding": tuple(r.value for r in Rounding),
}
"""Values tried by the sweep of each non-format knob (the base's value is skipped)."""

KNOBS: tuple[str, ...] = tuple(SIGNAL_CLASSES) + tuple(OTHER_KNOB_VALUES)
"""Everything ``--sweep`` accepts (``frac`` selects every signal class)."""

DEFAULT_BITS = (8, 24, 4)
"""Fraction bits a signal-class sweep tries by default: ``range(8, 24 + 1, 4)``."""

DEFAULT_STRIDES = (1, 2, 4, 8)
"""Fraction bits one optimiser move may remove from a signal class."""


def parse_bits(text: str) -> tuple[int, int, int]:
    """``"MIN:MAX"`` or ``"MIN:MAX:STEP"`` -> ``(min, max, step)``; ParameterError otherwise."""
    parts = str(text).split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        lo, hi = int(parts[0]), int(parts[1])
        step = int(parts[2]) if len(parts) == 3 else 1
    except ValueError:
        raise ParameterError(f"--bits expects MIN:MAX or MIN:MAX:STEP (integers), got '{text}'") from None
    if not 0 <= lo <= hi <= 60 or step < 1:
        raise ParameterError(f"--bits {text}: need 0 <= MIN <= MAX <= 60 and STEP >= 1")
    return lo, hi, step


def parse_knobs(text: str | Sequence[str] | None) -> list[str]:
    """A comma list of knobs (``all``, ``frac``, ``none`` allowed) -> knob names in :data:`KNOBS` order."""
    if text is None:
        return list(KNOBS)
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text) if t.strip()]
    if not items:
        raise ParameterError("--sweep: empty knob list (use 'none' for no sweep)")
    chosen: set[str] = set()
    for item in items:
        low = item.lower()
        if low == "none":
            continue
        if low == "all":
            chosen.update(KNOBS)
        elif low == "frac":
            chosen.update(SIGNAL_CLASSES)
        elif low in KNOBS:
            chosen.add(low)
        else:
            raise ParameterError(f"--sweep: unknown knob '{item}'; expected all, none, frac or some of "
                                 f"{', '.join(KNOBS)}")
    return [k for k in KNOBS if k in chosen]


@dataclass(frozen=True)
class Config:
    """One configuration of a study: a FormatSet, or the reason it could not be built."""

    label: str
    fs: FormatSet | None
    kind: str = "sweep"  # base | preset | sweep | optimiser | chosen
    knob: str = ""
    value: Any = ""
    error: str = ""

    @property
    def key(self) -> str | None:
        return None if self.fs is None else fs_key(self.fs)


def fs_key(fs: FormatSet) -> str:
    """Identity of a FormatSet's contents (name and notes ignored)."""
    d = fs.to_dict()
    d.pop("name", None)
    d.pop("notes", None)
    return json.dumps(d, sort_keys=True)


def class_frac_bits(fs: FormatSet, cls: str) -> int:
    """A signal class's fraction bits (its first field's)."""
    return getattr(fs, SIGNAL_CLASSES[cls][0]).frac_bits


def class_changes(fs: FormatSet, cls: str, bits: int) -> dict[str, str]:
    """Format changes that give class ``cls`` ``bits`` fraction bits (tied fields shift with it)."""
    shift = bits - class_frac_bits(fs, cls)
    changes = {}
    for f in SIGNAL_CLASSES[cls]:
        fmt = getattr(fs, f)
        if fmt.frac_bits + shift < 0:
            raise ValueError(f"{f} would have {fmt.frac_bits + shift} fraction bits")
        changes[f] = f"{'s' if fmt.signed else 'u'}{fmt.int_bits}.{fmt.frac_bits + shift}"
    return changes


def make_config(base: FormatSet, label: str, kind: str = "sweep", knob: str = "", value: Any = "",
                **changes: Any) -> Config:
    """``base`` with ``changes``; a refused combination becomes a Config with ``error`` set."""
    try:
        fs = base.replace(name=label, notes={}, **changes)
    except ValueError as exc:
        return Config(label, None, kind, knob, value, str(exc).splitlines()[0])
    return Config(label, fs, kind, knob, value)


def _knob_config(base: FormatSet, knob: str, value: Any, kind: str = "sweep", label: str | None = None) -> Config:
    label = label or f"{knob}={value}"
    if knob in SIGNAL_CLASSES:
        try:
            changes = class_changes(base, knob, int(value))
        except ValueError as exc:
            return Config(label, None, kind, knob, value, str(exc))
        return make_config(base, label, kind, knob, value, **changes)
    return make_config(base, label, kind, knob, value, **{knob: value})


def sweep_configs(base: FormatSet, knobs: Iterable[str] | None = None,
                  bits: tuple[int, int, int] = DEFAULT_BITS) -> list[Config]:
    """One-knob-at-a-time variations of ``base`` (values equal to the base's are skipped).

    Signal classes take the fraction bits ``range(bits[0], bits[1] + 1, bits[2])``;
    other knobs take :data:`OTHER_KNOB_VALUES`.  Refused combinations are
    included with their error message.
    """
    lo, hi, step = bits
    configs = []
    for knob in (KNOBS if knobs is None else knobs):
        if knob in SIGNAL_CLASSES:
            current = class_frac_bits(base, knob)
            values: Iterable[Any] = [b for b in range(lo, hi + 1, step) if b != current]
        elif knob in OTHER_KNOB_VALUES:
            current = getattr(base, knob)
            current = current.value if isinstance(current, Rounding) else current
            values = [v for v in OTHER_KNOB_VALUES[knob] if v != current]
        else:
            raise ParameterError(f"unknown knob '{knob}'")
        configs += [_knob_config(base, knob, v) for v in values]
    return configs


def preset_configs(base: FormatSet | None = None) -> list[Config]:
    """The presets, for comparison (the one equal to ``base`` is left out)."""
    out = []
    for name in FormatSet.presets():
        fs = FormatSet.preset(name)
        if base is not None and fs_key(fs) == fs_key(base):
            continue
        out.append(Config(f"preset:{name}", fs, "preset"))
    return out


# ----------------------------------------------------------------------------- cost model

#: The units whose multipliers the RTL instantiates (the controller's are not in the RTL).
RTL_UNITS = ("node_update", "rsqrt", "step_generator")


def multipliers(fs: FormatSet) -> list[tuple[str, int, int, int, int]]:
    """``(name, width_a, width_b, count, dsp_blocks_each)`` for every multiplication of the RTL.

    ``fs.products()`` of the node datapath, the rsqrt unit and the step generator, each split
    into 18×18 partial products by the RTL's own rule (:func:`golden_model.fixed.dsp.dsp_blocks`:
    a partial product with a 1-bit slice is a multiplexer, not a DSP block).
    """
    return [(p.name, p.a.width, p.b.width, p.count, _dsp_blocks(p.a, p.b))
            for p in fs.products() if p.unit in RTL_UNITS]


def dsp_blocks(fs: FormatSet) -> int:
    """18×18 DSP blocks of the node datapath (with its rsqrt unit) and the step generator."""
    return sum(count * each for _, _, _, count, each in multipliers(fs))


def datapath_bits(fs: FormatSet) -> int:
    """Sum of the widths of the node-datapath formats (:data:`DATAPATH_FIELDS`)."""
    return sum(getattr(fs, f).width for f in DATAPATH_FIELDS)


def rom_bits(fs: FormatSet) -> int:
    """rsqrt seed ROM (entries × seed fraction bits) + exp LUT (2**n + 1 entries × lut_entry width)."""
    cfg = fs.rsqrt_config()
    return cfg.seed_table_size * cfg.seed_frac_bits + ((1 << fs.lut_index_bits) + 1) * fs.lut_entry.width


@dataclass(frozen=True)
class Cost:
    """Hardware cost estimate of a FormatSet."""

    total_bits: int
    dsp: int
    rom_bits: int

    def key(self, metric: str = "bits") -> tuple[int, int, int]:
        """Lexicographic comparison key: ``bits`` or ``dsp`` first."""
        if metric == "dsp":
            return (self.dsp, self.total_bits, self.rom_bits)
        return (self.total_bits, self.dsp, self.rom_bits)

    def value(self, metric: str = "bits") -> int:
        return self.dsp if metric == "dsp" else self.total_bits


def cost(fs: FormatSet) -> Cost:
    return Cost(datapath_bits(fs), dsp_blocks(fs), rom_bits(fs))


# ----------------------------------------------------------------------------- runs and records


@dataclass(frozen=True)
class AccuracyTarget:
    """What "meets the target" means for one run against the float reference."""

    error: float = 1e-3  # max |ΔE_S| and |ΔE_C| (final values)
    iterations: int = 1  # max |Δ iterations|
    status: bool = True  # the status (converged / max-iterations / diverged) must match
    saturations: int = 0  # max saturation events (beyond the error measures' own clamp: RunRecord.measure_clamps)

    def __post_init__(self) -> None:
        if not (isinstance(self.error, (int, float)) and math.isfinite(self.error) and self.error > 0):
            raise ParameterError(f"--target must be a positive number, got {self.error!r}")

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
        return abs(self.area_error_fixed - self.area_error_float)

    @property
    def d_shape(self) -> float:
        return abs(self.shape_error_fixed - self.shape_error_float)

    @property
    def deviation(self) -> float:
        """``max(|ΔE_S|, |ΔE_C|)`` (NaN when refused)."""
        return max(self.d_area, self.d_shape) if not self.error else math.nan

    @property
    def d_iterations(self) -> int:
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
            "iterations_float": self.iterations_float, "iterations_fixed": self.iterations_fixed,
            "d_iterations": self.d_iterations,
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
class _FixedOutcome:
    status: str
    iterations: int
    area_error: float
    shape_error: float
    positions: np.ndarray | None
    saturations: int
    saturation_events: dict
    error: str
    seconds: float


def _run_fixed(case: StudyCase, fs: FormatSet) -> _FixedOutcome:
    t0 = time.perf_counter()
    try:
        r = flatten_fixed(case.mesh, case.positions, case.params, fs)
    except ValueError as exc:  # FixedPointError: the mesh/parameters do not fit these formats
        return _FixedOutcome("refused", 0, math.nan, math.nan, None, 0, {}, str(exc).splitlines()[0],
                             time.perf_counter() - t0)
    return _FixedOutcome(r.status, r.iterations, r.final.area_error, r.final.shape_error, r.positions,
                         int(r.extra.get("saturations", 0)), dict(r.extra.get("saturation_events", {})), "",
                         time.perf_counter() - t0)


def _compare(case: StudyCase, ref: FlattenResult, out: _FixedOutcome) -> RunRecord:
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
    history = {"area_error": reference.history.area_error, "shape_error": reference.history.shape_error}
    return sum(min(events.get(name, 0), int((np.asarray(values) >= 1).sum())) for name, values in history.items())


_WORKER_CASES: list[StudyCase] | None = None


def _init_worker(cases: list[StudyCase]) -> None:
    global _WORKER_CASES
    _WORKER_CASES = cases
    # Ctrl-C reaches the whole process group: the parent stops the study (and says so in one line);
    # a worker finishes its run quietly instead of printing a traceback of its own
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _worker_task(fs: FormatSet, index: int) -> _FixedOutcome:
    return _run_fixed(_WORKER_CASES[index], fs)


def _case_task(case: StudyCase, fs: FormatSet) -> _FixedOutcome:
    """A run for an executor given to :class:`Study` (it has no initializer: the case travels with the task)."""
    return _run_fixed(case, fs)


# ----------------------------------------------------------------------------- summaries


@dataclass(frozen=True)
class ConfigSummary:
    """One configuration over all cases."""

    config: Config
    cost: Cost | None
    cases: int
    failed: int  # cases missing the target
    refused: int  # cases the engine refused (or all, for an invalid configuration)
    worst_d_area: float
    worst_d_shape: float
    worst_deviation: float
    worst_max_position: float
    worst_rms_position: float
    max_abs_d_iterations: int
    status_mismatches: int
    saturations: int  # beyond the error measures' own clamp (RunRecord.measure_clamps)
    first_failure: str  # "<case>: <reason>"

    @property
    def meets(self) -> bool:
        return self.cases > 0 and self.failed == 0

    def row(self, metric: str = "bits") -> dict[str, Any]:
        """The ``summary.csv`` row."""
        c, fs = self.config, self.config.fs
        return {
            "config": c.label, "kind": c.kind, "knob": c.knob, "value": c.value,
            "total_bits": self.cost.total_bits if self.cost else "", "dsp": self.cost.dsp if self.cost else "",
            "rom_bits": self.cost.rom_bits if self.cost else "",
            "cases": self.cases, "failed_cases": self.failed, "refused_cases": self.refused,
            "worst_d_area_error": self.worst_d_area, "worst_d_shape_error": self.worst_d_shape,
            "worst_deviation": self.worst_deviation, "worst_max_position_error": self.worst_max_position,
            "worst_rms_position_error": self.worst_rms_position, "max_abs_d_iterations": self.max_abs_d_iterations,
            "status_mismatches": self.status_mismatches, "saturations": self.saturations,
            "meets_target": int(self.meets), "first_failure": self.first_failure,
            "formats": " ".join(f"{f}={getattr(fs, f)}" for f in FORMAT_FIELDS) if fs else "",
            "knobs": (f"seed={fs.rsqrt_seed_bits} newton={fs.rsqrt_newton_steps} lut={fs.lut_index_bits}"
                      f"{'i' if fs.lut_interpolate else ''} {fs.rounding.value}") if fs else "",
            "error": c.error,
        }


def _nanmax(values: Iterable[float]) -> float:
    vals = [v for v in values if not math.isnan(v)]
    return max(vals) if vals else math.nan


def summarise(config: Config, records: Sequence[RunRecord], target: AccuracyTarget) -> ConfigSummary:
    """Aggregate a configuration's records (worst case over the cases)."""
    failed, first = 0, ""
    for r in records:
        why = target.failures(r)
        if why:
            failed += 1
            first = first or f"{r.case}: {'; '.join(why)}"
    if config.fs is None and not records:
        first = f"invalid: {config.error}"
    return ConfigSummary(
        config, cost(config.fs) if config.fs is not None else None, len(records), failed,
        sum(1 for r in records if r.error),
        _nanmax(r.d_area for r in records if not r.error), _nanmax(r.d_shape for r in records if not r.error),
        _nanmax(r.deviation for r in records), _nanmax(r.max_position_error for r in records),
        _nanmax(r.rms_position_error for r in records),
        max((abs(r.d_iterations) for r in records), default=0),
        sum(1 for r in records if not r.error and not r.status_match),
        sum(r.saturations - r.measure_clamps for r in records), first)


# ----------------------------------------------------------------------------- the study

Progress = Callable[[str, int], None]
"""``progress(phase, runs_done)``: called after each fixed-point run (phase ``sweep`` or ``optimise``)."""


@dataclass(frozen=True)
class OptimiseStep:
    """An accepted move of the greedy optimiser."""

    move: str
    config: Config
    cost: Cost
    worst_deviation: float
    rejected: int  # moves rejected in this round before this one was accepted


@dataclass
class OptimiseResult:
    """The optimiser's path and result (``best`` is None when the base misses the target)."""

    base: Config
    metric: str
    best: Config | None
    steps: list[OptimiseStep] = field(default_factory=list)
    rejected: list[tuple[str, str]] = field(default_factory=list)  # (move tried from the final config, reason)
    runs: int = 0  # fixed-point runs the optimiser performed (cache hits excluded)
    candidates: int = 0  # candidate configurations tried
    reason: str = ""


class Study:
    """Cases, their cached float references and a cache of fixed-point runs.

    Use as a context manager when ``workers > 1`` (the worker pool is closed on exit).  ``executor``, a
    ``concurrent.futures.Executor`` of the caller's (a Dask cluster's, say), runs the fixed-point runs instead
    of a pool of ``workers`` processes; ``workers`` then only bounds the runs in flight when a stop rule
    may end a phase early.  The caller shuts it down.
    """

    def __init__(self, cases: Sequence[StudyCase], target: AccuracyTarget = AccuracyTarget(), workers: int = 1,
                 progress: Progress | None = None, executor: Executor | None = None):
        if not cases:
            raise ParameterError("a study needs at least one case")
        names = [c.name for c in cases]
        if len(set(names)) != len(names):
            raise ParameterError("study case names must be unique")
        self.cases = list(cases)
        self.target = target
        self.workers = max(1, int(workers))
        self.progress = progress
        self._float: dict[str, FlattenResult] = {}
        self._runs: dict[tuple[str, str], RunRecord] = {}  # (fs_key, case) -> record (config label "")
        self._configs: dict[str, Config] = {}  # label -> fully evaluated config
        self._pool: ProcessPoolExecutor | None = None
        self._external = executor
        self._fail_counts = {c.name: 0 for c in self.cases}
        self._knob_failure: dict[str, str] = {}  # knob -> the case that last failed a change of it
        self.runs = 0

    # -- plumbing
    def __enter__(self) -> "Study":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def _executor(self) -> Executor | None:
        if self._external is not None:
            return self._external
        if self.workers <= 1:
            return None
        if self._pool is None:
            self._pool = ProcessPoolExecutor(self.workers, initializer=_init_worker, initargs=(self.cases,))
        return self._pool

    def float_result(self, case: StudyCase) -> FlattenResult:
        """The float reference of ``case`` (computed once)."""
        if case.name not in self._float:
            self._float[case.name] = flatten(case.mesh, case.positions, case.params)
        return self._float[case.name]

    def _record(self, fs: FormatSet, index: int, outcome: _FixedOutcome) -> RunRecord:
        case = self.cases[index]
        rec = _compare(case, self.float_result(case), outcome)
        self._runs[(fs_key(fs), case.name)] = rec
        self.runs += 1
        return rec

    def _execute(self, tasks: list[tuple[FormatSet, int]], phase: str,
                 stop: Callable[[RunRecord], bool] | None = None) -> bool:
        """Run the (fs, case index) tasks not in the cache; False if ``stop`` fired."""
        tasks = [(fs, i) for fs, i in tasks if (fs_key(fs), self.cases[i].name) not in self._runs]
        for _, i in tasks:  # float references first, in this process
            self.float_result(self.cases[i])
        pool = self._executor()
        if pool is None:
            for fs, i in tasks:
                rec = self._record(fs, i, _run_fixed(self.cases[i], fs))
                if self.progress:
                    self.progress(phase, 1)
                if stop is not None and stop(rec):
                    return False
            return True
        limit = len(tasks) if stop is None else self.workers
        pending: dict[Future, tuple[FormatSet, int]] = {}
        queue = list(tasks)
        stopped = False
        while queue or pending:
            while queue and len(pending) < limit and not stopped:
                fs, i = queue.pop(0)
                future = (pool.submit(_worker_task, fs, i) if self._external is None
                          else pool.submit(_case_task, self.cases[i], fs))
                pending[future] = (fs, i)
            if not pending:
                break
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                fs, i = pending.pop(fut)
                rec = self._record(fs, i, fut.result())
                if self.progress:
                    self.progress(phase, 1)
                if stop is not None and stop(rec):
                    stopped = True
            if stopped:
                queue.clear()
        return not stopped

    def records(self, config: Config) -> list[RunRecord]:
        """The records of an evaluated configuration, in case order, labelled."""
        if config.fs is None:
            return [RunRecord(config.label, c.name, c.mesh_name, c.init, c.step, self.float_result(c).status,
                              "refused", self.float_result(c).iterations, 0,
                              self.float_result(c).final.area_error, math.nan,
                              self.float_result(c).final.shape_error, math.nan, math.nan, math.nan, 0, "",
                              f"invalid configuration: {config.error}") for c in self.cases]
        key = config.key
        return [replace(self._runs[(key, c.name)], config=config.label) for c in self.cases]

    def evaluate(self, configs: Sequence[Config], phase: str = "sweep") -> list[ConfigSummary]:
        """Run every configuration on every case (cached) and summarise."""
        order = sorted(range(len(self.cases)), key=lambda i: -self.cases[i].work)
        tasks = [(c.fs, i) for c in configs if c.fs is not None for i in order]
        self._execute(tasks, phase)
        out = []
        for c in configs:
            self._configs[c.label] = c
            out.append(self.summary(c))
        return out

    def summary(self, config: Config) -> ConfigSummary:
        return summarise(config, self.records(config), self.target)

    @property
    def evaluated(self) -> list[Config]:
        """Every fully evaluated configuration, in evaluation order."""
        return list(self._configs.values())

    def meets(self, config: Config, phase: str = "optimise") -> tuple[bool, str]:
        """Does ``config`` meet the target on every case?  Stops at the first failing case.

        Cases run in order: the case that last failed a change of the same knob,
        then by past failures (most first), then the quickest, so a bad
        candidate is usually rejected after one or two runs.  Returns
        ``(ok, reason of the first failure)``.
        """
        if config.fs is None:
            return False, f"invalid: {config.error}"
        hint = self._knob_failure.get(config.knob)
        order = sorted(range(len(self.cases)), key=lambda i: (self.cases[i].name != hint,
                                                              -self._fail_counts[self.cases[i].name],
                                                              self.cases[i].work, i))
        failure: list[str] = []

        def stop(rec: RunRecord) -> bool:
            why = self.target.failures(rec)
            if why:
                failure.append(f"{rec.case}: {'; '.join(why)}")
                self._fail_counts[rec.case] += 1
                if config.knob:
                    self._knob_failure[config.knob] = rec.case
                return True
            return False

        key = config.key
        for i in order:  # cache hits first: a cached failure decides at once
            rec = self._runs.get((key, self.cases[i].name))
            if rec is not None and stop(rec):
                return False, failure[0]
        if not self._execute([(config.fs, i) for i in order], phase, stop):
            return False, failure[0]
        return True, ""

    # -- the optimiser
    def _sweep_table(self) -> dict[str, list[tuple[Any, float, bool]]]:
        """knob -> [(value, worst deviation, meets)] of the evaluated one-knob sweep configs."""
        table: dict[str, list[tuple[Any, float, bool]]] = {}
        for c in self._configs.values():
            if c.kind == "sweep" and c.fs is not None:
                s = self.summary(c)
                table.setdefault(c.knob, []).append((c.value, s.worst_deviation, s.meets))
        return table

    def _sensitivity(self, base: FormatSet) -> tuple[Callable[[str, Any], float], Callable[[str, Any], str]]:
        """From the sweep: ``estimate(knob, value)`` (badness, lower = safer) and
        ``pruned(knob, value)`` (why the sweep shows the move cannot meet the target, or "").

        A value is pruned when the sweep ran ``knob`` at that value or a *cheaper*
        one between it and the base value with everything else at the base, and
        missed the target: removing more precision on top is assumed not to help.
        """
        table = self._sweep_table()

        def numeric(v: Any) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool)

        def base_value(knob: str) -> Any:
            if knob in SIGNAL_CLASSES:
                return class_frac_bits(base, knob)
            v = getattr(base, knob)
            return v.value if isinstance(v, Rounding) else v

        def estimate(knob: str, value: Any) -> float:
            entries = [e for e in table.get(knob, ()) if numeric(e[0])]
            if not entries or not numeric(value):
                return 0.0
            below = [e for e in entries if e[0] <= value]
            if not below:
                return math.inf
            v, dev, ok = max(below, key=lambda e: e[0])
            return dev if ok else math.inf

        def pruned(knob: str, value: Any) -> str:
            ref = base_value(knob)
            for v, _, ok in table.get(knob, ()):
                if ok:
                    continue
                if numeric(value) and numeric(v) and numeric(ref) and value <= v < ref:
                    return f"pruned: the sweep's {knob}={v} already misses the target"
                if not numeric(value) and v == value:
                    return f"pruned: the sweep's {knob}={v} already misses the target"
            return ""

        return estimate, pruned

    @staticmethod
    def _moves(fs: FormatSet, strides: Sequence[int] = (1,)) -> list[tuple[str, str, Any, dict[str, Any]]]:
        """Cost-reducing single moves from ``fs``: ``(name, knob, value, changes)``."""
        moves = []
        for cls in SIGNAL_CLASSES:
            for k in sorted(set(strides) | {1}):
                bits = class_frac_bits(fs, cls) - k
                try:
                    moves.append((f"{cls} frac -{k}", cls, bits, class_changes(fs, cls, bits)))
                except ValueError:
                    break
        if fs.lut_index_bits > 1:
            moves.append(("lut_index_bits -1", "lut_index_bits", fs.lut_index_bits - 1,
                          {"lut_index_bits": fs.lut_index_bits - 1}))
        if fs.rsqrt_seed_bits > 2:
            moves.append(("rsqrt_seed_bits -1", "rsqrt_seed_bits", fs.rsqrt_seed_bits - 1,
                          {"rsqrt_seed_bits": fs.rsqrt_seed_bits - 1}))
        if fs.rsqrt_newton_steps > 0:
            moves.append(("rsqrt_newton_steps -1", "rsqrt_newton_steps", fs.rsqrt_newton_steps - 1,
                          {"rsqrt_newton_steps": fs.rsqrt_newton_steps - 1}))
        if fs.lut_interpolate:
            moves.append(("lut_interpolate off", "lut_interpolate", False, {"lut_interpolate": False}))
        return moves

    def optimise(self, base: Config | FormatSet, metric: str = "bits", strides: Sequence[int] = DEFAULT_STRIDES,
                 prune: bool = True, max_rounds: int = 10_000) -> OptimiseResult:
        """Greedy word-length reduction from ``base`` (see the module docstring).

        ``strides``: fraction-bit reductions a signal-class move may make at
        once (1 is always included).  Larger strides only make the search
        faster: the result is always checked against every single-bit move.
        ``prune``: skip moves the one-knob sweep already shows to miss the
        target (see :meth:`_sensitivity`; needs the sweep evaluated first).
        """
        if metric not in ("bits", "dsp"):
            raise ParameterError(f"cost metric must be bits or dsp, got {metric!r}")
        if isinstance(base, FormatSet):
            base = Config(f"base:{base.name}", base, "base")
        runs0 = self.runs
        result = OptimiseResult(base, metric, None)
        self.evaluate([base], phase="optimise")
        ok, why = self.meets(base)
        if not ok:
            result.reason = f"the base configuration misses the target ({why})"
            result.runs = self.runs - runs0
            return result
        sensitivity, pruned = self._sensitivity(base.fs) if prune else (self._sensitivity(base.fs)[0], None)
        current = base
        frozen: set[str] = set()
        rechecked = False
        for round_no in range(1, max_rounds + 1):
            cur_key = cost(current.fs).key(metric)
            candidates = []
            # a recheck round tries single-bit moves only
            for idx, (name, knob, value, changes) in enumerate(self._moves(current.fs, (1,) if rechecked else strides)):
                if name in frozen or (pruned is not None and pruned(knob, value)):
                    continue
                cfg = make_config(current.fs, f"try-{round_no:03d}", "optimiser", knob, value, **changes)
                if cfg.fs is None:
                    frozen.add(name)
                    continue
                c_key = cost(cfg.fs).key(metric)
                if c_key >= cur_key:
                    continue
                candidates.append((c_key, sensitivity(knob, value), idx, name, knob, cfg))
            candidates.sort(key=lambda t: t[:3])
            accepted = None
            rejected = 0
            for _, _, _, name, knob, cfg in candidates:
                if name in frozen:  # frozen by a smaller stride's failure in this round
                    continue
                result.candidates += 1
                ok, _ = self.meets(cfg)
                if ok:
                    accepted = (name, cfg)
                    break
                rejected += 1
                frozen.add(name)
                if knob in SIGNAL_CLASSES:  # fewer bits than a failing value: assume failing too
                    stride = int(name.rsplit("-", 1)[1])
                    frozen.update(f"{knob} frac -{k}" for k in strides if k > stride)
            if accepted is not None:
                name, cfg = accepted
                label = f"opt-{len(result.steps) + 1:02d}"
                cfg = replace(cfg, label=label, fs=cfg.fs.replace(name=label))
                summary = self.evaluate([cfg], phase="optimise")[0]
                result.steps.append(OptimiseStep(name, cfg, summary.cost, summary.worst_deviation, rejected))
                current = cfg
                rechecked = False
                if cfg.knob in SIGNAL_CLASSES:  # the class took bits off: let it try the larger strides again
                    frozen.difference_update({f"{cfg.knob} frac -{k}" for k in strides})
                continue
            if frozen and not rechecked:
                frozen.clear()  # retry every move once against the final configuration
                rechecked = True
                continue
            break
        # why each single-bit move fails from the final configuration (cached after the recheck)
        for name, knob, value, changes in self._moves(current.fs):
            cfg = make_config(current.fs, "check", "optimiser", knob, value, **changes)
            if cfg.fs is None:
                result.rejected.append((name, f"invalid: {cfg.error}"))
            elif cost(cfg.fs).key(metric) >= cost(current.fs).key(metric):
                result.rejected.append((name, "does not reduce the cost"))
            elif pruned is not None and pruned(knob, value):
                result.rejected.append((name, pruned(knob, value)))
            else:
                ok, why = self.meets(cfg)
                result.rejected.append((name, "meets the target (round limit reached)" if ok else why))
        result.best = current
        result.runs = self.runs - runs0
        return result

    def cheapest(self, metric: str = "bits") -> ConfigSummary | None:
        """The cheapest fully evaluated configuration that meets the target (ties: smaller deviation)."""
        meeting = [s for s in (self.summary(c) for c in self._configs.values()) if s.meets]
        if not meeting:
            return None
        return min(meeting, key=lambda s: (s.cost.key(metric), s.worst_deviation))


# ----------------------------------------------------------------------------- one call


@dataclass
class StudyResult:
    """Everything a study produced (``summaries`` in evaluation order)."""

    cases: list[StudyCase]
    target: AccuracyTarget
    metric: str
    base: Config
    summaries: list[ConfigSummary]
    records: list[RunRecord]
    optimisation: OptimiseResult | None
    chosen: ConfigSummary | None
    floats: dict[str, FlattenResult]
    seconds: float
    runs: int
    bits: tuple[int, int, int]
    knobs: list[str]

    def summary_of(self, label: str) -> ConfigSummary | None:
        return next((s for s in self.summaries if s.config.label == label), None)


def run_study(cases: Sequence[StudyCase], base: FormatSet, knobs: Sequence[str] | None = None,
              bits: tuple[int, int, int] = DEFAULT_BITS, target: AccuracyTarget = AccuracyTarget(),
              metric: str = "bits", optimise: bool = True, workers: int = 1, presets: bool = True,
              strides: Sequence[int] = DEFAULT_STRIDES, progress: Progress | None = None,
              executor: Executor | None = None) -> StudyResult:
    """Base + presets + one-knob sweeps, then (optionally) the greedy optimiser; pick the cheapest.

    ``executor`` runs the fixed-point runs instead of a pool of ``workers`` processes (see :class:`Study`).
    """
    t0 = time.perf_counter()
    knobs = list(KNOBS) if knobs is None else list(knobs)
    base_cfg = Config(f"base:{base.name}", base, "base")
    configs = [base_cfg] + (preset_configs(base) if presets else []) + sweep_configs(base, knobs, bits)
    with Study(cases, target, workers, progress, executor) as study:
        study.evaluate(configs, phase="sweep")
        opt = study.optimise(base_cfg, metric, strides) if optimise else None
        chosen = study.cheapest(metric)
        evaluated = study.evaluated
        summaries = [study.summary(c) for c in evaluated]
        records = [r for c in evaluated for r in study.records(c)]
        floats = {c.name: study.float_result(c) for c in study.cases}
        runs = study.runs
    return StudyResult(list(cases), target, metric, base_cfg, summaries, records, opt, chosen, floats,
                       time.perf_counter() - t0, runs, tuple(bits), knobs)
