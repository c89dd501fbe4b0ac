"""Whole flattenings through the exported ``springflat_engine`` on Icarus and Verilator (cocotb), driven by
the host driver over Wishbone, bit-exact with ``run_image``; the refusals; ``rtl-check --engine-top`` and
``flatten --engine rtl``.

Icarus simulates this design at about a thousand clocks per second, so its cases are a 16-vertex dome and
a few iterations; Verilator takes the three dynamics modes. Every case shares one capacity (one build
per simulator).
"""

import dataclasses
import json
import os
import re
import subprocess

import numpy as np
import pytest

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import prepare
from golden_model.engine_spec.image import EngineCapacity, build_image, run_image
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from sim.engine_run import engine_directory, engine_sources, run_image_on_rtl, simulation_harness, top_ports
from sim.top_names import ENGINE_MODULE
from golden_model.engine_spec.image import UNGUARDED
from support import SPRINGFLAT, BenchCalled, need_simulator, record_bench_configs

pytestmark = pytest.mark.slow  # simulator builds (Verilator: minutes, cached)

DEFAULT = FormatSet.preset("default")
CAPACITY = EngineCapacity(64, 512, 128)

MODES = {
    "paper-variable": dict(density="auto", tol_area=0.0, tol_shape=0.0),
    "paper-fixed-barrier": dict(density="auto", step="fixed", dt=0.02, damping=0.05, barrier=True,
                                tol_area=0.0, tol_shape=0.0),
    "momentum": dict(density="auto", dynamics="momentum", **UNGUARDED, barrier=True, tol_area=0.0, tol_shape=0.0),
    # the step guard from a layout squeezed across: node steps clipped and held still by the certificate,
    # a step rolled back, saturating forces
    "momentum-guarded": dict(density="auto", dynamics="momentum", barrier=False, tol_area=0.0, tol_shape=0.0),
}
SQUEEZE = {"momentum-guarded": 0.01}


def dome_image(mode: str, max_iter: int):
    mesh = dome_grid(4)
    params = FlattenParams(**MODES[mode], max_iter=max_iter)
    layout = initial_layout(mesh, "tutte") * np.array([SQUEEZE.get(mode, 1.0), 1.0])
    return build_image(prepare(mesh, layout, params, DEFAULT), CAPACITY)


@pytest.mark.parametrize("simulator, mode", [("verilator", m) for m in MODES])
def test_whole_run_bit_exact(simulator, mode):
    """Every iteration's state (runs with N_max = 1, 2, read back) and a whole run: positions, velocities,
    status, iterations, E_S, E_C, energy and saturations equal run_image's; random bus wait states. (Icarus
    runs the engine whole in the reset test and in the ECP5 flavour below.)"""
    need_simulator(simulator)
    max_iter, per_iteration = 6, 2
    image = dome_image(mode, max_iter)
    if mode == "momentum-guarded" and simulator == "verilator":  # the run has each of the guard's events
        want = run_image(image, DEFAULT)
        assert want.guard.clipped > 0 and want.guard.frozen > 0 and want.guard.rejected > 0, want.guard
        assert want.saturations > 0
    run = run_image_on_rtl(image, DEFAULT, simulator, wait_states=3, seed=7,
                           checks={"iteration_checks": per_iteration})
    r = run.result
    assert run.passed, r.get("first_mismatches", r)
    want = run_image(image, DEFAULT)
    # the bench's own comparison aside: the read-back itself, against the golden model here
    assert np.array_equal(run.positions, want.positions) and np.array_equal(run.velocities, want.velocities)
    assert (r["status"], r["iterations"], r["area_error"], r["shape_error"], r["energy"]) == (
        want.status, want.iterations, want.area_error, want.shape_error, want.energy)
    assert r["iterations"] == max_iter  # tolerances 0: the run goes to N_max
    assert r["cycles"] > max_iter * (image.constants["entries"] + image.constants["triangles"])
    assert 0 <= r["python_share"] < 1 and r["cycles_per_second"] > 0


