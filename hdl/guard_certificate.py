"""The step guard's certificate of one triangle: the smallest fraction ``2^-r`` of the proposed moves
that keeps its signed area above the floor, and which corners cannot move at all, one triangle per
clock (or per two).

The RTL twin of :func:`golden_model.fixed.guard.triangle_levels_raw` and of a triangle's part of
:func:`~golden_model.fixed.guard.stuck_nodes_raw`, the tests the engine's guarded mode is to run in two
passes over the triangles (``docs/engine-guard.md``); every width comes from a
:class:`~golden_model.fixed.FormatSet` and the guard's constants from :mod:`golden_model.guard`.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal, Value
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.fixed.guard import EDGE_WEIGHT, MOVE_WEIGHTS, ROUNDING_MARGIN, floor_min_shift
from golden_model.guard import FLOOR_SHIFT, GUARD_LEVELS

from .fifo import LutFIFO
from .fixedpoint import FormatSetNotBuildable, clamp, shape_of, shift_round
from .layouts import certificate_layout, certificate_result_layout
from .pipeline import Pipeline, reduce_levels

__all__ = ["GuardCertificate", "SUBSETS"]

#: The corner subsets whose moves the certificate tries together (a triangle's doubled area is
#: multi-affine in its corners' move fractions): each as the corners it moves.
SUBSETS = ((0,), (1,), (2,), (0, 1), (1, 2), (2, 0), (0, 1, 2))


class GuardCertificate(wiring.Component):
    """A triangle's level ``r`` (its corners may move by ``2^-r`` of their proposals), bit-exact with
    ``triangle_levels_raw``.

    Per triangle (corners ``a``, ``b``, ``c`` [position], proposals ``V'`` [velocity], the host's
    area ``A`` [face_area], the layout's winding ``σ = ±1``; position, velocity and face_edge share
    their fraction bits, so every product is at twice them, "lsb²")::

        ab, ac, o_k = sat(edge → face_edge)            o_k the edge opposite corner k; wide if any saturates
        X0 = σ·(ab × ac),  L_k = σ·(V'_k × o_k),  Q_k = σ·(V'_k × V'_(k+1))
        M = 2·(|ab|₁ + |ac|₁) + 8 + 4|V'_a|₁ + 2|V'_b|₁ + 2|V'_c|₁         the moves' rounding margin
        floor = min(X0, max(X0 >> FLOOR_SHIFT, rnd(A·2^floor_min_shift))) + M     (half up)
        safe_r = ∀ S: X0 + (Σ_S L >> r) + (Σ_pairs⊂S Q >> 2r) ≥ floor
        level = min{r ≤ GUARD_LEVELS : safe_r}, else GUARD_LEVELS + 1 (also for a wide triangle)
        stuck_k = X0 + (L_k >> GUARD_LEVELS) < floor − M + M_k   (M_k: the margin with corner k's move alone)
                  or the triangle is wide

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
    interval : int
        The initiation interval, 1 or 2: clocks per triangle at most. At 2 each multiplier forms one
        product of a cross product in the triangle's clock and the other in the clock after, so the
        unit takes half the DSP blocks (28 instead of 56 in ``default``), for two more stages.
    registered_valid : bool
        ``o.valid`` from a flip-flop of its own (the result FIFO's ``registered_ready``), the same in every
        clock: for a build whose ``o.valid`` is routed across the device (the engine above
        ``DEFAULT_CAPACITY``: :class:`~hdl.guard_passes.GuardPasses`).

    Members
    -------
    i : ``In(stream.Signature(certificate_layout(fs)))``
        One triangle per beat.
    winding_negative : ``In(1)``
        ``σ = −1`` (the layout winds clockwise): a run constant, steady while triangles flow.
    o : ``Out(stream.Signature(certificate_result_layout()))``
        The triangle's ``level`` and ``stuck`` corners (bit k: corner k), in input order. The stuck
        pass reads ``stuck`` (with the proposals as they are), the certificate pass ``level`` (with
        the stuck nodes' proposals zeroed).

    Contract
    --------
    Throughput: one triangle per ``interval`` clocks (``i.ready`` is low in the clock after a
    transfer at II 2) while ``o.ready`` is high. Latency: with
    ``o.ready`` high, a triangle transferred at clock edge ``k`` is on ``o`` after edge
    ``k + latency`` (:meth:`latency_of`). Back-pressure is a credit count: the pipeline runs
    free (no clock enable fans out to its registers) into a result FIFO of :attr:`credits`
    levels, and ``i.ready`` (a register's compare) is high while fewer triangles than that are
    owed (accepted, their level not yet taken from ``o``), so the FIFO never overflows and the
    credits never run out while ``o`` is ready.

    Structure
    ---------
    A free-running pipeline: the beat registered; the exact edges; narrowed to
    face_edge (the wide flag, the norms' first sums); the 14 products (operands landed, DSP
    stages, adder levels, the margin's sums alongside); the products whole, in the order ``σ`` (from a
    register of its own) gives them; the cross products; the floor's cases (compares no wider than floor_min) and
    the subsets' pair sums; the floor picked and the triple sums; the margin added, per subset ``S``
    less its index ``i``; ``X0 − floor + i`` per subset (a copy each, so that no value drives more
    than 7 adders); per subset and level ``X0 − floor + i + (Σ L >> r)`` and ``(Σ Q >> 2r) − i``, then
    the sign of their sum; the flags copied, with no logic, into registers of their own; the level, the smallest
    safe one. Each stage does one add (a carry chain) of every value it forms.
    """

    def __init__(self, fs: FormatSet | str, *, interval: int = 1, registered_valid: bool = False):
        if interval not in (1, 2) or isinstance(interval, bool):
            raise ValueError(f"interval must be 1 or 2, not {interval!r}")
        if not isinstance(registered_valid, bool):
            raise TypeError(f"registered_valid must be a bool, not {registered_valid!r}")
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"GuardCertificate needs a FormatSet or a preset name, not {fs!r}")
        if not fs.position.frac_bits == fs.velocity.frac_bits == fs.face_edge.frac_bits:
            raise FormatSetNotBuildable(
                f"the certificate needs position {fs.position}, velocity {fs.velocity} and face_edge "
                f"{fs.face_edge} to share their fraction bits")
        self.fs, self.interval, self.registered_valid = fs, interval, registered_valid
        self.latency = self.latency_of(fs, interval)
        #: Triangles that may be owed at once: the result FIFO's depth (a power of two above the latency).
        self.credits = 1 << (self.latency + 1).bit_length()
        super().__init__({
            "i": In(stream.Signature(certificate_layout(fs))),
            "winding_negative": In(1),
            "o": Out(stream.Signature(certificate_result_layout())),
        })

    @staticmethod
    def stages_of(fs: FormatSet, interval: int = 1) -> int:
        """The pipeline's stages: beat, edges, narrowing, the multiply (:meth:`Pipeline.mul_stages` with
        landed operands and its adder levels), then the products whole, the cross products, three floor
        stages, ``X0 − floor``, the two compare stages, the flags' copies and the level; at II 2 also the operands' select
        before the multiply and the first products' register after it."""
        edge, move = shape_of(fs.face_edge), shape_of(fs.velocity)
        return 13 + 2 * (interval - 1) + Pipeline.mul_stages(land_operands=True) \
            + reduce_levels((edge, edge), (move, edge), (move, move))

    @classmethod
    def latency_of(cls, fs: FormatSet, interval: int = 1) -> int:
        """Clock edges from a triangle's transfer to its level on ``o``: the pipeline, then the FIFO."""
        return cls.stages_of(fs, interval) + 1

    def elaborate(self, platform):
        fs = self.fs
        m = Module()
        accept = self.i.valid & self.i.ready
        pipe = Pipeline(m, accept, land_operands=True, platform=platform)

        def stage(name, **values):
            pipe.stage(name)
            return {key: pipe.keep(Value.cast(value), f"{name}_{key}") for key, value in values.items()}

        beat = data.View(certificate_layout(fs), stage("beat", beat=self.i.payload.as_value())["beat"])
        corner, move = [beat.a, beat.b, beat.c], [beat.move_a, beat.move_b, beat.move_c]
        # exact edges: ab, ac and each corner's opposite edge (corner k+1 − corner k+2)
        edges = {"ab": (corner[1], corner[0]), "ac": (corner[2], corner[0])}
        edges.update({f"o{k}": (corner[(k + 1) % 3], corner[(k + 2) % 3]) for k in range(3)})
        edge_keys = [f"{n}_{axis}" for n in edges for axis in "xy"]
        s = stage("edge", **{f"{n}_{axis}": getattr(p, axis) - getattr(q, axis) for n, (p, q) in edges.items()
                             for axis in "xy"},
                  **{f"m{k}_{axis}": getattr(move[k], axis) for k in range(3) for axis in "xy"},
                  **{f"abs_m{k}_{axis}": abs(getattr(move[k], axis)) for k in range(3) for axis in "xy"},
                  floor_min=shift_round(beat.area, -floor_min_shift(fs), "half_up"))
        narrowed = {key: clamp(s[key], fs.face_edge) for key in edge_keys}
        # the margin's norms from the exact edges: where they differ from the narrowed ones, the
        # triangle is wide and its level is GUARD_LEVELS + 1 whatever the margin
        s = stage("narrow", **{key: value for key, (value, _) in narrowed.items()},
                  **{f"m{k}_{axis}": s[f"m{k}_{axis}"] for k in range(3) for axis in "xy"},
                  floor_min=s["floor_min"], wide=Cat(*(over for _, over in narrowed.values())).any(),
                  **{f"abs_{e}_{axis}": abs(s[f"{e}_{axis}"]) for e in ("ab", "ac") for axis in "xy"},
                  **{f"norm_m{k}": s[f"abs_m{k}_x"] + s[f"abs_m{k}_y"] for k in range(3)})

        # the margin M, one add per stage while the products are formed
        # and each corner's margin alone (its move's weight, the edges' part) for the stuck test
        carried = {"floor_min": s["floor_min"], "wide": s["wide"],
                   "edges_ab": s["abs_ab_x"] + s["abs_ab_y"], "edges_ac": s["abs_ac_x"] + s["abs_ac_y"],
                   "moves_ab": MOVE_WEIGHTS[0] * s["norm_m0"] + MOVE_WEIGHTS[1] * s["norm_m1"],
                   "moves_c": MOVE_WEIGHTS[2] * s["norm_m2"] + ROUNDING_MARGIN,
                   **{f"alone{k}": weight * s[f"norm_m{k}"] + ROUNDING_MARGIN for k, weight in enumerate(MOVE_WEIGHTS)}}
        alone = [f"alone{k}" for k in range(3)]
        margin_steps = [
            lambda c: {"floor_min": c["floor_min"], "wide": c["wide"], "edges": c["edges_ab"] + c["edges_ac"],
                       "moves": c["moves_ab"] + c["moves_c"], **{key: c[key] for key in alone}},
            lambda c: {"floor_min": c["floor_min"], "wide": c["wide"], "margin": EDGE_WEIGHT * c["edges"] + c["moves"],
                       **{f"stuck_margin{k}": EDGE_WEIGHT * c["edges"] + c[key] for k, key in enumerate(alone)}},
        ]

        def carry(stage_name):
            nonlocal carried
            for key, value in carried.items():
                carried[key] = pipe.keep(Value.cast(value), f"{stage_name}_{key}")
            if margin_steps:
                carried = margin_steps.pop(0)(carried)

        def cross_operands(u, v, name):
            return {f"{name}_p": (s[f"{u}_x"], s[f"{v}_y"]), f"{name}_q": (s[f"{u}_y"], s[f"{v}_x"])}

        products = {**cross_operands("ab", "ac", "x0")}
        for j in range(3):
            products.update(cross_operands(f"m{j}", f"o{j}", f"l{j}"))
            products.update(cross_operands(f"m{j}", f"m{(j + 1) % 3}", f"q{j}"))
        if self.interval == 2:
            products = self._products_in_two_clocks(m, pipe, products, carry)
        else:
            products = pipe.multiply(products, "products", carry)
        assert not margin_steps, "the multiply has fewer stages than the margin's adds"
        # the products whole (their partial products' last add) before the cross products' subtract
        # σ from a register of its own (a run constant): the products whole, each cross product's two
        # in the order σ gives them (σ·(p − q) = q − p for σ = −1), so that the next stage is one
        # subtract (a multiplexer between the subtract's operands and the subtract in one stage is
        # rewritten by synthesis into a subtract and a negation, two carry chains)
        negative = Signal(name="winding_negative_q")
        m.d.sync += negative.eq(self.winding_negative)
        terms = ("x0", "l0", "l1", "l2", "q0", "q1", "q2")
        ordered = {}
        for n in terms:
            p, q = products[f"{n}_p"], products[f"{n}_q"]
            ordered.update({f"{n}_p": Mux(negative, q, p), f"{n}_q": Mux(negative, p, q)})
        s = stage("joined", **ordered, **carried)
        s = stage("cross", **{n: s[f"{n}_p"] - s[f"{n}_q"] for n in terms}, **{k: s[k] for k in carried})
        # floor = min(X0, max(X0 >> FLOOR_SHIFT, floor_min)) with floor_min ≥ 0, by cases:
        # X0 < 0: X0;  X0 >> FLOOR_SHIFT ≥ floor_min: X0 >> FLOOR_SHIFT;  else min(X0, floor_min).
        # Each compare is against floor_min's width only (the wider bits of a non-negative X0 only
        # need to be zero), so no carry chain is longer than floor_min.
        x0, floor_min = s["x0"], s["floor_min"]
        bits = len(floor_min)
        shrunk = x0.shift_right(FLOOR_SHIFT)
        stuck_margins = {f"stuck_margin{k}": s[f"stuck_margin{k}"] for k in range(3)}
        s = stage("floor_cases", **{k: s[k] for k in terms}, margin=s["margin"], **stuck_margins, wide=s["wide"],
                  floor_min=floor_min,
                  shrunk=shrunk, shrunk_wins=(shrunk[bits:] != 0) | (shrunk[:bits] >= floor_min),
                  x0_below=(x0[bits:] == 0) & (x0[:bits] < floor_min),
                  l01=s["l0"] + s["l1"], l12=s["l1"] + s["l2"], l20=s["l2"] + s["l0"], q01=s["q0"] + s["q1"])
        x0 = s["x0"]
        floor = Mux(x0 < 0, x0, Mux(s["shrunk_wins"], s["shrunk"], Mux(s["x0_below"], x0, s["floor_min"])))
        lin = {0: s["l0"], 1: s["l1"], 2: s["l2"], 3: s["l01"], 4: s["l12"], 5: s["l20"], 6: s["l01"] + s["l2"]}
        quad = {3: s["q0"], 4: s["q1"], 5: s["q2"], 6: s["q01"] + s["q2"]}
        # X0 − floor fans out to the 7 × 7 level adders: one copy per subset i, kept distinct by an
        # offset of i (the margin less i, the compare against i), so each drives 7 adders
        subsets = range(len(SUBSETS))
        s = stage("floor_pick", floor=floor, x0=x0, wide=s["wide"], **{f"margin{i}": s["margin"] - i for i in subsets},
                  **{key: s[key] for key in stuck_margins},
                  **{f"lin{i}": v for i, v in lin.items()}, **{f"quad{i}": v for i, v in quad.items()})

        def sums(s):
            return {k: s[k] for k in s if k.startswith(("lin", "quad"))}

        s = stage("floor", x0=s["x0"], wide=s["wide"], **{f"floor{i}": s["floor"] + s[f"margin{i}"] for i in subsets},
                  **{f"stuck_floor{k}": s["floor"] + s[f"stuck_margin{k}"] for k in range(3)}, **sums(s))
        s = stage("slack", wide=s["wide"], **{f"slack{i}": s["x0"] - s[f"floor{i}"] for i in subsets},
                  **{f"stuck_slack{k}": s["x0"] - s[f"stuck_floor{k}"] for k in range(3)}, **sums(s))
        levels = range(GUARD_LEVELS + 1)
        # the quadratic terms less the copy's offset beside them, so that the compare is a sign
        # the stuck test: a corner's own move (subset i = k) at the smallest fraction, its margin alone
        s = stage("linear", wide=s["wide"],
                  **{f"stuck_p{k}": s[f"stuck_slack{k}"] + s[f"lin{k}"].shift_right(GUARD_LEVELS) for k in range(3)},
                  **{f"p{i}_{r}": s[f"slack{i}"] + s[f"lin{i}"].shift_right(r) for i in subsets for r in levels},
                  **{f"q{i}_{r}": s[f"quad{i}"].shift_right(2 * r) - i for i in subsets for r in levels
                     if f"quad{i}" in s})
        s = stage("compare", wide=s["wide"], stuck=Cat(*((s[f"stuck_p{k}"] < 0) | s["wide"] for k in range(3))),
                  **{f"ok{i}_{r}": (s[f"p{i}_{r}"] + s[f"q{i}_{r}"] >= 0) if f"q{i}_{r}" in s else (s[f"p{i}_{r}"] >= i)
                     for i in subsets for r in levels})
        # the flags copied into registers of their own, no logic between: each compare's flag then has one
        # load and is placed at the end of its carry chain, and the level's choice reads the copies
        s = stage("flags", **s)
        safe = [Cat(*(s[f"ok{i}_{r}"] for i in range(len(SUBSETS)))).all() & ~s["wide"] for r in levels]
        level = GUARD_LEVELS + 1
        for r in reversed(levels):  # the smallest safe level wins
            level = Mux(safe[r], r, level)
        s = stage("level", level=level, stuck=s["stuck"])
        result = Signal(certificate_result_layout())
        m.d.comb += [result.level.eq(s["level"]), result.stuck.eq(s["stuck"])]
        m.submodules.results = results = LutFIFO(width=len(result.as_value()), depth=self.credits,
                                                     registered_ready=self.registered_valid)
        m.d.comb += [results.w_data.eq(result), results.w_en.eq(pipe.valid),
                     self.o.payload.eq(results.r_data), self.o.valid.eq(results.r_rdy),
                     results.r_en.eq(self.o.ready)]
        # credits: owed = accepted, not yet taken; i.ready from a register's compare
        owed = Signal(range(self.credits + 1), name="owed")
        take = self.o.valid & self.o.ready
        m.d.sync += owed.eq(owed + accept - take)
        if self.interval == 2:  # no transfer in the clock after one: the multipliers' second products
            accepted = Signal(name="accepted")
            m.d.sync += accepted.eq(accept)
            m.d.comb += self.i.ready.eq((owed < self.credits) & ~accepted)
        else:
            m.d.comb += self.i.ready.eq(owed < self.credits)
        assert pipe.stages == self.stages_of(fs, self.interval), (pipe.stages, self.stages_of(fs, self.interval))
        return m

    @staticmethod
    def _products_in_two_clocks(m: Module, pipe: Pipeline, products: dict, carry) -> dict:
        """The products ``{n_p: (a, b), n_q: (c, d)}`` with one multiplier per pair: ``n_p``'s operands
        go in the clock of the triangle, ``n_q``'s in the clock after (no triangle follows in that
        clock: ``i.ready``), so ``n_q`` comes out of the multiply one clock after ``n_p``, which waits
        for it in a register of its own."""
        beat = pipe.valid  # the triangle is in the current (narrowing) stage's registers
        names = [key.removesuffix("_p") for key in products if key.endswith("_p")]
        assert sorted(products) == sorted(f"{n}_{half}" for n in names for half in "pq")
        later = {}  # the _q operands, held into the clock after the triangle's
        for n in names:
            for k, operand in enumerate(products[f"{n}_q"]):
                later[n, k] = Signal(Value.cast(operand).shape(), name=f"products_later_{n}_{k}", reset_less=True)
                m.d.sync += later[n, k].eq(operand)
        pipe.stage("products_select")
        shared = {n: tuple(pipe.keep(Mux(beat, products[f"{n}_p"][k], later[n, k]), f"products_select_{n}_{k}")
                           for k in range(2)) for n in names}
        carry("products_select")
        out = pipe.multiply(shared, "products", carry)
        pipe.stage("products_first")
        first = {n: pipe.keep(out[n], f"products_first_{n}") for n in names}
        carry("products_first")
        return {**{f"{n}_p": first[n] for n in names}, **{f"{n}_q": out[n] for n in names}}
