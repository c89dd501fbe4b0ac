"""Error studies: cost model, comparison records, sweeps, the greedy optimiser and `springflat study`."""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest

import sim.study.flow as study_flow
from golden_model.fixed import FormatSet
from golden_model.fixed.engine import flatten_fixed
from golden_model.params import ParameterError
from golden_model.reference import flatten
from golden_model.study import (
    AccuracyTarget,
    Config,
    class_changes,
    make_config,
    parse_bits,
    parse_knobs,
    sweep_configs,
)
from sim.study.cases import build_cases
from sim.outputs import OutputError
from sim.study.cli import REPORT_FILES, REPORT_TITLE, add_parser, cmd_study
from sim.study.cost import cost, multipliers
from sim.study.flow import Study


def tiny_formats(**changes) -> FormatSet:
    """Every operand <= 18 bits, so each multiplication is one 18x18 block."""
    fs = FormatSet(
        position="s4.8", velocity="s2.8", delta="s3.8", rest_length="u3.8", length_sq="u6.10", rsqrt="u4.8",
        spring="s3.8", force="s3.8", force_acc="s4.8", inv_mass="u3.8", accel="s4.8", dt="u0.12",
        half_dt_sq="u0.12", error_acc="u10.8", error="u0.10", lut_entry="u0.12", damping="u1.10",
        area="s6.8", barrier_gain="u4.8", barrier_coeff="u3.8", power="s6.8", power_acc="s12.8",
        face_edge="s5.8", face_area="u10.8", reciprocal="u1.18",
        rsqrt_seed_bits=6, rsqrt_newton_steps=1, lut_index_bits=6, lut_interpolate=True, name="tiny")
    return fs.replace(**changes) if changes else fs


# ----------------------------------------------------------------------------- cost model


def test_cost_model_by_hand():
    fs = tiny_formats()
    c = cost(fs)
    # widths of the 19 datapath formats (error u0.10 and lut_entry u0.12 are the step generator's,
    # power_acc the controller's)
    assert c.total_bits == 13 + 11 + 12 + 11 + 16 + 12 + 12 + 12 + 13 + 11 + 13 + 12 + 12 + 18 + 11 \
        + 15 + 12 + 11 + 15 == 242
    # one block each: delta^2 x2, d*r, L, s*delta x2, F/m x2, dt*V x2, dt*a x2, hdt2*a x2, dt*dt,
    # V*damping x2, LUT interpolation x2 (one per lookup lane), 1/2C*u  = 20; the barrier's cross
    # product x2, G*h, c*D x2 and the momentum's F.V x2 = 7; rsqrt: out u4.8 -> Fy = 12 + 3 = 15,
    # operands y u1.15 (16), M u2.15 (17), y^2 u1.15, h s0.15 (16): 3 blocks per Newton step
    assert c.dsp == 20 + 7 + 3 == 30
    # seed ROM: 3 * 2**(6-2) = 48 entries of min(15, 6 + 3) = 9 bits; LUT: 65 entries of 12 bits
    assert c.rom_bits == 48 * 9 + 65 * 12 == 1212

    wide = tiny_formats(rsqrt="u4.14")  # out value bits 18 -> Fy 21: rsqrt operands 22/23 bits -> 2x2 blocks
    # d*r 11 x 18 and L 16 x 18 stay at one block; the 3 rsqrt products go to 4 blocks each
    assert cost(wide).dsp == 20 + 7 + 12
    assert cost(wide).total_bits == 242 + 6
    two_steps = tiny_formats(rsqrt_newton_steps=2)
    assert cost(two_steps).dsp == 20 + 7 + 6
    # delta 20 bits (a signed product's slices: 17 + 3): delta^2 and the barrier's cross product
    # 2x2 x2 each, s*delta and c*D 1x2 x2 each
    wider_delta = tiny_formats(delta="s3.16", position="s4.16", face_edge="s5.16")
    assert cost(wider_delta).dsp == 30 - 2 - 2 + 8 + 4 - 2 - 2 + 8 + 4
    assert cost(wider_delta).total_bits == 242 + 16
    no_interp = tiny_formats(lut_interpolate=False)
    assert cost(no_interp).dsp == 28
    names = [m[0] for m in multipliers(fs)]
    assert sum(m[3] for m in multipliers(fs)) == 30  # every product here is one block
    assert any(n.startswith("spring*spring (1/2 C * u)") for n in names)
    assert cost(fs).key("bits") == (242, 30, 1212) and cost(fs).key("dsp") == (30, 242, 1212)
    # an unsigned 18-bit operand of a signed product: slices 17 + 1, the 1-bit slice a multiplexer
    assert cost(tiny_formats(inv_mass="u3.15")).dsp == 30


