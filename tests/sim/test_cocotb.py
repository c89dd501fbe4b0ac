"""cocotb on the exported Verilog, on Icarus and Verilator (cocotb_tools.runner driven from pytest)."""


import pytest

from golden_model.builtin import builtin_mesh
from golden_model.fixed import FormatSet
from hdl import SpringflatCore
from sim.cocotb_support import run_bench, verilog_sources
from golden_model.engine_spec.image import UNGUARDED
from support import need_simulator

pytestmark = pytest.mark.slow  # simulator builds and place-and-route: minutes

DEFAULT = FormatSet.preset("default")


@pytest.mark.parametrize("unit", ["rsqrt_unit", "step_generator"])
def test_units(simulator, unit):
    run = run_bench(simulator, DEFAULT, unit, "units", {"n": 1200, "seed": 1}, testcase=unit)
    assert (run.tests, run.failed) == (1, 0), run.result
    assert run.result["mismatches"] == 0 and run.result["inputs"] > 1000


def test_node_update_over_iterations_with_stalls_and_reset(simulator):
    config = {"mesh": "surf2", "init": "tutte", "params": {"density": 2.0, "damping": 0.02}, "iterations": 4,
              "p_valid": 0.75, "p_ready": 0.7, "seed": 2}
    run = run_bench(simulator, DEFAULT, "node_update", "node_update", config)
    assert (run.tests, run.failed) == (1, 0), run.result.get("first_mismatches")
    assert run.result["mismatches"] == 0


@pytest.mark.parametrize("toplevel, bench, testcase", [("rsqrt_unit", "units", "rsqrt_unit"),
                                                     ("step_generator", "units", "step_generator"),
                                                     ("node_update", "node_update", None)])
def test_ecp5_flavour_with_mult18x18d_instances(toplevel, bench, testcase):
    """The Verilog `springflat synth --target ecp5` synthesises (MULT18X18D instances with their
    own registers, the seed and exp ROMs DP16KDs with their output registers) against the golden model, on
    Icarus with models of the primitives (which Icarus runs some ten times slower than the generic Verilog:
    400 inputs to a unit, where ``test_units`` takes 1,200)."""
    need_simulator("icarus")
    config = ({"n": 400, "seed": 3} if bench == "units" else
              {"mesh": "surf1", "init": "pca", "params": {"density": 2.0, "damping": 0.02}, "iterations": 2,
               "p_valid": 0.8, "p_ready": 0.7, "seed": 4})
    run = run_bench("icarus", DEFAULT, toplevel, bench, config, testcase=testcase, dsp="ecp5")
    assert (run.tests, run.failed) == (1, 0), run.result.get("first_mismatches", run.result)
    assert run.result["mismatches"] == 0
    source = (verilog_sources(DEFAULT, "ecp5") / f"{toplevel}.v").read_text()
    assert "MULT18X18D" in source
    # the rsqrt unit's seed ROM and the step generator's exp ROMs, with their output registers
    assert "DP16KD" in source and '"OUTREG"' in source


def _paper_params(name, step):
    _, p = builtin_mesh(name)
    return dict(spring=p.spring, density=p.density, tol_area=p.tol_area, tol_shape=p.tol_shape,
                tol_energy=p.tol_energy, max_iter=p.max_iter, step=step)


@pytest.mark.parametrize("simulator, mesh", [("verilator", "surf1"), ("verilator", "surf2"), ("icarus", "surf1")])
def test_closed_loop_on_paper_meshes(simulator, mesh):
    """A whole flattening through the RTL, to the end, with the paper's parameters (Icarus, some ten times
    slower, on Surf1 alone)."""
    need_simulator(simulator)
    config = {"mesh": mesh, "init": "pca", "params": _paper_params(mesh, "variable"),
              "step_latency": SpringflatCore.step_latency_of(DEFAULT)}
    run = run_bench(simulator, DEFAULT, "springflat_core", "closed_loop", config)
    r = run.result
    assert (run.tests, run.failed) == (1, 0), r.get("first_mismatches")
    assert r["mismatches"] == 0
    # against the float reference, within the fixed-point engine's tolerances
    assert r["status"] == r["float_status"]
    assert abs(r["iterations"] - r["float_iterations"]) <= 1
    assert abs(r["area_error"] - r["float_area_error"]) <= 1e-3
    assert abs(r["shape_error"] - r["float_shape_error"]) <= 1e-3


