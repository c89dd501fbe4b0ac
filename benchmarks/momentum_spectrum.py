"""Why the guarded momentum step needs 175 and 217 iterations on the saddle and the strip: the spectrum of the
Jacobi-weighted Hessian at the minimum (float, docs/guard.md "Speed to the minimum").

Usage::

    .venv/bin/python benchmarks/momentum_spectrum.py      # issue 25's four patches, 25 s of CPU

For each patch at ~15 edges of radius: the minimum (3,000 iterations of the defaults from Tutte, as
``tests/golden_model/test_dynamics.py`` measures), the Hessian ``H`` of the springs' energy there by central
differences of the forces, and the eigenvalues of ``W^½ H W^½`` with ``W`` the step weights
``w_i = 2/(C·deg_i)`` (the springs alone: the barrier is off at every minimum here), ``λ_min`` the smallest
positive one (``negative``: how many are below zero, springs in compression; the three rigid motions are
left out). A heavy-ball step ``V ← β·V − α·W∇E`` with
the best β converges at ``ρ = 1 − 2/(√κ_α + 1)`` per iteration near the minimum, ``√κ_α ≈ 1/√(α·λ_min)`` for
a step ``α·W`` small against the stiff end, and is stable while ``α·λ_max < 2(1 + β) ≈ 4``. So the
iterations scale as ``1/√α``: the step that would bring a patch from its iterations to 120 is
``α = (iterations/120)²``, against the largest stable one, ``4/λ_max``.
Printed beside it, measured: the iterations to within 1 % of the minimum's E_C with the step weights
``f·w_i`` for each ``f`` in ``FACTORS`` (guard and barrier as by default; ``f = 1`` is the default).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from sim.layouts import initial_layout  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
import golden_model.reference as reference  # noqa: E402
from golden_model.reference import SpringModel, _Jacobi, flatten, iterations_to_within  # noqa: E402
from laplacian_step_trial import MESHES, RUN  # noqa: E402  (issue 25's four patches, run exactly max_iter)

BOUND = 120
#: Multiples of the default step weights measured (1: the default).
FACTORS = (1.0, 1.5, 2.0, 2.5, 3.0)
#: Central-difference step of the Hessian, in mesh units (the patches' edges are ~1/30).
H_STEP = 1e-6


def weighted_hessian(mesh, positions: np.ndarray) -> np.ndarray:
    """``W^½ H W^½`` of the springs' energy at ``positions`` (``2V × 2V``, coordinates interleaved)."""
    params = FlattenParams(dynamics="momentum", barrier=False, **RUN)
    model = SpringModel.build(mesh, positions, params.spring, params.density, None)
    state = _Jacobi(model, params, positions)
    n = 2 * len(positions)
    hessian = np.zeros((n, n))
    for k in range(n):
        for sign in (1.0, -1.0):
            moved = positions.copy()
            moved.flat[k] += sign * H_STEP
            state.positions = moved
            state._refresh()
            hessian[:, k] -= sign * state.forces().ravel() / (2 * H_STEP)
    root = np.sqrt(np.repeat(model.spring_weights, 2))
    return root[:, None] * (0.5 * (hessian + hessian.T)) * root[None, :]


def iterations_with_weights(mesh, p0: np.ndarray, target: float, factor: float) -> int | None:
    """Iterations to within 1 % of ``target`` from ``p0`` with the step weights ``factor·w_i`` (guard unchanged)."""
    scaled = type("_Scaled", (_Jacobi,),
                  {"_force_step": lambda self, forces: factor * _Jacobi._force_step(self, forces)})
    default, reference._Jacobi = reference._Jacobi, scaled
    try:
        history = flatten(mesh, p0, FlattenParams(dynamics="momentum", max_iter=400, **RUN)).history
    finally:
        reference._Jacobi = default
    return iterations_to_within(history.shape_error, target)


def main() -> None:
    print("| patch | V | negative | λ_min | λ_max | κ | " + " | ".join(f"iterations, {f}·w" for f in FACTORS)
          + f" | α for {BOUND} | largest stable α, 4/λ_max |")
    print("|---" * (8 + len(FACTORS)) + "|")
    for name, make in MESHES.items():
        mesh = make()
        p0 = initial_layout(mesh, "tutte")
        minimum = flatten(mesh, p0, FlattenParams(dynamics="momentum", max_iter=3000, **RUN))
        target = minimum.final.shape_error
        counts = [iterations_with_weights(mesh, p0, target, factor) for factor in FACTORS]
        eigenvalues = np.linalg.eigvalsh(weighted_hessian(mesh, minimum.positions))
        rigid = np.abs(eigenvalues) <= 1e-9 * eigenvalues[-1]  # translations and the rotation
        negative = int(np.sum(~rigid & (eigenvalues < 0)))
        softest, stiffest = eigenvalues[~rigid & (eigenvalues > 0)].min(), eigenvalues[-1]
        needed = f"{(counts[0] / BOUND) ** 2:.2f}" if counts[0] is not None else "—"
        print(f"| {name} | {mesh.n_vertices} | {negative} | {softest:.2e} | {stiffest:.3f} | {stiffest / softest:,.0f} | "
              + " | ".join(str(c) if c is not None else "> 400" for c in counts)
              + f" | {needed} | {4 / stiffest:.2f} |", flush=True)


if __name__ == "__main__":
    main()
