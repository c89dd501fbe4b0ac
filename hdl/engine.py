"""``SpringflatEngine``: the whole flattening on chip, behind a Wishbone bus.

Algorithm 1 from START to done with no host in the loop, the twin of the golden model's
:func:`~golden_model.engine_spec.image.run_image` (itself bit-identical to ``run_fixed``).
The host interface is the :class:`~golden_model.engine_spec.register_map.RegisterMap` of the format
set and capacity: this module decodes that map, it defines no address of its own.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import BUS_WORD_BITS, ITERATION_BITS, EngineCapacity, memory_layouts
from golden_model.engine_spec.register_map import RESULTS, STATES, RegisterMap

from . import wishbone
from .block_ram import BlockRam
from .dsp import registered_product
from .area_error import AreaError
from .controller_units import BetaDivider, EnergyCheck, Normaliser
from .fixedpoint import clamp, shape_of, shift_round
from .force_pass import ForcePass
from .integrator import Integrator
from .layouts import vector_layout, word_layout
from .rom import ENTRY_BANK_DEPTH
from .stepgen import StepGenerator, stepgen_idle_signal

__all__ = ["SpringflatEngine"]


def _code(codes: tuple[str, ...], name: str) -> int:
    return codes.index(name)


class SpringflatEngine(wiring.Component):
    """Algorithm 1 in hardware: memories, the passes, the controller and a Wishbone B4 target.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
    capacity : :class:`~golden_model.engine_spec.image.EngineCapacity`
        Depths of the node, entry and triangle memories.
    entry_bank_depth : int
        Words per bank of the entry memory (a power of two; :data:`ENTRY_BANK_DEPTH`, the deepest
        DP16KD mode of a wide word; a test passes less to have several banks at a small capacity).

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
    """

    #: Clocks the check phase waits after the math phase's last result: the saturation count's
    #: pipeline (event, pair sums, their sum, the count) and the registered limit compare, so a
    #: normaliser's saturation is counted before the limit is tested, as in ``run_image``.
    CHECK_SETTLE_CLOCKS = 3

    def __init__(self, fs: FormatSet | str, capacity: EngineCapacity, *, entry_bank_depth: int = ENTRY_BANK_DEPTH):
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"SpringflatEngine needs a FormatSet or a preset name, not {fs!r}")
        if not isinstance(capacity, EngineCapacity):
            raise TypeError(f"SpringflatEngine needs an EngineCapacity, not {capacity!r}")
        if isinstance(entry_bank_depth, bool) or not isinstance(entry_bank_depth, int) or entry_bank_depth < 2 \
                or entry_bank_depth & (entry_bank_depth - 1):
            raise ValueError(f"entry_bank_depth must be a power of two >= 2, not {entry_bank_depth!r}")
        self.fs, self.capacity = fs, capacity
        self.entry_bank_depth = entry_bank_depth
        self.register_map = RegisterMap.build(fs, capacity)
        self.layouts = memory_layouts(fs, capacity)
        end = max(w.base + w.size for w in self.register_map.windows)
        self.addr_width = (end - 1).bit_length()
        super().__init__({
            "bus": In(wishbone.Signature(addr_width=self.addr_width)),
            "irq": Out(1),
        })

    # ------------------------------------------------------------------ helpers
    def _value_signals(self):
        """One signal per register value (run constants, results, identification)."""
        values = {}
        for r in self.register_map.registers:
            for f in r.fields:
                if f.value is not None and f.value not in values:
                    values[f.value] = Signal(self.register_map.value_width(f.value), name=f"reg_{f.value}")
        return values

    def elaborate(self, platform):
        fs, cap, rmap = self.fs, self.capacity, self.register_map
        m = Module()
        values = self._value_signals()

        # ------------------------------------------------------------ units
        m.submodules.force = force = ForcePass(fs, energy=True, saturations=True)
        m.submodules.integrator = integ = Integrator(fs, saturations=True)
        m.submodules.area = area = AreaError(fs)
        m.submodules.norm_length = norm_length = Normaliser(fs, saturations=True)
        m.submodules.norm_area = norm_area = Normaliser(fs, saturations=True)
        m.submodules.energy = energy = EnergyCheck(fs, cap.entries)
        # k counts iterations since the last restart, so it never exceeds ITERATIONS: as wide, it never wraps
        m.submodules.beta = beta = BetaDivider(fs, k_bits=ITERATION_BITS)
        m.submodules.stepgen = stepgen = StepGenerator(fs, saturations=True)
        m.submodules.hs = hs = wishbone.TargetHandshake(addr_width=self.addr_width)
        wiring.connect(m, wiring.flipped(self.bus), hs.bus)

        # ------------------------------------------------------------ memories
        pos_shape = vector_layout(fs.position)
        vel_shape = vector_layout(fs.velocity)
        weight_shape = data.StructLayout({"inv_mass": shape_of(fs.inv_mass), "inv_mass_barrier": shape_of(fs.inv_mass)})
        force_shape = data.StructLayout({"force": vector_layout(fs.force_acc), "inside": unsigned(1)})
        entry_shape = word_layout(self.layouts["entries"])
        tri_shape = word_layout(self.layouts["triangles"])
        # Every memory is a BlockRam: its read data lands in a register two clocks after the address (on
        # ECP5 the DP16KD's own output register: its unregistered clock-to-out and the route to a fabric
        # register were the critical path at 119.7 MHz). No read whose data is used meets a write to its
        # address in the same clock (passes read ahead of the integrate pass's writes; the bus reads
        # and writes while idle, a word's write-back after its read): BlockRam's timing contract.
        def memory(name, shape, depth, read_ports=1):
            m.submodules[name] = ram = BlockRam(shape, depth, read_ports=read_ports, name=name)
            return ram

        positions = memory("positions", pos_shape, cap.vertices, read_ports=3)
        velocities = memory("velocities", vel_shape, cap.vertices)
        weights = memory("weights", weight_shape, cap.vertices)
        forces = memory("forces", force_shape, cap.vertices)
        triangles = memory("triangles", tri_shape, cap.triangles)
        # The entries, the deepest memory, in banks of ``entry_bank_depth`` words (ENTRY_BANK_DEPTH): Yosys maps a bank of
        # wide words to DP16KDs in their 2K×9 mode with no cascade, where a deeper memory gets a
        # multiplexer after the block RAMs' outputs (the engine's critical path at 6144 entries).
        # Every bank's read data lands in its register; the addressed bank's word is selected into
        # another the clock after.
        bank_depth = self.entry_bank_depth
        entry_banks = [memory(f"entries{b}", entry_shape, min(bank_depth, cap.entries - b * bank_depth))
                       for b in range(-(-cap.entries // bank_depth))]
        pos_a, pos_b, pos_c = positions.read
        pos_w = positions.write
        (vel_r,), vel_w = velocities.read, velocities.write
        (wgt_r,), wgt_w = weights.read, weights.write
        (frc_r,), frc_w = forces.read, forces.write
        ent_rs = [bank.read[0] for bank in entry_banks]
        ent_ws = [bank.write for bank in entry_banks]
        (tri_r,), tri_w = triangles.read, triangles.write
        bank_bits = (bank_depth - 1).bit_length() if len(entry_banks) > 1 else len(ent_rs[0].addr)
        ent_addr = Signal(range(cap.entries), name="ent_addr")  # the entry memory's address register
        ent_bank = [Signal(range(len(entry_banks)), name=f"ent_bank{k}") for k in (1, 2)]  # at E1, E2
        ent_landed = [port.data for port in ent_rs]  # at E2
        ent_data = Signal(entry_shape, reset_less=True)  # the addressed entry, the clock after landing
        m.d.comb += [port.addr.eq(ent_addr[:bank_bits]) for port in ent_rs]
        m.d.sync += [ent_bank[0].eq(ent_addr[bank_bits:] if len(entry_banks) > 1 else 0), ent_bank[1].eq(ent_bank[0])]
        with m.Switch(ent_bank[1]):
            for b, landed in enumerate(ent_landed):
                with m.Case(b):
                    m.d.sync += ent_data.eq(landed)

        # ------------------------------------------------------------ controller state
        state = Signal(range(len(STATES)), init=_code(STATES, "idle"))
        result = Signal(range(len(RESULTS)), init=_code(RESULTS, "none"))
        irq_pending = Signal()
        irq_enable = Signal()
        # ``state == running`` as a flip-flop of its own, set and cleared with ``state`` (set_state):
        # it gates every pass, port multiplexer and bus answer, so it starts their logic from a
        # register rather than a compare
        running = Signal()
        m.d.comb += self.irq.eq(irq_pending & irq_enable)

        def set_state(name):
            m.d.sync += [state.eq(_code(STATES, name)), running.eq(name == "running")]

        n_vertices, n_entries, n_triangles = values["vertices"], values["entries"], values["triangles"]
        mode_momentum, mode_fixed = values["momentum"], values["fixed_step"]

        # The run constants the datapath units read, each through a copy register of its own: the
        # register file sits by the bus decode, the units across the die, and a constant's route into a
        # unit's first stage was a critical path (MODE.barrier into the force pass's entry register,
        # 7.4 ns of routing at 4a4a5ea). The copy follows its register a clock later; the host writes
        # the constants a bus cycle or more before START, so every pass sees the values it wrote.
        def held(name):
            copy = Signal.like(values[name], name=f"{name}_held")
            m.d.sync += copy.eq(values[name])
            return copy

        unit_constants = {name: held(name) for name in (
            "barrier", "momentum", "half_spring", "damping", "area_reciprocal", "area_shift",
            "length_reciprocal", "length_shift", "tol_energy")}

        # phases of a run
        PH = {name: i for i, name in enumerate((
            "start", "force", "area", "math", "check", "step", "step_wait", "integrate", "drain"))}
        # One flip-flop per phase, all low while no run is under way (so each implies ``running``). A
        # transition clears the phase it leaves and sets the one it enters, so a flag's next value
        # depends only on the blocks that enter or leave it (and ABORT): with a phase code, or with
        # every transition writing every flag, each flag's logic took in the whole phase machine and
        # ``running``'s fan-out (the critical paths after 2e879ec)
        in_phase = {name: Signal(name=f"in_{name}") for name in PH}

        def move(leaving, entering=None):
            return [in_phase[leaving].eq(0), *([in_phase[entering].eq(1)] if entering else [])]

        # the phase's code, for a testbench only (``debug_signals``; nothing in the design reads it)
        phase = Signal(range(len(PH)))
        m.d.comb += phase.eq(_or_all([Mux(flag, PH[name], 0) for name, flag in in_phase.items()]))

        # ------------------------------------------------------------ force pass fetch
        # One entry per clock. Valid bits are named for the clock whose data they mark: E0 the
        # entry's address in the entry memory's address register; E1 the entry banks' read data;
        # E2 landed in fabric registers; E3 the addressed bank's entry (``ent_data``), its three
        # position addresses formed; E4 those in the position memory's address registers; E5 the
        # position memory's read data; E6 everything landed, into ForcePass.i. Every block RAM
        # address comes from a flip-flop after the pass multiplexer, and every block RAM output
        # lands in a register before any logic (clock-to-out is most of a period on ECP5).
        entry_index, fetch_force, e_valid = _fetch_sequencer(m, "entry_index", "fetch_force", "e", 7,
                                                             cap.entries, n_entries)
        e4_entry, e5_entry, e6_entry = (Signal(entry_shape, reset_less=True, name=f"e{k}_entry") for k in range(4, 7))
        e4_first, e5_first, e6_first = Signal(), Signal(), Signal()
        e6_pi, e6_pj, e6_pb = pos_a.data, pos_b.data, pos_c.data  # landed at E6
        node_of_entry = Signal(range(cap.vertices + 1))
        next_first = Signal()
        m.d.sync += [e4_entry.eq(ent_data), e5_entry.eq(e4_entry), e6_entry.eq(e5_entry),
                     e4_first.eq(next_first), e5_first.eq(e4_first), e6_first.eq(e5_first)]
        with m.If(e_valid[3]):  # the owner of the entry after this one
            m.d.sync += [next_first.eq(ent_data.last), node_of_entry.eq(node_of_entry + ent_data.last)]
        m.d.comb += [
            force.i.valid.eq(e_valid[6]),
            force.i.payload.first.eq(e6_first), force.i.payload.last.eq(e6_entry.last),
            force.i.payload.position.eq(e6_pi), force.i.payload.neighbour.position.eq(e6_pj),
            force.i.payload.neighbour.rest.eq(e6_entry.rest),
            force.i.payload.barrier.second.eq(e6_pb),
            force.i.payload.barrier.threshold.eq(Mux(unit_constants["barrier"], e6_entry.threshold, 0)),
            force.i.payload.barrier.gain.eq(Mux(unit_constants["barrier"], e6_entry.gain, 0)),
            force.half_spring.eq(unit_constants["half_spring"]), force.barrier.eq(unit_constants["barrier"]),
        ]
        # per-node results: the force memory and the exact sums
        force_out_index = Signal(range(cap.vertices + 1))
        length_sum = Signal(fs.error_acc.width + cap.vertices.bit_length())
        square_sum = Signal(len(energy.i.payload.square_sum))
        barrier_sum = Signal(len(energy.i.payload.barrier_sum))
        m.d.comb += [frc_w.addr.eq(force_out_index), frc_w.data.force.eq(force.o.payload.force),
                     frc_w.data.inside.eq(force.o.payload.inside), frc_w.en.eq(force.o.valid)]
        with m.If(force.o.valid):
            m.d.sync += [force_out_index.eq(force_out_index + 1),
                         length_sum.eq(length_sum + force.o.payload.error_sum),
                         square_sum.eq(square_sum + force.o.payload.error_squares),
                         barrier_sum.eq(barrier_sum + force.o.payload.barrier_energy)]

        # ------------------------------------------------------------ area pass fetch
        # As the force pass: T0 the triangle's address registered, T1 the triangle memory's data,
        # T2 landed (corner addresses formed), T3 registered, T4 the corners' data, T5 landed, into
        # AreaError.i.
        tri_index, fetch_area, t_valid = _fetch_sequencer(m, "tri_index", "fetch_area", "t", 6,
                                                          cap.triangles, n_triangles)
        t2_tri = tri_r.data  # landed at T2
        t3_area, t4_area, t5_area = (Signal(shape_of(fs.face_area), reset_less=True, name=f"t{k}_area")
                                     for k in (3, 4, 5))
        t5_p = [pos_a.data, pos_b.data, pos_c.data]  # landed at T5
        m.d.sync += [t3_area.eq(t2_tri.area), t4_area.eq(t3_area), t5_area.eq(t4_area)]
        m.d.comb += [area.i.valid.eq(t_valid[5]), area.i.payload.a.eq(t5_p[0]), area.i.payload.b.eq(t5_p[1]),
                     area.i.payload.c.eq(t5_p[2]), area.i.payload.area.eq(t5_area)]

        # ------------------------------------------------------------ integrate pass fetch
        # N0 the node's address registered, N1 the memories' data, N2 landed, into Integrator.i.
        node_index, fetch_nodes, n_valid = _fetch_sequencer(m, "node_index", "fetch_nodes", "n", 3,
                                                            cap.vertices, n_vertices)
        n2_pos, n2_vel, n2_wgt, n2_frc = pos_a.data, vel_r.data, wgt_r.data, frc_r.data  # landed at N2
        step_dt = Signal(shape_of(fs.dt))
        step_half = Signal(shape_of(fs.half_dt_sq))
        # The fixed step's ½Δt² (steplut.half_dt_sq), five stages from the DT register: the
        # product's operands, the product, its copy, rounding, saturation; DT is loaded long
        # before a step uses it.
        fixed_sq = Signal(2 * fs.dt.width, reset_less=True)
        fixed_rounded = Signal(2 * fs.dt.width, reset_less=True)
        fixed_half = Signal(shape_of(fs.half_dt_sq), reset_less=True)
        # the product in a DSP block with its own operand and product registers (hdl.dsp: a bare `*`
        # became a combinational MULT18X18D)
        m.d.sync += [fixed_sq.eq(registered_product(m, values["dt"], values["dt"], name="fixed_dt_sq",
                                                    platform=platform)),
                     fixed_rounded.eq(shift_round(fixed_sq, 2 * fs.dt.frac_bits + 1 - fs.half_dt_sq.frac_bits,
                                                  fs.rounding)),
                     fixed_half.eq(clamp(fixed_rounded, fs.half_dt_sq)[0])]
        m.d.comb += [
            integ.i.valid.eq(n_valid[2]),
            integ.i.payload.node.position.eq(n2_pos), integ.i.payload.node.velocity.eq(n2_vel),
            integ.i.payload.node.inv_mass.eq(n2_wgt.inv_mass),
            integ.i.payload.node.inv_mass_barrier.eq(n2_wgt.inv_mass_barrier),
            integ.i.payload.force.eq(n2_frc.force), integ.i.payload.inside.eq(n2_frc.inside),
            integ.dt.eq(step_dt), integ.half_dt_sq.eq(step_half), integ.damping.eq(unit_constants["damping"]),
            integ.momentum.eq(unit_constants["momentum"]),
        ]
        node_out_index = Signal(range(cap.vertices + 1))
        power_sum = Signal(signed(fs.power.width + cap.vertices.bit_length()))
        with m.If(integ.o.valid):
            m.d.sync += [node_out_index.eq(node_out_index + 1), power_sum.eq(power_sum + integ.o.payload.power)]

        # ------------------------------------------------------------ bus: decode
        # The request's address is decoded into flip-flops (REQ: the handshake's request; DEC: the
        # decode registered, ``bus_request``), and every action starts from them: the decode of a
        # 14-bit address into every register's write enable and the answer was the next critical
        # path once the memories' outputs had landed.
        n_windows = len(rmap.windows)
        bus_window = Signal(range(n_windows + 1))  # n_windows: none
        bus_index = Signal(max(cap.vertices, cap.entries, cap.triangles).bit_length())
        bus_word = Signal(range(max(w.words for w in rmap.windows) + 1))
        window_ok = Signal()
        for k, w in enumerate(rmap.windows):
            size_bits = (w.size - 1).bit_length()
            stride_bits = (w.stride - 1).bit_length()
            with m.If(hs.address[size_bits:] == (w.base >> size_bits)):
                index = hs.address[stride_bits:size_bits]
                word = hs.address[:stride_bits] if stride_bits else Const(0, 1)
                m.d.comb += [bus_window.eq(k), bus_index.eq(index), bus_word.eq(word),
                             window_ok.eq((index < w.depth) & (word < w.words))]
        with m.If(~window_ok):
            m.d.comb += bus_window.eq(n_windows)
        registers = rmap.registers
        bus_request = Signal()
        reg_select = Signal(len(registers))  # one-hot: the register addressed, if any
        window_q = Signal.like(bus_window)
        index_q = Signal.like(bus_index)
        word_q = Signal.like(bus_word)
        m.d.sync += [bus_request.eq(hs.request), window_q.eq(bus_window), index_q.eq(bus_index), word_q.eq(bus_word),
                     reg_select.eq(Cat(hs.address == r.offset for r in registers))]
        bus_reg_hit = reg_select.any()
        bus_write = bus_request & hs.write & hs.whole_word

        # register reads and writes: the write acts in DEC's clock; the answer comes the clock after,
        # from the read word landed in a register (an AND-OR over the one-hot select)
        read_word = Signal(BUS_WORD_BITS)
        read_only = Signal()
        # CONTROL's START and ABORT act from flip-flops the clock after the write (the bus decode into
        # the phase machine and on into the units' controls was the engine's critical path, 69 MHz)
        start_pulse, abort_pulse = Signal(), Signal()
        m.d.sync += [start_pulse.eq(0), abort_pulse.eq(0)]
        status_code = {"state": state, "result": result, "irq_pending": irq_pending}
        saturated = Signal()  # STATUS.saturated: SATURATIONS != 0, registered (a 32-bit OR off the read path)
        m.d.sync += saturated.eq(values["saturations"] != 0)
        read_terms, read_only_terms = [], []
        for k, r in enumerate(registers):
            selected = reg_select[k]
            word = Signal(BUS_WORD_BITS, name=f"rd_{r.name.lower()}")
            pieces = []  # (lsb, value) of each field
            for f in r.fields:
                if r.name == "CONTROL":
                    source = {"start": Const(0, 1), "abort": Const(0, 1), "irq_enable": irq_enable}[f.name]
                elif r.name == "STATUS":
                    source = status_code.get(f.name)
                    if f.name == "saturated":
                        source = saturated
                elif r.access == "ro" and r.reset and r.block == "identification":
                    source = Const((r.reset >> f.lsb) & ((1 << f.width) - 1), f.width)
                else:
                    source = values[f.value][f.value_lsb:f.value_lsb + f.width]
                pieces.append((f.lsb, Value.cast(source).as_unsigned()[:f.width], f.width))
            # the whole word in one assignment, unused bits as constant zeros beside the fields: a
            # separate constant-only assignment becomes an input-less `always @*` block in the
            # Verilog, which an event-driven simulator (Icarus) never runs
            parts, at = [], 0
            for lsb, value, width in sorted(pieces, key=lambda p: p[0]):
                parts += [Const(0, lsb - at)] if lsb > at else []
                parts.append(value)
                parts += [Const(0, width - len(value))] if len(value) < width else []
                at = lsb + width
            m.d.comb += word.eq(Cat(*parts))
            read_terms.append(Mux(selected, word, 0))
            if r.access == "ro":
                read_only_terms.append(selected)
            written = {f.name: hs.write_data[f.lsb:f.lsb + f.width] for f in r.fields}
            with m.If(bus_write & selected):
                if r.name == "CONTROL":
                    m.d.sync += [start_pulse.eq(written["start"]), abort_pulse.eq(written["abort"]),
                                 irq_enable.eq(written["irq_enable"])]
                elif r.name == "STATUS":
                    with m.If(written["irq_pending"]):
                        m.d.sync += irq_pending.eq(0)
                elif r.access == "rw":
                    for f in r.fields:
                        m.d.sync += values[f.value][f.value_lsb:f.value_lsb + f.width].eq(
                            hs.write_data[f.lsb:f.lsb + f.width])
        # The AND-OR over the one-hot select in two clocks: groups of eight registers, each OR landed in
        # a register of its own, then their OR (one clock from reg_select through the whole tree into
        # the landed word, 6.4 ns of it routing, was 4a4a5ea's critical path with seed 1)
        read_groups = [Signal(BUS_WORD_BITS, name=f"read_group{k}", reset_less=True)
                       for k in range(0, len(read_terms), 8)]
        m.d.sync += [group.eq(_or_all(read_terms[8 * k:8 * k + 8])) for k, group in enumerate(read_groups)]
        m.d.comb += read_word.eq(_or_all(read_groups))
        m.d.sync += read_only.eq(_or_all(read_only_terms))
        # identification values are constants
        for name in ("cap_vertices", "cap_entries", "cap_triangles"):
            m.d.comb += values[name].eq(getattr(cap, name[4:]))

        # memory windows: DEC forms the port addresses (in the memories' address registers the clock
        # after), then the block RAM read, the whole word landed in a register (the memories'
        # outputs come from all over the device), then the answer and, for a write, the modified
        # word written back
        bus_mem = ~running & (window_q != n_windows)
        # address registered, data, landed, the entry bank's word selected (the other windows' data
        # delayed alike), the whole word in the window's register (the write-back formed), the bus
        # word landed (the answer)
        mem_steps = [Signal(name=f"mem_step{k}") for k in range(6)]
        m.d.sync += [mem_steps[0].eq(bus_request & bus_mem), *(mem_steps[k].eq(mem_steps[k - 1]) for k in range(1, 6))]
        mem_landed, mem_answer = mem_steps[4], mem_steps[5]
        mem_data = Signal(BUS_WORD_BITS)
        mem_word = Signal(BUS_WORD_BITS, reset_less=True)
        m.d.sync += mem_word.eq(mem_data)
        # the word's select, one flip-flop per (window, word), set the clock after DEC from the decode
        # (long before the entry lands): the answer and the write-back are AND-OR selects from flip-flops
        word_hot = {(k, j): Signal(name=f"word_hot_{w.name}_{j}")
                    for k, w in enumerate(rmap.windows) for j in range(w.words)}
        m.d.sync += [hot.eq((window_q == k) & (word_q == j)) for (k, j), hot in word_hot.items()]
        answer_terms, new_words = [], {}
        for k, w in enumerate(rmap.windows):
            if w.name == "entries":
                word_value = ent_data.as_value()  # selected at the third clock after the address
            else:
                if w.name == "nodes":
                    read_data = Cat(pos_a.data.x, pos_a.data.y, vel_r.data.x, vel_r.data.y, wgt_r.data.inv_mass,
                                    wgt_r.data.inv_mass_barrier)
                else:
                    read_data = tri_r.data.as_value()
                # the memories' data has landed (BlockRam); one more clock aligns it with the entry bank's select
                word_value = Signal(len(read_data), name=f"bus_{w.name}_aligned", reset_less=True)
                m.d.sync += word_value.eq(read_data)
            padded = Signal(w.words * BUS_WORD_BITS, name=f"bus_{w.name}_word", reset_less=True)
            m.d.sync += padded.eq(word_value)
            words = [padded.word_select(j, BUS_WORD_BITS) for j in range(w.words)]
            answer_terms += [Mux(word_hot[k, j], words[j], 0) for j in range(w.words)]
            modified = Cat(*(Mux(word_hot[k, j], hs.write_data, words[j]) for j in range(w.words)))
            new_words[w.name] = (k, modified[:len(word_value)])
        m.d.comb += mem_data.eq(_or_all(answer_terms))
        bus_writing = mem_landed & hs.write & hs.whole_word

        # ------------------------------------------------------------ port multiplexing
        # Read addresses: the bus while idle, else the pass in progress, into a register per port
        # (the block RAMs' address inputs come from flip-flops).
        read_ports = {"pos_a": pos_a, "pos_b": pos_b, "pos_c": pos_c, "vel": vel_r, "wgt": wgt_r, "frc": frc_r,
                      "tri": tri_r}
        read_addr = {name: Signal.like(port.addr, name=f"{name}_addr") for name, port in read_ports.items()}
        m.d.comb += [port.addr.eq(read_addr[name]) for name, port in read_ports.items()]
        # Each register loads every clock (a read has no side effect), from as few sources as it
        # needs, selected by flip-flops (running, the phase flags): the entries and triangles
        # memories by the bus or their pass's counter, the node memories by the bus or the integrate
        # pass's, the second and third position ports by the area or the force pass.
        in_nodes = fetch_nodes | in_phase["integrate"]
        m.d.sync += [
            ent_addr.eq(Mux(running, entry_index, index_q)),
            read_addr["tri"].eq(Mux(running, tri_index, index_q)),
            *(read_addr[n].eq(Mux(running, node_index, index_q)) for n in ("vel", "wgt", "frc")),
            read_addr["pos_b"].eq(Mux(in_phase["area"], t2_tri.b, ent_data.neighbour)),
            read_addr["pos_c"].eq(Mux(in_phase["area"], t2_tri.c, ent_data.second)),
            read_addr["pos_a"].eq(Mux(~running | in_nodes, Mux(running, node_index, index_q),
                                      Mux(in_phase["area"], t2_tri.a, node_of_entry))),
        ]
        # Writes: the bus's read-modify-write while idle, the integrator's results while running, each
        # port's address, data and enable landed in registers before the block RAM.
        node_k, node_new = new_words["nodes"]
        ent_k, ent_new = new_words["entries"]
        tri_k, tri_new = new_words["triangles"]
        write_ports = {"pos": pos_w, "vel": vel_w, "wgt": wgt_w, "ent": None, "tri": tri_w}
        write_regs = {}
        for name, port in write_ports.items():
            if port is None:  # the entry banks: the bank's port enabled by the address's high bits
                regs = (Signal.like(ent_addr, name="ent_waddr"), Signal(entry_shape, name="ent_wdata"),
                        Signal(name="ent_wen"))
                for b, bank_port in enumerate(ent_ws):
                    hit = regs[0][bank_bits:] == b if len(ent_ws) > 1 else 1
                    m.d.comb += [bank_port.addr.eq(regs[0][:bank_bits]), bank_port.data.eq(regs[1]),
                                 bank_port.en.eq(regs[2] & hit)]
            else:
                regs = (Signal.like(port.addr, name=f"{name}_waddr"), Signal.like(port.data, name=f"{name}_wdata"),
                        Signal(name=f"{name}_wen"))
                m.d.comb += [port.addr.eq(regs[0]), port.data.eq(regs[1]), port.en.eq(regs[2])]
            write_regs[name] = regs
        with m.If(running):
            m.d.sync += [write_regs["pos"][0].eq(node_out_index), write_regs["pos"][1].eq(integ.o.payload.position),
                         write_regs["pos"][2].eq(integ.o.valid),
                         write_regs["vel"][0].eq(node_out_index), write_regs["vel"][1].eq(integ.o.payload.velocity),
                         write_regs["vel"][2].eq(integ.o.valid),
                         write_regs["wgt"][2].eq(0), write_regs["ent"][2].eq(0), write_regs["tri"][2].eq(0)]
        with m.Else():
            m.d.sync += [
                *(write_regs[n][0].eq(index_q) for n in write_ports),
                Cat(write_regs["pos"][1].as_value(), write_regs["vel"][1].as_value(),
                    write_regs["wgt"][1].as_value()).eq(node_new),
                write_regs["ent"][1].eq(ent_new), write_regs["tri"][1].eq(tri_new),
                *(write_regs[n][2].eq(bus_writing & (window_q == node_k)) for n in ("pos", "vel", "wgt")),
                write_regs["ent"][2].eq(bus_writing & (window_q == ent_k)),
                write_regs["tri"][2].eq(bus_writing & (window_q == tri_k)),
            ]

        # bus answers, every one from flip-flops: a register two clocks after DEC (its read word and error
        # landed, the word through two clocks of AND-OR), an unmapped word (or a memory while running)
        # the clock after DEC, a memory window five clocks after that
        reg_pending, reg_answer, refused = Signal(), Signal(), Signal()
        landed_word = Signal(BUS_WORD_BITS, reset_less=True)
        landed_error = Signal(reset_less=True)
        m.d.sync += [reg_pending.eq(bus_request & bus_reg_hit), reg_answer.eq(reg_pending),
                     refused.eq(bus_request & ~bus_reg_hit & ~bus_mem),
                     landed_word.eq(read_word), landed_error.eq((read_only & hs.write) | ~hs.whole_word)]
        with m.If(reg_answer):
            m.d.comb += [hs.done.eq(1), hs.error.eq(landed_error), hs.data.eq(landed_word)]
        with m.Elif(refused):
            m.d.comb += [hs.done.eq(1), hs.error.eq(1)]
        with m.Elif(mem_answer):
            m.d.comb += [hs.done.eq(1), hs.error.eq(~hs.whole_word), hs.data.eq(mem_word)]

        # ------------------------------------------------------------ controller
        iterations = values["iterations"]
        area_error_raw, shape_error_raw = values["area_error"], values["shape_error"]
        saturations = values["saturations"]
        cycles = values["cycles"]
        # CYCLES counts in two 32-bit halves, the high half a clock behind the low half's wrap (a 64-bit
        # carry chain in one clock was among the longest paths); it is exact a clock after the run
        half = len(cycles) // 2
        cycles_wrapped = Signal()
        m.d.sync += cycles_wrapped.eq(running & (cycles[:half] == (1 << half) - 1))
        with m.If(running):
            m.d.sync += cycles[:half].eq(cycles[:half] + 1)
        with m.If(cycles_wrapped):
            m.d.sync += cycles[half:].eq(cycles[half:] + 1)

        momentum_k = Signal(len(beta.i.payload))
        restart_pending = Signal()
        step_was_restart = Signal()
        first_measure = Signal()
        math_pending = Signal(3)  # length, area, energy results still to come
        settled = Signal()
        area_clear = Signal()
        # the register is as wide as the energy check's tolerance (both from the golden model's
        # ENERGY_TOL_* bits), so every value START sees is valid
        assert len(values["tol_energy"]) == len(energy.tolerance), (len(values["tol_energy"]), len(energy.tolerance))

        length_total = Mux(length_sum > fs.error_acc.raw_max, fs.error_acc.raw_max, length_sum)
        # The units' requests: valid set by the phase machine and held until taken; the payloads
        # are the sums and registers themselves, which hold still from the end of their pass until
        # the unit's result is in (the next pass starts after the math phase).
        m.d.comb += [
            energy.half_spring.eq(unit_constants["half_spring"]),
            energy.tolerance.eq(unit_constants["tol_energy"]),
            norm_length.o.ready.eq(1), norm_area.o.ready.eq(1), energy.o.ready.eq(1), beta.o.ready.eq(1),
            stepgen.o.ready.eq(1),
            area.clear.eq(area_clear),
            norm_length.i.payload.sum.eq(length_total),
            norm_length.i.payload.mantissa.eq(unit_constants["length_reciprocal"]),
            norm_length.i.payload.shift.eq(unit_constants["length_shift"]),
            energy.i.payload.square_sum.eq(square_sum), energy.i.payload.barrier_sum.eq(barrier_sum),
            energy.i.payload.first.eq(first_measure),
            norm_area.i.payload.sum.eq(area.total),
            norm_area.i.payload.mantissa.eq(unit_constants["area_reciprocal"]),
            norm_area.i.payload.shift.eq(unit_constants["area_shift"]),
            stepgen.i.payload.area_error.eq(area_error_raw), stepgen.i.payload.shape_error.eq(shape_error_raw),
        ]
        for unit in (norm_length, norm_area, energy, beta, stepgen):
            with m.If(unit.i.valid & unit.i.ready):
                m.d.sync += unit.i.valid.eq(0)
        with m.If(norm_length.o.valid):
            m.d.sync += [shape_error_raw.eq(norm_length.o.payload.error), math_pending[0].eq(0)]
        with m.If(norm_area.o.valid):
            m.d.sync += [area_error_raw.eq(norm_area.o.payload.error), math_pending[1].eq(0)]
        with m.If(energy.o.valid):
            m.d.sync += [values["energy"].eq(energy.o.payload.energy), settled.eq(energy.o.payload.settled),
                         math_pending[2].eq(0)]
        with m.If(beta.o.valid):
            m.d.sync += step_dt.eq(beta.o.payload)
        with m.If(stepgen.o.valid):
            m.d.sync += [step_dt.eq(stepgen.o.payload.dt), step_half.eq(stepgen.o.payload.half_dt_sq)]
        # the fixed step is loaded the clock after the step phase (from a flip-flop, as the units'
        # results are), long before the integrate pass's first node reaches the integrator
        fixed_load = Signal()
        m.d.sync += fixed_load.eq(0)
        with m.If(fixed_load):
            m.d.sync += [step_dt.eq(values["dt"]), step_half.eq(fixed_half)]

        def finish(code):
            set_state("done")
            m.d.sync += [result.eq(_code(RESULTS, code)), irq_pending.eq(1)]  # (no pass is fetching then)

        fetching = Cat(*e_valid, *t_valid, *n_valid).any()
        units_idle = force.idle & area.idle & integ.idle & ~fetching

        # START's checks of the run constants, as golden_model's constant_fault states them
        top = 1 << (fs.reciprocal.width - 1)
        reciprocal_bad = [(values[f"{k}_reciprocal"] < top) | (values[f"{k}_reciprocal"] >= 2 * top)
                          | (values[f"{k}_shift"] < fs.error.frac_bits + 2) for k in ("area", "length")]
        bad_constants = ((n_vertices > cap.vertices) | (n_entries > cap.entries) | (n_triangles > cap.triangles)
                         | (n_entries == 0) | (n_triangles == 0) | reciprocal_bad[0] | reciprocal_bad[1]
                         | (mode_fixed & ~mode_momentum & (values["dt"] == 0)) | (values["max_iter"] == 0))
        stepgen_idle = stepgen_idle_signal(m, stepgen)
        # START's and the check phase's decisions from flip-flops: each comparison registered the clock
        # before it is used. What they read is stable by then (START follows the last constant's write by
        # a whole bus cycle; the check phase follows the math phase, after every pass and unit has
        # reported), and the controller's next-state logic starts from one flag instead of a 32-bit
        # compare (MAX_ITER against the iteration count into the phase machine was the engine's
        # critical path, 84 MHz on ECP5-85F).
        limit = values["saturation_limit"]
        no_mesh_q, bad_constants_q, converged_q, diverged_q, at_max_iter_q = (
            Signal(name=n) for n in ("no_mesh_q", "bad_constants_q", "converged_q", "diverged_q", "at_max_iter_q"))
        m.d.sync += [no_mesh_q.eq(n_vertices == 0), bad_constants_q.eq(bad_constants),
                     converged_q.eq((area_error_raw <= values["tol_area"]) & (shape_error_raw <= values["tol_shape"])
                                    & settled),
                     diverged_q.eq((limit != 0) & (saturations >= limit)),
                     at_max_iter_q.eq(iterations == values["max_iter"])]
        # The passes' ends, registered the same way: a pulse the clock after the pass's last result
        # (its counter's compare and the units' idle flags stay off the phase machine's logic).
        force_done, area_done, integrate_done = Signal(), Signal(), Signal()
        area_fetching = Cat(*t_valid).any()
        m.d.sync += [
            force_done.eq(in_phase["force"] & (force_out_index == n_vertices) & ~force_done),
            area_done.eq(in_phase["area"] & (tri_index == n_triangles) & ~area_fetching & area.idle
                         & ~area_clear & ~area_done),
            integrate_done.eq(in_phase["integrate"] & (node_out_index == n_vertices)
                              & ~integrate_done),
        ]

        # SATURATIONS: every event the golden model counts, added as the units report them, stopping at
        # its maximum. The force pass's, integrate stage's and step generator's per beat; the area pass's
        # at its end; the E_C sum's (length_sum) when the force pass ends; S's (power_acc) when an
        # integrate pass ends (momentum); E_S's and E_C's (an error of 1 or more) as the normalisers
        # answer. Each event lands in a register, the pairs' sums in four, their sum in another (six
        # counts summed in one clock were d06964b's critical path, 118.4 MHz), then the count: a unit's
        # event is in SATURATIONS four clocks after the unit reports it, and in diverged_q one later, so
        # the math phase holds the check phase back until the normalisers' events are in
        # (CHECK_SETTLE_CLOCKS).
        events = [
            Mux(force.o.valid, force.o.payload.saturations, 0),
            Mux(integ.o.valid & running, integ.o.payload.saturations, 0),
            Mux(stepgen.o.valid, stepgen.o.payload.saturations, 0),
            Mux(area_done, area.saturations.face_edge + area.saturations.face_area + area.saturations.area_sum, 0),
            force_done & (length_sum > fs.error_acc.raw_max),
            integrate_done & mode_momentum & ((power_sum > fs.power_acc.raw_max) | (power_sum < fs.power_acc.raw_min)),
            norm_length.o.valid & norm_length.o.payload.saturations,
            norm_area.o.valid & norm_area.o.payload.saturations,
        ]
        event_regs = [Signal(len(Value.cast(e)), name=f"saturation_event{k}") for k, e in enumerate(events)]
        m.d.sync += [r.eq(e) for r, e in zip(event_regs, events)]
        new_events = Signal(max(len(r) for r in event_regs) + 3)
        pair_sums = [Signal(len(new_events) - 1, name=f"saturation_pair{k}") for k in range(len(event_regs) // 2)]
        m.d.sync += [p.eq(event_regs[2 * k] + event_regs[2 * k + 1]) for k, p in enumerate(pair_sums)]
        assert len(event_regs) == 2 * len(pair_sums)
        m.d.sync += new_events.eq(sum(pair_sums))
        total = saturations + new_events
        saturation_max = (1 << len(saturations)) - 1
        m.d.sync += saturations.eq(Mux(total > saturation_max, saturation_max, total))
        sequential_idle = ~Cat(*(u.i.valid for u in (norm_length, norm_area, energy, beta, stepgen))).any() \
            & norm_length.i.ready & norm_area.i.ready & energy.i.ready & beta.i.ready & stepgen_idle
        m.d.sync += area_clear.eq(0)
        # the drain's end, registered (the OR of every fetch stage's valid bit and the units' idle flags
        # into the fetch flags' enables was the critical path): once true it stays true, as nothing
        # starts while draining. The fetch counters' compares are registered a clock before it (the
        # triangle counter's compare into `drained` was 6b90691's critical path, 130.6 MHz): no pass
        # starts in the drain phase or on the abort clock before it, so that clock's lag is never stale.
        done_fetching = Signal()
        m.d.sync += done_fetching.eq(((entry_index == n_entries) | ~fetch_force)
                                     & ((tri_index == n_triangles) | ~fetch_area)
                                     & ((node_index == n_vertices) | ~fetch_nodes))
        drained = Signal()
        m.d.sync += drained.eq(in_phase["drain"] & units_idle & sequential_idle & done_fetching)
        # ABORT while running drains what is in flight (still "running": START is ignored and the memories
        # answer err until nothing can write them any more), then goes idle with no result. The pass under
        # way fetches to its end (a node half fed to the force pass would never leave it).
        # The passes' counters and sums restart from a phase flag, outside the phase machine's priority
        # logic: the force and area passes' in the start phase, the integrate pass's in the step phase.
        with m.If(in_phase["start"]):
            m.d.sync += [entry_index.eq(0), node_of_entry.eq(0), next_first.eq(1), force_out_index.eq(0),
                         length_sum.eq(0), square_sum.eq(0), barrier_sum.eq(0), tri_index.eq(0)]
        with m.If(in_phase["step"]):
            m.d.sync += [node_index.eq(0), node_out_index.eq(0), power_sum.eq(0)]
        with m.If(abort_pulse & running):
            m.d.sync += [flag.eq(name == "drain") for name, flag in in_phase.items()]
            for unit in (norm_length, norm_area, energy, beta, stepgen):
                m.d.sync += unit.i.valid.eq(0)
        with m.If(abort_pulse & ~running):
            set_state("idle")
            m.d.sync += result.eq(_code(RESULTS, "none"))
        with m.If(start_pulse & ~abort_pulse & ~running):
            m.d.sync += [cycles.eq(0), cycles_wrapped.eq(0), iterations.eq(0), saturations.eq(0), irq_pending.eq(0),
                         result.eq(_code(RESULTS, "none"))]
            with m.If(no_mesh_q):
                finish("no-mesh")
            with m.Elif(bad_constants_q):
                finish("bad-constants")
            with m.Else():
                set_state("running")
                m.d.sync += [in_phase["start"].eq(1), first_measure.eq(1)]
        # The phase machine: one block per phase, each enabled by its one-hot flag (and the pass-end
        # pulse it waits for), not by a decode of a phase code under ``running``: ``running`` fans out
        # to every port multiplexer, and the counters behind it (ITERATIONS, momentum_k) were the
        # engine's longest paths. The flags are low while idle, so none of these needs ``running``.
        go = ~abort_pulse
        with m.If(go & in_phase["start"]):  # a measurement: the force pass
            m.d.sync += [fetch_force.eq(1), *move("start", "force")]
        with m.If(go & in_phase["force"] & force_done):
            m.d.sync += [fetch_force.eq(0), fetch_area.eq(1), *move("force", "area"),
                         math_pending.eq(0b111), norm_length.i.valid.eq(1), energy.i.valid.eq(1),
                         area_clear.eq(1)]
        with m.If(go & in_phase["area"] & area_done):
            m.d.sync += [fetch_area.eq(0), *move("area", "math"), norm_area.i.valid.eq(1)]
        # the last result's clock t clears its math_pending bit (seen at t+1); its event reaches diverged_q
        # at t+5: the check phase starts then, CHECK_SETTLE_CLOCKS after math_pending reads 0
        math_settle = [Signal(name=f"math_settle{k}") for k in range(self.CHECK_SETTLE_CLOCKS)]
        m.d.sync += [math_settle[0].eq(in_phase["math"] & (math_pending == 0)),
                     *(math_settle[k].eq(math_settle[k - 1]) for k in range(1, len(math_settle)))]
        with m.If(go & in_phase["math"] & math_settle[-1]):
            m.d.sync += move("math", "check")
        with m.If(go & in_phase["check"]):
            # as run_image: the saturation limit first, then the stop rule (neither after the first
            # measurement), then the iteration limit
            m.d.sync += move("check")  # to the step phase, or the run is over
            with m.If(diverged_q & ~first_measure):
                finish("diverged")
            with m.Elif(converged_q & ~first_measure):
                finish("converged")
            with m.Elif(at_max_iter_q):
                finish("max-iterations")
            with m.Else():
                m.d.sync += [first_measure.eq(0), *move("check", "step")]
        # The 32-bit registers stay off the phase machine's enables (a control LUT that also drove
        # momentum_k's 32 flip-flops was placed beside them: 6780c63's critical paths). The divider's
        # k is loaded on every clock: momentum_k and restart_pending stand still from the step phase
        # until the divider takes the request, the clock after; they and ITERATIONS move on a
        # registered pulse the clock after their phase's block.
        # restart_pending's decision too (control → restart_pending through two far LUTs was d40a96c's
        # critical path): every pulse, and S's sign, is a flip-flop of its own, and restart_pending is
        # cleared by a pulse of its own (restart_clear: the launch's or the step's), not by the pulses
        # that move momentum_k: a LUT that ABC shared between momentum_k's 32-bit update and
        # restart_pending's enable, placed beside momentum_k, was 1db0307's critical path (127.2 and
        # 126.7 MHz, seeds 1 and 2).
        m.d.sync += beta.i.payload.eq(Mux(restart_pending, 0, momentum_k))
        launch_pulse, step_pulse, iterate_pulse, restart_pulse, restart_clear, power_negative = (
            Signal(name=n) for n in ("launch_pulse", "step_pulse", "iterate_pulse", "restart_pulse",
                                     "restart_clear", "power_negative"))
        launching = in_phase["start"] & first_measure
        stepping = go & in_phase["step"] & mode_momentum
        m.d.sync += [launch_pulse.eq(launching), step_pulse.eq(stepping), restart_clear.eq(launching | stepping),
                     iterate_pulse.eq(go & in_phase["integrate"] & integrate_done),
                     restart_pulse.eq(go & in_phase["integrate"] & integrate_done & mode_momentum & ~step_was_restart),
                     power_negative.eq(power_sum < 0)]
        with m.If(launch_pulse):  # a run's start: no momentum yet
            m.d.sync += momentum_k.eq(0)
        with m.If(step_pulse):
            m.d.sync += [momentum_k.eq(Mux(restart_pending, 1, momentum_k + 1)), step_was_restart.eq(restart_pending)]
        with m.If(restart_clear):
            m.d.sync += restart_pending.eq(0)
        with m.If(restart_pulse):
            m.d.sync += restart_pending.eq(power_negative)
        with m.If(iterate_pulse):
            m.d.sync += iterations.eq(iterations + 1)
        with m.If(go & in_phase["step"]):
            with m.If(mode_momentum):
                m.d.sync += beta.i.valid.eq(1)
            with m.Elif(mode_fixed):
                m.d.sync += fixed_load.eq(1)
            with m.Else():
                m.d.sync += stepgen.i.valid.eq(1)
            m.d.sync += move("step", "step_wait")
        waiting = beta.i.valid | ~beta.i.ready | stepgen.i.valid | ~stepgen.i.ready
        with m.If(go & in_phase["step_wait"] & ~waiting & ~beta.o.valid & ~stepgen.o.valid & stepgen_idle):
            m.d.sync += [fetch_nodes.eq(1), *move("step_wait", "integrate")]
        with m.If(go & in_phase["drain"] & drained):
            set_state("idle")
            m.d.sync += move("drain")
            m.d.sync += [result.eq(_code(RESULTS, "none")),
                         fetch_force.eq(0), fetch_area.eq(0), fetch_nodes.eq(0)]
        with m.If(go & in_phase["integrate"] & integrate_done):
            m.d.sync += [fetch_nodes.eq(0), *move("integrate", "start")]
        # Internal state a testbench may watch (``debug_signals``) or read (``debug_memories``).
        self.debug_memories = {"positions": positions.contents, "velocities": velocities.contents}
        self.debug_signals = {"state": state, "phase": phase, "entry_index": entry_index,
                              "force_out_index": force_out_index, "tri_index": tri_index,
                              "node_out_index": node_out_index, "math_pending": math_pending,
                              "iterations": iterations}
        return m


def _fetch_sequencer(m: Module, index_name: str, fetch_name: str, valid_prefix: str, stages: int,
                     capacity: int, count: Value) -> tuple[Signal, Signal, list[Signal]]:
    """A pass's fetch: while the ``fetch`` flag (set by the controller) is high, the ``index``
    counts 0, 1, … up to ``count`` (at most ``capacity``), one issued per clock, and ``valid[k]``
    marks the clock whose data belongs to an index issued ``k`` clocks ago (``valid[0]``: the
    index in the memories' address registers). Returns ``(index, fetch, valid)``."""
    index = Signal(range(capacity + 1), name=index_name)
    fetch = Signal(name=fetch_name)
    valid = [Signal(name=f"{valid_prefix}{k}_valid") for k in range(stages)]
    issue = fetch & (index < count)
    m.d.sync += [valid[0].eq(issue), *(valid[k].eq(valid[k - 1]) for k in range(1, stages))]
    with m.If(issue):
        m.d.sync += index.eq(index + 1)
    return index, fetch, valid


def _or_all(values) -> Value:
    """The OR of ``values`` as a balanced tree (an AND-OR multiplexer's second half)."""
    values = [Value.cast(v) for v in values]
    while len(values) > 1:
        values = [values[k] | values[k + 1] if k + 1 < len(values) else values[k] for k in range(0, len(values), 2)]
    return values[0]
