"""The fixed-point controller's own loop: an integer stopping rule (golden_model.fixed.engine)."""

import math

import numpy as np
import pytest

from golden_model.fixed import FormatSet, SaturationCounter
from golden_model.fixed.engine import (
    ENERGY_TOL_FRAC_BITS,
    FixedEngine,
    StopRule,
    energy_to_float,
    flatten_fixed,
    prepare,
)
from golden_model.fixed.measures import FixedPointError, energy_raw
from golden_model.fixed.pipeline import exact_sum, node_terms
from sim.generate import spherical_cap
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from golden_model.reference import SpringModel, barrier_energy, measure

DEFAULT = FormatSet.preset("default")


def test_tolerances_are_floored_to_the_error_lsb():
    """A raw error (at most error's maximum) passes the integer test exactly when its value passes the float
    one; a tolerance past float's range once scaled (1e303) is one as well."""
    lsb = 2.0 ** -DEFAULT.error.frac_bits
    for tol in (0.0, lsb, 0.01, 0.4, 0.4 + lsb / 3, 1.0, 2.5, 1e303):
        rule = StopRule.of(FlattenParams(tol_area=tol, tol_shape=tol), DEFAULT)
        for raw in range(max(0, rule.area - 3), min(rule.area + 4, DEFAULT.error.raw_max + 1)):
            assert (raw <= rule.area) == (raw * lsb <= tol), (tol, raw)
            assert (raw <= rule.shape) == (raw * lsb <= tol), (tol, raw)


def test_relative_energy_change_in_integers():
    rule = StopRule.of(FlattenParams(tol_area=1.0, tol_shape=1.0, tol_energy=1e-3), DEFAULT)
    assert rule.energy == round(1e-3 * 2**ENERGY_TOL_FRAC_BITS)
    before = 10**12
    assert rule.converged(before, before + 10**9 - 10**6, (0, 0))  # 0.999e-3: below ε
    assert not rule.converged(before, before + 10**9 + 10**6, (0, 0))  # 1.001e-3: above
    assert rule.converged(before, before - 10**9 + 10**6, (0, 0))  # decreasing alike
    assert not rule.converged(before, before, (rule.area + 1, 0))  # errors still gate it
    assert rule.converged(0, 0, (0, 0)) and not rule.converged(0, 1, (0, 0))


def test_a_tolerance_below_the_resolution_is_refused():
    mesh = spherical_cap(3)
    params = FlattenParams(tol_energy=1e-14)
    with pytest.raises(FixedPointError, match=r"--tol-energy 1e-14 is below the controller's resolution 2\^-40"):
        flatten_fixed(mesh, initial_layout(mesh, "tutte"), params, DEFAULT)


def test_exact_sum_of_large_int64_values():
    values = np.full(1000, (1 << 61) + 12345, dtype=np.int64)
    assert exact_sum(values) == 1000 * ((1 << 61) + 12345)  # np.sum would wrap


@pytest.mark.parametrize("barrier", [False, True])
def test_integer_energy_is_the_float_energy_of_the_same_layout(barrier):
    """3·(½C·Σe² + barrier) in integers, reported in mesh units: the float model's energy of the
    same (fixed-point) layout, the barrier's part included."""
    mesh = spherical_cap(5)
    p0 = 0.6 * initial_layout(mesh, "tutte")  # compressed: every triangle inside the barrier
    params = FlattenParams(dynamics="momentum", barrier=barrier)
    problem = prepare(mesh, p0, params, DEFAULT)
    engine = FixedEngine(problem, SaturationCounter())
    engine.measure()
    positions = engine.positions
    model = SpringModel.build(mesh, positions, params.spring, "auto")
    expected = measure(model, positions).energy
    if barrier:
        part = barrier_energy(positions, mesh.faces, mesh.face_areas, problem.winding, params.barrier_threshold,
                              params.barrier_gain, params.spring)
        assert part > 0.05 * expected  # the barrier's share is there to be checked
        expected += part
    got = energy_to_float(problem, energy_raw(problem.fs, problem.half_spring, engine.terms.error_square_sum,
                                              engine.terms.barrier_energy_sum))
    assert math.isclose(got, expected, rel_tol=1e-4), (got, expected)


def test_the_loop_stops_on_the_integer_rule():
    """flatten_fixed stops at the first iteration whose energy change over the window passes, and not before."""
    mesh = spherical_cap(4)
    params = FlattenParams(dynamics="momentum", tol_area=1.0, tol_shape=1.0, tol_energy=1e-4, max_iter=500)
    result = flatten_fixed(mesh, initial_layout(mesh, "tutte"), params, DEFAULT)
    assert result.status == "converged" and 1 < result.iterations < 500
    window, energies, taken = params.energy_window, result.history.energy, result.history.accepted

    def change(k):  # the window ending at iteration k, if it holds a taken step
        if k < window or not any(taken[k - window + 1:k + 1]):
            return None
        return abs(energies[k] - energies[k - window]) / energies[k - window]

    last = result.iterations
    assert change(last) <= 1e-4 * (1 + 1e-6)
    assert all(change(k) is None or change(k) > 1e-4 * (1 - 1e-6) for k in range(last))
