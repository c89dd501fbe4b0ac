"""The step guard (golden_model.guard, golden_model.fixed.guard): no accepted step raises the energy or
inverts a triangle, in float and bit-exact fixed point."""

import numpy as np
import pytest

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed, prepare
from golden_model.fixed.guard import floor_min_raw, guarded_moves_raw, stuck_nodes_raw
from sim.generate import delaunay_patch, spherical_cap
from golden_model.guard import (FLOOR_MIN_SHIFT, FLOOR_SHIFT, GUARD_LEVELS, SCALE_GROW_AFTER, SCALE_MAX_SHIFT,
                                StepScale, area_floor, guarded_moves)
from sim.layouts import initial_layout
from golden_model.mesh import signed_areas_2d
from golden_model.params import FlattenParams, ParameterError
from golden_model.reference import flatten

DEFAULT = FormatSet.preset("default")


def _doubled(positions, mesh, winding=1.0):
    return winding * 2.0 * signed_areas_2d(positions, mesh.faces)


@pytest.mark.parametrize("seed", range(6))
def test_no_guarded_move_takes_a_triangle_below_its_floor(seed):
    """Random proposals, some large enough to fold most triangles: every triangle keeps at least its floor."""
    rng = np.random.default_rng(seed)
    mesh = delaunay_patch(120, seed=seed)
    positions = initial_layout(mesh, "tutte")
    proposal = rng.normal(0.0, [0.01, 0.05, 0.2, 1.0, 3.0, 10.0][seed] * 0.05, positions.shape)
    before = _doubled(positions, mesh)
    floor = area_floor(before, 2.0 * mesh.face_areas)
    moves, levels = guarded_moves(positions, proposal, mesh.faces, 1.0, 2.0 * mesh.face_areas)
    after = _doubled(positions + moves, mesh)
    assert np.all(after >= floor * (1 - 1e-9))
    assert np.all(after > 0)
    unguarded = _doubled(positions + proposal, mesh)
    if seed >= 3:  # the large proposals would fold triangles: the guard had work to do
        assert np.any(unguarded <= 0) and np.any(levels > 0)
    # each node moves by 2^-level of its proposal, or not at all past the last level
    fraction = np.where(levels > GUARD_LEVELS, 0.0, 2.0 ** -np.minimum(levels, GUARD_LEVELS))
    assert np.allclose(moves, fraction[:, None] * proposal)


def test_floor_is_an_eighth_but_never_below_two_to_minus_twenty_of_the_3d_area():
    rest = np.array([1.0, 1.0, 1.0, 1.0])
    current = np.array([0.5, 2.0**-21, 2.0**-17, -0.25])
    assert np.array_equal(area_floor(current, rest),
                          [0.5 / 2**FLOOR_SHIFT, 2.0**-21, 2.0**-FLOOR_MIN_SHIFT, -0.25])


def test_step_scale_halves_on_rejection_and_doubles_after_twenty_accepted():
    scale = StepScale()
    for _ in range(3):
        scale = scale.rejected()
    assert scale.value == 0.125
    for _ in range(SCALE_GROW_AFTER - 1):
        scale = scale.accepted_step()
    assert scale.value == 0.125
    assert scale.accepted_step().value == 0.25
    stalled = StepScale(SCALE_MAX_SHIFT).rejected()
    assert stalled.stalled and not StepScale(SCALE_MAX_SHIFT).stalled


def test_accepted_steps_never_raise_the_energy_and_rejected_ones_roll_back():
    """From Tutte without the barrier the springs fold 15 triangles of this cap: the guard shortens the
    moves that would, rolls back the steps that raise the energy, and the energy never rises."""
    mesh = spherical_cap(12)
    p0 = initial_layout(mesh, "tutte")
    result = flatten(mesh, p0, FlattenParams(dynamics="momentum", barrier=False, tol_area=1.0, tol_shape=1.0,
                                             tol_energy=0.0, energy_window=1000, max_iter=300))
    energy = np.array(result.history.energy)
    assert np.all(np.diff(energy) <= 0)
    assert result.extra["rejected_steps"] > 0 and result.extra["clipped_node_steps"] > 0
    rejected = [k for k, taken in enumerate(result.history.accepted) if taken is False]  # (None: the start)
    assert all(energy[k] == energy[k - 1] for k in rejected)
    assert max(result.history.folded) == 0
    unguarded = flatten(mesh, p0, FlattenParams(dynamics="momentum", barrier=False, guard=False, tol_area=1.0,
                                                tol_shape=1.0, tol_energy=0.0, energy_window=1000, max_iter=300))
    assert unguarded.final.folded > 0 and np.any(np.diff(unguarded.history.energy) > 0)  # what the guard prevents


@pytest.mark.parametrize("barrier", [None, (0.05, 0.01), (0.5, 4.0), (1.0, 16.0)])
def test_from_a_fold_free_start_no_barrier_setting_folds_or_diverges(barrier):
    mesh = spherical_cap(8)
    p0 = initial_layout(mesh, "harmonic")
    options = dict(barrier=False) if barrier is None else dict(barrier_threshold=barrier[0], barrier_gain=barrier[1])
    result = flatten(mesh, p0, FlattenParams(dynamics="momentum", max_iter=400, tol_area=1.0, tol_shape=1.0,
                                             tol_energy=1e-4, **options))
    assert result.status in ("converged", "max-iterations", "stalled")
    assert max(result.history.folded) == 0


