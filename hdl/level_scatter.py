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
        pass's last, and not both in a clock.
    lookup : ``In(range(depth))``; ``level`` : ``Out(certificate_level_shape())``
        ``level`` is the level of the node ``lookup`` named :attr:`LOOKUP_LATENCY` (three) clocks before,
        from a register; a lookup taken while ``idle`` sees every update before it. ``lookup`` is
        ignored in a clock with an update (the update reads the block RAM then).
    idle : ``Out(1)``
        No update in flight: every update transferred before this clock is in the memory.

    Contract
    --------
    The block RAM (:class:`~hdl.block_ram.BlockRam`) answers a read two clocks after its address and
    gives an undefined word when a write to the same address lands at the clock edge where the read
    address is taken. Its word is registered once more in the fabric before any logic reads it (the
    block RAM's output is far from some of its readers: the maximum here, the engine's stuck test and
    commit). An update's read is issued in its own clock and its maximum written three clocks later, so
    it misses the writes of the three updates (or clears) before it: the largest of its read (dropped
    where it collided with the write three clocks before), its level and those three writes' words to
    the same node is the whole maximum, because each of those words is itself complete.
    """

    #: Clock edges from an update's transfer to the edge that writes its node's new level.
    LATENCY = 3
    #: Clocks from a ``lookup`` to its ``level``: the block RAM's two, then the fabric register.
    LOOKUP_LATENCY = BlockRam.LATENCY + 1

    def __init__(self, depth: int, *, name: str = "levels"):
        if not isinstance(depth, int) or depth < 1:
            raise ValueError(f"LevelScatter depth must be a positive integer, not {depth!r}")
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

        # the three writes before this clock's (``last``: one clock ago; ``middle``: two; ``earliest``: three,
        # the one that collided with the read), and whether each is to this update's node: compared a clock
        # ahead, against the registers that become ``last``, ``middle`` and ``earliest`` as the update moves
        # on, so that only the maximum lies between flip-flops and the block RAM's write port
        write_layout = data.StructLayout({"level": certificate_level_shape(), "node": range(self.depth), "en": 1})
        last, middle, earliest = (Signal(write_layout, name=f"write_{age}") for age in ("last", "middle", "earliest"))
        to_last, to_middle = Signal(name="update_meets_last"), Signal(name="update_meets_middle")
        collided = Signal(name="update_meets_earliest")
        node, level = waiting[2].node, waiting[2].level

        def larger(a, b):
            return Mux(a > b, a, b)

        largest = larger(larger(level, Mux(to_last, last.level, 0)),
                         larger(Mux(to_middle, middle.level, 0), Mux(collided, earliest.level, read)))

        # a clear is written a clock after its transfer, from registers (so the write port's multiplexer and
        # the compares above read flip-flops only)
        clear_node = Signal(range(self.depth), name="clear_node")
        clearing = Signal(name="clearing")
        m.d.sync += [clear_node.eq(self.clear.payload), clearing.eq(self.clear.valid)]
        write = ram.write
        with m.If(valid[2]):
            m.d.comb += [write.addr.eq(node), write.data.eq(largest), write.en.eq(1)]
        with m.Elif(clearing):
            m.d.comb += [write.addr.eq(clear_node), write.data.eq(0), write.en.eq(1)]
        # (the two writes just before an update's are updates' own, never clears: a clear before them would
        # have come with an update, which the contract rules out)
        next_node = waiting[1].node
        m.d.sync += [last.level.eq(write.data), last.node.eq(write.addr), last.en.eq(write.en),
                     middle.eq(last), earliest.eq(middle),
                     to_last.eq(valid[2] & (node == next_node)),
                     to_middle.eq(last.en & (last.node == next_node)),
                     collided.eq(middle.en & (middle.node == next_node))]
        m.d.comb += self.idle.eq(~(valid[0] | valid[1] | valid[2]))
        return m
