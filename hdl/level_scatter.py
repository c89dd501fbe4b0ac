"""Each node's guard level, the largest of its triangles' levels: a read-modify-write of a block RAM,
one triangle corner per clock.

The RTL twin of :func:`golden_model.guard.node_levels` for one corner slot: the engine's guarded mode
is to give each of a triangle's three corners (``a``, ``b``, ``c``) a :class:`LevelScatter` of its
own, so that a triangle's three updates go in the same clock, and to take a node's level as the
largest of the three slots' (``docs/engine-guard.md``).
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .block_ram import BlockRam
from .layouts import certificate_level_shape
from .parameters import check_int

__all__ = ["LevelScatter", "level_update_layout"]


def level_update_layout(depth: int) -> data.StructLayout:
    """One corner's update: ``node`` (its index, ``range(depth)``) and the triangle's ``level``."""
    return data.StructLayout({"node": range(depth), "level": certificate_level_shape()})


class LevelScatter(wiring.Component):
    """``level[node] = max(level[node], update.level)`` for ``depth`` nodes, one update per clock.

    Members
    -------
    update : ``In(stream.Signature(level_update_layout(depth), always_ready=True))``
        One corner per beat; any node, repeats included, back to back.
    clear : ``In(stream.Signature(range(depth), always_ready=True))``
        Set a node's level to 0 (the pass before the updates; written a clock after the transfer).
        Clears and updates are separate passes: an update pass's first beat comes after the clear
        pass's last, and a clear pass's first while ``idle``.
    lookup : ``In(range(depth))``; ``level`` : ``Out(certificate_level_shape())``
        ``level`` is the level of the node ``lookup`` named :attr:`LOOKUP_LATENCY` (three) clocks before,
        from a register; a lookup taken while ``idle`` sees every update before it. ``lookup`` is
        ignored in a clock with an update (the update reads the block RAM then).
    idle : ``Out(1)``
        No update or clear in flight: every one transferred before this clock is in the memory.

    Contract
    --------
    The block RAM (:class:`~hdl.block_ram.BlockRam`) answers a read two clocks after its address and
    gives an undefined word when a write to the same address lands at the clock edge where the read
    address is taken. Its word is registered once more in the fabric before any logic reads it (the
    block RAM's output is far from some of its readers: the maximum here, the engine's stuck test and
    commit). The write port is a register too, beside the block RAM, so the maximum's logic ends in a
    flip-flop and not in a route to the block RAM. An update's read is issued in its own clock and its
    maximum written four clocks later, so it misses the four writes before its own (the earliest may
    be a clear's, the others are updates'): the largest of its read (dropped where it collided with
    the write four clocks before), its level and those four writes' words to the same node is the
    whole maximum, because each of those words is itself complete.
    """

    #: Clock edges from an update's transfer to the edge that writes its node's new level.
    LATENCY = 4
    #: Clocks from a ``lookup`` to its ``level``: the block RAM's two, then the fabric register.
    LOOKUP_LATENCY = BlockRam.LATENCY + 1

    def __init__(self, depth: int, *, name: str = "levels"):
        check_int("LevelScatter depth", depth)
        self.depth, self.name = depth, name
        super().__init__({
            "update": In(stream.Signature(level_update_layout(depth), always_ready=True)),
            "clear": In(stream.Signature(range(depth), always_ready=True)),
            "lookup": In(range(depth)),
            "level": Out(certificate_level_shape()),
            "idle": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.ram = ram = BlockRam(certificate_level_shape(), self.depth, name=self.name)
        port = ram.read[0]
        read = Signal(certificate_level_shape(), name="read_level")
        m.d.comb += [port.addr.eq(Mux(self.update.valid, self.update.payload.node, self.lookup)),
                     self.level.eq(read)]
        m.d.sync += read.eq(port.data)

        # the update's node and level while its read is under way (three clocks)
        layout = level_update_layout(self.depth)
        waiting = [Signal(layout, name=f"update{k}") for k in (1, 2, 3)]
        valid = [Signal(name=f"update{k}_valid") for k in (1, 2, 3)]
        m.d.sync += [waiting[0].eq(self.update.payload), valid[0].eq(self.update.valid),
                     *(w.eq(v) for w, v in zip(waiting[1:], waiting)), *(w.eq(v) for w, v in zip(valid[1:], valid))]

        # the block RAM's write port is a register (``writing``): the maximum is computed into it, so the
        # route to the block RAM starts at a flip-flop
        write_layout = data.StructLayout({"level": certificate_level_shape(), "node": range(self.depth), "en": 1})
        writing = Signal(write_layout, name="write_port")
        m.d.comb += [ram.write.addr.eq(writing.node), ram.write.data.eq(writing.level), ram.write.en.eq(writing.en)]

        # the four writes an update's read misses, seen from the clock that computes its maximum: ``writing``
        # (in the block RAM's port this clock), ``last`` (one clock before), ``middle`` (two) and ``earliest``
        # (three: the one that collided with the read). Whether each is to this update's node is compared a
        # clock ahead, against the registers that become them as the update moves on, so that only the
        # maximum lies between flip-flops and the write port register.
        last, middle, earliest = (Signal(write_layout, name=f"write_{age}") for age in ("last", "middle", "earliest"))
        to_writing, to_last = Signal(name="update_meets_writing"), Signal(name="update_meets_last")
        to_middle, collided = Signal(name="update_meets_middle"), Signal(name="update_meets_earliest")
        node, level = waiting[2].node, waiting[2].level

        def larger(a, b):
            return Mux(a > b, a, b)

        largest = larger(larger(larger(level, Mux(to_writing, writing.level, 0)), Mux(to_last, last.level, 0)),
                         larger(Mux(to_middle, middle.level, 0), Mux(collided, earliest.level, read)))

        # a clear goes into the write port register in its own clock and lands a clock after its transfer:
        # an update transferred after it reads it or collides with it (``earliest``), and never misses it,
        # which a maximum could not mend. So ``writing``, ``last`` and ``middle`` are updates' writes.
        with m.If(valid[2]):
            m.d.sync += [writing.node.eq(node), writing.level.eq(largest), writing.en.eq(1)]
        with m.Elif(self.clear.valid):
            m.d.sync += [writing.node.eq(self.clear.payload), writing.level.eq(0), writing.en.eq(1)]
        with m.Else():
            m.d.sync += writing.en.eq(0)
        next_node = waiting[1].node
        m.d.sync += [last.eq(writing), middle.eq(last), earliest.eq(middle),
                     to_writing.eq(valid[2] & (node == next_node)),
                     to_last.eq(writing.en & (writing.node == next_node)),
                     to_middle.eq(last.en & (last.node == next_node)),
                     collided.eq(middle.en & (middle.node == next_node))]
        m.d.comb += self.idle.eq(~(valid[0] | valid[1] | valid[2] | writing.en))
        return m
