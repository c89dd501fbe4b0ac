"""Float reference: hand-computed values, gradients, update orders, convergence."""

import dataclasses
import math

import numpy as np
import pytest

from golden_model.builtin import builtin_mesh
from sim.layouts import initial_layout
from golden_model.mesh import Mesh
from golden_model.params import FlattenParams, ParameterError
from golden_model.reference import (
    SpringModel,
    flatten,
    measure,
    penalty_moves,
    spring_energy,
    spring_forces,
    variable_step,
)
from sim.generate import dome_grid, rolled_grid

SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]])
STRETCHED = np.array([[0, 0], [2, 0], [2, 1], [0, 1]], dtype=float)  # x doubled


def _model(mesh, positions, spring=0.5, density=2.0):
    return SpringModel.build(mesh, positions, spring, density)


def test_errors_and_energy_hand_computed():
    mesh = Mesh(SQUARE_V, SQUARE_F)
    m = measure(_model(mesh, STRETCHED), STRETCHED)
    # each triangle: 3D area 0.5, 2D area 1
    assert m.area_error == pytest.approx((0.5 + 0.5) / 1.0)
    # edges 0-1 and 2-3 double (1 -> 2), diagonal sqrt2 -> sqrt5, the others keep length 1
    assert m.shape_error == pytest.approx((1 + 1 + math.sqrt(5) - math.sqrt(2)) / (4 + math.sqrt(2)))
    assert m.energy == pytest.approx(0.5 * (1 + 1 + (math.sqrt(5) - math.sqrt(2)) ** 2))
    assert m.flipped == 0


def test_force_hand_computed():
    mesh = Mesh(SQUARE_V, SQUARE_F)
    f = spring_forces(STRETCHED, mesh.edges, mesh.rest_lengths, 0.5)
    # node 1: edge to 0 stretched 1 -> 2 pulls it by ½·C·(1 − 1/2)·(−2, 0); edge to 2 at rest
    assert f[1] == pytest.approx([-0.25, 0.0])
    assert f.sum(axis=0) == pytest.approx([0, 0], abs=1e-15)  # internal forces cancel


def test_flipped_counts_orientation_against_initial_layout():
    mesh = Mesh(SQUARE_V, SQUARE_F)
    model = _model(mesh, STRETCHED)
    folded = STRETCHED.copy()
    folded[1] = [-1.0, 0.5]  # node 1 through the diagonal: triangle 0 turns over
    assert measure(model, folded).flipped == 1


@pytest.mark.parametrize("seed", range(5))
def test_force_is_minus_quarter_energy_gradient(seed):
    mesh, _ = builtin_mesh("surf2")
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(mesh.n_vertices, 2))
    edges, rest = mesh.edges, mesh.rest_lengths

    def energy(p):
        d = p[edges[:, 1]] - p[edges[:, 0]]
        return spring_energy(np.hypot(d[:, 0], d[:, 1]), rest, 0.7)

    h = 1e-6
    gradient = np.zeros_like(positions)
    for i in range(mesh.n_vertices):
        for k in range(2):
            step = np.zeros_like(positions)
            step[i, k] = h
            gradient[i, k] = (energy(positions + step) - energy(positions - step)) / (2 * h)
    forces = spring_forces(positions, edges, rest, 0.7)
    assert np.allclose(forces, -0.25 * gradient, rtol=1e-6, atol=1e-8)


def test_variable_step_formula():
    # the paper: E_C = 0.717, E_S = 0.893 gives dt ≈ 0.092 in the first iteration
    assert variable_step(0.893, 0.717) == pytest.approx(0.0929, abs=5e-4)
    assert variable_step(0, 0) == pytest.approx(0.01 + 0.2 * math.exp(-5))
    assert variable_step(1, 1) == pytest.approx(0.21)
    assert variable_step(7.5, -1) == variable_step(1, 0)  # clamped to [0, 1]


