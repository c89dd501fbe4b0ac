"""The fixed-point pipeline and engine: definition, hand-worked example, refusals, accuracy."""

import json
import math
import re
import subprocess
from fractions import Fraction

import numpy as np
import pytest

from golden_model.builtin import builtin_mesh
from golden_model.fixed import FormatSet, SaturationCounter, rsqrt_with_config
from golden_model.fixed.engine import FixedEngine, flatten_fixed, prepare, presets_holding
from golden_model.fixed.measures import FixedPointError, Reciprocal
from golden_model.fixed.pipeline import (NeighbourStream, NodeConstants, edge_terms, neighbour_terms,
                                         node_update)
from sim.generate import dome_grid, generated_meshes, grid_faces, grid_uv, rolled_grid
from sim.layouts import initial_layout, tutte_layout
from golden_model.mesh import Mesh, signed_areas_2d
from golden_model.params import FlattenParams
from golden_model.reference import flatten
from support import PRESETS, SPRINGFLAT

DEFAULT = FormatSet.preset("default")
NARROW = FormatSet.preset("narrow")


@pytest.mark.parametrize("fs", [FormatSet.preset(p) for p in PRESETS], ids=PRESETS)
def test_edge_terms_equal_the_per_entry_definition(fs):
    mesh = dome_grid(9)
    problem = prepare(mesh, tutte_layout(mesh), FlattenParams(density="auto"), fs)
    forward, backward = problem.stream.edge_entries
    rng = np.random.default_rng(0)
    saturated = 0
    for trial in range(24):
        spread = 2 ** (fs.position.frac_bits - 10 + trial % 16)  # up to 32 mean edges: every preset's delta saturates
        p = problem.initial_positions + rng.integers(-spread, spread, size=problem.initial_positions.shape)
        if trial % 2:  # make rounding ties likely
            p = (p >> 3 << 3) | 4 * rng.integers(0, 2, size=p.shape)
        by_entry, by_edge = SaturationCounter(), SaturationCounter()
        force, error = neighbour_terms(fs, p, problem.stream, problem.half_spring, by_entry)
        f_f, f_b, e_f, e_b = edge_terms(fs, p, problem.stream, problem.half_spring, by_edge)
        assert np.array_equal(force[forward], f_f) and np.array_equal(force[backward], f_b)
        assert np.array_equal(error[forward], e_f) and np.array_equal(error[backward], e_b)
        assert by_entry.as_dict() == by_edge.as_dict()
        saturated += by_entry.total
    assert saturated > 0  # the comparison covered saturating entries too


def _rq(x: Fraction, frac_bits: int, lo: int, hi: int) -> int:
    """Round half up to ``frac_bits`` and saturate: the datapath's requantisation, written out."""
    return min(max(math.floor(x * 2**frac_bits + Fraction(1, 2)), lo), hi)


