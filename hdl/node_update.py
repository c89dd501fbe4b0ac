"""The node-update datapath: force accumulation and the Euler step, one neighbour entry per clock.

The RTL twin of :func:`golden_model.fixed.pipeline.node_update`; every width comes
from a :class:`~golden_model.fixed.FormatSet`. ``docs/hardware.md`` maps each
pipeline stage onto the steps of ``docs/fixed-point.md``.
"""

from __future__ import annotations

import math

from amaranth.hdl import Module, Mux, Signal, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.fifo import SyncFIFO
from amaranth.lib.wiring import In, Out

from golden_model.fixed import Format, FormatSet
from golden_model.fixed.pipeline import accumulator_guard_bits

from .fixedpoint import clamp, dsp_partial_products, dsp_sum, requantize, shape_of
from .rsqrt import RsqrtUnit

__all__ = ["NodeUpdate", "vector_layout", "entry_layout", "node_layout", "result_layout"]


def vector_layout(fmt: Format) -> data.StructLayout:
    """A 2D vector of raw ``fmt`` values: fields ``x``, ``y``."""
    return data.StructLayout({"x": shape_of(fmt), "y": shape_of(fmt)})


def node_layout(fs: FormatSet) -> data.StructLayout:
    """A node's state: ``position`` [position], ``velocity`` [velocity], ``inv_mass`` [inv_mass]."""
    return data.StructLayout({
        "position": vector_layout(fs.position),
        "velocity": vector_layout(fs.velocity),
        "inv_mass": shape_of(fs.inv_mass),
    })


def entry_layout(fs: FormatSet) -> data.StructLayout:
    """One input beat: a neighbour entry, with its node's header on the node's first entry.

    ``first``/``last`` mark a node's first and last neighbour entries; ``node``
    is read only when ``first`` is set; ``neighbour`` holds the neighbour's
    ``position`` and the edge's ``rest`` length [rest_length].
    """
    return data.StructLayout({
        "first": unsigned(1),
        "last": unsigned(1),
        "node": node_layout(fs),
        "neighbour": data.StructLayout({"position": vector_layout(fs.position), "rest": shape_of(fs.rest_length)}),
    })


