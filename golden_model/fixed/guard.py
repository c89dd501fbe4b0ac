"""The step guard in integers, bit for bit as the engine computes it (``golden_model.guard`` in float).

The guarantee that no accepted step inverts a triangle holds in fixed point by the same
multi-affine argument as in float, with one integer margin for the rounding of the moves:

* a triangle's doubled area ``X0`` and the terms ``L``, ``Q`` are exact integer products of
  position differences and proposals (position, velocity and face_edge share their fraction bits,
  so all are at twice position's fraction bits: "lsb²");
* at level ``r`` the certificate evaluates ``X0 + (L_S >> r) + (Q_S >> 2r)`` (floor shifts: never
  above the exact value) and asks it to stay ``M`` above the floor, where
  ``M = 2·(|P_b − P_a|₁ + |P_c − P_a|₁ + 2|V'_a|₁ + |V'_b|₁ + |V'_c|₁) + 8`` bounds how much moving
  each corner by less than one lsb per coordinate can change the area: the node's move at level
  ``r_i``, ``V' >> r_i``, is its exact fraction ``2^-r_i·V'`` plus such an error;
* the floor ``min(X0, max(X0 >> FLOOR_SHIFT, X*·2^-FLOOR_MIN_SHIFT))`` takes ``X*·2^-20`` from the
  host's triangle area [face_area] by a shift;
* a triangle whose edges do not fit ``face_edge`` is never trusted, and a node whose move would
  leave the position range does not move: holding a node still is always safe;
* as in float, a node whose own move fails its triangle's certificate even at ``2^-GUARD_LEVELS``
  (:func:`stuck_nodes_raw`) is held still before the certificate is taken on the others' moves, so
  that it does not freeze its neighbours;
* the committed move is ``V = P'' − P``, so a rollback ``P − V`` restores ``P`` exactly.

The energy comparison uses the exact :func:`~golden_model.fixed.measures.energy_raw`.
"""

from __future__ import annotations

import numpy as np

from ..guard import FLOOR_MIN_SHIFT, FLOOR_SHIFT, GUARD_LEVELS, node_levels
from .format import Overflow, SaturationCounter, requantize, shift_round
from .formats_set import FormatSet

__all__ = ["MOVE_WEIGHTS", "EDGE_WEIGHT", "ROUNDING_MARGIN", "proposal", "floor_min_shift", "floor_min_raw",
           "triangle_levels_raw", "stuck_nodes_raw", "guarded_moves_raw", "taken_moves_raw", "commit"]

SAT = Overflow.SATURATE

#: The margin's weight on each corner's ``|V'|₁`` (corner a's move also moves both edges the margin measures).
MOVE_WEIGHTS = (4, 2, 2)
#: The margin's weight on the edges' ``|P_b − P_a|₁ + |P_c − P_a|₁``, and its constant part [lsb²].
EDGE_WEIGHT, ROUNDING_MARGIN = 2, 8


def proposal(fs: FormatSet, velocities: np.ndarray, force: np.ndarray, weights: np.ndarray, beta: int, shift: int,
             counter: SaturationCounter | None = None, coarse: np.ndarray | None = None) -> np.ndarray:
    """``(V, 2)`` the guarded momentum step's proposal [velocity]::

        a  = rq(F·w → accel)                              w [inv_mass]
        a  = sat(a + coarse → accel)                      with the coarse move [accel] (golden_model.fixed.coarse)
        a' = rq(a · 2^-shift → accel)                     the step scale
        V' = rq(β·V + a' → velocity)                      β [dt]; one rounding for both terms
    """
    rnd = fs.rounding
    accel = requantize(force * weights[:, None], fs.force_acc.frac_bits + fs.inv_mass.frac_bits,
                       fs.accel, rnd, SAT, counter, "accel")
    if coarse is not None:
        accel = requantize(accel + coarse, fs.accel.frac_bits, fs.accel, rnd, SAT, counter, "accel")
    if shift:
        accel = shift_round(accel, shift, rnd)
    fv = fs.dt.frac_bits + fs.velocity.frac_bits
    fa = fs.accel.frac_bits
    step_frac = max(fv, fa)
    step = (beta * velocities << (step_frac - fv)) + (accel << (step_frac - fa))
    return requantize(step, step_frac, fs.velocity, rnd, SAT, counter, "velocity")


