"""The coarse space's work at one node: its basis, and either its share of the sums ``ΦᵀF`` or its coarse move.

The RTL twin of the per-node stages of :mod:`golden_model.fixed.coarse`: :func:`~golden_model.fixed.coarse.integer_basis`,
:func:`~golden_model.fixed.coarse.narrow_forces` with :func:`~golden_model.fixed.coarse.coarse_sums`, and
:func:`~golden_model.fixed.coarse.node_moves`. In the engine it serves
both the coarse phase's sums pass and the integrate pass (:class:`~hdl.coarse_passes.CoarsePasses`).
"""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.coarse import COARSE_DEGREE_MAX, basis_exponents
from golden_model.fixed import FormatSet
from golden_model.fixed.coarse import (BASIS, BASIS_FRAC_BITS, MOVE_BITS, OPERAND_BITS, move_shift_range,
                                       narrow_force_format, sum_bits)

from .fixedpoint import FormatSetNotBuildable, clamp, requantize, round_half_bit, shift_round, variable_shift
from .force_pass import format_set
from .layouts import vector_layout
from .parameters import check_in_range, check_int
from .pipeline import LiveValues, Pipeline, count_stages

__all__ = ["CoarseNode", "move_shift_shape"]


def move_shift_shape(fs: FormatSet):
    """The shape of :attr:`CoarseNode.move_shift`: :func:`golden_model.fixed.coarse.move_shift_range`."""
    return signed(max(abs(end) for end in move_shift_range(fs)).bit_length() + 1)


