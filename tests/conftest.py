"""Fixtures shared by the test packages (tests/golden_model, tests/hdl, tests/sim).

Plain helpers and paths are in :mod:`support` (``tests/support/``), importable from any test.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from sim.cocotb_support import SIMULATORS
from support import need_simulator, refused_components


@pytest.fixture(params=SIMULATORS)
def simulator(request) -> str:
    """Each simulator in turn (Icarus, Verilator); a missing one fails the test (see ``need_simulator``)."""
    need_simulator(request.param)
    return request.param


@pytest.fixture
def unelaborated():
    """Components built only for their attributes (widths, port bits) are not reported as unused."""
    with refused_components():
        yield


#: The test files that take longest (simulator builds, whole runs on simulators), in the order to start them,
#: longest first. ``make test`` hands whole files to its workers in collection order (``--dist loadfile
#: --no-loadscope-reorder``; pytest-xdist's default order, most tests first, started these last and left
#: one worker alone with them at the end); started first, the short files fill in around them.
LONGEST_FIRST = ("sim/test_cocotb.py", "sim/test_engine_rtl.py", "hdl/test_engine.py", "hdl/test_engine_guard.py",
                 "sim/test_synth.py", "hdl/test_engine_saturation.py", "hdl/test_hdl_block_ram.py")
TESTS = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """:data:`LONGEST_FIRST` first; otherwise collection order (a stable sort: each file's tests together)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}

    def key(item: pytest.Item) -> int:
        try:
            return rank.get(item.path.resolve().relative_to(TESTS).as_posix(), len(rank))
        except ValueError:  # a test outside tests/
            return len(rank)

    items.sort(key=key)
