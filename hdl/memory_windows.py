"""The engine's memories and their bus windows: every block RAM, the entry memory's banks, the bus's
read-modify-write of a window word, and each port's multiplexer between the bus and the passes."""

from __future__ import annotations

from amaranth.hdl import Array, Cat, Const, Module, Mux, Shape, Signal, Value
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import BUS_WORD_BITS, EngineCapacity, memory_layouts
from golden_model.engine_spec.register_map import RegisterMap

from .block_ram import BlockRam, dp16kd_banks, kept_per_slice
from .dsp import kept_register
from .layouts import force_word_layout, vector_layout, weight_word_layout, word_layout
from .logic import or_tree
from .parameters import check_power_of_two
from .rom import ENTRY_BANK_DEPTH

__all__ = ["ENTRY_BANK_LATENCY", "ENTRY_LATENCY", "MemoryWindows", "READ_LATENCY", "WINDOW_STEPS", "entry_latency",
           "matrix_read_latency", "needs_registered_select", "node_read_latency", "node_write_layout", "window_steps",
           "write_signature"]

#: Clocks from a block RAM's read address register to its data landed (:attr:`BlockRam.LATENCY`), for the
#: node and triangle memories of a capacity whose node memories are one bank each and have no pin registers
#: (:attr:`MemoryWindows.read_latency`).
READ_LATENCY = BlockRam.LATENCY


def needs_registered_select(fs: FormatSet, capacity: EngineCapacity) -> bool:
    """Whether the node memories take more than one bank of ``DP16KD`` (:func:`hdl.block_ram.dp16kd_banks`):
    then the node and triangle memories select their banks in registered stages (:class:`BlockRam`'s
    ``registered_select``), as the entry memory does: a bank multiplexer after the output registers of
    banks spread over the die is a route across it with logic on the way (``docs/synthesis.md``)."""
    return dp16kd_banks(capacity.vertices, vector_layout(fs.position).size)[2] > 1


#: The entry memory's bank select after the banks' output registers, one registered stage each: every
#: bank's word kept or zeroed by that bank's own select flag in a register beside the bank, groups of
#: up to :data:`ENTRY_GROUP` banks ORed, the groups ORed.
ENTRY_SELECT_STAGES = 3
#: Banks per group in the select's second stage (one LUT4 per bit).
ENTRY_GROUP = 4
#: Clocks from an entry bank's read address to its data: a :class:`BlockRam` with ``pin_registers``.
ENTRY_BANK_LATENCY = BlockRam.LATENCY + 1
#: With the registered select, a relay register after each entry block RAM, before its kept register: the
#: block RAMs of a large build spread over the whole device, and one route from a block RAM to the kept
#: register, which the placer puts near its group's OR, can take most of a period with no logic on it.
ENTRY_RELAY_STAGES = 1


def entry_latency(registered_select: bool) -> int:
    """Clocks from the entry memory's address register (``ent_addr``) to the addressed entry in ``entry``:
    the banks' read, with ``registered_select`` the relay, the bank select."""
    return ENTRY_BANK_LATENCY + ENTRY_RELAY_STAGES * registered_select + ENTRY_SELECT_STAGES


def node_read_latency(registered_select: bool = False, pin_registers: bool = False, lanes: int = 1) -> int:
    """Clocks from a node or triangle memory's address register to its data (:attr:`MemoryWindows.read_latency`):
    the block RAM's, its pin registers' (implied by ``registered_select``), the bank select's stages, and with
    lanes the bank's word selected in a register of its own."""
    pin_registers = bool(pin_registers) or registered_select
    return READ_LATENCY + pin_registers + BlockRam.SELECT_STAGES * registered_select + (lanes > 1)


def matrix_read_latency(registered_select: bool = False, pin_registers: bool = False, lanes: int = 1) -> int:
    """With a coarse space, clocks from ``matrix_addr`` to its entry in ``matrix_word``
    (:attr:`MemoryWindows.matrix_read_latency`): the address register after the port's multiplexer, then
    :func:`node_read_latency`."""
    return 1 + node_read_latency(registered_select, pin_registers, lanes)


def window_steps(registered_select: bool) -> int:
    """Clocks from DEC to a window's answer: the address registered, the entry read (the other windows'
    data delayed alike), the whole word in the window's register (the write-back formed), the bus word
    landed."""
    return 1 + entry_latency(registered_select) + 2


#: :func:`entry_latency` and :func:`window_steps` of the builds up to ``DEFAULT_CAPACITY`` (no registered select).
ENTRY_LATENCY, WINDOW_STEPS = entry_latency(False), window_steps(False)


def write_signature(addr_shape, data_shape) -> wiring.Signature:
    """A write into a memory, the writer's view: ``data`` is written at ``addr`` at the clock edge where
    ``en`` is high."""
    return wiring.Signature({"addr": Out(addr_shape), "data": Out(data_shape), "en": Out(1)})


def node_write_layout(fs: FormatSet) -> data.StructLayout:
    """What the integrate pass writes back to a node: its position and velocity."""
    return data.StructLayout({"position": vector_layout(fs.position), "velocity": vector_layout(fs.velocity)})


