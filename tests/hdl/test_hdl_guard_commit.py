"""RTL guarded commit (hdl.GuardCommit) against the golden model's ``guarded_moves_raw`` / ``taken_moves_raw``
and ``commit``, and a rollback's ``P − V``, in Amaranth's simulator: every node's position, move and level,
bit for bit, in order, at the stated latency."""

import gc
import warnings

import numpy as np
import pytest
from amaranth.hdl import UnusedElaboratable

from golden_model.fixed import FormatSet
from golden_model.fixed.guard import (commit, floor_min_raw, guarded_moves_raw, stuck_nodes_raw, taken_moves_raw,
                                      triangle_levels_raw)
from golden_model.guard import GUARD_LEVELS, node_levels
from hdl.fixedpoint import FormatSetNotBuildable
from hdl.guard_commit import GuardCommit
from sim.payloads import pack_beats, unpack_beats
from support import PRESETS
from support.streams import run_streams, top_level_verilog

HELD = GUARD_LEVELS + 1


def run_commit(fs, positions, velocities, slots, stuck, rollback, *, seed=0, p_valid=1.0):
    """The nodes through the RTL: ``(outputs as arrays, run, dut)``; ``slots`` (V, 3) the slot levels."""
    dut = GuardCommit(fs)
    vec = lambda a: {"x": a[:, 0], "y": a[:, 1]}  # noqa: E731
    beats = pack_beats(dut.i.payload.shape(), {
        "position": vec(positions), "velocity": vec(velocities), "levels": {k: slots[:, k] for k in range(3)},
        "stuck": stuck.astype(np.int64), "rollback": rollback.astype(np.int64)})
    run = run_streams(dut, beats, seed=seed, p_valid=p_valid, watch={"idle": dut.idle})
    return unpack_beats(dut.o.payload.shape(), run.outputs), run, dut


def check(out, want_p, want_v, want_level):
    """The RTL's outputs against the expected arrays (the first mismatch named)."""
    n = len(want_level)
    for name, got, expected in (
        ("position.x", out["position"]["x"], want_p[:, 0]), ("position.y", out["position"]["y"], want_p[:, 1]),
        ("velocity.x", out["velocity"]["x"], want_v[:, 0]), ("velocity.y", out["velocity"]["y"], want_v[:, 1]),
        ("level", out["level"], want_level),
    ):
        assert len(got) == n, f"{name}: {len(got)} results for {n} nodes"
        bad = np.flatnonzero(got != expected)
        assert bad.size == 0, f"{name}: {bad.size} mismatches; first at node {int(bad[0])}: rtl {int(got[bad[0]])} " \
                              f"golden {int(expected[bad[0]])}"


