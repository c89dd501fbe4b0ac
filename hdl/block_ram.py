"""A block RAM whose read data lands in a register: generic RTL or ECP5 ``DP16KD`` with its output register.

:class:`BlockRam` is the engine's node, entry and triangle storage: one write port and
``read_ports`` read ports, each read answering ``mem[addr]`` two clocks after ``addr`` (the
address registered in the block RAM, then its data registered). In generic RTL that is an
:class:`amaranth.lib.memory.Memory` read port and a flip-flop on its data. Yosys's ``synth_ecp5``
maps the read port to a ``DP16KD`` with ``REGMODE = "NOREG"`` and leaves the flip-flop in the
fabric, so every read costs the block RAM's unregistered clock-to-output (5.83 ns in nextpnr's
ECP5 model) plus a route to that flip-flop, most of a clock period at the engine's clock.
Elaborated with :data:`hdl.dsp.ECP5` as the platform, each read port is
therefore a row of ``DP16KD`` instances, port A written and port B read with
``REGMODE_B = "OUTREG"``, one instance per column slice of the word, in the configuration that
holds ``depth`` words in the fewest block RAMs (:func:`dp16kd_banks`); every read port has its own
copy of the memory, as Yosys makes for a memory with several read ports (or, with
``shared_write_port``, every two read ports one: below). Where that takes several
banks (a depth above 2,048, or just above a power of two: 3,072 words of 66 bits are 3 banks of
1K×18, 12 block RAMs, where one 4K×4 bank takes 17), the addressed bank's word is selected after
the output registers, by the address's high bits registered alongside: a multiplexer between the
output registers and the user's logic. Both forms have the same function and
latency. The ECP5 form is simulated with ``sim/models/DP16KD.v``, whose write and read pins are
checked against Yosys's own mapping of an inferred RAM (``tests/sim/test_synth.py``).

Timing contract: a write (``write.en`` high at a clock edge) is visible to a read whose address
is registered at a later edge. A read and a write of the same address at the same edge are a
collision: the generic form returns the old word, a ``DP16KD`` an undefined one (the simulation
model returns X), so a user must never use such a read's data (Yosys's ``no_rw_check``, which the
generic form carries, says the same to the synthesis tool).

``shared_write_port``: a ``DP16KD`` has two ports, and a copy's write port (A) reads whenever it does
not write. With it, ``read_ports`` ports take :attr:`copies` = ⌈read_ports / 2⌉ copies of the
memory instead of one per port: read port ``k`` reads port B of copy ``k`` while ``k <``
:attr:`copies`, else port A of copy ``k - copies`` (its address on the pins in every clock without
a write, ``WRITEMODE_A = "NORMAL"``), with the same latency. Such a *shared* port
(:attr:`shared_reads`) does not read at an edge where a write is issued (any address): the word it
answers for that edge is undefined (the generic form answers all ones, so that a bench whose
design used one would see it), and its user must not need it.
"""

from __future__ import annotations

from amaranth.hdl import ClockSignal, Const, Module, Mux, Shape, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.memory import Memory, MemoryData, WritePort
from amaranth.lib.wiring import In, Out

from .dsp import ECP5, dsp_target, kept_register
from .logic import or_tree
from .parameters import check_int
from .rom import DP16KD_ADDRESS_PINS, DP16KD_CONFIGS, DP16KD_DATA_PINS, dp16kd, dp16kd_port

__all__ = ["BlockRam", "dp16kd_banks", "kept_per_slice"]