def _one_iteration_oracle(mesh, p0, params, order):
    """Plain-Python Algorithm 1 step (eqs. 2, 7-9), one node at a time."""
    neighbours = {i: {} for i in range(mesh.n_vertices)}
    for (i, j), d in zip(mesh.edges.tolist(), mesh.rest_lengths.tolist()):
        neighbours[i][j] = d
        neighbours[j][i] = d
    masses = mesh.masses(params.density)
    dt = variable_step(measure(_model(mesh, p0), p0).area_error, measure(_model(mesh, p0), p0).shape_error)
    old = [tuple(p) for p in p0.tolist()]
    new = list(old)
    for i in range(mesh.n_vertices):
        seen = new if order == "sequential" else old
        fx = fy = 0.0
        for j, d in neighbours[i].items():
            dx, dy = seen[j][0] - seen[i][0], seen[j][1] - seen[i][1]
            length = math.hypot(dx, dy)
            fx += 0.5 * params.spring * (length - d) * dx / length
            fy += 0.5 * params.spring * (length - d) * dy / length
        ax, ay = fx / masses[i], fy / masses[i]
        new[i] = (seen[i][0] + 0.5 * dt * dt * ax, seen[i][1] + 0.5 * dt * dt * ay)  # V = 0 at start
    return np.array(new)


@pytest.mark.parametrize("order", ["jacobi", "sequential"])
def test_update_orders_match_a_plain_python_oracle(order):
    mesh = dome_grid(5)
    p0 = initial_layout(mesh, "tutte")
    params = FlattenParams(update=order, max_iter=1)
    result = flatten(mesh, p0, params)
    assert result.iterations == 1
    assert np.allclose(result.positions, _one_iteration_oracle(mesh, p0, params, order), rtol=0, atol=1e-14)


def test_orders_agree_where_updates_cannot_interact():
    # An isometric layout of a developable patch, moved rigidly: every spring is at
    # rest, so no node's update can depend on another's. Both orders must leave it as is.
    mesh, unrolled = rolled_grid(6, 6)
    angle = 0.7
    rotation = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    p0 = unrolled @ rotation.T + [3.0, -2.0]
    results = [flatten(mesh, p0, FlattenParams(update=u, max_iter=5, tol_area=0, tol_shape=0, tol_energy=0))
               for u in ("jacobi", "sequential")]
    for r in results:
        assert np.allclose(r.positions, p0, atol=1e-13)
        assert r.final.shape_error < 1e-14
    assert np.array_equal(results[0].positions, results[1].positions)


@pytest.mark.slow
def test_orders_agree_on_the_converged_result():
    mesh, _ = rolled_grid(6, 6)
    p0 = initial_layout(mesh, "pca")
    params = FlattenParams(damping=0.05, tol_area=1e-3, tol_shape=1e-3, tol_energy=0.05, max_iter=5000)
    jacobi = flatten(mesh, p0, params)
    sequential = flatten(mesh, p0, params.with_(update="sequential"))
    assert jacobi.status == sequential.status == "converged"
    assert abs(jacobi.iterations - sequential.iterations) <= 0.02 * jacobi.iterations


@pytest.mark.parametrize("update", ["jacobi", "sequential"])
def test_rolled_plane_flattens_with_damping(update):
    mesh, _ = rolled_grid(6, 6, arc_degrees=60)
    p0 = initial_layout(mesh, "pca")
    params = FlattenParams(damping=0.05, update=update, tol_area=1e-3, tol_shape=1e-3, tol_energy=0.05,
                           max_iter=20000)
    result = flatten(mesh, p0, params)
    assert result.status == "converged"
    assert result.final.area_error < 1e-3 and result.final.shape_error < 1e-3
    assert result.initial.shape_error > 0.01  # it really had to move
    assert result.iterations > 500
    assert result.final.flipped == 0


def test_history_starts_with_the_initial_layout():
    mesh, params = builtin_mesh("surf1")
    p0 = initial_layout(mesh, "pca")
    result = flatten(mesh, p0, FlattenParams(max_iter=7, tol_area=0, tol_shape=0, tol_energy=0))
    h = result.history
    assert len(h) == 8 and result.iterations == 7 and result.status == "max-iterations"
    assert math.isnan(h.dt[0])
    start = measure(_model(mesh, p0), p0)
    assert h.area_error[0] == start.area_error and h.shape_error[0] == start.shape_error
    # iteration 1 uses the errors of P0, iteration k+1 those after iteration k
    assert h.dt[1] == variable_step(h.area_error[0], h.shape_error[0])
    assert h.dt[5] == variable_step(h.area_error[4], h.shape_error[4])


def test_fixed_step_uses_dt():
    mesh, _ = builtin_mesh("surf1")
    result = flatten(mesh, initial_layout(mesh, "pca"), FlattenParams(step="fixed", dt=0.02, max_iter=3))
    assert result.history.dt[1:] == [0.02, 0.02, 0.02]


