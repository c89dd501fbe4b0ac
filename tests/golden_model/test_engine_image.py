"""The engine's memory images and image-driven controller (golden_model.engine_spec.image)."""

import dataclasses
import re

import numpy as np
import pytest

from golden_model.modes import mode_named
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed, prepare
from golden_model.fixed.measures import FixedPointError, energy_raw
from golden_model.fixed.pipeline import NodeTerms
from golden_model.engine_spec.image import (EngineCapacity, MemoryLayout, WordField, build_image, constant_fault,
                                            decode_entries, decode_nodes, decode_triangles, energy_width,
                                            memory_layouts, run_image)
from sim.generate import dome_grid, generated_meshes, grid_faces, grid_uv
from sim.layouts import initial_layout
from golden_model.mesh import Mesh
from golden_model.params import FlattenParams
from golden_model.engine_spec.image import UNGUARDED

DEFAULT = FormatSet.preset("default")
CAPACITY = EngineCapacity(vertices=1024, entries=8192, triangles=2048)
MESHES = generated_meshes()

RUNS = {  # both dynamics, with and without the barrier, fixed and variable step
    "paper-variable": FlattenParams(density="auto", max_iter=25),
    "paper-fixed-barrier": FlattenParams(density="auto", step="fixed", dt=0.2, barrier=True, max_iter=25),
    "paper-fixed-damped": FlattenParams(density="auto", step="fixed", dt=0.3, damping=0.1, max_iter=25),
    "momentum-barrier": FlattenParams(dynamics="momentum", **UNGUARDED, max_iter=60),
    "momentum-no-barrier": FlattenParams(dynamics="momentum", **UNGUARDED, barrier=False, max_iter=60),
    # the energy always passes: the iteration whose E_S first passes stops the run
    "momentum-area-gate": FlattenParams(dynamics="momentum", **UNGUARDED, tol_area=0.02, tol_shape=1.0, tol_energy=1.0,
                                        max_iter=60),
    # the step guard with its window: the momentum dynamics' default
    "momentum-guarded": FlattenParams(dynamics="momentum", max_iter=60),
    "momentum-guarded-no-barrier": FlattenParams(dynamics="momentum", barrier=False, max_iter=60),
}


def _reference_bits(value: int, layout: MemoryLayout, values: dict[str, int]) -> int:
    """The word as one Python int, field by field from bit 0 (independent of the numpy packer)."""
    lsb = 0
    for f in layout.fields:
        value |= (values[f.name] & ((1 << f.width) - 1)) << lsb
        lsb += f.width
    return value


def test_pack_places_fields_lsb_first_and_splits_into_32_bit_words():
    layout = MemoryLayout("t", (WordField("a", 3), WordField("b", 40, signed=True), WordField("c", 1),
                                WordField("d", 30, signed=True)), depth=4)
    assert (layout.bits, layout.words, layout.stride) == (74, 3, 4)
    words = layout.pack({"a": np.array([5]), "b": np.array([-1]), "c": np.array([1]), "d": np.array([-2])})
    # b = -1 fills bits 42:3, c is bit 43, d = -2 is bits 73:44 with bit 44 clear
    assert words.tolist() == [[0xFFFF_FFFD, 0xFFFF_EFFF, 0x3FF]]


def test_pack_unpack_round_trip_over_the_whole_range():
    rng = np.random.default_rng(1)
    for layout in memory_layouts(DEFAULT, CAPACITY).values():
        n = 500
        values = {f.name: rng.integers(f.raw_min, f.raw_max, n, endpoint=True) for f in layout.fields}
        for f in layout.fields:  # the extremes of every field
            values[f.name][:2] = f.raw_min, f.raw_max
        words = layout.pack(values)
        assert words.dtype == np.uint32 and words.shape == (n, layout.words)
        for i in (0, 1, 7, 499):
            expected = _reference_bits(0, layout, {k: int(v[i]) for k, v in values.items()})
            assert sum(int(w) << (32 * k) for k, w in enumerate(words[i])) == expected
        back = layout.unpack(words)
        for f in layout.fields:
            np.testing.assert_array_equal(back[f.name], values[f.name], err_msg=f.name)