def edge_positions(fs, n, rng, reach):
    """``(n, 2)`` positions, about half of them within ``reach`` [raw] of the position range's ends."""
    pos = fs.position
    p = rng.integers(pos.raw_min // 4, pos.raw_max // 4, size=(n, 2))
    near = rng.random((n, 2)) < 0.5
    offset = rng.integers(0, reach + 1, size=(n, 2))
    top = rng.random((n, 2)) < 0.5
    return np.where(near, np.where(top, pos.raw_max - offset, pos.raw_min + offset), p)


def random_nodes(fs, n, rng):
    """Positions (half near the range's ends), proposals over the velocity range (some small), slot levels
    0 … GUARD_LEVELS + 1 (each node's largest uniform over them), stuck nodes with their proposal zeroed."""
    vel = fs.velocity
    positions = edge_positions(fs, n, rng, vel.raw_max)
    proposals = rng.integers(vel.raw_min, vel.raw_max + 1, size=(n, 2))
    small = rng.random(n) < 0.3
    proposals[small] >>= rng.integers(8, vel.width, size=(small.sum(), 1))
    top = rng.integers(0, HELD + 1, n)
    slots = np.minimum(rng.integers(0, HELD + 1, (n, 3)), top[:, None])
    slots[np.arange(n), rng.integers(0, 3, n)] = top
    stuck = rng.random(n) < 0.1
    proposals[stuck] = 0
    return positions, proposals, slots, stuck


def golden_commit(fs, positions, proposals, slots, stuck):
    """``(P'', V'', level)``: the node's level the largest slot's (``GUARD_LEVELS + 1`` if stuck), then the
    golden model's ``taken_moves_raw`` and ``commit``."""
    level = np.where(stuck, HELD, slots.max(axis=1))
    taken, level = taken_moves_raw(fs, positions, proposals, level)
    new_p, new_v = commit(positions, taken)
    return new_p, new_v, level


@pytest.mark.parametrize("preset", PRESETS)
def test_random_commits_and_rollbacks_mixed_with_gaps(preset):
    """Commits at every level, held and stuck nodes, moves that would leave the range, and rollbacks of
    committed moves, in one stream with gaps; the rollbacks restore the positions before their commits."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng([40, PRESETS.index(preset)])
    n = 1200
    positions, proposals, slots, stuck = random_nodes(fs, n, rng)
    new_p, new_v, level = golden_commit(fs, positions, proposals, slots, stuck)
    # a third of the beats roll back a committed move: P'' − V'' is P
    rollback = rng.random(n) < 0.3
    in_p = np.where(rollback[:, None], new_p, positions)
    in_v = np.where(rollback[:, None], new_v, proposals)
    want_p = np.where(rollback[:, None], positions, new_p)
    want_v = np.where(rollback[:, None], 0, new_v)
    want_level = np.where(rollback, 0, level)
    out, run, dut = run_commit(fs, in_p, in_v, slots, stuck, rollback, seed=41, p_valid=0.7)
    check(out, want_p, want_v, want_level)
    # what the nodes exercised: every level, held past GUARD_LEVELS, stuck, and out of range
    commits = ~rollback
    assert set(level[commits]) == set(range(HELD + 1))
    target = positions + (proposals >> np.minimum(np.where(stuck, HELD, slots.max(axis=1)), GUARD_LEVELS)[:, None])
    outside = ((target < fs.position.raw_min) | (target > fs.position.raw_max)).any(axis=1)
    unheld = commits & ~stuck & (slots.max(axis=1) <= GUARD_LEVELS)
    assert (unheld & outside).sum() > 20, "moves that would leave the range"
    assert (unheld & ~outside & (new_v != 0).any(axis=1)).sum() > 200, "moves taken"
    assert (commits & stuck).sum() > 20 and (rollback & (new_v != 0).any(axis=1)).sum() > 100
    # idle: high exactly when every node taken in has come out
    idle = np.asarray(run.watched["idle"], dtype=bool)
    edges = np.arange(len(idle))
    assert np.array_equal(idle, np.searchsorted(run.in_cycles, edges) == np.searchsorted(run.out_cycles, edges))


def grid_mesh(fs, rng, side=12):
    """A jittered ``side × side`` grid near a corner of the position range (some of its nodes within a
    proposal of the range's ends) and its faces (counter-clockwise)."""
    pos = fs.position
    h = 2.0 ** rng.uniform(-8, -6) * 2.0**pos.frac_bits
    ij = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), axis=-1).reshape(-1, 2)
    real = (ij + rng.uniform(-0.2, 0.2, ij.shape)) * h
    corner = np.array([pos.raw_max, pos.raw_min]) + np.array([-(side - 1.5) * h, 0.5 * h])
    positions = np.clip(np.round(corner + real), pos.raw_min, pos.raw_max).astype(np.int64)
    faces = []
    for i in range(side - 1):
        for j in range(side - 1):
            a, b, c, d = i * side + j, (i + 1) * side + j, (i + 1) * side + j + 1, i * side + j + 1
            faces += [(a, b, c), (a, c, d)]
    return positions, np.array(faces, dtype=np.int64), h