def test_hand_worked_node_update():
    """One node with two neighbours through every rounding point of docs/fixed-point.md."""
    fs = DEFAULT
    F = lambda fmt: fmt.frac_bits  # noqa: E731
    lim = lambda fmt: (fmt.raw_min, fmt.raw_max)  # noqa: E731
    # node 0 at (0.1, -0.2) moving with (0.25, -0.5); neighbours at (1.6, 1.8) and (-0.9, -0.2)
    P = {0: (Fraction(1, 10), Fraction(-2, 10)), 1: (Fraction(16, 10), Fraction(18, 10)), 2: (Fraction(-9, 10), Fraction(-2, 10))}
    raw_p = np.array([[_rq(c, F(fs.position), *lim(fs.position)) for c in P[n]] for n in range(3)])
    rest = {1: Fraction(2), 2: Fraction(5, 4)}
    raw_rest = {j: _rq(d, F(fs.rest_length), *lim(fs.rest_length)) for j, d in rest.items()}
    inv_mass, dt, keep = Fraction(2), Fraction(1, 8), Fraction(9, 10)
    half_c = Fraction(1, 4)  # C = 0.5
    raw = dict(inv_mass=_rq(inv_mass, F(fs.inv_mass), *lim(fs.inv_mass)), dt=_rq(dt, F(fs.dt), *lim(fs.dt)),
               keep=_rq(keep, F(fs.damping), *lim(fs.damping)), half_c=_rq(half_c, F(fs.spring), *lim(fs.spring)))
    half_dt_sq = _rq(Fraction(raw["dt"], 2**F(fs.dt)) ** 2 / 2, F(fs.half_dt_sq), *lim(fs.half_dt_sq))
    velocity = [_rq(Fraction(1, 4), F(fs.velocity), *lim(fs.velocity)), _rq(Fraction(-1, 2), F(fs.velocity), *lim(fs.velocity))]

    def value(r, fmt):
        return Fraction(int(r), 2 ** F(fmt))

    force_sum, error_sum = [0, 0], 0
    for j in (1, 2):
        delta = [_rq(value(raw_p[j][k] - raw_p[0][k], fs.position), F(fs.delta), *lim(fs.delta)) for k in (0, 1)]
        square = sum(value(c, fs.delta) ** 2 for c in delta)
        length_sq = _rq(square, F(fs.length_sq), *lim(fs.length_sq))
        r = int(rsqrt_with_config(np.int64(length_sq), fs.rsqrt_config()))  # the unit, checked on its own
        exact_r = 1 / math.sqrt(float(value(length_sq, fs.length_sq)))
        assert abs(r - exact_r * 2 ** F(fs.rsqrt)) < 1  # faithful
        u = _rq(1 - value(raw_rest[j], fs.rest_length) * value(r, fs.rsqrt), F(fs.spring), *lim(fs.spring))
        s = _rq(value(raw["half_c"], fs.spring) * value(u, fs.spring), F(fs.spring), *lim(fs.spring))
        for k in (0, 1):
            force_sum[k] += _rq(value(s, fs.spring) * value(delta[k], fs.delta), F(fs.force), *lim(fs.force))
        length = _rq(value(length_sq, fs.length_sq) * value(r, fs.rsqrt), F(fs.rest_length), *lim(fs.rest_length))
        error_sum += abs(length - raw_rest[j])
    accel = [_rq(value(f, fs.force_acc) * value(raw["inv_mass"], fs.inv_mass), F(fs.accel), *lim(fs.accel))
             for f in force_sum]
    new_p, new_v = [], []
    for k in (0, 1):
        step = value(raw["dt"], fs.dt) * value(velocity[k], fs.velocity) \
            + value(half_dt_sq, fs.half_dt_sq) * value(accel[k], fs.accel)
        new_p.append(min(max(int(raw_p[0][k]) + _rq(step, F(fs.position), -2**62, 2**62), fs.position.raw_min),
                         fs.position.raw_max))
        kick = _rq(value(raw["dt"], fs.dt) * value(accel[k], fs.accel), F(fs.velocity), -2**62, 2**62)
        v = min(max(velocity[k] + kick, fs.velocity.raw_min), fs.velocity.raw_max)
        new_v.append(_rq(value(v, fs.velocity) * value(raw["keep"], fs.damping), F(fs.velocity), *lim(fs.velocity)))

    stream = NeighbourStream(indptr=np.array([0, 2, 3, 4]), neighbour=np.array([1, 2, 0, 0]),
                             rest=np.array([raw_rest[1], raw_rest[2], raw_rest[1], raw_rest[2]]),
                             inv_mass=np.array([raw["inv_mass"]] * 3))
    velocities = np.array([velocity, [0, 0], [0, 0]])
    counter = SaturationCounter()
    out = node_update(fs, raw_p, velocities, stream, NodeConstants(raw["dt"], half_dt_sq, raw["half_c"], raw["keep"]),
                      counter)
    assert out.positions[0].tolist() == new_p
    assert out.velocities[0].tolist() == new_v
    assert int(out.error_sums[0]) == error_sum << (F(fs.error_acc) - F(fs.rest_length))
    assert counter.total == 0
    # and the example is not trivial: the node moved and felt both springs
    assert new_p != raw_p[0].tolist() and error_sum > 0


def test_zero_step_moves_nothing():
    mesh, _ = builtin_mesh("surf2")
    problem = prepare(mesh, initial_layout(mesh, "tutte"), FlattenParams(), DEFAULT)
    rng = np.random.default_rng(2)
    v = rng.integers(-2**15, 2**15, size=problem.initial_positions.shape)
    constants = NodeConstants(0, 0, problem.half_spring, 1 << DEFAULT.damping.frac_bits)
    out = node_update(DEFAULT, problem.initial_positions, v, problem.stream, constants)
    assert np.array_equal(out.positions, problem.initial_positions) and np.array_equal(out.velocities, v)