def test_pack_refuses_a_value_outside_its_field():
    layout = MemoryLayout("t", (WordField("a", 4, signed=True),), depth=2)
    with pytest.raises(ValueError, match=r"t\.a: raw values \[-9, 0\] outside \[-8, 7\]"):
        layout.pack({"a": np.array([-9, 0])})


def test_word_layouts_take_their_widths_from_the_formats_and_the_capacity():
    layouts = memory_layouts(DEFAULT, CAPACITY)
    index = 10  # 1024 vertices
    assert layouts["nodes"].bits == 2 * DEFAULT.position.width + 2 * DEFAULT.velocity.width + 2 * DEFAULT.inv_mass.width
    assert layouts["entries"].bits == 2 * index + 1 + DEFAULT.rest_length.width + DEFAULT.area.width \
        + DEFAULT.barrier_gain.width
    assert layouts["triangles"].bits == 3 * index + DEFAULT.face_area.width
    assert [f.name for f in layouts["entries"].fields] == ["neighbour", "last", "rest", "second", "threshold", "gain"]
    assert EngineCapacity(1025, 8192, 2048).vertex_index_bits == 11


def test_energy_width_holds_the_largest_energy():
    """energy_raw of every entry at the largest |L − d| and the largest barrier c·h reaches the width."""
    cap = EngineCapacity(4, 6, 4)
    per_node = np.array([2, 1, 2, 1])  # entries of each node
    worst = NodeTerms(np.zeros((4, 2), np.int64), np.zeros(4, np.int64),
                      error_squares=per_node * DEFAULT.rest_length.raw_max ** 2,
                      barrier_energies=per_node * (DEFAULT.barrier_coeff.raw_max * DEFAULT.area.raw_max))
    energy = energy_raw(DEFAULT, DEFAULT.spring.raw_max, worst.error_square_sum, worst.barrier_energy_sum)
    assert energy_width(DEFAULT, cap.entries) == energy.bit_length()


@pytest.mark.parametrize("what, capacity", [
    ("vertices", EngineCapacity(63, 8192, 2048)),
    ("neighbour entries", EngineCapacity(1024, 300, 2048)),
    ("triangles", EngineCapacity(1024, 8192, 97)),
])
def test_a_mesh_over_capacity_is_refused_in_one_line(what, capacity):
    mesh = MESHES["dome"]  # 64 vertices, 98 triangles, 2 x 161 entries
    problem = prepare(mesh, initial_layout(mesh, "tutte"), RUNS["paper-variable"], DEFAULT)
    with pytest.raises(FixedPointError) as info:
        build_image(problem, capacity)
    message = str(info.value)
    assert "\n" not in message and f" {what}; the engine holds at most " in message
    assert f"capacity vertices={capacity.vertices}, entries={capacity.entries}, triangles={capacity.triangles}" \
        in message


def test_a_capacity_must_be_a_count():
    with pytest.raises(ValueError, match="EngineCapacity: entries must be an int >= 2, got 1"):
        EngineCapacity(10, 1, 10)


@pytest.mark.parametrize("run", ["paper-fixed-barrier", "momentum-barrier"])
def test_the_images_decode_to_the_problem(run):
    mesh = MESHES["delaunay"]
    problem = prepare(mesh, initial_layout(mesh, "tutte"), RUNS[run], DEFAULT)
    image = build_image(problem, CAPACITY)
    stream = problem.stream
    positions, velocities, inv_mass, inv_mass_barrier = decode_nodes(image.nodes, DEFAULT, CAPACITY)
    np.testing.assert_array_equal(positions, problem.initial_positions)
    assert not velocities.any()
    np.testing.assert_array_equal(inv_mass, stream.inv_mass)
    np.testing.assert_array_equal(inv_mass_barrier, stream.header_inv_mass_barrier)
    indptr, neighbour, rest, barrier = decode_entries(image.entries, DEFAULT, CAPACITY, barrier=True)
    for got, want in ((indptr, stream.indptr), (neighbour, stream.neighbour), (rest, stream.rest),
                      (barrier.second, stream.barrier.second), (barrier.threshold, stream.barrier.threshold),
                      (barrier.gain, stream.barrier.gain)):
        np.testing.assert_array_equal(got, want)
    faces, areas = decode_triangles(image.triangles, DEFAULT, CAPACITY)
    np.testing.assert_array_equal(faces, mesh.faces)
    np.testing.assert_array_equal(areas, problem.face_areas)
    c = image.constants
    assert (c["vertices"], c["entries"], c["triangles"]) == (mesh.n_vertices, len(stream.neighbour), mesh.n_faces)
    assert (c["area_reciprocal"], c["area_shift"]) == (problem.area_reciprocal.mantissa, problem.area_reciprocal.shift)
    assert c["barrier"] == 1
    assert c["mode"] == mode_named("momentum" if run == "momentum-barrier" else "paper-fixed").code


