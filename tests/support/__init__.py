"""What many test files share: the repository's paths, the console script, one-line errors, simulators.

Importable from every test (``pythonpath = ["tests"]`` in ``pyproject.toml``); the fixtures built on
these are in ``tests/conftest.py``.  ``support.streams`` and ``support.wishbone`` drive Amaranth-simulator
streams and Wishbone cycles, ``support.ram_traffic`` random block-RAM traffic.
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest

from golden_model.fixed import FormatSet

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
DATA = REPO / "tests" / "data"
SCANS = DATA / "scans"
SPRINGFLAT = str(Path(sys.executable).parent / "springflat")
"""The console script of this environment."""
TESTS = REPO / "tests"
PRESETS: tuple[str, ...] = tuple(FormatSet.presets())
"""Every preset format set (``golden_model/data/formats``): the tests that cover each take them from here."""

#: The test files that take longest (simulator builds, whole runs on simulators), in the order to start them,
#: longest first. ``make test`` hands whole files to its workers in collection order (``--dist loadfile
#: --no-loadscope-reorder``; pytest-xdist's default order, most tests first, started these last and left
#: one worker alone with them at the end); started first, the short files fill in around them.
LONGEST_FIRST = ("sim/test_cocotb.py", "sim/test_engine_rtl.py", "hdl/test_engine.py", "hdl/test_engine_lanes.py",
                 "hdl/test_engine_guard.py",
                 "sim/test_synth.py", "hdl/test_engine_saturation.py", "hdl/test_hdl_block_ram.py")


def press_ctrl_c(*args, **kwargs) -> None:
    """SIGINT to this process, as a Ctrl-C while the work goes on, for a test to put in place of a step of a
    command run in-process. The command's handler raises ``KeyboardInterrupt`` at once; where the signal lands in a
    finaliser (the garbage collector runs those anywhere) the handler sends it again a moment later
    (:func:`sim.outputs.on_interrupt`), and the work going on here (a few seconds of it) receives it as a real
    run would."""
    signal.raise_signal(signal.SIGINT)
    time.sleep(5)


def run_springflat(*args, cwd=None, timeout: float = 600) -> subprocess.CompletedProcess:
    """``springflat args...`` in a subprocess, text output captured."""
    return subprocess.run([SPRINGFLAT, *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=timeout)


def one_line(error) -> str:
    """The message of an exception (or a ``pytest.raises`` info), checked to be one non-empty line."""
    text = str(getattr(error, "value", error))
    assert text and "\n" not in text, repr(text)
    return text


def need_simulator(simulator: str) -> None:
    """Fail when ``simulator`` cannot run here (the set-up installs both); skip instead under
    ``SPRINGFLAT_ALLOW_MISSING_SIMULATOR``."""
    from sim.cocotb_support import missing_simulator

    reason = missing_simulator(simulator)
    if reason:
        if os.environ.get("SPRINGFLAT_ALLOW_MISSING_SIMULATOR"):
            pytest.skip(reason)
        pytest.fail(reason)


@contextlib.contextmanager
def refused_components():
    """For components whose ``__init__`` raises: Amaranth still reports each as unused when it is
    collected, so the warning is ignored and the objects collected before leaving."""
    from amaranth.hdl import UnusedElaboratable

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        yield
        gc.collect()


class BenchCalled(Exception):
    """Raised by :func:`record_bench_configs`' stand-in for ``run_bench``: the call was made, nothing simulated."""


def record_bench_configs(monkeypatch, module, export: str, directory: Path) -> list[dict]:
    """Replace ``module``'s ``run_bench`` with a stand-in that records each bench's config and raises
    :class:`BenchCalled`, and its export function ``export`` with one that returns ``directory``: what a flow
    hands the bench, without a build or a simulator. Returns the list the configs are appended to."""
    seen: list[dict] = []

    def bench(simulator, fs, toplevel, name, config, **kwargs):
        seen.append(config)
        raise BenchCalled

    monkeypatch.setattr(module, export, lambda *args, **kwargs: directory)
    monkeypatch.setattr(module, "run_bench", bench)
    return seen

