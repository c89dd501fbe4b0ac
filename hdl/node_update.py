"""The node-update datapath: force accumulation and the Euler step, one neighbour entry per clock.

The RTL twin of :func:`golden_model.fixed.pipeline.node_update`; every width comes
from a :class:`~golden_model.fixed.FormatSet`. ``docs/hardware.md`` maps each
pipeline stage onto the steps of ``docs/fixed-point.md``.
"""

from __future__ import annotations

from amaranth.hdl import Module, Signal
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet

from .fifo import SlicedFIFO
from .fixedpoint import shape_of
from .force_pass import ForcePass, format_set
from .integrator import Integrator
from .layouts import entry_layout, node_layout, result_layout

__all__ = ["NodeUpdate"]


class NodeUpdate(wiring.Component):
    """Pipelined per-node update (``jacobi``), bit-exact with the golden model's ``node_update``.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        Every width, the rounding mode and ``max_degree`` come from it.

    Members
    -------
    i : ``In(stream.Signature(entry_layout(fs)))``
        Neighbour entries, node after node; the node's header (position, velocity,
        1/m and the barrier's weight) rides on its first entry (``first``), ``last`` closes the node. A node
        with n ≥ 1 neighbours is n beats.
    o : ``Out(stream.Signature(result_layout(fs)))``
        One beat per node, in input order: new position, new velocity (damped), and
        the node's Σ|L − d| of the *input* positions.
    dt, half_dt_sq, half_spring, damping : ``In(...)``
        ``Δt`` [dt], ``½Δt²`` [half_dt_sq], ``½C`` [spring], ``1 − γ`` [damping]. Hold them
        stable while a pass is in flight (they are registered once per clock).
    idle : ``Out(1)``
        No entry in flight: every node whose entries were accepted has left ``o``, and no node
        is half accepted. A pass is done when ``idle`` rises after its last entry.
    momentum : ``In(1)``
        The momentum dynamics (``docs/dynamics.md``): ``dt`` carries ``β``, the Euler step
        becomes ``V' = rq(β·V + a → velocity)``, ``P' = sat(P + V')``; ``half_dt_sq`` and
        ``damping`` are not used. Change it only between passes.

    Contract
    --------
    Throughput: one neighbour entry per clock (II = 1) whenever ``o`` is ready, with no
    gap between nodes, for nodes of any degree from 1 to ``fs.max_degree``.
    Latency: ``latency`` clocks from the transfer of a node's last entry to its result
    on ``o`` when never stalled (so N entries take N + ``latency`` clocks).
    Back-pressure: ``o.valid`` and ``o.payload`` never depend on ``o.ready``; a result
    stays offered until taken; any stall pattern on either side is allowed.
    ``o.payload`` is one of two registers per FIFO column slice (a 2:1 multiplexer, no other logic).

    Structure
    ---------
    :class:`~hdl.force_pass.ForcePass` → node-header FIFO → :class:`~hdl.integrator.Integrator`
    → result FIFO. The datapath never stalls. Every stage register loads on every clock, so no
    enable fans out across the ~26,900 flip-flops. The force pass sums each node's forces,
    ``|L − d|`` and ``inside`` over its entries; the node's header (position, velocity and the two
    weights) waits in a FIFO from the input until the force pass's result leaves, and the
    integrator's first stage registers both (the header straight from the FIFO's LUT RAM, read
    on a flip-flop: the force pass's ``o.valid``); the integrator runs ``a = F·w`` (the barrier's
    weight if a triangle of the node is inside it), the Euler or momentum step and damping, and
    carries the error sum along. Results enter a LUT-RAM FIFO (column slices with their own
    pointers), each slice ending in two output registers; it holds ``result_depth`` =
    ``credits`` + 2 results. Back-pressure is a credit count: ``i.ready`` is high while fewer
    than ``credits`` nodes are owed (accepted last entries whose results have not left ``o``) as
    counted, and the count sees a node two clocks after its last entry, so at most
    ``result_depth`` nodes are ever owed (exactly that many are accepted with ``o`` stalled and
    a node arriving every clock) and the result FIFO can never overflow; ``credits`` covers the
    latency and that delay, so credits never run out while ``o`` is ready, even for degree-1
    nodes. ``front_stages``, ``rsqrt_latency``, ``back_stages`` (the force pass) and
    ``tail_stages`` (the integrator) are counted from the pipelines the components build.

    Every multiplier sits alone between registers (its 18×18 partial products, operands and
    products registered, then the products landed in fabric registers); partial
    products are added pairwise, one adder per stage; every rounding and every
    saturation has a stage of its own.
    """

    #: Width of one column slice of the header and result FIFOs (each slice has its own pointers).
    #: 12 bits: a slice of the 128-deep result FIFO is 24 LUT RAM cells, which its read pointer
    #: reaches within a clock wherever they are placed (wider slices' pointers reach more cells, and
    #: their timing then depends on placement).
    FIFO_SLICE_BITS = 12

    def __init__(self, fs: FormatSet | str):
        fs = format_set(fs, "NodeUpdate")
        self.fs = fs
        self._force_pass = ForcePass(fs)
        self._integrator = Integrator(fs, side=shape_of(fs.error_acc))  # the error sum rides along
        stages = self._force_pass.stages
        self.front_stages, self.rsqrt_latency, self.back_stages = stages.front, stages.rsqrt, stages.back
        self.tail_stages = self._integrator.latency
        self.pipeline_stages = self._force_pass.latency + self._integrator.latency
        # The result FIFO's write register (per slice, see below), its write and the output register.
        self.latency = self.pipeline_stages + 3
        # Credits: a power of two, more than the latency plus the count's two clocks of delay, so
        # the credits never run out while o is ready; the result FIFO (as deep, plus its two
        # output registers per slice) holds every node owed, up to result_depth.
        self.credits = 1 << (self.latency + 3).bit_length()
        self.result_depth = self.credits + 2
        super().__init__({
            "i": In(stream.Signature(entry_layout(fs))),
            "o": Out(stream.Signature(result_layout(fs))),
            "dt": In(shape_of(fs.dt)),
            "half_dt_sq": In(shape_of(fs.half_dt_sq)),
            "half_spring": In(shape_of(fs.spring)),
            "damping": In(shape_of(fs.damping)),
            "momentum": In(1),
            "idle": Out(1),
        })

    def elaborate(self, platform):
        fs = self.fs
        m = Module()
        m.submodules.force_pass = force_pass = self._force_pass
        m.submodules.integrator = integrator = self._integrator

        # ------------------------------------------------------------ credits
        # owed: accepted last entries whose results have not left o, as counted. A node's last
        # entry reaches the count two clocks late, through two flip-flops that the placer can put
        # at the input and at the counter (the input's last bit into the counter's carry chain
        # across the die is a long path). i.ready = counted owed < credits
        # leaves a flip-flop, set from the current count and this clock's handshakes alone (no
        # adder on that path): credits is a power of two. Up to two nodes are accepted but not yet
        # counted, so up to credits + 2 are owed: the result FIFO holds exactly that many.
        credits = self.credits
        owed = Signal(range(credits + 3))
        # The same decision in two flip-flops: `accepting` drives i.ready out of the block,
        # `refusing` (its complement, so that synthesis does not merge the two) everything inside,
        # so the counter's loop stays local (one flip-flop driving both was 5.6 ns of routing
        # away from the counter).
        accepting = Signal(init=1)
        refusing = Signal(init=0)
        take = self.i.valid & ~refusing
        node_taken, node_counted = Signal(), Signal()
        m.d.sync += [node_taken.eq(take & self.i.payload.last), node_counted.eq(node_taken)]
        leave = self.o.valid & self.o.ready
        grow = node_counted & ~leave
        shrink = leave & ~node_counted
        top = credits.bit_length() - 1
        assert credits == 1 << top
        below = ~owed[top]  # owed < credits (owed < 2·credits always)
        at_credits_minus_1 = below & owed[:top].all()
        at_credits = owed[top] & ~owed[:top].any()
        accept_next = (below & ~(at_credits_minus_1 & grow)) | (at_credits & shrink)
        m.d.sync += [owed.eq(owed + grow - shrink), accepting.eq(accept_next), refusing.eq(~accept_next)]
        m.d.comb += self.i.ready.eq(accepting)
        # idle: no node owed, none on its way to the count, none half accepted (between its first
        # and last entry)
        open_node = Signal()
        with m.If(take):
            m.d.sync += open_node.eq(~self.i.payload.last)
        m.d.comb += self.idle.eq((owed == 0) & ~node_taken & ~node_counted & ~open_node)

        # ------------------------------------------------------------ force pass
        beat = self.i.payload
        entry = force_pass.i.payload
        m.d.comb += [
            force_pass.i.valid.eq(take), force_pass.half_spring.eq(self.half_spring),
            entry.first.eq(beat.first), entry.last.eq(beat.last), entry.position.eq(beat.node.position),
            entry.neighbour.eq(beat.neighbour), entry.barrier.eq(beat.barrier),
        ]

        # ------------------------------------------------------------ node headers
        # The header is written two clocks late, from registers here and again in each FIFO slice
        # (write_register): the write enable would otherwise fan out to every LUT RAM row of
        # the FIFO, and the read comes dozens of clocks later anyway. A node's header is read
        # when its forces leave the force pass: the read enable is then a flip-flop (the pass's
        # o.valid) that drives only the slices' read pointers, and the integrator's first stage
        # registers the header straight from the LUT RAM (reading with the last entry itself,
        # through an AND gate into the pointers and a header register, adds logic to a long
        # route). At most one node per force-pass stage is in flight, so the FIFO never fills.
        m.submodules.headers = headers = SlicedFIFO(
            width=node_layout(fs).size, slice_bits=self.FIFO_SLICE_BITS, write_register=True,
            depth=1 << (force_pass.latency + 1).bit_length())
        header_write = Signal(name="header_write")
        header_data = Signal(node_layout(fs), name="header_data", reset_less=True)
        m.d.sync += [header_write.eq(take & beat.first), header_data.eq(beat.node)]
        m.d.comb += [headers.w_stream.valid.eq(header_write), headers.w_stream.payload.eq(header_data.as_value()),
                     headers.r_stream.ready.eq(force_pass.o.valid)]

        # ------------------------------------------------------------ integrator
        forces, node = force_pass.o.payload, integrator.i.payload
        m.d.comb += [
            integrator.i.valid.eq(force_pass.o.valid),
            node.node.eq(headers.r_stream.payload), node.force.eq(forces.force), node.inside.eq(forces.inside),
            node.side.eq(forces.error_sum),
            integrator.dt.eq(self.dt), integrator.half_dt_sq.eq(self.half_dt_sq),
            integrator.damping.eq(self.damping), integrator.momentum.eq(self.momentum),
        ]

        # ------------------------------------------------------------ results
        # The result FIFO: LUT RAM column slices, each with its own pointers and its own two
        # output registers, so a read enable reaches only its own 12-bit slice and o.ready only
        # a few flags per slice (one shared read enable over every slice fans out across the die).
        # Never written full: the credits count its depth and the output register.
        new = integrator.o.payload
        result = Signal(result_layout(fs), name="result")
        m.d.comb += [result.position.eq(new.position), result.velocity.eq(new.velocity),
                     result.error_sum.eq(new.side), result.power.eq(new.power)]
        # Each slice registers its own write (write_register): the integrator's valid bit as the
        # write enable of every slice's LUT RAM would be one signal routed to all of them.
        m.submodules.results = results = SlicedFIFO(width=result_layout(fs).size, depth=self.credits,
                                                    slice_bits=self.FIFO_SLICE_BITS, registered=True,
                                                    write_register=True)
        m.d.comb += [results.w_stream.valid.eq(integrator.o.valid), results.w_stream.payload.eq(result.as_value()),
                     self.o.valid.eq(results.r_stream.valid), self.o.payload.eq(results.r_stream.payload),
                     results.r_stream.ready.eq(self.o.ready)]
        return m