def test_reciprocals_are_correctly_rounded():
    for total in [1, 2, 3, 5, 7, 1000, 2**20, 2**20 + 1, 123456789, 2**40 - 3]:
        r = Reciprocal.of(total, 24)
        assert r.mantissa.bit_length() == 24
        assert abs(Fraction(2**r.shift, total) - r.mantissa) <= Fraction(1, 2)


@pytest.mark.parametrize("rounding", ["half_up", "floor", "nearest_even"])
def test_normalisation_is_the_exact_quotient_rounded_once(rounding):
    """``sum·mantissa`` is 64 bits wide in the default set (error_acc u20.16 times reciprocal u1.27): formed
    in int64 it wrapped for error sums of 2^19 mean edges and up, and a huge error normalised to E = 0."""
    fs = DEFAULT.replace(rounding=rounding)
    rng = np.random.default_rng(5)
    mantissa_bits = fs.reciprocal.width
    cases = [(fs.error_acc.raw_max, 3 << 16), (fs.error_acc.raw_max, 2**40 - 3), (2**35 + 7, 2**36 - 5), (0, 5)]
    cases += [(int(t * f), int(t)) for t, f in zip(rng.integers(1, 2**40, 300), rng.uniform(0, 1.2, 300))]
    cases += [(int(rng.integers(0, 2**36)), int(rng.integers(1, 2**24))) for _ in range(100)]
    for sum_raw, total in cases:
        r = Reciprocal.of(total, mantissa_bits)
        exact = Fraction(sum_raw * r.mantissa, 2 ** (r.shift - fs.error.frac_bits))  # E in error lsbs
        low = math.floor(exact)
        if rounding == "floor":
            want = low
        elif rounding == "half_up":
            want = low + (exact - low >= Fraction(1, 2))
        else:
            want = low + (exact - low > Fraction(1, 2) or (exact - low == Fraction(1, 2) and low % 2 == 1))
        assert r.normalise(sum_raw, fs.error, fs.rounding) == min(want, fs.error.raw_max), (sum_raw, total)
    assert Reciprocal.of(3 << 16, mantissa_bits).normalise(fs.error_acc.raw_max, fs.error, fs.rounding) \
        == fs.error.raw_max


def _grid(n: int) -> Mesh:
    uv = grid_uv(n, n, n - 1.0, n - 1.0)
    return Mesh(np.column_stack([uv, np.zeros(len(uv))]), grid_faces(n, n), name=f"grid{n}")


@pytest.mark.parametrize("fs", [DEFAULT, NARROW], ids=["default", "narrow"])
def test_a_layout_with_one_huge_triangle(fs):
    """A 100 x 100 grid grown to a layout with one triangle of doubled area 2^20 - 1 mean edges^2.

    Positions grow up to +-1024 while the layout relaxes (the initial layout must fit +-512).
    Here one corner triangle of the grid spans about [-512, 512]^2; its far corners' other
    triangles lie along the grid's diagonal (little area). At the default set's 44 product
    fraction bits its doubled area is (2^20 - 1) * 2^44 > 2^63: numpy's int64 wrapped it to
    -2^44, so E_S came out 0.05 (and the step size with it) with no saturation counted, where
    it is 53. Now the edges saturate into face_edge (counted) and E_S is 1; the narrow set's
    face_edge holds every edge of its positions, so its areas, E_S and fold count are exact.
    """
    n = 100
    mesh = _grid(n)
    at = lambda i, j: j * n + i  # noqa: E731 (grid vertex i, j)
    c1, a1, far, d1 = at(n - 2, 1), at(n - 2, 0), at(n - 1, 0), at(n - 1, 1)
    p0 = mesh.vertices[:, :2] - mesh.vertices[c1, :2]  # c1 at the origin
    params = FlattenParams(density="auto", max_iter=1)
    problem = prepare(mesh, p0, params, fs)
    assert problem.scale_exp == 0
    layout = p0.copy()
    layout[[a1, far, d1]] = [[-512, -513], [512, -512], [513, 512]]  # a1, d1 by the diagonal through c1
    assert [tuple(f) for f in mesh.faces if far in f] == [(a1, far, d1)]
    raw = np.round(layout * 2**fs.position.frac_bits).astype(np.int64)

    counter = SaturationCounter()
    engine = FixedEngine(problem, counter)
    engine.raw_positions = raw
    fixed = engine.measure()
    exact = flatten(mesh, layout, params).initial
    assert exact.area_error > 50 and engine.errors[0] == fs.error.raw_max  # E_S >= 1 clamps
    if fs is DEFAULT:  # edges of 1024 mean edges do not fit s8.22: counted (and fold counts approximate)
        assert counter.saturations["face_edge"] > 0
    else:
        assert "face_edge" not in counter.saturations and "face_area" not in counter.saturations
        assert (fixed.folded, fixed.flipped) == (exact.folded, exact.flipped) == (0, 0)
        e_s = np.abs(mesh.face_areas - np.abs(signed_areas_2d(layout, mesh.faces))).sum() / mesh.face_areas.sum()
        assert e_s == pytest.approx(exact.area_error, rel=1e-12)