@pytest.mark.parametrize("preset", PRESETS)
def test_a_mesh_commit_is_guarded_moves_raw_then_its_rollback_restores_it(preset):
    """A small mesh's guarded step as the engine is to run it: the stuck nodes' proposals zeroed, each
    node's three slot levels from the golden certificate (``triangle_levels_raw``, ``node_levels`` per
    corner slot); the commit is ``guarded_moves_raw`` and ``commit``, and its rollback the layout before."""
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng([42, PRESETS.index(preset)])
    positions, faces, h = grid_mesh(fs, rng)
    n = len(positions)
    vel = fs.velocity
    proposals = rng.normal(size=(n, 2)) * h * 10.0 ** rng.uniform(-2, 0.5, (n, 1))
    wild = rng.random(n) < 0.05  # moves of about a hundred triangles' sizes: stuck nodes
    proposals[wild] *= 300
    proposals = np.clip(np.round(proposals), vel.raw_min, vel.raw_max).astype(np.int64)
    floor_min = floor_min_raw(fs, np.full(len(faces), int(0.5 * (h / 2.0**fs.position.frac_bits) ** 2
                                                            * 2.0**fs.face_area.frac_bits)))
    want_v, want_level = guarded_moves_raw(fs, positions, proposals, faces, 1.0, floor_min)
    want_p, want_v = commit(positions, want_v)
    stuck = stuck_nodes_raw(fs, positions, proposals, faces, 1.0, floor_min)
    free = np.where(stuck[:, None], 0, proposals)
    face_level = triangle_levels_raw(fs, positions, free, faces, 1.0, floor_min)
    slots = np.stack([node_levels(face_level, faces[:, [k]], n) for k in range(3)], axis=1)
    assert len(set(want_level)) >= 6 and stuck.any() and (want_v != 0).any(), (set(want_level), stuck.sum())
    by_range = (want_level == HELD) & ~stuck & (slots.max(axis=1) <= GUARD_LEVELS)
    assert by_range.any(), "a node held by the position range"
    out, _, _ = run_commit(fs, positions, free, slots, stuck, np.zeros(n, dtype=bool), seed=43, p_valid=0.8)
    check(out, want_p, want_v, want_level)
    # the rollback of that step: P'' − V'', V = 0
    out, _, _ = run_commit(fs, want_p, want_v, slots, stuck, np.ones(n, dtype=bool), seed=44, p_valid=0.8)
    check(out, positions, np.zeros_like(positions), np.zeros(n, dtype=np.int64))


def test_a_rollback_out_of_range_keeps_the_position():
    """A move no commit wrote (``P − V`` out of range) neither wraps nor clamps: ``P`` stays."""
    fs = FormatSet.preset("default")
    pos, vel = fs.position, fs.velocity
    positions = np.array([[pos.raw_min, 0], [0, pos.raw_max], [pos.raw_min + 5, 7], [pos.raw_max, pos.raw_min]])
    moves = np.array([[1, 0], [0, -1], [5, 0], [vel.raw_min, vel.raw_max]])
    outside = np.array([1, 1, 0, 1])
    want_p = np.where(outside[:, None] == 1, positions, positions - moves)
    out, _, _ = run_commit(fs, positions, moves, np.zeros((4, 3), dtype=np.int64), np.zeros(4, dtype=bool),
                           np.ones(4, dtype=bool))
    check(out, want_p, np.zeros_like(moves), np.zeros(4, dtype=np.int64))


#: Independent pin of the stages GuardCommit builds.
LATENCY = 5


@pytest.mark.parametrize("preset", PRESETS)
def test_one_node_per_clock_and_the_latency(preset):
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng(45)
    positions, proposals, slots, stuck = random_nodes(fs, 60, rng)
    rollback = rng.random(60) < 0.3
    out, run, dut = run_commit(fs, positions, proposals, slots, stuck, rollback)
    assert dut.latency == LATENCY
    assert run.in_cycles == list(range(60))
    assert run.out_cycles == [c + LATENCY for c in range(60)]


def test_parameter_validation():
    fs = FormatSet.preset("default")
    with warnings.catch_warnings():  # the refused objects are never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match="GuardCommit needs a FormatSet or a preset name, not 3"):
            GuardCommit(3)
        with pytest.raises(FormatSetNotBuildable, match="fraction bits"):
            GuardCommit(fs.replace(velocity="s3.20"))
        with pytest.raises(FormatSetNotBuildable, match="wider than position"):
            GuardCommit(fs.replace(velocity="s12.22"))
        gc.collect()


@pytest.mark.parametrize("preset", PRESETS)
def test_converts_to_verilog(preset, monkeypatch):
    """Top level: the streams' constant ``ready`` is left out of the ports (amaranth-lang/amaranth#1574)."""
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    fs = FormatSet.preset(preset)
    text = top_level_verilog(GuardCommit(fs), "guard_commit")
    assert "module guard_commit" in text
    width = 2 * fs.position.width + 2 * fs.velocity.width + (GUARD_LEVELS + 1).bit_length()
    assert f"output [{width - 1}:0] o__payload;" in text
