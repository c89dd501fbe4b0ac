"""The node-update datapath: force accumulation and the Euler step, one neighbour entry per clock.

The RTL twin of :func:`golden_model.fixed.pipeline.node_update`; every width comes
from a :class:`~golden_model.fixed.FormatSet`. ``docs/hardware.md`` maps each
pipeline stage onto the steps of ``docs/fixed-point.md``.
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import Format, FormatSet
from golden_model.fixed.pipeline import accumulator_guard_bits

from .fifo import SlicedFIFO
from .fixedpoint import clamp, shape_of, shift_round, sum_round
from .layouts import entry_layout, node_layout, result_layout, vector_layout
from .pipeline import Pipeline, aligned_add, reduce_levels
from .rsqrt import RsqrtUnit

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
    The datapath never stalls. Every stage register loads on every clock, so no enable
    fans out across the ~28,750 flip-flops: a front section (narrowing, squares,
    ``|Δ|²``) feeds the :class:`~hdl.rsqrt.RsqrtUnit` (its ``o.ready`` tied high), the
    entry's side data rides along in a delay line of the rsqrt latency, a back section
    forms ``s``, the forces and ``|L − d|`` and accumulates per node, and a node tail runs
    ``a = F/m`` (``inv_mass_barrier`` for ``1/m`` if any of the node's triangles is inside
    the fold barrier, ``h > 0``), Euler and damping. Node headers wait in a FIFO from the input to the
    accumulators. Results enter a LUT-RAM FIFO (column slices with their own pointers)
    in front of the output register; ``result_depth`` counts both. Back-pressure is a
    credit count: ``i.ready`` is high while fewer than ``result_depth`` nodes are owed (accepted last entries whose results have not
    left ``o``), so the result FIFO can never overflow; ``result_depth`` covers the
    latency, so credits never run out while ``o`` is ready, even for degree-1 nodes.

    Every multiplier sits alone between registers (its 18×18 partial products, operands and
    products registered, then the products landed in fabric registers); partial
    products are added pairwise, one adder per stage; every rounding and every
    saturation has a stage of its own.
    """

    #: Width of one column slice of the header and result FIFOs (each slice has its own pointers).
    #: 12 bits: a slice of the 128-deep result FIFO is 24 LUT RAM cells, which its read pointer
    #: reaches within a clock wherever they are placed (20-bit slices, 40 cells: 137–158 MHz
    #: depending on placement).
    FIFO_SLICE_BITS = 12

    def __init__(self, fs: FormatSet | str):
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"NodeUpdate needs a FormatSet or a preset name, not {fs!r}")
        if fs.delta.frac_bits > fs.position.frac_bits:
            raise ValueError(f"delta {fs.delta} cannot have more fraction bits than position {fs.position}")
        if fs.velocity.frac_bits != fs.position.frac_bits:
            raise ValueError(f"the momentum step adds V to P: velocity {fs.velocity} needs position's "
                             f"{fs.position.frac_bits} fraction bits")
        self.fs = fs
        self.rsqrt_latency = RsqrtUnit.latency_of(fs.rsqrt_config())
        s = shape_of
        mul = Pipeline.mul_stages(land_operands=True)
        self.front_stages = 8 + mul + reduce_levels((s(fs.delta), s(fs.delta)))
        # the fold barrier runs beside the rsqrt unit, in its delay line
        self.barrier_stages = 6 + 2 * mul + (reduce_levels((s(fs.barrier_gain), unsigned(fs.area.width - 1)))
                                             + reduce_levels((s(fs.barrier_coeff), s(fs.delta))))
        if self.barrier_stages > self.rsqrt_latency:
            raise ValueError(f"the fold barrier needs {self.barrier_stages} stages, more than the rsqrt unit's "
                             f"{self.rsqrt_latency} it runs beside")
        self.back_stages = 8 + 3 * mul + (reduce_levels((s(fs.rest_length), s(fs.rsqrt)), (s(fs.length_sq), s(fs.rsqrt)))
                                 + reduce_levels((s(fs.spring), s(fs.spring)))
                                 + reduce_levels((s(fs.spring), s(fs.delta))))
        self.tail_stages = 10 + 3 * mul + (reduce_levels((s(fs.force_acc), s(fs.inv_mass)),
                                                         (s(fs.force_acc), s(fs.velocity)))
                                 + reduce_levels((s(fs.dt), s(fs.velocity)), (s(fs.half_dt_sq), s(fs.accel)),
                                                  (s(fs.dt), s(fs.accel)))
                                 + reduce_levels((s(fs.velocity), s(fs.damping))))
        self.pipeline_stages = self.front_stages + self.rsqrt_latency + self.back_stages + self.tail_stages
        # The result FIFO's write and the output register.
        self.latency = self.pipeline_stages + 2
        # Credits: the result FIFO (a power of two, more entries than the latency, so the
        # credits never run out while o is ready) plus the output register.
        self.result_depth = (1 << (self.latency + 1).bit_length()) + 1
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
        rnd = fs.rounding
        m = Module()
        m.submodules.rsqrt = rsqrt = RsqrtUnit(fs)
        assert rsqrt.latency == self.rsqrt_latency

        # Constants, registered so that they reach the multipliers from registers.
        dt, half_dt_sq, half_spring, damping = (Signal.like(p, name=f"{n}_r", reset_less=True) for n, p in (
            ("dt", self.dt), ("half_dt_sq", self.half_dt_sq), ("half_spring", self.half_spring),
            ("damping", self.damping)))
        momentum = Signal(name="momentum_r", reset_less=True)
        one = 1 << fs.damping.frac_bits  # the momentum step is not damped: × 1 exactly
        m.d.sync += [dt.eq(self.dt), half_dt_sq.eq(self.half_dt_sq), half_spring.eq(self.half_spring),
                     damping.eq(Mux(self.momentum, one, self.damping)), momentum.eq(self.momentum)]

        def rounded(value, from_frac, fmt):
            """``value`` (``from_frac`` fraction bits) rounded to ``fmt``'s lsb; not yet saturated."""
            return shift_round(value, from_frac - fmt.frac_bits, rnd)

        def saturated(value, fmt):
            return clamp(value, fmt)[0]

        # ------------------------------------------------------------ credits
        # owed: accepted last entries whose results have not left o. i.ready = owed < depth
        # leaves a flip-flop, set from the current count and this clock's handshakes alone
        # (no adder on that path): depth - 1 is a power of two.
        owed = Signal(range(self.result_depth + 1))
        accepting = Signal(init=1)
        take = self.i.valid & accepting
        grow = take & self.i.payload.last & ~(self.o.valid & self.o.ready)
        shrink = self.o.valid & self.o.ready & ~(take & self.i.payload.last)
        top = (self.result_depth - 1).bit_length() - 1
        assert self.result_depth - 1 == 1 << top
        at_depth_minus_1 = owed[top] & ~owed[:top].any()
        at_depth = owed[top] & owed[0]
        m.d.sync += [
            owed.eq(owed + grow - shrink),
            accepting.eq(~owed[top] | (at_depth_minus_1 & ~grow) | (at_depth & shrink)),
        ]
        m.d.comb += self.i.ready.eq(accepting)
        # idle: no node owed and none half accepted (between its first and last entry)
        open_node = Signal()
        with m.If(take):
            m.d.sync += open_node.eq(~self.i.payload.last)
        m.d.comb += self.idle.eq((owed == 0) & ~open_node)

        # ------------------------------------------------------------ stage helper
        live = {}

        def carry_live(p, name, drop=(), **new):
            """Register, in ``p``'s current stage, ``new`` and every value in ``live`` not dropped."""
            out = {}
            carried = [(k, v) for k, v in live.items() if k not in drop and k not in new]
            for key, value in carried + list(new.items()):
                out[key] = p.keep(value, f"{name}_{key}")
            live.clear()
            live.update(out)

        def step(p, name, drop=(), **new):
            """One stage of ``p`` (see :func:`carry_live`)."""
            p.stage(name)
            carry_live(p, name, drop, **new)

        def multiply(p, name, drop=(), **products):
            """Whole products (:meth:`~hdl.pipeline.Pipeline.multiply`), carrying ``live`` along."""
            drops = [drop]
            live.update(p.multiply(products, name,
                                   lambda stage_name: carry_live(p, stage_name, drops.pop() if drops else ())))

        # ------------------------------------------------------------ front
        m.submodules.headers = headers = SlicedFIFO(
            width=node_layout(fs).size, slice_bits=self.FIFO_SLICE_BITS, write_register=True,
            depth=1 << (self.front_stages + self.rsqrt_latency + self.back_stages + 1).bit_length())
        beat = self.i.payload
        current = Signal(vector_layout(fs.position), name="current_position", reset_less=True)
        # The header is written two clocks late, from registers here and again in each FIFO slice
        # (write_register): the write enable would otherwise fan out to every LUT RAM row of
        # the FIFO, and the read comes dozens of clocks later anyway.
        header_write = Signal(name="header_write")
        header_data = Signal(node_layout(fs), name="header_data", reset_less=True)
        m.d.sync += [header_write.eq(take & beat.first), header_data.eq(beat.node)]
        m.d.comb += [headers.w_stream.valid.eq(header_write), headers.w_stream.payload.eq(header_data.as_value())]

        front = Pipeline(m, take, land_operands=True, platform=platform)
        position = vector_layout(fs.position)
        # F0: the beat as it arrived, so that i.valid drives no wide enable (the held P_i's was
        # the critical path once the barrier widened the entry)
        step(front, "f0", beat=beat.as_value())
        beat = data.View(entry_layout(fs), live["beat"])
        with m.If(front.valid & beat.first):
            m.d.sync += current.eq(beat.node.position)
        # F1: P_i comes from the header on a node's first entry
        step(front, "f1", drop=("beat",), p_i=Mux(beat.first, beat.node.position.as_value(), current.as_value()),
             p_j=beat.neighbour.position.as_value(), p_b=beat.barrier.second.as_value(), rest=beat.neighbour.rest,
             threshold=beat.barrier.threshold, gain=beat.barrier.gain, first=beat.first, last=beat.last)
        p_i, p_j, p_b = (data.View(position, live[k]) for k in ("p_i", "p_j", "p_b"))
        # F2: P_j − P_i and the barrier's P_second − P_i, exact;  F3: rounded to delta;  F4: saturated
        step(front, "f2", drop=("p_i", "p_j", "p_b"), dx=p_j.x - p_i.x, dy=p_j.y - p_i.y,
             bx=p_b.x - p_i.x, by=p_b.y - p_i.y)
        step(front, "f3", **{k: rounded(live[k], fs.position.frac_bits, fs.delta) for k in ("dx", "dy", "bx", "by")})
        step(front, "f4", **{k: saturated(live[k], fs.delta) for k in ("dx", "dy", "bx", "by")})
        # F5…: Δx², Δy² and the barrier's Δa.x·Δb.y, Δa.y·Δb.x;  then S = rq(Δx² + Δy² → length_sq)
        # and X = rq(Δa × Δb → area) as sum, rounding, saturation
        multiply(front, "f5", sq_x=(live["dx"], live["dx"]), sq_y=(live["dy"], live["dy"]),
                 cross_a=(live["dx"], live["by"]), cross_b=(live["dy"], live["bx"]))
        square_frac = 2 * fs.delta.frac_bits
        step(front, "f6", drop=("sq_x", "sq_y", "cross_a", "cross_b"), s=live["sq_x"] + live["sq_y"],
             cross=live["cross_a"] - live["cross_b"])
        step(front, "f7", s=rounded(live["s"], square_frac, fs.length_sq), cross=rounded(live["cross"], square_frac, fs.area))
        step(front, "f8", s=saturated(live["s"], fs.length_sq), cross=saturated(live["cross"], fs.area))
        assert front.stages == self.front_stages, (front.stages, self.front_stages)
        m.d.comb += [rsqrt.i.valid.eq(front.valid), rsqrt.i.payload.eq(live["s"]), rsqrt.o.ready.eq(1)]

        # The entry's side data waits for r in a delay line as long as the rsqrt unit; the fold
        # barrier's force is computed there.
        side = Pipeline(m, front.valid, land_operands=True, platform=platform)
        # S1: the shortfall T − X and the opposite edge D = Δa − Δb, exact
        step(side, "s1", drop=("cross", "threshold", "bx", "by"), short=live["threshold"] - live["cross"],
             ex=live["dx"] - live["bx"], ey=live["dy"] - live["by"])
        # S2: h = sat(max(T − X, 0) → area), non-negative;  D saturated to delta;  inside: h > 0
        short = live["short"]
        step(side, "s2", short=Mux(short < 0, 0, saturated(short, fs.area))[:fs.area.width - 1],
             ex=saturated(live["ex"], fs.delta), ey=saturated(live["ey"], fs.delta),
             inside=(short >= 0) & short.any())
        # c = rq(G·h → barrier_coeff)
        multiply(side, "s3", drop=("short", "gain"), c=(live["gain"], live["short"]))
        step(side, "s4", c=rounded(live["c"], fs.barrier_gain.frac_bits + fs.area.frac_bits, fs.barrier_coeff))
        step(side, "s5", c=saturated(live["c"], fs.barrier_coeff))
        # f_b = rq(c·(D.y, −D.x) → force): the minus folds into the rounding's subtraction
        multiply(side, "s6", drop=("c", "ex", "ey"), fb_x=(live["c"], live["ey"]), fb_y=(live["c"], live["ex"]))
        fb_frac = fs.barrier_coeff.frac_bits + fs.delta.frac_bits
        step(side, "s7", fb_x=rounded(live["fb_x"], fb_frac, fs.force),
             fb_y=sum_round((), fb_frac - fs.force.frac_bits, rnd, sub=[live["fb_y"]]))
        step(side, "s8", fb_x=saturated(live["fb_x"], fs.force), fb_y=saturated(live["fb_y"], fs.force))
        assert side.stages == self.barrier_stages, (side.stages, self.barrier_stages)
        for n in range(self.barrier_stages, self.rsqrt_latency):
            step(side, f"side{n}")

        # ------------------------------------------------------------ back
        back = Pipeline(m, rsqrt.o.valid, land_operands=True, platform=platform)
        r = rsqrt.o.payload.rsqrt  # leaves the rsqrt unit's output register
        # d·r and S·r
        multiply(back, "b1", drop=("s",), d_r=(live["rest"], r), s_r=(live["s"], r))
        # u = rq(1 − d·r → spring), L = rq(S·r → rest_length): rounding, then saturation
        dr_frac = fs.rest_length.frac_bits + fs.rsqrt.frac_bits
        if fs.spring.frac_bits < dr_frac:  # the rounding constant folds into 1 − d·r: one subtraction
            u = sum_round((), dr_frac - fs.spring.frac_bits, rnd, sub=[live["d_r"]], const=1 << dr_frac)
        else:
            u = rounded((1 << dr_frac) - live["d_r"], dr_frac, fs.spring)
        step(back, "b2", drop=("d_r", "s_r"), u=u,
             length=rounded(live["s_r"], fs.length_sq.frac_bits + fs.rsqrt.frac_bits, fs.rest_length))
        step(back, "b3", u=saturated(live["u"], fs.spring), length=saturated(live["length"], fs.rest_length))
        # e = |L − d| alongside ½C·u
        length, rest = live["length"], live["rest"]
        live["e"] = Mux(length > rest, length - rest, rest - length)[:fs.rest_length.width]
        multiply(back, "b4", drop=("length", "rest", "u"), c_u=(half_spring, live["u"]))
        # s = rq(½C·u → spring)
        step(back, "b5", c_u=rounded(live["c_u"], 2 * fs.spring.frac_bits, fs.spring))
        step(back, "b6", drop=("c_u",), s=saturated(live["c_u"], fs.spring))
        # s·Δ, then f = rq(s·Δ → force)
        multiply(back, "b7", drop=("s", "dx", "dy"), f_x=(live["s"], live["dx"]), f_y=(live["s"], live["dy"]))
        f_frac = fs.spring.frac_bits + fs.delta.frac_bits
        step(back, "b8", f_x=rounded(live["f_x"], f_frac, fs.force), f_y=rounded(live["f_y"], f_frac, fs.force))
        step(back, "b9", f_x=saturated(live["f_x"], fs.force), f_y=saturated(live["f_y"], fs.force))
        # B10: the entry's force, spring plus barrier, exact
        step(back, "b10", drop=("fb_x", "fb_y"), f_x=live["f_x"] + live["fb_x"], f_y=live["f_y"] + live["fb_y"])

        # B11: per-node accumulators with guard bits (exact; saturated once in the tail). The
        # node's header is read one clock after its last entry, when T1 registers it straight
        # from the FIFO: the read enable is then a flip-flop (b10_node_done) that drives only
        # the slices' read pointers (reading with the last entry itself, through an AND gate
        # into the pointers and a header register, was the critical path: 137 MHz).
        guard = accumulator_guard_bits(fs.max_degree)
        acc_f = [Signal(signed(fs.force.width + 1 + guard), name=f"acc_f_{k}", reset_less=True) for k in "xy"]
        acc_e = Signal(unsigned(fs.rest_length.width + guard), name="acc_e", reset_less=True)
        acc_inside = Signal(name="acc_inside", reset_less=True)  # a triangle of the node is inside the barrier
        first, last = live["first"], live["last"]
        with m.If(back.valid):
            for acc, f in zip(acc_f, (live["f_x"], live["f_y"])):
                m.d.sync += acc.eq(Mux(first, f, acc + f))
            m.d.sync += [acc_e.eq(Mux(first, live["e"], acc_e + live["e"])),
                         acc_inside.eq(Mux(first, live["inside"], acc_inside | live["inside"]))]
        node_done_r = Signal(name="b10_node_done")
        m.d.sync += node_done_r.eq(back.valid & last)
        m.d.comb += headers.r_stream.ready.eq(node_done_r)
        header = data.View(node_layout(fs), headers.r_stream.payload)
        back.stages += 1
        live.clear()
        assert back.stages == self.back_stages, (back.stages, self.back_stages)

        # ------------------------------------------------------------ node tail
        tail = Pipeline(m, node_done_r, land_operands=True, platform=platform)
        # T1: the node's header; F and Σe rounded;  T2: saturated
        step(tail, "t1", f_x=rounded(acc_f[0], fs.force.frac_bits, fs.force_acc),
             f_y=rounded(acc_f[1], fs.force.frac_bits, fs.force_acc),
             e=rounded(acc_e, fs.rest_length.frac_bits, fs.error_acc),
             p_x=header.position.x, p_y=header.position.y, v_x=header.velocity.x, v_y=header.velocity.y,
             inv_mass=header.inv_mass, inv_mass_barrier=header.inv_mass_barrier, inside=acc_inside)
        # T2: the weight, the barrier's where a triangle of the node is inside it
        step(tail, "t2", drop=("inv_mass_barrier", "inside"),
             f_x=saturated(live["f_x"], fs.force_acc), f_y=saturated(live["f_y"], fs.force_acc),
             e=saturated(live["e"], fs.error_acc),
             inv_mass=Mux(live["inside"], live["inv_mass_barrier"], live["inv_mass"]))
        # F·(1/m), then a = rq(F·(1/m) → accel)
        # and the power F·V of the input state (the momentum restart's S, summed by the controller)
        multiply(tail, "t3", drop=("f_x", "f_y", "inv_mass"),
                 a_x=(live["f_x"], live["inv_mass"]), a_y=(live["f_y"], live["inv_mass"]),
                 pw_x=(live["f_x"], live["v_x"]), pw_y=(live["f_y"], live["v_y"]))
        a_frac = fs.force_acc.frac_bits + fs.inv_mass.frac_bits
        step(tail, "t4", drop=("pw_x", "pw_y"), a_x=rounded(live["a_x"], a_frac, fs.accel),
             a_y=rounded(live["a_y"], a_frac, fs.accel), pw=live["pw_x"] + live["pw_y"])
        step(tail, "t5", a_x=saturated(live["a_x"], fs.accel), a_y=saturated(live["a_y"], fs.accel),
             pw=rounded(live["pw"], fs.force_acc.frac_bits + fs.velocity.frac_bits, fs.power))
        live["pw"] = saturated(live["pw"], fs.power)
        # Δt·V, ½Δt²·a, Δt·a
        multiply(tail, "t6",
                 dtv_x=(dt, live["v_x"]), dtv_y=(dt, live["v_y"]),
                 ha_x=(half_dt_sq, live["a_x"]), ha_y=(half_dt_sq, live["a_y"]),
                 dta_x=(dt, live["a_x"]), dta_y=(dt, live["a_y"]))
        # P' = sat(P + rq(Δt·V + ½Δt²·a → wide_p)),  V' = sat(V + rq(Δt·a → wide_v))
        fv = fs.dt.frac_bits + fs.velocity.frac_bits
        fa = fs.half_dt_sq.frac_bits + fs.accel.frac_bits
        step_frac = max(fv, fa)
        wide_p = Format(fs.position.signed, fs.position.int_bits + 1, fs.position.frac_bits)
        wide_v = Format(fs.velocity.signed, fs.velocity.int_bits + 1, fs.velocity.frac_bits)
        kick_frac = fs.dt.frac_bits + fs.accel.frac_bits
        # momentum: step = β·V + a, the a term aligned as ½Δt²·a would be (fraction bits fa).
        # Both dynamics' sums are formed and rounded side by side; the mode picks one only at
        # the saturation (T9), which muxes anyway: a mux in front of the 50-bit adder was the
        # critical path (139 MHz).
        sums = {}
        for k in "xy":
            for mode, second in (("paper", live[f"ha_{k}"]), ("mom", live[f"a_{k}"] << fs.half_dt_sq.frac_bits)):
                value, shift = aligned_add(live[f"dtv_{k}"], step_frac - fv, second, step_frac - fa)
                sums[f"step_{mode}_{k}"] = Value.cast(value) << shift if shift else value
            sums[f"kick_{k}"] = rounded(live[f"dta_{k}"], kick_frac, wide_v)
        step(tail, "t7", drop=tuple(f"{n}_{k}" for n in ("dtv", "ha", "dta", "a") for k in "xy"), **sums)
        step(tail, "t8", **{f"step_{mode}_{k}": rounded(live[f"step_{mode}_{k}"], step_frac, wide_p)
                            for mode in ("paper", "mom") for k in "xy"},
             **{f"kick_{k}": saturated(live[f"kick_{k}"], wide_v) for k in "xy"})
        # paper: the position step saturated to wide_p; momentum: V' = step saturated to velocity
        step(tail, "t9", drop=tuple(f"{n}_{k}" for n in ("kick", "step_paper", "step_mom") for k in "xy"),
             **{f"step_{k}": Mux(momentum, saturated(live[f"step_mom_{k}"], fs.velocity),
                                 saturated(live[f"step_paper_{k}"], wide_p)) for k in "xy"},
             **{f"v_{k}": live[f"v_{k}"] + live[f"kick_{k}"] for k in "xy"})
        step(tail, "t10", drop=("step_x", "step_y"),
             **{f"p_{k}": live[f"p_{k}"] + live[f"step_{k}"] for k in "xy"},
             **{f"v_{k}": Mux(momentum, live[f"step_{k}"], saturated(live[f"v_{k}"], fs.velocity)
                              )[:fs.velocity.width].as_signed() for k in "xy"})
        # V'·(1 − γ) alongside the position's saturation, then V'' = rq(V'·(1 − γ) → velocity)
        live.update({f"p_{k}": saturated(live[f"p_{k}"], fs.position) for k in "xy"})
        multiply(tail, "t11", drop=("v_x", "v_y"), vk_x=(live["v_x"], damping), vk_y=(live["v_y"], damping))
        vk_frac = fs.velocity.frac_bits + fs.damping.frac_bits
        step(tail, "t12", **{f"vk_{k}": rounded(live[f"vk_{k}"], vk_frac, fs.velocity) for k in "xy"})
        step(tail, "t13", **{f"vk_{k}": saturated(live[f"vk_{k}"], fs.velocity) for k in "xy"})
        assert tail.stages == self.tail_stages, (tail.stages, self.tail_stages)

        # ------------------------------------------------------------ results
        layout = result_layout(fs)
        result = Signal(layout, name="result")
        m.d.comb += [
            result.position.x.eq(live["p_x"]), result.position.y.eq(live["p_y"]),
            result.velocity.x.eq(live["vk_x"]), result.velocity.y.eq(live["vk_y"]),
            result.error_sum.eq(live["e"]), result.power.eq(live["pw"]),
        ]
        # The result FIFO: LUT RAM column slices, each with its own pointers and its own two
        # output registers, so a read enable reaches only its own 12-bit slice and o.ready only
        # a few flags per slice (one shared read enable over ten slices was the critical path,
        # 123–138 MHz). Never written full: the credits count its depth and the output register.
        m.submodules.results = results = SlicedFIFO(width=result_layout(fs).size, depth=self.result_depth - 1,
                                                    slice_bits=self.FIFO_SLICE_BITS, registered=True)
        m.d.comb += [results.w_stream.valid.eq(tail.valid), results.w_stream.payload.eq(result.as_value()),
                     self.o.valid.eq(results.r_stream.valid), self.o.payload.eq(results.r_stream.payload),
                     results.r_stream.ready.eq(self.o.ready)]
        return m