def test_presets_cost_ordering():
    d, n = cost(FormatSet.preset("default")), cost(FormatSet.preset("narrow"))
    assert n.total_bits < d.total_bits and n.dsp <= d.dsp


# ----------------------------------------------------------------------------- knobs and sweeps


def test_class_changes_keep_tied_offsets():
    d = FormatSet.preset("default")
    ch = class_changes(d, "rest_length", d.rest_length.frac_bits - 3)
    assert set(ch) == {"rest_length", "error_acc", "face_area"}
    fs = d.replace(**ch)
    assert fs.error_acc.frac_bits - fs.rest_length.frac_bits == d.error_acc.frac_bits - d.rest_length.frac_bits
    ch = class_changes(d, "position", 12)
    assert FormatSet.replace(d, **ch).delta.frac_bits == 12 == FormatSet.replace(d, **ch).position.frac_bits


def test_sweep_records_invalid_combinations():
    d = FormatSet.preset("default")
    configs = sweep_configs(d, ["rsqrt", "lut_index_bits", "rounding"], (8, 60, 4))
    by_label = {c.label: c for c in configs}
    assert f"rsqrt={d.rsqrt.frac_bits}" not in by_label  # the base value is not repeated
    bad = [c for c in configs if c.fs is None]
    assert bad and all(c.error for c in bad)
    assert any("int64" in c.error for c in bad)  # a too-wide rsqrt makes a product exceed 63 bits
    assert {c.value for c in configs if c.knob == "rounding"} == {"floor", "nearest_even"}
    narrow_error = make_config(d, "x", error="u0.6")  # lut_index_bits 8 > 6 fraction bits
    assert narrow_error.fs is None and "lut_index_bits" in narrow_error.error


def test_parse_helpers():
    assert parse_bits("8:20") == (8, 20, 1) and parse_bits("8:20:4") == (8, 20, 4)
    for bad in ("8", "20:8", "a:b", "8:20:0", "-1:4", "8:70", "1:2:3:4"):
        with pytest.raises(ParameterError):
            parse_bits(bad)
    assert parse_knobs("none") == []
    assert parse_knobs("frac")[:2] == ["position", "velocity"]
    assert parse_knobs("rounding,delta".replace("delta", "position")) == ["position", "rounding"]
    with pytest.raises(ParameterError):
        parse_knobs("bogus")
    with pytest.raises(ParameterError):
        build_cases(["no-such-mesh"])


# ----------------------------------------------------------------------------- comparison


@pytest.fixture(scope="module")
def surf1_cases():
    return build_cases(["surf1"], ["pca"], ["variable", "fixed"], max_iter=60)


def test_float_reference_computed_once(monkeypatch, surf1_cases):
    calls = []

    def counting(*a, **kw):
        calls.append(1)
        return flatten(*a, **kw)

    monkeypatch.setattr(study_flow, "flatten", counting)
    d = FormatSet.preset("default")
    st = Study(surf1_cases)
    st.evaluate([Config("a", d, "base"), make_config(d, "b", velocity="s3.18")])
    st.evaluate([make_config(d, "c", velocity="s3.17")])
    assert len(calls) == len(surf1_cases)


