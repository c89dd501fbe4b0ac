"""Trials, not defaults: the guarded momentum step with a graph-Laplacian preconditioner, larger Jacobi
weights, a speed restart, nonlinear conjugate gradients, or a polynomial coarse space (the last built in:
``--coarse-degree``).

Usage::

    .venv/bin/python benchmarks/laplacian_step_trial.py                      # issue 25's four patches
    .venv/bin/python benchmarks/laplacian_step_trial.py --corpus [--only NAME ...] [--kinds KIND ...]
    .venv/bin/python benchmarks/laplacian_step_trial.py [--corpus] --variants jacobi jacobi2
    .venv/bin/python benchmarks/laplacian_step_trial.py [--corpus] --variants jacobi coarse_hybrid --coarse-degree 3
    .venv/bin/python benchmarks/laplacian_step_trial.py --variants jacobi coarse_hybrid --engine fixed

The default step proposes ``V' = β_k·V + s·w_i·f_i`` with the Jacobi weights ``w_i = 2/(C·deg_i)``
(``docs/guard.md``). The trial replaces ``w_i·f_i`` by ``K⁻¹f`` with ``K = C·((1 + δ)·D − A)``, the
graph Laplacian of the springs (each spring's stiffness along its edge is C; ``D`` the degrees, ``A``
the adjacency, ``δ = 0.01`` keeps ``K`` regular on a free boundary), factored once per run
(``scipy.sparse.linalg.splu``). Everything else, the guard included, is the default's: each proposal
passes the same flip certificate and energy comparison, so the guarantees hold by construction.

Variants beside the default (``jacobi``):

* ``laplacian``: ``K⁻¹f`` on every step;
* ``hybrid``: ``K⁻¹f``; a rolled-back plain gradient step (no momentum) switches to the Jacobi step for
  ``HYBRID_JACOBI_STEPS`` accepted steps instead of halving the scale (the global direction, clipped
  node by node by the guard, stops being a descent direction near the floor; the local one does not);
* ``jacobi2``: the Jacobi step with twice the weights, ``2·w_i`` (the momentum step's stability bound,
  ``w·λ < 2(1 + β)``, leaves that room where the springs' stiffness is well below its bound ``C·deg_i``);
* ``speed``: the Jacobi step with a speed restart (Su, Boyd & Candès 2016; the kinetic damping of dynamic
  relaxation): besides the gradient restart, an accepted move shorter than the one before
  (``‖V_k‖ < ‖V_{k−1}‖``) restarts the momentum, from ``SPEED_RESTART_AFTER`` iterations after the last
  restart on;
* ``cg``: Jacobi-preconditioned nonlinear conjugate gradients instead of the momentum (Polak–Ribière+,
  ``d = w·f + γ·d_prev``, ``γ = max(0, (w·f)·(f − f_prev) / (w_prev·f_prev)·f_prev)``, ``d := w·f`` where
  ``d`` is not a descent direction). Each iteration tries the step ``α·d`` (the guard's certificate on it),
  fits a parabola through the energy there, the energy and its slope ``−f·d`` at the layout, and tries its
  minimum ``α*`` too; the lower of the two is taken if it does not raise the energy, else ``d := w·f`` and
  ``α`` halves. Up to two energy evaluations an iteration against the default's one: a line search the engine's
  passes do not have, tried for what it would give. A Krylov method adapts to the spectrum where the
  heavy ball's fixed schedule cannot (isolated slow modes cost it a few iterations each);
* ``coarse``: ``w·f + Φ (ΦᵀKΦ)⁻¹ Φᵀ f``, a two-level step: the Jacobi step plus the best move, for the
  springs' Laplacian ``K``, in a coarse space of smooth global functions, ``Φ`` the monomials up to degree
  ``--coarse-degree`` (default ``DEFAULT_COARSE_DEGREE``) of the start layout's coordinates (10 for degree 3,
  centred and scaled to the layout's extent). ``ΦᵀKΦ`` is a small run constant; each iteration needs the
  sums ``Φᵀf`` over the nodes and each node's ``Φc``, which the engine's passes could carry;
* ``coarse_hybrid``: ``coarse``, with ``hybrid``'s rule: a rolled-back plain gradient step switches to the
  Jacobi step alone for ``HYBRID_JACOBI_STEPS`` accepted steps. Built in: the models' ``--coarse-degree``
  (``golden_model.coarse``, ``golden_model.fixed.coarse``), which this variant runs, in float or, with
  ``--engine fixed``, in fixed point, as ``jacobi`` (the built-in default);
* ``sweeps`` (the four patches only): ``SWEEPS`` damped Jacobi sweeps on ``K x = f`` from ``w·f``, each one
  more pass over the neighbours, the kind of preconditioner the engine's passes could run.

Default mode: from Tutte's layout on the cap, bumpy patch, saddle and cylinder strip at ~15 edges of
radius, the iterations until E_C stays within 1 % of the minimum's (the minimum: 3,000 iterations of the
default dynamics; ``tests/golden_model/test_dynamics.py``'s measure) and, under the mesh files' stop
rule, status, iterations and E_C.

``--corpus``: each patch's no-option start (``start_layout(mesh, "auto")``) and file defaults, run
in-process with each variant: status, iterations, seconds of the run alone (not the start, not the
command's start-up: compare the columns, not with ``corpus_table.py``'s wall times), E_C and folds,
and E_C against the cached peers (``CORPUS/peers.json`` from ``corpus_table.py``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

import golden_model.coarse as coarse  # noqa: E402
import golden_model.reference as reference  # noqa: E402
from sim.generate import bumpy_grid, rolled_grid, saddle_grid, spherical_cap  # noqa: E402
from golden_model.guard import guarded_moves  # noqa: E402
from sim.layouts import initial_layout, start_layout  # noqa: E402
from golden_model.params import FlattenParams  # noqa: E402
from golden_model.fixed.engine import flatten_fixed  # noqa: E402
from golden_model.reference import flatten, iterations_to_within  # noqa: E402
from sim.run_options import FILE_ITER_PER_EDGE, FILE_MIN_ITER, FILE_TOL_ENERGY, edge_radius  # noqa: E402

#: ``hybrid``: accepted Jacobi steps after a rolled-back gradient step, before the Laplacian step again.
HYBRID_JACOBI_STEPS = 20
#: ``speed``: iterations since the last restart before a shorter move restarts the momentum.
SPEED_RESTART_AFTER = 10
VARIANTS = ("jacobi", "laplacian", "hybrid", "jacobi2", "speed", "cg", "coarse", "coarse_hybrid")
#: Four patches only: ``SWEEPS`` damped Jacobi sweeps on ``K x = f`` from the default's ``w·f`` (one more
#: pass over the neighbours each, as the engine could run them).
SWEEPS = 8
MESHES = {
    "spherical cap, 15 rings": lambda: spherical_cap(15),
    "bumpy 31×31": lambda: bumpy_grid(31),
    "saddle 31×31": lambda: saddle_grid(31),
    "cylinder strip 31×31, 180°": lambda: rolled_grid(31, 31, arc_degrees=180)[0],
}
RUN = dict(tol_area=1.0, tol_shape=1.0, tol_energy=0.0, energy_window=1000)  # exactly max_iter iterations


class _Trial(reference._Jacobi):
    """``reference._Jacobi`` with the trial's direction in the guarded momentum step: its ``w·f``
    (``_force_step``) replaced, and for ``hybrid`` what a rolled-back step does (``_after_rejection``)."""

    variant = "jacobi"
    coarse_degree = coarse.DEFAULT_COARSE_DEGREE

    def _graph(self) -> tuple[sp.csr_matrix, np.ndarray]:
        """The springs' adjacency matrix and the nodes' degrees."""
        mesh = self.model.mesh
        i, j = mesh.edges.T
        n = mesh.n_vertices
        adjacency = sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
        return adjacency, np.asarray(adjacency.sum(axis=1)).ravel()

    def _stiffness(self) -> sp.csr_matrix:
        """``K = C·((1 + δ)·D − A)``."""
        adjacency, degree = self._graph()
        return self.params.spring * (sp.diags((1.0 + coarse.STIFFNESS_SHIFT) * degree) - adjacency)

    def _laplacian_solve(self, forces: np.ndarray) -> np.ndarray:
        if not hasattr(self, "_lu"):
            self._lu = spla.splu(self._stiffness().tocsc())
        return self._lu.solve(np.ascontiguousarray(forces))

    def _coarse(self, forces: np.ndarray) -> np.ndarray:
        """The coarse space's correction ``Φ (ΦᵀKΦ)⁻¹ Φᵀ f`` (:mod:`golden_model.coarse`, the built-in step's)."""
        if not hasattr(self, "_basis"):
            self._basis = coarse.basis(self.positions, self.coarse_degree)
            self._coarse_inverse = coarse.coarse_inverse(self._basis, self.model.mesh.edges, self.params.spring)
        return coarse.coarse_move(self._basis, self._coarse_inverse, forces)

    def _sweeps(self, forces: np.ndarray) -> np.ndarray:
        adjacency, degree = self._graph()
        degree = degree[:, None]
        inverse = 1.0 / (self.params.spring * degree)
        x = 2.0 * inverse * forces
        for _ in range(SWEEPS):
            x = x + 0.5 * inverse * (forces - self.params.spring * (degree * x - adjacency @ x))
        return x

    def _try(self, proposal: np.ndarray) -> tuple[float, tuple]:
        """The energy of the layout the guard lets ``proposal`` reach, and that layout's state (not taken)."""
        mesh = self.model.mesh
        moves, _ = guarded_moves(self.positions, proposal, mesh.faces, self.model.winding, 2.0 * mesh.face_areas)
        before = (self.positions, self.delta, self.length, self.signed, self._layout_energy)
        self.positions = self.positions + moves
        self._refresh()
        energy = self.energy_of_layout()
        reached = (self.positions, self.delta, self.length, self.signed, self._layout_energy)
        self.positions, self.delta, self.length, self.signed, self._layout_energy = before
        return energy, reached

    def _advance_cg(self) -> None:
        forces = self.forces()
        z = self.model.step_weights(self.positions, self.signed)[:, None] * forces
        previous, alpha = getattr(self, "_cg_previous", None), getattr(self, "_cg_alpha", 1.0)
        direction = z
        if previous is not None:
            forces_before, z_before, direction_before = previous
            gamma = max(0.0, float(np.sum(z * (forces - forces_before))) / float(np.sum(z_before * forces_before)))
            direction = z + gamma * direction_before
            if float(np.sum(direction * forces)) <= 0.0:
                direction = z
        slope = float(np.sum(forces * direction))  # −dE/dα at α = 0
        energy_1, reached_1 = self._try(alpha * direction)
        curvature = 2.0 * (energy_1 - self.energy + alpha * slope) / alpha**2
        best = (energy_1, reached_1)
        if curvature > 0.0:
            alpha_star = slope / curvature
            energy_2, reached_2 = self._try(alpha_star * direction)
            if energy_2 < energy_1:
                best = (energy_2, reached_2)
        else:
            alpha_star = 2.0 * alpha
        self.accepted = best[0] <= self.energy
        if self.accepted:
            self.energy = best[0]
            self.positions, self.delta, self.length, self.signed, self._layout_energy = best[1]
            self._cg_previous, self._cg_alpha = (forces, z, direction), alpha_star
        else:
            self._cg_previous, self._cg_alpha = None, min(alpha_star, alpha / 2.0)
            self.guard.rejected += 1

    def _advance_momentum(self) -> None:
        if self.variant == "cg":
            if self.guard is None:
                raise ValueError("the trial is the guarded step's")
            self._advance_cg()
            return
        speed_before, k = float(np.sum(self.velocities**2)), self.momentum_k
        super()._advance_momentum()
        if self.variant == "speed" and self.accepted and k >= SPEED_RESTART_AFTER \
                and float(np.sum(self.velocities**2)) < speed_before:
            self.restart = True

    def _force_step(self, forces: np.ndarray) -> np.ndarray:
        if self.guard is None:
            raise ValueError("the trial is the guarded step's")
        # hybrid: the Jacobi steps left, counted down by a taken step (a rolled-back one restores it)
        self._jacobi_left_before = jacobi_left = getattr(self, "_jacobi_left", 0)
        self._jacobi_left = jacobi_left - 1
        if self.variant in ("jacobi", "jacobi2", "speed") or (self.variant == "hybrid" and jacobi_left > 0):
            factor = 2.0 if self.variant == "jacobi2" else 1.0
            return factor * super()._force_step(forces)
        if self.variant == "sweeps":
            return self._sweeps(forces)
        if self.variant == "coarse":
            return super()._force_step(forces) + self._coarse(forces)
        return self._laplacian_solve(forces)

    def _after_rejection(self, with_momentum: bool) -> None:
        self._jacobi_left = jacobi_left = self._jacobi_left_before
        if self.variant == "hybrid" and not with_momentum and jacobi_left <= 0:
            self._jacobi_left = HYBRID_JACOBI_STEPS  # the Jacobi step next, the scale kept
            return
        super()._after_rejection(with_momentum)