def test_stopping_rule_three_outcomes():
    mesh, _ = builtin_mesh("surf1")
    p0 = initial_layout(mesh, "pca")
    loose = flatten(mesh, p0, FlattenParams(tol_area=1, tol_shape=1, tol_energy=1))
    assert (loose.status, loose.iterations) == ("converged", 1)  # at least one iteration runs
    tight = flatten(mesh, p0, FlattenParams(tol_area=0, tol_shape=0, tol_energy=0, max_iter=4))
    assert (tight.status, tight.iterations) == ("max-iterations", 4)
    # a huge fixed step blows the undamped oscillator up
    blown = flatten(mesh, p0, FlattenParams(step="fixed", dt=1e3, max_iter=1000, tol_area=0))
    assert blown.status == "diverged"
    assert np.isfinite(blown.positions).all()
    assert len(blown.history) == blown.iterations + 1


def test_penalty_pushes_a_collapsing_node_back():
    mesh = Mesh(SQUARE_V, SQUARE_F)
    p0 = SQUARE_V[:, :2].copy()
    model = _model(mesh, p0)
    squashed = p0.copy()
    squashed[1] = [0.7, 0.6]  # node 1 close to the diagonal 0-2 (3D altitude 1/sqrt2)
    moves = penalty_moves(model, squashed, kappa=1.0, gain=1.0)
    h = abs(0.7 - 0.6) / math.sqrt(2)  # distance to line y = x
    expected = (1 / math.sqrt(2) - h) * np.array([1, -1]) / math.sqrt(2)
    assert moves[1] == pytest.approx(expected)
    # nodes 0 and 2 are far from their opposite sides: kappa = 0.1 leaves them alone
    assert penalty_moves(model, p0, kappa=0.1, gain=1.0) == pytest.approx(np.zeros((4, 2)))


def test_penalty_run_keeps_triangles_unflipped():
    mesh = dome_grid(6, height=0.6)
    p0 = initial_layout(mesh, "tutte")
    base = FlattenParams(density="auto", max_iter=40, tol_area=0, tol_shape=0, tol_energy=0)
    with_penalty = flatten(mesh, p0, base.with_(penalty=True, penalty_kappa=0.3, penalty_gain=0.5))
    assert with_penalty.status == "max-iterations"
    assert with_penalty.final.flipped == 0


@pytest.mark.parametrize("changes, message", [
    ({"spring": 0}, "spring constant"),
    ({"density": -1}, "density"),
    ({"density": "heavy"}, "density"),
    ({"dt": 0}, "dt"),
    ({"damping": 1.0}, "damping"),
    ({"tol_area": -0.1}, "tol-area"),
    ({"tol_energy": float("nan")}, "tol-energy must be a finite number"),
    ({"max_iter": 0}, "max-iter"),
    ({"step": "adaptive"}, "step"),
    ({"update": "random"}, "update"),
])
def test_parameters_are_validated(changes, message):
    with pytest.raises(ParameterError, match=message):
        FlattenParams(**changes)


def test_numpy_scalars_are_their_python_values():
    """A value taken from an array (np.int64, np.float32, np.bool_) is a number like any other: it was refused
    as 'must be an integer >= 1, got np.int64(500)'; the parameters keep Python types."""
    params = FlattenParams(max_iter=np.int64(500), spring=np.float32(0.5), barrier=np.bool_(True),
                           dynamics=np.str_("momentum"), energy_window=np.uint8(4))
    assert (params.max_iter, params.spring, params.barrier, params.dynamics, params.energy_window) == (
        500, 0.5, True, "momentum", 4)
    assert [type(v) for v in (params.max_iter, params.spring, params.barrier)] == [int, float, bool]
    with pytest.raises(ParameterError, match=r"max-iter must be an integer >= 1, got 2\.5"):
        FlattenParams(max_iter=np.float64(2.5))


