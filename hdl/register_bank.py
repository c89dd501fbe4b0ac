"""The engine's register bank: every register of a :class:`~golden_model.engine_spec.register_map.RegisterMap`,
each field acting as its declared access type says, and the bus target's answers.

As ``amaranth_soc.csr`` takes a field's behaviour from its action (``csr.action.R``, ``RW``, ``RW1C``,
...), the bank takes it from the map's access type (:data:`~golden_model.engine_spec.register_map.ACCESS`);
it knows no register by name. A field's port is named for the value it carries (``BitField.value``;
a value wider than a word is one port over all its registers):

========  ==================================================================================
access    behaviour and port
========  ==================================================================================
``ro``    reads the ``In`` port of its value; in an ``identification`` register, reads the
          register's declared reset (the map's constants: magic, version, format hash,
          capacity), no port. Writing a register whose access is ``ro`` is a bus error.
``rw``    storage (reset 0), written by a whole-word bus write, read back; ``Out`` port.
``w1p``   writing 1 raises the ``Out`` port for one clock, the clock after the write; reads 0.
``w1c``   a flag with storage (reset 0), the ``Out`` port; reads the flag; writing 1 clears it.
          ``<value>_set`` (``In``) sets it, ``<value>_clear`` (``In``) clears it. In one clock the
          set input wins over the clear input, which wins over the bus write (a run that START
          ends at once, with no mesh or bad constants, leaves its interrupt pending).
========  ==================================================================================
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.engine_spec.image import BUS_WORD_BITS
from golden_model.engine_spec.register_map import RegisterMap

from .logic import or_tree
from .parameters import check_int

__all__ = ["RegisterBank"]

#: The bus side's members (the handshake's registered request and the answer; the windows' part).
_BUS_MEMBERS = ("request", "address", "write", "write_data", "whole_word", "bus_request", "window_hit",
                "window_answer", "window_data", "done", "error", "data")

#: A read-only register of this block reads its declared reset: the map's constants.
CONSTANT_BLOCK = "identification"


class RegisterBank(wiring.Component):
    """The registers of ``register_map`` on the bus, fields by access type (see the module).

    Parameters
    ----------
    register_map : :class:`~golden_model.engine_spec.register_map.RegisterMap`
    addr_width : int
        Width of the bus's word address (the map's registers and windows fit it).
    copies : tuple of str
        ``rw`` values that also get a copy register, ``Out`` port ``<value>_held``, following the
        value a clock later: a value read by a unit across the die is read from its copy (registered
        because the register file sits by the bus decode and the unit's first stage far from it).
        The host writes a run constant a bus cycle or more before START, so the copy is current
        when a run reads it.
    registered_write : bool
        Each writable register's write enable and the bus's data in flip-flops: a write acts a clock
        after DEC (see the contract), its answer as before.

    Members
    -------
    request, address, write, write_data, whole_word : ``In``
        The bus handshake's registered request (:class:`~hdl.wishbone.TargetHandshake`).
    bus_request : ``Out(1)``
        DEC: ``request`` registered, the clock the address decode is registered (``reg_select``
        here, the windows' decode in :class:`~hdl.memory_windows.MemoryWindows`).
    window_hit, window_answer, window_data : ``In``
        From the memory windows: the decoded request is a window's and the engine is idle (at
        DEC); the window's answer and its read word.
    done, error, data : ``Out``
        The answer to the handshake.
    one port per field value, see the module; ``<value>_held`` per ``copies``.

    Contract
    --------
    A register write acts at DEC's clock edge: ``rw`` storage holds the word the clock after DEC,
    a ``w1p`` port is high that clock (with ``registered_write`` a clock later: each writable register's
    write enable and the bus's data in flip-flops first, so that the enable reaches a register placed
    beside its loads from a flip-flop). A register answers two clocks after DEC (the one-hot select's
    AND-OR into groups of eight, landed, then their OR, landed): ``error`` for a write to a ``ro``
    register or a partial word. A request that is neither a register nor an idle window is refused
    (``error``) the clock after DEC. A window's answer is passed on as it comes.
    """

    def __init__(self, register_map: RegisterMap, *, addr_width: int, copies: tuple[str, ...] = (),
                 registered_write: bool = False):
        if not isinstance(register_map, RegisterMap):
            raise TypeError(f"RegisterBank needs a RegisterMap, not {register_map!r}")
        if not isinstance(registered_write, bool):
            raise TypeError(f"RegisterBank registered_write must be a bool, not {registered_write!r}")
        self.registered_write = registered_write
        end = max([r.offset + 1 for r in register_map.registers] + [w.base + w.size for w in register_map.windows])
        check_int("addr_width", addr_width, minimum=max(1, (end - 1).bit_length()))  # (to reach the map's last word)
        self.register_map, self.addr_width, self.copies = register_map, addr_width, tuple(copies)
        self.values = _field_values(register_map)
        members = {}
        for value, (access, width) in self.values.items():
            if access == "ro":
                members[value] = In(width)
            elif access in ("rw", "w1p"):
                members[value] = Out(width)
            else:  # w1c
                members.update({value: Out(width), f"{value}_set": In(width), f"{value}_clear": In(width)})
        for name in self.copies:
            if self.values.get(name, ("",))[0] != "rw":
                raise ValueError(f"a copy register is for a rw value; {name!r} is not one")
            members[f"{name}_held"] = Out(self.values[name][1])
        clashes = sorted(set(members) & (set(_BUS_MEMBERS) | set(dir(wiring.Component)) | set(vars(self))))
        if clashes:
            raise ValueError(f"register map values {clashes} clash with RegisterBank's members or attributes")
        super().__init__({
            "request": In(1), "address": In(addr_width), "write": In(1), "write_data": In(BUS_WORD_BITS),
            "whole_word": In(1), "bus_request": Out(1),
            "window_hit": In(1), "window_answer": In(1), "window_data": In(BUS_WORD_BITS),
            "done": Out(1), "error": Out(1), "data": Out(BUS_WORD_BITS),
            **members,
        })

    def elaborate(self, platform):
        m = Module()
        registers = self.register_map.registers
        storage = {v: Signal(w, name=f"reg_{v}") for v, (a, w) in self.values.items() if a == "rw"}
        pulses = {v: Signal(w, name=f"{v}_pulse") for v, (a, w) in self.values.items() if a == "w1p"}
        flags = {v: getattr(self, v) for v, (a, _) in self.values.items() if a == "w1c"}
        m.d.comb += [getattr(self, v).eq(s) for v, s in (storage | pulses).items()]
        m.d.sync += [getattr(self, f"{v}_held").eq(storage[v]) for v in self.copies]

        # DEC: the request and a one-hot register select, registered (the decode of the whole address
        # into every register's write enable and the answer is a clock of its own). The select decodes
        # the address's low bits only, and `bus_reg_hit` is whether the address is a register's: a bit of
        # a constant map of the offsets, indexed by the low bits, with the high bits zero. A write needs
        # both; a read's word and read-only flag are used only on a hit. (The select's compares of the
        # whole address and the OR of the select in front of the answer's logic were long paths.)
        offset_bits = max(1, max(r.offset for r in registers).bit_length())
        offset_map = Const(sum(1 << r.offset for r in registers), 1 << offset_bits)
        low = self.address[:offset_bits]
        low_hit, high_zero = offset_map.bit_select(low, 1), self.address[offset_bits:] == 0
        reg_select = Signal(len(registers))
        m.d.sync += [self.bus_request.eq(self.request), reg_select.eq(Cat(low == r.offset for r in registers))]
        if self.registered_write:
            # the hit's two halves in registers of their own, ANDed where they are used: the bank sits far
            # from the handshake's address register, and that route leaves time for two LUTs, not for the
            # five of the whole decode
            bus_low_hit, bus_high_zero = Signal(name="bus_low_hit"), Signal(name="bus_high_zero")
            m.d.sync += [bus_low_hit.eq(low_hit), bus_high_zero.eq(high_zero)]
            bus_reg_hit = bus_low_hit & bus_high_zero
        else:
            bus_reg_hit = Signal(name="bus_reg_hit")
            m.d.sync += bus_reg_hit.eq(low_hit & high_zero)
        bus_write = self.bus_request & self.write & self.whole_word & bus_reg_hit
        write_data = self.write_data
        if self.registered_write:  # a register's write enable and the data in flip-flops, a clock later
            write_data = Signal.like(self.write_data, name="write_data_q", reset_less=True)
            m.d.sync += write_data.eq(self.write_data)
            # DEC's write a flip-flop of its own, loaded with the request from the handshake's flags (``write``
            # and ``whole_word`` hold from the request to the answer), the decode's hit joining it at each
            # register's write enable: that enable is one LUT from flip-flops, and no decode lies in front of
            # the flag, which the placer puts by its loads, across the die from the handshake
            write_request = Signal(name="bus_write_request")
            m.d.sync += write_request.eq(self.request & self.write & self.whole_word)
            bus_write = write_request & bus_reg_hit

        # reads and writes: a write acts in DEC's clock (registered_write: the next); the answer comes from
        # the read word landed
        m.d.sync += [p.eq(0) for p in pulses.values()]
        read_terms, read_only_terms = [], []
        for k, r in enumerate(registers):
            selected = reg_select[k]
            word = Signal(BUS_WORD_BITS, name=f"rd_{r.name.lower()}")
            m.d.comb += word.eq(_register_word([(f.lsb, self._read_source(r, f, storage), f.width) for f in r.fields]))
            read_terms.append(Mux(selected, word, 0))
            if r.access == "ro":
                read_only_terms.append(selected)
            writes = bus_write & selected
            if self.registered_write and r.access != "ro":
                writes = Signal(name=f"write_{r.name.lower()}")
                m.d.sync += writes.eq(bus_write & selected)
            with m.If(writes):
                for f in r.fields:
                    bits = write_data[f.lsb:f.lsb + f.width]
                    at = slice(f.value_lsb, f.value_lsb + f.width)
                    if f.access == "rw":
                        m.d.sync += storage[f.value][at].eq(bits)
                    elif f.access == "w1p":
                        m.d.sync += pulses[f.value][at].eq(bits)
                    elif f.access == "w1c":
                        for i in range(f.width):
                            with m.If(bits[i]):
                                m.d.sync += flags[f.value][f.value_lsb + i].eq(0)
        for v, flag in flags.items():  # after the bus write, so the hardware wins: its clear, then its set
            clear, set_ = getattr(self, f"{v}_clear"), getattr(self, f"{v}_set")
            for i in range(len(flag)):
                with m.If(clear[i]):
                    m.d.sync += flag[i].eq(0)
                with m.If(set_[i]):
                    m.d.sync += flag[i].eq(1)

        # The AND-OR over the one-hot select in two clocks: groups of eight registers, each OR landed in
        # a register of its own, then their OR (registered because one clock from reg_select through the
        # whole tree into the landed word is most of a period in routing alone)
        read_word = Signal(BUS_WORD_BITS)
        read_only = Signal()
        read_groups = [Signal(BUS_WORD_BITS, name=f"read_group{k}", reset_less=True)
                       for k in range(0, len(read_terms), 8)]
        m.d.sync += [group.eq(or_tree(read_terms[8 * k:8 * k + 8])) for k, group in enumerate(read_groups)]
        m.d.comb += read_word.eq(or_tree(read_groups))
        m.d.sync += read_only.eq(or_tree(read_only_terms))
        self._answer(m, bus_reg_hit, read_word, read_only)
        return m

    def _read_source(self, register, field, storage) -> Value:
        """What ``field`` of ``register`` reads, ``field.width`` bits."""
        if field.access == "w1p":
            source = Const(0, 1)
        elif field.access == "rw":
            source = storage[field.value][field.value_lsb:field.value_lsb + field.width]
        elif field.access == "ro" and register.block == CONSTANT_BLOCK:
            source = Const((register.reset >> field.lsb) & ((1 << field.width) - 1), field.width)
        else:  # ro from its port, w1c from its flag
            source = getattr(self, field.value)[field.value_lsb:field.value_lsb + field.width]
        return Value.cast(source).as_unsigned()[:field.width]

    def _answer(self, m: Module, bus_reg_hit, read_word, read_only) -> None:
        """Every answer from flip-flops: a register's two clocks after DEC (its word and error landed),
        a refusal (an unmapped word, or a window while running) the clock after DEC, a window's as it
        comes."""
        reg_pending, reg_answer = Signal(name="reg_pending"), Signal(name="reg_answer")
        refused = Signal()
        landed_word = Signal(BUS_WORD_BITS, reset_less=True)
        landed_error = Signal(reset_less=True)
        m.d.sync += [reg_pending.eq(self.bus_request & bus_reg_hit), reg_answer.eq(reg_pending),
                     refused.eq(self.bus_request & ~bus_reg_hit & ~self.window_hit),
                     landed_word.eq(read_word), landed_error.eq((read_only & self.write) | ~self.whole_word)]
        with m.If(reg_answer):
            m.d.comb += [self.done.eq(1), self.error.eq(landed_error), self.data.eq(landed_word)]
        with m.Elif(refused):
            m.d.comb += [self.done.eq(1), self.error.eq(1)]
        with m.Elif(self.window_answer):
            m.d.comb += [self.done.eq(1), self.error.eq(~self.whole_word), self.data.eq(self.window_data)]


def _field_values(register_map: RegisterMap) -> dict[str, tuple[str, int]]:
    """``{value: (access, width)}`` of every field value with a port or storage (not the constants)."""
    values: dict[str, tuple[str, int]] = {}
    for r in register_map.registers:
        for f in r.fields:
            if f.value is None or (f.access == "ro" and r.block == CONSTANT_BLOCK):
                continue
            access = values.get(f.value, (f.access,))[0]
            if access != f.access:
                raise ValueError(f"register map: {f.value} is {access} in one field and {f.access} in another")
            values[f.value] = (f.access, register_map.value_width(f.value))
    return values


def _register_word(pieces) -> Value:
    """A register's word from ``(lsb, value, width)`` pieces, unused bits as constant zeros.

    The whole word in one assignment, zeros beside the fields: a separate constant-only assignment
    becomes an input-less ``always @*`` block in the Verilog, which an event-driven simulator (Icarus)
    never runs."""
    parts, at = [], 0
    for lsb, value, width in sorted(pieces, key=lambda p: p[0]):
        parts += [Const(0, lsb - at)] if lsb > at else []
        parts.append(value)
        parts += [Const(0, width - len(value))] if len(value) < width else []
        at = lsb + width
    return Cat(*parts)