def _first_restart(mesh, params: dict) -> int:
    """The iteration of the golden model's first momentum restart from Tutte (its ``S < 0`` the one before)."""
    from golden_model.fixed.engine import FixedEngine, prepare
    from golden_model.fixed.format import SaturationCounter
    from sim.layouts import initial_layout
    from golden_model.params import FlattenParams

    engine = FixedEngine(prepare(mesh, initial_layout(mesh, "tutte"), FlattenParams(**params), DEFAULT),
                         SaturationCounter())
    restarts = []

    def note_restart(k: int) -> None:
        if engine.momentum.restart:  # S < 0 in iteration k: iteration k + 1 restarts
            restarts.append(k + 1)

    engine.run(on_iteration=note_restart)
    return min(restarts, default=params["max_iter"] + 1)


@pytest.mark.parametrize("simulator, barrier", [("verilator", True), ("verilator", False), ("icarus", True)])
def test_closed_loop_momentum_dynamics(simulator, barrier, tmp_path):
    """The momentum dynamics through the RTL: β_k from the controller, restarts from the RTL's F·V,
    the barrier's forces in the stream; every iteration bit for bit, the end against the float model
    (Icarus, some ten times slower, with the barrier alone on a two-ring cap, 19 vertices, and 8 iterations:
    the fixed-point run's one restart is its seventh iteration, ``S < 0`` in its sixth; the four-ring cap's
    first restart is its sixteenth)."""
    need_simulator(simulator)
    from sim.generate import spherical_cap
    from sim.mesh_io import save_obj

    cap = spherical_cap(4 if simulator == "verilator" else 2)
    path = tmp_path / "cap.obj"
    save_obj(path, cap.vertices, cap.faces)
    config = {"mesh": str(path), "init": "tutte",
              "params": {"dynamics": "momentum", **UNGUARDED, "barrier": barrier, "tol_area": 1.0, "tol_shape": 1.0,
                         "tol_energy": 0.0, "max_iter": 25 if simulator == "verilator" else 8},
              "p_valid": 0.9, "p_ready": 0.8, "seed": 5, "step_latency": SpringflatCore.step_latency_of(DEFAULT)}
    assert _first_restart(cap, config["params"]) < config["params"]["max_iter"]  # it restarts, then runs on
    run = run_bench(simulator, DEFAULT, "springflat_core", "closed_loop", config)
    r = run.result
    assert (run.tests, run.failed) == (1, 0), r.get("first_mismatches")
    assert r["mismatches"] == 0 and r["iterations"] == config["params"]["max_iter"] and r["dynamics"] == "momentum"
    assert r["status"] == r["float_status"] and r["iterations"] == r["float_iterations"]
    assert abs(r["area_error"] - r["float_area_error"]) <= 1e-3
    assert abs(r["shape_error"] - r["float_shape_error"]) <= 1e-3


def test_closed_loop_fixed_step_with_stalls(simulator):
    config = {"mesh": "surf1", "init": "tutte", "params": {**_paper_params("surf1", "fixed"), "damping": 0.05},
              "iterations": 12, "p_valid": 0.7, "p_ready": 0.6, "seed": 3,
              "step_latency": SpringflatCore.step_latency_of(DEFAULT)}
    run = run_bench(simulator, DEFAULT, "springflat_core", "closed_loop", config)
    assert (run.tests, run.failed) == (1, 0), run.result.get("first_mismatches")
    assert run.result["mismatches"] == 0 and run.result["iterations"] == 12


