"""The coarse space's cost in clocks: ``SpringflatEngine`` built with ``coarse_degree=3`` on Amaranth's simulator,
the run's phases clock by clock.

Usage: .venv/bin/python benchmarks/coarse_phase_clocks.py [--iterations 3]

Runs the 16-vertex dome of ``tests/support/engine_sim.py`` (its capacity, with the coarse space), guarded, every
iteration taking the coarse move, and prints each phase's clocks per iteration, then the same run on the build
without the coarse space (the Jacobi step), whose integrate pass is the unit's latency shorter. About a minute;
``docs/guard.md`` holds its output.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the engine's shared test harness

from support.engine_sim import CAPACITY, FS, PreloadableEngine, image_of, load_directly, phase_spans, simulate  # noqa: E402

from golden_model.engine_spec.image import run_image  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402


def phase_clocks(coarse_degree: int, iterations: int) -> tuple[dict, int]:
    """Each phase's clocks summed over a run of ``iterations`` from START, and the run's iterations (checked
    against ``run_image``)."""
    from hdl.phase_controller import phases_of

    capacity = dataclasses.replace(CAPACITY, coarse_degree=coarse_degree)
    image = image_of(FlattenParams(dynamics="momentum", coarse_degree=coarse_degree, max_iter=iterations,
                                   tol_area=1.0, tol_shape=1.0, tol_energy=0.0), capacity)
    dut = PreloadableEngine(FS, capacity)
    watch, spans, _, _ = phase_spans(dut, phases_of(capacity))

    def host(driver, bus):
        load_directly(driver, bus, dut, image)
        driver.start()
        driver.wait(poll=lambda: bus.idle(100), max_polls=5000)

    simulate(dut, host, {"watcher": watch})
    totals = defaultdict(int)
    for name, begin, end in spans:
        totals[name] += end - begin + 1
    return dict(totals), run_image(image, FS).iterations


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--iterations", type=int, default=3)
    args = parser.parse_args()
    print("| build | phase | clocks an iteration |")
    print("|---|---|---|")
    for degree in (3, 0):
        totals, iterations = phase_clocks(degree, args.iterations)
        for name, clocks in totals.items():
            print(f"| {'coarse_degree=3' if degree else 'no coarse space'} | {name} | {clocks / iterations:.1f} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
