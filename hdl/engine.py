"""``SpringflatEngine``: the whole flattening on chip, behind a Wishbone bus.

Algorithm 1 from START to done with no host in the loop, the twin of the golden model's
:func:`~golden_model.engine_spec.image.run_image` (itself bit-identical to ``run_fixed``).
The host interface is the :class:`~golden_model.engine_spec.register_map.RegisterMap` of the format
set and capacity: this module decodes that map, it defines no address of its own.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import EngineCapacity, lane_count_fields, memory_layouts
from golden_model.engine_spec.register_map import RegisterMap
from golden_model.modes import Step

from . import wishbone
from .area_error import AreaError
from .coarse_passes import CoarsePasses
from .force_pass import ForcePass
from .guard_passes import GUARD_PASSES, GuardPasses
from .integrator import Integrator
from .layouts import PASS_SUMS
from .lanes import LANE_PASSES, LANE_SUMS, LaneSums
from .logic import mode_steps
from .memory_windows import MemoryWindows, needs_registered_select, window_steps
from .parameters import check_power_of_two
from .pass_sequencer import FETCH_FLAGS, PHASE_INPUTS, PassSequencer
from .phase_controller import CONSTANTS, HELD, RESULT_VALUES, PhaseController
from .register_bank import RegisterBank
from .rom import ENTRY_BANK_DEPTH
from .saturation_tally import SaturationTally

__all__ = ["SpringflatEngine"]

#: The run constants the datapath units, the pass sequencer and the guard read, each through a copy
#: register of its own in the register bank (:class:`~hdl.register_bank.RegisterBank`'s ``copies``):
#: a storage register read across the device is placed by its readers, and the bus's write decode
#: then reaches its enable over the same distance.
UNIT_CONSTANTS = ("barrier", "mode", "half_spring", "damping", "area_reciprocal", "area_shift",
                  "length_reciprocal", "length_shift", "tol_energy", "vertices", "entries", "triangles")


#: The controller's flags each pass sequencer reads.
SEQUENCER_FLAGS = (*FETCH_FLAGS, *PHASE_INPUTS, "running", "area_clear", "guarded", "half_rate", "node_restart",
                   "triangle_restart")


class SpringflatEngine(wiring.Component):
    """Algorithm 1 in hardware: memories, the passes, the controller and a Wishbone B4 target.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
    capacity : :class:`~golden_model.engine_spec.image.EngineCapacity`
        Depths of the node, entry and triangle memories, and whether the step guard is built (its
        passes, :class:`~hdl.guard_passes.GuardPasses`, and the proposal memories; without it START
        answers a guarded mode with ``bad-constants`` and FEATURES.guard reads 0); its ``lanes`` K > 1 build K
        datapaths, each on the vertices ``l, l + K, …`` (:meth:`_elaborate_lanes`; without the guard and
        without the build options below).
    entry_bank_depth : int
        Words per bank of the entry memory (a power of two; :data:`ENTRY_BANK_DEPTH`, the deepest
        DP16KD mode of a wide word; a test passes less to have several banks at a small capacity).
    registered_select : bool or None
        The node and triangle memories built as the entry memory (pin registers, the bank select in
        registered stages), their reads three clocks longer (:class:`~hdl.memory_windows.MemoryWindows`); the
        entry memory's bank flag a copy per block RAM; the fetch counters' issues and ends from down-counters,
        and their pass enables from copies beside them, a clock late (a force, area or integrate pass
        issues a clock later; :class:`~hdl.pass_sequencer.PassSequencer`'s ``down_counters``); a register write a clock later,
        from a write enable per register (:class:`~hdl.register_bank.RegisterBank`'s ``registered_write``);
        the check phase a clock longer, its verdict from registers
        (:class:`~hdl.phase_controller.PhaseController`'s ``registered_verdict``); ABORT's register and
        ``running`` copied for groups of their loads (its ``control_copies``; the read addresses' copies of
        ``running`` in the memories); the guard certificate's output valid from a flip-flop
        (:class:`~hdl.guard_passes.GuardPasses`' ``registered_valid``); the bus handshake's state in two
        flip-flops (:class:`~hdl.wishbone.TargetHandshake`'s ``busy_copy``); SATURATIONS' count held by overflow
        bits, not a multiplexer after its adder (:class:`~hdl.saturation_tally.SaturationTally`'s
        ``overflow_bits``); the momentum step's pulse from the β request (the controller's ``control_copies``);
        ``None``: where the node memories take
        several banks (:func:`~hdl.memory_windows.needs_registered_select`: above 2,048 vertices in
        ``default``). A test passes ``True`` to run those latencies at a small capacity.
    pin_registers : bool or None
        The node and triangle memories' block RAM inputs each in a register of their own, without the
        registered select (implied by ``registered_select``): their writes land a clock later, their
        reads take a clock more (:class:`~hdl.memory_windows.MemoryWindows`); ``None``: only with
        ``registered_select``. A build option for timing trials (``docs/engine-guard.md``: at
        ``DEFAULT_CAPACITY`` with the guard it did not raise Fmax).
    delay_lines : bool
        The force pass's and the integrator's values that ride along unchanged for several stages
        carried in delay lines of distributed RAM instead of a register per stage
        (:class:`~hdl.pipeline.Pipeline`): the same results in the same clocks, with 13,040 fewer
        flip-flops in ``default``. A build option, off by default: placed and routed, it did not raise
        Fmax at ``DEFAULT_CAPACITY`` nor make 3072 vertices route (``docs/synthesis.md``).

    Members
    -------
    bus : ``In(wishbone.Signature(addr_width=...))``
        The register map of :attr:`register_map` (Wishbone B4 classic, 32-bit words).
    irq : ``Out(1)``
        STATUS.irq_pending and CONTROL.irq_enable.

    Iteration
    ---------
    Each measurement is a **force pass** over the entries (one per clock: the entry memory, then
    the three position reads ``P_i``, ``P_j``, ``P_second``, into :class:`~hdl.force_pass.ForcePass`,
    whose per-node ``F``/``inside`` go to a force memory and whose error and energy partials are
    summed exactly), then an **area pass** over the triangles (the same three position ports
    read ``a``, ``b``, ``c`` into :class:`~hdl.area_error.AreaError`). The normalisers and the
    energy check run beside the area pass. Between measurements the **step** (the step
    generator, the fixed ``Δt``, or ``β_k`` from the divider) and the **integrate pass** over
    the nodes (positions, velocities, weights and forces into :class:`~hdl.integrator.Integrator`,
    new positions and velocities written back in place: every force of the iteration is in the
    force memory before any node moves, so the update stays synchronous without ping-pong
    memories).

    Blocks
    ------
    ``elaborate`` only instantiates and connects them:

    * :class:`~hdl.wishbone.TargetHandshake` (``hs``): the bus cycle, one at a time;
    * :class:`~hdl.register_bank.RegisterBank` (``registers``): the register map's fields by access
      type, the run constants' copies for the units, the bus's answers;
    * :class:`~hdl.memory_windows.MemoryWindows` (``memories``): the block RAMs, their bus windows and
      each port's multiplexer between the bus (idle) and the passes (running);
    * :class:`~hdl.pass_sequencer.PassSequencer` (``sequencer``): each pass's fetch into its unit and
      the collection of its results;
    * :class:`~hdl.phase_controller.PhaseController` (``controller``): the run's state and phases, the
      stop decisions, the normalisers, the energy check and the step's units;
    * :class:`~hdl.saturation_tally.SaturationTally` (``tally``): SATURATIONS;
    * the passes' units: :class:`~hdl.force_pass.ForcePass` (``force``),
      :class:`~hdl.area_error.AreaError` (``area``), :class:`~hdl.integrator.Integrator` (``integrator``);
    * with K lanes, a sequencer and those units per lane (``sequencer0``, ``force0``, …) and
      :class:`~hdl.lanes.LaneSums` (``sums``), their pass ends and sums joined for the controller.
    """

    #: Clocks the check phase waits after the math phase's last result (the saturation tally's
    #: pipeline and the registered limit compare): :attr:`PhaseController.CHECK_SETTLE_CLOCKS`.
    CHECK_SETTLE_CLOCKS = PhaseController.CHECK_SETTLE_CLOCKS

    def __init__(self, fs: FormatSet | str, capacity: EngineCapacity, *, entry_bank_depth: int = ENTRY_BANK_DEPTH,
                 registered_select: bool | None = None, pin_registers: bool | None = None,
                 delay_lines: bool = False):
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"SpringflatEngine needs a FormatSet or a preset name, not {fs!r}")
        if not isinstance(capacity, EngineCapacity):
            raise TypeError(f"SpringflatEngine needs an EngineCapacity, not {capacity!r}")
        check_power_of_two("entry_bank_depth", entry_bank_depth)
        for flag, value in (("registered_select", registered_select), ("pin_registers", pin_registers)):
            if value is not None and not isinstance(value, bool):
                raise TypeError(f"{flag} must be a bool or None, not {value!r}")
        if not isinstance(delay_lines, bool):
            raise TypeError(f"delay_lines must be a bool, not {delay_lines!r}")
        if capacity.lanes > 1 and (capacity.guard or registered_select or pin_registers or delay_lines):
            raise ValueError(f"SpringflatEngine: lanes={capacity.lanes} are built without the step guard "
                             "(EngineCapacity(guard=False)), the registered select, the pin registers and the delay lines")
        self.fs, self.capacity = fs, capacity
        self.entry_bank_depth = entry_bank_depth
        self.registered_select = (needs_registered_select(fs, capacity) and capacity.lanes == 1) \
            if registered_select is None else registered_select
        if pin_registers is False and self.registered_select:
            raise ValueError("registered_select needs the pin registers: pin_registers=False contradicts it")
        self.pin_registers = self.registered_select or bool(pin_registers)
        if capacity.coarse_degree and (self.registered_select or self.pin_registers or delay_lines):
            raise ValueError("SpringflatEngine: a coarse space (coarse_degree > 0) is built without the registered "
                             "select (the capacities above DEFAULT_CAPACITY's node memories), the pin registers and "
                             "the delay lines")
        #: Clocks from ``stb`` to the target raising ``ack`` or ``err`` (the initiator samples it at the next
        #: edge): a register (the handshake's request register, the registered decode, the read word's two
        #: AND-OR stages, ``ack``); a memory word, read or write (the decode, then
        #: :func:`~hdl.memory_windows.window_steps`: a clock more with the registered select); an ``err`` for
        #: a word that decodes to nothing or a memory word while running. ``tests/hdl/test_engine.py``
        #: measures them, with and without the registered select.
        self.bus_answer_clocks = {"register": 5, "memory word": 3 + window_steps(self.registered_select), "err": 4}
        self.delay_lines = delay_lines
        self.register_map = RegisterMap.build(fs, capacity)
        self.layouts = memory_layouts(fs, capacity)
        self.addr_width = self.register_map.address_bits
        super().__init__({
            "bus": In(wishbone.Signature(addr_width=self.addr_width)),
            "irq": Out(1),
        })

    def elaborate(self, platform):
        fs, cap, rmap = self.fs, self.capacity, self.register_map
        m = Module()
        hs, registers, memories = self._blocks(m)
        if cap.lanes > 1:
            self._elaborate_lanes(m, hs, registers, memories, platform)
            return m
        # the registered select's builds (above DEFAULT_CAPACITY) also end the fetches from down-counters,
        # take the check's verdict from registers and read ABORT and running from copies by their loads
        m.submodules.sequencer = sequencer = PassSequencer(fs, rmap, read_latency=memories.read_latency,
                                                           entry_latency=memories.entry_latency,
                                                           down_counters=self.registered_select)
        m.submodules.controller = controller = PhaseController(fs, rmap, registered_verdict=self.registered_select,
                                                               control_copies=self.registered_select)
        if self.registered_select:
            _wire(m, controller, memories, "running_next")
        m.submodules.force = force = ForcePass(fs, energy=True, saturations=True, delay_lines=self.delay_lines)
        m.submodules.area = area = AreaError(fs)
        m.submodules.integrator = integrator = Integrator(fs, saturations=True, delay_lines=self.delay_lines,
                                                          shift_copy=self.registered_select,
                                                          coarse=bool(cap.coarse_degree))
        coarse = CoarsePasses(fs, cap, read_latency=memories.matrix_read_latency) if cap.coarse_degree else None
        if coarse is not None:
            m.submodules.coarse = coarse
        guard = GuardPasses(fs, cap, read_latency=memories.read_latency,
                            registered_valid=self.registered_select) if cap.guard else None
        if guard is not None:
            m.submodules.guard = guard
        # SATURATIONS' sources, in the order they are summed in pairs
        producers = {"force": sequencer, "integrate": sequencer, "step": controller, "area": sequencer,
                     "length": sequencer, "power": sequencer, "shape_error": controller, "area_error": controller,
                     **({"coarse_force": coarse, "coarse_move": coarse} if coarse is not None else {})}
        tally = self._tally(m, {name: unit.event_widths[name] for name, unit in producers.items()})
        self._bus_and_run(m, hs, registers, memories, controller, tally,
                          {name: getattr(unit, f"{name}_events") for name, unit in producers.items()},
                          ("force", "area", "length", "shape_error", "area_error"))

        # the passes: the controller's flags, the memories' ports, the units' streams
        _wire(m, controller, sequencer, *SEQUENCER_FLAGS)
        self._pass_flags(m, controller, memories)
        m.d.comb += [integrator.scale_shift.eq(controller.scale_shift), integrator.propose.eq(controller.guarded)]
        if guard is not None:
            _wire(m, controller, guard, "in_step", "in_integrate", *(f"in_{name}" for name in GUARD_PASSES))
            m.d.comb += [guard.vertices.eq(registers.vertices_held), guard.triangles.eq(registers.triangles_held)]
            _wire(m, sequencer, guard, "node_index", "node_landed", "triangle_landed", "corners")
            _wire(m, memories, guard, "position", "proposal", "velocity")
            m.d.comb += [guard.area.eq(sequencer.landed_area), controller.guard_done.eq(guard.done),
                         controller.passes_idle.eq(sequencer.passes_idle & guard.idle)]
        else:  # START refuses the guarded modes: no guard pass ever starts
            m.d.comb += controller.passes_idle.eq(sequencer.passes_idle)
        _wire(m, registers, sequencer, "barrier_held")
        m.d.comb += [sequencer.vertices.eq(registers.vertices_held), sequencer.entries.eq(registers.entries_held),
                     sequencer.triangles.eq(registers.triangles_held)]
        _wire(m, memories, sequencer, "entry", "triangle", "position", "velocity", "weight_word", "force_word")
        _wire(m, sequencer, memories, "entry_index", "tri_index", "node_index", "node_of_entry")
        _wire(m, sequencer, controller, "force_done", "area_done", "integrate_done", *PASS_SUMS)
        _connect_units(m, sequencer, force, area, integrator, coarse)
        if coarse is not None:  # the coarse space: its passes read the basis, force and matrix memories
            _wire(m, controller, coarse, "in_coarse", "coarse_step")
            _wire(m, sequencer, coarse, "node_landed")
            _wire(m, memories, coarse, "force_word")
            _wire(m, coarse, memories, "matrix_addr")
            m.d.comb += [coarse.basis.eq(memories.basis_word), coarse.matrix_data.eq(memories.matrix_word.entry),
                         coarse.vertices.eq(registers.vertices_held), coarse.matrix_exponent.eq(registers.matrix_exponent),
                         controller.coarse.eq(registers.coarse), controller.coarse_done.eq(coarse.done),
                         controller.coarse_clipped.eq(guard.clipped)]
        wiring.connect(m, sequencer.force_write, memories.force_write)
        # the node memories' and the proposal memory's writers: one pass at a time, so the writer whose
        # enable is high
        for port in ("node_write", "proposal_write"):
            theirs, sink = getattr(sequencer, port), getattr(memories, port)
            if guard is None:
                m.d.comb += [sink.en.eq(theirs.en), sink.addr.eq(theirs.addr), sink.data.eq(theirs.data)]
                continue
            ours = getattr(guard, port)
            m.d.comb += [sink.en.eq(ours.en | theirs.en), sink.addr.eq(Mux(ours.en, ours.addr, theirs.addr)),
                         sink.data.eq(Mux(ours.en, ours.data, theirs.data))]
        _constants_into_units(m, registers, controller, sequencer, force, area, integrator, area_total=controller.area_total,
                              coarse=coarse)

        # Internal state a testbench may watch (``debug_signals``) or read (``debug_memories``).
        self.debug_memories = {name: memories.rams[name].contents for name in ("positions", "velocities")}
        self._debug_signals(controller, sequencer, memories.node_write.en)
        return m

    def _blocks(self, m: Module):
        """The bus handshake, the register bank and the memories: ``(hs, registers, memories)``."""
        fs, cap, rmap = self.fs, self.capacity, self.register_map
        # (with the registered select the register bank decodes its own copy of the address: the bank and
        # the windows' decode sit apart on the die)
        m.submodules.hs = hs = wishbone.TargetHandshake(addr_width=self.addr_width,
                                                        address_copy=self.registered_select,
                                                        busy_copy=self.registered_select)
        copies = UNIT_CONSTANTS + tuple(f.name for f in lane_count_fields(cap))
        m.submodules.registers = registers = RegisterBank(rmap, addr_width=self.addr_width, copies=copies,
                                                          registered_write=self.registered_select)
        m.submodules.memories = memories = MemoryWindows(fs, cap, rmap, addr_width=self.addr_width,
                                                         entry_bank_depth=self.entry_bank_depth,
                                                         registered_select=self.registered_select,
                                                         pin_registers=self.pin_registers)
        return hs, registers, memories

    def _tally(self, m: Module, widths: dict):
        """SATURATIONS' tally of the event sources ``widths`` (in the order they are summed in pairs)."""
        m.submodules.tally = tally = SaturationTally(widths, count_bits=self.register_map.value_width("saturations"),
                                                       overflow_bits=self.registered_select)
        return tally

    def _bus_and_run(self, m: Module, hs, registers, memories, controller, tally, events: dict, measured) -> None:
        """The bus into the register bank and the windows; the run constants and CONTROL into the controller,
        its state and results back to STATUS; ``events`` (each source's signal) into the tally, those of a
        ``measured`` source gated off while the controller measures an accepted layout again."""
        # the bus: the handshake's request into the register bank (which answers) and the windows
        wiring.connect(m, wiring.flipped(self.bus), hs.bus)
        _wire(m, hs, registers, "request")
        m.d.comb += registers.address.eq(hs.address_copy if self.registered_select else hs.address)
        _wire(m, hs, registers, "write", "write_data", "whole_word")
        _wire(m, hs, memories, "address", "write", "write_data", "whole_word")
        _wire(m, registers, hs, "done", "error", "data")
        _wire(m, registers, memories, "bus_request")
        m.d.comb += [registers.window_hit.eq(memories.hit), registers.window_answer.eq(memories.answer),
                     registers.window_data.eq(memories.answer_data),
                     self.irq.eq(registers.irq_pending & registers.irq_enable)]
        # the run: constants and CONTROL into the controller, its state and results back to STATUS
        _wire(m, registers, controller, "start", "abort", *CONSTANTS, *(f"{name}_held" for name in HELD))
        _wire(m, controller, registers, "state", "result", *RESULT_VALUES)
        _wire(m, tally, registers, "saturations", "saturated")
        _wire(m, tally, controller, "saturations")
        m.d.comb += [registers.irq_pending_set.eq(controller.irq_set),
                     registers.irq_pending_clear.eq(controller.starting), tally.clear.eq(controller.starting)]
        # the accepted layout measured again after a rollback counts no event (the golden model restores
        # its results)
        for name, signal in events.items():
            m.d.comb += getattr(tally, f"{name}_events").eq(
                Mux(controller.measuring_again, 0, signal) if name in measured else signal)

    @staticmethod
    def _pass_flags(m: Module, controller, memories) -> None:
        """The controller's flags that choose the memories' port sources."""
        _wire(m, controller, memories, "running", "fetch_nodes")
        # the position ports read the triangles' corners in every triangle pass, the node in every node pass:
        # the phase flags ORed into registers (a clock late: a triangle's corners are addressed from its
        # second clock on, and a node pass's first node from its fetch flag)
        corner_pass, node_pass = Signal(name="corner_pass"), Signal(name="node_pass")
        m.d.sync += [corner_pass.eq(controller.in_area | controller.in_stuck | controller.in_certify),
                     node_pass.eq(controller.in_integrate | controller.in_hold | controller.in_commit
                                  | controller.in_rollback)]
        m.d.comb += [memories.in_area.eq(corner_pass), memories.in_integrate.eq(node_pass)]

    def _elaborate_lanes(self, m: Module, hs, registers, memories, platform) -> None:
        """K > 1 lanes (``capacity.lanes``, without the guard): a pass sequencer, force pass, area unit and
        integrator per lane, on lane ``l``'s vertices ``l, l + K, …`` (its bank of every node memory), its
        triangles ``l, l + K, …`` and its share of the entries; their pass ends and sums joined
        (:class:`~hdl.lanes.LaneSums`) for the one controller."""
        fs, cap, rmap = self.fs, self.capacity, self.register_map
        lanes, bank_bits = cap.lanes, (cap.lanes - 1).bit_length()
        sequencers, units = [], []
        for lane in range(lanes):
            sequencer = PassSequencer(fs, rmap, read_latency=memories.read_latency,
                                      entry_latency=memories.entry_latency)
            m.submodules[f"sequencer{lane}"] = sequencer
            sequencers.append(sequencer)
        m.submodules.controller = controller = PhaseController(fs, rmap)
        for lane in range(lanes):
            lane_units = (ForcePass(fs, energy=True, saturations=True), AreaError(fs), Integrator(fs, saturations=True))
            for name, unit in zip(("force", "area", "integrator"), lane_units):
                m.submodules[f"{name}{lane}"] = unit
            units.append(lane_units)
        m.submodules.sums = sums = LaneSums(fs, cap)
        # SATURATIONS' sources: each lane's per-node and per-triangle events, the whole sums' from the join
        events, widths = {}, {}
        for lane, sequencer in enumerate(sequencers):
            for name in ("force", "integrate", "area"):
                events[f"{name}{lane}"] = getattr(sequencer, f"{name}_events")
                widths[f"{name}{lane}"] = sequencer.event_widths[name]
        for name in ("length", "power", "area"):
            events[f"{name}_sum" if name == "area" else name] = getattr(sums, f"{name}_events")
            widths[f"{name}_sum" if name == "area" else name] = 1
        for name in ("step", "shape_error", "area_error"):
            events[name], widths[name] = getattr(controller, f"{name}_events"), controller.event_widths[name]
        measured = {*(f"{name}{lane}" for name in ("force", "area") for lane in range(lanes)),
                    "length", "area_sum", "shape_error", "area_error"}
        self._bus_and_run(m, hs, registers, memories, controller, self._tally(m, widths), events, measured)
        self._pass_flags(m, controller, memories)
        # START's check of the lanes' entries: they add up to ENTRIES and each fits its share
        counts = [getattr(registers, f.name) for f in lane_count_fields(cap)]
        lane_fault = Signal(name="lane_fault")
        m.d.sync += lane_fault.eq((sum(counts) != registers.entries)
                                  | Cat(count > cap.lane_entries for count in counts).any())
        m.d.comb += [controller.lane_fault.eq(lane_fault), controller.passes_idle.eq(
            Cat(sequencer.passes_idle for sequencer in sequencers).all())]
        m.d.comb += [sums.restart.eq(controller.in_start), sums.momentum.eq(mode_steps(registers.mode, Step.MOMENTUM))]
        for name in LANE_PASSES:
            m.d.comb += getattr(controller, f"{name}_done").eq(getattr(sums, f"{name}_done"))
            for sum_name in LANE_SUMS[name]:
                m.d.comb += getattr(controller, sum_name).eq(getattr(sums, sum_name))
        for lane, (sequencer, (force, area, integrator)) in enumerate(zip(sequencers, units)):
            _wire(m, controller, sequencer, *SEQUENCER_FLAGS)
            m.d.comb += [integrator.scale_shift.eq(controller.scale_shift), integrator.propose.eq(controller.guarded)]
            # the lane's counts, registered (run constants, written before START): its vertices and triangles
            # those whose index is the lane's mod K, its entries LANEk_ENTRIES
            for what in ("vertices", "triangles"):
                count = Signal.like(getattr(sequencer, what), name=f"lane{lane}_{what}")
                m.d.sync += count.eq((getattr(registers, f"{what}_held") + (lanes - 1 - lane)) >> bank_bits)
                m.d.comb += getattr(sequencer, what).eq(count)
            m.d.comb += sequencer.entries.eq(getattr(registers, f"lane{lane}_entries_held"))
            for name in ("entry", "triangle", "position", "velocity", "weight_word", "force_word"):
                source = getattr(memories, name)[lane]
                if name == "position":
                    m.d.comb += [sequencer.position[k].eq(source[k]) for k in range(3)]
                else:
                    m.d.comb += getattr(sequencer, name).eq(source)
            m.d.comb += [memories.entry_index[lane].eq(sequencer.entry_index),
                         memories.node_of_entry[lane].eq(sequencer.node_of_entry)]
            wiring.connect(m, sequencer.force_write, memories.force_write[lane])
            write, sink = sequencer.node_write, memories.node_write[lane]
            m.d.comb += [sink.en.eq(write.en), sink.addr.eq(write.addr), sink.data.eq(write.data)]
            _wire(m, registers, sequencer, "barrier_held")
            _connect_units(m, sequencer, force, area, integrator)
            _constants_into_units(m, registers, controller, sequencer, force, area, integrator)
            for name in LANE_PASSES:
                m.d.comb += getattr(sums, f"{name}_done_in")[lane].eq(getattr(sequencer, f"{name}_done"))
            for sum_name in PASS_SUMS:
                m.d.comb += getattr(sums, f"{sum_name}_in")[lane].eq(getattr(sequencer, sum_name))
            m.d.comb += [sums.area_total_in[lane].eq(area.total),
                         sums.area_saturated_in[lane].eq(area.saturations.area_sum)]
        # the triangle and integrate passes run the lanes in step: lane 0's counters address every bank
        m.d.comb += [memories.tri_index.eq(sequencers[0].tri_index), memories.node_index.eq(sequencers[0].node_index)]
        self.debug_memories = {f"{name}{b}": memories.rams[f"{name}{b}"].contents
                               for name in ("positions", "velocities") for b in range(lanes)}
        self._debug_signals(controller, sequencers[0], memories.node_write[0].en)

    def _debug_signals(self, controller, sequencer, node_write_en) -> None:
        """Internal state a testbench may watch (``debug_signals``): the first lane's counters."""
        self.debug_signals = {"state": controller.state, "phase": controller.phase,
                              "entry_index": sequencer.entry_index, "force_out_index": sequencer.force_out_index,
                              "tri_index": sequencer.tri_index, "node_out_index": sequencer.node_out_index,
                              "math_pending": controller.math_pending, "iterations": controller.iterations,
                              "passes_idle": controller.passes_idle, "node_write": node_write_en}


def _connect_units(m: Module, sequencer, force, area, integrator, coarse=None) -> None:
    """A sequencer's streams into and out of its units (the integrate pass's nodes through the coarse passes,
    where the build has them)."""
    wiring.connect(m, sequencer.force_entry, force.i)
    wiring.connect(m, sequencer.triangle_out, area.i)
    if coarse is None:
        wiring.connect(m, sequencer.node_out, integrator.i)
    else:
        wiring.connect(m, sequencer.node_out, coarse.node_in)
        wiring.connect(m, coarse.node_out, integrator.i)
    wiring.connect(m, force.o, sequencer.forces)
    wiring.connect(m, integrator.o, sequencer.integrated)


def _constants_into_units(m: Module, registers, controller, sequencer, force, area, integrator, area_total=None,
                          coarse=None) -> None:
    """A sequencer's units: their state into it, the run constants and the step into them; the area unit's
    sum into ``area_total`` (the controller's, with one lane). The coarse passes, where the build has them, count
    with the integrator for the passes' idle state."""
    integrating_idle = integrator.idle if coarse is None else integrator.idle & coarse.idle
    m.d.comb += [sequencer.area_saturations.eq(area.saturations), sequencer.force_idle.eq(force.idle),
                 sequencer.area_idle.eq(area.idle), sequencer.integrator_idle.eq(integrating_idle),
                 *([area_total.eq(area.total)] if area_total is not None else []), area.clear.eq(controller.area_clear),
                 force.half_spring.eq(registers.half_spring_held), force.barrier.eq(registers.barrier_held),
                 integrator.damping.eq(registers.damping_held), integrator.momentum.eq(mode_steps(registers.mode_held, Step.MOMENTUM)),
                 sequencer.momentum.eq(mode_steps(registers.mode, Step.MOMENTUM)),
                 integrator.dt.eq(controller.step_dt), integrator.half_dt_sq.eq(controller.step_half)]


def _wire(m: Module, source, sink, *names: str) -> None:
    """Drive each ``In`` port ``name`` of ``sink`` from the ``Out`` port of the same name of ``source``."""
    for name in names:
        if source.signature.members[name].flow != Out or sink.signature.members[name].flow != In:
            raise TypeError(f"{name}: not an Out port of {type(source).__name__} and an In port of "
                            f"{type(sink).__name__}")
        ins, outs = getattr(sink, name), getattr(source, name)
        for i, o in zip(ins, outs) if isinstance(ins, list) else ((ins, outs),):
            m.d.comb += i.eq(o)
