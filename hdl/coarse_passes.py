"""The coarse space in the engine: its sums pass over the nodes, its coefficients, and each node's coarse move
joined to the node on its way into the integrator.

The RTL twin of :func:`golden_model.fixed.coarse.coarse_accel` as ``SpringflatEngine`` runs it, in the iterations
whose step takes the coarse move (:class:`~hdl.guard_decision.GuardDecision`'s ``coarse_step``): a node pass
(the ``coarse`` phase, :class:`~hdl.phase_controller.PhaseController`) reads each node's basis word and force,
:class:`~hdl.coarse_node.CoarseNode` sums ``ΦᵀF``, and :class:`~hdl.coarse_coefficients.CoarseCoefficients`
forms ``c`` and the move's shift from the sums and the matrix memory; the integrate pass then passes each node
through :class:`~hdl.coarse_node.CoarseNode` again for its move.
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.coarse import basis_exponents
from golden_model.engine_spec.image import EngineCapacity, basis_field_names, basis_word_layout
from golden_model.fixed import FormatSet
from golden_model.fixed.coarse import MATRIX_EXPONENT_BITS, SUM_BITS

from .coarse_coefficients import CoarseCoefficients
from .coarse_node import CoarseNode
from .layouts import force_word_layout, integrator_input_layout, word_layout
from .parameters import check_int

__all__ = ["CoarsePasses"]


class CoarsePasses(wiring.Component):
    """The coarse space's passes: the sums pass and the coefficients in the ``coarse`` phase, the moves joined to
    the integrate pass's nodes.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
    capacity : :class:`~golden_model.engine_spec.image.EngineCapacity`
        Its ``coarse_degree`` (at least 1) and ``vertices``.
    read_latency : int
        Clocks from ``matrix_addr`` to its entry on ``matrix_data``: in the engine the memories' address register
        and :attr:`MemoryWindows.read_latency <hdl.memory_windows.MemoryWindows>`.

    Members
    -------
    node_in : ``In(stream.Signature(integrator_input_layout(fs), always_ready=True))``
        The integrate pass's nodes (:class:`~hdl.pass_sequencer.PassSequencer`'s ``node_out``).
    node_out : ``Out(stream.Signature(integrator_input_layout(fs, coarse=True), always_ready=True))``
        The same nodes :attr:`latency` clocks later, each with its coarse move (0 where ``coarse_step`` is low),
        into :class:`~hdl.integrator.Integrator` built with ``coarse``.
    basis, force_word : ``In``
        The landed node's basis word (the basis memory, :func:`~golden_model.engine_spec.image.basis_word_layout`)
        and force word, beside ``node_landed`` and ``node_in``'s beats.
    node_landed : ``In(1)``
        A node pass's node has landed (the sequencer's); in the ``coarse`` phase, one of the sums pass.
    in_coarse : ``In(1)``
        The controller's ``coarse`` phase: its first clock clears the sums, its node pass sums, and once
        ``vertices`` nodes have landed the coefficients are formed; ``done`` then rises. The phase's end
        makes the block ready for the next (an ABORT's too: a coefficient result under way is finished and
        dropped).
    coarse_step : ``In(1)``
        The integrate pass's step takes the coarse move (steady through the pass).
    vertices : ``In``
        VERTICES (the nodes a sums pass counts).
    matrix_exponent : ``In(signed(MATRIX_EXPONENT_BITS))``
        MATRIX_EXPONENT (a run constant).
    matrix_addr : ``Out``, matrix_data : ``In(signed(SUM_BITS))``
        The matrix memory's read port (``read_latency``).
    done : ``Out(1)``
        In the ``coarse`` phase: the coefficients are in (a register).
    idle : ``Out(1)``
        No node in the unit or the delay line, the coefficient unit idle.
    coarse_force_events, coarse_move_events : ``Out``
        A node's saturation events: its force's narrowing in the sums pass (``coarse_force``), its move's clamp
        in an integrate pass that takes the move (``coarse_move``; none in one that does not).

    Contract
    --------
    The integrate pass's nodes take :attr:`latency` clocks more (the node unit's); a sums pass takes its node
    pass, the unit's latency and a clock, then :attr:`CoarseCoefficients.cycles
    <hdl.coarse_coefficients.CoarseCoefficients>` (and a clock to take its result).
    """

    def __init__(self, fs: FormatSet, capacity: EngineCapacity, *, read_latency: int):
        if not isinstance(fs, FormatSet) or not isinstance(capacity, EngineCapacity):
            raise TypeError(f"CoarsePasses needs a FormatSet and an EngineCapacity, not {fs!r}, {capacity!r}")
        if not capacity.coarse_degree:
            raise ValueError("CoarsePasses needs a capacity with a coarse space (coarse_degree > 0)")
        check_int("read_latency", read_latency)
        self.fs, self.capacity = fs, capacity
        self.node = CoarseNode(fs, capacity.coarse_degree, capacity.vertices, basis_input=True)
        self.coefficients = CoarseCoefficients(fs, capacity.coarse_degree, capacity.vertices,
                                               read_latency=read_latency)
        #: Clocks a node of the integrate pass takes more: the node unit's latency.
        self.latency = self.node.latency
        events = self.node.o.payload.saturations.shape()  # (a node's events, the unit's)
        #: Width of each saturation-event output.
        self.event_widths = {"coarse_force": events.width, "coarse_move": events.width}
        functions = len(basis_exponents(capacity.coarse_degree))
        super().__init__({
            "node_in": In(stream.Signature(integrator_input_layout(fs), always_ready=True)),
            "node_out": Out(stream.Signature(integrator_input_layout(fs, coarse=True), always_ready=True)),
            "basis": In(word_layout(basis_word_layout(capacity))),
            "force_word": In(force_word_layout(fs)),
            "node_landed": In(1), "in_coarse": In(1), "coarse_step": In(1),
            "vertices": In(range(capacity.vertices + 1)),
            "matrix_exponent": In(signed(MATRIX_EXPONENT_BITS)),
            "matrix_addr": Out(range(functions * functions)), "matrix_data": In(signed(SUM_BITS)),
            "done": Out(1), "idle": Out(1), "coarse_force_events": Out(events), "coarse_move_events": Out(events),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.node = node = self.node
        m.submodules.coefficients = coefficients = self.coefficients
        basis = basis_field_names(self.capacity.coarse_degree)  # (the word's fields, from the second function)

        # the phase's first clock (the sums cleared), and the sums pass's nodes counted
        was_coarse = Signal(name="was_coarse")
        m.d.sync += was_coarse.eq(self.in_coarse)
        entering = self.in_coarse & ~was_coarse
        landed = Signal(range(self.capacity.vertices + 1), name="sums_landed")
        summing, settling = Signal(name="summing"), Signal(name="sums_settling")
        with m.If(entering):
            m.d.sync += [landed.eq(0), summing.eq(1)]
        with m.Elif(self.in_coarse & self.node_landed):
            m.d.sync += landed.eq(landed + 1)
        # the node unit: a sums pass in the coarse phase, a moves pass otherwise (the kind changes only while it
        # is idle: the sums pass's nodes are out before the phase ends, the integrate pass's in before it starts)
        m.d.comb += [
            node.clear.eq(entering), node.moves.eq(~self.in_coarse),
            node.i.valid.eq((self.in_coarse & self.node_landed) | self.node_in.valid),
            node.i.payload.force.eq(self.force_word.force),
            *(node.i.payload.phi[k].eq(getattr(self.basis, field)) for k, field in enumerate(basis)),
        ]
        # every node landed and out of the unit, its share in the sums a clock later: the coefficients
        all_landed = Signal(name="sums_all_landed")
        m.d.sync += all_landed.eq(summing & (landed == self.vertices) & ~entering)
        with m.If(all_landed & node.idle & ~settling):
            m.d.sync += [summing.eq(0), settling.eq(1)]
        with m.If(settling):
            m.d.sync += [settling.eq(0), coefficients.i.valid.eq(1)]
        with m.If(coefficients.i.valid & coefficients.i.ready):
            m.d.sync += coefficients.i.valid.eq(0)
        m.d.comb += [coefficients.i.payload.sums.eq(node.sums), coefficients.o.ready.eq(1),
                     coefficients.matrix_exponent.eq(self.matrix_exponent),
                     self.matrix_addr.eq(coefficients.matrix_addr), coefficients.matrix_data.eq(self.matrix_data)]
        held = Signal(node.coefficients.shape(), name="coefficients_held")
        shift = Signal.like(node.move_shift, name="move_shift_held")
        m.d.comb += [node.coefficients.eq(held), node.move_shift.eq(shift)]
        with m.If(coefficients.o.valid):
            m.d.sync += [held.eq(coefficients.o.payload.coefficients), shift.eq(coefficients.o.payload.move_shift),
                         self.done.eq(self.in_coarse)]
        with m.If(~self.in_coarse):  # the phase over (or aborted): ready for the next
            m.d.sync += [summing.eq(0), settling.eq(0), self.done.eq(0)]

        # the integrate pass: each node beside its move, the unit's latency later
        beat = self.node_in.payload
        delayed_valid, delayed = self.node_in.valid, beat
        for k in range(self.latency):
            valid_k = Signal(name=f"delay{k}_valid")
            beat_k = Signal.like(beat, name=f"delay{k}_node", reset_less=True)
            m.d.sync += [valid_k.eq(delayed_valid), beat_k.eq(delayed)]
            delayed_valid, delayed = valid_k, beat_k
        out = self.node_out.payload
        move = node.o.payload.move
        m.d.comb += [self.node_out.valid.eq(delayed_valid), out.node.eq(delayed.node), out.force.eq(delayed.force),
                     out.inside.eq(delayed.inside),
                     out.coarse.x.eq(Mux(self.coarse_step, move.x, 0)), out.coarse.y.eq(Mux(self.coarse_step, move.y, 0)),
                     self.coarse_force_events.eq(Mux(node.o.valid & ~node.moves, node.o.payload.saturations, 0)),
                     self.coarse_move_events.eq(Mux(node.o.valid & node.moves & self.coarse_step,
                                                    node.o.payload.saturations, 0))]
        in_delay = Signal(range(self.latency + 2), name="delay_count")
        m.d.sync += in_delay.eq(in_delay + self.node_in.valid - delayed_valid)
        # (the coefficient unit idle: no request and no result under way)
        solving = ~coefficients.i.ready | coefficients.i.valid | coefficients.o.valid
        m.d.comb += self.idle.eq(node.idle & (in_delay == 0) & ~solving & ~settling)
        return m