#: The variants the models have built in (``--coarse-degree``), which ``--engine fixed`` runs too.
BUILT_IN = ("jacobi", "coarse_hybrid")


def run(variant: str, mesh, p0: np.ndarray, params: FlattenParams, engine: str = "float"):
    """:func:`golden_model.reference.flatten` (or, for the built-in steps, ``engine`` ``fixed``'s
    :func:`~golden_model.fixed.engine.flatten_fixed`) with the trial's step ``variant``."""
    if variant in BUILT_IN:
        params = params.with_(coarse_degree=_Trial.coarse_degree if variant == "coarse_hybrid" else 0)
        return (flatten if engine == "float" else flatten_fixed)(mesh, p0, params)
    if engine != "float":
        raise ValueError(f"{variant} is a float trial: --engine fixed runs {' and '.join(BUILT_IN)}")
    trial = type(f"_Trial_{variant}", (_Trial,), {"variant": variant})
    default = reference._Jacobi
    reference._Jacobi = trial
    try:
        return flatten(mesh, p0, params)
    finally:
        reference._Jacobi = default


def file_defaults(mesh) -> FlattenParams:
    """What a mesh file gets with no options (sim.run_options.resolve_mesh)."""
    return FlattenParams(density="auto", dynamics="momentum", tol_area=1.0, tol_shape=1.0, tol_energy=FILE_TOL_ENERGY,
                         max_iter=max(FILE_MIN_ITER, FILE_ITER_PER_EDGE * edge_radius(mesh)))