@pytest.mark.parametrize("v", [3, 4, 17])
def test_the_fillable_vertices_are_those_of_the_leanest_disk_a_fan(v):
    """A fan of ``v`` vertices (a convex polygon's triangles from one corner) is the disk with the fewest
    entries and triangles for its vertices: depths that hold it hold ``v`` vertices, one entry or triangle
    fewer do not (``springflat verilog --capacity`` refuses such depths)."""
    angles = np.linspace(0.0, np.pi, v)
    fan = Mesh(np.column_stack([np.cos(angles), np.sin(angles), np.zeros(v)]),
               np.array([(0, i, i + 1) for i in range(1, v - 1)]))
    entries, triangles = 2 * len(fan.edges), len(fan.faces)
    assert EngineCapacity.least_for(v) == (entries, triangles)
    assert EngineCapacity(v, entries, max(triangles, 2)).fillable_vertices == v
    assert EngineCapacity(v, entries - 1, max(triangles, 2)).fillable_vertices < v
    if triangles > 2:
        assert EngineCapacity(v, entries, triangles - 1).fillable_vertices < v


def test_tolerances_above_one_are_clamped_to_the_error_range():
    mesh = MESHES["dome"]
    params = RUNS["paper-variable"].with_(tol_area=3.0)
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, DEFAULT), CAPACITY)
    assert image.constants["tol_area"] == DEFAULT.error.raw_max


def test_an_energy_tolerance_the_register_cannot_hold_is_refused():
    mesh = MESHES["dome"]
    for tol_energy in (256.0, 1e300):  # (1e300 was a float overflow on its way into the register)
        params = RUNS["paper-variable"].with_(tol_energy=tol_energy)
        with pytest.raises(FixedPointError, match=rf"^--tol-energy {re.escape(f'{tol_energy:g}')} does not fit the engine's TOL_ENERGY "
                                                  r"register \(u8\.40: below 256\); use a smaller value$"):
            build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, DEFAULT), CAPACITY)
    params = RUNS["paper-variable"].with_(tol_energy=255.9)
    assert build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, DEFAULT), CAPACITY).constants[
        "tol_energy"] == round(255.9 * 2**40)


def _check_bit_identical(mesh: Mesh, params: FlattenParams, fs: FormatSet = DEFAULT,
                         capacity: EngineCapacity = CAPACITY):
    p0 = initial_layout(mesh, "tutte")
    reference = flatten_fixed(mesh, p0, params, fs)
    state = reference.engine_state
    result = run_image(build_image(prepare(mesh, p0, params, fs), capacity), fs)
    assert (result.status, result.iterations) == (reference.status, reference.iterations)
    np.testing.assert_array_equal(result.positions, state.raw_positions)
    np.testing.assert_array_equal(result.velocities, state.raw_velocities)
    assert (result.area_error, result.shape_error) == state.errors
    assert result.energy == state.energy_raw
    assert result.saturations == reference.extra["saturations"]
    positions, velocities, _, _ = decode_nodes(result.nodes, fs, capacity)  # written back in place
    np.testing.assert_array_equal(positions, state.raw_positions)
    np.testing.assert_array_equal(velocities, state.raw_velocities)
    return result


