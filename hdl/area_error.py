"""The area pass of the engine's controller: Σ|A − |A'|| over the triangles, one per clock.

The RTL twin of the sum that :func:`golden_model.fixed.measures.area_error` forms before it
normalises it (:class:`hdl.controller_units.Normaliser` does that); every width comes from a
:class:`~golden_model.fixed.FormatSet`.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Value
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet

from .fixedpoint import FormatSetNotBuildable, clamp, requantize, shape_of, shift_round
from .layouts import area_saturations_layout, triangle_layout
from .pipeline import Pipeline, reduce_levels

__all__ = ["AreaError"]


class AreaError(wiring.Component):
    """``Σ|A − |A'||`` [error_acc] of a pass over the triangles, bit-exact with ``area_error``'s sum.

    Per triangle (corners ``a``, ``b``, ``c`` [position], host's area ``A`` [face_area])::

        u = sat(b − a → face_edge),  v = sat(c − a → face_edge)      (x and y; fraction bits equal)
        |A'| = rq(|u.x·v.y − u.y·v.x| → face_area)                   (the cross product has 2F + 1
                                                                       fraction bits: a doubled area)
        total = sat(Σ |A − |A'|| → error_acc)

    The running sum saturates at every triangle, which equals the golden model's single
    saturation of the exact sum because every term is non-negative.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        Every width and the rounding mode come from it.

    Members
    -------
    i : ``In(stream.Signature(triangle_layout(fs), always_ready=True))``
        One triangle per beat; always ready (the pipeline never stalls).
    clear : ``In(1)``
        Start a new pass: the sum and the counts restart from the triangle (if any) that
        reaches the accumulator in this clock. Assert it for a clock while ``idle`` (the clock
        of the new pass's first transfer is fine: that triangle is still far from the accumulator).
    total : ``Out(shape_of(fs.error_acc))``
        The pass's sum so far (a register).
    saturations : ``Out(area_saturations_layout(fs))``
        The pass's saturation events as the golden model's ``SaturationCounter`` counts them:
        ``face_edge`` one per saturated edge component (0–4 per triangle), ``face_area`` one per
        triangle whose area saturated, ``area_sum`` 1 once the sum has saturated. The counts are
        exact for every pass the host accepts (fewer than ``2**(63 − face_area.width)`` triangles).
    idle : ``Out(1)``
        No triangle in flight: every triangle transferred before this clock is in ``total``
        and ``saturations``. A pass is done when ``idle`` is high after its last transfer.

    Contract
    --------
    Throughput: one triangle per clock (II = 1), ``i.ready`` is constant 1.
    Latency: a triangle transferred at clock edge ``k`` is in ``total`` and ``saturations``
    after edge ``k + latency`` (:meth:`latency_of`: 14 in both presets), when ``idle`` is high
    again if no other triangle followed; N triangles back to back are summed
    ``N − 1 + latency`` edges after the first transfer.

    Top-level conversion: ``i.ready`` is a constant, which ``verilog.convert`` cannot take as
    a port (amaranth-lang/amaranth#1574): pass ``ports=`` without it (the tests show how).

    Structure
    ---------
    A free-running pipeline (no clock enable): the beat registered; the four edge components
    exact; saturated to ``face_edge`` (edge events counted); the two products of the cross
    product (:meth:`~hdl.pipeline.Pipeline.multiply`, operands landed in fabric registers,
    18×18 partial products, adder levels); their difference; its magnitude; rounded to
    ``face_area``; saturated (area events counted); ``|A − |A'||``; then the accumulator.
    Every multiply sits alone between registers, every rounding and saturation has a stage.
    """

    def __init__(self, fs: FormatSet | str):
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"AreaError needs a FormatSet or a preset name, not {fs!r}")
        if fs.face_edge.frac_bits != fs.position.frac_bits:  # FormatSet checks it; the edges rely on it
            raise FormatSetNotBuildable(
                f"face_edge {fs.face_edge} needs position's {fs.position.frac_bits} fraction bits")
        if fs.face_area.frac_bits != fs.error_acc.frac_bits:
            raise FormatSetNotBuildable(
                f"face_area {fs.face_area} needs error_acc's {fs.error_acc.frac_bits} fraction bits")
        self.fs = fs
        self.latency = self.latency_of(fs)
        super().__init__({
            "i": In(stream.Signature(triangle_layout(fs), always_ready=True)),
            "clear": In(1),
            "total": Out(shape_of(fs.error_acc)),
            "saturations": Out(area_saturations_layout(fs)),
            "idle": Out(1),
        })

    @staticmethod
    def latency_of(fs: FormatSet) -> int:
        """Clock edges from a triangle's transfer (which loads the beat register) to its term in
        ``total``: edges, edge saturation, the cross product's multiply (:meth:`Pipeline.mul_stages`
        with landed operands and its adder levels), difference, magnitude, rounding, saturation,
        ``|A − |A'||``, and the accumulator."""
        edge = shape_of(fs.face_edge)
        return 8 + Pipeline.mul_stages(land_operands=True) + reduce_levels((edge, edge))

    def elaborate(self, platform):
        fs = self.fs
        rnd = fs.rounding
        m = Module()
        pipe = Pipeline(m, self.i.valid, land_operands=True, platform=platform)
        valids = []  # every stage's valid bit: idle is their NOR

        def stage(name, **values):
            """The next stage, registering ``values``; returns them as registers."""
            valids.append(pipe.stage(name))
            return {key: pipe.keep(Value.cast(value), f"{name}_{key}") for key, value in values.items()}

        beat = data.View(triangle_layout(fs), stage("beat", beat=self.i.payload.as_value())["beat"])
        a, b, c = beat.a, beat.b, beat.c
        # exact edges, then narrowed to face_edge (same fraction bits: only a saturation)
        s = stage("edge", ux=b.x - a.x, vx=c.x - a.x, uy=b.y - a.y, vy=c.y - a.y, area=beat.area)
        narrowed = {k: requantize(s[k], fs.position.frac_bits, fs.face_edge, rnd) for k in ("ux", "vx", "uy", "vy")}
        edge_events = sum(over for _, over in narrowed.values())
        s = stage("edge_sat", **{k: value for k, (value, _) in narrowed.items()}, area=s["area"],
                  edge_events=edge_events)

        carried = {"area": s["area"], "edge_events": s["edge_events"]}

        def carry(stage_name):
            valids.append(pipe.valid)
            for key, value in carried.items():
                carried[key] = pipe.keep(value, f"{stage_name}_{key}")

        products = pipe.multiply({"p": (s["ux"], s["vy"]), "q": (s["uy"], s["vx"])}, "cross", carry)
        s = stage("cross", cross=products["p"] - products["q"], **carried)
        cross = s["cross"]
        s = stage("abs", doubled=Mux(cross < 0, -cross, cross).as_unsigned(), area=s["area"],
                  edge_events=s["edge_events"])
        doubled_frac = 2 * fs.face_edge.frac_bits + 1
        s = stage("area_round", area_new=shift_round(s["doubled"], doubled_frac - fs.face_area.frac_bits, rnd),
                  area=s["area"], edge_events=s["edge_events"])
        area_new, area_over = clamp(s["area_new"], fs.face_area)
        s = stage("area_sat", area_new=area_new, area=s["area"], edge_events=s["edge_events"],
                  area_events=area_over)
        host, new = s["area"], s["area_new"]
        # |A − |A'||, 0 for a stage without a triangle, and the events gated the same way: the accumulator
        # and the counts then add registers straight (a valid bit gating them in front of the adders
        # would reach their carry chains from across the die)
        s = stage("diff", diff=Mux(pipe.valid, Mux(host > new, host - new, new - host)[:fs.face_area.width], 0),
                  edge_events=Mux(pipe.valid, s["edge_events"], 0), area_events=pipe.valid & s["area_events"])

        # The accumulator: all terms are non-negative, so saturating each partial sum gives the
        # golden model's saturation of the exact sum (once past raw_max, it stays past).
        counts = self.saturations
        # ``clear`` chooses between the sums and the term alone after the adders, not in front of them
        # (in front, clear would feed the 37-bit carry chain: a long path from the controller)
        clear = self.clear
        summed, sum_over = clamp(self.total + s["diff"], fs.error_acc)
        alone, alone_over = clamp(s["diff"], fs.error_acc)
        edge_events, area_events = s["edge_events"], s["area_events"]
        m.d.sync += [
            self.total.eq(Mux(clear, alone, summed)),
            counts.face_edge.eq(Mux(clear, edge_events, counts.face_edge + edge_events)),
            counts.face_area.eq(Mux(clear, area_events, counts.face_area + area_events)),
            counts.area_sum.eq(Mux(clear, alone_over, counts.area_sum | sum_over)),
        ]
        m.d.comb += self.idle.eq(~Cat(*valids).any())
        assert pipe.stages == self.latency, (pipe.stages, self.latency)
        return m