def generated(variants: tuple[str, ...], engine: str = "float") -> None:
    print("| patch | minimum's E_C | " + " | ".join(f"{v}: to within 1 %" for v in variants) + " | "
          + " | ".join(f"{v}: default stop (status, it, E_C)" for v in variants) + " |")
    print("|---" * (2 + 2 * len(variants)) + "|")
    for name, make in MESHES.items():
        mesh = make()
        p0 = initial_layout(mesh, "tutte")
        target = flatten(mesh, p0, FlattenParams(dynamics="momentum", max_iter=3000, **RUN)).final.shape_error
        within, stopped = [], []
        for variant in variants:
            history = run(variant, mesh, p0, FlattenParams(dynamics="momentum", max_iter=400, **RUN), engine).history
            reached = iterations_to_within(history.shape_error, target)
            within.append(str(reached) if reached is not None else f"> {len(history.shape_error) - 1}")
            r = run(variant, mesh, p0, FlattenParams(dynamics="momentum", density="auto", tol_area=1.0, tol_shape=1.0,
                                                     tol_energy=FILE_TOL_ENERGY, max_iter=3000), engine)
            stopped.append(f"{r.status}, {r.iterations}, {r.final.shape_error:.4f}")
        print(f"| {name} | {target:.4f} | " + " | ".join(within) + " | " + " | ".join(stopped) + " |", flush=True)