@pytest.mark.parametrize("run", RUNS)
@pytest.mark.parametrize("mesh", MESHES)
def test_run_image_is_bit_identical_to_run_fixed(mesh, run):
    _check_bit_identical(MESHES[mesh], RUNS[run])


def test_the_runs_cover_both_stopping_outcomes():
    """The comparisons above see both converged and max-iterations runs (so status and count are tested)."""
    mesh = MESHES["developable"]
    p0 = initial_layout(mesh, "tutte")
    statuses = {flatten_fixed(mesh, p0, RUNS[run], DEFAULT).status for run in ("paper-variable", "momentum-barrier")}
    assert statuses == {"converged", "max-iterations"}


def test_saturation_events_are_counted_as_run_fixed_counts_them():
    params = FlattenParams(step="fixed", dt=0.5, spring=5.0, density="auto", max_iter=20)
    _check_bit_identical(dome_grid(6), params)


def test_the_saturation_limit_stops_a_run_as_diverged():
    mesh = dome_grid(6)
    p0 = initial_layout(mesh, "tutte")
    params = FlattenParams(step="fixed", dt=0.5, spring=5.0, density="auto", max_iter=20)
    image = build_image(prepare(mesh, p0, params, DEFAULT), CAPACITY)
    free = run_image(image, DEFAULT)
    assert free.status == "max-iterations" and free.saturations > 10
    limited = run_image(dataclasses.replace(image, constants={**image.constants, "saturation_limit": 10}), DEFAULT)
    assert limited.status == "diverged" and 1 <= limited.iterations < free.iterations
    assert limited.saturations >= 10


@pytest.mark.parametrize("change, answer", [
    ({"vertices": 0}, "no-mesh"),
    ({"entries": 8193}, "bad-constants"),
    ({"triangles": 0}, "bad-constants"),
    ({"area_reciprocal": 1 << 26}, "bad-constants"),  # not a u1.27 mantissa in [1, 2)
    ({"length_shift": 21}, "bad-constants"),  # normalise needs shift >= error.frac_bits + 2
    ({"mode": mode_named("paper-fixed").code, "dt": 0}, "bad-constants"),
    ({"mode": mode_named("momentum-guarded").code}, None),  # every mode code is one the engine runs
    ({"mode": mode_named("paper-fixed").code, "dt": 1}, None),
    ({"max_iter": 0}, "bad-constants"),
    ({}, None),
])
def test_start_answers_bad_run_constants_with_a_result_code(change, answer):
    mesh = MESHES["dome"]
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), RUNS["paper-variable"], DEFAULT), CAPACITY)
    constants = {**image.constants, **change}
    assert constant_fault(constants, DEFAULT, CAPACITY) == answer
    if answer is not None:
        result = run_image(dataclasses.replace(image, constants=constants), DEFAULT)
        assert (result.status, result.iterations) == (answer, 0)
        np.testing.assert_array_equal(result.nodes, image.nodes)


@pytest.mark.slow
def test_a_90000_vertex_mesh_images_at_a_large_capacity():
    """17-bit vertex indices and 20-bit entry indices: the vectorised packer round-trips a 90,000-vertex
    mesh (how fast it does so is in ``benchmarks/bench_engines.py``, not here)."""
    uv = grid_uv(300, 300, 299.0, 299.0)
    mesh = Mesh(np.column_stack([uv, 0.1 * np.sin(uv[:, 0] / 20)]), grid_faces(300, 300))
    problem = prepare(mesh, uv - 149.5, FlattenParams(dynamics="momentum", **UNGUARDED), DEFAULT)
    capacity = EngineCapacity(1 << 17, 1 << 20, 1 << 18)
    image = build_image(problem, capacity)
    assert image.nodes.shape == (90_000, 5) and image.entries.shape[0] == len(problem.stream.neighbour)
    positions, _, inv_mass, _ = decode_nodes(image.nodes, DEFAULT, capacity)
    np.testing.assert_array_equal(positions, problem.initial_positions)
    np.testing.assert_array_equal(inv_mass, problem.stream.inv_mass)
    indptr, neighbour, rest, _ = decode_entries(image.entries, DEFAULT, capacity, barrier=True)
    for got, want in ((indptr, problem.stream.indptr), (neighbour, problem.stream.neighbour),
                      (rest, problem.stream.rest)):
        np.testing.assert_array_equal(got, want)
    faces, _ = decode_triangles(image.triangles, DEFAULT, capacity)
    np.testing.assert_array_equal(faces, mesh.faces)


