"""RTL guard certificate (hdl.GuardCertificate) against the golden model's ``triangle_levels_raw`` and
``stuck_nodes_raw``, in Amaranth's simulator: every triangle's level and stuck corners, bit for bit, in
order, at the stated latency."""

import dataclasses
import gc
import warnings

import numpy as np
import pytest
from amaranth.back import verilog
from amaranth.hdl import UnusedElaboratable

from golden_model.fixed import FormatSet
from golden_model.fixed.dsp import Operand, dsp_blocks
from golden_model.fixed.guard import floor_min_raw, stuck_nodes_raw, triangle_levels_raw
from golden_model.guard import GUARD_LEVELS
from hdl.dsp import mult18x18d_count
from hdl.fixedpoint import FormatSetNotBuildable
from hdl.guard_certificate import GuardCertificate
from hdl.layouts import certificate_result_layout
from sim.payloads import pack_beats
from support import PRESETS
from support.streams import run_streams



def golden(fs, corners, moves, areas, winding):
    """``((F,) levels, (F,) stuck corners)`` for triangles ``corners``/``moves`` (F, 3, 2) raw:
    ``triangle_levels_raw``, and ``stuck_nodes_raw`` of each triangle's corners as bits (corner k: bit k),
    each triangle on nodes of its own."""
    n = len(corners)
    faces = np.arange(3 * n).reshape(n, 3)
    args = (fs, corners.reshape(-1, 2), moves.reshape(-1, 2), faces, winding, floor_min_raw(fs, areas))
    stuck = stuck_nodes_raw(*args)[faces].astype(np.int64)
    return triangle_levels_raw(*args), stuck[:, 0] | stuck[:, 1] << 1 | stuck[:, 2] << 2


def results(run):
    """``(levels, stuck corners)`` of the RTL's outputs (``certificate_result_layout``'s fields)."""
    layout = certificate_result_layout()
    fields = [layout["level"], layout["stuck"]]
    return tuple(np.array([(out >> f.offset) & ((1 << f.width) - 1) for out in run.outputs], dtype=np.int64)
                 for f in fields)


def certificate_beats(dut, corners, moves, areas):
    fields = {name: {"x": corners[:, k, 0], "y": corners[:, k, 1]} for k, name in enumerate("abc")}
    fields.update({f"move_{name}": {"x": moves[:, k, 0], "y": moves[:, k, 1]} for k, name in enumerate("abc")})
    fields["area"] = areas
    return pack_beats(dut.i.payload.shape(), fields)


def triangles(fs, n, rng):
    """``n`` triangles of every kind the certificate meets: sizes from 2^-12 to 8 real units, proposals
    from 1/100 to 30 times the size (every level from 0 to GUARD_LEVELS + 1 turns up), near-degenerate
    ones, ones whose edges do not fit face_edge, host areas from 0 to face_area's max."""
    pos, vel = fs.position, fs.velocity
    size = 2.0 ** rng.uniform(-12, 3, n)
    centre = rng.uniform(-0.5, 0.5, (n, 1, 2)) * 2.0 ** (pos.width - pos.frac_bits - 2)
    shape = rng.normal(size=(n, 3, 2))
    flat = rng.random(n) < 0.1  # near-degenerate: the third corner close to the first edge
    shape[flat, 2] = 0.5 * (shape[flat, 0] + shape[flat, 1]) + 1e-4 * rng.normal(size=(flat.sum(), 2))
    real = centre + shape * size[:, None, None]
    wide = rng.random(n) < 0.05  # edges over face_edge's range
    real[wide, 1] = -np.sign(real[wide, 0]) * 2.0 ** (pos.width - pos.frac_bits - 1) * 0.9
    corners = np.clip(np.round(real * 2.0**pos.frac_bits), pos.raw_min, pos.raw_max).astype(np.int64)
    reach = size * 10.0 ** rng.uniform(-2, 1.5, n)
    moves = rng.normal(size=(n, 3, 2)) * reach[:, None, None]
    still = rng.random((n, 3)) < 0.15  # corners that do not move
    moves[still] = 0
    moves = np.clip(np.round(moves * 2.0**vel.frac_bits), vel.raw_min, vel.raw_max).astype(np.int64)
    area = fs.face_area
    areas = np.where(rng.random(n) < 0.1, rng.choice([0, area.raw_max], n),
                     np.round(0.5 * size**2 * rng.uniform(0.1, 2, n) * 2.0**area.frac_bits)).astype(np.int64)
    return corners, moves, np.clip(areas, 0, area.raw_max)


def run_certificate(fs, corners, moves, areas, winding, *, interval=1, seed=0, p_valid=1.0, p_ready=1.0,
                    ready_after=0, registered_valid=False):
    dut = GuardCertificate(fs, interval=interval, registered_valid=registered_valid)

    def setup(ctx):
        ctx.set(dut.winding_negative, int(winding < 0))

    run = run_streams(dut, certificate_beats(dut, corners, moves, areas), seed=seed, p_valid=p_valid,
                      p_ready=p_ready, ready_after=ready_after, setup=setup)
    return dut, run


