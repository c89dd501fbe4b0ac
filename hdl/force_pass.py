"""The force pass: per neighbour entry the spring and barrier forces, per node their sums.

The RTL twin of :func:`golden_model.fixed.pipeline.node_terms`; every width comes from a
:class:`~golden_model.fixed.FormatSet`. ``docs/hardware.md`` maps each stage onto the steps of
``docs/fixed-point.md``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from types import SimpleNamespace

from amaranth.hdl import Cat, Module, Mux, Shape, Signal, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet

from .dsp import kept_register
from .fixedpoint import FormatSetNotBuildable, clamp, shape_of, shift_round, sum_round
from .layouts import (FORCE_ENTRY_EVENTS, FORCE_NODE_EVENTS, force_entry_layout, force_saturations_max,
                      node_force_layout, vector_layout)
from .pipeline import EventCount, LiveValues, Pipeline, count_stages
from .rsqrt import RsqrtUnit

__all__ = ["ForcePass", "ForcePassStages", "format_set"]


def format_set(fs: FormatSet | str, component: str) -> FormatSet:
    """``fs``, or the preset it names; a clear error for anything else."""
    if isinstance(fs, str):
        fs = FormatSet.preset(fs)
    if not isinstance(fs, FormatSet):
        raise TypeError(f"{component} needs a FormatSet or a preset name, not {fs!r}")
    return fs


@dataclass(frozen=True)
class ForcePassStages:
    """Stages of a :class:`ForcePass` as its pipelines build them.

    Attributes:
        front: F0…F8, the entry to the rsqrt unit's input.
        barrier: S1…S8, the fold barrier's force, computed in the delay line beside the rsqrt unit.
        rsqrt: the rsqrt unit's latency, which the delay line matches.
        back: B1…B11 (B11: the node's accumulators) and the node's N1, N2 (rounding, saturation).
    """

    front: int
    barrier: int
    rsqrt: int
    back: int

    @property
    def latency(self) -> int:
        return self.front + self.rsqrt + self.back


class ForcePass(wiring.Component):
    """Pipelined force pass over neighbour entries, bit-exact with the golden model's ``node_terms``.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        Every width, the rounding mode and ``max_degree`` come from it.
    energy : :class:`bool`
        Also sum each node's exact energy partials (``error_squares``, ``barrier_energy`` of
        :func:`~hdl.layouts.node_force_layout`): two more multiplies (``e²`` beside ``½C·u``,
        ``c·h`` beside ``c·D``), which a datapath without them does not pay for.
    saturations : :class:`bool`
        Also count each node's saturation events as the golden model's ``SaturationCounter``
        counts them in ``node_terms`` (``saturations`` of :func:`~hdl.layouts.node_force_layout`;
        per entry the events of :data:`~hdl.layouts.FORCE_ENTRY_EVENTS`, per node those of
        :data:`~hdl.layouts.FORCE_NODE_EVENTS`), and take the ``barrier`` input. Every saturation
        stage's overflow bits are added into a small running count that rides with the entry and
        is summed per node like the forces; no stage, no multiply more.
    delay_lines : :class:`bool`
        Carry the values that ride along unchanged for several stages in delay lines of
        distributed RAM, not a register per stage (:class:`~hdl.pipeline.Pipeline`): the same
        results clock for clock, fewer flip-flops.

    Members
    -------
    i : ``In(stream.Signature(force_entry_layout(fs), always_ready=True))``
        Neighbour entries, node after node (``first``, ``last``); the node's own position rides on
        its first entry. A node with n ≥ 1 neighbours is n beats. Always ready.
    o : ``Out(stream.Signature(node_force_layout(fs, energy), always_ready=True))``
        One beat per node, in input order: ``Σf`` [force_acc] and ``Σ|L − d|`` [error_acc]
        (saturated), ``inside``, with ``energy`` the exact ``Σe²`` and ``Σc·h``, with
        ``saturations`` the node's event count ``saturations`` (up to
        :func:`~hdl.layouts.force_saturations_max`: ``max_degree`` · 18 + 3; the entries' count plus the
        node's three flags, one small adder after the registers). ``o.valid`` is a
        register: its consumer takes every beat on the clock it is offered.
    half_spring : ``In(shape_of(fs.spring))``
        ``½C`` [spring]; registered once per clock, hold it stable while a pass is in flight.
    barrier : ``In(1)``, with ``saturations`` only
        The fold barrier is on: its events (the Δb narrowing, ``area``, ``area_short``,
        ``barrier_coeff``, ``barrier_edge``, ``barrier_force``) count. Off, the golden model computes
        no barrier terms and the entries' triangles are filler, whose events must not count.
        Registered once per clock, like ``half_spring``.
    idle : ``Out(1)``
        No node in flight: every node whose first entry was accepted has left ``o``.

    Contract
    --------
    Throughput: one entry per clock (II = 1), no gap between nodes, any degree 1…``fs.max_degree``.
    Latency: ``latency`` clocks from a node's last entry to its result on ``o``
    (``stages.front + stages.rsqrt + stages.back``, counted from the pipelines the pass builds).
    No back-pressure: neither stream stalls.

    Structure
    ---------
    A free-running pipeline: every stage register loads on every clock (no enable fans out), a
    valid bit travels with the data. A front section (``P_i`` held from the first entry, the
    differences, ``|Δ|²`` and the barrier triangle's doubled area) feeds the
    :class:`~hdl.rsqrt.RsqrtUnit` (``o.ready`` tied high); the entry's other data waits for
    ``r`` in a delay line as long as the unit, whose first stages compute the barrier's force;
    a back section forms ``s``, the spring force and ``|L − d|`` and accumulates per node with
    guard bits (exact), and two node stages round and saturate the sums. Every multiply's
    operands land in fabric registers first, its partial products sit alone between
    registers and are added pairwise, one adder per stage; every rounding and every saturation
    has a stage of its own.
    """

    def __init__(self, fs: FormatSet | str, *, energy: bool = False, saturations: bool = False,
                 delay_lines: bool = False):
        fs = format_set(fs, "ForcePass")
        if fs.delta.frac_bits > fs.position.frac_bits:
            raise FormatSetNotBuildable(f"delta {fs.delta} cannot have more fraction bits than position {fs.position}")
        self.fs, self.energy, self.saturations = fs, bool(energy), bool(saturations)
        self.delay_lines = bool(delay_lines)
        super().__init__(self.signature_of(fs, self.energy, self.saturations))
        self.stages = _stage_counts(fs, self.energy, self.saturations)
        if self.stages.barrier > self.stages.rsqrt:
            raise FormatSetNotBuildable(
                f"the fold barrier needs {self.stages.barrier} stages, more than the rsqrt unit's "
                f"{self.stages.rsqrt} it runs beside")
        self.latency = self.stages.latency

    @staticmethod
    def signature_of(fs: FormatSet, energy: bool = False, saturations: bool = False) -> wiring.Signature:
        """The component's signature (also the throwaway build's stand-in ports)."""
        members = {
            "i": In(stream.Signature(force_entry_layout(fs), always_ready=True)),
            "o": Out(stream.Signature(node_force_layout(fs, energy, saturations), always_ready=True)),
            "half_spring": In(shape_of(fs.spring)),
            "idle": Out(1),
        }
        if saturations:
            members["barrier"] = In(1)
        return wiring.Signature(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.rsqrt = rsqrt = RsqrtUnit(self.fs)
        _build(m, self.fs, self.energy, self.saturations, self, rsqrt, platform, self.delay_lines)
        return m


@functools.cache
def _stage_counts(fs: FormatSet, energy: bool, saturations: bool) -> ForcePassStages:
    """The stages :func:`_build` builds (a throwaway build with stand-in ports)."""
    config = fs.rsqrt_config()
    rsqrt = SimpleNamespace(  # the rsqrt unit's ports, as RsqrtUnit declares them
        i=stream.Signature(unsigned(config.fmt_in.width)).create(),
        o=stream.Signature(RsqrtUnit.output_layout(config)).create(),
        latency=RsqrtUnit.latency_of(config))
    ports = ForcePass.signature_of(fs, energy, saturations).create()
    return count_stages(lambda m: _build(m, fs, energy, saturations, ports, rsqrt, None))


def _build(m: Module, fs: FormatSet, energy: bool, saturations: bool, ports, rsqrt, platform,
           delay_lines: bool = False) -> ForcePassStages:
    """The force pass's datapath into ``m``: ``ports`` (``i``, ``o``, ``half_spring``, ``idle``, with
    ``saturations`` ``barrier``) and the rsqrt unit's ``i``, ``o`` and ``latency``; returns the
    stages it built (the same with or without ``delay_lines``: :class:`~hdl.pipeline.Pipeline`)."""
    rnd = fs.rounding
    half_spring = Signal.like(ports.half_spring, name="half_spring_r", reset_less=True)
    m.d.sync += half_spring.eq(ports.half_spring)
    live = LiveValues()

    # Saturation events: counted by a few small adders along the entry, not a bit per event per
    # stage (EventCount); the fold barrier's flags count only while it is on.
    entry_events = sum(FORCE_ENTRY_EVENTS.values())
    barrier_on = Signal(name="barrier_r", reset_less=True)
    if saturations:
        m.d.sync += barrier_on.eq(ports.barrier)
    count = EventCount(live, entry_events.bit_length(), barrier=barrier_on)

    def events(*flags, barrier=()):
        """The stage's event values (:class:`~hdl.pipeline.EventCount`; ``{}`` without ``saturations``)."""
        return count(*flags, barrier=barrier) if saturations else {}

    def rounded(value, from_frac, fmt):
        """``value`` (``from_frac`` fraction bits) rounded to ``fmt``'s lsb; not yet saturated."""
        return shift_round(value, from_frac - fmt.frac_bits, rnd)

    # ------------------------------------------------------------ front
    current = Signal(vector_layout(fs.position), name="current_position", reset_less=True)
    front = Pipeline(m, ports.i.valid, land_operands=True, platform=platform, delay_lines=delay_lines)
    position = vector_layout(fs.position)
    # F0: the beat as it arrived, so that i.valid drives no wide enable (the held P_i's was
    # the critical path once the barrier widened the entry)
    live.step(front, "f0", beat=ports.i.payload.as_value())
    beat = data.View(force_entry_layout(fs), live["beat"])
    # The held P_i loads on a flip-flop of its own, set beside F0 (f0_valid, which drives the
    # whole front, was 6 ns of routing away from these 64 registers).
    load_current = Signal(name="load_current_position")
    m.d.sync += load_current.eq(ports.i.valid & ports.i.payload.first)
    with m.If(load_current):
        m.d.sync += current.eq(beat.position)
    # F1: P_i comes from the node's first entry
    live.step(front, "f1", drop=("beat",), p_i=Mux(beat.first, beat.position.as_value(), current.as_value()),
              p_j=beat.neighbour.position.as_value(), p_b=beat.barrier.second.as_value(), rest=beat.neighbour.rest,
              threshold=beat.barrier.threshold, gain=beat.barrier.gain, first=beat.first, last=beat.last)
    p_i, p_j, p_b = (data.View(position, live[k]) for k in ("p_i", "p_j", "p_b"))
    # F2: P_j − P_i and the barrier's P_second − P_i, exact;  F3: rounded to delta;  F4: saturated
    live.step(front, "f2", drop=("p_i", "p_j", "p_b"), dx=p_j.x - p_i.x, dy=p_j.y - p_i.y,
              bx=p_b.x - p_i.x, by=p_b.y - p_i.y)
    live.step(front, "f3", **{k: rounded(live[k], fs.position.frac_bits, fs.delta) for k in ("dx", "dy", "bx", "by")})
    narrowed = {k: clamp(live[k], fs.delta) for k in ("dx", "dy", "bx", "by")}
    live.step(front, "f4", **{k: value for k, (value, _) in narrowed.items()},
              **events(narrowed["dx"][1], narrowed["dy"][1], barrier=(narrowed["bx"][1], narrowed["by"][1])))

    # F5…: Δx², Δy² and the barrier's Δa.x·Δb.y, Δa.y·Δb.x;  then S = rq(Δx² + Δy² → length_sq)
    # and X = rq(Δa × Δb → area) as sum, rounding, saturation
    live.multiply(front, "f5", sq_x=(live["dx"], live["dx"]), sq_y=(live["dy"], live["dy"]),
                  cross_a=(live["dx"], live["by"]), cross_b=(live["dy"], live["bx"]))
    square_frac = 2 * fs.delta.frac_bits
    live.step(front, "f6", drop=("sq_x", "sq_y", "cross_a", "cross_b"), s=live["sq_x"] + live["sq_y"],
              cross=live["cross_a"] - live["cross_b"])
    live.step(front, "f7", s=rounded(live["s"], square_frac, fs.length_sq),
              cross=rounded(live["cross"], square_frac, fs.area))
    length_sq, area = clamp(live["s"], fs.length_sq), clamp(live["cross"], fs.area)
    live.step(front, "f8", s=length_sq[0], cross=area[0], **events(length_sq[1], barrier=(area[1],)))
    m.d.comb += [rsqrt.i.valid.eq(front.valid), rsqrt.i.payload.eq(live["s"]), rsqrt.o.ready.eq(1)]

    # The entry's side data waits for r in a delay line as long as the rsqrt unit; the fold
    # barrier's force is computed there.
    side = Pipeline(m, front.valid, land_operands=True, platform=platform, delay_lines=delay_lines)
    # S1: the shortfall T − X and the opposite edge D = Δa − Δb, exact
    live.step(side, "s1", drop=("cross", "threshold", "bx", "by"), short=live["threshold"] - live["cross"],
              ex=live["dx"] - live["bx"], ey=live["dy"] - live["by"])
    # S2: h = sat(max(T − X, 0) → area), non-negative;  D saturated to delta;  inside: h > 0
    short = live["short"]
    short_sat, edge_x, edge_y = clamp(short, fs.area), clamp(live["ex"], fs.delta), clamp(live["ey"], fs.delta)
    live.step(side, "s2", short=Mux(short < 0, 0, short_sat[0])[:fs.area.width - 1],
              ex=edge_x[0], ey=edge_y[0], inside=(short >= 0) & short.any(),
              **events(barrier=(short_sat[1] & (short >= 0), edge_x[1], edge_y[1])))
    # c = rq(G·h → barrier_coeff);  h stays for c·h when the energy is summed
    live.multiply(side, "s3", drop=("gain",) if energy else ("short", "gain"), c=(live["gain"], live["short"]))
    live.step(side, "s4", c=rounded(live["c"], fs.barrier_gain.frac_bits + fs.area.frac_bits, fs.barrier_coeff))
    coeff = clamp(live["c"], fs.barrier_coeff)
    live.step(side, "s5", c=coeff[0], **events(barrier=(coeff[1],)))
    # f_b = rq(c·(D.y, −D.x) → force): the minus folds into the rounding's subtraction;
    # beside it the entry's barrier energy c·h (exact)
    energy_product = {"ch": (live["c"], live["short"])} if energy else {}
    live.multiply(side, "s6", drop=("c", "ex", "ey", "short"), fb_x=(live["c"], live["ey"]),
                  fb_y=(live["c"], live["ex"]), **energy_product)
    fb_frac = fs.barrier_coeff.frac_bits + fs.delta.frac_bits
    live.step(side, "s7", fb_x=rounded(live["fb_x"], fb_frac, fs.force),
              fb_y=sum_round((), fb_frac - fs.force.frac_bits, rnd, sub=[live["fb_y"]]))
    fb_x, fb_y = clamp(live["fb_x"], fs.force), clamp(live["fb_y"], fs.force)
    live.step(side, "s8", fb_x=fb_x[0], fb_y=fb_y[0], **events(barrier=(fb_x[1], fb_y[1])))
    barrier_stages = side.stages
    for n in range(side.stages, rsqrt.latency):
        live.step(side, f"side{n}")

    # ------------------------------------------------------------ back
    back = Pipeline(m, rsqrt.o.valid, land_operands=True, platform=platform, delay_lines=delay_lines)
    r = rsqrt.o.payload.rsqrt  # leaves the rsqrt unit's output register
    live.update(events(rsqrt.o.payload.saturated))  # registered by b1's first stage, beside r's use
    # d·r and S·r
    live.multiply(back, "b1", drop=("s",), d_r=(live["rest"], r), s_r=(live["s"], r))
    # u = rq(1 − d·r → spring), L = rq(S·r → rest_length): rounding, then saturation
    dr_frac = fs.rest_length.frac_bits + fs.rsqrt.frac_bits
    if fs.spring.frac_bits < dr_frac:  # the rounding constant folds into 1 − d·r: one subtraction
        u = sum_round((), dr_frac - fs.spring.frac_bits, rnd, sub=[live["d_r"]], const=1 << dr_frac)
    else:
        u = rounded((1 << dr_frac) - live["d_r"], dr_frac, fs.spring)
    live.step(back, "b2", drop=("d_r", "s_r"), u=u,
              length=rounded(live["s_r"], fs.length_sq.frac_bits + fs.rsqrt.frac_bits, fs.rest_length))
    u, length = clamp(live["u"], fs.spring), clamp(live["length"], fs.rest_length)
    live.step(back, "b3", u=u[0], length=length[0], **events(u[1], length[1]))
    # e = |L − d| alongside ½C·u (and e², exact, when the energy is summed)
    length, rest = live["length"], live["rest"]
    live["e"] = e = Mux(length > rest, length - rest, rest - length)[:fs.rest_length.width]
    live.multiply(back, "b4", drop=("length", "rest", "u"), c_u=(half_spring, live["u"]),
                  **({"e_sq": (e, e)} if energy else {}))
    # s = rq(½C·u → spring)
    live.step(back, "b5", c_u=rounded(live["c_u"], 2 * fs.spring.frac_bits, fs.spring))
    spring = clamp(live["c_u"], fs.spring)
    live.step(back, "b6", drop=("c_u",), s=spring[0], **events(spring[1]))
    # s·Δ, then f = rq(s·Δ → force)
    live.multiply(back, "b7", drop=("s", "dx", "dy"), f_x=(live["s"], live["dx"]), f_y=(live["s"], live["dy"]))
    f_frac = fs.spring.frac_bits + fs.delta.frac_bits
    live.step(back, "b8", f_x=rounded(live["f_x"], f_frac, fs.force), f_y=rounded(live["f_y"], f_frac, fs.force))
    f_x, f_y = clamp(live["f_x"], fs.force), clamp(live["f_y"], fs.force)
    live.step(back, "b9", f_x=f_x[0], f_y=f_y[0], **events(f_x[1], f_y[1]))
    # B10: the entry's force, spring plus barrier, exact; the last saturation flags join the count
    entry_before, first_before = back.valid, live["first"]
    live.step(back, "b10", drop=("fb_x", "fb_y", "first"),
              f_x=live["f_x"] + live["fb_x"], f_y=live["f_y"] + live["fb_y"],
              **(count.flush() if saturations else {}))

    # B11: per-node accumulators with guard bits (exact; rounded and saturated once, in N1, N2),
    # restarted on a node's first entry. The stage's valid bit is the node's last entry: from
    # here on one beat is one node.
    acc = {name: Shape(width, is_signed) for name, (is_signed, width) in fs.accumulators().items()}
    out = ports.o.payload
    sums = {  # name: (accumulator shape, this entry's term, combine)
        "f_x": (acc["force"], live["f_x"], "add"),  # two terms per entry with the barrier
        "f_y": (acc["force"], live["f_y"], "add"),
        "e": (acc["error"], live["e"], "add"),
        "inside": (unsigned(1), live["inside"], "or"),  # a triangle of the node is inside the barrier
    }
    if energy:
        sums["e_sq"] = (out.error_squares.shape(), live["e_sq"], "add")
        sums["ch"] = (out.barrier_energy.shape(), live["ch"], "add")
    if saturations:
        assert sum(count.counted) == entry_events, (count.counted, FORCE_ENTRY_EVENTS)
        sums["ev"] = (unsigned((fs.max_degree * entry_events).bit_length()), live["ev"], "add")
    last, entry_valid = live["last"], back.valid
    # each accumulator's enable and restart from copies of B10's valid and first bits of its own (one
    # pair fanned out to every accumulator's bits, spread over the device, is a path across it)
    restart = {name: (kept_register(m, entry_before, name=f"b10_valid_{name}", platform=platform),
                      kept_register(m, first_before, name=f"b10_first_{name}", platform=platform))
               for name in sums}
    back.stage("b11", valid=entry_valid & last)
    live.clear()
    for name, (shape, term, combine) in sums.items():
        acc = live[name] = Signal(shape, name=f"acc_{name}", reset_less=True)
        valid, first = restart[name]
        with m.If(valid):
            m.d.sync += acc.eq(Mux(first, term, (acc | term) if combine == "or" else acc + term))
    # N1: the sums rounded;  N2: saturated (the exact energy partials ride along)
    live.step(back, "n1", f_x=rounded(live["f_x"], fs.force.frac_bits, fs.force_acc),
              f_y=rounded(live["f_y"], fs.force.frac_bits, fs.force_acc),
              e=rounded(live["e"], fs.rest_length.frac_bits, fs.error_acc))
    force_x, force_y, error = (clamp(live["f_x"], fs.force_acc), clamp(live["f_y"], fs.force_acc),
                               clamp(live["e"], fs.error_acc))
    if saturations:  # the node's own events, registered beside their clamps (N2), join its entries' sum at o
        node_flags = (force_x[1], force_y[1], error[1])
        assert len(node_flags) == sum(FORCE_NODE_EVENTS.values()), FORCE_NODE_EVENTS
        live["ev_node"] = Cat(*node_flags)
    live.step(back, "n2", f_x=force_x[0], f_y=force_y[0], e=error[0])
    m.d.comb += [ports.o.valid.eq(back.valid), out.force.x.eq(live["f_x"]), out.force.y.eq(live["f_y"]),
                 out.error_sum.eq(live["e"]), out.inside.eq(live["inside"])]
    if energy:
        m.d.comb += [out.error_squares.eq(live["e_sq"]), out.barrier_energy.eq(live["ch"])]
    if saturations:
        # the clamps' flags added after N2, from registers (added in N1 -> N2 with the clamps, the flags
        # would route from the clamps' carry chains into the count in one clock)
        flags = live["ev_node"]
        total = live["ev"] + sum(flags[i] for i in range(len(flags)))
        m.d.comb += out.saturations.eq(total[:force_saturations_max(fs).bit_length()])
    stages = ForcePassStages(front=front.stages, barrier=barrier_stages, rsqrt=rsqrt.latency, back=back.stages)

    # ------------------------------------------------------------ idle
    # nodes in flight: last entries accepted whose results have not left o (at most one per stage)
    in_flight = Signal(range(stages.latency + 2), name="nodes_in_flight")
    open_node = Signal(name="open_node")  # between a node's first and last entry
    node_in = ports.i.valid & ports.i.payload.last
    m.d.sync += in_flight.eq(in_flight + node_in - ports.o.valid)
    with m.If(ports.i.valid):
        m.d.sync += open_node.eq(~ports.i.payload.last)
    m.d.comb += ports.idle.eq((in_flight == 0) & ~open_node)
    return stages