def test_controller_products_are_checked():
    with pytest.raises(ValueError, match=r"product face_edge\*face_edge -> face_area \(E_S cross product\) needs "
                                         r"32 \+ 32 = 64"):
        DEFAULT.replace(face_edge="s9.22", face_area="u18.16")
    with pytest.raises(ValueError, match="face_area u16.16 needs at least 18 integer bits"):
        DEFAULT.replace(face_edge="s9.22")
    with pytest.raises(ValueError, match=r"face_edge s8.21 needs position's fraction bits \(22\)"):
        DEFAULT.replace(face_edge="s8.21")
    with pytest.raises(ValueError, match=r"face_area u16.15 needs error_acc's fraction bits \(16\)"):
        DEFAULT.replace(face_area="u16.15")
    with pytest.raises(ValueError, match=r"reciprocal u1.20 must be u1.F \(a mantissa in \[1, 2\)\) with more "
                                         "fraction bits than error u0.20"):
        DEFAULT.replace(reciprocal="u1.20")
    controller = {p.name: p for p in DEFAULT.products() if p.unit == "controller"}
    assert set(controller) == {"face_edge*face_edge -> face_area (E_S cross product)",
                               "error_acc*reciprocal -> error (E_S, E_C normalisation)"}
    # the normalisation is a scalar formed as a Python int (64 bits here), the cross products int64
    assert not controller["error_acc*reciprocal -> error (E_S, E_C normalisation)"].int64


def _strip(n: int) -> Mesh:
    uv = grid_uv(n, 2, float(n - 1), 1.0)
    return Mesh(np.column_stack([uv, np.zeros(len(uv))]), grid_faces(n, 2), name="strip")


@pytest.mark.parametrize("case, message", [
    ("long strip", "too many edges across"),
    ("heavy density", "1/m"),
    ("short edges", "shortest edge"),
    ("sequential", "jacobi"),
    ("penalty", "penalty"),
])
def test_out_of_range_problems_are_refused(case, message):
    if case == "long strip":
        mesh, params = _strip(1200), FlattenParams(density="auto")
    elif case == "heavy density":
        mesh, params = dome_grid(30), FlattenParams(density=0.5)
    elif case == "short edges":
        # vertex 4 sits 0.0011 from vertex 0 in a unit square: 1/700 of the mean edge
        v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.001, 0.0005, 0]], dtype=float)
        mesh, params = Mesh(v, np.array([[0, 1, 4], [4, 1, 2], [4, 2, 3], [0, 4, 3]])), FlattenParams()
    else:
        mesh, params = dome_grid(5), FlattenParams(density="auto", **{"update": "sequential"} if case == "sequential"
                                                  else {"penalty": True})
    with pytest.raises(FixedPointError, match=message) as info:
        flatten_fixed(mesh, initial_layout(mesh, "pca"), params, DEFAULT)
    assert "\n" not in str(info.value)


def test_trajectory_is_the_scaled_float_trajectory():
    mesh, paper = builtin_mesh("surf2")  # scaled by 2: mean edge 0.56
    p0 = initial_layout(mesh, "pca")
    params = FlattenParams(max_iter=60, tol_area=0, tol_shape=0, tol_energy=0)
    reference = flatten(mesh, p0, params)
    fixed = flatten_fixed(mesh, p0, params, DEFAULT)
    assert fixed.extra["scale"] == 2.0
    mean_edge = mesh.rest_lengths.mean()
    assert np.abs(fixed.positions - reference.positions).max() < 1e-4 * mean_edge
    assert np.abs(fixed.velocities - reference.velocities).max() < 1e-3


