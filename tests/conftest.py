"""Fixtures shared by the test packages (tests/golden_model, tests/hdl, tests/sim).

Plain helpers and paths are in :mod:`support` (``tests/support/``), importable from any test.
"""

from __future__ import annotations

import signal

import pytest

from sim.cocotb_support import SIMULATORS
from support import LONGEST_FIRST, TESTS, need_simulator, refused_components


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


def pytest_configure(config) -> None:
    """Ctrl-C answered as in a terminal, for the tests that send one to a command run in-process: a shell without
    job control (a script's ``make test &``) starts its background jobs with SIGINT ignored, and a command leaves
    an ignored signal ignored (``nohup``'s SIGHUP), so those tests would test the launcher, not the command. Each
    xdist worker runs this too."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """:data:`LONGEST_FIRST` first; otherwise collection order (a stable sort: each file's tests together)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}

    def key(item: pytest.Item) -> int:
        try:
            return rank.get(item.path.resolve().relative_to(TESTS).as_posix(), len(rank))
        except ValueError:  # a test outside tests/
            return len(rank)

    items.sort(key=key)