class CoarseNode(wiring.Component):
    """One node per clock: the basis ``Φ_i`` of its coordinates, then ``Φ_i`` times the node's narrowed force
    (into the sums) or times the coefficients (its move), bit-exact with the golden model::

        Φ_i  = integer_basis(u, v)                        m = (degree + 1)(degree + 2)/2 values [basis]
        sums:   F' = rq_half_up(F → 18 bits), saturating;  sums[k][d] += Φ_ik·F'_d   (exact)
        moves:  move_d = sat(rq(Σ_k Φ_ik·c_kd >> move_shift → accel))

    The same ``2(m − 1)`` multipliers serve both (``moves`` chooses their second operand; ``Φ_0 = 1`` is a
    shift), so a sums pass and a propose pass can share them.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        The force_acc and accel formats and the rounding.
    degree : int
        The coarse space's degree, 1 … :data:`~golden_model.coarse.COARSE_DEGREE_MAX`.
    max_nodes : int
        The most nodes a sums pass adds (the sums' width, :func:`golden_model.fixed.coarse.sum_bits`).
    basis_input : bool
        Take each node's basis values ``Φ_i`` but the constant 1 (``phi``, as the engine's basis memory holds
        them: :func:`golden_model.engine_spec.image.basis_word_layout`) instead of ``u, v``: no basis stages,
        and none of their ``m − degree − 1`` multipliers.

    Members
    -------
    i : ``In(stream.Signature(StructLayout({"uv": vector [basis], "force": vector [force_acc]}), always_ready=True))``
        One node per beat: its basis coordinates ``u, v`` (with ``basis_input``, ``phi``: an array of its ``m − 1``
        basis values [basis] in :func:`~golden_model.coarse.basis_exponents`' order from the second) and (for a
        sums pass) its force. Always ready.
    o : ``Out(stream.Signature(StructLayout({"move": vector [accel], "saturations": 0..2}), always_ready=True))``
        One beat per node, in input order: its coarse move (a moves pass; 0 in a sums pass) and the node's
        saturation events (the forces' narrowing in a sums pass, ``coarse_force``; the move's clamp in a moves
        pass, ``coarse_move``). ``o.valid`` is a register; the consumer takes every beat.
    moves : ``In(1)``
        A moves pass (1) or a sums pass (0). Change it only while ``idle``: the stages read it as the node
        passes them, so a change with nodes in flight would move them to the other kind.
    coefficients : ``In(ArrayLayout(vector of signed 18 bits, m))``
        ``c`` as mantissas (:func:`golden_model.fixed.coarse.coefficients`). Change them only while ``idle``.
    move_shift : ``In(move_shift_shape(fs))``
        :func:`golden_model.fixed.coarse.move_shift` of the pass. Change it only while ``idle``.
    clear : ``In(1)``
        Zeroes the sums at the clock edge (before a sums pass; no node may be in flight).
    sums : ``Out(ArrayLayout(vector of signed sum_bits(max_nodes), m))``
        The exact sums of the nodes of the sums passes since the last ``clear`` (registers).
    idle : ``Out(1)``
        No node in flight.

    Contract
    --------
    Throughput: one node per clock (II = 1). Latency: :attr:`latency` clocks from a node's transfer on ``i`` to
    its result on ``o`` (the stages built, counted); its share of the sums is in ``sums`` a clock later. No
    back-pressure.
    """

    def __init__(self, fs: FormatSet | str, degree: int, max_nodes: int, *, basis_input: bool = False):
        fs = format_set(fs, "CoarseNode")
        check_in_range("degree", degree, 1, COARSE_DEGREE_MAX)
        check_int("max_nodes", max_nodes)
        if not isinstance(basis_input, bool):
            raise TypeError(f"CoarseNode basis_input must be a bool, not {basis_input!r}")
        if not fs.accel.signed or not fs.force_acc.signed:
            raise FormatSetNotBuildable(f"force_acc {fs.force_acc} and accel {fs.accel} must be signed")
        self.fs, self.degree, self.max_nodes, self.basis_input = fs, degree, max_nodes, basis_input
        self.exponents = basis_exponents(degree)
        super().__init__(self.signature_of(fs, degree, max_nodes, basis_input))
        self.latency = count_stages(lambda m: _build(
            m, self, self.signature_of(fs, degree, max_nodes, basis_input).create(), None))

    @staticmethod
    def signature_of(fs: FormatSet, degree: int, max_nodes: int, basis_input: bool = False) -> wiring.Signature:
        """The component's signature (also the throwaway build's stand-in ports)."""
        m = len(basis_exponents(degree))
        coefficient = data.StructLayout({"x": signed(OPERAND_BITS), "y": signed(OPERAND_BITS)})
        total = data.StructLayout({"x": signed(sum_bits(max_nodes)), "y": signed(sum_bits(max_nodes))})
        basis = {"phi": data.ArrayLayout(signed(OPERAND_BITS), m - 1)} if basis_input else {"uv": vector_layout(BASIS)}
        return wiring.Signature({
            "i": In(stream.Signature(data.StructLayout({**basis, "force": vector_layout(fs.force_acc)}),
                                     always_ready=True)),
            "o": Out(stream.Signature(data.StructLayout({"move": vector_layout(fs.accel), "saturations": range(3)}),
                                      always_ready=True)),
            "moves": In(1),
            "coefficients": In(data.ArrayLayout(coefficient, m)),
            "move_shift": In(move_shift_shape(fs)),
            "clear": In(1),
            "sums": Out(data.ArrayLayout(total, m)),
            "idle": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        stages = _build(m, self, self, platform)
        assert stages == self.latency, (stages, self.latency)
        return m


def _build(m: Module, unit: CoarseNode, ports, platform) -> int:
    """The node's datapath into ``m`` (``ports``: the component's members; ``platform``: :data:`hdl.dsp.ECP5` for
    ``MULT18X18D`` instances); returns its stages."""
    fs, exponents = unit.fs, unit.exponents
    live = LiveValues()
    pipe = Pipeline(m, ports.i.valid, platform=platform)
    node = ports.i.payload
    moves = Signal(name="moves_held")  # the pass's kind, registered (it changes only between passes)
    # the move's shift as the shifters take it, registered from the port (it changes only between passes): the
    # right amount, or the left one negated, so that no negation sits before a shifter
    amount_bits = fs.accel.width.bit_length()
    left_shift = Signal(name="move_left_shift")
    right_amount = Signal(len(ports.move_shift), name="move_right_amount")
    left_amount = Signal(amount_bits, name="move_left_amount")
    negative = ports.move_shift.as_signed() < 0
    m.d.sync += [moves.eq(ports.moves), left_shift.eq(negative),
                 right_amount.eq(Mux(negative, 0, ports.move_shift.as_unsigned())),
                 left_amount.eq(Mux(negative, (-ports.move_shift.as_signed())[:amount_bits], 0))]
    # C1: the inputs, and the forces rounded to the sums' 18 bits (their saturation flags with them)
    narrow = narrow_force_format(fs)
    narrowed = {d: requantize(node.force[d], fs.force_acc.frac_bits, narrow, "half_up") for d in "xy"}
    if unit.basis_input:  # the basis as the node's word holds it
        phi = {e: f"phi{e[0]}{e[1]}" for e in exponents[1:]}
        basis = {phi[e]: node.phi[k] for k, e in enumerate(exponents[1:])}
    else:
        phi = {(1, 0): "u", (0, 1): "v"}
        basis = {"u": node.uv.x, "v": node.uv.y}
    live.step(pipe, "c1", **basis, **{f"f_{d}": narrowed[d][0] for d in "xy"},
              force_events=narrowed["x"][1] + narrowed["y"][1])
    # the basis, a degree at a time (unless it comes in): each monomial from one of a degree lower times u (or v),
    # rounded half up
    levels = () if unit.basis_input else range(2, unit.degree + 1)
    for level in levels:
        wanted = [(a, b) for a, b in exponents if a + b == level]
        products = {f"p{a}{b}": (live[phi[(a - 1, b) if a else (a, b - 1)]], live["u" if a else "v"])
                    for a, b in wanted}
        live.multiply(pipe, f"basis{level}", **products)
        live.step(pipe, f"basis{level}_round", drop=tuple(products),
                  **{f"phi{a}{b}": shift_round(live[f"p{a}{b}"], BASIS_FRAC_BITS, "half_up")[:OPERAND_BITS].as_signed()
                     for a, b in wanted})
        phi.update({(a, b): f"phi{a}{b}" for a, b in wanted})
    # the second operands, landed: the narrowed force (sums) or the coefficient (moves)
    live.step(pipe, "operands", drop=("f_x", "f_y"),
              **{f"o{k}{d}": Mux(moves, ports.coefficients[k][d], live[f"f_{d}"])
                 for k in range(len(exponents)) for d in "xy"})
    # the products Φ_k·o_k, 18 × 18 each; Φ_0 = 1 is a shift, carried along
    products = {f"q{k}{d}": (live[phi[e]], live[f"o{k}{d}"]) for k, e in enumerate(exponents) if k for d in "xy"}
    for d in "xy":
        live[f"q0{d}"] = live.pop(f"o0{d}").shift_left(BASIS_FRAC_BITS)
    live.multiply(pipe, "products", drop=tuple(phi.values()) + tuple(f"o{k}{d}" for k in range(1, len(exponents))
                                                                       for d in "xy"), **products)
    # the sums: every product of a sums pass added, exact
    width = sum_bits(unit.max_nodes)
    sums_valid = pipe.valid & ~moves
    for k in range(len(exponents)):
        for d in "xy":
            total = ports.sums[k][d]
            with m.If(ports.clear):
                m.d.sync += total.eq(0)
            with m.Elif(sums_valid):
                m.d.sync += total.eq((total + live[f"q{k}{d}"])[:width].as_signed())
    # the move: Σ_k Φ_k·c_k by pairwise adder levels, then the variable shift, its rounding, the clamp
    terms = {d: [f"q{k}{d}" for k in range(len(exponents))] for d in "xy"}
    level = 0
    while len(terms["x"]) > 1:
        level += 1
        new, names = {}, {}
        for d in "xy":
            names[d] = []
            for j in range(0, len(terms[d]), 2):
                pair = terms[d][j:j + 2]
                name = f"s{level}_{j // 2}{d}"
                new[name] = live[pair[0]] if len(pair) == 1 else live[pair[0]] + live[pair[1]]
                names[d].append(name)
        live.step(pipe, f"move_sum{level}", drop=tuple(terms["x"] + terms["y"]), **new)
        terms = names
    right = {d: variable_shift(live[terms[d][0]], right_amount, fs.rounding) for d in "xy"}
    left = {d: live[terms[d][0]] << left_amount for d in "xy"}
    live.step(pipe, "move_shift", drop=tuple(terms["x"] + terms["y"]), left_shift=left_shift,
              **{f"t_{d}": right[d][0] for d in "xy"}, **{f"sticky_{d}": right[d][1] for d in "xy"},
              **{f"l_{d}": left[d] for d in "xy"})
    live.step(pipe, "move_round", drop=tuple(f"{n}_{d}" for n in ("t", "sticky", "l") for d in "xy") + ("left_shift",),
              **{f"r_{d}": Mux(live["left_shift"], live[f"l_{d}"],
                               round_half_bit(live[f"t_{d}"], fs.rounding, live[f"sticky_{d}"])) for d in "xy"})
    clamped = {d: clamp(live[f"r_{d}"], fs.accel) for d in "xy"}
    live.step(pipe, "move_clamp", drop=("r_x", "r_y", "force_events"),
              **{f"out_{d}": Mux(moves, clamped[d][0], 0) for d in "xy"},
              events=Mux(moves, clamped["x"][1] + clamped["y"][1], live["force_events"]))
    out = ports.o.payload
    m.d.comb += [ports.o.valid.eq(pipe.valid), out.move.x.eq(live["out_x"]), out.move.y.eq(live["out_y"]),
                 out.saturations.eq(live["events"])]
    in_flight = Signal(range(pipe.stages + 2), name="nodes_in_flight")
    m.d.sync += in_flight.eq(in_flight + ports.i.valid - ports.o.valid)
    m.d.comb += ports.idle.eq(in_flight == 0)
    return pipe.stages