@pytest.mark.slow
@pytest.mark.parametrize("interval", [1, 2])
@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("winding", [1.0, -1.0])
def test_levels_are_the_golden_models_with_gaps_and_back_pressure(preset, winding, interval):
    fs = FormatSet.preset(preset)
    rng = np.random.default_rng([7, int(winding > 0), PRESETS.index(preset)])
    corners, moves, areas = triangles(fs, 600, rng)
    if winding < 0:  # the same triangles wound the other way
        corners = corners[:, ::-1].copy()
        moves = moves[:, ::-1].copy()
    want, want_stuck = golden(fs, corners, moves, areas, winding)
    assert set(np.unique(want)) == set(range(GUARD_LEVELS + 2)), "the triangles must reach every level"
    assert set(np.unique(want_stuck)) == set(range(8)), "every combination of stuck corners must turn up"
    _, run = run_certificate(fs, corners, moves, areas, winding, interval=interval, seed=3, p_valid=0.7, p_ready=0.6)
    got, got_stuck = results(run)
    mismatch = np.flatnonzero(got != want)
    assert mismatch.size == 0, f"{mismatch.size} of {len(want)} levels differ, first at {mismatch[:5]}: " \
                               f"RTL {got[mismatch[:5]]}, golden {want[mismatch[:5]]}"
    mismatch = np.flatnonzero(got_stuck != want_stuck)
    assert mismatch.size == 0, f"{mismatch.size} of {len(want)} stuck corners differ, first at {mismatch[:5]}: " \
                               f"RTL {got_stuck[mismatch[:5]]}, golden {want_stuck[mismatch[:5]]}"


@pytest.mark.parametrize("registered_valid", [False, True])
@pytest.mark.parametrize("interval", [1, 2])
@pytest.mark.parametrize("preset", PRESETS)
def test_latency_and_order(preset, interval, registered_valid):
    """``registered_valid`` (``o.valid`` from a flip-flop) changes no clock."""
    fs = FormatSet.preset(preset)
    corners, moves, areas = triangles(fs, 24, np.random.default_rng(11))
    dut, run = run_certificate(fs, corners, moves, areas, 1.0, interval=interval, registered_valid=registered_valid)
    assert [o - i for i, o in zip(run.in_cycles, run.out_cycles)] == [dut.latency] * len(corners)
    # a triangle offered every clock goes in every ``interval`` clocks
    assert set(np.diff(run.in_cycles)) == {interval}
    assert [list(r) for r in results(run)] == [list(g) for g in golden(fs, corners, moves, areas, 1.0)]


@pytest.mark.parametrize("registered_valid", [False, True])
@pytest.mark.parametrize("interval", [1, 2])
def test_a_stopped_consumer_takes_every_level_once_the_credits_ran_out(interval, registered_valid):
    """Nothing is taken for 120 clocks: exactly ``credits`` triangles go in meanwhile, none is lost; then the
    levels come one per clock."""
    fs = FormatSet.preset("default")
    corners, moves, areas = triangles(fs, 80, np.random.default_rng(5))
    dut, run = run_certificate(fs, corners, moves, areas, 1.0, interval=interval, ready_after=120,
                               registered_valid=registered_valid)
    assert sum(cycle < 120 for cycle in run.in_cycles) == dut.credits
    assert list(np.diff(run.out_cycles[:dut.credits])) == [1] * (dut.credits - 1)
    assert [list(r) for r in results(run)] == [list(g) for g in golden(fs, corners, moves, areas, 1.0)]


def test_parameter_validation():
    # A component whose __init__ raises is still reported as unused when collected.
    fs = FormatSet.preset("default")
    other = dataclasses.replace(fs, velocity=dataclasses.replace(fs.velocity, frac_bits=fs.velocity.frac_bits - 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        with pytest.raises(TypeError, match="GuardCertificate needs a FormatSet or a preset name, not 3"):
            GuardCertificate(3)
        with pytest.raises(FormatSetNotBuildable, match="share their fraction bits"):
            GuardCertificate(other)
        with pytest.raises(ValueError, match="interval must be 1 or 2, not 3"):
            GuardCertificate(fs, interval=3)
        with pytest.raises(TypeError, match="registered_valid must be a bool, not 1"):
            GuardCertificate(fs, registered_valid=1)
        gc.collect()


@pytest.mark.parametrize("preset", PRESETS)
def test_converts_to_verilog(preset, monkeypatch):
    monkeypatch.setenv("AMARANTH_USE_YOSYS", "builtin")
    text = verilog.convert(GuardCertificate(preset), name="guard_certificate")
    assert "module guard_certificate" in text
    assert f"output [{(GUARD_LEVELS + 1).bit_length() + 3 - 1}:0] o__payload;" in text  # the level, 3 stuck bits


@pytest.mark.parametrize("preset", PRESETS)
def test_interval_two_shares_each_multiplier_between_a_cross_products_two_products(preset):
    """7 cross products (X0: face_edge², L_k: velocity × face_edge, Q_k: velocity²) of two multiplies each,
    at the golden model's split rule: all 14 in DSP blocks at II 1, one block per pair at II 2."""
    fs = FormatSet.preset(preset)
    edge, move = Operand.of(fs.face_edge), Operand.of(fs.velocity)
    per_pair = dsp_blocks(edge, edge) + 3 * dsp_blocks(move, edge) + 3 * dsp_blocks(move, move)
    assert mult18x18d_count(GuardCertificate(fs)) == 2 * per_pair
    assert mult18x18d_count(GuardCertificate(fs, interval=2)) == per_pair
