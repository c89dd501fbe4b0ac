"""The integrate stage: a node's acceleration, its Euler or momentum step, damping and power.

The RTL twin of :func:`golden_model.fixed.pipeline.integrate` / ``integrate_momentum`` and
``node_power``; every width comes from a :class:`~golden_model.fixed.FormatSet`.
``docs/hardware.md`` maps each stage onto the steps of ``docs/fixed-point.md``.
"""

from __future__ import annotations

import functools

from amaranth.hdl import Module, Mux, Shape, ShapeCastable, Signal, Value
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import Format, FormatSet
from golden_model.guard import SCALE_MAX_SHIFT

from .dsp import kept_register
from .fixedpoint import FormatSetNotBuildable, clamp, round_half_bit, shape_of, shift_round, variable_shift
from .force_pass import format_set
from .layouts import COARSE_INTEGRATOR_EVENTS, INTEGRATOR_EVENTS, integrator_input_layout, integrator_output_layout
from .pipeline import EventCount, LiveValues, Pipeline, aligned_add, count_stages

__all__ = ["Integrator"]


class Integrator(wiring.Component):
    """Pipelined per-node integration, bit-exact with the golden model's ``integrate`` (the paper's
    Euler step), ``integrate_momentum`` and ``node_power``.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        Every width and the rounding mode come from it.
    side : shape or ``None``
        An opaque field of this shape carried from ``i`` to ``o`` with the node (``None``: none);
        :class:`~hdl.node_update.NodeUpdate` carries the node's error sum this way instead of in
        a delay line of its own.
    saturations : :class:`bool`
        Also count each node's saturation events as the golden model's ``SaturationCounter``
        counts them (``saturations`` of :func:`~hdl.layouts.integrator_output_layout`, up to
        :data:`~hdl.layouts.INTEGRATOR_EVENTS`: 13). Every saturation stage's overflow bits
        (those of the dynamics in use) are added into a running count that rides with the node;
        one stage more (the last flags' addition), no multiply more.
    delay_lines : :class:`bool`
        Carry the values that ride along unchanged for several stages in delay lines of
        distributed RAM, not a register per stage (:class:`~hdl.pipeline.Pipeline`): the same
        results clock for clock, fewer flip-flops.
    coarse : :class:`bool`
        Take each node's coarse move (``coarse`` [accel] in ``i``, :class:`~hdl.coarse_node.CoarseNode`'s)
        into the momentum step's ``a`` before the step scale, ``a = sat(a + coarse → accel)``, as
        :func:`golden_model.fixed.guard.proposal` does with its ``coarse``: one stage more, two events more
        (:data:`~hdl.layouts.COARSE_INTEGRATOR_EVENTS`). Drive 0 for a step without it. Not with
        ``shift_copy``. Not yet built into ``SpringflatEngine``.

    Members
    -------
    i : ``In(stream.Signature(integrator_input_layout(fs, side), always_ready=True))``
        One node per beat: its state (position, velocity, ``1/m`` and the barrier's weight ``w_b``),
        ``F`` [force_acc] and ``inside`` (use ``w_b``). Always ready.
    o : ``Out(stream.Signature(integrator_output_layout(fs, side), always_ready=True))``
        One beat per node, in input order: new position, new (damped) velocity, the power ``F·V``
        [power] of the input state, with ``saturations`` the node's event count ``saturations``.
        ``o.valid`` is a register; its consumer takes every beat.
    dt, half_dt_sq, damping : ``In(...)``
        ``Δt`` [dt], ``½Δt²`` [half_dt_sq], ``1 − γ`` [damping]; registered once per clock, hold
        them stable while a pass is in flight.
    momentum : ``In(1)``
        The momentum dynamics (``docs/dynamics.md``): ``dt`` carries ``β``, the step becomes
        ``V' = rq(β·V + a → velocity)``, ``P' = sat(P + V')``; ``half_dt_sq`` and ``damping`` are
        not used. Change it only between passes.
    scale_shift : ``In(range(SCALE_MAX_SHIFT + 2))``
        The guarded step's scale, ``2^-scale_shift`` (:class:`golden_model.guard.StepScale`'s shift, up
        to ``SCALE_MAX_SHIFT + 1``): with ``momentum``, the step takes ``a' = rq(a·2^-scale_shift)``
        for ``a`` (:func:`golden_model.fixed.guard.proposal`); 0 leaves it alone. The paper's step
        ignores it. Registered; change it only between passes.
    propose : ``In(1)``
        With ``momentum``: a pass of proposals (the guarded mode's propose pass, whose position output
        is not used): ``saturations`` then counts what :func:`~golden_model.fixed.guard.proposal` counts
        (``accel`` and ``velocity``) and the power's (the guarded step forms ``S`` as it proposes:
        :meth:`~golden_model.fixed.controller.Controller.choose_step`), not the position's saturation.
        The outputs are the same either way. Registered; change it only between passes.
    idle : ``Out(1)``
        No node in flight.

    Contract
    --------
    Throughput: one node per clock (II = 1). Latency: ``latency`` clocks from a node's transfer on
    ``i`` to its result on ``o`` (the stages the pipeline builds, counted). No back-pressure.

    Structure
    ---------
    A free-running pipeline (no enable fans out). T1 registers the input as it arrives (in
    :class:`~hdl.node_update.NodeUpdate` straight from the node-header FIFO's LUT RAM); the
    weight is chosen as it lands for the first multiply. Both dynamics' step sums are formed and
    rounded and saturated side by side and the mode picks one in a stage of its own (neither in
    front of the 50-bit adder nor behind the saturation: both were critical paths). The proposal's
    ``a'`` is shifted and rounded in the first two of the ``Δt·V`` multiply's stages, beside it. Every
    multiply's operands land in fabric registers first; one adder, rounding or saturation per stage.
    """

    def __init__(self, fs: FormatSet | str, *, side: ShapeCastable | None = None, saturations: bool = False,
                 delay_lines: bool = False, shift_copy: bool = False, coarse: bool = False):
        fs = format_set(fs, "Integrator")
        if coarse and shift_copy:
            raise ValueError("Integrator: shift_copy copies a before the coarse move is added to it; build it "
                             "without shift_copy")
        if fs.velocity.frac_bits != fs.position.frac_bits:
            raise FormatSetNotBuildable(f"the momentum step adds V to P: velocity {fs.velocity} needs position's "
                                        f"{fs.position.frac_bits} fraction bits")
        if side is not None:
            Shape.cast(side)  # a clear error now rather than at elaboration
        self.fs, self.side, self.saturations = fs, side, bool(saturations)
        self.delay_lines, self.shift_copy, self.coarse = bool(delay_lines), bool(shift_copy), bool(coarse)
        super().__init__(self.signature_of(fs, side, self.saturations, self.coarse))
        self.latency = _stage_count(fs, side, self.saturations, self.coarse)

    @staticmethod
    def signature_of(fs: FormatSet, side: ShapeCastable | None = None, saturations: bool = False,
                     coarse: bool = False) -> wiring.Signature:
        """The component's signature (also the throwaway build's stand-in ports)."""
        return wiring.Signature({
            "i": In(stream.Signature(integrator_input_layout(fs, side, coarse), always_ready=True)),
            "o": Out(stream.Signature(integrator_output_layout(fs, side, saturations, coarse), always_ready=True)),
            "dt": In(shape_of(fs.dt)),
            "half_dt_sq": In(shape_of(fs.half_dt_sq)),
            "damping": In(shape_of(fs.damping)),
            "momentum": In(1),
            "scale_shift": In(range(SCALE_MAX_SHIFT + 2)),
            "propose": In(1),
            "idle": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        _build(m, self.fs, self.side, self.saturations, self, platform, self.delay_lines, self.shift_copy,
               self.coarse)
        return m


@functools.cache
def _stage_count(fs: FormatSet, side, saturations: bool, coarse: bool = False) -> int:
    """The stages :func:`_build` builds (a throwaway build with stand-in ports)."""
    ports = Integrator.signature_of(fs, side, saturations, coarse).create()
    return count_stages(lambda m: _build(m, fs, side, saturations, ports, None, coarse=coarse))


def _build(m: Module, fs: FormatSet, side, saturations: bool, ports, platform, delay_lines: bool = False,
           shift_copy: bool = False, coarse: bool = False) -> int:
    """The integrator's datapath into ``m`` (``ports``: the component's members); returns its stages
    (the same with or without ``delay_lines`` (:class:`~hdl.pipeline.Pipeline`) and ``shift_copy``; one more
    with ``coarse``)."""
    rnd = fs.rounding
    # Constants, registered so that they reach the multipliers from registers.
    dt, half_dt_sq, damping = (Signal.like(p, name=f"{n}_r", reset_less=True) for n, p in (
        ("dt", ports.dt), ("half_dt_sq", ports.half_dt_sq), ("damping", ports.damping)))
    momentum = Signal(name="momentum_r", reset_less=True)
    scale_shift = Signal.like(ports.scale_shift, name="scale_shift_r", reset_less=True)
    # the gate of the events the proposal (propose) does not count: the position's
    place = Signal(name="count_position_r", reset_less=True)
    power_gate = Signal(name="count_power_r", reset_less=True)
    one = 1 << fs.damping.frac_bits  # the momentum step is not damped: × 1 exactly
    m.d.sync += [dt.eq(ports.dt), half_dt_sq.eq(ports.half_dt_sq),
                 damping.eq(Mux(ports.momentum, one, ports.damping)), momentum.eq(ports.momentum),
                 scale_shift.eq(ports.scale_shift), place.eq(~(ports.momentum & ports.propose)),
                 power_gate.eq(ports.momentum)]

    def rounded(value, from_frac, fmt):
        """``value`` (``from_frac`` fraction bits) rounded to ``fmt``'s lsb; not yet saturated."""
        return shift_round(value, from_frac - fmt.frac_bits, rnd)

    live = LiveValues()
    # Saturation events: counted by a few small adders along the node (EventCount); a dynamics'
    # flags count only while it is the one in use.
    node_events = sum(INTEGRATOR_EVENTS.values()) + (sum(COARSE_INTEGRATOR_EVENTS.values()) if coarse else 0)
    count = EventCount(live, node_events.bit_length(), paper=~momentum, mom=momentum, place=place, power=power_gate)

    def events(*flags, **gated):
        """The stage's event values (:class:`~hdl.pipeline.EventCount`; ``{}`` without ``saturations``)."""
        return count(*flags, **gated) if saturations else {}
    tail = Pipeline(m, ports.i.valid, land_operands=True, platform=platform, delay_lines=delay_lines)
    node = ports.i.payload
    # T1: the node as it arrives
    live.step(tail, "t1", f_x=node.force.x, f_y=node.force.y, p_x=node.node.position.x, p_y=node.node.position.y,
              v_x=node.node.velocity.x, v_y=node.node.velocity.y, inv_mass=node.node.inv_mass,
              inv_mass_barrier=node.node.inv_mass_barrier, inside=node.inside,
              **({"side": Value.cast(node.side)} if side is not None else {}),
              **({"c_x": node.coarse.x, "c_y": node.coarse.y} if coarse else {}))
    # F·w, w the barrier's weight where a triangle of the node is inside it (chosen as it lands),
    # then a = rq(F·w → accel); and the power F·V of the input state (the momentum restart's S)
    weight = Mux(live["inside"], live["inv_mass_barrier"], live["inv_mass"])
    live.multiply(tail, "t2", drop=("f_x", "f_y", "inv_mass", "inv_mass_barrier", "inside"),
                  a_x=(live["f_x"], weight), a_y=(live["f_y"], weight),
                  pw_x=(live["f_x"], live["v_x"]), pw_y=(live["f_y"], live["v_y"]))
    a_frac = fs.force_acc.frac_bits + fs.inv_mass.frac_bits
    live.step(tail, "t3", drop=("pw_x", "pw_y"), a_x=rounded(live["a_x"], a_frac, fs.accel),
              a_y=rounded(live["a_y"], a_frac, fs.accel), pw=live["pw_x"] + live["pw_y"])
    a_x, a_y = clamp(live["a_x"], fs.accel), clamp(live["a_y"], fs.accel)
    live.step(tail, "t4", a_x=a_x[0], a_y=a_y[0],
              pw=rounded(live["pw"], fs.force_acc.frac_bits + fs.velocity.frac_bits, fs.power),
              **events(a_x[1], a_y[1]))
    if coarse:
        # T4c: a = sat(a + coarse → accel), the proposal's coarse move added before the step scale; in the
        # paper's step and an unguarded momentum step the coarse input is 0 and changes nothing
        a_x, a_y = (clamp(live[f"a_{k}"] + live[f"c_{k}"], fs.accel) for k in "xy")
        live.step(tail, "t4c", drop=("c_x", "c_y"), a_x=a_x[0], a_y=a_y[0], **events(a_x[1], a_y[1]))
    power = clamp(live["pw"], fs.power)
    live["pw"] = power[0]
    # the power counts only in the momentum dynamics: the controller forms S (and the golden model
    # node_power) only there; not in a proposal (the guarded mode forms S as it measures a layout)
    live.update(events(power=(power[1],)))  # registered by t5's first stage, beside the power's saturation
    # the momentum step's a' = a·2^-scale_shift rounded (the guarded proposal's step scale; a' = a at
    # shift 0), alongside the multiply: the variable shift in its first stage, the rounding's carry
    # chain in its second
    clamped = {"x": a_x[0], "y": a_y[0]}
    for k in "xy":
        # shift_copy: loaded from t4's input in the clock t4 loads a (the pipeline is free-running)
        accel = kept_register(m, clamped[k], name=f"t4_a_shift_{k}", platform=platform).as_signed() \
            if shift_copy else live[f"a_{k}"]
        live[f"as_{k}"], live[f"as_sticky_{k}"] = variable_shift(accel, scale_shift, rnd)

    def scaled_accel(values):
        rounded_a = {}
        for k in "xy":
            exact = round_half_bit(values[f"as_{k}"], rnd, values.pop(f"as_sticky_{k}"))
            # a' = a at shift 0; past it |a'| ≤ |a|/2 + 1/2 lsb: in accel's range either way
            rounded_a[f"as_{k}"] = exact[:fs.accel.width].as_signed()
        return rounded_a
    # Δt·V, ½Δt²·a, Δt·a
    live.multiply(tail, "t5", later=(scaled_accel,),
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
    # Both dynamics' sums are formed, rounded and saturated side by side; the mode picks one in
    # a stage of its own (T8m), not in front of the 50-bit adder (a multiplexer before a carry chain
    # that long adds its delay to the chain's).
    sums = {}
    for k in "xy":
        for mode, second in (("paper", live[f"ha_{k}"]), ("mom", live[f"as_{k}"].shift_left(fs.half_dt_sq.frac_bits))):
            value, shift = aligned_add(live[f"dtv_{k}"], step_frac - fv, second, step_frac - fa)
            sums[f"step_{mode}_{k}"] = Value.cast(value).shift_left(shift)
        sums[f"kick_{k}"] = rounded(live[f"dta_{k}"], kick_frac, wide_v)
    live.step(tail, "t6", drop=tuple(f"{n}_{k}" for n in ("dtv", "ha", "dta", "a", "as") for k in "xy"), **sums)
    kick = {k: clamp(live[f"kick_{k}"], wide_v) for k in "xy"}
    live.step(tail, "t7", **{f"step_{mode}_{k}": rounded(live[f"step_{mode}_{k}"], step_frac, wide_p)
                             for mode in ("paper", "mom") for k in "xy"},
              **{f"kick_{k}": kick[k][0] for k in "xy"}, **events(paper=(kick["x"][1], kick["y"][1])))
    # paper: the position step saturated to wide_p; momentum: V' = step saturated to velocity
    # (the momentum step's V' = rq(β·V + a → velocity) is its velocity event, the paper's its position_step)
    step_mom = {k: clamp(live[f"step_mom_{k}"], fs.velocity) for k in "xy"}
    step_paper = {k: clamp(live[f"step_paper_{k}"], wide_p) for k in "xy"}
    live.step(tail, "t8", drop=("kick_x", "kick_y"),
              **{f"step_{mode}_{k}": step[k][0] for mode, step in (("paper", step_paper), ("mom", step_mom))
                 for k in "xy"},
              **{f"v_{k}": live[f"v_{k}"] + live[f"kick_{k}"] for k in "xy"},
              **events(paper=(step_paper["x"][1], step_paper["y"][1]), mom=(step_mom["x"][1], step_mom["y"][1])))
    # the mode's step in a stage of its own: saturation and the mode's multiplexer in one stage
    # (six LUT levels) were the core's critical path (docs/synthesis.md)
    live.step(tail, "t8m", drop=tuple(f"step_{mode}_{k}" for mode in ("paper", "mom") for k in "xy"),
              **{f"step_{k}": Mux(momentum, live[f"step_mom_{k}"], live[f"step_paper_{k}"]) for k in "xy"})
    velocity = {k: clamp(live[f"v_{k}"], fs.velocity) for k in "xy"}
    live.step(tail, "t9", drop=("step_x", "step_y"),
              **{f"p_{k}": live[f"p_{k}"] + live[f"step_{k}"] for k in "xy"},
              **{f"v_{k}": Mux(momentum, live[f"step_{k}"], velocity[k][0]
                               )[:fs.velocity.width].as_signed() for k in "xy"},
              **events(paper=(velocity["x"][1], velocity["y"][1])))
    # V'·(1 − γ) alongside the position's saturation, then V'' = rq(V'·(1 − γ) → velocity)
    position = {k: clamp(live[f"p_{k}"], fs.position) for k in "xy"}
    live.update({f"p_{k}": position[k][0] for k in "xy"})
    live.update(events(place=(position["x"][1], position["y"][1])))
    live.multiply(tail, "t10", drop=("v_x", "v_y"), vk_x=(live["v_x"], damping), vk_y=(live["v_y"], damping))
    vk_frac = fs.velocity.frac_bits + fs.damping.frac_bits
    live.step(tail, "t11", **{f"vk_{k}": rounded(live[f"vk_{k}"], vk_frac, fs.velocity) for k in "xy"})
    damped = {k: clamp(live[f"vk_{k}"], fs.velocity) for k in "xy"}
    live.step(tail, "t12", **{f"vk_{k}": damped[k][0] for k in "xy"}, **events(damped["x"][1], damped["y"][1]))
    if saturations:
        # the last flags join the count a clock later, so that the route from the damping's product
        # ends in the clamp's flag registers, not in the count's adder (docs/engine-guard.md)
        live.step(tail, "t13", **count.flush())

    out = ports.o.payload
    m.d.comb += [ports.o.valid.eq(tail.valid),
                 out.position.x.eq(live["p_x"]), out.position.y.eq(live["p_y"]),
                 out.velocity.x.eq(live["vk_x"]), out.velocity.y.eq(live["vk_y"]), out.power.eq(live["pw"])]
    if side is not None:
        m.d.comb += Value.cast(out.side).eq(live["side"])
    if saturations:
        assert sum(count.counted) == node_events, (count.counted, INTEGRATOR_EVENTS)
        m.d.comb += out.saturations.eq(live["ev"])

    # nodes in flight (at most one per stage)
    in_flight = Signal(range(tail.stages + 2), name="nodes_in_flight")
    m.d.sync += in_flight.eq(in_flight + ports.i.valid - ports.o.valid)
    m.d.comb += ports.idle.eq(in_flight == 0)
    return tail.stages