def floor_min_shift(fs: FormatSet) -> int:
    """The left shift (negative: a right shift, rounded half up) from a host area [face_area] to
    ``X*·2^-FLOOR_MIN_SHIFT`` at the certificate's fraction bits (``X* = 2A``; twice face_edge's)."""
    return 2 * fs.face_edge.frac_bits + 1 - FLOOR_MIN_SHIFT - fs.face_area.frac_bits


def floor_min_raw(fs: FormatSet, face_areas: np.ndarray) -> np.ndarray:
    """``(F,)`` ``X*·2^-FLOOR_MIN_SHIFT`` at the certificate's fraction bits (twice face_edge's), from the
    host's areas ``A`` [face_area] (``X* = 2A``), rounded half up."""
    return shift_round(np.asarray(face_areas, dtype=np.int64), -floor_min_shift(fs), "half_up")


def _narrow(fs: FormatSet, diff: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``diff`` [position] narrowed to face_edge, and where it did not fit (not counted: such a
    triangle is only held still, which is exact)."""
    fmt = fs.face_edge
    return np.clip(diff, fmt.raw_min, fmt.raw_max), (diff < fmt.raw_min) | (diff > fmt.raw_max)


def _terms_raw(fs: FormatSet, positions: np.ndarray, moves: np.ndarray, faces: np.ndarray, winding: float,
               floor_min: np.ndarray) -> tuple:
    """Per triangle ``X0``, ``L_a, L_b, L_c``, ``Q_ab, Q_bc, Q_ca`` [lsb²], the floor without the margin, the
    margin's part from the edges (``2·(|P_b − P_a|₁ + |P_c − P_a|₁) + 8``), each corner's ``|V'|₁`` and whether
    an edge does not fit face_edge (never trusted)."""
    sigma = int(winding)
    corner = [positions[faces[:, k]] for k in range(3)]
    move = [moves[faces[:, k]] for k in range(3)]
    ab, wide_ab = _narrow(fs, corner[1] - corner[0])
    ac, wide_ac = _narrow(fs, corner[2] - corner[0])
    wide = (wide_ab | wide_ac).any(axis=1)
    opposite = []
    for k in range(3):
        edge, too_wide = _narrow(fs, corner[(k + 1) % 3] - corner[(k + 2) % 3])
        opposite.append(edge)
        wide |= too_wide.any(axis=1)

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return sigma * (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])

    def norm1(u: np.ndarray) -> np.ndarray:
        return np.abs(u[:, 0]) + np.abs(u[:, 1])

    x0 = cross(ab, ac)
    linear = [cross(move[k], opposite[k]) for k in range(3)]
    pair = [cross(move[k], move[(k + 1) % 3]) for k in range(3)]
    edge_margin = EDGE_WEIGHT * (norm1(ab) + norm1(ac)) + ROUNDING_MARGIN
    floor = np.minimum(x0, np.maximum(x0 >> FLOOR_SHIFT, floor_min))
    return x0, linear, pair, floor, edge_margin, [norm1(m) for m in move], wide


def triangle_levels_raw(fs: FormatSet, positions: np.ndarray, moves: np.ndarray, faces: np.ndarray, winding: float,
                        floor_min: np.ndarray) -> np.ndarray:
    """``(F,)`` the smallest ``r`` in 0 … GUARD_LEVELS whose certificate holds with the rounding margin,
    else ``GUARD_LEVELS + 1`` (as :func:`golden_model.guard.triangle_levels`)."""
    x0, linear, pair, floor, edge_margin, move_norm, wide = _terms_raw(fs, positions, moves, faces, winding, floor_min)
    floor = floor + edge_margin + sum(w * n for w, n in zip(MOVE_WEIGHTS, move_norm))
    subset_linear = [linear[0], linear[1], linear[2], linear[0] + linear[1], linear[1] + linear[2],
                     linear[2] + linear[0], linear[0] + linear[1] + linear[2]]
    zero = np.zeros_like(x0)
    subset_pair = [zero, zero, zero, pair[0], pair[1], pair[2], pair[0] + pair[1] + pair[2]]
    level = np.full(len(faces), GUARD_LEVELS + 1, dtype=np.int64)
    for r in range(GUARD_LEVELS, -1, -1):
        safe = ~wide
        for lin, quad in zip(subset_linear, subset_pair):
            safe &= x0 + (lin >> r) + (quad >> (2 * r)) >= floor
        level[safe] = r
    return level


def stuck_nodes_raw(fs: FormatSet, positions: np.ndarray, moves: np.ndarray, faces: np.ndarray, winding: float,
                    floor_min: np.ndarray) -> np.ndarray:
    """``(V,)`` bool: the nodes whose own move, alone, fails the certificate of one of their triangles at the
    smallest fraction ``2^-GUARD_LEVELS`` (as :func:`golden_model.guard.stuck_nodes`, with the margin of that
    corner's move alone). Such a node cannot move; holding it still first keeps it from freezing its
    neighbours. A triangle whose edges do not fit face_edge is never trusted: its corners are stuck. Only a
    choice of which proposals to zero: the certificate that follows keeps the guarantee."""
    x0, linear, _, floor, edge_margin, move_norm, wide = _terms_raw(fs, positions, moves, faces, winding, floor_min)
    stuck = np.zeros(len(positions), dtype=bool)
    for k in range(3):
        fails = wide | (x0 + (linear[k] >> GUARD_LEVELS) < floor + edge_margin + MOVE_WEIGHTS[k] * move_norm[k])
        stuck[faces[fails, k]] = True
    return stuck


def guarded_moves_raw(fs: FormatSet, positions: np.ndarray, moves: np.ndarray, faces: np.ndarray, winding: float,
                      floor_min: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(moves (V, 2) [velocity], node levels (V,))``: each node's proposal ``>> level``; 0 past
    GUARD_LEVELS, and 0 (level ``GUARD_LEVELS + 1``) for the :func:`stuck_nodes_raw` and where the move
    would leave the position range. Two rounds, as in float: the stuck nodes' proposals are set to 0, then
    every triangle's certificate is taken on the rest."""
    stuck = stuck_nodes_raw(fs, positions, moves, faces, winding, floor_min)
    free = np.where(stuck[:, None], 0, moves)
    face_level = triangle_levels_raw(fs, positions, free, faces, winding, floor_min)
    level = node_levels(face_level, faces, len(positions))
    level[stuck] = GUARD_LEVELS + 1
    return taken_moves_raw(fs, positions, free, level)


def taken_moves_raw(fs: FormatSet, positions: np.ndarray, moves: np.ndarray, level: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``(moves (V, 2) [velocity], node levels (V,))`` from the nodes' levels (0 … GUARD_LEVELS + 1): each
    proposal [velocity] ``>> level`` (an arithmetic shift), 0 past GUARD_LEVELS; a node whose move would
    leave the position range (either coordinate) does not move, its level ``GUARD_LEVELS + 1``. The last
    step of :func:`guarded_moves_raw`."""
    level = np.array(level, dtype=np.int64)
    taken = moves >> np.minimum(level, GUARD_LEVELS)[:, None]
    target = positions + taken
    outside = ((target < fs.position.raw_min) | (target > fs.position.raw_max)).any(axis=1)
    level[outside] = GUARD_LEVELS + 1
    taken[level > GUARD_LEVELS] = 0
    return taken, level


def commit(positions: np.ndarray, moves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P'', V'')``: ``P'' = P + D`` [position] (in range: :func:`guarded_moves_raw` holds a node still
    otherwise) and the move taken, ``V'' = D``, which a rollback subtracts."""
    return positions + moves, moves