def _acceptance(mesh, p0, params):
    reference = flatten(mesh, p0, params)
    fixed = flatten_fixed(mesh, p0, params, DEFAULT)
    assert fixed.status == reference.status
    assert abs(fixed.iterations - reference.iterations) <= 1
    assert abs(fixed.final.area_error - reference.final.area_error) <= 1e-3
    assert abs(fixed.final.shape_error - reference.final.shape_error) <= 1e-3
    # the one saturation allowed is the error measures' own: an E_S or E_C of 1 or more (error is u0.F),
    # once for every measurement at which the float reference's is
    at_one = {name: int((np.asarray(values) >= 1).sum()) for name, values in
              (("area_error", reference.history.area_error), ("shape_error", reference.history.shape_error))}
    assert fixed.extra["saturation_events"] == {name: n for name, n in at_one.items() if n}
    return reference, fixed


@pytest.mark.parametrize("name", ["surf1", "surf2"])
@pytest.mark.parametrize("init", ["pca", "tutte"])
@pytest.mark.parametrize("step", ["fixed", "variable"])
def test_default_preset_follows_float_on_paper_meshes(name, init, step):
    mesh, paper = builtin_mesh(name)
    params = paper.flatten_params(step=step)
    _acceptance(mesh, initial_layout(mesh, init), params)


@pytest.mark.parametrize("name", ["developable", "dome", "saddle", "delaunay"])
@pytest.mark.parametrize("init", ["pca", "tutte"])
@pytest.mark.parametrize("step", ["fixed", "variable"])
def test_default_preset_follows_float_on_generated_meshes(name, init, step):
    mesh = generated_meshes()[name]
    p0 = initial_layout(mesh, init)
    base = FlattenParams(density="auto", damping=0.05, step=step, tol_area=0, tol_shape=0, tol_energy=0.05,
                         max_iter=300)
    # Tolerances the float run meets where both errors still fall by >= 2e-5 per iteration, so that
    # a stop within ±1 iteration is a fair demand; runs that creep (fixed step, heavy masses) keep
    # tolerance 0 and must agree on max-iterations and the final errors.
    probe = flatten(mesh, p0, base)
    s_err, c_err = np.array(probe.history.area_error), np.array(probe.history.shape_error)
    falling = np.flatnonzero((s_err[:-1] - s_err[1:] >= 2e-5) & (c_err[:-1] - c_err[1:] >= 2e-5)) + 1
    falling = falling[falling >= 20]
    params = base
    if len(falling):
        k = int(falling[0])
        params = base.with_(tol_area=float(s_err[k]), tol_shape=float(c_err[k]))
    reference, _ = _acceptance(mesh, p0, params)
    assert reference.status == ("converged" if len(falling) else "max-iterations")


@pytest.mark.slow
def test_cli_fixed_engine(tmp_path):
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf2", "--init", "tutte", "--engine", "fixed", "--json",
                           "--history", tmp_path / "h.csv"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert (summary["engine"], summary["formats"], summary["saturations"]) == ("fixed", "default", 0)
    assert (tmp_path / "h.csv").read_text().count("\n") == summary["iterations"] + 2
    narrow = json.loads(subprocess.run([SPRINGFLAT, "flatten", "surf2", "--init", "tutte", "--engine", "fixed",
                                        "--formats", "narrow", "--json"], capture_output=True, text=True).stdout)
    assert narrow["saturations"] > 0 and narrow["saturation_events"]


def test_cli_notes_the_saturations_of_a_run_and_the_fields_that_saturated():
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf2", "--init", "tutte", "--engine", "fixed", "--formats", "narrow"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    notes = [line for line in proc.stderr.splitlines() if "clamped" in line]
    assert len(notes) == 1 and re.fullmatch(
        r"springflat: note: format set 'narrow' clamped (\d+) values to its range \((rsqrt|one_minus_dr) \d+.*\), which "
        r"moves the result away from the float reference's; a format set with more integer bits holds them \("
        r"presets: default, wide; docs/fixed-point.md\)", notes[0]), notes  # not narrow itself
    quiet = subprocess.run([SPRINGFLAT, "flatten", "surf2", "--init", "tutte", "--engine", "fixed"],
                           capture_output=True, text=True)
    assert quiet.returncode == 0 and "clamped" not in quiet.stderr  # no saturation, no note


