"""The board simulated whole on Verilator (sim/board_sim.py, sim/cocotb_benches/board.py): BoardCore (UART
bridge, engine, LEDs) with the host driver speaking frames over the serial line: the self-test read, the bad
frames (error answers, no bus access), and a Surf1 flattening whose layout file is byte for byte
``flatten --engine fixed``'s."""

import subprocess

import pytest

from golden_model.engine_spec import uart_protocol as protocol
from golden_model.fixed.engine import prepare
from golden_model.engine_spec.image import EngineCapacity
from golden_model.engine_spec.register_map import MAGIC, VERSION
from sim.layouts import initial_layout
from sim.board_sim import run_board_sim
from sim.cli import build_parser
from sim.engine_run import engine_flatten_result
from sim.patterns import PatternDrawing, run_caption, write_pattern_file
from sim.run_options import default_init, load_format_set, params_from_args, resolve_mesh
from support import SPRINGFLAT, BenchCalled, need_simulator, record_bench_configs

pytestmark = pytest.mark.slow  # a Verilator build of the engine (cached)

CAPACITY = EngineCapacity(64, 512, 128)


def cli_problem(argv):
    """The FixedProblem ``springflat flatten ARGV --engine fixed`` runs, built as the CLI builds it."""
    args = build_parser().parse_args(["flatten", *argv, "--engine", "fixed"])
    mesh, defaults = resolve_mesh(args.mesh)
    params = params_from_args(args, defaults)
    positions = initial_layout(mesh, args.init or default_init(args.mesh))
    return mesh, prepare(mesh, positions, params, load_format_set(args.formats or "default"))


def test_surf1_over_the_simulated_uart_is_byte_identical_to_engine_fixed(tmp_path):
    need_simulator("verilator")
    mesh, problem = cli_problem(["surf1"])
    run = run_board_sim(problem, CAPACITY, work=tmp_path / "sim", log_file=tmp_path / "sim.log")
    r = run.result
    assert run.passed, r.get("mismatches", r)
    assert r["self_test"] == {"id": MAGIC, "version_major": VERSION[0]}
    want = {"wrong checksum": protocol.BAD_CHECKSUM, "overlong length": protocol.BAD_LENGTH,
            "truncated frame": protocol.TIMEOUT, "bad command": protocol.BAD_COMMAND}
    assert {name: (f["status"], f["bus_accesses"]) for name, f in r["bad_frames"].items()} == {
        name: (status, 0) for name, status in want.items()}
    result = engine_flatten_result(problem, run.positions, run.velocities, r["status"], r["iterations"], "board",
                                   {"saturations": r["saturations"]})
    final = result.final  # the file as --out writes it: the layout turned as seen, as vt, the run's line in its header
    caption = run_caption(result.status, result.iterations, final.area_error, final.shape_error, final.folded)
    write_pattern_file(tmp_path / "board.obj", PatternDrawing.of(mesh, result.positions, caption=caption).as_seen())
    proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", "fixed", "--out", "fixed.obj", "--json"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "board.obj").read_bytes() == (tmp_path / "fixed.obj").read_bytes()
    assert r["status"] == "converged" and r["iterations"] > 10 and r["cycles"] > r["iterations"] * 100


def test_the_board_bench_is_told_the_capacity_it_runs_on(monkeypatch, tmp_path):
    """run_board_sim hands the bench the whole capacity, the step guard included (the driver checks
    FEATURES.guard against the register map it builds from it)."""
    import dataclasses

    import sim.board_sim as board_sim

    seen = record_bench_configs(monkeypatch, board_sim, "board_sources", tmp_path)
    _, problem = cli_problem(["surf1"])
    guardless = dataclasses.replace(CAPACITY, guard=False)
    for capacity in (CAPACITY, guardless):
        with pytest.raises(BenchCalled):
            run_board_sim(problem, capacity, work=tmp_path / str(capacity.guard))
    assert [EngineCapacity(*config["capacity"]) for config in seen] == [CAPACITY, guardless]