@pytest.mark.parametrize("seed", range(4))
def test_fixed_point_certificate_keeps_exact_areas_above_the_floor(seed):
    """In integers, with the rounding of each node's fraction of its proposal: every triangle's exact doubled
    area after the guarded moves is at least its floor, and positive."""
    rng = np.random.default_rng(seed)
    mesh = delaunay_patch(100, seed=seed)
    p0 = initial_layout(mesh, "tutte")
    problem = prepare(mesh, p0, FlattenParams(dynamics="momentum"), DEFAULT)
    raw = problem.initial_positions
    scale = [1e3, 1e4, 1e5, 3e5][seed]  # in position lsbs: from tiny moves to moves of many edge lengths
    proposal = np.round(rng.normal(0.0, scale * 16, raw.shape)).astype(np.int64)
    floor_min = floor_min_raw(DEFAULT, problem.face_areas)
    moves, levels = guarded_moves_raw(DEFAULT, raw, proposal, mesh.faces, problem.winding, floor_min)

    def doubled(p):
        a, b, c = (p[mesh.faces[:, k]] for k in range(3))
        u, v = b - a, c - a
        return int(problem.winding) * (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])

    before, after = doubled(raw), doubled(raw + moves)
    floor = np.minimum(before, np.maximum(before >> FLOOR_SHIFT, floor_min))
    assert np.all(after >= floor) and np.all(after > 0)
    assert np.array_equal(moves[levels <= GUARD_LEVELS], proposal[levels <= GUARD_LEVELS] >> levels[levels <= GUARD_LEVELS, None])
    if seed >= 2:
        assert np.any(doubled(raw + proposal) <= 0) and np.any(levels > 0)


def test_fixed_guarded_run_never_raises_the_exact_energy():
    mesh = spherical_cap(8)
    p0 = initial_layout(mesh, "tutte")
    params = FlattenParams(dynamics="momentum", barrier=False, tol_area=1.0, tol_shape=1.0, tol_energy=0.0,
                           energy_window=1000, max_iter=200)
    result = flatten_fixed(mesh, p0, params, DEFAULT)
    assert np.all(np.diff(result.history.energy) <= 0)
    assert result.extra["rejected_steps"] > 0 and max(result.history.folded) == 0


def test_guard_options_are_checked():
    with pytest.raises(ParameterError, match="belongs to the momentum dynamics"):
        FlattenParams(dynamics="paper", guard=True)
    with pytest.raises(ParameterError, match="void its guarantees"):
        FlattenParams(dynamics="momentum", penalty=True)
    with pytest.raises(ParameterError, match="energy-window must be an integer"):
        FlattenParams(energy_window=0)
    assert FlattenParams(dynamics="momentum").guard and not FlattenParams().guard
    assert FlattenParams(dynamics="momentum").energy_window == 10 and FlattenParams().energy_window == 1


def test_fixed_point_margin_covers_the_rounding_of_a_shortened_move():
    """A triangle of a few lsbs whose corner c moves by −52 lsb: at a sixteenth the exact move (−3.25)
    keeps a quarter of the area, but the shift takes −4 and would flatten it. The margin holds c still."""
    positions = np.array([[0, 0], [4, 0], [0, 4]], dtype=np.int64)
    proposal = np.array([[0, 0], [0, 0], [0, -52]], dtype=np.int64)
    faces = np.array([[0, 1, 2]])
    moves, levels = guarded_moves_raw(DEFAULT, positions, proposal, faces, 1.0, np.zeros(1, dtype=np.int64))
    moved = positions + moves
    u, v = moved[1] - moved[0], moved[2] - moved[0]
    assert u[0] * v[1] - u[1] * v[0] > 0
    assert levels[2] > GUARD_LEVELS and not moves.any()


def test_a_stuck_node_does_not_freeze_its_neighbours_in_fixed_point_as_in_float():
    """Node 2's own move folds triangle (0, 1, 2) even at 2^-GUARD_LEVELS of it: it is held still, and node 1,
    whose small move is safe, moves in full in both models (rather than frozen by node 2's triangle)."""
    positions = np.array([[0, 0], [1000, 0], [0, 1000], [1000, 1000]], dtype=np.int64)
    proposal = np.array([[0, 0], [10, 0], [0, -200_000], [0, 0]], dtype=np.int64)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    moves, levels = guarded_moves_raw(DEFAULT, positions, proposal, faces, 1.0, np.zeros(2, dtype=np.int64))
    float_moves, float_levels = guarded_moves(positions.astype(float), proposal.astype(float), faces, 1.0,
                                              np.full(2, 2e-6))
    assert np.array_equal(levels, float_levels) and np.array_equal(moves, float_moves)
    assert levels[2] > GUARD_LEVELS and np.array_equal(moves[1], [10, 0])


def test_a_triangle_too_wide_for_face_edge_holds_its_corners_still_and_not_its_neighbours():
    """Triangle (0, 1, 2) has an edge longer than face_edge holds: it is never trusted, so its corners are
    stuck (their proposals zeroed before the certificate) and do not move; the small triangle (3, 5, 4)
    beside it moves."""
    edge = DEFAULT.face_edge
    far = edge.raw_max + 1000  # past face_edge, inside position's range
    assert far <= DEFAULT.position.raw_max
    positions = np.array([[0, 0], [far, 0], [0, 1000], [far, 1000], [far + 1000, 2000], [far + 1000, 1000]],
                         dtype=np.int64)
    proposal = np.array([[5, 5], [5, 5], [5, 5], [5, 5], [5, 5], [5, 5]], dtype=np.int64)
    faces = np.array([[0, 1, 2], [3, 5, 4]])
    stuck = stuck_nodes_raw(DEFAULT, positions, proposal, faces, 1.0, np.zeros(2, dtype=np.int64))
    assert stuck.tolist() == [True, True, True, False, False, False]
    moves, levels = guarded_moves_raw(DEFAULT, positions, proposal, faces, 1.0, np.zeros(2, dtype=np.int64))
    assert (levels[:3] > GUARD_LEVELS).all() and not moves[:3].any() and moves[3:].any()