@pytest.mark.parametrize("bench, toplevel, config", [
    ("units", "rsqrt_unit", {"n": 200}),
    ("node_update", "node_update", {"mesh": "surf1", "init": "pca", "params": {"density": 2.0}, "iterations": 3}),
    ("closed_loop", "springflat_core", {"mesh": "surf1", "init": "pca", "iterations": 3}),
])
def test_a_broken_expectation_fails(simulator, bench, toplevel, config):
    """The benches can fail: one deliberately wrong golden value is reported, naming where."""
    config = {**config, "broken_expectation": True, "step_latency": SpringflatCore.step_latency_of(DEFAULT)}
    if bench == "closed_loop":
        config["params"] = _paper_params("surf1", "variable")
    run = run_bench(simulator, DEFAULT, toplevel, bench, config, testcase=toplevel if bench == "units" else None)
    assert run.failed == 1
    assert run.result["mismatches"] >= 1
    # pytest rewrote the bench's asserts (a failure shows its values), and no module the bench imports
    assert f"sim.cocotb_benches.{bench}" in run.result["rewritten_modules"]
    assert all(name.split(".")[:2] == ["sim", "cocotb_benches"] for name in run.result["rewritten_modules"])
    if bench != "units":
        assert "iteration" in run.result["first_mismatches"][0]


PAPER_CLI = ("--dynamics", "paper", "--init", "pca", "--damping", "0.05")
MOMENTUM_CLI = ("--no-guard", "--energy-window", "1")


@pytest.mark.parametrize("simulator, dynamics", [("verilator", PAPER_CLI), ("verilator", MOMENTUM_CLI),
                                                 ("icarus", MOMENTUM_CLI)],
                         ids=["verilator-paper", "verilator-momentum", "icarus-momentum"])