def test_a_layout_that_runs_away_has_diverged_while_its_numbers_are_finite():
    """Undamped, with a fixed step too large, the paper dynamics grows for thousands of iterations before
    anything overflows (this run reached N_max at 1.5e28 mesh widths, E_S 4.8e51, as max-iterations): a
    layout RUNAWAY_FACTOR times wider than the mesh's edges laid end to end is ``diverged``, with the last
    state before it. A mesh at the end of the coordinate range is no runaway."""
    from golden_model.mesh import COORDINATE_LIMIT
    from golden_model.reference import RUNAWAY_FACTOR, in_range, runaway_width

    assert in_range(np.array([[0.0, 0.0], [1.0, 0.0]]), 1.0)
    for bad in (np.nextafter(1.0, 2.0), np.inf, np.nan):
        assert not in_range(np.array([[0.0, 0.0], [bad, 0.0]]), 1.0)
    mesh = dome_grid(6)
    start = initial_layout(mesh, "tutte")
    params = FlattenParams(step="fixed", dt=0.05, max_iter=3000, tol_area=0, tol_shape=0, tol_energy=0)
    result = flatten(mesh, start, params)
    width = runaway_width(mesh, start)
    assert result.status == "diverged" and 500 < result.iterations < 3000, (result.status, result.iterations)
    # no runaway: a layout whose every edge is at most RUNAWAY_FACTOR times its 3D length (the mesh is connected)
    stretch = np.max(np.linalg.norm(np.subtract(*start[mesh.edges.T]), axis=1) / mesh.rest_lengths)
    assert in_range(start * (RUNAWAY_FACTOR / stretch), width)
    assert np.ptp(result.positions, axis=0).max() <= width
    assert np.isfinite(result.velocities).all() and np.isfinite(result.final.energy)
    huge = Mesh(mesh.vertices * (COORDINATE_LIMIT / np.abs(mesh.vertices).max()), mesh.faces)
    assert flatten(huge, initial_layout(huge, "tutte"), FlattenParams(dynamics="momentum", max_iter=50)).status != \
        "diverged"


@pytest.mark.parametrize("mesh, max_iter", [("surf1", 300), ("dome", 50)])
def test_the_literal_overlap_penalty_that_runs_away_has_diverged(mesh, max_iter):
    """The paper's penalty (kappa = lambda = 1) pushes nodes apart without bound on these patches: a layout
    10^15 times as wide with E_S 1e31 (the dome) or 2e12 (Surf1) had ended as ``max-iterations``."""
    from golden_model.builtin import builtin_mesh

    mesh = builtin_mesh("surf1")[0] if mesh == "surf1" else dome_grid(6)
    result = flatten(mesh, initial_layout(mesh, "pca"), FlattenParams(penalty=True, max_iter=max_iter))
    assert result.status == "diverged", (result.status, result.final.area_error)


def test_a_spring_constant_whose_energies_underflow_is_refused():
    """C·Σd² below MIN_ENERGY_SCALE is refused: its energies underflow to 0, and an unmoved layout
    passed the stop rule as converged. The momentum step is independent of C (its weights carry 1/C),
    so a small C that still resolves takes the same run as the default."""
    from golden_model.reference import MIN_ENERGY_SCALE

    mesh = dome_grid(8)
    start = initial_layout(mesh, "tutte")
    scale = float(np.sum(mesh.rest_lengths**2))
    params = FlattenParams(dynamics="momentum", max_iter=300)
    with pytest.raises(ParameterError, match=r"spring constant C = .* is too small for this mesh.*--spring"):
        flatten(mesh, start, dataclasses.replace(params, spring=MIN_ENERGY_SCALE / scale / 2))
    small = flatten(mesh, start, dataclasses.replace(params, spring=4 * MIN_ENERGY_SCALE / scale))
    default = flatten(mesh, start, params)
    assert default.status == small.status == "converged"
    assert small.iterations == default.iterations > 10
    assert small.history.shape_error[-1] == pytest.approx(default.history.shape_error[-1], rel=1e-6)


def test_no_layout_within_the_runaway_factor_of_its_edges_is_a_runaway():
    """A strip rolled ten times round has a 3D box 30 times narrower than its unrolled length, and Tutte's
    start is a circle: its exact layout, with every edge stretched up to RUNAWAY_FACTOR times, is still no
    runaway (a bound on the boxes alone called it one)."""
    from sim.generate import rolled_grid
    from golden_model.reference import RUNAWAY_FACTOR, in_range, runaway_width

    rolled, unrolled = rolled_grid(40, 3, arc_degrees=3600.0)
    vertices, unrolled = rolled.vertices * [1.0, 0.01, 1.0], unrolled * [1.0, 0.01]
    mesh = Mesh(vertices, rolled.faces)
    width = runaway_width(mesh, initial_layout(mesh, "tutte"))
    stretch = np.max(np.linalg.norm(np.subtract(*unrolled[mesh.edges.T]), axis=1) / mesh.rest_lengths)
    assert in_range(unrolled * (0.99 * RUNAWAY_FACTOR / stretch), width)
