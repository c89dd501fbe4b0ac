"""Fixtures shared by the test packages (tests/golden_model, tests/hdl, tests/sim).

Plain helpers and paths are in :mod:`support` (``tests/support/``), importable from any test.
"""

from __future__ import annotations

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