class MemoryWindows(wiring.Component):
    """The node, entry and triangle memories (and the force memory) with their bus windows.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
    capacity : :class:`~golden_model.engine_spec.image.EngineCapacity`
    register_map : :class:`~golden_model.engine_spec.register_map.RegisterMap`
        Its windows (``nodes``, ``entries``, ``triangles``: base, stride, words).
    addr_width : int
        Width of the bus's word address.
    entry_bank_depth : int
        Words per bank of the entry memory (a power of two).
    registered_select : bool
        The node and triangle memories as the entry memory: every block RAM input in a register of its
        own (:class:`BlockRam`'s ``pin_registers``: a write lands a clock later) and the read data through
        its ``registered_select``; :attr:`read_latency` is four clocks more. The entry memory's bank flag
        is then a copy per block RAM (:meth:`_entry_read`; ``entry_bank_depth`` one ``DP16KD`` deep).
    pin_registers : bool
        The node and triangle memories' pin registers alone (implied by ``registered_select``): a write
        lands a clock later, :attr:`read_latency` is one clock more.

    Members
    -------
    address, bus_request, write, write_data, whole_word : ``In``
        The bus's registered request (:class:`~hdl.wishbone.TargetHandshake`) and DEC
        (:attr:`RegisterBank.bus_request <hdl.register_bank.RegisterBank>`).
    hit, answer, answer_data : ``Out``
        At DEC: the request is a window word's and the engine is idle (``hit``, combinational from
        flip-flops); ``answer`` with ``answer_data`` (the word read, a register) :attr:`window_steps`
        (nine, ten with ``registered_select``) clocks after DEC, for a write as for a read.
    running, in_area, in_integrate, fetch_nodes : ``In(1)``
        The controller's flip-flops that choose each port's source (with ``registered_select``, ``fetch_nodes``
        through a copy of its own beside the address multiplexers, a clock late, as the sequencer's
        down-counters issue).
    running_next : ``In(1)``
        With ``registered_select`` only: ``running``'s next value (the controller's), from which the read
        addresses' copies of ``running`` are loaded (cleared by the domain's reset, as ``running`` is):
        one each for the entry, the triangle and the node memories, placed by their address registers.
    entry_index, tri_index, node_index, node_of_entry : ``In``
        The passes' addresses (:class:`~hdl.pass_sequencer.PassSequencer`).
    entry, triangle, position[3], velocity, weight_word, force_word : ``Out``
        The passes' read data: ``entry`` (the addressed bank's word, a register)
        :attr:`entry_latency` (six, seven with ``registered_select``) clocks after the entry address is in
        ``ent_addr``, every other
        port :attr:`read_latency` (two, three with ``pin_registers``, six with ``registered_select``) clocks
        after its address register.
    force_write : ``In(write_signature(...))``
        The force pass's per-node results: written to the force memory (not on the bus).
    node_write : ``In(write_signature(...))``
        The integrator's results: written back to the position and velocity memories while running.
    proposal, proposal_write : ``Out``, ``In(write_signature(...))``
        The guarded step's proposals [velocity]: three read ports, each at its position port's address
        (``proposal[k]`` beside ``position[k]``), written while running; not on the bus. A capacity
        without ``guard`` has no proposal memory (``proposal`` reads 0).

    Port sources
    ------------
    Every block RAM address comes from a register after its multiplexer (each register loads every
    clock, from as few sources as it needs, chosen by flip-flops): while idle the bus's index, while
    running the entry and triangle memories their pass's counter, the node memories the integrate
    pass's, the position memory's second and third ports the entry's neighbour and second node or
    the triangle's corners, its first port the node of the entry, a corner or the integrate pass's
    node. Writes: the bus's read-modify-write while idle, the integrator's results while running,
    each port's address, data and enable landed in registers before the block RAM, the choice made by a
    copy of ``running`` of the port's own, a clock late. Every memory is
    a :class:`~hdl.block_ram.BlockRam` (its data in a register two clocks after the address); no read
    whose data is used meets a write to its address in the same clock (the passes read ahead of
    the integrate pass's writes; the bus reads and writes while idle, a word's write-back after its
    read): BlockRam's timing contract.

    With ``pin_registers`` the position and proposal memories are two copies each, not three: the third
    port (``position[2]``, ``proposal[2]``, the triangle's third corner and the entry's second node)
    reads the first copy's write port (:class:`~hdl.block_ram.BlockRam`'s ``shared_write_port``), so its
    word is undefined for an edge where that memory is written. Only the node passes (integrate, hold,
    commit, rollback) write them, and none of them uses the third port: the force, area and guard
    triangle passes, which do, start after a node pass's last write (the whole-run tests with the
    registered select compare every iteration with the golden model, on a generic form that answers
    such a read with all ones).

    The entry memory
    ----------------
    Its banks (``entries0``, ``entries1``, …) spread over the device, and so do one bank's block
    RAMs. Every block RAM input has a register of its own beside it (the banks are
    :class:`BlockRam` instances with ``pin_registers``: registered because one register fanning out to every
    block RAM crosses the device), and the addressed bank's word is selected in registered stages,
    so that no path crosses the device through logic:

    * read: E0 ``ent_addr`` and its one-hot bank flags ``ent_hot``; E1 the address in every block
      RAM's pin registers, and each bank's own select flag; E3 the banks' data
      (:data:`ENTRY_BANK_LATENCY`); E4 ``ent_kept<b>``: a bank's data, or 0 when the bank is not the
      one addressed (a register beside the bank, reset by the bank's flag: no logic between the
      output register and it); E5 ``ent_group<g>``: the OR of a group of banks; E6 ``entry``: the OR
      of the groups (:func:`entry_latency`). With the registered select a relay register
      ``ent_relay<b>`` comes first (E4), and each block RAM's slice of ``ent_kept<b>`` (E5) is reset by a
      copy of the flag of its own: every stage a route with no logic, so that each can be short, and the
      kept slice can sit by its block RAM's relay; E6 the groups, E7 ``entry``;
    * write (the bus's write-back only): the address, data and one-hot bank-enable registers, then
      the block RAMs' pin registers: a clock more, which the bus cycle absorbs (its next read comes
      after its answer).

    Lanes
    -----
    With ``capacity.lanes`` K > 1 (built without the guard and the pin registers): every node and
    triangle memory is K banks by the index's low bits, the position banks with three read ports per
    lane; a force memory per lane; the entry memory in K shares, each read as above by its lane
    (:meth:`_lane_rams`). The pass ports are per lane (:meth:`_lane_members`), every pass read one
    clock longer: the bank's word selected in a register. The bus's word of a node or triangle comes
    from its bank, of an entry from the share that holds it (the others read 0), and its write-back
    goes to that bank or share alone.
    """

    def __init__(self, fs: FormatSet, capacity: EngineCapacity, register_map: RegisterMap, *, addr_width: int,
                 entry_bank_depth: int = ENTRY_BANK_DEPTH, registered_select: bool = False,
                 pin_registers: bool = False):
        if not isinstance(fs, FormatSet) or not isinstance(capacity, EngineCapacity):
            raise TypeError(f"MemoryWindows needs a FormatSet and an EngineCapacity, not {fs!r}, {capacity!r}")
        if not isinstance(register_map, RegisterMap) or register_map.capacity != capacity:
            raise ValueError(f"MemoryWindows needs the RegisterMap of capacity {capacity}, not {register_map!r}")
        if sorted(w.name for w in register_map.windows) != sorted(memory_layouts(fs, capacity)):
            raise ValueError(f"MemoryWindows decodes the windows {sorted(memory_layouts(fs, capacity))}")
        check_power_of_two("entry_bank_depth", entry_bank_depth)
        self.fs, self.capacity, self.register_map = fs, capacity, register_map
        self.entry_bank_depth = entry_bank_depth
        self.registered_select = bool(registered_select)
        self.pin_registers = bool(pin_registers) or self.registered_select
        #: The lanes (``capacity.lanes``): K > 1 splits every node and triangle memory into K banks by the
        #: index's low bits and the entry memory into K shares (:meth:`_lane_rams`).
        self.lanes = lanes = capacity.lanes
        if lanes > 1 and (capacity.guard or self.pin_registers):
            raise ValueError(f"MemoryWindows: lanes={lanes} are built without the guard and without pin registers")
        #: Clocks from a node or triangle memory's address register to its data (with lanes, the bank's word
        #: selected in a register of its own).
        self.read_latency = node_read_latency(self.registered_select, self.pin_registers, lanes)
        #: With a coarse space, clocks from ``matrix_addr`` to its entry in ``matrix_word``: the address
        #: register after the port's multiplexer, then :attr:`read_latency`.
        self.matrix_read_latency = matrix_read_latency(self.registered_select, self.pin_registers, lanes)
        #: Clocks from ``ent_addr`` to ``entry`` (:func:`entry_latency`), and from DEC to a window's answer.
        self.entry_latency = entry_latency(self.registered_select)
        self.window_steps = window_steps(self.registered_select)
        assert self.read_latency <= self.entry_latency, "the bus aligns every window's word to the entry's"
        select = {"registered_select": self.registered_select, "pin_registers": self.pin_registers}
        # a triangle's three corners at once: where the pins are registered, the third port reads the first
        # copy's write port, and its address multiplexer sits before a pin register beside the block RAM
        # (the passes never read a corner at an edge with a write to the node memories: see the class)
        corners = {"read_ports": 3, "shared_write_port": self.pin_registers, **select}
        layouts = memory_layouts(fs, capacity)
        self.entry_shape, self.triangle_shape = word_layout(layouts["entries"]), word_layout(layouts["triangles"])
        entry_width = Shape.cast(self.entry_shape).width
        if self.registered_select and dp16kd_banks(entry_bank_depth, entry_width)[2] > 1:
            raise ValueError(f"MemoryWindows: with the registered select an entry bank is one DP16KD deep: "
                             f"entry_bank_depth={entry_bank_depth} of {entry_width}-bit entries is more")
        pos_shape, vel_shape = vector_layout(fs.position), vector_layout(fs.velocity)
        weight_shape, force_shape = weight_word_layout(fs), force_word_layout(fs)
        cap, banks = capacity, -(-capacity.entries // entry_bank_depth)
        #: The block RAMs by name (``contents`` for a testbench); the entries in banks of
        #: ``entry_bank_depth`` words: Yosys maps a bank of wide words to DP16KDs with no cascade,
        #: where a deeper memory gets a multiplexer after the block RAMs' outputs.
        self.rams = self._lane_rams(pos_shape, vel_shape, weight_shape, force_shape) if lanes > 1 else {
            "positions": BlockRam(pos_shape, cap.vertices, name="positions", **corners),
            "velocities": BlockRam(vel_shape, cap.vertices, name="velocities", **select),
            "weights": BlockRam(weight_shape, cap.vertices, name="weights", **select),
            "forces": BlockRam(force_shape, cap.vertices, name="forces", **select),
            "triangles": BlockRam(self.triangle_shape, cap.triangles, name="triangles", **select),
            # the guarded step's proposals, a read port per position port: with shared write ports one memory
            # of three ports, else a memory per port (the netlist DEFAULT_CAPACITY's timing rows were placed
            # from: a rename alone moves nextpnr's placement)
            **({} if not cap.guard else
               {"proposals": BlockRam(vel_shape, cap.vertices, name="proposals", **corners)} if self.pin_registers else
               {f"proposals{k}": BlockRam(vel_shape, cap.vertices, name=f"proposals{k}", **select) for k in range(3)}),
            **{f"entries{b}": BlockRam(self.entry_shape, min(entry_bank_depth, cap.entries - b * entry_bank_depth),
                                       name=f"entries{b}", pin_registers=True) for b in range(banks)},
            # the coarse space's basis (a word per node) and matrix, on the bus and read by the coarse passes
            **({} if not cap.coarse_degree else
               {name: BlockRam(word_layout(layouts[name]), layouts[name].depth, name=name, **select)
                for name in ("basis", "matrix")}),
        }
        if lanes > 1:
            super().__init__({**self._bus_members(addr_width),
                              **self._lane_members(pos_shape, vel_shape, weight_shape, force_shape)})
            return
        super().__init__({
            **self._bus_members(addr_width),
            **({"running_next": In(1)} if self.registered_select else {}),
            "entry_index": In(range(cap.entries + 1)), "tri_index": In(range(cap.triangles + 1)),
            "node_index": In(range(cap.vertices + 1)), "node_of_entry": In(range(cap.vertices + 1)),
            "entry": Out(self.entry_shape), "triangle": Out(self.triangle_shape), "position": Out(pos_shape).array(3),
            "velocity": Out(vel_shape), "weight_word": Out(weight_shape), "force_word": Out(force_shape),
            "force_write": In(write_signature(range(cap.vertices + 1), force_shape)),
            "node_write": In(write_signature(range(cap.vertices + 1), node_write_layout(fs))),
            "proposal": Out(vel_shape).array(3),
            "proposal_write": In(write_signature(range(cap.vertices + 1), vel_shape)),
            **({} if not cap.coarse_degree else
               {"basis_word": Out(word_layout(layouts["basis"])), "matrix_word": Out(word_layout(layouts["matrix"])),
                "matrix_addr": In(range(layouts["matrix"].depth))}),
        })

    @staticmethod
    def _bus_members(addr_width: int) -> dict:
        """The bus's request and answer, and the controller's flags: the members every build has."""
        return {"address": In(addr_width), "bus_request": In(1), "write": In(1), "write_data": In(BUS_WORD_BITS),
                "whole_word": In(1), "hit": Out(1), "answer": Out(1), "answer_data": Out(BUS_WORD_BITS),
                "running": In(1), "in_area": In(1), "in_integrate": In(1), "fetch_nodes": In(1)}

    def elaborate(self, platform):
        m = Module()
        for name, ram in self.rams.items():
            m.submodules[name] = ram
        if self.lanes > 1:
            self._elaborate_lanes(m, platform)
            return m
        entry_banks = [ram for name, ram in self.rams.items() if name.startswith("entries")]
        bank_bits = (self.entry_bank_depth - 1).bit_length() if len(entry_banks) > 1 \
            else len(entry_banks[0].read[0].addr)
        ent_addr = Signal(range(self.capacity.entries), name="ent_addr")  # the entry memory's address register
        ent_hot = Signal(len(entry_banks), name="ent_hot")  # ent_addr's bank, one flag per bank
        ent_data = self._entry_read(m, entry_banks, ent_addr, ent_hot, platform)

        positions, triangles, forces = self.rams["positions"], self.rams["triangles"], self.rams["forces"]
        m.d.comb += [self.entry.eq(ent_data), self.triangle.eq(triangles.read[0].data),
                     *(self.position[k].eq(port.data) for k, port in enumerate(positions.read)),
                     self.velocity.eq(self.rams["velocities"].read[0].data),
                     self.weight_word.eq(self.rams["weights"].read[0].data), self.force_word.eq(forces.read[0].data)]
        # the force pass's per-node results, straight into the force memory (not on the bus)
        m.d.comb += [forces.write.addr.eq(self.force_write.addr), forces.write.data.eq(self.force_write.data),
                     forces.write.en.eq(self.force_write.en)]
        # the guarded step's proposals (not on the bus): each copy read at its position port's address,
        # written from registers as the node memories are (none in a build without the guard: ``proposal``
        # reads 0)
        if self.capacity.guard:
            proposal_regs = (Signal.like(self.proposal_write.addr, name="prop_waddr"),
                             Signal.like(self.proposal_write.data, name="prop_wdata"), Signal(name="prop_wen"))
            m.d.sync += [proposal_regs[0].eq(self.proposal_write.addr),
                         proposal_regs[1].eq(self.proposal_write.data),
                         proposal_regs[2].eq(self.proposal_write.en & self.running)]
            proposals = iter(self.proposal)
            for ram in self._proposal_rams():
                m.d.comb += [*(next(proposals).eq(port.data) for port in ram.read),
                             ram.write.addr.eq(proposal_regs[0]), ram.write.data.eq(proposal_regs[1]),
                             ram.write.en.eq(proposal_regs[2])]

        window_q, index_q, word_q = self._decode(m)
        pos_a, vel_r, wgt_r = self.rams["positions"].read[0], self.rams["velocities"].read[0], self.rams["weights"].read[0]
        reads = {"nodes": (Cat(pos_a.data.x, pos_a.data.y, vel_r.data.x, vel_r.data.y, wgt_r.data.inv_mass,
                               wgt_r.data.inv_mass_barrier), self.read_latency),
                 "triangles": (self.rams["triangles"].read[0].data.as_value(), self.read_latency),
                 "entries": (ent_data.as_value(), self.entry_latency)}
        if self.capacity.coarse_degree:
            for name in ("basis", "matrix"):
                data_out = self.rams[name].read[0].data
                m.d.comb += getattr(self, f"{name}_word").eq(data_out)
                reads[name] = (data_out.as_value(), self.read_latency)
        bus_writing, new_words = self._bus_words(m, window_q, word_q, reads)
        self._read_addresses(m, index_q, ent_addr, ent_hot, bank_bits, ent_data, platform)
        self._writes(m, index_q, window_q, bus_writing, new_words, ent_addr, bank_bits, entry_banks, platform)
        return m

    def _proposal_rams(self) -> list[BlockRam]:
        """The proposal memories: one of three read ports, or three of one (none without the guard)."""
        return [ram for name, ram in self.rams.items() if name.startswith("proposals")]

    def _proposal_ports(self) -> list:
        """The proposal memories' read ports, one per position port."""
        return [port for ram in self._proposal_rams() for port in ram.read]

    def _entry_read(self, m: Module, entry_banks, ent_addr, ent_hot, platform, prefix: str = "ent"):
        """The entry memory's read, E0 (``ent_addr``, ``ent_hot``) to :attr:`entry_latency` (the returned
        register): see the class's docstring. ``prefix`` names its registers.

        With the registered select, the bank's word is relayed through a register first, and the bank's E4
        flag is a copy per block RAM (a ``DP16KD`` slice of the word, :func:`~hdl.block_ram.dp16kd_banks`),
        kept distinct: a bank's block RAMs spread over the device, and each slice of ``ent_kept<b>`` can
        then sit by its own block RAM's relay."""
        shape = self.entry_shape
        kept = []
        for b, bank in enumerate(entry_banks):
            assert bank.latency == ENTRY_BANK_LATENCY
            port = bank.read[0]
            select = [Signal(name=f"{prefix}_select{b}_{k}") for k in range(1, ENTRY_BANK_LATENCY + 1)]  # E1 … E3
            m.d.sync += [select[0].eq(ent_hot[b]), *(select[k].eq(select[k - 1]) for k in range(1, len(select)))]
            m.d.comb += port.addr.eq(ent_addr[:len(port.addr)])
            kept.append(Signal(shape, reset_less=True, name=f"{prefix}_kept{b}"))
            if self.registered_select:  # E4 the relay, E5 the kept slices under E4's flag's copies
                relay = Signal(shape, reset_less=True, name=f"{prefix}_relay{b}")
                m.d.sync += relay.eq(port.data)
                self._kept_per_block_ram(m, bank, select[-1], Value.cast(relay), Value.cast(kept[b]), platform,
                                         name=f"{prefix}_select{b}_4")
            else:
                with m.If(select[-1]):
                    m.d.sync += kept[b].eq(port.data)
                with m.Else():
                    m.d.sync += kept[b].eq(0)
        n_groups = -(-len(kept) // ENTRY_GROUP)
        size = -(-len(kept) // n_groups)
        groups = [Signal(shape, reset_less=True, name=f"{prefix}_group{g}") for g in range(n_groups)]
        m.d.sync += [group.eq(or_tree(kept[g * size:(g + 1) * size])) for g, group in enumerate(groups)]
        ent_data = Signal(shape, reset_less=True, name=f"{prefix}_data")  # the addressed entry
        m.d.sync += ent_data.eq(or_tree(groups))
        return ent_data

    @staticmethod
    def _kept_per_block_ram(m: Module, bank: BlockRam, before_last, data: Value, kept: Value, platform, *,
                            name: str) -> None:
        """``kept``, each block RAM's slice of it under a select flag of its own (:func:`~hdl.block_ram.kept_per_slice`,
        the slices of :func:`~hdl.block_ram.dp16kd_banks`)."""
        slice_width, _, inner_banks = dp16kd_banks(bank.depth, len(data))
        assert inner_banks == 1, "an entry bank is one DP16KD deep (checked in __init__)"
        kept_per_slice(m, before_last, data, kept, slice_width, name=name, platform=platform)

    def _decode(self, m: Module):
        """The request's window, index and word, registered at DEC (``n_windows``: none)."""
        windows, cap = self.register_map.windows, self.capacity
        n_windows = len(windows)
        bus_window = Signal(range(n_windows + 1))  # n_windows: none
        bus_index = Signal(max(cap.vertices, cap.entries, cap.triangles).bit_length())
        bus_word = Signal(range(max(w.words for w in windows) + 1))
        window_ok = Signal()
        for k, w in enumerate(windows):
            size_bits = (w.size - 1).bit_length()
            stride_bits = (w.stride - 1).bit_length()
            with m.If(self.address[size_bits:] == (w.base >> size_bits)):
                index = self.address[stride_bits:size_bits]
                word = self.address[:stride_bits] if stride_bits else Const(0, 1)
                m.d.comb += [bus_window.eq(k), bus_index.eq(index), bus_word.eq(word),
                             window_ok.eq((index < w.depth) & (word < w.words))]
        with m.If(~window_ok):
            m.d.comb += bus_window.eq(n_windows)
        window_q = Signal.like(bus_window, name="window_q")
        index_q = Signal.like(bus_index, name="index_q")
        word_q = Signal.like(bus_word, name="word_q")
        m.d.sync += [window_q.eq(bus_window), index_q.eq(bus_index), word_q.eq(bus_word)]
        m.d.comb += self.hit.eq(~self.running & (window_q != n_windows))
        return window_q, index_q, word_q

    def _bus_words(self, m: Module, window_q, word_q, reads):
        """A window word's read and write-back: DEC forms the port addresses (in the memories' address
        registers the clock after), then the block RAM read, the whole word landed in a register (the
        memories' outputs come from all over the device), then the answer and, for a write, the
        modified word written back. ``reads``: per window, its word as the memories read it and the clocks
        from the address registers to it. Returns ``(bus_writing, {window: (k, new word)})``."""
        windows = self.register_map.windows
        steps = self.window_steps
        mem_steps = [Signal(name=f"mem_step{k}") for k in range(steps)]
        m.d.sync += [mem_steps[0].eq(self.bus_request & self.hit),
                     *(mem_steps[k].eq(mem_steps[k - 1]) for k in range(1, steps))]
        mem_landed, mem_answer = mem_steps[steps - 2], mem_steps[steps - 1]
        mem_data = Signal(BUS_WORD_BITS)
        mem_word = Signal(BUS_WORD_BITS, reset_less=True, name="mem_word")
        m.d.sync += mem_word.eq(mem_data)
        m.d.comb += [self.answer.eq(mem_answer), self.answer_data.eq(mem_word)]
        # the word's select, one flip-flop per (window, word), set the clock after DEC from the decode
        # (long before the entry lands): the answer and the write-back are AND-OR selects from flip-flops
        word_hot = {(k, j): Signal(name=f"word_hot_{w.name}_{j}") for k, w in enumerate(windows) for j in range(w.words)}
        m.d.sync += [hot.eq((window_q == k) & (word_q == j)) for (k, j), hot in word_hot.items()]
        answer_terms, new_words = [], {}
        for k, w in enumerate(windows):
            # the memories' data has landed (BlockRam); delayed to the entry's clock (entry_latency clocks after
            # the address register)
            word_value, latency = reads[w.name]
            for d in range(self.entry_latency - latency):
                aligned = Signal(len(word_value), name=f"bus_{w.name}_aligned{d}", reset_less=True)
                m.d.sync += aligned.eq(word_value)
                word_value = aligned
            padded = Signal(w.words * BUS_WORD_BITS, name=f"bus_{w.name}_word", reset_less=True)
            m.d.sync += padded.eq(word_value)
            words = [padded.word_select(j, BUS_WORD_BITS) for j in range(w.words)]
            answer_terms += [Mux(word_hot[k, j], words[j], 0) for j in range(w.words)]
            modified = Cat(*(Mux(word_hot[k, j], self.write_data, words[j]) for j in range(w.words)))
            new_words[w.name] = (k, modified[:len(word_value)])
        m.d.comb += mem_data.eq(or_tree(answer_terms))
        return mem_landed & self.write & self.whole_word, new_words

    def _read_addresses(self, m: Module, index_q, ent_addr, ent_hot, bank_bits, ent_data, platform) -> None:
        """Each read address register: the bus's index while idle, the pass's address while running
        (with ``registered_select``, ``running`` from a copy per memory group)."""
        positions = self.rams["positions"].read
        read_ports = {"pos_a": positions[0], "pos_b": positions[1], "pos_c": positions[2],
                      "vel": self.rams["velocities"].read[0], "wgt": self.rams["weights"].read[0],
                      "frc": self.rams["forces"].read[0], "tri": self.rams["triangles"].read[0]}
        coarse = self.capacity.coarse_degree
        if coarse:
            read_ports |= {"bas": self.rams["basis"].read[0], "mtx": self.rams["matrix"].read[0]}
        read_addr = {name: Signal.like(port.addr, name=f"{name}_addr") for name, port in read_ports.items()}
        m.d.comb += [port.addr.eq(read_addr[name]) for name, port in read_ports.items()]
        # the proposals' ports read at their position port's address register (a second register with
        # the same inputs would be merged into it by Yosys)
        m.d.comb += [port.addr.eq(read_addr[f"pos_{c}"]) for port, c in zip(self._proposal_ports(), "abc")]
        t2_tri = self.rams["triangles"].read[0].data
        running, in_area = self.running, self.in_area
        if self.registered_select:
            running = {group: kept_register(m, self.running_next, name=f"{group}_reads_running", platform=platform,
                                            reset=True) for group in ("ent", "tri", "node")}
        else:
            running = dict.fromkeys(("ent", "tri", "node"), running)
        # a node pass: fetching, or its last nodes in flight. With the registered select, the fetch flag from a
        # copy beside the address multiplexers (a clock late: the sequencer's down-counters, which the
        # registered select comes with, issue a node the clock after the flag, from a copy like it)
        fetch_nodes = self.fetch_nodes
        if self.registered_select:
            fetch_nodes = kept_register(m, self.fetch_nodes, name="node_reads_fetch", platform=platform, reset=True)
        in_nodes = fetch_nodes | self.in_integrate
        ent_next = Signal.like(ent_addr, name="ent_next")
        m.d.comb += ent_next.eq(Mux(running["ent"], self.entry_index, index_q))
        m.d.sync += [
            ent_addr.eq(ent_next),
            ent_hot.eq(Cat(ent_next[bank_bits:] == b for b in range(len(ent_hot))) if len(ent_hot) > 1 else 1),
            read_addr["tri"].eq(Mux(running["tri"], self.tri_index, index_q)),
            *(read_addr[n].eq(Mux(running["node"], self.node_index, index_q))
              for n in ("vel", "wgt", "frc", *(("bas",) if coarse else ()))),
            *([read_addr["mtx"].eq(Mux(running["node"], self.matrix_addr, index_q))] if coarse else []),
            read_addr["pos_b"].eq(Mux(in_area, t2_tri.b, ent_data.neighbour)),
            read_addr["pos_c"].eq(Mux(in_area, t2_tri.c, ent_data.second)),
            read_addr["pos_a"].eq(Mux(~running["node"] | in_nodes, Mux(running["node"], self.node_index, index_q),
                                      Mux(in_area, t2_tri.a, self.node_of_entry))),
        ]

    def _writes(self, m: Module, index_q, window_q, bus_writing, new_words, ent_addr, bank_bits, entry_banks,
                platform) -> None:
        """Each write port's address, data and enable registers: the bus's write-back while idle, the
        integrator's results while running (the entry banks: one enable flag per bank)."""
        write_ports = {"pos": self.rams["positions"].write, "vel": self.rams["velocities"].write,
                       "wgt": self.rams["weights"].write, "ent": None, "tri": self.rams["triangles"].write,
                       **({"bas": self.rams["basis"].write, "mtx": self.rams["matrix"].write}
                          if self.capacity.coarse_degree else {})}
        write_regs = {}
        for name, port in write_ports.items():
            if port is None:  # the entry banks, each enabled by its flag (then their pin registers)
                regs = (Signal.like(ent_addr, name="ent_waddr"), Signal(self.entry_shape, name="ent_wdata"),
                        Signal(len(entry_banks), name="ent_whot"))
                for b, bank in enumerate(entry_banks):
                    m.d.comb += [bank.write.addr.eq(regs[0][:len(bank.write.addr)]), bank.write.data.eq(regs[1]),
                                 bank.write.en.eq(regs[2][b])]
            else:
                regs = (Signal.like(port.addr, name=f"{name}_waddr"), Signal.like(port.data, name=f"{name}_wdata"),
                        Signal(name=f"{name}_wen"))
                m.d.comb += [port.addr.eq(regs[0]), port.data.eq(regs[1]), port.en.eq(regs[2])]
            write_regs[name] = regs
        node_k, node_new = new_words["nodes"]
        ent_k, ent_new = new_words["entries"]
        tri_k, tri_new = new_words["triangles"]
        node = self.node_write
        pos_bits, vel_bits = (len(Value.cast(write_regs[n][1])) for n in ("pos", "vel"))
        node_writing = bus_writing & (window_q == node_k)
        # while idle, the bus's write-back: (the index; the condition that loads it into the address, None for
        # any window; data; enable). A port loads the index only for its own window where another port's address
        # register would otherwise have the same logic: Yosys merges such registers into one, which then
        # drives block RAMs placed far apart.
        from_bus = {
            "pos": (index_q, None, node_new[:pos_bits], node_writing),
            "vel": (index_q, None, node_new[pos_bits:pos_bits + vel_bits], node_writing),
            "wgt": (index_q, window_q == node_k, node_new[pos_bits + vel_bits:], node_writing),
            "ent": (index_q, window_q == ent_k, ent_new, Cat(bus_writing & (window_q == ent_k)
                                                             & (index_q[bank_bits:] == b if len(entry_banks) > 1 else 1)
                                                             for b in range(len(entry_banks)))),
            "tri": (index_q, window_q == tri_k, tri_new, bus_writing & (window_q == tri_k)),
        }
        for name, window in (("bas", "basis"), ("mtx", "matrix")):  # the coarse space's: the bus's alone
            if name in write_ports:
                k, new = new_words[window]
                from_bus[name] = (index_q, window_q == k, new, bus_writing & (window_q == k))
        # while running, the integrator's results into the node memories; the others hold, not enabled
        from_passes = {"pos": (node.addr, node.data.position, node.en), "vel": (node.addr, node.data.velocity, node.en)}
        for name, regs in write_regs.items():
            self._choose_writes(m, name, regs, from_passes.get(name), from_bus[name], platform)

    def _choose_writes(self, m: Module, name: str, regs, from_passes, from_bus, platform) -> None:
        """A write port's registers ``regs`` (address, data, enable): ``from_passes`` (address, data, enable)
        while running, or not enabled where it is ``None``; ``from_bus`` (address, the condition that loads it
        or ``None`` for always, data, enable) while idle."""
        addr, word, en = regs
        # the choice from a copy of ``running`` of each port's own, beside its registers, a clock late:
        # the controller's flip-flop drives logic all over the device, so a route from it into these
        # multiplexers crosses the die. A clock late is safe: no pass writes in the start phase's
        # first clock, the bus's last write has been answered before START, and nothing writes once a
        # run has drained.
        with m.If(kept_register(m, self.running, name=f"{name}_writes_running", platform=platform)):
            if from_passes is not None:
                m.d.sync += [reg.eq(value) for reg, value in zip(regs, from_passes)]
            else:
                m.d.sync += en.eq(0)
        with m.Else():
            bus_addr, load, bus_data, bus_en = from_bus
            if load is None:
                m.d.sync += addr.eq(bus_addr)
            else:
                with m.If(load):
                    m.d.sync += addr.eq(bus_addr)
            m.d.sync += [word.eq(bus_data), en.eq(bus_en)]

    # ------------------------------------------------------------------ lanes
    def _lane_rams(self, pos_shape, vel_shape, weight_shape, force_shape) -> dict[str, BlockRam]:
        """K > 1 lanes: every node and triangle memory in K banks, bank ``b`` holding the nodes (or triangles)
        whose index is ``b`` mod K at the index divided by K; the position banks with three read ports per
        lane (a lane's force and area passes read any node); a force memory per lane; the entry memory in K
        shares of ``entries / K`` words (lane ``l``'s at ``l · entries / K`` in the window), each in banks of
        ``entry_bank_depth`` words."""
        cap, lanes, depth = self.capacity, self.lanes, self.entry_bank_depth
        nodes, share = cap.vertices // lanes, cap.lane_entries
        rams = {}
        for b in range(lanes):
            rams[f"positions{b}"] = BlockRam(pos_shape, nodes, read_ports=3 * lanes, name=f"positions{b}")
            rams[f"velocities{b}"] = BlockRam(vel_shape, nodes, name=f"velocities{b}")
            rams[f"weights{b}"] = BlockRam(weight_shape, nodes, name=f"weights{b}")
            rams[f"triangles{b}"] = BlockRam(self.triangle_shape, cap.triangles // lanes, name=f"triangles{b}")
        for lane in range(lanes):
            rams[f"forces{lane}"] = BlockRam(force_shape, nodes, name=f"forces{lane}")
            for b in range(-(-share // depth)):
                rams[f"lane{lane}_entries{b}"] = BlockRam(self.entry_shape, min(depth, share - b * depth),
                                                          name=f"lane{lane}_entries{b}", pin_registers=True)
        return rams

    def _lane_members(self, pos_shape, vel_shape, weight_shape, force_shape) -> dict:
        """K > 1 lanes: each pass port once per lane (``[lane]``; ``position[lane][k]``), the node and entry
        indices lane-local: lane ``l``'s ``n``-th node is node ``l + n·K``, its word ``n`` of bank ``l``. The
        triangle and integrate passes run the lanes in step, from lane 0's counters (``tri_index``,
        ``node_index``: a bank word)."""
        cap, lanes = self.capacity, self.lanes
        nodes = range(cap.vertices // lanes + 1)
        return {
            "entry_index": In(range(cap.lane_entries + 1)).array(lanes), "tri_index": In(range(cap.triangles // lanes + 1)),
            "node_index": In(nodes), "node_of_entry": In(nodes).array(lanes),
            "entry": Out(self.entry_shape).array(lanes), "triangle": Out(self.triangle_shape).array(lanes),
            "position": Out(pos_shape).array(lanes, 3), "velocity": Out(vel_shape).array(lanes),
            "weight_word": Out(weight_shape).array(lanes), "force_word": Out(force_shape).array(lanes),
            "force_write": In(write_signature(nodes, force_shape)).array(lanes),
            "node_write": In(write_signature(nodes, node_write_layout(self.fs))).array(lanes),
        }

    def _elaborate_lanes(self, m: Module, platform) -> None:
        """K > 1 lanes: each lane's entry share read as the entry memory is; every pass read landed, then (a
        clock more, :attr:`read_latency`) its bank's word selected in a register; the bus's word of a node or
        triangle from its bank, of an entry from its lane's share."""
        cap, lanes = self.capacity, self.lanes
        bank_bits = (lanes - 1).bit_length()
        window_q, index_q, word_q = self._decode(m)
        bus_word, bus_bank = index_q[bank_bits:], index_q[:bank_bits]
        running, in_area = self.running, self.in_area
        in_nodes = self.fetch_nodes | self.in_integrate  # the integrate pass: fetching, or its last nodes in flight
        # the entry shares: each lane's read while running, the bus's index within its share while idle
        shares = []
        for lane in range(lanes):
            banks = [ram for name, ram in self.rams.items() if name.startswith(f"lane{lane}_entries")]
            share_bits = (self.entry_bank_depth - 1).bit_length() if len(banks) > 1 else len(banks[0].read[0].addr)
            ent_addr = Signal(range(cap.lane_entries), name=f"lane{lane}_ent_addr")
            ent_hot = Signal(len(banks), name=f"lane{lane}_ent_hot")
            ent_data = self._entry_read(m, banks, ent_addr, ent_hot, platform, prefix=f"lane{lane}_ent")
            m.d.comb += self.entry[lane].eq(ent_data)
            start = lane * cap.lane_entries
            local = Signal(range(cap.lane_entries), name=f"lane{lane}_bus_index")
            in_share = Signal(name=f"lane{lane}_bus_in_share")
            m.d.comb += [local.eq(index_q - start), in_share.eq((index_q >= start) & (index_q < start + cap.lane_entries))]
            ent_next = Signal.like(ent_addr, name=f"lane{lane}_ent_next")
            m.d.comb += ent_next.eq(Mux(running, self.entry_index[lane], local))
            m.d.sync += [ent_addr.eq(ent_next),
                         ent_hot.eq(Cat(((ent_next[share_bits:] == b) if len(banks) > 1 else 1) & (running | in_share)
                                        for b in range(len(banks))))]
            shares.append((banks, share_bits, local, in_share, ent_data))

        # the node and triangle banks: lane 0's counters address every bank while running (the lanes run in
        # step), the bus's word while idle; each lane's word landed a clock after the bank's
        rams = self.rams
        word_addr, tri_addr = Signal(range(cap.vertices // lanes), name="node_word_addr"), \
            Signal(range(cap.triangles // lanes), name="tri_word_addr")
        m.d.sync += [word_addr.eq(Mux(running, self.node_index, bus_word)),
                     tri_addr.eq(Mux(running, self.tri_index, bus_word))]
        for b in range(lanes):
            m.d.comb += [rams[f"{name}{b}"].read[0].addr.eq(word_addr) for name in ("velocities", "weights", "forces")]
            m.d.comb += rams[f"triangles{b}"].read[0].addr.eq(tri_addr)
        for lane in range(lanes):
            for name, out in (("velocities", self.velocity), ("weights", self.weight_word), ("forces", self.force_word),
                              ("triangles", self.triangle)):
                landed = Signal.like(out[lane], name=f"{name}_landed{lane}", reset_less=True)
                m.d.sync += landed.eq(rams[f"{name}{lane}"].read[0].data)
                m.d.comb += out[lane].eq(landed)
        # the position ports: each lane's three, every bank read at the port's word, the bank's word selected
        # by the node's low bits, carried beside the read
        for lane in range(lanes):
            tri, entry = self.triangle[lane], self.entry[lane]
            own_or_a = Mux(in_area, tri.a[bank_bits:], self.node_of_entry[lane])
            sources = {  # (word, bank) while running
                "a": (Mux(in_nodes, self.node_index, own_or_a), Mux(in_area & ~in_nodes, tri.a[:bank_bits], lane)),
                "b": (Mux(in_area, tri.b[bank_bits:], entry.neighbour[bank_bits:]),
                      Mux(in_area, tri.b[:bank_bits], entry.neighbour[:bank_bits])),
                "c": (Mux(in_area, tri.c[bank_bits:], entry.second[bank_bits:]),
                      Mux(in_area, tri.c[:bank_bits], entry.second[:bank_bits])),
            }
            for k, (port, (word, bank)) in enumerate(sources.items()):
                addr = Signal(range(cap.vertices // lanes), name=f"pos_{port}_addr{lane}")
                banks = [Signal(bank_bits, name=f"pos_{port}_bank{lane}_{d}") for d in range(READ_LATENCY + 1)]
                m.d.sync += [addr.eq(Mux(running, word, bus_word)), banks[0].eq(Mux(running, bank, bus_bank)),
                             *(banks[d].eq(banks[d - 1]) for d in range(1, len(banks)))]
                reads = [rams[f"positions{b}"].read[3 * lane + k] for b in range(lanes)]
                m.d.comb += [read.addr.eq(addr) for read in reads]
                landed = Signal.like(self.position[lane][k], name=f"pos_{port}_landed{lane}", reset_less=True)
                m.d.sync += landed.eq(Array(read.data for read in reads)[banks[READ_LATENCY]])
                m.d.comb += self.position[lane][k].eq(landed)
        # the bus's word: a node's and a triangle's from its bank (lane 0's first port reads the positions), an
        # entry's from every share (the shares that do not hold it read 0)
        node_words = [Cat(rams[f"positions{b}"].read[0].data.x, rams[f"positions{b}"].read[0].data.y,
                          rams[f"velocities{b}"].read[0].data.x, rams[f"velocities{b}"].read[0].data.y,
                          rams[f"weights{b}"].read[0].data.inv_mass, rams[f"weights{b}"].read[0].data.inv_mass_barrier)
                      for b in range(lanes)]
        reads = {"nodes": (Array(node_words)[bus_bank], READ_LATENCY),
                 "triangles": (Array(rams[f"triangles{b}"].read[0].data.as_value() for b in range(lanes))[bus_bank],
                               READ_LATENCY),
                 "entries": (or_tree([share[-1].as_value() for share in shares]), self.entry_latency)}
        bus_writing, new_words = self._bus_words(m, window_q, word_q, reads)
        self._lane_writes(m, window_q, bus_word, bus_bank, bus_writing, new_words, shares, platform)

    def _lane_writes(self, m: Module, window_q, bus_word, bus_bank, bus_writing, new_words, shares, platform) -> None:
        """K > 1 lanes: each bank's write registers (lane ``b``'s integrate pass writes bank ``b`` while running,
        the bus's write-back the bank of its index while idle); each share's (the bus only); each lane's force
        memory (its force pass)."""
        rams, lanes = self.rams, self.lanes
        node_k, node_new = new_words["nodes"]
        ent_k, ent_new = new_words["entries"]
        tri_k, tri_new = new_words["triangles"]
        pos_bits, vel_bits = (Shape.cast(rams[f"{name}0"].shape).width for name in ("positions", "velocities"))
        node_writing = bus_writing & (window_q == node_k)
        for b in range(lanes):
            hit = bus_bank == b
            lane_write = self.node_write[b]
            ports = {  # (port, data and enable from the bus, (address, data, enable) from lane b or None)
                "pos": (rams[f"positions{b}"].write, node_new[:pos_bits], node_writing & hit,
                        (lane_write.addr, lane_write.data.position, lane_write.en)),
                "vel": (rams[f"velocities{b}"].write, node_new[pos_bits:pos_bits + vel_bits], node_writing & hit,
                        (lane_write.addr, lane_write.data.velocity, lane_write.en)),
                "wgt": (rams[f"weights{b}"].write, node_new[pos_bits + vel_bits:], node_writing & hit, None),
                "tri": (rams[f"triangles{b}"].write, tri_new, bus_writing & (window_q == tri_k) & hit, None),
            }
            for name, (port, bus_data, bus_en, from_lane) in ports.items():
                regs = (Signal.like(port.addr, name=f"{name}{b}_waddr"), Signal.like(port.data, name=f"{name}{b}_wdata"),
                        Signal(name=f"{name}{b}_wen"))
                m.d.comb += [port.addr.eq(regs[0]), port.data.eq(regs[1]), port.en.eq(regs[2])]
                self._choose_writes(m, f"{name}{b}", regs, from_lane, (bus_word, None, bus_data, bus_en), platform)
        for lane, (banks, share_bits, local, in_share, _) in enumerate(shares):
            regs = (Signal(range(self.capacity.lane_entries), name=f"lane{lane}_ent_waddr"),
                    Signal(self.entry_shape, name=f"lane{lane}_ent_wdata"), Signal(len(banks), name=f"lane{lane}_ent_whot"))
            for b, bank in enumerate(banks):
                m.d.comb += [bank.write.addr.eq(regs[0][:len(bank.write.addr)]), bank.write.data.eq(regs[1]),
                             bank.write.en.eq(regs[2][b])]
            writing = bus_writing & (window_q == ent_k) & in_share
            hot = Cat(writing & ((local[share_bits:] == b) if len(banks) > 1 else 1) for b in range(len(banks)))
            self._choose_writes(m, f"lane{lane}_ent", regs, None, (local, window_q == ent_k, ent_new, hot), platform)
        for lane in range(lanes):
            forces, write = rams[f"forces{lane}"], self.force_write[lane]
            m.d.comb += [forces.write.addr.eq(write.addr), forces.write.data.eq(write.data), forces.write.en.eq(write.en)]