def test_classes_no_case_reads_change_no_result_and_the_optimiser_keeps_them(surf1_cases):
    """The built-ins run the paper dynamics undamped and without the fold barrier: area, barrier, power and
    damping are never read, so any width of theirs 'meets the target' and the optimiser took them to 0 bits,
    'savings' of nothing measured (a chosen.json with area s8.0). It keeps them at the base's widths."""
    from golden_model.params import FlattenParams
    from golden_model.study import GENERATED_PARAMS, unexercised_classes

    assert unexercised_classes(c.params for c in surf1_cases) == ("damping", "area", "barrier", "power")
    assert unexercised_classes([GENERATED_PARAMS]) == ("area", "barrier", "power")  # damped: damping is read
    assert unexercised_classes([FlattenParams(dynamics="momentum")]) == ("damping",)  # barrier and restart on
    d = FormatSet.preset("default")
    st = Study(surf1_cases)
    narrowed = make_config(d, "narrowed", area="s8.0", barrier_gain="u8.0", barrier_coeff="u4.0", power="s9.0",
                           power_acc="s30.0", damping="u1.0")
    base, cut = st.evaluate([Config("base", d, "base"), narrowed])
    assert [(r.d_area, r.d_shape, r.d_iterations) for r in st.records(narrowed)] == [
        (r.d_area, r.d_shape, r.d_iterations) for r in st.records(Config("base", d, "base"))]
    assert not {knob for _, knob, _, _ in st._moves(d, (1, 2, 4, 8))} & {"damping", "area", "barrier", "power"}


def test_records_match_an_independent_run(surf1_cases):
    d = FormatSet.preset("default")
    st = Study(surf1_cases)
    (summary,) = st.evaluate([Config("base", d, "base")])
    for case, rec in zip(surf1_cases, st.records(Config("base", d, "base"))):
        ref = flatten(case.mesh, case.positions, case.params)
        fx = flatten_fixed(case.mesh, case.positions, case.params, d)
        assert rec.d_area == abs(fx.final.area_error - ref.final.area_error)
        assert rec.d_shape == abs(fx.final.shape_error - ref.final.shape_error)
        assert rec.d_iterations == fx.iterations - ref.iterations
        err = np.hypot(*(fx.positions - ref.positions).T) / case.mesh.rest_lengths.mean()
        assert rec.max_position_error == pytest.approx(err.max())
        assert rec.rms_position_error == pytest.approx(math.sqrt(np.mean(err**2)))
    assert summary.meets  # the default preset is designed for 1e-3


def test_error_measure_clamps_shared_with_the_float_run_do_not_fail_the_target():
    """Surf1 from Tutte, variable step: the float run's E_S passes 1 at 11 measurements, and the default
    formats hold those E_S just below 1 (11 ``area_error`` events). They are the clamp the step applies
    anyway, so the record meets the target; an event the float run does not share would not."""
    (case,) = build_cases(["surf1"], ["tutte"], ["variable"])
    d = FormatSet.preset("default")
    st = Study([case], AccuracyTarget(1e-3))
    (summary,) = st.evaluate([Config("base", d, "base")])
    (rec,) = st.records(Config("base", d, "base"))
    assert (rec.saturations, rec.measure_clamps, rec.saturated_signals) == (11, 11, "area_error:11")
    assert summary.meets and summary.saturations == 0
    assert AccuracyTarget(1e-3).failures(dataclasses.replace(rec, measure_clamps=10)) == [
        "1 saturations (area_error:11)"]


