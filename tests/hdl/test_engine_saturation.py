"""SpringflatEngine's saturation events on Amaranth's simulator: SATURATIONS counted as the golden model's
``run_image`` counts them (the force pass, the integrator, the area pass, the sums and the error measures'
normalisers), and the saturation limit that stops a run as diverged."""

import dataclasses

import pytest

from golden_model.engine_spec.image import EngineCapacity, UNGUARDED, build_image, run_image
from golden_model.fixed.engine import prepare
from golden_model.fixed.format import Format
from sim.generate import dome_grid
from sim.layouts import initial_layout
from golden_model.params import FlattenParams
from support.engine_sim import CAPACITY, FS, MESH, PreloadableEngine, assert_same_run, image_of, run_on_engine

pytestmark = pytest.mark.slow  # the whole engine on the Python simulator: seconds per iteration


def test_saturation_events_are_counted_and_the_limit_stops_the_run_as_diverged():
    """A run that saturates (a large spring constant and step): SATURATIONS equals the golden model's
    count, and with a saturation limit the run stops as diverged at the same iteration."""
    params = FlattenParams(step="fixed", dt=0.9, spring=7.0, density="auto", max_iter=6)
    image = image_of(params)
    expected = run_image(image, FS)
    assert expected.saturations > 10  # the case saturates
    limited = dataclasses.replace(image, constants={**image.constants, "saturation_limit": 4})
    expected_limited = run_image(limited, FS)
    assert expected_limited.status == "diverged"
    for img, exp in ((image, expected), (limited, expected_limited)):
        _, read_back = run_on_engine(PreloadableEngine(FS, CAPACITY), img)
        assert_same_run(read_back, exp)


@pytest.mark.parametrize("dynamics", ["momentum", "paper"])
def test_area_and_shape_sum_saturations_are_counted(dynamics):
    """Narrow face_edge and error_acc formats: the area pass's and the E_C sum's saturation events reach
    SATURATIONS as the golden model counts them (the test above saturates only the force pass and the
    integrator)."""
    fs = dataclasses.replace(FS, face_edge=Format(True, 0, 22), error_acc=Format(False, 2, 16))
    params = FlattenParams(dynamics=dynamics, density="auto", max_iter=6,
                           **(UNGUARDED if dynamics == "momentum" else {}))
    image = build_image(prepare(MESH, initial_layout(MESH, "tutte"), params, fs), CAPACITY)
    expected = run_image(image, fs)
    assert expected.saturations > 10  # the case saturates
    _, read_back = run_on_engine(PreloadableEngine(fs, CAPACITY), image)
    assert_same_run(read_back, expected)


@pytest.mark.parametrize("registered_select", [False, True])
def test_error_measure_saturations_are_counted_before_the_limit_is_tested(registered_select):
    """A layout twice the mesh's size: E_S and E_C are 1 or more at every measurement, the only events
    (the normalisers saturate; two per measurement). Counted as the golden model counts them, and with
    a limit of 4 the run stops as diverged after its one iteration, not at N_max: the check phase waits until the
    normalisers' events are in the count (without that wait it saw 3 and went on). 72 triangles: the area
    normaliser answers after the energy check, so its event is the math phase's last. Also with the
    registered select's verdict, which must be taken in the check phase, not before it."""
    params = FlattenParams(density="auto", max_iter=1)
    mesh, capacity = dome_grid(7), EngineCapacity(64, 512, 128)
    image = build_image(prepare(mesh, 2.0 * initial_layout(mesh, "tutte"), params, FS), capacity)
    expected = run_image(image, FS)
    assert (expected.saturations, expected.status) == (4, "max-iterations")
    limited = dataclasses.replace(image, constants={**image.constants, "saturation_limit": 4})
    expected_limited = run_image(limited, FS)
    assert (expected_limited.status, expected_limited.iterations, expected_limited.saturations) == ("diverged", 1, 4)
    # the limited run alone on the engine: a check that went on at 3 counted events would end at N_max
    # (max-iterations), and its count is compared
    _, read_back = run_on_engine(PreloadableEngine(FS, capacity, registered_select=registered_select), limited)
    assert_same_run(read_back, expected_limited)