def test_cli_a_fixed_point_run_that_ran_away_into_its_range_says_so():
    """The fixed-point engine clamps a runaway instead of diverging: the note says E_S/E_C sit at the top of
    their format and what to try against a runaway (wider formats only move the top: 'wide' ends there too);
    no note that blames the energy rule's rounding."""
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", "fixed", "--dynamics", "paper", "--step",
                           "fixed", "--dt", "0.9", "--max-iter", "200"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert ("E_S or E_C is at the top of its format: the run ran away (the float engine calls such a run diverged), "
            "and the pattern is no flattening; the paper dynamics has no guard: try --damping 0.05, a smaller --dt, "
            "or --dynamics momentum") in proc.stderr
    assert "holds them" not in proc.stderr and "rounding" not in proc.stderr


def test_cli_the_saturation_note_of_a_format_set_file(tmp_path):
    """The note judges the set the run used, also one from a file (its name is no preset's): Surf2 clamps 66
    values in narrow's formats (one_minus_dr, rsqrt) without running away; default and wide hold them."""
    FormatSet.preset("narrow").replace(name="mine").save(tmp_path / "mine.json")
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf2", "--engine", "fixed", "--formats", tmp_path / "mine.json",
                           "--out", tmp_path / "o.flat.obj"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert ("format set 'mine' clamped 66 values to its range (one_minus_dr 54, rsqrt 12), which moves the result "
            "away from the float reference's; a format set with more integer bits holds them (presets: default, "
            "wide;") in proc.stderr