def test_too_narrow_configuration_misses_the_target(surf1_cases):
    d = FormatSet.preset("default")
    narrow_delta = make_config(d, "position=5", **class_changes(d, "position", 5))
    assert narrow_delta.fs is not None
    st = Study(surf1_cases, AccuracyTarget(1e-3))
    (s,) = st.evaluate([narrow_delta])
    assert not s.meets and s.failed >= 1 and s.first_failure
    assert s.worst_deviation > 1e-3 or s.status_mismatches or s.max_abs_d_iterations > 1
    ok, why = st.meets(narrow_delta)
    assert not ok and why
    # an invalid combination is reported as not meeting the target on every case
    (inv,) = st.evaluate([make_config(d, "bad", error="u0.4")])
    assert not inv.meets and inv.refused == len(surf1_cases) and inv.cost is None


@pytest.mark.slow
def test_optimiser_result_meets_the_target_on_its_cases(surf1_cases):
    target = AccuracyTarget(1e-3)
    base = FormatSet.preset("default")
    with Study(surf1_cases, target) as st:
        st.evaluate(sweep_configs(base, ["position", "spring", "rsqrt_seed_bits"], (8, 16, 4)))
        res = st.optimise(base, "bits")
        assert res.best is not None and res.steps, res.reason
        assert cost(res.best.fs).key("bits") < cost(base).key("bits")
        cheapest = st.cheapest("bits")
        assert cheapest is not None and cheapest.meets
    # check every accepted configuration independently of the study's cache
    for step in res.steps:
        for case in surf1_cases:
            ref = flatten(case.mesh, case.positions, case.params)
            fx = flatten_fixed(case.mesh, case.positions, case.params, step.config.fs)
            assert abs(fx.final.area_error - ref.final.area_error) <= target.error
            assert abs(fx.final.shape_error - ref.final.shape_error) <= target.error
            assert fx.status == ref.status and abs(fx.iterations - ref.iterations) <= target.iterations
            assert fx.extra["saturations"] == 0
    # and no single-bit move from the result is acceptable
    assert res.rejected and all("meets the target" not in why for _, why in res.rejected)


# ----------------------------------------------------------------------------- the command


def _parse(argv):
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="command")
    add_parser(sub)
    return parser.parse_args(["study", *argv])


def test_parser_defaults():
    args = _parse([])
    assert args.func is cmd_study
    assert args.meshes == ["surf1", "surf2", "developable", "dome", "saddle", "delaunay"]
    assert (args.init, args.step, args.sweep, args.base, args.target, args.optimise) == \
        ("both", "both", "all", "default", 1e-3, True)
    assert _parse(["--no-optimise"]).optimise is False


@pytest.mark.parametrize("argv, message", [
    (["--bits", "20:8"], "--bits"),
    (["--bits", "x"], "--bits"),
    (["--sweep", "nonsense"], "--sweep"),
    (["--sweep", "none,frac"], "--sweep none,frac: 'none' sweeps nothing: give it alone, or drop it"),
    (["--sweep", "none", "--bits", "8:12"], "--bits sets the fraction bits swept for each signal class; --sweep "
                                            "none sweeps no signal class: give --sweep frac, or a class, instead"),
    (["--sweep", "lut_interpolate,rounding", "--bits", "8:12"], "--sweep lut_interpolate,rounding sweeps no signal class"),
    (["no-such-mesh"], "unknown mesh"),
    (["--base", "no/such/formats.json"], "not found"),
    (["--target", "0"], "--target"),
    (["--jobs", "0"], "--jobs must be >= 1, got 0"),
    (["--workers", "0"], "--jobs must be >= 1, got 0"),  # its older name, the same option
    (["--jobs", "1000000"], "--jobs 1000000: at most .* local worker processes"),
    (["--scheduler", "tcp://host:65536"], "--scheduler 'tcp://host:65536': port 65536 is not in 1-65535"),
    (["--jobs", "2", "--scheduler", "tcp://127.0.0.1:8786"], "--jobs sets the local worker processes; the "
                                                               "Dask scheduler at 'tcp://127.0.0.1:8786' has its own"),
])
def test_bad_input_is_a_parameter_error(tmp_path, argv, message):
    with pytest.raises(ParameterError, match=message):
        cmd_study(_parse([*argv, "--out", str(tmp_path / "out"), "--quiet"]))
    assert not (tmp_path / "out").exists()


