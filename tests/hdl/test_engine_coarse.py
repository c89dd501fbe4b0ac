"""SpringflatEngine with a coarse space (``EngineCapacity.coarse_degree``) on Amaranth's simulator: guarded
whole runs that take the coarse move bit for bit against the golden model's ``run_image``, the basis and
matrix windows loaded over the bus, and START's check of the COARSE run constant."""

import dataclasses

import numpy as np
import pytest

from golden_model.coarse import CoarseSchedule
from golden_model.engine_spec.image import constant_fault, run_image
from golden_model.fixed.format import SaturationCounter
from golden_model.modes import mode_named
from golden_model.params import FlattenParams
from support.engine_sim import (CAPACITY, FS, PreloadableEngine, aborts_then_a_whole_run, assert_same_run, image_of,
                                load_and_snapshot, load_directly, phase_spans, run_on_engine, simulate,
                                start_answers)

# the whole engine on the Python simulator (seconds per iteration): every test but the last is marked slow

COARSE = dataclasses.replace(CAPACITY, coarse_degree=3)
RUN = FlattenParams(dynamics="momentum", coarse_degree=3, max_iter=12)


def golden_run(image, monkeypatch):
    """``run_image`` of ``image``, with the schedule's hand-overs to the Jacobi step by kind (``"rejected"``: a
    rolled-back plain gradient step that took the coarse move; ``"clipped"``: an accepted one clipped deep) and the
    saturation events by name."""
    handovers, events = set(), {}
    rejected, accepted, add = CoarseSchedule.rejected, CoarseSchedule.accepted, SaturationCounter.add_saturations

    def watched_rejected(schedule, scale, with_momentum):
        if schedule.coarse and not with_momentum:
            handovers.add("rejected")
        return rejected(schedule, scale, with_momentum)

    def watched_accepted(schedule, clipped=False):
        if schedule.coarse and clipped:
            handovers.add("clipped")
        return accepted(schedule, clipped)

    def watched_add(counter, name, n):
        events[name] = events.get(name, 0) + int(n)
        return add(counter, name, n)

    monkeypatch.setattr(CoarseSchedule, "rejected", watched_rejected)
    monkeypatch.setattr(CoarseSchedule, "accepted", watched_accepted)
    monkeypatch.setattr(SaturationCounter, "add_saturations", watched_add)
    return run_image(image, FS), handovers, events


@pytest.mark.slow
@pytest.mark.parametrize("squeeze, iterations, handover", [(0.05, 12, "clipped"), (0.2, 20, "rejected")])
def test_a_coarse_run_with_rollbacks_and_the_hand_over_matches_the_golden_model(monkeypatch, squeeze, iterations,
                                                                                 handover):
    """Squeezed across, the run clips steps and rolls some back; the schedule hands over to the Jacobi step after
    an accepted step clipped deep (``clipped``), or after a rolled-back plain gradient step that took the coarse
    move (``rejected``): the engine's whole run is the golden model's, bit for bit."""
    image = image_of(RUN.with_(max_iter=iterations), COARSE, squeeze=squeeze)
    expected, handovers, _ = golden_run(image, monkeypatch)
    assert handovers == {handover} and expected.guard.rejected >= 1 and expected.guard.clipped > 0
    assert not np.array_equal(expected.positions, run_image(image_of(RUN.with_(coarse_degree=0, max_iter=iterations),
                                                                     COARSE, squeeze=squeeze), FS).positions)
    result, read_back = run_on_engine(PreloadableEngine(FS, COARSE), image)
    assert result == expected.status
    assert_same_run(read_back, expected)


@pytest.mark.slow
def test_coarse_moves_clamped_to_accel_are_counted_as_the_golden_model_counts_them(monkeypatch):
    """A host's matrix exponent 14 below the image's makes the moves 2^14 times larger: they clamp to [accel],
    and SATURATIONS counts each clamp as the golden model does (``coarse_move``)."""
    image = image_of(RUN.with_(max_iter=4), COARSE)
    image = dataclasses.replace(image, constants={**image.constants,
                                                  "matrix_exponent": image.constants["matrix_exponent"] - 14})
    expected, _, events = golden_run(image, monkeypatch)
    assert events.get("coarse_move", 0) > 0 and expected.saturations >= events["coarse_move"]
    result, read_back = run_on_engine(PreloadableEngine(FS, COARSE), image)
    assert result == expected.status
    assert_same_run(read_back, expected)