@pytest.mark.parametrize("params, message", [
    (FlattenParams(dynamics="momentum", energy_window=4), r"over 10 accepted iterations in this mode, not 4: use "
                                                          r"--energy-window 10"),
    (FlattenParams(dynamics="momentum", guard=False), r"over 1 iteration in this mode, not 10"),
])
def test_a_stop_rule_window_the_engine_lacks_is_refused_in_one_line(params, message):
    mesh = MESHES["dome"]
    with pytest.raises(FixedPointError, match=message) as info:
        build_image(prepare(mesh, initial_layout(mesh, "tutte"), params, DEFAULT), CAPACITY)
    assert "\n" not in str(info.value)


def test_a_build_without_the_guard_refuses_the_guarded_step_in_one_line():
    mesh = MESHES["dome"]
    guardless = dataclasses.replace(CAPACITY, guard=False)
    with pytest.raises(FixedPointError, match=r"built without the step guard, so it does not run 'momentum-guarded': "
                                              r"use --no-guard") as info:
        build_image(prepare(mesh, initial_layout(mesh, "tutte"), FlattenParams(dynamics="momentum"), DEFAULT),
                    guardless)
    assert "\n" not in str(info.value)
    unguarded = FlattenParams(dynamics="momentum", guard=False, energy_window=1)
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), unguarded, DEFAULT), guardless)
    assert image.capacity.guard is False
    with pytest.raises(ValueError, match="EngineCapacity: guard must be a bool, got 1"):
        EngineCapacity(10, 10, 10, guard=1)


@pytest.mark.parametrize("params, hint", [
    (FlattenParams(dynamics="paper", energy_window=3), "use --energy-window 1"),
    (FlattenParams(dynamics="momentum", guard=False, energy_window=10),
     "use --energy-window 1 (or the guard, with its window)"),
    (FlattenParams(dynamics="momentum", energy_window=5), "use --energy-window 10"),
])
def test_a_window_the_engine_lacks_is_refused_with_a_remedy_the_mode_takes(params, hint):
    """The paper dynamics has no guard: its refusal offered one ('or the guard'), which --guard then refused."""
    from golden_model.engine_spec.image import check_engine_params

    with pytest.raises(FixedPointError, match=r"^SpringflatEngine's stop rule measures the energy change over") as refused:
        check_engine_params(params)
    assert str(refused.value).endswith(hint)


COARSE_CAPACITY = dataclasses.replace(CAPACITY, coarse_degree=3)
COARSE_RUN = FlattenParams(dynamics="momentum", coarse_degree=3, max_iter=60)


@pytest.mark.parametrize("mesh, barrier", [("dome", True), ("saddle", True), ("delaunay", False)])
def test_run_image_with_the_coarse_space_is_bit_identical_to_run_fixed(mesh, barrier, monkeypatch):
    """The basis and matrix memories and the coarse run constants carry what ``run_fixed`` reads; the runs take
    the coarse move (they end elsewhere than the same build's runs without it), and the Delaunay patch's rolls
    back a plain gradient step that took it (the schedule's hand-over to the Jacobi step)."""
    from golden_model.coarse import CoarseSchedule

    rejected, handed_over = CoarseSchedule.rejected, []

    def watched(schedule, scale, with_momentum):
        handed_over.append(schedule.coarse and not with_momentum)
        return rejected(schedule, scale, with_momentum)

    monkeypatch.setattr(CoarseSchedule, "rejected", watched)
    params = COARSE_RUN.with_(barrier=barrier)
    with_coarse = _check_bit_identical(MESHES[mesh], params, capacity=COARSE_CAPACITY)
    without = _check_bit_identical(MESHES[mesh], params.with_(coarse_degree=0), capacity=COARSE_CAPACITY)
    assert with_coarse.iterations != without.iterations or not np.array_equal(with_coarse.positions, without.positions)
    if mesh == "delaunay":
        assert any(handed_over) and with_coarse.guard.rejected > 2