def test_rtl_check_cli_on_an_unseen_mesh(simulator, tmp_path, dynamics):
    """springflat rtl-check on a mesh file it has never seen, with the paper's dynamics and with the
    file defaults' unguarded momentum mode (the engine's: fold barrier, start from --init auto): a few
    iterations, zero mismatches. (Icarus, some ten times slower, with the momentum mode alone on a patch of
    100 vertices: the same command and bench; the paper's dynamics runs on it in the closed-loop tests above.)"""
    need_simulator(simulator)
    import json
    import subprocess
    import sys
    from pathlib import Path

    from sim.generate import delaunay_patch
    from sim.mesh_io import save_obj

    nodes = 100 if simulator == "icarus" else 220
    mesh = delaunay_patch(nodes, seed=11)
    save_obj(tmp_path / "patch.obj", mesh.vertices, mesh.faces)
    springflat = str(Path(sys.executable).parent / "springflat")
    proc = subprocess.run([springflat, "rtl-check", "patch.obj", "--sim", simulator, "--iterations", "3",
                           "--tol-area", "0", *dynamics, "--stall", "0.1", "--json"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout)
    for key in ("mismatches", "iterations", "simulator", "area_error", "shape_error", "float_area_error",
                "float_shape_error", "cycles", "cycles_per_second"):
        assert key in result
    assert (result["mismatches"], result["iterations"], result["simulator"]) == (0, 3, simulator)
    assert result["nodes"] == nodes and result["cycles"] > 2 * 3 * result["entries"]
    assert result["dynamics"] == ("paper" if "paper" in dynamics else "momentum")
    assert abs(result["area_error"] - result["float_area_error"]) <= 1e-3


@pytest.mark.parametrize("holes", ["--keep-holes", "--fill-holes"])
def test_rtl_check_datapath_bench_reads_a_holed_mesh_as_the_command_does(tmp_path, holes):
    """The datapath bench reads the mesh file itself: with the command's --keep-holes or --fill-holes, not refused
    as a mesh with holes (the bench ended without a result); kept, the bench runs the piece's own nodes."""
    need_simulator("icarus")
    import json
    import subprocess
    import sys
    from pathlib import Path

    from sim.generate import holed_dome
    from sim.mesh_io import save_obj

    mesh = holed_dome(7, holes=((2, 2, 2),))
    save_obj(tmp_path / "holed.obj", mesh.vertices, mesh.faces)
    springflat = str(Path(sys.executable).parent / "springflat")
    proc = subprocess.run([springflat, "rtl-check", "holed.obj", holes, "--sim", "icarus", "--iterations", "2",
                           *MOMENTUM_CLI, "--json"], capture_output=True, text=True, cwd=tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(proc.stdout)
    assert (result["mismatches"], result["iterations"]) == (0, 2)
    run_mesh = mesh if holes == "--keep-holes" else mesh.disk  # the fill: triangles across the hole, no new vertex
    assert (result["nodes"], result["entries"]) == (run_mesh.n_vertices, 2 * len(run_mesh.edges))


def test_step_generator_whole_lanes_on_verilator():
    """Every E_S with E_C fixed and every E_C with E_S fixed (2 x 2^20 for the default preset), one a clock
    through the exported Verilog on Verilator (``sim/stream_sweep.py``), against the golden model's
    ``step_size``; with the reachable-sum sweep of ``tests/hdl/test_hdl_stepgen.py``, every input pair."""
    import numpy as np

    from golden_model.fixed import step_size
    from hdl import StepGenerator
    from sim.payloads import pack_beats, unpack_beats
    from sim.stream_sweep import sweep_on_verilator

    need_simulator("verilator")
    top = DEFAULT.error.raw_max
    lane = np.arange(top + 1, dtype=np.int64)
    area = np.concatenate([lane, np.full(len(lane), top // 3)])
    shape = np.concatenate([np.full(len(lane), top // 2), lane])
    beats = pack_beats(StepGenerator.input_layout(DEFAULT), {"area_error": area, "shape_error": shape})
    got = unpack_beats(StepGenerator.output_layout(DEFAULT), sweep_on_verilator("step_generator", DEFAULT, beats))
    want_dt, want_half = step_size(area, shape, DEFAULT)
    assert len(got["dt"]) == len(area) == 2 * (top + 1)
    for name, want in (("dt", want_dt), ("half_dt_sq", want_half)):
        bad = np.flatnonzero(got[name] != want)
        assert not bad.size, (f"{name}: {bad.size} mismatches; first area_error {area[bad[0]]} shape_error "
                              f"{shape[bad[0]]}: rtl {got[name][bad[0]]} golden {want[bad[0]]}")


def test_rsqrt_narrow_stride_sweep_on_verilator():
    """The narrow preset's rsqrt unit (u7.16 in: 2^23 inputs) at 2^20 evenly spaced inputs, 0 and raw_max
    among them, one a clock through the exported Verilog on Verilator (``sim/stream_sweep.py``): each
    result and saturation flag against the golden model. (Boundaries, random inputs and stalls:
    ``tests/hdl/test_hdl_rsqrt.py``.)"""
    import numpy as np

    from golden_model.fixed import SaturationCounter, rsqrt_stages, rsqrt_with_config
    from hdl import RsqrtUnit
    from sim.payloads import unpack_beats
    from sim.stream_sweep import sweep_on_verilator

    need_simulator("verilator")
    narrow = FormatSet.preset("narrow")
    cfg = narrow.rsqrt_config()
    x = np.linspace(0, cfg.fmt_in.raw_max, 1 << 20, dtype=np.int64)
    assert len(np.unique(x)) == len(x) and (x[0], x[-1]) == (0, cfg.fmt_in.raw_max)
    got = unpack_beats(RsqrtUnit.output_layout(cfg), sweep_on_verilator("rsqrt_unit", narrow, x))
    counter = SaturationCounter()
    want = rsqrt_with_config(x, cfg, counter)
    bad = np.flatnonzero(got["rsqrt"] != want)
    assert not bad.size, f"{bad.size} mismatches; first x={x[bad[0]]}: rtl {got['rsqrt'][bad[0]]} golden {want[bad[0]]}"
    saturated = got["saturated"].astype(bool)
    np.testing.assert_array_equal(saturated, rsqrt_stages(x, cfg)["saturate"])
    assert int(saturated.sum()) == counter["rsqrt"] > 0
