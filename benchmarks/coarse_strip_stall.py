"""The developable strip on which the coarse space stalls: the 12×12 half-cylinder of
``tests/golden_model/test_dynamics.py`` (``rolled_grid(12, 12, arc_degrees=180)``), from Tutte, in float, with the
test's run settings (no stop rule: exactly ``--max-iter`` iterations), for each coarse degree with and without the
barrier.

Usage: .venv/bin/python benchmarks/coarse_strip_stall.py [--max-iter 1000] [--degrees 0 1 2 3] [--n 12]
       [--without-clip-handover]

Prints a row per run: the final E_C and energy, the iteration at which E_C first falls below 1e-4, the guard's
rolled-back steps and its clipped and frozen node steps, the final step scale, and the smallest triangle's area
as a fraction of its 3D area. Then the stop rule's ending (the default's ``tol_energy``, ``energy_window``) of
each run. ``--without-clip-handover`` runs the coarse schedule without its hand-over after a step clipped deep
(``golden_model.coarse.CLIP_HANDOVER_LEVEL``), as it was when the strip stalled. ``docs/guard.md`` holds its
output (under ten seconds).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from golden_model.coarse import CoarseSchedule
from golden_model.params import FlattenParams
from golden_model.reference import flatten, signed_areas_2d
from sim.generate import rolled_grid
from sim.layouts import initial_layout

#: The test's settings: the stop rule never fires, every run takes exactly ``max_iter`` iterations.
EXACT = dict(tol_area=1.0, tol_shape=1.0, tol_energy=0.0, energy_window=1000)
#: The E_C that counts as reached.
REACHED = 1e-4


def first_below(values: np.ndarray, bound: float) -> int | None:
    """The first iteration whose value is below ``bound`` (a history's row index: row 0 is the start), or
    ``None``."""
    below = np.flatnonzero(np.asarray(values) < bound)
    return int(below[0]) if below.size else None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-iter", type=int, default=1000)
    parser.add_argument("--degrees", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--n", type=int, default=12, help="the strip's grid (n × n)")
    parser.add_argument("--without-clip-handover", action="store_true",
                        help="the schedule's hand-over only after a rolled-back step")
    args = parser.parse_args()
    if args.without_clip_handover:
        accepted = CoarseSchedule.accepted
        CoarseSchedule.accepted = lambda schedule, clipped=False: accepted(schedule, False)
    mesh = rolled_grid(args.n, args.n, arc_degrees=180)[0]
    p0 = initial_layout(mesh, "tutte")
    print("| degree | barrier | E_C | energy | E_C < 1e-4 at | rolled back | clipped | frozen | scale | smallest area / 3D |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for barrier in (False, True):
        for degree in args.degrees:
            result = flatten(mesh, p0, FlattenParams(dynamics="momentum", barrier=barrier, coarse_degree=degree,
                                                     max_iter=args.max_iter, **EXACT))
            ratio = np.abs(signed_areas_2d(result.positions, mesh.faces)) / mesh.face_areas
            guard = result.extra
            print(f"| {degree} | {'on' if barrier else 'off'} | {result.final.shape_error:.2g} | "
                  f"{result.final.energy:.2g} | {first_below(result.history.shape_error, REACHED) or '–'} | "
                  f"{guard['rejected_steps']} | {guard['clipped_node_steps']} | {guard['frozen_node_steps']} | "
                  f"{guard['step_scale']:.2g} | {ratio.min():.2g} |", flush=True)
    print("\nUnder the default stop rule:")
    for barrier in (False, True):
        for degree in args.degrees:
            result = flatten(mesh, p0, FlattenParams(dynamics="momentum", barrier=barrier, coarse_degree=degree,
                                                     max_iter=args.max_iter))
            print(f"  barrier {'on' if barrier else 'off'}, degree {degree}: {result.status} at iteration "
                  f"{result.iterations}, E_C {result.final.shape_error:.2g}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
