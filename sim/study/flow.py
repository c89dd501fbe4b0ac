"""The study flow: runs over a process pool, summaries with costs, the greedy optimiser."""

from __future__ import annotations

import math
import time
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable, Sequence

from golden_model.fixed.format import Rounding
from golden_model.fixed.formats_set import FORMAT_FIELDS, FormatSet
from golden_model.params import ParameterError
from golden_model.reference import flatten
from golden_model.results import FlattenResult
from golden_model.study.cases import StudyCase
from golden_model.study.knobs import (
    DEFAULT_BITS, DEFAULT_STRIDES, KNOBS, SIGNAL_CLASSES, Config, class_frac_bits,
    class_changes, fs_key, make_config, preset_configs, sweep_configs, unexercised_classes,
)
from golden_model.study.records import AccuracyTarget, FixedOutcome, RunRecord, compare, run_fixed

from ..workers import WorkerPool, undo_dask_malloc_trim, wait_for_one
from .cost import Cost, cost

_WORKER_CASES: list[StudyCase] | None = None


def _init_worker(cases: list[StudyCase]) -> None:
    global _WORKER_CASES
    _WORKER_CASES = cases


def _worker_task(fs: FormatSet, index: int) -> FixedOutcome:
    return run_fixed(_WORKER_CASES[index], fs)


def _case_task(case: StudyCase, fs: FormatSet) -> FixedOutcome:
    """A run for an executor given to :class:`Study` (it has no initializer: the case travels with the task)."""
    undo_dask_malloc_trim()
    return run_fixed(case, fs)


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
    # None where no case ran (every one refused): no run, so nothing matched or differed
    max_abs_d_iterations: int | None
    status_mismatches: int | None
    saturations: int | None  # beyond the error measures' own clamp (RunRecord.measure_clamps)
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
            "worst_rms_position_error": self.worst_rms_position,
            **{name: "" if value is None else value for name, value in (
                ("max_abs_d_iterations", self.max_abs_d_iterations), ("status_mismatches", self.status_mismatches),
                ("saturations", self.saturations))},
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
    ran = [r for r in records if not r.error]
    return ConfigSummary(
        config, cost(config.fs) if config.fs is not None else None, len(records), failed,
        sum(1 for r in records if r.error),
        _nanmax(r.d_area for r in records if not r.error), _nanmax(r.d_shape for r in records if not r.error),
        _nanmax(r.deviation for r in records), _nanmax(r.max_position_error for r in records),
        _nanmax(r.rms_position_error for r in records),
        *((max(abs(r.d_iterations) for r in ran), sum(1 for r in ran if not r.status_match),
           sum(r.saturations - r.measure_clamps for r in ran)) if ran else (None, None, None)), first)


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
        #: classes no case reads (:func:`~golden_model.study.unexercised_classes`): the optimiser keeps them
        self.unexercised = unexercised_classes(c.params for c in self.cases)
        self.target = target
        self.workers = max(1, int(workers))
        self.progress = progress
        self._float: dict[str, FlattenResult] = {}
        self._runs: dict[tuple[str, str], RunRecord] = {}  # (fs_key, case) -> record (config label "")
        self._configs: dict[str, Config] = {}  # label -> fully evaluated config
        self._pool: WorkerPool | None = None
        self._external = executor
        self._fail_counts = {c.name: 0 for c in self.cases}
        self._knob_failure: dict[str, str] = {}  # knob -> the case that last failed a change of it
        self.runs = 0

    # -- plumbing
    def __enter__(self) -> "Study":
        return self

    def __exit__(self, exc_type, exc_value, traceback) -> None:
        if exc_type is not None and self._pool is not None:  # Ctrl-C, say: the runs in flight are not waited for
            self._pool.stop()
            self._pool = None
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
            self._pool = WorkerPool(self.workers, initializer=_init_worker, initargs=(self.cases,))
        return self._pool

    def float_result(self, case: StudyCase) -> FlattenResult:
        """The float reference of ``case`` (computed once)."""
        if case.name not in self._float:
            self._float[case.name] = flatten(case.mesh, case.positions, case.params)
        return self._float[case.name]

    def _record(self, fs: FormatSet, index: int, outcome: FixedOutcome) -> RunRecord:
        case = self.cases[index]
        rec = compare(case, self.float_result(case), outcome)
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
                rec = self._record(fs, i, run_fixed(self.cases[i], fs))
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
            done = wait_for_one(pending)
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

    def _moves(self, fs: FormatSet, strides: Sequence[int] = (1,)) -> list[tuple[str, str, Any, dict[str, Any]]]:
        """Cost-reducing single moves from ``fs``: ``(name, knob, value, changes)``; none of a class no case
        reads (:attr:`unexercised`)."""
        moves = []
        for cls in (c for c in SIGNAL_CLASSES if c not in self.unexercised):
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
        """The cheapest fully evaluated configuration that meets the target (ties: smaller deviation); a sweep of
        a class no case reads is none (its width changes no result here, so its saving is not one)."""
        meeting = [s for s in (self.summary(c) for c in self._configs.values())
                   if s.meets and not (s.config.kind == "sweep" and s.config.knob in self.unexercised)]
        if not meeting:
            return None
        return min(meeting, key=lambda s: (s.cost.key(metric), s.worst_deviation))


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
