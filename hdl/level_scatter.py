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
        ``level`` is the level of the node ``lookup`` named two clocks before; a lookup taken while
        ``idle`` sees every update before it. ``lookup`` is ignored in a clock with an update (the
        update reads the block RAM then).
    idle : ``Out(1)``
        No update in flight: every update transferred before this clock is in the memory.

    Contract
    --------
    The block RAM (:class:`~hdl.block_ram.BlockRam`) answers a read two clocks after its address and
    gives an undefined word when a write to the same address lands at the clock edge where the read
    address is taken. An update's read is issued in its own clock and its maximum written two clocks
    later, so it misses the writes of the two updates (or clears) before it: the largest of its read
    (dropped where it collided with the write two clocks before), its level and those two writes' words
    to the same node is the whole maximum, because each of those words is itself complete.
    """

    #: Clock edges from an update's transfer to the edge that writes its node's new level.
    LATENCY = 2

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
        m.d.comb += [port.addr.eq(Mux(self.update.valid, self.update.payload.node, self.lookup)),
                     self.level.eq(port.data)]

        # the update's node and level while its read is under way (two clocks)
        layout = level_update_layout(self.depth)
        waiting = [Signal(layout, name=f"update{k}") for k in (1, 2)]
        valid = [Signal(name=f"update{k}_valid") for k in (1, 2)]
        m.d.sync += [waiting[0].eq(self.update.payload), valid[0].eq(self.update.valid),
                     waiting[1].eq(waiting[0]), valid[1].eq(valid[0])]

        # the two writes before this clock's (last: one clock ago; earlier: two clocks ago), and whether each
        # is to this update's node: compared a clock ahead, against the write and the last write of the
        # clock before (which become ``last`` and ``earlier`` as the update moves on), so that only the
        # maximum's compares lie between flip-flops and the block RAM's write port
        write_layout = data.StructLayout({"level": certificate_level_shape(), "en": 1})
        last, earlier = Signal(write_layout, name="write_last"), Signal(write_layout, name="write_earlier")
        last_node = Signal(range(self.depth), name="write_last_node")
        to_last, collided = Signal(name="update_meets_last"), Signal(name="update_meets_earlier")
        node, level = waiting[1].node, waiting[1].level

        def larger(a, b):
            return Mux(a > b, a, b)

        largest = larger(larger(level, Mux(to_last, last.level, 0)),
                         larger(Mux(collided, 0, port.data), Mux(collided, earlier.level, 0)))

        # a clear is written a clock after its transfer, from registers (so the write port's multiplexer and
        # the compare above read flip-flops only)
        clear_node = Signal(range(self.depth), name="clear_node")
        clearing = Signal(name="clearing")
        m.d.sync += [clear_node.eq(self.clear.payload), clearing.eq(self.clear.valid)]
        write = ram.write
        with m.If(valid[1]):
            m.d.comb += [write.addr.eq(node), write.data.eq(largest), write.en.eq(1)]
        with m.Elif(clearing):
            m.d.comb += [write.addr.eq(clear_node), write.data.eq(0), write.en.eq(1)]
        # (a clear is never the write just before an update's: that clear would have come with the update)
        next_node = waiting[0].node
        m.d.sync += [last.level.eq(write.data), last.en.eq(write.en), last_node.eq(write.addr), earlier.eq(last),
                     to_last.eq(valid[1] & (node == next_node)), collided.eq(last.en & (last_node == next_node))]
        m.d.comb += self.idle.eq(~(valid[0] | valid[1]))
        return m