def corpus(directory: Path, only: list[str] | None, kinds: list[str] | None, variants: tuple[str, ...]) -> None:
    from corpus_table import EC_TOLERANCE, load_patch, patches

    cache_path = directory / "peers.json"
    cache = json.loads(cache_path.read_text()) if cache_path.is_file() else {}
    print("| mesh | V | " + " | ".join(f"{v}: status, it, s, E_C, folded" for v in variants) + " | SLIM E_C | ARAP E_C (folded) |")
    print("|---" * (4 + len(variants)) + "|")
    totals = {v: [0, 0.0, 0, 0] for v in variants}  # iterations, seconds, E_C misses, folded runs
    for entry in patches(directory, only, kinds):
        mesh = load_patch(entry, directory)
        p0 = start_layout(mesh, "auto").positions
        peers = cache.get(entry["patch"]["sha256"], {})
        slim, arap = peers.get("slim", {}), peers.get("arap", {})
        cells = []
        for variant in variants:
            start = time.perf_counter()
            r = run(variant, mesh, p0, file_defaults(mesh))
            seconds = time.perf_counter() - start
            ec = r.final.shape_error
            miss = (slim and ec > slim["shape_error"] * (1 + EC_TOLERANCE)) or \
                (arap and arap["folded"] == 0 and ec > arap["shape_error"] * (1 + EC_TOLERANCE))
            t = totals[variant]
            t[0] += r.iterations
            t[1] += seconds
            t[2] += bool(miss)
            t[3] += r.final.folded > 0
            cells.append(f"{r.status}, {r.iterations}, {seconds:.1f}, {ec:.4f}{' (E_C miss)' if miss else ''}, {r.final.folded}")
        arap_cell = f"{arap['shape_error']:.4f} ({arap['folded']})" if arap else "–"
        slim_cell = f"{slim['shape_error']:.4f}" if slim else "–"
        print(f"| {entry['name']} | {mesh.n_vertices} | " + " | ".join(cells) + f" | {slim_cell} | {arap_cell} |",
              flush=True)
    print()
    for variant, (iterations, seconds, misses, folded) in totals.items():
        print(f"{variant}: {iterations} iterations, {seconds:.0f} s of runs, {misses} E_C misses, {folded} folded runs")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--corpus", nargs="?", type=Path, const=REPO / "build" / "corpus", default=None,
                        metavar="DIR", help="the corpus's no-option runs (default DIR: build/corpus)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="with --corpus: only these patches")
    parser.add_argument("--kinds", nargs="+", metavar="KIND", help="with --corpus: only these kinds")
    parser.add_argument("--coarse-degree", type=int, default=coarse.DEFAULT_COARSE_DEGREE, metavar="D",
                        help="coarse, coarse_hybrid: the coarse space's polynomial degree (default "
                             f"{coarse.DEFAULT_COARSE_DEGREE})")
    parser.add_argument("--variants", nargs="+", choices=VARIANTS + ("sweeps",), metavar="VARIANT",
                        help=f"the steps to compare (default: all; {', '.join(VARIANTS)}, and sweeps without --corpus)")
    parser.add_argument("--engine", choices=("float", "fixed"), default="float",
                        help="without --corpus: the model that runs the built-in steps (jacobi, coarse_hybrid); the "
                             "minimum is float's (default float)")
    args = parser.parse_args()
    _Trial.coarse_degree = args.coarse_degree
    if args.engine == "fixed" and (args.corpus is not None or not set(args.variants or VARIANTS) <= set(BUILT_IN)):
        parser.error(f"--engine fixed runs the built-in steps ({', '.join(BUILT_IN)}) on the four patches")
    if args.corpus is None:
        generated(tuple(args.variants or VARIANTS + ("sweeps",)), args.engine)
    elif "sweeps" in (args.variants or ()):
        parser.error("sweeps runs on the four patches only, not with --corpus")
    else:
        corpus(args.corpus, args.only, args.kinds, tuple(args.variants or VARIANTS))


if __name__ == "__main__":
    main()