def test_a_mesh_given_twice_is_refused_as_flatten_refuses_it(tmp_path):
    """``study surf1 surf1`` ran every case of Surf1 twice."""
    from sim.run_options import UserError

    with pytest.raises(UserError, match="^the mesh 'surf1' is given twice$"):
        cmd_study(_parse(["surf1", "surf1", "--out", str(tmp_path / "out"), "--quiet"]))
    assert not (tmp_path / "out").exists()


def test_a_report_that_would_replace_its_own_base_is_refused_before_the_study(tmp_path, monkeypatch):
    """study's docs check a choice with --base study-report/chosen.json: into the default --out the new
    chosen.json would replace it. Refused at once (it was refused after the whole study), nothing written."""
    from sim.outputs import OutputError

    monkeypatch.chdir(tmp_path)
    Path("study-report").mkdir()
    FormatSet.preset("default").save("study-report/chosen.json")
    before = Path("study-report/chosen.json").read_bytes()
    with pytest.raises(OutputError, match=r"^output \(written when a format set meets the target\) "
                                          r"'study-report/chosen.json' is the same file as --base "
                                          r"'study-report/chosen.json'$"):
        cmd_study(_parse(["surf1", "--base", "study-report/chosen.json", "--sweep", "none", "--no-optimise",
                          "--quiet"]))
    assert os.listdir("study-report") == ["chosen.json"] and Path("study-report/chosen.json").read_bytes() == before


def test_an_earlier_choice_that_this_report_does_not_make_is_removed_and_said(tmp_path, monkeypatch, capsys):
    """A chosen.json beside a report that chose nothing would mislead (a build would take it); it goes, and the
    result line says so."""
    monkeypatch.chdir(tmp_path)
    Path("s").mkdir()
    Path("s/report.md").write_text(f"{REPORT_TITLE}\n\nan earlier study's report\n")
    FormatSet.preset("narrow").save("s/chosen.json")
    assert cmd_study(_parse(["dome", "--sweep", "none", "--no-optimise", "--workers", "1", "--max-iter", "5",
                             "--target", "1e-15", "--out", "s", "--quiet"])) == 0  # a target nothing meets
    assert not Path("s/chosen.json").exists()
    assert capsys.readouterr().out.rstrip().endswith("; removed s/chosen.json, an earlier run's choice, which this "
                                                     "report does not make")


def test_files_of_a_reports_names_that_no_study_wrote_are_refused_before_the_runs(tmp_path, monkeypatch):
    """A directory of the user's with a chosen.json and a plot of those names: the study removed the first ('an
    earlier run's choice') and the second silently. Without an earlier study's report.md there they are the
    user's: refused in one line before any run, and left."""
    import sim.study.cli as study_cli

    monkeypatch.chdir(tmp_path)
    Path("u").mkdir()
    Path("u/chosen.json").write_text("my formats\n")
    Path("u/study-knobs.png").write_bytes(b"my plot")
    monkeypatch.setattr(study_cli, "run_study", lambda *a, **k: pytest.fail("the study ran"))
    with pytest.raises(OutputError, match=r"^--out 'u' holds chosen.json, study-knobs.png, which this run would "
                                          r"replace and no earlier run of this command wrote there"):
        cmd_study(_parse(["dome", "--sweep", "none", "--no-optimise", "--workers", "1", "--out", "u", "--quiet"]))
    assert Path("u/chosen.json").read_text() == "my formats\n" and sorted(os.listdir("u")) == ["chosen.json",
                                                                                              "study-knobs.png"]