@pytest.mark.slow
def test_the_coarse_windows_load_over_the_bus_and_start_checks_the_coarse_constant():
    """The basis and matrix windows written over Wishbone leave their block RAMs as the preload does (every word);
    FEATURES.coarse reads the degree; START answers COARSE with an unguarded mode as ``constant_fault`` does
    (bad-constants), and runs it without."""
    image = image_of(RUN, COARSE)
    answers = {}

    def start_checks(driver, bus):
        answers["FEATURES.coarse"] = driver.read_value("feature_coarse")
        unguarded = mode_named("momentum").code
        for name, change in (("coarse unguarded", {"mode": unguarded}), ("unguarded", {"mode": unguarded, "coarse": 0})):
            answers[name] = start_answers(driver, bus, image.constants, change)

    over_the_bus = load_and_snapshot(PreloadableEngine(FS, COARSE), image, True, ("basis", "matrix"))
    preloaded = load_and_snapshot(PreloadableEngine(FS, COARSE), image, False, ("basis", "matrix"), start_checks)
    assert any(over_the_bus["basis"]) and any(over_the_bus["matrix"])
    assert preloaded == over_the_bus
    assert answers["FEATURES.coarse"] == 3
    unguarded = {**image.constants, "mode": mode_named("momentum").code}
    assert constant_fault(unguarded, FS, COARSE) == "bad-constants"
    assert answers["coarse unguarded"] == ("done", "bad-constants")
    assert answers["unguarded"] == ("running", "none")


@pytest.mark.slow
def test_the_paper_dynamics_runs_bit_exact_on_a_coarse_build():
    """The integrate pass's nodes pass the coarse unit in every mode (its latency), with a move of 0 where the step
    takes none: the paper dynamics' run on the coarse build is the golden model's."""
    image = image_of(FlattenParams(density="auto", barrier=True, max_iter=4), COARSE)
    assert image.constants["coarse"] == 0
    expected = run_image(image, FS)
    result, read_back = run_on_engine(PreloadableEngine(FS, COARSE), image)
    assert result == expected.status
    assert_same_run(read_back, expected)


@pytest.mark.slow
def test_abort_in_the_coarse_phase_drains_and_a_clean_rerun_matches():
    """ABORT in the coarse phase's sums pass and in its coefficients, each followed by a reload of the node memory:
    the drain waits for the coarse unit, and the last, whole run is bit-exact (the next coarse phase starts
    clean). The clocks are taken from a first run's phases, the abort's lag calibrated by a first abort."""
    from hdl.phase_controller import phases_of

    image = image_of(RUN.with_(max_iter=3), COARSE)
    dut = PreloadableEngine(FS, COARSE)
    watch, spans, aborted_in, drained_at = phase_spans(dut, phases_of(COARSE))
    out = {}

    def host(driver, bus):
        load_directly(driver, bus, dut, image)
        driver.start()
        driver.wait(poll=lambda: bus.idle(100), max_polls=5000)
        name, begin, end = next(span for span in spans if span[0] == "coarse")
        out["targets"] = (begin + 6, (begin + end) // 2)  # the sums pass; the coefficients
        out["read_back"] = aborts_then_a_whole_run(driver, bus, dut, image, drained_at, aborted_in, begin,
                                                   out["targets"])

    simulate(dut, host, {"watcher": watch})
    assert aborted_in == ["coarse", "coarse"], (aborted_in, out["targets"])
    assert_same_run(out["read_back"], run_image(image, FS))


def test_a_coarse_space_is_built_up_to_one_bank_per_node_memory_and_refused_beyond_in_one_line():
    """(fast: no elaboration) The coarse build at DEFAULT_CAPACITY; at LARGEST_85F_CAPACITY, whose node memories
    take the registered select, SpringflatEngine and the command line's capacity refuse it."""
    import gc
    import warnings

    from amaranth.hdl import UnusedElaboratable

    from golden_model.engine_spec.image import DEFAULT_CAPACITY, LARGEST_85F_CAPACITY
    from golden_model.params import ParameterError
    from hdl.engine import SpringflatEngine
    from sim.register_map_export import engine_capacity

    large = dataclasses.replace(LARGEST_85F_CAPACITY, coarse_degree=3)
    with warnings.catch_warnings():  # engines built here are never elaborated
        warnings.simplefilter("ignore", UnusedElaboratable)
        assert SpringflatEngine(FS, dataclasses.replace(DEFAULT_CAPACITY, coarse_degree=3)).registered_select is False
        with pytest.raises(ValueError, match=r"^SpringflatEngine: a coarse space .* is built without the registered "):
            SpringflatEngine(FS, large)
        for option in ({"delay_lines": True}, {"pin_registers": True}):
            with pytest.raises(ValueError, match="is built without the registered select"):
                SpringflatEngine(FS, COARSE, **option)
        gc.collect()
    with pytest.raises(ParameterError, match=r"^--capacity 3072 18432 6144: the engine's coarse space is built only "):
        engine_capacity((3072, 18432, 6144), FS, coarse_degree=3)
    with pytest.raises(ParameterError, match=r"builds the engine's coarse space .*: drop --no-guard$"):
        engine_capacity(None, FS, guard=False, coarse_degree=3)
    assert engine_capacity(None, FS, coarse_degree=3).coarse_degree == 3