def test_ecp5_flavour_whole_run_bit_exact():
    """What ``springflat synth --target ecp5`` synthesises (every memory a row of DP16KDs read through their
    output registers, the multipliers MULT18X18Ds, the step generator's tables DP16KD ROMs), on Icarus with
    the primitives' models: a two-iteration run's state equals run_image's. The DP16KD model reads X where
    a port reads bits the other writes at the same clock, so this also checks that no read whose data is
    used meets a write (BlockRam's timing contract). (Icarus runs these models slowly, most of the clocks
    the bus's loading and reading back: so one run, no run per iteration, and the guarded momentum run
    alone: it reads and writes every memory and multiplier the unguarded one does, and the guard's.)"""
    need_simulator("icarus")
    image = dome_image("momentum-guarded", 2)
    run = run_image_on_rtl(image, DEFAULT, "icarus", wait_states=2, seed=11, dsp="ecp5")
    r = run.result
    assert run.passed, r.get("first_mismatches", r)
    want = run_image(image, DEFAULT)
    assert np.array_equal(run.positions, want.positions) and np.array_equal(run.velocities, want.velocities)
    assert (r["status"], r["iterations"], r["energy"]) == (want.status, want.iterations, want.energy)
    source = (engine_sources(DEFAULT, CAPACITY, "icarus", "ecp5") / f"{ENGINE_MODULE}.v").read_text()
    assert '.REGMODE_B("OUTREG")' in source and "MULT18X18D" in source and "no_rw_check" not in source


@pytest.mark.parametrize("simulator", ["verilator", "icarus"])
def test_reset_mid_run_and_refusals(simulator):
    """START with nothing loaded (the driver refuses; the hardware answers no-mesh), an unmapped read and a
    memory read while running (bus error), rst in the middle of a run (the engine idles, the run
    constants cleared), then a clean rerun that matches run_image bit for bit."""
    need_simulator(simulator)
    image = dome_image("paper-variable", 2)
    checks = {"no_mesh_check": True, "unmapped_check": True, "busy_check": True, "reset_after": 150}
    run = run_image_on_rtl(image, DEFAULT, simulator, wait_states=1, seed=3, checks=checks)
    r = run.result
    assert run.passed, r.get("first_mismatches", r)
    c = r["checks"]
    assert c["driver_start_without_mesh"] == "no mesh loaded: call load(image) before start()"
    assert c["hardware_start_without_mesh"] == "no-mesh"
    assert c["unmapped_read"].startswith("bus error: read at word") and c["unmapped_read"].endswith("answered err")
    assert c["memory_read_while_running"].startswith("bus error: read at word 0x")
    assert (c["running_before_reset"], c["state_after_reset"], c["vertices_after_reset"]) == ("running", "idle", 0)
    assert r["iterations"] == 2 and r["status"] == "max-iterations"


def test_a_broken_expectation_fails():
    """The bench can fail: one wrong golden bit is reported as a mismatch naming the node and field."""
    need_simulator("verilator")
    run = run_image_on_rtl(dome_image("paper-variable", 2), DEFAULT, "verilator",
                           checks={"broken_expectation": True})
    assert not run.passed and run.mismatches == 1
    assert run.result["first_mismatches"][0].startswith("whole run: node 8 position.y: rtl ")


def test_each_design_has_its_own_export_directory():
    """A build without the step guard is another Verilog at the same depths, and so is the ECP5 flavour:
    neither may reuse (or overwrite) the guarded export of a cached build."""
    guardless = dataclasses.replace(CAPACITY, guard=False)
    directories = {engine_directory(DEFAULT, CAPACITY), engine_directory(DEFAULT, guardless),
                   engine_directory(DEFAULT, CAPACITY, "ecp5"), engine_directory(DEFAULT, guardless, "ecp5")}
    assert len(directories) == 4


#: A Yosys ``always @*`` block that only assigns a constant: it has no input, so an event-driven
#: simulator (Icarus) never runs it and the bits stay X.
CONSTANT_BLOCK = re.compile(r"always @\*\n(\s+)([^\n;]*?) = (\d+'[hbd][0-9a-fA-F_]+);\n")


def test_the_export_has_no_input_less_always_block():
    """Icarus runs the export as it is: no ``always @*`` block assigns only a constant (the register
    read words are single assignments with constant zeros beside the fields)."""
    assert CONSTANT_BLOCK.search("  always @*\n    rd_status[7] = 1'h0;\n")  # the pattern finds one
    text = (engine_sources(DEFAULT, CAPACITY, "icarus") / f"{ENGINE_MODULE}.v").read_text()
    assert CONSTANT_BLOCK.findall(text) == []