def test_a_study_that_sweeps_nothing_draws_no_sweep_plots_and_removes_an_earlier_runs(tmp_path, monkeypatch):
    """--sweep none: the sweep plots would be empty axes (the report links none); an earlier run's would pass for
    this one's."""
    monkeypatch.chdir(tmp_path)
    Path("s").mkdir()
    Path("s/report.md").write_text(f"{REPORT_TITLE}\n\nan earlier study's report\n")
    for name in ("study-bits.png", "study-knobs.png"):
        Path("s", name).write_bytes(b"an earlier run's plot")
    assert cmd_study(_parse(["dome", "--sweep", "none", "--no-optimise", "--workers", "1", "--max-iter", "5",
                             "--out", "s", "--quiet"])) == 0
    assert sorted(os.listdir("s")) == sorted(set(REPORT_FILES) - {"study-bits.png", "study-knobs.png"})
    report = Path("s/report.md").read_text()
    assert "](study-pareto.png)" in report and "](study-bits.png)" not in report


def test_a_mesh_path_that_cannot_be_read_says_why_not_unknown_mesh(tmp_path, monkeypatch):
    from golden_model.mesh import MeshError

    monkeypatch.chdir(tmp_path)
    os.mkfifo("pipe")
    for name, message in [("./pipe", "cannot read mesh 'pipe': is a named pipe (FIFO), not a regular file"),
                          ("pipe", "cannot read mesh 'pipe': is a named pipe"),
                          ("no/such.obj", "cannot read mesh 'no/such.obj': no such file")]:
        with pytest.raises(MeshError, match=re.escape(message)):
            cmd_study(_parse([name, "--sweep", "none", "--no-optimise", "--out", "out", "--quiet"]))
    assert sorted(os.listdir()) == ["pipe"]


@pytest.mark.slow
def test_cmd_study_writes_outputs(tmp_path, capsys):
    out = tmp_path / "study"
    args = _parse(["surf1", "--init", "pca", "--step", "variable", "--sweep", "position,lut_interpolate",
                   "--bits", "10:18:4", "--max-iter", "40", "--workers", "1", "--out", str(out), "--quiet"])
    assert cmd_study(args) == 0
    assert "chosen" in capsys.readouterr().out
    assert set(os.listdir(out)) == set(REPORT_FILES)  # what is checked before the study is what it writes
    with open(out / "summary.csv", newline="") as f:
        summary = list(csv.DictReader(f))
    with open(out / "results.csv", newline="") as f:
        results = list(csv.DictReader(f))
    assert len(results) == len(summary)  # one case: one row per configuration
    assert {"config", "case", "d_area_error", "d_shape_error", "max_position_error", "rms_position_error",
            "d_iterations", "status_match", "saturations", "error"} <= set(results[0])
    labels = {r["config"] for r in summary}
    assert {"base:default", "position=10", "position=14", "position=18", "lut_interpolate=False"} <= labels
    assert any(r["kind"] == "optimiser" for r in summary)
    chosen = FormatSet.load(str(out / "chosen.json"))
    chosen_rows = [r for r in summary if r["meets_target"] == "1"]
    best = min(chosen_rows, key=lambda r: (int(r["total_bits"]), int(r["dsp"]), int(r["rom_bits"])))
    assert cost(chosen).total_bits == int(best["total_bits"])
    report = (out / "report.md").read_text()
    assert "```json" in report and json.loads(report.split("```json")[1].split("```")[0]) == chosen.to_dict()
    for png in ("study-bits.png", "study-knobs.png", "study-pareto.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert f"]({png})" in report