def test_the_coarse_memories_hold_the_hosts_basis_and_matrix():
    from golden_model.engine_spec.image import decode_coarse

    mesh = MESHES["dome"]
    problem = prepare(mesh, initial_layout(mesh, "tutte"), COARSE_RUN, DEFAULT)
    image = build_image(problem, COARSE_CAPACITY)
    assert set(image.memories()) == {"nodes", "entries", "triangles", "basis", "matrix"}
    assert image.basis.shape == (mesh.n_vertices, 6) and image.matrix.shape == (100, 1)  # 9 × 18 bits; 25 bits
    decoded = decode_coarse(image)
    np.testing.assert_array_equal(decoded.phi, problem.coarse.phi)
    np.testing.assert_array_equal(decoded.matrix, problem.coarse.matrix)
    assert (image.constants["coarse"], image.constants["matrix_exponent"]) == (1, problem.coarse.matrix_exponent)
    off = build_image(prepare(mesh, initial_layout(mesh, "tutte"), COARSE_RUN.with_(coarse_degree=0), DEFAULT),
                      COARSE_CAPACITY)
    assert off.constants["coarse"] == 0 and decode_coarse(off) is None
    assert not build_image(prepare(mesh, initial_layout(mesh, "tutte"), COARSE_RUN.with_(coarse_degree=0), DEFAULT),
                           CAPACITY).memories().keys() - {"nodes", "entries", "triangles"}


def test_the_coarse_move_asked_of_an_unguarded_mode_is_a_bad_constant():
    mesh = MESHES["dome"]
    image = build_image(prepare(mesh, initial_layout(mesh, "tutte"), COARSE_RUN, DEFAULT), COARSE_CAPACITY)
    assert constant_fault(image.constants, DEFAULT, COARSE_CAPACITY) is None
    unguarded = {**image.constants, "mode": mode_named("momentum").code}
    assert constant_fault(unguarded, DEFAULT, COARSE_CAPACITY) == "bad-constants"
    assert constant_fault({**unguarded, "coarse": 0}, DEFAULT, COARSE_CAPACITY) is None


@pytest.mark.parametrize("capacity, params, message", [
    (CAPACITY, COARSE_RUN, r"^this engine was built without a coarse space: use --coarse-degree 0, or build the engine "
                           r"with one \(springflat verilog --coarse-degree 3 --out DIR\)$"),
    (dataclasses.replace(CAPACITY, coarse_degree=2), COARSE_RUN,
     r"^this engine's coarse space is of degree 2, not 3: use --coarse-degree 2 or 0$"),
])
def test_a_coarse_space_the_engine_lacks_is_refused_in_one_line(capacity, params, message):
    """Against the engine's capacity (``build_image`` checks it; not known yet, nothing is refused)."""
    from golden_model.engine_spec.image import check_engine_params

    with pytest.raises(FixedPointError, match=message):
        check_engine_params(params, capacity)
    with pytest.raises(FixedPointError, match=message):
        build_image(prepare(MESHES["dome"], initial_layout(MESHES["dome"], "tutte"), params, DEFAULT), capacity)
    check_engine_params(params.with_(coarse_degree=0), capacity)
    check_engine_params(params, None)
    check_engine_params(params, COARSE_CAPACITY)


@pytest.mark.parametrize("changes, message", [
    ({"coarse_degree": 5}, "coarse_degree must be an int from 0"),
    ({"coarse_degree": True}, "coarse_degree must be an int from 0"),
    ({"coarse_degree": 3, "guard": False}, "built with the step guard and one lane"),
    ({"coarse_degree": 3, "lanes": 2}, "built with the step guard and one lane"),
])
def test_a_coarse_build_takes_the_guard_one_lane_and_a_degree_in_range(changes, message):
    with pytest.raises(ValueError, match=message):
        dataclasses.replace(CAPACITY, **changes)
