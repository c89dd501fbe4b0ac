"""The engine's pass sequencer: each pass's fetch from the memories into its unit, one item per clock,
and the collection of the unit's per-node results (counts, exact sums, saturation events)."""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal, Value, signed
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import EngineCapacity, memory_layouts
from golden_model.engine_spec.register_map import RegisterMap

from .dsp import kept_register
from .fixedpoint import shape_of
from .force_pass import ForcePass
from .integrator import Integrator
from .layouts import (area_saturations_layout, force_entry_layout, force_word_layout,
                      integrator_input_layout, integrator_output_layout, node_force_layout, triangle_layout,
                      pass_sum_shapes, vector_layout, weight_word_layout, word_layout)
from .memory_windows import ENTRY_LATENCY, READ_LATENCY, node_write_layout, write_signature

__all__ = ["PassSequencer", "fetch_counter", "fetch_latencies"]

def fetch_latencies(read_latency: int, entry_latency: int = ENTRY_LATENCY) -> tuple[int, int, int]:
    """``(force, area, node)``: each pass's clocks from its first address to its unit's input, for node and
    triangle memories answering ``read_latency`` clocks after their address registers and the entry memory
    ``entry_latency`` clocks after its own. The force pass: the entry read, its position addresses
    registered, their read; the area pass: the triangle's read, its corners' addresses registered, their
    read; the integrate pass: the node's read."""
    return entry_latency + 1 + read_latency, read_latency + 1 + read_latency, read_latency


#: :func:`fetch_latencies` with the node memories' :data:`READ_LATENCY` (one bank each).
FORCE_FETCH_LATENCY, AREA_FETCH_LATENCY, NODE_FETCH_LATENCY = fetch_latencies(READ_LATENCY)

#: The counters and sums the sequencer restarts, each with the phase flag that restarts it (``in_start``: the
#: force and area passes', ``in_step``: the integrate pass's) and whether it is one of the run's sums (read by
#: the controller's units), which restart a clock after their phase.
RESTARTS = {
    "entry_index": ("in_start", False), "node_of_entry": ("in_start", False), "force_out_index": ("in_start", False),
    "length_sum": ("in_start", True), "square_sum": ("in_start", True), "barrier_sum": ("in_start", True),
    "tri_index": ("in_start", False),
    "node_index": ("in_step", False), "node_out_index": ("in_step", False), "power_sum": ("in_step", True),
}
RESTARTED = tuple(RESTARTS)
#: The passes' fetch counters (:func:`fetch_counter`), each with the mesh size it counts to.
FETCH_COUNTERS = {"entry_index": "entries", "tri_index": "triangles", "node_index": "vertices"}

#: The controller's pass enables, one per fetch counter (in :data:`FETCH_COUNTERS`' order).
FETCH_FLAGS = ("fetch_force", "fetch_area", "fetch_nodes")

#: The guard passes' restart pulses from the controller, each restarting one fetch counter.
RESTART_PULSES = {"tri_index": "triangle_restart", "node_index": "node_restart"}

#: The phase flags the sequencer reads (:class:`~hdl.phase_controller.PhaseController`).
PHASE_INPUTS = ("in_start", "in_force", "in_area", "in_step", "in_integrate")