def test_an_e_of_1_or_more_held_just_below_1_is_no_deviation_and_a_refused_run_has_no_iterations():
    """Surf1 from Tutte cut at 60 iterations: float E_S 1.4434, the fixed run's E_S held at 0.99999 by u0.20 while
    the layouts agree to 1.3e-4 mean edges. The step clamps E to 1 (eqs. 18-20), so the record compares E as the
    step sees it; a refused run's iteration cells are empty, not a match of 0."""
    from golden_model.study.records import RunRecord

    ended = RunRecord("c", "surf1/tutte/variable", "surf1", "tutte", "variable", "max-iterations", "max-iterations", 60,
                      60, 1.4434, 1 - 2**-20, 0.62, 0.6201, 1.3e-4, 5e-5, 11, "area_error:11", measure_clamps=11)
    assert ended.d_area == 2**-20 and ended.d_shape == pytest.approx(1e-4)
    assert not AccuracyTarget(1e-3).failures(ended)
    apart = dataclasses.replace(ended, area_error_fixed=0.5)  # a fixed E below 1 against a float one above
    assert apart.d_area == 0.5 and AccuracyTarget(1e-3).failures(apart) == ["|dE| 0.5 > 0.001"]
    refused = RunRecord("c", "d/pca/fixed", "delaunay", "pca", "fixed", "converged", "refused", 40, 0, 0.01,
                        math.nan, 0.02, math.nan, math.nan, math.nan, 0, "", error="the shortest edge is 0.05")
    row = refused.row(AccuracyTarget())
    assert (row["iterations_float"], row["iterations_fixed"], row["d_iterations"], row["meets_target"]) == (40, None,
                                                                                                           None, 0)


def test_a_configuration_whose_runs_were_all_refused_has_no_counts_and_its_reason_keeps_its_cell():
    """summary.csv had 0 for a refused configuration's iterations, status mismatches and saturations (read: all
    matched); report.md's cells split at the reason's '|dE|' pipes, so the reason and its numbers were lost."""
    from golden_model.study.records import RunRecord
    from sim.study.cli import _summary_row
    from golden_model.study.knobs import Config
    from sim.study.flow import summarise

    refused = RunRecord("c", "d/pca/fixed", "delaunay", "pca", "fixed", "converged", "refused", 40, 0, 0.01,
                        math.nan, 0.02, math.nan, math.nan, math.nan, 0, "", error="the shortest edge is 0.05")
    ran = RunRecord("c", "s/pca/fixed", "surf1", "pca", "fixed", "converged", "converged", 40, 43, 0.01, 0.0101,
                    0.02, 0.02, 1e-4, 5e-5, 0, "")
    config = Config("c", FormatSet.preset("default"), kind="base")
    nothing_ran = summarise(config, [refused], AccuracyTarget(1e-7))
    row = nothing_ran.row()
    assert (row["max_abs_d_iterations"], row["status_mismatches"], row["saturations"]) == ("", "", "")
    some_ran = summarise(config, [refused, ran], AccuracyTarget(1e-7))
    assert (some_ran.max_abs_d_iterations, some_ran.status_mismatches, some_ran.saturations) == (3, 0, 0)
    cells = _summary_row(summarise(config, [ran], AccuracyTarget(1e-7))).split(" | ")
    assert len(cells) == 12 and cells[-1] == "s/pca/fixed: iterations 43 vs 40; \\|dE\\| 0.0001 > 1e-07 |"


def test_the_choice_says_how_it_was_made_and_whether_the_rtl_can_build_it(tmp_path, monkeypatch, capsys):
    """--no-optimise: chosen.json must not claim the optimiser; a pick without the rsqrt unit's Newton step runs in
    the golden model but the RTL refuses it, which chosen.json, the report and stderr say."""
    monkeypatch.chdir(tmp_path)
    FormatSet.preset("narrow").replace(name="no-newton", rsqrt_newton_steps=0).save("no-newton.json")
    assert cmd_study(_parse(["dome", "--sweep", "none", "--no-optimise", "--jobs", "1", "--max-iter", "5",
                             "--base", "no-newton.json", "--out", "s", "--quiet"])) == 0
    out, err = capsys.readouterr()
    assert out.startswith("chosen base:no-newton: ")
    notes = json.loads(Path("s/chosen.json").read_text())["notes"]["_"]
    assert "(cost metric bits, among the base, the presets and the sweeps: the optimiser did not run)" in notes
    assert "greedy" not in notes and "on 4 cases: dome;" in notes
    refusal = "the fold barrier needs"
    assert f"The RTL cannot be built with it (the golden model runs it): {refusal}" in notes
    assert f"**The RTL cannot be built with it** (`verilog`, `rtl-check` and `synth` refuse it" in Path(
        "s/report.md").read_text()
    assert err.startswith("springflat: note: the RTL cannot be built with s/chosen.json (the golden model runs it): "
                          f"{refusal}")


