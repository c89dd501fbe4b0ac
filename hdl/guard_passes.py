"""The guarded step's passes after the proposal: the stuck-node and certificate passes over the triangles,
and the hold, commit and rollback passes over the nodes.

The RTL twin of :func:`golden_model.fixed.guard.guarded_moves_raw` and :func:`~golden_model.fixed.guard.commit`
(and of the rollback of :meth:`golden_model.fixed.controller.Controller._advance_guarded`), pass by pass as
``docs/engine-guard.md`` plans them; the fetches are the :class:`~hdl.pass_sequencer.PassSequencer`'s.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.coarse import CLIP_HANDOVER_LEVEL
from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import EngineCapacity

from .block_ram import BlockRam
from .dsp import kept_register
from .fifo import LutFIFO
from .guard_certificate import GuardCertificate
from .guard_commit import GuardCommit
from .fixedpoint import shape_of
from .layouts import certificate_level_shape, vector_layout
from .level_scatter import LevelScatter
from .memory_windows import node_write_layout, write_signature
from .parameters import check_int

__all__ = ["GuardPasses", "GUARD_PASSES"]

#: The guard's passes after the proposal, in the order an iteration runs them (``rollback`` only after a
#: rejected step); each has the controller's phase flag ``in_<name>``.
GUARD_PASSES = ("stuck", "hold", "certify", "commit", "rollback")


class GuardPasses(wiring.Component):
    """The guard's certificate unit, its three level scatters and the commit, fed by the sequencer's fetches.

    * **stuck** (triangles, one per two clocks): :class:`~hdl.guard_certificate.GuardCertificate` on the
      corners' positions and proposals (the landed triangle registered first); each corner's ``stuck``
      bit into its slot's :class:`~hdl.level_scatter.LevelScatter` (a maximum of 0/1 is an OR);
    * **hold** (nodes): a node stuck in any slot gets a proposal of 0 (all three proposal copies
      written), and its slots are cleared for the certificate;
    * **certify** (triangles, one per two clocks): the certificate on the held proposals; each
      triangle's ``level`` into its three corners' slots;
    * **commit** (nodes): :class:`~hdl.guard_commit.GuardCommit` on the node's position, proposal and
      its slots' levels (the landed node registered first, one clock more per node pass): ``P + D``
      and ``V = D`` into the node memories;
    * **rollback** (nodes, a rejected step only): the same unit on the node's position and committed
      move: ``P − V`` and ``V = 0``.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
    capacity : :class:`~golden_model.engine_spec.image.EngineCapacity`
    read_latency : int
        Clocks from the node memories' address registers to their data. The scatters' lookups are taken
        a clock before those registers, from ``node_index``, and answer
        :attr:`LevelScatter.LOOKUP_LATENCY <hdl.level_scatter.LevelScatter.LOOKUP_LATENCY>` after it:
        their levels are delayed by the difference.
    registered_valid : bool
        The certificate's ``o.valid`` from a flip-flop of its own
        (:class:`~hdl.guard_certificate.GuardCertificate`'s ``registered_valid``), the same in every clock:
        it steps the triangle count, whose end flag sits by the controller across the device from the
        certificate. The engine builds it with the registered select (above ``DEFAULT_CAPACITY``).

    Members
    -------
    in_stuck, in_hold, in_certify, in_commit, in_rollback : ``In(1)``
        The controller's phase flags (one at a time).
    vertices, triangles : ``In``
        The mesh's counts (a pass's end).
    node_index : ``In``
        The sequencer's node counter, from which the memories' read addresses are registered: the
        scatters' lookup, a clock earlier.
    node_landed, triangle_landed, corners[3], area : ``In``
        The sequencer's landed items (:class:`~hdl.pass_sequencer.PassSequencer`).
    position[3], proposal[3], velocity : ``In``
        The memories' read data (corner k's on port k; a node pass's on port 0).
    proposal_write, node_write : ``Out(write_signature(...))``
        The hold pass's proposals; the commit and rollback passes' positions and velocities.
    done : ``Out(1)``
        A pass's end: one clock, registered, after its last write.
    idle : ``Out(1)``
        Registered: in the clock before, no triangle was owed by the certificate, no update was in a
        scatter and no node in the commit (an aborted run drains until then).
    clipped : ``Out(1)``
        With a coarse space only (``capacity.coarse_degree``): a node of the last commit pass took a level of
        :data:`~golden_model.coarse.CLIP_HANDOVER_LEVEL` or more (a register, cleared in the step phase, which
        follows the decision on that commit: :func:`golden_model.coarse.clipped_deep`).
    """

    def __init__(self, fs: FormatSet, capacity: EngineCapacity, *, read_latency: int = BlockRam.LATENCY,
                 registered_valid: bool = False):
        if not isinstance(fs, FormatSet) or not isinstance(capacity, EngineCapacity):
            raise TypeError(f"GuardPasses needs a FormatSet and an EngineCapacity, not {fs!r}, {capacity!r}")
        shortest = LevelScatter.LOOKUP_LATENCY - 1
        check_int("read_latency", read_latency, shortest)
        if not isinstance(registered_valid, bool):
            raise TypeError(f"registered_valid must be a bool, not {registered_valid!r}")
        self.fs, self.capacity, self.read_latency = fs, capacity, read_latency
        self.registered_valid = registered_valid
        nodes = range(capacity.vertices + 1)
        pos, vel = vector_layout(fs.position), vector_layout(fs.velocity)
        super().__init__({
            **{f"in_{name}": In(1) for name in GUARD_PASSES}, "in_step": In(1), "in_integrate": In(1),
            "vertices": In(nodes), "triangles": In(range(capacity.triangles + 1)),
            "node_index": In(nodes), "node_landed": In(1), "triangle_landed": In(1),
            "corners": In(range(capacity.vertices)).array(3), "area": In(shape_of(fs.face_area)),
            "position": In(pos).array(3), "proposal": In(vel).array(3), "velocity": In(vel),
            "proposal_write": Out(write_signature(nodes, vel)),
            "node_write": Out(write_signature(nodes, node_write_layout(fs))),
            "done": Out(1), "idle": Out(1), **({"clipped": Out(1)} if capacity.coarse_degree else {}),
        })

    def elaborate(self, platform):
        m = Module()
        fs, cap = self.fs, self.capacity
        m.submodules.certificate = certificate = GuardCertificate(fs, interval=2,
                                                                  registered_valid=self.registered_valid)
        m.submodules.commit = commit = GuardCommit(fs)
        scatters = [LevelScatter(cap.vertices, name=f"guard_levels_{slot}") for slot in "abc"]
        for slot, scatter in zip("abc", scatters):
            m.submodules[f"scatter_{slot}"] = scatter

        # the triangle passes: the certificate, and the corners beside it in a FIFO (results come in order)
        corner_bits = len(self.corners[0])
        m.submodules.corner_fifo = corner_fifo = LutFIFO(width=3 * corner_bits, depth=certificate.credits,
                                                         checked=False)
        # the landed triangle registered here, beside the certificate: its valid flag is the sequencer's logic
        # on the controller's phase flag, and would otherwise be routed across the device into the
        # certificate's credit counter (the sequencer issues one triangle per two clocks, so the
        # certificate is ready for each)
        beat = certificate.i.payload
        landed = Signal(name="certify_landed")
        landed_corners = Signal(3 * corner_bits, name="certify_corners", reset_less=True)
        m.d.sync += [landed.eq(self.triangle_landed), landed_corners.eq(Cat(*self.corners)),
                     beat.a.eq(self.position[0]), beat.b.eq(self.position[1]), beat.c.eq(self.position[2]),
                     beat.move_a.eq(self.proposal[0]), beat.move_b.eq(self.proposal[1]),
                     beat.move_c.eq(self.proposal[2]), beat.area.eq(self.area)]
        m.d.comb += [
            certificate.i.valid.eq(landed), certificate.winding_negative.eq(0),
            corner_fifo.w_data.eq(landed_corners), corner_fifo.w_en.eq(landed),
            certificate.o.ready.eq(1), corner_fifo.r_en.eq(certificate.o.valid),
        ]
        # each corner's update registered before its scatter (the FIFO's LUT RAM read and the choice of
        # level would otherwise run into the scatter's block RAM address)
        result = certificate.o.payload
        for k, scatter in enumerate(scatters):
            update = scatter.update
            m.d.sync += [update.valid.eq(certificate.o.valid),
                         update.payload.node.eq(corner_fifo.r_data[k * corner_bits:(k + 1) * corner_bits]),
                         update.payload.level.eq(Mux(self.in_stuck, result.stuck[k], result.level))]
        results = Signal(range(cap.triangles + 1), name="certified")
        with m.If(certificate.o.valid):
            m.d.sync += results.eq(results + 1)

        # the node passes: the scatters' lookups a clock before the memories' address registers (the
        # scatters register their block RAMs' words once more), their levels delayed to the memories' latency
        levels = []
        for k, scatter in enumerate(scatters):
            m.d.comb += scatter.lookup.eq(self.node_index)
            level = scatter.level
            for d in range(self.read_latency + 1 - LevelScatter.LOOKUP_LATENCY):
                later = Signal(certificate_level_shape(), name=f"guard_level{k}_{d}")
                m.d.sync += later.eq(level)
                level = later
            levels.append(level)

        # the proposal pass clears every node's slots for the stuck pass (whatever an aborted run left), the
        # hold pass each node's behind its lookup for the certificate pass
        # (the pass flags for the clears registered here, beside the scatters, because the controller's flag
        # would otherwise be routed across the device into the scatters' write ports; no node lands in a
        # node pass's first clock or after it ends, so the clock's delay changes no clear)
        clearing_pass = Signal(name="clearing_pass")
        m.d.sync += clearing_pass.eq(self.in_integrate | self.in_hold)
        hold = self.in_hold & self.node_landed
        clearing = clearing_pass & self.node_landed
        held = Signal(range(cap.vertices + 1), name="held_nodes")  # the node landed (nodes land in order)
        # the held proposal written two clocks later: the stuck test into a register beside the scatters, then
        # the zeroing into the proposal memories' write registers (a route across the device from each)
        stuck = Signal(name="hold_stuck")
        hold_node = Signal(range(cap.vertices + 1), name="hold_node")
        hold_proposal = Signal(vector_layout(self.fs.velocity), name="hold_proposal")
        hold_write = Signal(name="hold_write")
        m.d.sync += [stuck.eq(Cat(*(level != 0 for level in levels)).any()), hold_node.eq(held),
                     hold_proposal.eq(self.proposal[0]), hold_write.eq(hold),
                     self.proposal_write.addr.eq(hold_node), self.proposal_write.en.eq(hold_write),
                     self.proposal_write.data.eq(Mux(stuck, 0, hold_proposal))]
        for scatter in scatters:
            m.d.comb += [scatter.clear.valid.eq(clearing), scatter.clear.payload.eq(held)]
        with m.If(clearing):
            m.d.sync += held.eq(held + 1)

        # the landed node registered here, beside the commit: the memories' words are routed across the
        # device, and the commit's first stage starts a carry chain (−V) on them; the proposal or the
        # velocity is chosen from these registers
        c_in = commit.i.payload
        landed_node = Signal(name="commit_landed")
        rollback = Signal(name="commit_rollback")
        landed_position = Signal(vector_layout(fs.position), name="commit_position", reset_less=True)
        landed_proposal = Signal(vector_layout(fs.velocity), name="commit_proposal", reset_less=True)
        landed_velocity = Signal(vector_layout(fs.velocity), name="commit_velocity", reset_less=True)
        landed_levels = [Signal(certificate_level_shape(), name=f"commit_level{k}", reset_less=True)
                         for k in range(len(levels))]
        m.d.sync += [landed_node.eq((self.in_commit | self.in_rollback) & self.node_landed),
                     rollback.eq(self.in_rollback), landed_position.eq(self.position[0]),
                     landed_proposal.eq(self.proposal[0]), landed_velocity.eq(self.velocity),
                     *(q.eq(level) for q, level in zip(landed_levels, levels))]
        m.d.comb += [commit.i.valid.eq(landed_node), c_in.position.eq(landed_position),
                     c_in.velocity.eq(Mux(rollback, landed_velocity, landed_proposal)),
                     *(c_in.levels[k].eq(level) for k, level in enumerate(landed_levels)),
                     c_in.stuck.eq(0), c_in.rollback.eq(rollback)]
        committed = Signal(range(cap.vertices + 1), name="committed_nodes")
        m.d.comb += [self.node_write.addr.eq(committed), self.node_write.en.eq(commit.o.valid),
                     self.node_write.data.position.eq(commit.o.payload.position),
                     self.node_write.data.velocity.eq(commit.o.payload.velocity)]
        with m.If(commit.o.valid):
            m.d.sync += committed.eq(committed + 1)
        if cap.coarse_degree:
            with m.If(self.in_step):
                m.d.sync += self.clipped.eq(0)
            with m.Elif(commit.o.valid & (commit.o.payload.level >= CLIP_HANDOVER_LEVEL)):
                m.d.sync += self.clipped.eq(1)

        # Each counter's end (``count == size``) a flag beside it, set in the clock it steps from size − 1, so
        # that a pass's end reads flags: the sizes come from the register bank across the die, and a compare
        # with them in front of ``done`` puts that route before five levels of logic. The sizes are run
        # constants, copied beside the counters (two clocks late; no guard pass runs in a run's first
        # passes), and at least 1 in any run START accepts, so every flag is clear when its counter restarts.
        last = {}
        for name, size in (("vertex", self.vertices), ("triangle", self.triangles)):
            copy = kept_register(m, size, name=f"guard_{name}s", platform=platform)
            last[name] = Signal.like(size, name=f"guard_last_{name}", reset_less=True)
            m.d.sync += last[name].eq(copy - 1)
        ends = {}
        for counter, steps, name in ((results, certificate.o.valid, "triangle"), (held, clearing, "vertex"),
                                     (committed, commit.o.valid, "vertex")):
            ends[counter.name] = end = Signal(name=f"{counter.name}_end")
            with m.If(steps):
                m.d.sync += end.eq(counter == last[name])

        # a pass's end, registered; its counters restart the clock after
        scatters_idle = Cat(*(s.idle & ~s.update.valid for s in scatters)).all()
        m.d.sync += self.idle.eq(~landed & (corner_fifo.level == 0) & scatters_idle & ~landed_node & commit.idle)
        triangles_done = (self.in_stuck | self.in_certify) & ends["certified"] & scatters_idle
        nodes_done = (self.in_hold & ends["held_nodes"] & ~hold_write & ~self.proposal_write.en) \
            | ((self.in_commit | self.in_rollback) & ends["committed_nodes"])
        m.d.sync += self.done.eq((triangles_done | nodes_done) & ~self.done)
        with m.If(self.done | self.in_step):
            m.d.sync += [results.eq(0), held.eq(0), committed.eq(0), *(end.eq(0) for end in ends.values())]
        return m