class BlockRam(wiring.Component):
    """``depth`` words of ``shape`` in block RAM, one write port, ``read_ports`` registered read ports.

    Members: ``write`` (:class:`amaranth.lib.memory.WritePort.Signature`: ``addr``, ``data``,
    ``en``; the word is written at the clock edge where ``en`` is high) and ``read[k]`` (``addr`` in,
    ``data`` out: ``data`` is the word at the ``addr`` of two clocks before; there is no read
    enable, every port reads every clock). Initial contents: all zeros.

    ``pin_registers``: every block RAM input (read and write address, write data and enable) goes
    through a register of its own, so a read answers :attr:`latency` = three clocks after ``addr``
    and a write lands a clock after ``en`` (visible to a read whose address is registered two edges
    later). In the ECP5 form these are ``TRELLIS_FF`` instances per ``DP16KD``, marked ``keep``
    (Yosys merges identical registers): registered because one register fanning out to block RAMs
    spread over the device crosses it, where a copy per block RAM can sit between the source and
    its block RAM. In generic RTL one register per port.

    ``registered_select``: the word read passes three more registers, :attr:`latency` three clocks more. In
    the ECP5 form with several banks these hold the bank select: each block RAM's slice of the word relayed
    through a register (which the placer can put beside that block RAM), then kept, or zeroed where it is
    not the bank addressed, under a copy of the bank's flag per block RAM, then the banks' words ORed into
    a register, so that no logic sits between a bank's output register and a route across the device,
    and no route from a block RAM to a register placed by the others takes a whole period
    (``docs/synthesis.md``); with one bank, and in generic RTL, they only delay the word.

    ``name`` prefixes the ``DP16KD`` instances of the ECP5 form (``{name}_r{k}_{slice}``).
    ``contents`` is the generic form's :class:`amaranth.lib.memory.MemoryData`, for a testbench
    that reads the memory directly (``ctx.get(ram.contents[i])``).
    """

    #: Clocks from a read port's ``addr`` to its ``data``: the address registered in the block RAM,
    #: then its data in the output register.
    LATENCY = 2
    #: Clocks ``registered_select`` adds: the block RAMs' words relayed, kept or zeroed, then ORed.
    SELECT_STAGES = 3

    def __init__(self, shape, depth: int, *, read_ports: int = 1, name: str = "ram", pin_registers: bool = False,
                 registered_select: bool = False, shared_write_port: bool = False):
        check_int("BlockRam depth", depth)
        check_int("BlockRam read_ports", read_ports)
        width = Shape.cast(shape).width
        if width < 1:
            raise ValueError(f"BlockRam word width must be at least 1, not {width}")
        for flag, value in (("pin_registers", pin_registers), ("registered_select", registered_select),
                            ("shared_write_port", shared_write_port)):
            if not isinstance(value, bool):
                raise TypeError(f"BlockRam {flag} must be a bool, not {value!r}")
        self.shape, self.depth, self.name, self.pin_registers = shape, depth, name, pin_registers
        self.registered_select = registered_select
        #: Copies of the memory: one per read port, or with ``shared_write_port`` one per two.
        self.copies = -(-read_ports // 2) if shared_write_port else read_ports
        #: The read ports served by a copy's write port (none without ``shared_write_port``).
        self.shared_reads = range(self.copies, read_ports)
        #: Clocks from a read port's ``addr`` to its ``data``.
        self.latency = self.LATENCY + pin_registers + self.SELECT_STAGES * registered_select
        self.contents = MemoryData(shape=shape, depth=depth, init=[])
        addr_width = max(1, (depth - 1).bit_length())
        read = wiring.Signature({"addr": In(addr_width), "data": Out(shape)})
        super().__init__({"write": Out(WritePort.Signature(addr_width=addr_width, shape=shape)),
                          "read": Out(read).array(read_ports)})

    def elaborate(self, platform):
        m = Module()
        if dsp_target(platform) == "ecp5":
            self._dp16kd(m)
            return m
        # no_rw_check: see the module's timing contract (no collision bypass after the block RAM)
        m.submodules.memory = memory = Memory(data=self.contents, attrs={"no_rw_check": 1})
        write = memory.write_port()
        m.d.comb += [write.addr.eq(self._pin(m, self.write.addr, "w_addr")),
                     write.data.eq(self._pin(m, Value.cast(self.write.data), "w_data")),
                     write.en.eq(self._pin(m, self.write.en, "w_en"))]
        # a shared port's read at an edge with a write (``wrote`` the clock after): its word lands as all ones
        if self.shared_reads:
            wrote = Signal(name="wrote")
            m.d.sync += wrote.eq(write.en)
            width = Shape.cast(self.shape).width
            ones = Const((1 << width) - 1, width)
        for k, port in enumerate(self.read):
            read = memory.read_port()
            landed = Signal(self.shape, reset_less=True, name=f"landed{k}")
            m.d.comb += [read.addr.eq(self._pin(m, port.addr, f"r{k}_addr")),
                         Value.cast(port.data).eq(self._delayed(m, Value.cast(landed), f"r{k}"))]
            read_data = Mux(wrote, ones, Value.cast(read.data)) if k in self.shared_reads else Value.cast(read.data)
            m.d.sync += Value.cast(landed).eq(read_data)
        return m

    def _delayed(self, m: Module, value: Value, name: str) -> Value:
        """``value`` through the ``registered_select`` stages (none without it)."""
        for n in range(self.SELECT_STAGES * self.registered_select):
            q = Signal(len(value), reset_less=True, name=f"{name}_select{n}")
            m.d.sync += q.eq(value)
            value = q
        return value

    def _pin(self, m: Module, value: Value, name: str, *, kept: bool = False) -> Value:
        """``value``, or (``pin_registers``) ``value`` registered: a plain register, or with ``kept`` one
        ``TRELLIS_FF`` per bit marked ``keep``."""
        if not self.pin_registers:
            return value
        if kept:
            return kept_register(m, value, name=name, platform=ECP5)
        q = Signal(len(value), name=name)
        m.d.sync += q.eq(value)
        return q

    def _dp16kd(self, m: Module) -> None:
        width = Shape.cast(self.shape).width
        slice_width, words, banks = dp16kd_banks(self.depth, width)
        address_bits = (words - 1).bit_length()
        shift = DP16KD_ADDRESS_PINS - address_bits
        # In the 18-bit configuration the two lowest address pins of a writing port are its byte
        # enables (Yosys's brams_map_16kd.v): both high, every write is a whole word (a read ignores them).
        ada = Signal(DP16KD_ADDRESS_PINS, name="w_ada")
        low = 0b11 if slice_width == DP16KD_DATA_PINS else 0
        m.d.comb += ada.eq((self.write.addr[:address_bits] << shift) | low)
        write_bank = self.write.addr[address_bits:]
        write_data = Value.cast(self.write.data)
        for k in range(self.copies):  # copy k: read port k on port B, a shared read port on port A
            port = self.read[k]
            shared_k = k + self.copies
            shared = self.read[shared_k] if shared_k < len(self.read) else None
            adb = Signal(DP16KD_ADDRESS_PINS, name=f"r{k}_adb")
            m.d.comb += adb.eq(port.addr[:address_bits] << shift)
            bank_data = [Signal(width, name=f"r{k}_bank{b}_data") for b in range(banks)]
            shared_data = [Signal(width, name=f"r{shared_k}_bank{b}_data") for b in range(banks)] if shared else []
            for b in range(banks):
                write_enable = self.write.en & (write_bank == b) if banks > 1 else self.write.en
                # port A's address: the write's, or with a shared port, the write's in a clock that writes
                # this bank and the shared port's in any other
                write_addr = self.write.addr[:address_bits]
                a_addr = write_addr if shared is None else Mux(write_enable, write_addr, shared.addr[:address_bits])
                if shared is not None and not self.pin_registers:
                    shared_ada = Signal(DP16KD_ADDRESS_PINS, name=f"r{shared_k}_bank{b}_ada")
                    m.d.comb += shared_ada.eq((a_addr << shift) | low)
                for s, lo in enumerate(range(0, width, slice_width)):
                    bits = min(slice_width, width - lo)
                    dia = Signal(DP16KD_DATA_PINS, name=f"r{k}_{b}_{s}_dia")
                    dob = Signal(DP16KD_DATA_PINS, name=f"r{k}_{b}_{s}_dob")
                    inst = f"{self.name}_r{k}_{b}_{s}"
                    if self.pin_registers:  # this block RAM's own copy of every input that varies
                        ada_pins = Signal(DP16KD_ADDRESS_PINS, name=f"{inst}_ada")
                        adb_pins = Signal(DP16KD_ADDRESS_PINS, name=f"{inst}_adb")
                        m.d.comb += [
                            ada_pins.eq((self._pin(m, a_addr, f"{inst}_wa", kept=True) << shift) | low),
                            adb_pins.eq(self._pin(m, port.addr[:address_bits], f"{inst}_ra", kept=True) << shift),
                            dia.eq(self._pin(m, write_data[lo:lo + bits], f"{inst}_wd", kept=True))]
                        wea = self._pin(m, write_enable, f"{inst}_we", kept=True)
                    else:
                        ada_pins, adb_pins, wea = ada if shared is None else shared_ada, adb, write_enable
                        m.d.comb += dia.eq(write_data[lo:lo + bits])
                    m.d.comb += bank_data[b][lo:lo + bits].eq(dob[:bits])
                    doa = None  # port A read too (a shared port), through its output register
                    if shared is not None:
                        doa = Signal(DP16KD_DATA_PINS, name=f"r{k}_{b}_{s}_doa")
                        m.d.comb += shared_data[b][lo:lo + bits].eq(doa[:bits])
                    m.submodules[inst] = dp16kd(
                        slice_width, regmode_a="NOREG" if doa is None else "OUTREG", regmode_b="OUTREG",
                        **dp16kd_port("A", clock=ClockSignal(), address=ada_pins, write_data=dia, write_enable=wea,
                                      read_data=doa),
                        **dp16kd_port("B", clock=ClockSignal(), address=adb_pins, read_data=dob))
            self._bank_select(m, k, port, bank_data, banks, address_bits)
            if shared is not None:
                self._bank_select(m, shared_k, shared, shared_data, banks, address_bits)

    def _bank_select(self, m: Module, k: int, port, bank_data: list, banks: int, address_bits: int) -> None:
        """Read port ``k``'s word from its banks' words (output registers), selected by the address's high bits."""
        width = Shape.cast(self.shape).width
        read_data = Value.cast(port.data)
        if banks == 1:
            m.d.comb += read_data.eq(self._delayed(m, bank_data[0], f"r{k}"))
            return
        # the bank of the word in the output registers: the address's high bits, carried to the clock
        # of the banks' data (the address registered, in the pin registers, then read)
        to_data = self.LATENCY + self.pin_registers
        if self.registered_select:  # the relays; one flag per bank, copied per block RAM; the kept words ORed
            slice_width = dp16kd_banks(self.depth, width)[0]
            flags = [[Signal(name=f"r{k}_bank{b}_q{n}") for n in range(1, to_data + 1)] for b in range(banks)]
            kept = [Signal(width, reset_less=True, name=f"r{k}_bank{b}_kept") for b in range(banks)]
            for b in range(banks):
                m.d.sync += [flags[b][0].eq(port.addr[address_bits:] == b),
                             *(flags[b][n].eq(flags[b][n - 1]) for n in range(1, to_data))]
                relay = Signal(width, reset_less=True, name=f"r{k}_bank{b}_relay")
                m.d.sync += relay.eq(bank_data[b])
                kept_per_slice(m, flags[b][-1], relay, kept[b], slice_width, name=f"r{k}_bank{b}_kept_flag",
                               platform=ECP5)
            selected = Signal(width, reset_less=True, name=f"r{k}_selected")
            m.d.sync += selected.eq(or_tree(kept))
            m.d.comb += read_data.eq(selected)
            return
        bank = [Signal(range(banks), name=f"r{k}_bank_q{n}") for n in range(1, to_data + 1)]
        m.d.sync += [bank[0].eq(port.addr[address_bits:]), *(bank[n].eq(bank[n - 1]) for n in range(1, len(bank)))]
        with m.Switch(bank[-1]):
            for b in range(banks):
                with m.Case(b):
                    m.d.comb += read_data.eq(bank_data[b])


def kept_per_slice(m: Module, before_last, data: Value, kept: Value, slice_width: int, *, name: str,
                   platform) -> None:
    """``kept`` loaded with ``data``, or zeroed, each ``slice_width``-bit slice (a ``DP16KD``'s share of the
    word) under a select flag of its own: ``before_last`` registered once per slice (``{name}_s<slice>``,
    :func:`~hdl.dsp.kept_register`, kept distinct from its copies), so that each slice's flag can sit by the
    block RAM whose word it selects."""
    for s, lo in enumerate(range(0, len(data), slice_width)):
        bits = slice(lo, lo + slice_width)
        with m.If(kept_register(m, before_last, name=f"{name}_s{s}", platform=platform)):
            m.d.sync += kept[bits].eq(data[bits])
        with m.Else():
            m.d.sync += kept[bits].eq(0)


def dp16kd_banks(depth: int, width: int) -> tuple[int, int, int]:
    """``(slice width, words per bank, banks)``: the DP16KD configuration that holds ``depth`` words of
    ``width`` bits in the fewest block RAMs (``banks`` × ``ceil(width / slice width)``), fewer banks
    breaking a tie (one bank needs no multiplexer after the output registers)."""
    options = [(-(-depth // words) * -(-width // w), -(-depth // words), w, words) for w, words in DP16KD_CONFIGS]
    count, banks, w, words = min(options)
    return w, words, banks