def test_a_study_of_under_a_second_does_not_say_0_s():
    from sim.study.cli import _seconds

    assert [_seconds(t) for t in (0.43, 9.94, 9.96, 12.6, 135.2)] == ["0.4 s", "9.9 s", "10 s", "13 s", "135 s"]


def test_a_study_that_sweeps_only_other_knobs_draws_no_bits_plot_and_no_empty_table(tmp_path, monkeypatch):
    """--sweep rounding: no signal class's bits were swept, so their plot would be the target line alone and
    their table a header; the knobs' plot is drawn and linked."""
    monkeypatch.chdir(tmp_path)
    assert cmd_study(_parse(["dome", "--sweep", "rounding", "--no-optimise", "--workers", "1", "--max-iter", "5",
                             "--out", "s", "--quiet"])) == 0
    assert sorted(os.listdir("s")) == sorted(set(REPORT_FILES) - {"study-bits.png"})
    report = Path("s/report.md").read_text()
    assert "](study-knobs.png)" in report and "](study-bits.png)" not in report
    assert "fewest swept bits meeting the target" not in report


def test_a_choice_the_default_dynamics_refuses_says_so(tmp_path, monkeypatch, capsys):
    """The study runs the paper dynamics; its pick with velocity s3.12 was refused by a plain flatten of a mesh
    file (the momentum dynamics adds V to P), which nothing said. A preset gets no such note."""
    monkeypatch.chdir(tmp_path)
    FormatSet.preset("narrow").replace(name="v8", velocity="s3.8").save("v8.json")  # cheaper than every preset
    assert cmd_study(_parse(["dome", "--sweep", "none", "--no-optimise", "--jobs", "1", "--max-iter", "5",
                             "--target", "1", "--base", "v8.json", "--out", "s", "--quiet"])) == 0
    out, err = capsys.readouterr()
    assert out.startswith("chosen base:v8: ")
    assert ("springflat: note: s/chosen.json runs the paper dynamics it was studied on; a mesh file's default, the "
            "momentum dynamics, refuses it (the momentum dynamics adds V to P directly: format set 'v8' needs "
            "velocity (s3.8) and position (s10.14) with the same fraction bits): flatten with it and --dynamics "
            "paper") in err
    assert cmd_study(_parse(["dome", "--sweep", "none", "--no-optimise", "--jobs", "1", "--max-iter", "5",
                             "--out", "d", "--quiet"])) == 0
    out, err = capsys.readouterr()
    assert out.startswith("chosen preset:narrow: ") and "momentum dynamics" not in err


def test_a_sweep_of_a_class_no_case_reads_is_never_chosen(tmp_path, monkeypatch, capsys):
    """Without the optimiser the cheapest sweep row was chosen: power=4 on a paper run, which reads no power, so
    its 'saving' went into chosen.json while the report said no case reads the class."""
    monkeypatch.chdir(tmp_path)
    assert cmd_study(_parse(["surf2", "--init", "pca", "--step", "fixed", "--workers", "1", "--no-optimise",
                             "--sweep", "power", "--bits", "4:16:4", "--out", "s", "--quiet"])) == 0
    said = capsys.readouterr().out
    assert "chosen power=" not in said and "power" not in json.loads(Path("s/chosen.json").read_text())["name"], said