def fetch_counter(m: Module, index: Signal, fetch, count, valid_prefix: str, stages: int,
                  left: Signal | None = None, valid_fetch=None, left_fetch=None) -> list[Signal]:
    """A pass's fetch: while ``fetch`` is high, ``index`` counts 0, 1, … up to ``count``, one issued
    per clock. Returns ``valid``: ``valid[k]`` marks the clock whose data belongs to an index issued
    ``k`` clocks ago (``valid[0]``: the index in the memories' address registers).

    ``left``: a signed down-counter that is ``count − 1 − index`` in every clock, restarted by the caller
    with ``index`` (to ``count − 1``; ``count`` stands still from a restart to the pass's end). The issue
    reads ``left``'s sign bit, a flip-flop (``left ≥ 0`` is ``index < count``; it stops at −1), so no
    compare lies on the route to the counter, which the placer puts by the block RAMs it addresses:
    ``left``'s decrement is a carry chain from its own flip-flops back into them.

    ``valid_fetch`` (``None``: ``fetch``): a flag equal to ``fetch`` in every clock, from which ``valid[0]``'s
    issue is formed, so that the counter's own issue, whose loads are the counter's clock enables, is a
    LUT of its own beside the counter, not one shared with the valid chain and placed between the two.

    ``left_fetch`` (``None``: ``fetch``): likewise, a flag equal to ``fetch`` from which ``left``'s issue is
    formed, so that the up-counter and the down-counter each have an issue LUT of their own, placed by
    it (the placer puts the two counters apart: the up-counter by the block RAMs it addresses)."""
    valid = [Signal(name=f"{valid_prefix}{k}_valid") for k in range(stages)]
    more = (index < count) if left is None else ~left[-1]
    issue = fetch & more
    m.d.sync += [valid[0].eq(issue if valid_fetch is None else valid_fetch & more),
                 *(valid[k].eq(valid[k - 1]) for k in range(1, stages))]
    with m.If(issue):
        m.d.sync += index.eq(index + 1)
        if left is not None and left_fetch is None:
            m.d.sync += left.eq(left - 1)
    if left is not None and left_fetch is not None:
        with m.If(left_fetch & more):
            m.d.sync += left.eq(left - 1)
    return valid


