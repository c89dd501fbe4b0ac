"""The step guard's commit of one node, or its rollback: the move a node takes at its level, kept in the
position range.

The RTL twin of the tail of :func:`golden_model.fixed.guard.guarded_moves_raw` (from the node's level
on) and of :func:`~golden_model.fixed.guard.commit`; a rolled-back step's ``P − V``, ``V = 0`` as
:meth:`golden_model.fixed.controller.Controller._advance_guarded` restores it. The engine's guarded mode
is to run it in its commit and rollback passes over the nodes (``docs/engine-guard.md``).
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.guard import GUARD_LEVELS

from .fixedpoint import FormatSetNotBuildable, clamp
from .force_pass import format_set
from .layouts import commit_input_layout, commit_output_layout
from .pipeline import LiveValues, Pipeline, count_stages

__all__ = ["GuardCommit"]


class GuardCommit(wiring.Component):
    """One node's guarded commit or rollback, bit-exact with the golden model::

        commit (rollback = 0):  level = max(levels);  level = GUARD_LEVELS + 1 if stuck
                                D = V' >> level (arithmetic), 0 if level > GUARD_LEVELS
                                if P + D leaves the position range (either coordinate): D = 0, level = GUARD_LEVELS + 1
                                position = P + D, velocity = D
        rollback (rollback = 1): position = P − V, velocity = 0, level = 0

    A rollback's ``P − V`` is exact: the golden model's commit keeps ``P + V`` in range, so ``P − V`` is the
    position before it. A velocity memory holding a move no commit wrote could take it out of range; the
    unit then neither wraps nor clamps: it keeps ``P``.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        The position and velocity formats (same fraction bits: a move is added to a position).

    Members
    -------
    i : ``In(stream.Signature(commit_input_layout(fs), always_ready=True))``
        One node per beat: ``position`` P [position], ``velocity`` (the proposal V' [velocity], which the
        engine has already zeroed for a stuck node; for a rollback the committed move V), the node's
        three slot ``levels`` (:class:`~hdl.level_scatter.LevelScatter`'s, each 0 … GUARD_LEVELS + 1),
        ``stuck`` (the node is held still: level GUARD_LEVELS + 1) and ``rollback``. Always ready.
    o : ``Out(stream.Signature(commit_output_layout(fs), always_ready=True))``
        One beat per node, in input order: the new ``position`` and ``velocity``, the node's final
        ``level`` (GUARD_LEVELS + 1 where held or out of range; 0 after a rollback) for the guard's
        statistics. ``o.valid`` and the payload are registers; the consumer takes every beat.
    idle : ``Out(1)``
        No node in flight.

    Contract
    --------
    Throughput: one node per clock (II = 1), rollbacks and commits mixed freely. Latency: :attr:`latency`
    (5) clocks from a node's transfer on ``i`` to its result on ``o`` (the stages built, counted). No
    back-pressure.

    Structure
    ---------
    A free-running pipeline, one kind of work per stage: C1 the node's level (the largest of three,
    and whether it is held); C1b that level copied, with no logic, and ``−V``; C2 the move,
    ``V' >> level`` (a shifter of three mux levels) or ``−V`` or 0; C3 ``P + D`` (the position's carry
    chain); C4 the range test on the sum's top bits and the choice of the outputs (its flag fans out to
    every output bit: behind a carry chain it would be the stage's longest path).
    """

    def __init__(self, fs: FormatSet | str):
        fs = format_set(fs, "GuardCommit")
        if fs.velocity.frac_bits != fs.position.frac_bits:
            raise FormatSetNotBuildable(f"a move is added to a position: velocity {fs.velocity} needs position's "
                                        f"{fs.position.frac_bits} fraction bits")
        if not (fs.position.signed and fs.velocity.signed):
            raise FormatSetNotBuildable(f"position {fs.position} and velocity {fs.velocity} must be signed")
        if fs.velocity.width > fs.position.width:
            raise FormatSetNotBuildable(f"velocity {fs.velocity} is wider than position {fs.position}: a move could "
                                        f"step over the whole position range")
        self.fs = fs
        super().__init__(self.signature_of(fs))
        self.latency = count_stages(lambda m: _build(m, fs, self.signature_of(fs).create()))

    @staticmethod
    def signature_of(fs: FormatSet) -> wiring.Signature:
        """The component's signature (also the throwaway build's stand-in ports)."""
        return wiring.Signature({
            "i": In(stream.Signature(commit_input_layout(fs), always_ready=True)),
            "o": Out(stream.Signature(commit_output_layout(fs), always_ready=True)),
            "idle": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        stages = _build(m, self.fs, self)
        assert stages == self.latency, (stages, self.latency)
        return m


def _build(m: Module, fs: FormatSet, ports) -> int:
    """The commit's datapath into ``m`` (``ports``: the component's members); returns its stages."""
    held_level = GUARD_LEVELS + 1
    live = LiveValues()
    pipe = Pipeline(m, ports.i.valid)
    node = ports.i.payload
    levels = [node.levels[k] for k in range(3)]
    largest = levels[0]
    for level in levels[1:]:
        largest = Mux(level > largest, level, largest)
    held = node.stuck | Value.cast(largest > GUARD_LEVELS)
    # C1: the node's level and whether it is held, in registers placed by the compares (the level's
    # next consumer, the shifter, is wide and far: a route across ends in C1b's copies, not here)
    live.step(pipe, "c1", p_x=node.position.x, p_y=node.position.y, v_x=node.velocity.x, v_y=node.velocity.y,
              level=largest, held=held, rollback=node.rollback)
    # C1b: the level and held copied, with no logic, for the shifter; −V for a rollback (one more bit:
    # −raw_min)
    live.step(pipe, "c1b", neg_x=-live["v_x"], neg_y=-live["v_y"])
    # C2: D = V' >> level (the shift by a level past GUARD_LEVELS is never used: D = 0 there), or −V
    move = {k: Mux(live["rollback"], live[f"neg_{k}"], Mux(live["held"], 0, live[f"v_{k}"] >> live["level"]))
            for k in "xy"}
    live.step(pipe, "c2", drop=("v_x", "v_y", "neg_x", "neg_y", "held"),
              level=Mux(live["rollback"], 0, Mux(live["held"], held_level, live["level"])),
              **{f"d_{k}": move[k] for k in "xy"})
    # C3: P + D, one bit wider than position: its top two bits tell whether it left the range
    live.step(pipe, "c3", **{f"s_{k}": live[f"p_{k}"] + live[f"d_{k}"] for k in "xy"})
    # C4: out of range (either coordinate): the node stays at P with no move
    outside = clamp(live["s_x"], fs.position)[1] | clamp(live["s_y"], fs.position)[1]
    rollback = live["rollback"]
    live.step(pipe, "c4", drop=("s_x", "s_y", "d_x", "d_y", "p_x", "p_y", "rollback"),
              **{f"out_p_{k}": Mux(outside, live[f"p_{k}"], live[f"s_{k}"][:fs.position.width].as_signed())
                 for k in "xy"},
              **{f"out_v_{k}": Mux(outside | rollback, 0, live[f"d_{k}"][:fs.velocity.width].as_signed())
                 for k in "xy"},
              level=Mux(outside & ~rollback, held_level, live["level"]))

    out = ports.o.payload
    m.d.comb += [ports.o.valid.eq(pipe.valid),
                 out.position.x.eq(live["out_p_x"]), out.position.y.eq(live["out_p_y"]),
                 out.velocity.x.eq(live["out_v_x"]), out.velocity.y.eq(live["out_v_y"]),
                 out.level.eq(live["level"])]
    in_flight = Signal(range(pipe.stages + 2), name="nodes_in_flight")
    m.d.sync += in_flight.eq(in_flight + ports.i.valid - ports.o.valid)
    m.d.comb += ports.idle.eq(in_flight == 0)
    return pipe.stages