def result_layout(fs: FormatSet) -> data.StructLayout:
    """One output beat: the node's new ``position``, ``velocity`` and ``error_sum`` Σ|L − d| [error_acc]."""
    return data.StructLayout({
        "position": vector_layout(fs.position),
        "velocity": vector_layout(fs.velocity),
        "error_sum": shape_of(fs.error_acc),
    })


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
        1/m) rides on its first entry (``first``), ``last`` closes the node. A node
        with n ≥ 1 neighbours is n beats.
    o : ``Out(stream.Signature(result_layout(fs)))``
        One beat per node, in input order: new position, new velocity (damped), and
        the node's Σ|L − d| of the *input* positions.
    dt, half_dt_sq, half_spring, damping : ``In(...)``
        ``Δt`` [dt], ``½Δt²`` [half_dt_sq], ``½C`` [spring], ``1 − γ`` [damping]. Hold them
        stable while a pass is in flight (they are registered once per clock).

    Contract
    --------
    Throughput: one neighbour entry per clock (II = 1) whenever ``o`` is ready, with no
    gap between nodes, for nodes of any degree from 1 to ``fs.max_degree``.
    Latency: ``latency`` clocks from the transfer of a node's last entry to its result
    on ``o`` when never stalled (so N entries take N + ``latency`` clocks).
    Back-pressure: ``o.valid`` and ``o.payload`` never depend on ``o.ready``; a result
    stays offered until taken; any stall pattern on either side is allowed.
    Every multiplier sits alone in a stage, between registers.

    Structure: a front pipeline (narrowing, squares, ``|Δ|²``) feeds the
    :class:`~hdl.rsqrt.RsqrtUnit` stream; the entry's side data waits in a FIFO
    alongside the rsqrt pipeline; a back pipeline forms ``s``, the forces and ``|L − d|``,
    accumulates per node, and runs the node tail (``a = F/m``, Euler, damping). Node
    headers wait in a FIFO from the input to the node tail. Each section moves as a
    whole when its output register is empty or being read.
    """

    FRONT_STAGES = 5
    BACK_STAGES = 12
    TAIL_STAGES = 10

    def __init__(self, fs: FormatSet | str):
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"NodeUpdate needs a FormatSet or a preset name, not {fs!r}")
        if fs.delta.frac_bits > fs.position.frac_bits:
            raise ValueError(f"delta {fs.delta} cannot have more fraction bits than position {fs.position}")
        self.fs = fs
        self.rsqrt_latency = RsqrtUnit.latency_of(fs.rsqrt_config())
        self.latency = self.FRONT_STAGES + self.rsqrt_latency + self.BACK_STAGES + self.TAIL_STAGES
        super().__init__({
            "i": In(stream.Signature(entry_layout(fs))),
            "o": Out(stream.Signature(result_layout(fs))),
            "dt": In(shape_of(fs.dt)),
            "half_dt_sq": In(shape_of(fs.half_dt_sq)),
            "half_spring": In(shape_of(fs.spring)),
            "damping": In(shape_of(fs.damping)),
        })

    def elaborate(self, platform):
        fs = self.fs
        rnd = fs.rounding
        m = Module()
        m.submodules.rsqrt = rsqrt = RsqrtUnit(fs)
        assert rsqrt.latency == self.rsqrt_latency

        def pipeline(advance, first_valid):
            """``stage()`` and ``reg()`` helpers for a section moving on ``advance``."""
            state = {"valid": first_valid, "stages": 0}

            def stage():
                valid = Signal(name=f"s{state['stages']}_valid")
                with m.If(advance):
                    m.d.sync += valid.eq(state["valid"])
                state["valid"] = valid
                state["stages"] += 1
                return valid

            def reg(value, shape, name):
                sig = Signal(shape, name=name)
                with m.If(advance):
                    m.d.sync += sig.eq(value)
                return sig

            def mul(a, b, name):
                """``a * b`` split into 18x18 partial products, each registered (one DSP each)."""
                return [(reg(p, p.shape(), f"{name}_pp{i}"), shift)
                        for i, (p, shift) in enumerate(dsp_partial_products(a, b))]

            def product(parts, shape, name):
                """The next stage: the partial products' exact sum, registered."""
                return reg(dsp_sum(parts), shape, name)

            return stage, reg, state, mul, product

        # Constants, registered so that they reach the multipliers from registers.
        dt, half_dt_sq, half_spring, damping = (Signal.like(p, name=f"{n}_r") for n, p in (
            ("dt", self.dt), ("half_dt_sq", self.half_dt_sq), ("half_spring", self.half_spring),
            ("damping", self.damping)))
        m.d.sync += [dt.eq(self.dt), half_dt_sq.eq(self.half_dt_sq), half_spring.eq(self.half_spring),
                     damping.eq(self.damping)]

        # ---------------------------------------------------------------- front
        side_layout = data.StructLayout({
            "first": unsigned(1), "last": unsigned(1), "delta": vector_layout(fs.delta),
            "rest": shape_of(fs.rest_length), "length_sq": shape_of(fs.length_sq),
        })
        in_flight = self.latency + 2  # entries (hence nodes) that can be inside at once
        m.submodules.side = side = SyncFIFO(width=side_layout.size, depth=self.rsqrt_latency + 2)
        m.submodules.headers = headers = SyncFIFO(width=node_layout(fs).size, depth=in_flight)

        front_out_valid = Signal()
        fa = Signal()
        m.d.comb += fa.eq(~front_out_valid | rsqrt.i.ready)
        m.d.comb += self.i.ready.eq(fa & headers.w_rdy)
        take = self.i.valid & self.i.ready
        stage, reg, state, mul, product = pipeline(fa, take)
        beat = self.i.payload

        # F1: capture; P_i comes from the header on a node's first entry
        current = Signal(vector_layout(fs.position))
        with m.If(take & beat.first):
            m.d.sync += current.eq(beat.node.position)
        m.d.comb += [headers.w_en.eq(take & beat.first), headers.w_data.eq(beat.node.as_value())]
        stage()
        p_i = reg(Mux(beat.first, beat.node.position.as_value(), current.as_value()), vector_layout(fs.position),
                  "f1_pi")
        p_j = reg(beat.neighbour.position, vector_layout(fs.position), "f1_pj")
        rest = reg(beat.neighbour.rest, shape_of(fs.rest_length), "f1_rest")
        first = reg(beat.first, 1, "f1_first")
        last = reg(beat.last, 1, "f1_last")

        # F2: Δ = rq(P_j − P_i → delta)
        stage()
        delta = [reg(requantize(p_j[c] - p_i[c], fs.position.frac_bits, fs.delta, rnd)[0], shape_of(fs.delta),
                     f"f2_delta_{c}") for c in "xy"]
        rest, first, last = (reg(v, v.shape(), f"f2_{n}") for n, v in (("rest", rest), ("first", first), ("last", last)))

        # F3: Δx², Δy² (partial products); F3b: their sums
        stage()
        square = [mul(d, d, f"f3_sq_{c}") for c, d in zip("xy", delta)]
        delta = [reg(d, d.shape(), f"f3_delta_{c}") for c, d in zip("xy", delta)]
        rest, first, last = (reg(v, v.shape(), f"f3_{n}") for n, v in (("rest", rest), ("first", first), ("last", last)))
        stage()
        square = [product(p, unsigned(2 * fs.delta.width), f"f3b_sq_{c}") for c, p in zip("xy", square)]
        delta = [reg(d, d.shape(), f"f3b_delta_{c}") for c, d in zip("xy", delta)]
        rest, first, last = (reg(v, v.shape(), f"f3b_{n}") for n, v in (("rest", rest), ("first", first), ("last", last)))

        # F4 (front output register): S = rq(Δx² + Δy² → length_sq)
        stage()
        s_value = requantize(square[0] + square[1], 2 * fs.delta.frac_bits, fs.length_sq, rnd)[0]
        length_sq = reg(s_value, shape_of(fs.length_sq), "f4_length_sq")
        side_data = Signal(side_layout, name="f4_side")
        with m.If(fa):
            m.d.sync += [
                side_data.first.eq(first), side_data.last.eq(last), side_data.rest.eq(rest),
                side_data.delta.x.eq(delta[0]), side_data.delta.y.eq(delta[1]), side_data.length_sq.eq(s_value),
            ]
        m.d.comb += [
            front_out_valid.eq(state["valid"]),
            rsqrt.i.valid.eq(front_out_valid),
            rsqrt.i.payload.eq(length_sq),
            side.w_en.eq(rsqrt.i.valid & rsqrt.i.ready),
            side.w_data.eq(side_data.as_value()),
        ]
        assert state["stages"] == self.FRONT_STAGES

        # ---------------------------------------------------------------- back
        ba = Signal()
        m.d.comb += ba.eq(~self.o.valid | self.o.ready)
        m.d.comb += [rsqrt.o.ready.eq(ba), side.r_en.eq(rsqrt.o.valid & ba)]
        stage, reg, state, mul, product = pipeline(ba, rsqrt.o.valid)
        head = data.View(side_layout, side.r_data)

        def carry(prefix, **values):
            return {n: reg(v, v.shape(), f"{prefix}_{n}") for n, v in values.items()}

        # B1: r and the entry's side data
        stage()
        r = reg(rsqrt.o.payload.rsqrt, unsigned(fs.rsqrt.width), "b1_r")
        c = carry("b1", first=head.first, last=head.last, rest=head.rest, length_sq=head.length_sq,
                  dx=head.delta.x, dy=head.delta.y)

        # B1b: registered again. Yosys merges the B1 registers into the side FIFO's memory as
        # its read register; this stage keeps that memory's output off the multipliers.
        stage()
        r = reg(r, r.shape(), "b1b_r")
        c = carry("b1b", **c)

        # B2: d·r and S·r
        stage()
        d_r = mul(c["rest"], r, "b2_dr")
        s_r = mul(c["length_sq"], r, "b2_sr")
        c = carry("b2", first=c["first"], last=c["last"], rest=c["rest"], dx=c["dx"], dy=c["dy"])
        stage()
        d_r = product(d_r, unsigned(fs.rest_length.width + fs.rsqrt.width), "b2b_dr")
        s_r = product(s_r, unsigned(fs.length_sq.width + fs.rsqrt.width), "b2b_sr")
        c = carry("b2b", **c)

        # B3: u = rq(1 − d·r → spring), L = rq(S·r → rest_length), e = |L − d|
        stage()
        dr_frac = fs.rest_length.frac_bits + fs.rsqrt.frac_bits
        one_minus = Signal(signed(fs.rest_length.width + fs.rsqrt.width + 2))
        m.d.comb += one_minus.eq((1 << dr_frac) - d_r)
        u = reg(requantize(one_minus, dr_frac, fs.spring, rnd)[0], shape_of(fs.spring), "b3_u")
        length = requantize(s_r, fs.length_sq.frac_bits + fs.rsqrt.frac_bits, fs.rest_length, rnd)[0]
        error = reg(Mux(length > c["rest"], length - c["rest"], c["rest"] - length), unsigned(fs.rest_length.width),
                    "b3_e")
        c = carry("b3", first=c["first"], last=c["last"], dx=c["dx"], dy=c["dy"])

        # B4: ½C·u
        stage()
        c_u = mul(half_spring, u, "b4_cu")
        c = carry("b4", first=c["first"], last=c["last"], dx=c["dx"], dy=c["dy"], e=error)
        stage()
        c_u = product(c_u, signed(2 * fs.spring.width), "b4b_cu")
        c = carry("b4b", **c)

        # B5: s = rq(½C·u → spring)
        stage()
        s = reg(requantize(c_u, 2 * fs.spring.frac_bits, fs.spring, rnd)[0], shape_of(fs.spring), "b5_s")
        c = carry("b5", **c)

        # B6: s·Δ
        stage()
        s_d = [mul(s, c[k], f"b6_sd_{k}") for k in ("dx", "dy")]
        c = carry("b6", first=c["first"], last=c["last"], e=c["e"])
        stage()
        s_d = [product(p, signed(fs.spring.width + fs.delta.width), f"b6b_sd_{k}") for k, p in zip("xy", s_d)]
        c = carry("b6b", **c)

        # B7: f = rq(s·Δ → force)
        stage()
        force = [reg(requantize(p, fs.spring.frac_bits + fs.delta.frac_bits, fs.force, rnd)[0], shape_of(fs.force),
                     f"b7_f_{k}") for k, p in zip("xy", s_d)]
        c = carry("b7", **c)

        # B8: per-node accumulators with guard bits (exact; saturated once in the tail)
        guard = accumulator_guard_bits(fs.max_degree)
        acc_f = [Signal(signed(fs.force.width + guard), name=f"acc_f_{k}") for k in "xy"]
        acc_e = Signal(unsigned(fs.rest_length.width + guard), name="acc_e")
        b7_valid = state["valid"]
        with m.If(ba & b7_valid):
            for acc, f in zip(acc_f, force):
                m.d.sync += acc.eq(Mux(c["first"], f, acc + f))
            m.d.sync += acc_e.eq(Mux(c["first"], c["e"], acc_e + c["e"]))
        node_done = Signal(name="b8_valid")
        # The node's header leaves its FIFO with the node's last entry in B8 (into a register
        # Yosys merges into the FIFO memory's read port), so that T1 registers it once more and
        # no memory output reaches a multiplier.
        m.d.comb += headers.r_en.eq(ba & b7_valid & c["last"])
        header = Signal(node_layout(fs), name="b8_header")
        with m.If(ba & b7_valid & c["last"]):
            m.d.sync += header.eq(headers.r_data)
        with m.If(ba):
            m.d.sync += node_done.eq(b7_valid & c["last"])
        state["stages"] += 1
        assert state["stages"] == self.BACK_STAGES

        # ---------------------------------------------------------------- node tail
        stage, reg, state, mul, product = pipeline(ba, node_done)

        # T1: F = sat(Σf → force_acc), Σe = sat(Σe → error_acc), the node's header
        stage()
        f_acc = [reg(requantize(acc, fs.force.frac_bits, fs.force_acc, rnd)[0], shape_of(fs.force_acc), f"t1_F_{k}")
                 for k, acc in zip("xy", acc_f)]
        e_sum = reg(requantize(acc_e, fs.rest_length.frac_bits, fs.error_acc, rnd)[0], shape_of(fs.error_acc),
                    "t1_esum")
        pos = [reg(header.position[k], shape_of(fs.position), f"t1_p_{k}") for k in "xy"]
        vel = [reg(header.velocity[k], shape_of(fs.velocity), f"t1_v_{k}") for k in "xy"]
        inv_mass = reg(header.inv_mass, shape_of(fs.inv_mass), "t1_inv_mass")

        def carry_node(prefix, with_vel=True):
            nonlocal pos, vel, e_sum
            pos = [reg(p, p.shape(), f"{prefix}_p_{k}") for k, p in zip("xy", pos)]
            if with_vel:
                vel = [reg(v, v.shape(), f"{prefix}_v_{k}") for k, v in zip("xy", vel)]
            e_sum = reg(e_sum, e_sum.shape(), f"{prefix}_esum")

        # T2: F·(1/m)
        stage()
        f_m = [mul(f, inv_mass, f"t2_fm_{k}") for k, f in zip("xy", f_acc)]
        carry_node("t2")
        stage()
        f_m = [product(p, signed(fs.force_acc.width + fs.inv_mass.width + 1), f"t2b_fm_{k}")
               for k, p in zip("xy", f_m)]
        carry_node("t2b")

        # T3: a = rq(F·(1/m) → accel)
        stage()
        accel = [reg(requantize(p, fs.force_acc.frac_bits + fs.inv_mass.frac_bits, fs.accel, rnd)[0],
                     shape_of(fs.accel), f"t3_a_{k}") for k, p in zip("xy", f_m)]
        carry_node("t3")

        # T4: Δt·V, ½Δt²·a, Δt·a
        stage()
        dt_v = [mul(dt, v, f"t4_dtv_{k}") for k, v in zip("xy", vel)]
        h_a = [mul(half_dt_sq, a, f"t4_ha_{k}") for k, a in zip("xy", accel)]
        dt_a = [mul(dt, a, f"t4_dta_{k}") for k, a in zip("xy", accel)]
        carry_node("t4")
        stage()
        dt_v = [product(p, signed(fs.dt.width + fs.velocity.width + 1), f"t4b_dtv_{k}") for k, p in zip("xy", dt_v)]
        h_a = [product(p, signed(fs.half_dt_sq.width + fs.accel.width + 1), f"t4b_ha_{k}") for k, p in zip("xy", h_a)]
        dt_a = [product(p, signed(fs.dt.width + fs.accel.width + 1), f"t4b_dta_{k}") for k, p in zip("xy", dt_a)]
        carry_node("t4b")

        # T5: P' = sat(P + rq(Δt·V + ½Δt²·a)), V' = sat(V + rq(Δt·a))
        stage()
        fv = fs.dt.frac_bits + fs.velocity.frac_bits
        fa_ = fs.half_dt_sq.frac_bits + fs.accel.frac_bits
        step_frac = max(fv, fa_)
        wide_p = Format(fs.position.signed, fs.position.int_bits + 1, fs.position.frac_bits)
        wide_v = Format(fs.velocity.signed, fs.velocity.int_bits + 1, fs.velocity.frac_bits)
        new_pos, new_vel = [], []
        for k, p, v, a1, a2, a3 in zip("xy", pos, vel, dt_v, h_a, dt_a):
            step = (a1 << (step_frac - fv)) + (a2 << (step_frac - fa_))
            moved = p + requantize(step, step_frac, wide_p, rnd)[0]
            new_pos.append(reg(clamp(moved, fs.position)[0], shape_of(fs.position), f"t5_p_{k}"))
            kicked = v + requantize(a3, fs.dt.frac_bits + fs.accel.frac_bits, wide_v, rnd)[0]
            new_vel.append(reg(clamp(kicked, fs.velocity)[0], shape_of(fs.velocity), f"t5_v_{k}"))
        pos, vel = new_pos, new_vel
        e_sum = reg(e_sum, e_sum.shape(), "t5_esum")

        # T6: V'·(1 − γ)
        stage()
        v_k = [mul(v, damping, f"t6_vk_{k}") for k, v in zip("xy", vel)]
        carry_node("t6", with_vel=False)
        stage()
        v_k = [product(p, signed(fs.velocity.width + fs.damping.width + 1), f"t6b_vk_{k}") for k, p in zip("xy", v_k)]
        carry_node("t6b", with_vel=False)

        # T7 (output register): V'' = rq(V'·(1 − γ) → velocity)
        with m.If(ba):
            m.d.sync += [
                self.o.valid.eq(state["valid"]),
                self.o.payload.position.x.eq(pos[0]),
                self.o.payload.position.y.eq(pos[1]),
                self.o.payload.velocity.x.eq(requantize(v_k[0], fs.velocity.frac_bits + fs.damping.frac_bits,
                                                        fs.velocity, rnd)[0]),
                self.o.payload.velocity.y.eq(requantize(v_k[1], fs.velocity.frac_bits + fs.damping.frac_bits,
                                                        fs.velocity, rnd)[0]),
                self.o.payload.error_sum.eq(e_sum),
            ]
        state["stages"] += 1
        assert state["stages"] == self.TAIL_STAGES
        return m