def test_the_simulation_harness_keeps_every_port_and_registers_rst():
    """springflat_engine_sim: the engine's ports, each connected by name, except rst through one flip-flop."""
    text = (engine_sources(DEFAULT, CAPACITY, "verilator") / f"{ENGINE_MODULE}.v").read_text()
    ports = top_ports(text)
    assert {"clk", "rst", "irq", "bus__cyc", "bus__stb", "bus__ack", "bus__dat_r"} <= {name for *_, name in ports}
    harness = simulation_harness(text)
    assert [(d, w, n) for d, w, n in ports] == [
        (m[1], (m[2] or "").strip(), m[3]) for m in re.finditer(
            r"^  (input|output) (\[\d+:\d+\] )?(\w+),?$", harness, re.MULTILINE)]
    for _, _, name in ports:
        assert f".{name}({'rst_q' if name == 'rst' else name})" in harness
    assert "always @(posedge clk) rst_q <= rst;" in harness


def test_rtl_check_engine_top_cli(tmp_path):
    """rtl-check --engine-top: one JSON object, bit-exact, with the speed numbers; exit 0."""
    need_simulator("verilator")
    proc = subprocess.run([SPRINGFLAT, "rtl-check", "surf1", "--engine-top", "--capacity", "64", "512", "128",
                           "--iterations", "4", "--wait-states", "2", "--json"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = json.loads(proc.stdout)
    assert (r["mismatches"], r["top"], r["simulator"], r["iterations"]) == (0, "springflat_engine", "verilator", 4)
    for key in ("cycles", "cycles_per_iteration", "cycles_per_second", "python_share", "status"):
        assert key in r
    # E as every other command gives it (a float), and the register's integer beside it: [error] is u0.20
    assert r["area_error"] == r["area_error_raw"] / 2**20 and 0 < r["area_error"] < 1
    assert r["shape_error"] == r["shape_error_raw"] / 2**20 and isinstance(r["energy_raw"], int)


def test_rtl_check_lanes_is_bit_exact_in_fewer_cycles(tmp_path):
    """rtl-check --engine-top --lanes 2 (an engine of two lanes, without the guard) on an unguarded momentum run:
    bit-exact, and in fewer than 0.65 of one lane's clocks on a 256-vertex dome (the passes' latencies, which
    lanes do not shorten, weigh more on a small mesh: 0.51 on the 2,025-vertex patch of docs/engine.md)."""
    from sim.mesh_io import save_obj

    need_simulator("verilator")
    mesh = dome_grid(16)
    save_obj(tmp_path / "dome.obj", mesh.vertices, mesh.faces)
    runs = {}
    for lanes in ("1", "2"):
        proc = subprocess.run([SPRINGFLAT, "rtl-check", "dome.obj", "--engine-top", "--lanes", lanes, "--capacity", "256",
                               "1536", "512", "--no-guard", "--energy-window", "1", "--iterations", "4", "--json"],
                              capture_output=True, text=True, cwd=tmp_path, timeout=1200)
        assert proc.returncode == 0, proc.stderr[-2000:]
        runs[lanes] = json.loads(proc.stdout)
    assert [(r["mismatches"], r["iterations"], r["lanes"]) for r in runs.values()] == [(0, 4, 1), (0, 4, 2)]
    assert runs["2"]["energy_raw"] == runs["1"]["energy_raw"]
    assert runs["2"]["cycles"] < 0.65 * runs["1"]["cycles"]


def test_rtl_check_on_a_mesh_file_with_its_defaults_runs_the_whole_engine(tmp_path):
    """A mesh file's defaults are the guarded momentum dynamics, which only the whole engine runs: rtl-check
    says so in a note and checks SpringflatEngine, bit-exact, instead of refusing its own defaults."""
    from sim.mesh_io import save_obj

    need_simulator("verilator")
    mesh = dome_grid(4)
    save_obj(tmp_path / "dome.obj", mesh.vertices, mesh.faces)
    proc = subprocess.run([SPRINGFLAT, "rtl-check", "dome.obj", "--capacity", "64", "512", "128", "--iterations", "3",
                           "--json"], capture_output=True, text=True, cwd=tmp_path, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "springflat: note: the guarded momentum dynamics (the default for mesh files) runs on the whole engine only" \
        in proc.stderr
    r = json.loads(proc.stdout)
    assert (r["mismatches"], r["top"], r["iterations"]) == (0, "springflat_engine", 3)


def test_the_engine_runs_a_mesh_with_kept_holes_bit_exact(tmp_path):
    """A disk with a hole (a cut-out): the engine needs nothing of a disk, and rtl-check takes --keep-holes."""
    from sim.generate import holed_dome
    from sim.mesh_io import save_obj

    need_simulator("verilator")
    mesh = holed_dome(7, holes=((2, 2, 2),))
    save_obj(tmp_path / "holed.obj", mesh.vertices, mesh.faces)
    proc = subprocess.run([SPRINGFLAT, "rtl-check", "holed.obj", "--keep-holes", "--capacity", "64", "512", "128",
                           "--iterations", "4", "--json"], capture_output=True, text=True, cwd=tmp_path, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "1 hole kept as cut-out" in proc.stderr
    r = json.loads(proc.stdout)
    assert (r["mismatches"], r["top"], r["iterations"]) == (0, "springflat_engine", 4)


@pytest.mark.parametrize("command", [["rtl-check", "surf2", "--engine-top"], ["flatten", "surf2", "--engine", "rtl"]])
def test_a_mesh_over_capacity_is_refused_in_one_line(command, tmp_path):
    """Refused before anything is built: exit 2 and one line naming the count and the capacity."""
    extra = ["--capacity", "8", "64", "32"] if command[0] == "rtl-check" else []
    env = {**os.environ, "SPRINGFLAT_ENGINE_CAPACITY": "8,64,32"}
    proc = subprocess.run([SPRINGFLAT, *command, *extra], capture_output=True, text=True, cwd=tmp_path, env=env,
                          timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0] == ("springflat: error: the mesh has 15 vertices; the engine holds at most 8 "
                                            "(capacity vertices=8, entries=64, triangles=32)")


def test_flatten_engine_rtl_writes_the_fixed_engines_layout(tmp_path):
    """flatten --engine rtl writes the layout flatten --engine fixed writes, bit for bit."""
    need_simulator("verilator")
    env = {**os.environ, "SPRINGFLAT_ENGINE_CAPACITY": "64,512,128"}
    outs = {}
    for engine in ("rtl", "fixed"):
        proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", engine, "--max-iter", "5",
                               "--out", f"{engine}.flat.obj", "--json"], capture_output=True, text=True, cwd=tmp_path,
                              env=env, timeout=1200)
        assert proc.returncode == 0, proc.stderr[-2000:]
        outs[engine] = json.loads(proc.stdout)
    assert (tmp_path / "rtl.flat.obj").read_text() == (tmp_path / "fixed.flat.obj").read_text()  # the layouts
    assert outs["rtl"]["iterations"] == outs["fixed"]["iterations"] == 5
    assert outs["rtl"]["status"] == outs["fixed"]["status"]
    assert (outs["rtl"]["engine"], outs["fixed"]["engine"]) == ("rtl", "fixed")  # each result names its engine


def test_a_stalled_run_is_bit_exact_and_starts_as_flatten_does(tmp_path):
    """``floor`` rounding stalls the guarded run on Surf1 (docs/fixed-point.md): the engine ends ``stalled``
    at the fixed engine's iteration, bit-exact, from the start ``flatten`` takes (PCA folds 3 triangles
    there, untangled first), and ``flatten --engine rtl`` writes the fixed engine's layout."""
    need_simulator("verilator")
    floor = tmp_path / "floor.json"
    DEFAULT.replace(rounding="floor", name="default_floor").save(floor)
    env = {**os.environ, "SPRINGFLAT_ENGINE_CAPACITY": "64,512,128"}
    common = ["surf1", "--dynamics", "momentum", "--formats", str(floor), "--json"]
    outs = {}
    for engine in ("fixed", "rtl"):
        proc = subprocess.run([SPRINGFLAT, "flatten", *common, "--engine", engine, "--out", f"{engine}.flat.obj"],
                              capture_output=True, text=True, cwd=tmp_path, env=env, timeout=1200)
        assert proc.returncode == 0, proc.stderr[-2000:]
        outs[engine] = json.loads(proc.stdout)
    assert outs["fixed"]["status"] == outs["rtl"]["status"] == "stalled"
    assert outs["fixed"]["iterations"] == outs["rtl"]["iterations"] > 0 and outs["rtl"]["folded"] == 0
    assert (tmp_path / "rtl.flat.obj").read_text() == (tmp_path / "fixed.flat.obj").read_text()
    proc = subprocess.run([SPRINGFLAT, "rtl-check", *common, "--engine-top", "--capacity", "64", "512", "128"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-2000:]
    check = json.loads(proc.stdout)
    assert (check["mismatches"], check["status"], check["iterations"]) == (0, "stalled", outs["fixed"]["iterations"])
    assert "folds 3 triangles: untangling it" in proc.stderr


def test_the_bench_is_told_the_capacity_it_runs_on(monkeypatch, tmp_path):
    """run_image_on_rtl hands the bench the whole capacity, the step guard included: a build without the
    guard must be driven with its own register map (the driver checks FEATURES.guard against it)."""
    import sim.engine_run as engine_run

    seen = record_bench_configs(monkeypatch, engine_run, "engine_sources", tmp_path)
    image = dome_image("paper-variable", 2)
    guardless = dataclasses.replace(CAPACITY, guard=False)
    for capacity in (CAPACITY, guardless):
        with pytest.raises(BenchCalled):
            run_image_on_rtl(dataclasses.replace(image, capacity=capacity), DEFAULT, "verilator",
                             work=tmp_path / str(capacity.guard))
    assert [EngineCapacity(**config["capacity"]) for config in seen] == [CAPACITY, guardless]


COARSE = dataclasses.replace(CAPACITY, coarse_degree=3)


@pytest.mark.parametrize("simulator", ["verilator", "icarus"])
def test_a_coarse_run_is_bit_exact(simulator):
    """The engine with a coarse space (``EngineCapacity.coarse_degree``), exported to Verilog: a guarded run that
    takes the coarse move, squeezed across so that steps are clipped and rolled back, equals ``run_image`` every
    iteration (N_max = 1, 2 read back) and whole, with bus wait states, on both simulators."""
    need_simulator(simulator)
    mesh = dome_grid(4)
    params = FlattenParams(density="auto", dynamics="momentum", coarse_degree=3, tol_area=0.0, tol_shape=0.0,
                           max_iter=8)
    layout = initial_layout(mesh, "tutte") * np.array([0.05, 1.0])
    image = build_image(prepare(mesh, layout, params, DEFAULT), COARSE)
    want = run_image(image, DEFAULT)
    assert want.guard.rejected > 0 and want.guard.clipped > 0 and image.constants["coarse"] == 1
    run = run_image_on_rtl(image, DEFAULT, simulator, wait_states=3, seed=7, checks={"iteration_checks": 2})
    r = run.result
    assert run.passed, r.get("first_mismatches", r)
    assert np.array_equal(run.positions, want.positions) and np.array_equal(run.velocities, want.velocities)
    assert (r["status"], r["iterations"], r["shape_error"], r["energy"]) == (
        want.status, want.iterations, want.shape_error, want.energy)


def test_flatten_engine_rtl_with_the_coarse_space_writes_the_fixed_engines_layout(tmp_path):
    """flatten --engine rtl --coarse-degree 3 builds the engine with the coarse space and writes the layout
    flatten --engine fixed --coarse-degree 3 writes, bit for bit."""
    need_simulator("verilator")
    env = {**os.environ, "SPRINGFLAT_ENGINE_CAPACITY": "64,512,128"}
    outs = {}
    for engine in ("rtl", "fixed"):
        proc = subprocess.run([SPRINGFLAT, "flatten", "surf1", "--engine", engine, "--dynamics", "momentum",
                               "--coarse-degree", "3",
                               "--max-iter", "12", "--out", f"{engine}.flat.obj", "--json"], capture_output=True,
                              text=True, cwd=tmp_path, env=env, timeout=1800)
        assert proc.returncode == 0, proc.stderr[-2000:]
        outs[engine] = json.loads(proc.stdout)
    assert (tmp_path / "rtl.flat.obj").read_text() == (tmp_path / "fixed.flat.obj").read_text()
    assert outs["rtl"]["iterations"] == outs["fixed"]["iterations"]
    assert outs["rtl"]["coarse_degree"] == outs["fixed"]["coarse_degree"] == 3