@pytest.mark.parametrize("formats, message", [
    ("nosuchpreset", "unknown FormatSet preset"),
    ("bad.json", "product spring*spring (1/2 C * u)"),
])
def test_cli_bad_formats(tmp_path, formats, message):
    spec = DEFAULT.to_dict()
    spec["formats"]["spring"] = "s30.20"
    (tmp_path / "bad.json").write_text(json.dumps(spec))
    proc = subprocess.run([SPRINGFLAT, "flatten", "--engine", "fixed", "--formats", formats, "--out", "o.obj"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1 and message in proc.stderr
    assert not (tmp_path / "o.obj").exists()


def test_cli_refuses_a_mesh_out_of_range(tmp_path):
    mesh = _strip(1200)
    from sim.mesh_io import save_obj
    save_obj(tmp_path / "strip.obj", mesh.vertices, mesh.faces)
    proc = subprocess.run([SPRINGFLAT, "flatten", "strip.obj", "--engine", "fixed", "--out", "o.obj"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2 and "too many edges across" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "o.obj").exists()


def _wheel(spokes: int) -> Mesh:
    """A cone's tip as CAD tessellates it: one vertex with ``spokes`` neighbours, the ring around it."""
    angle = 2 * np.pi * np.arange(spokes) / spokes
    vertices = np.vstack([[0.0, 0.0, 0.5], np.column_stack([np.cos(angle), np.sin(angle), np.zeros(spokes)])])
    faces = np.array([[0, 1 + i, 1 + (i + 1) % spokes] for i in range(spokes)])
    return Mesh(vertices, faces, name="wheel")


def test_presets_holding_are_the_presets_a_problem_fits():
    wheel, dome = _wheel(40), dome_grid(9)
    assert presets_holding(wheel, tutte_layout(wheel), FlattenParams(dynamics="momentum")) == ["wide"]  # degree 40
    assert presets_holding(wheel, None, FlattenParams(dynamics="momentum")) == ["wide"]  # the mesh alone decides it
    assert presets_holding(dome, tutte_layout(dome), FlattenParams(density="auto")) == ["default", "narrow", "wide"]


def test_cli_names_the_preset_that_holds_a_mesh_the_default_formats_refuse(tmp_path):
    from sim.mesh_io import save_obj

    wheel = _wheel(40)
    save_obj(tmp_path / "wheel.obj", wheel.vertices, wheel.faces)
    proc = subprocess.run([SPRINGFLAT, "flatten", "wheel.obj", "--engine", "fixed", "--out", "o.obj"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr == (
        "springflat: error: a node has 40 neighbours; format set 'default' accumulates at most 32 (max_degree); "
        "the preset wide holds it: --formats wide\n")
    assert not (tmp_path / "o.obj").exists()
    proc = subprocess.run([SPRINGFLAT, "flatten", "wheel.obj", "--engine", "fixed", "--formats", "wide", "--json"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert (summary["formats"], summary["status"], summary["folded"]) == ("wide", "converged", 0)


def test_per_node_sums_are_exact_where_float64_is_not():
    """``rest_length`` of 29 bits (the widest whose Σe² accumulator, 2·29 + 5 guard bits, fits 63): the
    squares of |L − d| reach 2^58 and their per-node sums must still be exact (float64 keeps 53 bits)."""
    from golden_model.fixed.pipeline import node_terms

    fs = DEFAULT.replace(rest_length="u3.26", error_acc="u20.26", face_area="u16.26", name="wide")
    mesh = dome_grid(6)
    problem = prepare(mesh, tutte_layout(mesh), FlattenParams(density="auto"), fs)
    stream = problem.stream
    # rest lengths of 1 lsb against edges of several mean edges: e = |L - d| near 2^28 raw
    stream = NeighbourStream(stream.indptr, stream.neighbour, np.ones_like(stream.rest), stream.inv_mass)
    positions = problem.initial_positions * 6 + np.arange(problem.initial_positions.size).reshape(-1, 2) * 7919
    terms = node_terms(fs, positions, stream, problem.half_spring)
    _, error = neighbour_terms(fs, positions, stream, problem.half_spring)  # the per-entry definition
    assert int(error.max()) ** 2 > 2**53  # float64 could not hold these squares exactly
    spans = zip(stream.indptr[:-1], stream.indptr[1:])
    assert terms.error_squares.tolist() == [sum(int(v) ** 2 for v in error[a:b]) for a, b in spans]
    assert terms.error_sums.tolist() == [min(int(error[a:b].sum()), fs.error_acc.raw_max)
                                         for a, b in zip(stream.indptr[:-1], stream.indptr[1:])]


def test_accumulators_that_would_not_fit_int64_are_refused():
    with pytest.raises(ValueError, match=r"the error_squares accumulator takes 67 bits > 63"):
        DEFAULT.replace(rest_length="u3.28", error_acc="u20.28", face_area="u16.28")
    with pytest.raises(ValueError, match=r"the error_squares accumulator takes 65 bits > 63"):
        DEFAULT.replace(rest_length="u3.26", error_acc="u20.26", face_area="u16.26", max_degree=128)
    with pytest.raises(ValueError, match=r"the position step takes 64 bits > 63"):  # Δt·V shifted 48 bits up
        DEFAULT.replace(dt="u0.10", half_dt_sq="u0.24", accel="s4.34", velocity="s3.10", position="s10.10",
                        delta="s3.10", face_edge="s8.10")
    assert DEFAULT.accumulators() == {"force": (True, 30), "error": (False, 23), "error_squares": (False, 41),
                                      "barrier_energy": (False, 57)}


def test_clamps_of_the_error_measures_alone_are_said_to_move_nothing():
    """Surf1 from Tutte in the default formats: 11 layouts with E_S of 1 or more, held at error's top. The note
    said they moved the result from float's and sent the user to 'wide', whose error format is the same."""
    from support import run_springflat

    proc = run_springflat("flatten", "surf1", "--init", "tutte", "--engine", "fixed", "--formats", "default")
    assert proc.returncode == 0 and "11 saturation events" in proc.stdout, proc.stdout
    assert ("springflat: note: format set 'default' held 11 E_S/E_C measures of 1 or more at the top of its error "
            "format (u0.20): no step or stop rule tells them from 1, so the run is not moved by them, but --history "
            "records such a layout's E_S or E_C as 0.999999") in proc.stderr, proc.stderr
    assert "wide" not in proc.stderr


def test_a_format_set_whose_bound_promises_nothing_says_so(tmp_path):
    """velocity s3.2: the bound is 100 (E_S, E_C are at most 1) and the run went far from float's with no
    saturation and no word."""
    from support import run_springflat

    FormatSet.preset("default").replace(velocity="s3.2", name="vel2").save(tmp_path / "vel2.json")
    assert FormatSet.load(tmp_path / "vel2.json").accuracy_bound() >= 1
    coarse = run_springflat("flatten", "surf1", "--engine", "fixed", "--formats", tmp_path / "vel2.json")
    assert coarse.returncode == 0 and ("springflat: note: format set 'vel2' is so coarse that its accuracy bound "
                                       "against the float engine is 100, which promises nothing") in coarse.stderr
    plain = run_springflat("flatten", "surf1", "--engine", "fixed", "--formats", "default")
    assert plain.returncode == 0 and "so coarse" not in plain.stderr
