"""The per-node update pipeline, bit for bit as the hardware computes it.

``docs/fixed-point.md`` lists the same operations as a table; the RTL
(``hdl/``) follows that page stage by stage.  Every value is a numpy int64
*raw* integer in the :class:`~golden_model.fixed.formats_set.FormatSet`
format named in brackets; ``rq(x, F → fmt)`` is :func:`requantize` from ``F``
fraction bits with ``fs.rounding`` and saturation (each clamped element
counted under the signal's name).  Products are exact before ``rq``.

Per neighbour entry ``(j, d)`` of node ``i`` (``jacobi``: all from the
positions at the start of the iteration)::

    D   = P_j − P_i                         exact, position fraction bits
    Δ   = rq(D → delta)                                       [delta]
    S   = rq(Δx² + Δy² → length_sq)                           [length_sq]
    r   = rsqrt(S)                          the rsqrt unit    [rsqrt]
    u   = rq(1 − d·r → spring)              1 exact at d·r's fraction bits
    s   = rq(½C · u → spring)               ½C a constant in [spring]
    f   = rq(s·Δ → force)                   per component     [force]
    L   = rq(S·r → rest_length)             |Δ| = |Δ|²/|Δ|    [length]
    e   = |L − d|                           exact             [rest_length]

Per node, after its last neighbour::

    F   = rq(Σ f → force_acc)               exact sum in an accumulator with
                                            ceil(log2(max_degree)) guard bits
    Σe  = rq(Σ e → error_acc)               likewise
    a   = rq(F · (1/m) → accel)
    P'  = sat(P + rq(Δt·V + ½Δt²·a → position))   one rounding for both terms
    V'  = sat(V + rq(Δt·a → velocity))
    V'' = rq(V' · (1 − γ) → velocity)       exact when γ = 0

The guard bits make the sums order-independent (the hardware saturates once,
when the node leaves the accumulator), so the model may sum with numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .format import Format, Overflow, SaturationCounter, requantize
from .formats_set import FormatSet, accumulator_guard_bits
from .rsqrt import rsqrt_with_config

__all__ = ["BarrierEntries", "NeighbourStream", "NodeConstants", "NodeTerms", "NodeUpdate",
           "accumulator_guard_bits", "per_node_sums", "integrate", "integrate_momentum", "barrier_terms", "node_power",
           "edge_terms", "neighbour_terms", "node_terms", "node_update"]

SAT = Overflow.SATURATE


@dataclass(frozen=True, eq=False)
class BarrierEntries:
    """The fold barrier's part of each neighbour entry (raw).

    Entry ``k`` of node ``i`` carries at most one of the node's triangles,
    ``(i, j_k, second_k)`` wound so that its doubled area ``X`` is positive in
    a fold-free pattern.

    Attributes:
        second: ``(N,)`` the triangle's third node (any node where ``gain`` is 0).
        threshold: ``(N,)`` ``κ·X*`` [area], ``X*`` the doubled 3D area.
        gain: ``(N,)`` ``G = μ·C/(4·X*)`` [barrier_gain]; 0 for an entry without a triangle.
    """

    second: np.ndarray
    threshold: np.ndarray
    gain: np.ndarray


@dataclass(frozen=True, eq=False)
class NeighbourStream:
    """The static part of the input stream: CSR neighbour lists and node constants.

    Attributes:
        indptr: ``(V+1,)`` node ``i``'s entries are ``indptr[i]:indptr[i+1]``.
        neighbour: ``(N,)`` neighbour node index of each entry.
        rest: ``(N,)`` raw rest length ``d`` of each entry [rest_length].
        inv_mass: ``(V,)`` raw ``1/m`` [inv_mass] (the momentum dynamics: ``w_i``).
        barrier: the fold barrier's entry data, or ``None`` (no barrier).
        inv_mass_barrier: ``(V,)`` raw weight [inv_mass] of a node while one of its triangles is
            inside the barrier (the momentum dynamics' smaller, barrier-stable ``w_i``);
            ``None``: ``inv_mass`` throughout.
    """

    indptr: np.ndarray
    neighbour: np.ndarray
    rest: np.ndarray
    inv_mass: np.ndarray
    barrier: BarrierEntries | None = None
    inv_mass_barrier: np.ndarray | None = None

    @property
    def header_inv_mass_barrier(self) -> np.ndarray:
        """``(V,)`` the header's second weight: :attr:`inv_mass_barrier`, or :attr:`inv_mass`."""
        return self.inv_mass if self.inv_mass_barrier is None else self.inv_mass_barrier

    def node_weights(self, barrier_active: np.ndarray | None) -> np.ndarray:
        """``(V,)`` the weights the tail multiplies by: the barrier weight where ``barrier_active``."""
        if barrier_active is None:
            return self.inv_mass
        return np.where(barrier_active, self.header_inv_mass_barrier, self.inv_mass)

    @property
    def owner(self) -> np.ndarray:
        """``(N,)`` the node each entry belongs to."""
        return np.repeat(np.arange(len(self.indptr) - 1), np.diff(self.indptr))

    @property
    def max_degree(self) -> int:
        return int(np.diff(self.indptr).max())

    @cached_property
    def edge_entries(self) -> tuple[np.ndarray, np.ndarray] | None:
        """For each undirected edge ``(a < b)``: the entry ``a → b`` and the entry ``b → a``.

        ``None`` when the lists are not those of an undirected graph (a
        synthetic stream), which then takes the per-entry path.
        """
        owner = self.owner
        forward = np.flatnonzero(owner < self.neighbour)
        backward_all = np.flatnonzero(owner > self.neighbour)
        if len(forward) != len(backward_all) or len(forward) * 2 != len(owner):
            return None
        key_f = owner[forward] * len(self.indptr) + self.neighbour[forward]
        key_b = self.neighbour[backward_all] * len(self.indptr) + owner[backward_all]
        order_f, order_b = np.argsort(key_f), np.argsort(key_b)
        if not np.array_equal(key_f[order_f], key_b[order_b]) or \
                not np.array_equal(self.rest[forward[order_f]], self.rest[backward_all[order_b]]):
            return None
        backward = np.empty_like(forward)
        backward[order_f] = backward_all[order_b]
        return forward, backward


@dataclass(frozen=True)
class NodeConstants:
    """The datapath's per-iteration inputs (raw).

    Attributes:
        dt: ``Δt`` [dt].
        half_dt_sq: ``½Δt²`` [half_dt_sq].
        half_spring: ``½C`` [spring].
        damping: ``1 − γ`` [damping].
    """

    dt: int
    half_dt_sq: int
    half_spring: int
    damping: int


@dataclass(frozen=True, eq=False)
class NodeUpdate:
    """Outputs of one pass over all nodes (raw)."""

    positions: np.ndarray  # (V, 2) [position]
    velocities: np.ndarray  # (V, 2) [velocity]
    error_sums: np.ndarray  # (V,) Σ|L − d| per node [error_acc]
    power: np.ndarray  # (V,) F·V of the input state [power]


def neighbour_terms(fs: FormatSet, positions: np.ndarray, stream: NeighbourStream,
                    half_spring: int, counter: SaturationCounter | None = None,
                    entries: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-entry force ``f`` ``(N, 2)`` [force] and ``|L − d|`` ``(N,)`` [rest_length].

    The definition: every entry computed on its own, as the datapath does.
    ``entries`` restricts it to some entries (default all).
    """
    owner, neighbour, rest = stream.owner, stream.neighbour, stream.rest
    if entries is not None:
        owner, neighbour, rest = owner[entries], neighbour[entries], rest[entries]
    delta = _narrow(fs, positions[neighbour] - positions[owner], counter)
    spring, error = _spring_terms(fs, delta, rest, half_spring, counter)
    return _force(fs, spring, delta, counter), error


def _narrow(fs: FormatSet, diff: np.ndarray, counter: SaturationCounter | None) -> np.ndarray:
    return requantize(diff, fs.position.frac_bits, fs.delta, fs.rounding, SAT, counter, "delta")


def _spring_terms(fs: FormatSet, delta: np.ndarray, rest: np.ndarray, half_spring: int,
                  counter: SaturationCounter | None) -> tuple[np.ndarray, np.ndarray]:
    """``s`` [spring] and ``|L − d|`` [rest_length] of each entry from its ``Δ``."""
    rnd = fs.rounding
    square = delta[:, 0] * delta[:, 0] + delta[:, 1] * delta[:, 1]
    length_sq = requantize(square, 2 * fs.delta.frac_bits, fs.length_sq, rnd, SAT, counter, "length_sq")
    r = rsqrt_with_config(length_sq, fs.rsqrt_config(), counter, "rsqrt")
    dr_frac = fs.rest_length.frac_bits + fs.rsqrt.frac_bits
    u = requantize((1 << dr_frac) - rest * r, dr_frac, fs.spring, rnd, SAT, counter, "one_minus_dr")
    spring = requantize(half_spring * u, 2 * fs.spring.frac_bits, fs.spring, rnd, SAT, counter, "spring")
    length = requantize(length_sq * r, fs.length_sq.frac_bits + fs.rsqrt.frac_bits, fs.rest_length, rnd, SAT,
                        counter, "length")
    return spring, np.abs(length - rest)


def _force(fs: FormatSet, spring: np.ndarray, delta: np.ndarray, counter: SaturationCounter | None) -> np.ndarray:
    return _round_force(fs, spring[:, None] * delta, counter)


def _round_force(fs: FormatSet, product: np.ndarray, counter: SaturationCounter | None) -> np.ndarray:
    """``f = rq(s·Δ → force)`` from the exact product."""
    return requantize(product, fs.spring.frac_bits + fs.delta.frac_bits, fs.force, fs.rounding, SAT, counter,
                      "force")


def edge_terms(fs: FormatSet, positions: np.ndarray, stream: NeighbourStream, half_spring: int,
               counter: SaturationCounter | None = None) -> tuple[np.ndarray, ...]:
    """:func:`neighbour_terms` arranged by undirected edge: same values, same counts, faster.

    Returns ``(force_forward, force_backward, error_forward, error_backward)``
    for the entries listed by :attr:`NeighbourStream.edge_entries`.  The two
    entries of an edge see ``Δ`` and ``−Δ``.  Where narrowing keeps that
    symmetry (it breaks only at rounding ties and saturation), ``|Δ|²``, ``r``,
    ``s`` and ``|L − d|`` are equal for both and computed once; the forces are
    rounded per direction.  The other edges take the per-entry path.
    """
    forward, backward = stream.edge_entries
    a, b = stream.neighbour[backward], stream.neighbour[forward]
    rest = stream.rest[forward]
    diff = positions[b] - positions[a]
    delta_f = _narrow(fs, diff, counter)
    if fs.position.frac_bits == fs.delta.frac_bits and -fs.delta.raw_max <= delta_f.min() \
            and delta_f.max() < fs.delta.raw_max:
        # narrowing only saturates, and nothing came near the range: −Δ is exactly the other entry's Δ
        delta_b, asym = -delta_f, np.empty(0, dtype=np.int64)
    else:
        delta_b = _narrow(fs, -diff, counter)
        asym = np.flatnonzero(np.any(delta_b != -delta_f, axis=1))

    once = SaturationCounter()
    if len(asym) == 0:
        spring, error = _spring_terms(fs, delta_f, rest, half_spring, once)
        product = spring[:, None] * delta_f
        force_f = _round_force(fs, product, counter)
        force_b = _round_force(fs, -product, counter)
        error_f = error_b = error
    else:
        sym = np.flatnonzero(np.all(delta_b == -delta_f, axis=1))
        force_f, force_b = np.empty_like(delta_f), np.empty_like(delta_b)
        error_f, error_b = np.empty(len(rest), dtype=np.int64), np.empty(len(rest), dtype=np.int64)
        spring, error = _spring_terms(fs, delta_f[sym], rest[sym], half_spring, once)
        force_f[sym] = _force(fs, spring, delta_f[sym], counter)
        force_b[sym] = _force(fs, spring, delta_b[sym], counter)
        error_f[sym] = error
        error_b[sym] = error
        pair = np.concatenate([delta_f[asym], delta_b[asym]])
        spring, error = _spring_terms(fs, pair, np.concatenate([rest[asym], rest[asym]]), half_spring, counter)
        force = _force(fs, spring, pair, counter)
        n = len(asym)
        force_f[asym], force_b[asym] = force[:n], force[n:]
        error_f[asym], error_b[asym] = error[:n], error[n:]
    if counter is not None:
        counter.merge(once).merge(once)  # the symmetric edges' events happen in both entries
    return force_f, force_b, error_f, error_b


@dataclass(frozen=True, eq=False)
class NodeTerms:
    """What the neighbour half of the pipeline (the force pass) produces per node (raw)."""

    force: np.ndarray  # (V, 2) Σ f [force_acc]
    error_sums: np.ndarray  # (V,) Σ|L − d| [error_acc]
    #: (V,) Σ over the node's entries of |L − d|² (raw [rest_length]², exact)
    error_squares: np.ndarray
    #: (V,) Σ over the node's entries of the barrier's ``c·h`` (raw [barrier_coeff]·[area], exact;
    #: zeros without a barrier): each triangle's barrier energy is ``2·c·h``, and each triangle is
    #: on three entries
    barrier_energies: np.ndarray
    #: (V,) bool: a triangle of the node is inside the barrier (``h > 0``); ``None`` without one
    barrier_active: np.ndarray | None = None

    @property
    def error_square_sum(self) -> int:
        """Σ over all entries of |L − d|² (raw², exact): the host's energy estimate."""
        return exact_sum(self.error_squares)

    @property
    def barrier_energy_sum(self) -> int:
        """Σ over all entries of ``c·h`` (raw, exact; 0 without a barrier)."""
        return exact_sum(self.barrier_energies)


def exact_sum(values: np.ndarray) -> int:
    """The exact integer sum of int64 ``values`` of up to 62 bits (in two 31-bit halves, so the
    int64 partial sums cannot wrap for fewer than 2**31 values)."""
    values = np.asarray(values, dtype=np.int64)
    return (int(np.sum(values >> 31)) << 31) + int(np.sum(values & ((1 << 31) - 1)))


def per_node_sums(values: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """``(V,)`` the exact int64 sum of each node's entries ``indptr[i]:indptr[i+1]`` of ``values`` (N,).

    Prefix sums in int64 wrap modulo 2**64 and the differences of two of them are taken modulo
    2**64 as well, so each node's sum is exact whenever it fits int64 (the prefix sums need not).
    Nodes without entries sum to 0.
    """
    prefix = np.concatenate([[0], np.cumsum(np.asarray(values, dtype=np.int64))])
    return prefix[indptr[1:]] - prefix[indptr[:-1]]


def barrier_terms(fs: FormatSet, positions: np.ndarray, stream: NeighbourStream,
                  counter: SaturationCounter | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-entry barrier force ``(N, 2)`` [force] (zero rows where the gain is 0), ``(N,)``
    whether the entry's triangle is inside the barrier (``h > 0``; never on an entry without one),
    and ``(N,)`` ``c·h`` (raw, exact: half the triangle's barrier energy ``½μC·X*·(κ − X/X*)²₊``)::

        Δa  = rq(P_j − P_i → delta),  Δb = rq(P_second − P_i → delta)
        X   = rq(Δa.x·Δb.y − Δa.y·Δb.x → area)         doubled signed area
        h   = sat(max(T − X, 0) → area)                 shortfall below the threshold T
        c   = rq(G·h → barrier_coeff)
        D   = sat(Δa − Δb → delta)                      the opposite edge, P_j − P_second
        f_b = rq(c·(D.y, −D.x) → force)
    """
    barrier = stream.barrier
    rnd = fs.rounding
    owner = stream.owner
    here = positions[owner]
    delta_a = _narrow(fs, positions[stream.neighbour] - here, None)  # the spring's Δ: counted there
    delta_b = _narrow(fs, positions[barrier.second] - here, counter)
    cross = delta_a[:, 0] * delta_b[:, 1] - delta_a[:, 1] * delta_b[:, 0]
    area = requantize(cross, 2 * fs.delta.frac_bits, fs.area, rnd, SAT, counter, "area")
    short = requantize(np.maximum(barrier.threshold - area, 0), fs.area.frac_bits, fs.area, rnd, SAT, counter,
                       "area_short")
    coeff = requantize(barrier.gain * short, fs.barrier_gain.frac_bits + fs.area.frac_bits, fs.barrier_coeff, rnd,
                       SAT, counter, "barrier_coeff")
    diff = requantize(delta_a - delta_b, fs.delta.frac_bits, fs.delta, rnd, SAT, counter, "barrier_edge")
    product = coeff[:, None] * np.column_stack([diff[:, 1], -diff[:, 0]])
    return requantize(product, fs.barrier_coeff.frac_bits + fs.delta.frac_bits, fs.force, rnd, SAT, counter,
                      "barrier_force"), short > 0, coeff * short


def node_terms(fs: FormatSet, positions: np.ndarray, stream: NeighbourStream, half_spring: int,
               counter: SaturationCounter | None = None) -> NodeTerms:
    """Every node's accumulated force and error partial sum from the same positions.

    With a barrier, each entry's force is its spring term plus its barrier
    term, summed exactly (the accumulators have guard bits for both).
    """
    rnd = fs.rounding
    n = len(stream.indptr) - 1
    if stream.edge_entries is None:  # any stream: every entry on its own, summed per node
        force_entries, error_entries = neighbour_terms(fs, positions, stream, half_spring, counter)
        starts = stream.indptr[:-1]
        force = np.add.reduceat(force_entries, starts, axis=0)
        error = np.add.reduceat(error_entries, starts)
        squares = per_node_sums(error_entries * error_entries, stream.indptr)
    else:  # a mesh: each edge once for both of its entries
        forward, backward = stream.edge_entries
        a, b = stream.neighbour[backward], stream.neighbour[forward]
        force_f, force_b, error_f, error_b = edge_terms(fs, positions, stream, half_spring, counter)

        def per_node(forward_values: np.ndarray, backward_values: np.ndarray) -> np.ndarray:
            # each value back in its entry's place (entry forward[k] belongs to node a[k], backward[k] to b[k]),
            # then every node's entries summed in int64: exact, as the accumulators are
            # (FormatSet.accumulators() fit 63 bits), whatever the widths
            values = np.empty(len(stream.neighbour), dtype=np.int64)
            values[forward], values[backward] = forward_values, backward_values
            return per_node_sums(values, stream.indptr)

        force = np.column_stack([per_node(force_f[:, 0], force_b[:, 0]), per_node(force_f[:, 1], force_b[:, 1])])
        error = per_node(error_f, error_b)
        squares = per_node(error_f * error_f, error_b * error_b)
    active, barrier_energies = None, np.zeros(n, dtype=np.int64)
    if stream.barrier is not None:
        barrier, inside, energy = barrier_terms(fs, positions, stream, counter)
        barrier_energies = per_node_sums(energy, stream.indptr)
        force = force + np.column_stack([per_node_sums(barrier[:, 0], stream.indptr),
                                         per_node_sums(barrier[:, 1], stream.indptr)])
        active = np.bincount(stream.owner, inside, n) > 0
    force_acc = requantize(force, fs.force.frac_bits, fs.force_acc, rnd, SAT, counter, "force_acc")
    error_sums = requantize(error, fs.rest_length.frac_bits, fs.error_acc, rnd, SAT, counter, "error_acc")
    return NodeTerms(force_acc, error_sums, squares, barrier_energies, active)


def integrate(fs: FormatSet, positions: np.ndarray, velocities: np.ndarray, force: np.ndarray,
              inv_mass: np.ndarray, constants: NodeConstants,
              counter: SaturationCounter | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The node half of the pipeline: ``a = F/m`` and the Euler step with damping."""
    rnd = fs.rounding
    accel = requantize(force * inv_mass[:, None], fs.force_acc.frac_bits + fs.inv_mass.frac_bits,
                       fs.accel, rnd, SAT, counter, "accel")
    # Δt·V and ½Δt²·a aligned to the finer of their fraction bits, summed, rounded once.
    fv = fs.dt.frac_bits + fs.velocity.frac_bits
    fa = fs.half_dt_sq.frac_bits + fs.accel.frac_bits
    step_frac = max(fv, fa)
    step = (constants.dt * velocities << (step_frac - fv)) + (constants.half_dt_sq * accel << (step_frac - fa))
    moved = positions + requantize(step, step_frac, _wide(fs.position), rnd, SAT, counter, "position_step")
    new_positions = requantize(moved, fs.position.frac_bits, fs.position, rnd, SAT, counter, "position")
    kick = requantize(constants.dt * accel, fs.dt.frac_bits + fs.accel.frac_bits, _wide(fs.velocity), rnd, SAT,
                      counter, "velocity_step")
    new_velocities = requantize(velocities + kick, fs.velocity.frac_bits, fs.velocity, rnd, SAT, counter, "velocity")
    new_velocities = requantize(new_velocities * constants.damping, fs.velocity.frac_bits + fs.damping.frac_bits,
                                fs.velocity, rnd, SAT, counter, "damping")
    return new_positions, new_velocities


def node_power(fs: FormatSet, force: np.ndarray, velocities: np.ndarray,
               counter: SaturationCounter | None = None) -> np.ndarray:
    """``(V,)`` each node's ``F·V`` [power] (the momentum restart's terms of ``S``)."""
    dot = force[:, 0] * velocities[:, 0] + force[:, 1] * velocities[:, 1]
    return requantize(dot, fs.force_acc.frac_bits + fs.velocity.frac_bits, fs.power, fs.rounding, SAT, counter,
                      "power")


def integrate_momentum(fs: FormatSet, positions: np.ndarray, velocities: np.ndarray, force: np.ndarray,
                       weights: np.ndarray, beta: int, counter: SaturationCounter | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The momentum dynamics' node half::

        a  = rq(F·w → accel)                       w = 2/(C·deg) [inv_mass]
        V' = rq(β·V + a → velocity)                β [dt]; one rounding for both terms
        P' = sat(P + V' → position)                velocity has position's fraction bits

    The datapath reuses the paper's products: ``Δt·V`` with ``β`` in the
    ``Δt`` port, and ``a`` in place of ``½Δt²·a``.
    """
    rnd = fs.rounding
    accel = requantize(force * weights[:, None], fs.force_acc.frac_bits + fs.inv_mass.frac_bits,
                       fs.accel, rnd, SAT, counter, "accel")
    fv = fs.dt.frac_bits + fs.velocity.frac_bits
    fa = fs.accel.frac_bits
    step_frac = max(fv, fa)
    step = (beta * velocities << (step_frac - fv)) + (accel << (step_frac - fa))
    new_velocities = requantize(step, step_frac, fs.velocity, rnd, SAT, counter, "velocity")
    new_positions = requantize(positions + new_velocities, fs.position.frac_bits, fs.position, rnd, SAT, counter,
                               "position")
    return new_positions, new_velocities


def node_update(fs: FormatSet, positions: np.ndarray, velocities: np.ndarray, stream: NeighbourStream,
                constants: NodeConstants, counter: SaturationCounter | None = None,
                momentum: bool = False) -> NodeUpdate:
    """One ``jacobi`` pass of the datapath: every node's update from the same positions.

    The error partial sums and the power describe the *input* state (they are
    formed from the same neighbour entries as the forces).  ``momentum``
    selects :func:`integrate_momentum` with ``β = constants.dt``.
    """
    terms = node_terms(fs, positions, stream, constants.half_spring, counter)
    n = len(stream.indptr) - 1  # positions may hold more rows: neighbours that are not updated
    weights = stream.node_weights(terms.barrier_active)
    if momentum:
        new_positions, new_velocities = integrate_momentum(fs, positions[:n], velocities[:n], terms.force,
                                                           weights, constants.dt, counter)
    else:
        new_positions, new_velocities = integrate(fs, positions[:n], velocities[:n], terms.force, weights,
                                                  constants, counter)
    power = node_power(fs, terms.force, velocities[:n], counter)
    return NodeUpdate(new_positions, new_velocities, terms.error_sums, power)


def _wide(fmt: Format) -> Format:
    """``fmt`` with one more integer bit: the adder input before the final saturation.

    The step term is held in this width and the sum with the old value is
    formed exactly and saturated once; a step that does not fit the wide
    format saturates too (counted separately).
    """
    return Format(fmt.signed, fmt.int_bits + 1, fmt.frac_bits)