class PassSequencer(wiring.Component):
    """The force, area and integrate passes' fetch and collection.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
    register_map : :class:`~golden_model.engine_spec.register_map.RegisterMap`
        Its capacity sizes the counters, its values the mesh-size inputs.
    read_latency, entry_latency : int
        Clocks from a node or triangle memory's address register to its data, and from the entry memory's
        to the entry (:func:`fetch_latencies`; :attr:`MemoryWindows.entry_latency
        <hdl.memory_windows.MemoryWindows>`).
    down_counters : bool
        Each fetch counter's issue and end read the sign of a down-counter restarted and counted with it
        (:func:`fetch_counter`'s ``left``: no compare of the counter), which is loaded from a copy of the
        mesh size of its own (a clock late: run constants, written before START), so that the register
        bank's size registers, which the guard also reads, are not placed between the two; and its pass
        enable from a copy of its own, loaded from the controller's flag (a clock late) and cleared by the
        reset. The copy's input is then a route from a flip-flop, with no logic of the controller's in
        front of it, so the placer puts the copy, and the issue LUT that reads it, by the counter. The
        valid chain's issue reads a second such copy (:func:`fetch_counter`'s ``valid_fetch``) and the
        down-counter's a third (its ``left_fetch``), so that each counter's issue has no load but that
        counter. A pass then issues a clock after its enable
        rises, not in that clock, and the sequencer is the one without ``down_counters`` fed its enables a
        clock late, but for ``passes_idle``, which counts a pass as fetching from its enable's rise: a
        pass fetching but not issuing yet is never taken for idle. The guard's restart pulses are read
        from copies too (a clock late), so that the controller's pulses, set by the phase machine's
        decisions, have no load but their copies: a guard pass's counter restarts in its enable's second
        clock, and the pass issues in its third (a node pass a clock later than without
        ``down_counters``; a triangle pass, which issues every other clock, in the same clock), and the
        enable's rise counts as the restart for ``passes_idle``.

    Members
    -------
    fetch_force, fetch_area, fetch_nodes : ``In(1)``
        The controller's pass enables: while high, the pass issues one item per clock until its
        counter reaches the mesh size (``entries``, ``triangles``, ``vertices``).
    in_start, in_force, in_area, in_step, in_integrate, running, area_clear : ``In(1)``
        The controller's flags: the start phase restarts the force and area passes' counters and
        sums, the step phase the integrate pass's; the pass phases time the passes' ends.
    guarded, half_rate, node_restart, triangle_restart : ``In(1)``
        The guarded mode (the integrate pass proposes: its velocities go to ``proposal_write``, not to the
        node memories), a triangle issued every other clock (the guard's triangle passes, for the
        certificate's interval of 2), and the guard's passes' restarts of the node and triangle counters
        (a pulse in the clock their fetch flag rises, when the counter still stands at its end; the
        sequencer reads them a clock late with ``down_counters``).
    vertices, entries, triangles, momentum, barrier_held : ``In``
        Run constants (a momentum mode in MODE.mode gates S's saturation event; MODE.barrier's copy the barrier terms).
    entry, triangle, position[3], velocity, weight_word, force_word : ``In``
        The memories' read data (:class:`~hdl.memory_windows.MemoryWindows`).
    entry_index, tri_index, node_index, node_of_entry : ``Out``
        The addresses the passes read (the entry's node: the owner of the entry fetched).
    force_entry, triangle_out, node_out : ``Out`` streams
        Into ``ForcePass.i``, ``AreaError.i``, ``Integrator.i``.
    forces, integrated : ``In`` streams; area_saturations, force_idle, area_idle, integrator_idle : ``In``
        The units' results and state.
    force_out_index, node_out_index : ``Out``
        The node of the unit's next result.
    force_write, node_write, proposal_write : ``Out(write_signature(...))``
        The force pass's results into the force memory, the integrator's into the node memories (or its
        velocities, the proposals, into the proposal memory in the guarded mode).
    node_landed, triangle_landed, corners[3], landed_area : ``Out``
        For the guard's passes (:class:`~hdl.guard_passes.GuardPasses`): a node's, or a triangle's, data
        landed this clock (its memories' words: ``position``, ``velocity``, the proposals), with the
        triangle's corner indices and host area.
    force_done, area_done, integrate_done : ``Out(1)``
        A pass's end: one clock, registered, the clock after its last result.
    passes_idle : ``Out(1)``
        Registered: in the clock before, no pass had an item left to issue (its counter at its end
        two clocks before that) and no item was in a fetch or a unit.
    length_sum, square_sum, barrier_sum, power_sum : ``Out``
        The passes' exact sums (Σ|L − d|, Σe², Σc·h of the force pass; S of the integrate pass),
        still from a pass's end until the next pass restarts them.
    force_events, integrate_events, area_events, length_events, power_events : ``Out``
        Saturation events as the golden model counts them: per node (the force pass, the integrator
        while running), per area pass (at its end), the E_C sum's (at the force pass's end) and S's
        (at the integrate pass's end, momentum only); 0 when there is none.

    Latency
    -------
    Valid bits are named for the clock whose data they mark. The force pass
    (:data:`FORCE_FETCH_LATENCY`, nine clocks, with ``read_latency`` 2 and ``entry_latency`` 6): E0 the
    entry's address in the entry memory's address register; E6 the addressed entry
    (:data:`~hdl.memory_windows.ENTRY_LATENCY`: the block RAMs' pin registers, their read, the bank select
    in registered stages), its three position addresses formed; E7 those in the position memory's address
    registers; E8 its read data; E9 everything landed, into ``ForcePass.i``. The area pass
    (:data:`AREA_FETCH_LATENCY`): T0 the triangle's address, T1 the data, T2 landed (corner addresses
    formed), T3 registered, T4 the corners' data, T5 landed, into ``AreaError.i``. The integrate pass (:data:`NODE_FETCH_LATENCY`): N0 the node's
    address, N1 the data, N2 landed, into ``Integrator.i``. Every block RAM address comes from
    a flip-flop after the port multiplexer, every block RAM output lands in a register before any
    logic (clock-to-out is most of a period on ECP5). One item per clock; a pass fetched to its end
    drains on its own.
    """

    def __init__(self, fs: FormatSet, register_map: RegisterMap, *, read_latency: int = READ_LATENCY,
                 entry_latency: int = ENTRY_LATENCY, down_counters: bool = False):
        if not isinstance(fs, FormatSet) or not isinstance(register_map, RegisterMap):
            raise TypeError(f"PassSequencer needs a FormatSet and a RegisterMap, not {fs!r}, {register_map!r}")
        if not isinstance(down_counters, bool):
            raise TypeError(f"PassSequencer down_counters must be a bool, not {down_counters!r}")
        #: Each fetch counter's issue and end read a down-counter's sign (:func:`fetch_counter`'s ``left``).
        self.down_counters = down_counters
        cap: EngineCapacity = register_map.capacity
        self.fs, self.capacity = fs, cap
        #: With K > 1 lanes this is one lane's: its counts are the lane's (``vertices``, ``entries``,
        #: ``triangles``), its indices lane-local (a bank's word), and the events of a whole pass's sum
        #: (E_C's, S's, E_S's ``area_sum``) are the lanes' sum's, not its own (:class:`~hdl.lanes.LaneSums`).
        self.lanes = lanes = cap.lanes
        #: Each pass's clocks from its first address to its unit's input (:func:`fetch_latencies`).
        self.force_fetch_latency, self.area_fetch_latency, self.node_fetch_latency = \
            fetch_latencies(read_latency, entry_latency)
        self.read_latency, self.entry_latency = read_latency, entry_latency
        layouts = memory_layouts(fs, cap)
        # with a coarse space, the integrator takes the coarse move (and counts its add's events)
        coarse = bool(cap.coarse_degree)
        force_sig = ForcePass.signature_of(fs, True, True)
        integrator_sig = Integrator.signature_of(fs, None, True, coarse)
        width = register_map.value_width
        nodes = range(cap.vertices // lanes + 1)
        area_saturations = Signal(area_saturations_layout(fs))
        #: Width of each saturation-event output (a unit's count, 0 when it reports none).
        self.event_widths = {
            "force": node_force_layout(fs, True, True)["saturations"].shape.width,
            "integrate": integrator_output_layout(fs, None, True, coarse)["saturations"].shape.width,
            "area": len(area_saturations.face_edge + area_saturations.face_area + area_saturations.area_sum),
            "length": 1, "power": 1,
        }
        super().__init__({
            **{name: In(1) for name in FETCH_FLAGS},
            **{name: In(1) for name in PHASE_INPUTS}, "running": In(1), "area_clear": In(1),
            "vertices": In(width("vertices")), "entries": In(width("entries")), "triangles": In(width("triangles")),
            "momentum": In(1), "barrier_held": In(1),
            "guarded": In(1), "half_rate": In(1), "node_restart": In(1), "triangle_restart": In(1),
            "entry": In(word_layout(layouts["entries"])), "triangle": In(word_layout(layouts["triangles"])),
            "position": In(vector_layout(fs.position)).array(3), "velocity": In(vector_layout(fs.velocity)),
            "weight_word": In(weight_word_layout(fs)), "force_word": In(force_word_layout(fs)),
            "entry_index": Out(range(cap.lane_entries + 1)), "tri_index": Out(range(cap.triangles // lanes + 1)),
            "node_index": Out(nodes), "node_of_entry": Out(nodes),
            "force_entry": Out(stream.Signature(force_entry_layout(fs), always_ready=True)),
            "triangle_out": Out(stream.Signature(triangle_layout(fs), always_ready=True)),
            "node_out": Out(stream.Signature(integrator_input_layout(fs), always_ready=True)),
            "forces": In(force_sig.members["o"].signature), "integrated": In(integrator_sig.members["o"].signature),
            "area_saturations": In(area_saturations_layout(fs)),
            "force_idle": In(1), "area_idle": In(1), "integrator_idle": In(1),
            "force_out_index": Out(nodes), "node_out_index": Out(nodes),
            "force_write": Out(write_signature(nodes, force_word_layout(fs))),
            "node_write": Out(write_signature(nodes, node_write_layout(fs))),
            "proposal_write": Out(write_signature(nodes, vector_layout(fs.velocity))),
            "node_landed": Out(1), "triangle_landed": Out(1), "corners": Out(range(cap.vertices)).array(3),
            "landed_area": Out(shape_of(fs.face_area)),
            "force_done": Out(1), "area_done": Out(1), "integrate_done": Out(1),
            "passes_idle": Out(1),
            **{name: Out(shape) for name, shape in pass_sum_shapes(fs, cap.vertices, cap.entries).items()},
            **{f"{name}_events": Out(w) for name, w in self.event_widths.items()},
        })

    def elaborate(self, platform):
        m = Module()
        # The counters and sums are flip-flops without the domain's reset: the start or step phase clears
        # them before any pass reads them, so the phase flag alone drives their reset pins (with the
        # domain's reset, a net across the whole device, in front of it, one LUT fans out to some 200
        # flip-flops' reset pins: a long path on the board).
        r = {name: Signal.like(getattr(self, name), reset_less=True, name=f"{name}_q") for name in RESTARTED}
        m.d.comb += [getattr(self, name).eq(q) for name, q in r.items()]
        # with down_counters, the fetch counters' down-counters (restarted with them; at −1, no issue and
        # the pass at its end, until the first restart)
        self._left = {name: Signal(signed(len(r[name]) + 1), init=-1, name=f"{name}_left", reset_less=True)
                      for name in FETCH_COUNTERS if self.down_counters}
        # the mesh sizes the counters read: with down_counters, copies beside the down-counters
        self._sizes = {name: kept_register(m, getattr(self, name), name=f"{name}_size", platform=platform)
                       if self.down_counters else getattr(self, name) for name in FETCH_COUNTERS.values()}
        # the pass enables the fetch counters read: with down_counters, copies beside the counters (a clock late)
        self._fetch = {name: kept_register(m, getattr(self, name), name=f"{name}_copy", platform=platform, reset=True)
                       if self.down_counters else getattr(self, name) for name in FETCH_FLAGS}
        # a second copy for each fetch's valid chain, a third for its down-counter (``fetch_counter``'s
        # ``valid_fetch`` and ``left_fetch``)
        self._valid_fetch, self._left_fetch = (
            {name: kept_register(m, getattr(self, name), name=f"{name}_{kind}_copy", platform=platform, reset=True)
             if self.down_counters else None for name in FETCH_FLAGS} for kind in ("valid", "left"))
        # the guard passes' restart pulses: with down_counters, copies beside the counters (a clock late)
        self._restart = {name: kept_register(m, getattr(self, pulse), name=f"{pulse}_copy", platform=platform,
                                             reset=True) if self.down_counters else getattr(self, pulse)
                         for name, pulse in RESTART_PULSES.items()}
        e_valid, next_first = self._force_pass(m, r, platform)
        t_valid = self._area_pass(m, r)
        n_valid = self._integrate_pass(m, r)
        self._ends(m, e_valid, t_valid, n_valid)
        # The counters and sums restart from a phase flag, outside the phase machine's priority logic:
        # the force and area passes' in the start phase, the integrate pass's in the step phase. The run's
        # sums, which the placer puts by the math units that read them, across the device from the phase
        # machine, restart from a copy of the flag of their own (``kept_register``), a clock later: their
        # pass's first terms arrive tens of clocks after the phase.
        copies = {phase: kept_register(m, getattr(self, phase), platform=platform,
                                       name=f"sums_restart_at_{phase.removeprefix('in_')}")
                  for phase in ("in_start", "in_step")}
        def restart(names):  # the registers named to 0, their down-counters to size − 1
            return [*(r[name].eq(0) for name in names),
                    *(self._left[name].eq(self._sizes[FETCH_COUNTERS[name]] - 1) for name in names if name in self._left)]

        for phase, copy in copies.items():
            with m.If(getattr(self, phase)):
                m.d.sync += restart([name for name, (at, is_sum) in RESTARTS.items() if at == phase and not is_sum])
            with m.If(copy):
                m.d.sync += restart([name for name, (at, is_sum) in RESTARTS.items() if at == phase and is_sum])
        with m.If(self.in_start):
            m.d.sync += next_first.eq(1)
        for name, pulse in self._restart.items():
            with m.If(pulse):
                m.d.sync += restart([name])
        return m

    def _force_pass(self, m: Module, r: dict[str, Signal], platform):
        """E0 … E9 into ``ForcePass.i``, one entry per clock; its per-node results counted and summed."""
        e_valid = fetch_counter(m, r["entry_index"], self._fetch["fetch_force"], self._sizes["entries"], "e",
                                self.force_fetch_latency + 1, self._left.get("entry_index"),
                                self._valid_fetch["fetch_force"], self._left_fetch["fetch_force"])
        entry_shape = self.entry.shape()
        ent_data = self.entry  # the addressed entry, at entry_latency
        next_first = Signal(name="next_first")
        # the entry and its first flag carried from entry_latency to force_fetch_latency, beside its
        # positions' read
        e_entry, e_first = ent_data, next_first
        for k in range(self.entry_latency + 1, self.force_fetch_latency + 1):
            entry_k, first_k = Signal(entry_shape, reset_less=True, name=f"e{k}_entry"), Signal(name=f"e{k}_first")
            m.d.sync += [entry_k.eq(e_entry), first_k.eq(e_first)]
            e_entry, e_first = entry_k, first_k
        with m.If(e_valid[self.entry_latency]):  # the owner of the entry after this one
            m.d.sync += [next_first.eq(ent_data.last), r["node_of_entry"].eq(r["node_of_entry"] + ent_data.last)]
        # MODE.barrier gates the entry's barrier terms through a copy of its own beside the gating: the
        # register bank's copy sits by the bus decode, and a route from it into this multiplexer crosses
        # the die. A clock late is safe: it is a run constant, written a bus cycle or more before START.
        beat = self.force_entry.payload
        barrier = kept_register(m, self.barrier_held, name="force_barrier", platform=platform)
        m.d.comb += [
            self.force_entry.valid.eq(e_valid[self.force_fetch_latency]),
            beat.first.eq(e_first), beat.last.eq(e_entry.last),
            beat.position.eq(self.position[0]), beat.neighbour.position.eq(self.position[1]),  # landed at E9
            beat.neighbour.rest.eq(e_entry.rest),
            beat.barrier.second.eq(self.position[2]),
            beat.barrier.threshold.eq(Mux(barrier, e_entry.threshold, 0)),
            beat.barrier.gain.eq(Mux(barrier, e_entry.gain, 0)),
        ]
        # per-node results: into the force memory, and the exact sums
        m.d.comb += [self.force_write.addr.eq(r["force_out_index"]),
                     self.force_write.data.force.eq(self.forces.payload.force),
                     self.force_write.data.inside.eq(self.forces.payload.inside),
                     self.force_write.en.eq(self.forces.valid)]
        with m.If(self.forces.valid):
            m.d.sync += r["force_out_index"].eq(r["force_out_index"] + 1)
        # a node's terms land in registers beside the sums before they are added (the force pass's output
        # is routed across the device, and its valid bit would be the enable of every sum bit at the end
        # of that route); the sums are whole the clock after the index reaches the vertices, when the
        # registered force_done reads them
        payload = self.forces.payload
        node_terms = {"length_sum": payload.error_sum, "square_sum": payload.error_squares,
                      "barrier_sum": payload.barrier_energy}
        landed = Signal(name="force_terms_landed")
        terms = {name: Signal.like(term, name=f"landed_{name}", reset_less=True) for name, term in node_terms.items()}
        m.d.sync += [landed.eq(self.forces.valid), *(terms[name].eq(term) for name, term in node_terms.items())]
        with m.If(landed):
            m.d.sync += [r[name].eq(r[name] + term) for name, term in terms.items()]
        return e_valid, next_first

    def _area_pass(self, m: Module, r: dict[str, Signal]):
        """T0 … T5 into ``AreaError.i``, one triangle per clock."""
        # the guard's triangle passes issue every other clock (the certificate's interval of 2)
        alternate = Signal(name="tri_alternate")
        m.d.sync += alternate.eq(~alternate & self.half_rate)
        valid_fetch, left_fetch = self._valid_fetch["fetch_area"], self._left_fetch["fetch_area"]
        t_valid = fetch_counter(m, r["tri_index"], self._fetch["fetch_area"] & ~alternate, self._sizes["triangles"],
                                "t", self.area_fetch_latency + 1, self._left.get("tri_index"),
                                None if valid_fetch is None else valid_fetch & ~alternate,
                                None if left_fetch is None else left_fetch & ~alternate)
        # the triangle's area and corners, landed with it, carried beside its corners' read
        area, corners = self.triangle.area, [self.triangle.a, self.triangle.b, self.triangle.c]
        for k in range(self.read_latency + 1, self.area_fetch_latency + 1):
            area_k = Signal(shape_of(self.fs.face_area), reset_less=True, name=f"t{k}_area")
            corners_k = [Signal(range(self.capacity.vertices), reset_less=True, name=f"t{k}_corner{c}") for c in "abc"]
            m.d.sync += [area_k.eq(area), *(ck.eq(c) for ck, c in zip(corners_k, corners))]
            area, corners = area_k, corners_k
        landed = t_valid[self.area_fetch_latency]
        m.d.comb += [self.triangle_landed.eq(landed & ~self.in_area), self.landed_area.eq(area),
                     *(out.eq(c) for out, c in zip(self.corners, corners))]
        out = self.triangle_out
        m.d.comb += [out.valid.eq(landed & self.in_area), out.payload.a.eq(self.position[0]),
                     out.payload.b.eq(self.position[1]), out.payload.c.eq(self.position[2]),
                     out.payload.area.eq(area)]
        return t_valid

    def _integrate_pass(self, m: Module, r: dict[str, Signal]):
        """N0 … N2 into ``Integrator.i``, one node per clock; its results counted and S summed."""
        n_valid = fetch_counter(m, r["node_index"], self._fetch["fetch_nodes"], self._sizes["vertices"], "n",
                                self.node_fetch_latency + 1, self._left.get("node_index"),
                                self._valid_fetch["fetch_nodes"], self._left_fetch["fetch_nodes"])
        node = self.node_out.payload
        landed = n_valid[self.node_fetch_latency]
        m.d.comb += [  # landed at N2
            self.node_out.valid.eq(landed & self.in_integrate), self.node_landed.eq(landed),
            node.node.position.eq(self.position[0]), node.node.velocity.eq(self.velocity),
            node.node.inv_mass.eq(self.weight_word.inv_mass), node.node.inv_mass_barrier.eq(self.weight_word.inv_mass_barrier),
            node.force.eq(self.force_word.force), node.inside.eq(self.force_word.inside),
        ]
        # its results: back into the node memories, and S summed
        m.d.comb += [self.node_write.addr.eq(r["node_out_index"]),
                     self.node_write.data.position.eq(self.integrated.payload.position),
                     self.node_write.data.velocity.eq(self.integrated.payload.velocity),
                     self.node_write.en.eq(self.integrated.valid & ~self.guarded),
                     self.proposal_write.addr.eq(r["node_out_index"]),
                     self.proposal_write.data.eq(self.integrated.payload.velocity),
                     self.proposal_write.en.eq(self.integrated.valid & self.guarded)]
        with m.If(self.integrated.valid):
            m.d.sync += [r["node_out_index"].eq(r["node_out_index"] + 1),
                         r["power_sum"].eq(r["power_sum"] + self.integrated.payload.power)]
        return n_valid

    def _ends(self, m: Module, e_valid, t_valid, n_valid) -> None:
        """The passes' ends and their saturation events; the fetch's and the units' idle state."""
        fs = self.fs
        # a pulse the clock after the pass's last result, registered (its counter's compare and the
        # units' idle flags stay off the phase machine's logic)
        area_fetching = Cat(*t_valid).any()
        tri_at_end = self._at_end("tri_index")
        if self.lanes == 1:  # the controller leaves the phase the clock after the pulse
            m.d.sync += [
                self.force_done.eq(self.in_force & (self.force_out_index == self._sizes["vertices"]) & ~self.force_done),
                self.area_done.eq(self.in_area & tri_at_end & ~area_fetching & self.area_idle
                                  & ~self.area_clear & ~self.area_done),
                self.integrate_done.eq(self.in_integrate & (self.node_out_index == self._sizes["vertices"]) & ~self.integrate_done),
            ]
        else:  # the joined end (hdl.lanes.LaneSums) comes a clock after the last lane's, so the phase outlasts the
            # pulse, which would come again every other clock: a lane's end pulses once in its phase
            ends = {"force": (self.in_force, self.force_done, self.force_out_index == self._sizes["vertices"]),
                    "area": (self.in_area, self.area_done, tri_at_end & ~area_fetching
                             & self.area_idle & ~self.area_clear),
                    "integrate": (self.in_integrate, self.integrate_done, self.node_out_index == self._sizes["vertices"])}
            for name, (phase, done, at_end) in ends.items():
                ended = Signal(name=f"{name}_ended")
                m.d.sync += [done.eq(phase & at_end & ~done & ~ended), ended.eq(phase & (ended | done))]
        sat, power = self.area_saturations, self.power_sum
        m.d.comb += [
            self.force_events.eq(Mux(self.forces.valid, self.forces.payload.saturations, 0)),
            self.integrate_events.eq(Mux(self.integrated.valid & self.running, self.integrated.payload.saturations, 0)),
        ]
        if self.lanes > 1:  # a sum's event is the lanes' sum's (hdl.lanes.LaneSums)
            m.d.comb += self.area_events.eq(Mux(self.area_done, sat.face_edge + sat.face_area, 0))
            return self._idle(m, e_valid, t_valid, n_valid)
        m.d.comb += [
            self.area_events.eq(Mux(self.area_done, sat.face_edge + sat.face_area + sat.area_sum, 0)),
            self.length_events.eq(self.force_done & (self.length_sum > fs.error_acc.raw_max)),
            self.power_events.eq(self.integrate_done & self.momentum
                                 & ((power > fs.power_acc.raw_max) | (power < fs.power_acc.raw_min))),
        ]
        self._idle(m, e_valid, t_valid, n_valid)

    def _at_end(self, name: str) -> Value:
        """Fetch counter ``name`` stands at its mesh size: with ``down_counters`` its down-counter's sign
        (−1 from the last issue to the next restart), no compare."""
        if name in self._left:
            return self._left[name][-1]
        return getattr(self, name) == self._sizes[FETCH_COUNTERS[name]]

    def _idle(self, m: Module, e_valid, t_valid, n_valid) -> None:
        """``passes_idle``: the fetch counters at their ends and no item in a fetch or a unit."""
        # The fetch counters' ends (compares, or down-counters' signs) in registers beside them, then `done_fetching` from
        # those, two clocks behind the counters, so that no compare's logic sits on the route across
        # the device into the drain's end. A guard pass restarts its counter in its first clock (with
        # down_counters its second), while the counter still stands at the previous pass's end: neither
        # that clock's compare nor `done_fetching` a clock later reads it as done. A pass without a restart
        # pulse starts from a counter at 0 and issues in its first clock (its second), so `passes_idle`
        # covers the lag's clock there.
        restart = self._restart
        at_end = Signal(3, name="fetch_at_end")  # entries, triangles, nodes
        m.d.sync += at_end.eq(Cat(self._at_end("entry_index"), self._at_end("tri_index") & ~restart["tri_index"],
                                  self._at_end("node_index") & ~restart["node_index"]))
        # a pass is fetching while its enable is high; with down_counters also while the copies its counter
        # reads are: from the enable's rise, a clock before the first issue, to the copies' fall. There a
        # guard pass's counter restarts a clock after the rise, from the pulse's copy: the rise itself
        # (the enable high, its copy still low) is not done, in place of the pulse
        force, area, nodes = (getattr(self, flag) | self._valid_fetch[flag] if self.down_counters
                              else getattr(self, flag) for flag in FETCH_FLAGS)
        if self.down_counters:
            flags = dict(zip(FETCH_COUNTERS, FETCH_FLAGS))
            restarting = {name: pulse | (getattr(self, flags[name]) & ~self._fetch[flags[name]])  # or the rise
                          for name, pulse in restart.items()}
        else:
            restarting = restart
        done_fetching = Signal(name="done_fetching")
        m.d.sync += done_fetching.eq(
            (at_end[0] | ~force)
            & ((at_end[1] & ~restarting["tri_index"]) | ~area)
            & ((at_end[2] & ~restarting["node_index"]) | ~nodes))
        # the passes' idle state registered here too, for the drain's end (hdl.phase_controller)
        fetching = Cat(*e_valid, *t_valid, *n_valid).any()
        m.d.sync += self.passes_idle.eq(self.force_idle & self.area_idle & self.integrator_idle & ~fetching
                                        & done_fetching)
